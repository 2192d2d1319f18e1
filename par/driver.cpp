// SPDX-License-Identifier: GPL-3.0-or-later
#include "par/driver.hpp"

#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <thread>

#include "analysis/snapshot.hpp"
#include "io/checkpoint_collective.hpp"
#include "par/decomposition.hpp"
#include "par/exchange.hpp"
#include "par/messages.hpp"
#include "par/particle_products.hpp"
#include "par/setup.hpp"
#include "par/spectrum.hpp"
#include "par/state.hpp"
#include "remote/endpoint.hpp"
#include "remote/proxy.hpp"
#include "sim/initial_conditions.hpp"
#include "sim/neighbour_search.hpp"

namespace sphles::par {

namespace {

/// A rank waiting for rank 0's next request tests for it without pause this long [s], then
/// sleeps kIdleSleep between tests: a run paused, or busy with analysis and checkpoints on rank
/// 0, does not keep the other ranks' cores spinning (MPI_Bcast would), while requests that
/// follow each other closely (steps) are taken at once.
constexpr std::chrono::milliseconds kIdleSpin{5};
constexpr std::chrono::microseconds kIdleSleep{500};

/// Broadcasts a request's size from rank 0 (a non-blocking broadcast on every rank: they must
/// match), waiting as above.
void broadcast_size(MPI_Comm comm, unsigned long long& size) {
  MPI_Request request = MPI_REQUEST_NULL;
  MPI_Ibcast(&size, 1, MPI_UNSIGNED_LONG_LONG, 0, comm, &request);
  const auto start = std::chrono::steady_clock::now();
  for (int done = 0;;) {
    MPI_Test(&request, &done, MPI_STATUS_IGNORE);
    if (done) return;
    if (std::chrono::steady_clock::now() - start > kIdleSpin)
      std::this_thread::sleep_for(kIdleSleep);
  }
}

/// Rank 0 sends `request` to the other ranks (remote/codec.hpp's bytes) without the particles
/// or state of a Make or Restore, which only rank 0 holds: the ranks receive their shares when
/// the solver is made (par::scatter_state).
void send_to_ranks(MPI_Comm comm, const remote::Request& request) {
  remote::Encoder e;
  if (const auto* make = std::get_if<remote::Make>(&request))
    encode(e, remote::Request{remote::Make{make->scene, {}}});
  else if (const auto* restore = std::get_if<remote::Restore>(&request))
    encode(e, remote::Request{remote::Restore{restore->scene, {}}});
  else
    encode(e, request);
  unsigned long long size = e.bytes().size();
  broadcast_size(comm, size);
  MPI_Bcast(const_cast<std::byte*>(e.bytes().data()), mpi_count(e.bytes().size(), "a request"),
            MPI_BYTE, 0, comm);
}

/// The other ranks: rank 0's next request.
remote::Request receive_from_rank_zero(MPI_Comm comm) {
  unsigned long long size = 0;
  broadcast_size(comm, size);
  std::vector<std::byte> bytes(static_cast<std::size_t>(size));
  MPI_Bcast(bytes.data(), mpi_count(bytes.size(), "a request"), MPI_BYTE, 0, comm);
  return remote::decode_all<remote::Request>(bytes);
}

/// One rank's part of a distributed solver.
struct Member {
  sim::SolverConfig config;
  std::unique_ptr<Decomposition> decomposition;
  std::shared_ptr<MpiExchange> exchange;
  std::unique_ptr<sim::Simulation> local;
  /// The analysis spectrum's plan and buffers, kept while its grid stays the same.
  std::unique_ptr<DistributedSpectrum> spectrum;
  int spectrum_points = 0;

  /// Collective: the velocity spectrum of SPEC §5 on M^n nodes, from the owned particles.
  analysis::EnergySpectrum velocity_spectrum(int points_per_side) {
    if (!spectrum || spectrum_points != points_per_side) {
      spectrum.reset();
      spectrum = std::make_unique<DistributedSpectrum>(*decomposition, points_per_side);
      spectrum_points = points_per_side;
    }
    sim::ParticleArrays owned = local->particles();
    owned.truncate(local->owned_count());  // without the halo copies
    return spectrum->compute(owned);
  }

  /// Collective: the particle products of `request`, from the owned particles.
  analysis::RanksProducts particle_products(const analysis::RanksRequest& request) const {
    sim::ParticleArrays owned = local->particles();
    owned.truncate(local->owned_count());
    return distributed_particle_products(*decomposition, owned, config.kernel,
                                         config.support_radius, request);
  }

  /// Collective: the checkpoint `path` written by every rank, each its block of the particles in
  /// id order (par::id_block), into one file.
  io::CheckpointShape write_checkpoint(const std::string& path,
                                       const io::CheckpointMetadata& metadata,
                                       int gzip_level) const {
    std::uint64_t first = 0, total = 0;
    const sim::SolverState block = id_block(*decomposition, local->state(), first, total);
    return io::write_checkpoint_collective(decomposition->comm(), path, block, first, total,
                                           metadata, {.gzip_level = gzip_level});
  }
};

/// How a member starts: from particles (by position), made by the ranks (par::set_up_share),
/// from a state of all particles read on rank 0, from a checkpoint file its ranks read, or
/// from each rank's own state (a live change; the last three by list reference position).
enum class Start { Fresh, SetUp, Restore, RestoreFile, Continue };

/// A new run's set-up on the ranks: the options (rank 0's, with its cancellation) and the
/// packing's report.
struct SetUp {
  sim::SetupOptions options;
  sim::PackingReport report;
};

/// Every rank: the solver of `scene` over the ranks of `comm`, each receiving its share of
/// `whole` (read on rank 0 only), or of the checkpoint `file`, or making it (`setup`); to
/// continue, `whole` is this rank's own state.
std::unique_ptr<Member> make_member(MPI_Comm comm, const sim::Scene& scene, sim::SolverState whole,
                                    Start start, const std::filesystem::path& file = {},
                                    SetUp* setup = nullptr) {
  const bool restore = start != Start::Fresh && start != Start::SetUp;
  auto m = std::make_unique<Member>();
  m->config = sim::make_solver_config(scene);
  const sim::SolverConfig& c = m->config;
  const sim::VerletNeighbourSearch search(c.box, c.support_radius,
                                          c.neighbour_skin * c.support_radius);
  double halo_width = search.list_radius();
  if (start == Start::SetUp && scene.packing.enabled)  // the packing's lists are the ranks' too
    halo_width = std::max(halo_width, sim::packing_list_radius(c.box, c.support_radius));
  m->decomposition = std::make_unique<Decomposition>(comm, c.box, halo_width, c.particle_spacing);
  m->exchange = std::make_shared<MpiExchange>(*m->decomposition);
  if (start == Start::SetUp) {
    sim::ParticleArrays share =
        set_up_share(*m->decomposition, scene, c, setup->options, setup->report);
    m->local = sim::make_simulation(c, std::move(share), 0.0, 0, m->exchange);
    return m;
  }
  if (!restore) {
    // A fresh start: owned by position (wrapped into the box, as the solver does).
    for (int a = 0; a < whole.particles.dimension; ++a) {
      const auto axis = static_cast<std::size_t>(a);
      std::vector<double>& x = whole.particles.position[axis];
      for (double& v : x) v = sim::wrap_periodic(v, c.box.length[axis]);
      whole.list_reference_positions[axis] = x;
    }
  }
  // A change keeps each particle on its rank (to_owners moves none unless the box changed).
  sim::SolverState share = start == Start::RestoreFile ? read_share(*m->decomposition, file)
                           : start == Start::Continue  ? to_owners(*m->decomposition, whole)
                                                       : scatter_state(*m->decomposition, whole, 0);
  whole = sim::SolverState{};  // rank 0 keeps its share only
  if (restore)
    m->local = sim::restore_simulation(c, std::move(share), m->exchange);
  else
    m->local =
        sim::make_simulation(c, std::move(share.particles), share.time, share.step, m->exchange);
  return m;
}

/// One rank's part of the distributed solver, as a solver: every call is collective (all ranks
/// make it together, rank 0 as the other ranks' requests say). particles() are this rank's
/// (owned, then halo copies); state() is every particle, gathered on rank 0 (empty elsewhere).
class RankSolver final : public sim::Simulation,
                         public analysis::DistributedProducts,
                         public io::DistributedCheckpoints {
 public:
  explicit RankSolver(std::unique_ptr<Member> member) : m_(std::move(member)) {}

  void step(double max_dt) override { m_->local->step(max_dt); }
  double time() const override { return m_->local->time(); }
  std::uint64_t step_count() const override { return m_->local->step_count(); }
  // Time step, diagnostics and maxima are global on every rank already.
  const sim::StepDiagnostics& diagnostics() const override { return m_->local->diagnostics(); }
  const sim::SolverConfig& config() const override { return m_->config; }
  double stable_time_step() const override { return m_->local->stable_time_step(); }
  /// Summed by every rank over its owned particles.
  std::vector<double> case_diagnostics(const sim::Scene& scene) const override {
    return m_->local->case_diagnostics(scene);
  }
  const sim::ParticleArrays& particles() const override { return m_->local->particles(); }
  std::size_t owned_count() const override { return m_->local->owned_count(); }
  std::shared_ptr<const sim::NeighbourList> neighbour_list() const override {
    return m_->local->neighbour_list();
  }
  sim::SolverState state() const override {
    return gather_state(*m_->decomposition, m_->local->state(), 0);
  }
  /// This rank's own part of the state, for a change on the ranks.
  sim::SolverState local_state() const { return m_->local->state(); }

  /// Every rank grids its own particles and a slab of the transform (par/spectrum.hpp).
  analysis::EnergySpectrum velocity_spectrum(int points_per_side) const override {
    return m_->velocity_spectrum(points_per_side);
  }
  /// Every rank computes them for its own particles and slice nodes
  /// (par/particle_products.hpp).
  analysis::RanksProducts particle_products(const analysis::RanksRequest& request) const override {
    return m_->particle_products(request);
  }
  /// Every rank writes its block of the particles in id order into the one file; rank 0 then
  /// writes the XDMF side file.
  void write_checkpoint(const std::filesystem::path& path, const io::CheckpointMetadata& metadata,
                        const io::CheckpointWriteOptions& options) const override {
    const io::CheckpointShape shape = m_->write_checkpoint(path, metadata, options.gzip_level);
    if (m_->decomposition->rank() == 0) io::write_checkpoint_xdmf(path, shape);
  }

 private:
  std::unique_ptr<Member> m_;
};

/// Every rank's solver factories: each call is collective, rank 0's particles or state are
/// scattered to the ranks, a change continues each rank's own particles (no gather).
sim::SolverFactories rank_solvers(MPI_Comm comm) {
  const auto solver = [comm](const sim::Scene& scene, sim::SolverState whole, Start start,
                             const std::filesystem::path& file = {}, SetUp* setup = nullptr) {
    return std::make_unique<RankSolver>(
        make_member(comm, scene, std::move(whole), start, file, setup));
  };
  sim::SolverFactories solvers;
  solvers.make = [solver](const sim::Scene& scene, sim::ParticleArrays all) {
    sim::SolverState whole;
    whole.particles = std::move(all);
    return solver(scene, std::move(whole), Start::Fresh);
  };
  solvers.restore = [solver](const sim::Scene& scene, sim::SolverState whole) {
    return solver(scene, std::move(whole), Start::Restore);
  };
  solvers.restore_file = [solver](const sim::Scene& scene, const std::filesystem::path& path) {
    return solver(scene, sim::SolverState{}, Start::RestoreFile, path);
  };
  solvers.change = [solver](const sim::Simulation& current, const sim::Scene& scene) {
    const auto* mine = dynamic_cast<const RankSolver*>(&current);
    if (!mine) throw std::invalid_argument("a change of a solver the ranks did not make");
    return solver(scene, mine->local_state(), Start::Continue);
  };
  solvers.set_up = [solver](const sim::Scene& scene, const sim::SetupOptions& options,
                            sim::PackingReport& report) {
    SetUp setup{options, {}};
    auto made = solver(scene, sim::SolverState{}, Start::SetUp, {}, &setup);
    report = setup.report;
    return made;
  };
  return solvers;
}

}  // namespace

/// Rank 0's transport: each request goes to the other ranks, and rank 0 carries out its own
/// part of it, whose reply is the request's.
class Driver::RankZero final : public remote::Transport {
 public:
  explicit RankZero(MPI_Comm comm) : comm_(comm), endpoint_(rank_solvers(comm)) {}
  remote::Reply call(remote::Request request) override {
    send_to_ranks(comm_, request);
    return endpoint_.handle(std::move(request));
  }

 private:
  MPI_Comm comm_;
  remote::Endpoint endpoint_;
};

Driver::Driver(MPI_Comm comm) : comm_(comm) {
  int rank = 0;
  MPI_Comm_rank(comm, &rank);
  if (rank != 0) throw std::logic_error("par::Driver belongs on rank 0");
  rank_zero_ = std::make_shared<RankZero>(comm);
}

Driver::~Driver() {
  send_to_ranks(comm_, remote::Finish{});
}

sim::SolverFactories Driver::factories() {
  return remote::remote_solvers([transport = rank_zero_] { return transport; });
}

int Driver::ranks() const {
  int size = 1;
  MPI_Comm_size(comm_, &size);
  return size;
}

void serve_commands(MPI_Comm comm) {
  remote::Endpoint endpoint(rank_solvers(comm));
  for (;;) {
    remote::Request request = receive_from_rank_zero(comm);
    if (std::holds_alternative<remote::Finish>(request)) return;
    try {
      endpoint.handle(std::move(request));
    } catch (const std::exception&) {
      // The same error stopped rank 0's request (every check is collective); rank 0 reports it.
    }
  }
}

int drive_from_rank_zero(const std::function<int(Driver&)>& rank_zero) {
  int provided = 0;
  MPI_Init_thread(nullptr, nullptr, MPI_THREAD_FUNNELED, &provided);
  int rank = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  int rc = 0;
  if (rank == 0) {
    Driver driver(MPI_COMM_WORLD);
    rc = rank_zero(driver);
  } else {
    serve_commands(MPI_COMM_WORLD);
  }
  MPI_Finalize();
  return rc;
}

}  // namespace sphles::par
