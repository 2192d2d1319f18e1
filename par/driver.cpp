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
#include "scene/document.hpp"
#include "sim/initial_conditions.hpp"
#include "sim/neighbour_search.hpp"
#include "sim/state_view.hpp"

namespace sphles::par {

namespace {

enum class Command : int {
  Finish = 0,
  Make = 1,
  Restore = 2,
  Step = 3,
  Gather = 4,
  CaseDiagnostics = 5,
  Spectrum = 6,
  ParticleProducts = 7,
  WriteCheckpoint = 8,
  RestoreFile = 9,
  Change = 10,
  SetUp = 11
};

/// A rank waiting for rank 0's next command tests for it without pause this long [s], then
/// sleeps kIdleSleep between tests: a run paused, or busy with analysis and checkpoints on rank
/// 0, does not keep the other ranks' cores spinning (MPI_Bcast would), while commands that
/// follow each other closely (steps) are taken at once.
constexpr std::chrono::milliseconds kIdleSpin{5};
constexpr std::chrono::microseconds kIdleSleep{500};

/// Broadcasts the command header from rank 0 (a non-blocking broadcast on every rank: they must
/// match), waiting as above.
void broadcast_header(MPI_Comm comm, double (&header)[2]) {
  MPI_Request request = MPI_REQUEST_NULL;
  MPI_Ibcast(header, 2, MPI_DOUBLE, 0, comm, &request);
  const auto start = std::chrono::steady_clock::now();
  for (int done = 0;;) {
    MPI_Test(&request, &done, MPI_STATUS_IGNORE);
    if (done) return;
    if (std::chrono::steady_clock::now() - start > kIdleSpin)
      std::this_thread::sleep_for(kIdleSleep);
  }
}

/// Rank 0 tells every rank what comes next: the command and one number (the step's max_dt).
void send_command(MPI_Comm comm, Command command, double value = 0.0) {
  double header[2] = {static_cast<double>(command), value};
  broadcast_header(comm, header);
}

/// Sends a particle-products request from rank 0 to every rank (its numbers as doubles: each is
/// a flag, a small integer or a length; the particle snapshot's part as it is).
analysis::RanksRequest broadcast_request(MPI_Comm comm, analysis::RanksRequest r) {
  double fields[12] = {static_cast<double>(r.points_per_side),
                       r.fit_radius,
                       r.vorticity ? 1.0 : 0.0,
                       r.slice_omega2 ? 1.0 : 0.0,
                       r.slice_tau ? 1.0 : 0.0,
                       static_cast<double>(r.slice_axis),
                       r.slice_position,
                       r.statistics ? 1.0 : 0.0,
                       static_cast<double>(r.histogram_bins),
                       static_cast<double>(r.angle_bins),
                       r.angle_threshold,
                       r.slice_eddy ? 1.0 : 0.0};
  MPI_Bcast(fields, 12, MPI_DOUBLE, 0, comm);
  r.points_per_side = static_cast<int>(fields[0]);
  r.fit_radius = fields[1];
  r.vorticity = fields[2] != 0.0;
  r.slice_omega2 = fields[3] != 0.0;
  r.slice_tau = fields[4] != 0.0;
  r.slice_axis = static_cast<int>(fields[5]);
  r.slice_position = fields[6];
  r.statistics = fields[7] != 0.0;
  r.histogram_bins = static_cast<int>(fields[8]);
  r.angle_bins = static_cast<int>(fields[9]);
  r.angle_threshold = fields[10];
  r.slice_eddy = fields[11] != 0.0;
  // The grid fields; the particle snapshot's file, fields, time, step and metadata.
  int flags[7] = {r.fields.velocity,  r.fields.omega2, r.fields.tau,    r.fields.eddy,
                  r.particles.omega2, r.particles.tau, r.particles.eddy};
  MPI_Bcast(flags, 7, MPI_INT, 0, comm);
  r.fields.velocity = flags[0] != 0;
  r.fields.omega2 = flags[1] != 0;
  r.fields.tau = flags[2] != 0;
  r.fields.eddy = flags[3] != 0;
  r.particles.omega2 = flags[4] != 0;
  r.particles.tau = flags[5] != 0;
  r.particles.eddy = flags[6] != 0;
  MPI_Bcast(&r.particles.time, 1, MPI_DOUBLE, 0, comm);
  unsigned long long step = r.particles.step;
  MPI_Bcast(&step, 1, MPI_UNSIGNED_LONG_LONG, 0, comm);
  r.particles.step = step;
  broadcast_string(comm, r.particles.path);
  broadcast_string(comm, r.particles.metadata.scene_json);
  broadcast_string(comm, r.particles.metadata.code_version);
  // The 3D particle view's points.
  unsigned long long view[2] = {r.view.max_points, static_cast<unsigned long long>(r.view.field)};
  MPI_Bcast(view, 2, MPI_UNSIGNED_LONG_LONG, 0, comm);
  r.view.max_points = view[0];
  r.view.field = static_cast<analysis::SliceField>(view[1]);
  return r;
}

/// A checkpoint's file and metadata, from rank 0 to every rank (the gzip level travels in the
/// command header).
void broadcast_checkpoint(MPI_Comm comm, std::string& path, io::CheckpointMetadata& metadata) {
  broadcast_string(comm, path);
  broadcast_string(comm, metadata.scene_json);
  broadcast_string(comm, metadata.code_version);
  broadcast_string(comm, metadata.packing);
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

/// Every rank: the solver of `scene_json` over the ranks of `comm`, each receiving its share of
/// `whole` (read on rank 0 only), or of the checkpoint `file`, or making it (`setup`); to
/// continue, `whole` is this rank's own state.
std::unique_ptr<Member> make_member(MPI_Comm comm, const std::string& scene_json,
                                    sim::SolverState whole, Start start,
                                    const std::string& file = {}, SetUp* setup = nullptr) {
  const bool restore = start != Start::Fresh && start != Start::SetUp;
  auto m = std::make_unique<Member>();
  const sim::Scene scene = scene::parse_scene(nlohmann::json::parse(scene_json));
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

/// The distributed solver as rank 0's Run sees it.
class DistributedSimulation final : public sim::Simulation,
                                    public analysis::DistributedProducts,
                                    public io::DistributedCheckpoints {
 public:
  DistributedSimulation(MPI_Comm comm, std::unique_ptr<Member> member)
      : comm_(comm), m_(std::move(member)) {}

  void step(double max_dt) override {
    send_command(comm_, Command::Step, max_dt);
    m_->local->step(max_dt);
  }
  double time() const override { return m_->local->time(); }
  std::uint64_t step_count() const override { return m_->local->step_count(); }
  // Time step, diagnostics and maxima are global on every rank already.
  const sim::StepDiagnostics& diagnostics() const override { return m_->local->diagnostics(); }
  const sim::SolverConfig& config() const override { return m_->config; }
  double stable_time_step() const override { return m_->local->stable_time_step(); }
  /// Summed by every rank over its owned particles (the scene travels with the command).
  std::vector<double> case_diagnostics(const sim::Scene& scene) const override {
    send_command(comm_, Command::CaseDiagnostics);
    std::string json = scene::scene_to_json(scene).dump();
    broadcast_string(comm_, json);
    return m_->local->case_diagnostics(scene);
  }

  /// Every rank grids its own particles and a slab of the transform (par/spectrum.hpp).
  analysis::EnergySpectrum velocity_spectrum(int points_per_side) const override {
    send_command(comm_, Command::Spectrum, points_per_side);
    return m_->velocity_spectrum(points_per_side);
  }

  /// Every rank computes them for its own particles and slice nodes
  /// (par/particle_products.hpp).
  analysis::RanksProducts particle_products(const analysis::RanksRequest& request) const override {
    send_command(comm_, Command::ParticleProducts);
    return m_->particle_products(broadcast_request(comm_, request));
  }

  /// Every rank writes its block of the particles in id order into the one file; rank 0 then
  /// writes the XDMF side file.
  void write_checkpoint(const std::filesystem::path& path, const io::CheckpointMetadata& metadata,
                        const io::CheckpointWriteOptions& options) const override {
    send_command(comm_, Command::WriteCheckpoint, options.gzip_level);
    std::string file = path.string();
    io::CheckpointMetadata sent = metadata;
    broadcast_checkpoint(comm_, file, sent);
    io::write_checkpoint_xdmf(path, m_->write_checkpoint(file, sent, options.gzip_level));
  }

  const sim::ParticleArrays& particles() const override { return gathered().particles; }
  std::size_t owned_count() const override { return particles().size(); }
  sim::SolverState state() const override { return gathered(); }
  /// Rank 0's own part of the state (its owned particles), for a change on the ranks.
  sim::SolverState local_state() const { return m_->local->state(); }

  /// A list over the gathered particles (for the analysis), built once per step asked for.
  std::shared_ptr<const sim::NeighbourList> neighbour_list() const override {
    return view_.neighbour_list(step_count(), particles());
  }

 private:
  const sim::SolverState& gathered() const {
    return view_.state(step_count(), [this] {
      send_command(comm_, Command::Gather);
      return gather_state(*m_->decomposition, m_->local->state(), 0);
    });
  }

  MPI_Comm comm_;
  std::unique_ptr<Member> m_;
  sim::StateView view_{m_->config};
};

}  // namespace

Driver::Driver(MPI_Comm comm) : comm_(comm) {
  int rank = 0;
  MPI_Comm_rank(comm, &rank);
  if (rank != 0) throw std::logic_error("par::Driver belongs on rank 0");
}

Driver::~Driver() {
  send_command(comm_, Command::Finish);
}

sim::SolverFactories Driver::factories() {
  return {[this](const sim::Scene& scene, sim::ParticleArrays all) {
            return make(scene, std::move(all));
          },
          [this](const sim::Scene& scene, sim::SolverState whole) {
            return restore(scene, std::move(whole));
          },
          [this](const sim::Scene& scene, const std::filesystem::path& path) {
            return restore_file(scene, path);
          },
          [this](const sim::Simulation& current, const sim::Scene& scene) {
            return change(current, scene);
          },
          [this](const sim::Scene& scene, const sim::SetupOptions& options,
                 sim::PackingReport& report) { return set_up(scene, options, report); }};
}

int Driver::ranks() const {
  int size = 1;
  MPI_Comm_size(comm_, &size);
  return size;
}

std::unique_ptr<sim::Simulation> Driver::make(const sim::Scene& scene, sim::ParticleArrays all) {
  send_command(comm_, Command::Make);
  std::string json = scene::scene_to_json(scene).dump();
  broadcast_string(comm_, json);
  sim::SolverState whole;
  whole.particles = std::move(all);
  return std::make_unique<DistributedSimulation>(
      comm_, make_member(comm_, json, std::move(whole), Start::Fresh));
}

std::unique_ptr<sim::Simulation> Driver::set_up(const sim::Scene& scene,
                                                const sim::SetupOptions& options,
                                                sim::PackingReport& report) {
  send_command(comm_, Command::SetUp);
  std::string json = scene::scene_to_json(scene).dump();
  broadcast_string(comm_, json);
  std::string cache = options.packing_cache_dir.string();
  broadcast_string(comm_, cache);
  SetUp setup{options, {}};
  auto member = make_member(comm_, json, sim::SolverState{}, Start::SetUp, {}, &setup);
  report = setup.report;
  return std::make_unique<DistributedSimulation>(comm_, std::move(member));
}

std::unique_ptr<sim::Simulation> Driver::restore(const sim::Scene& scene, sim::SolverState whole) {
  send_command(comm_, Command::Restore);
  std::string json = scene::scene_to_json(scene).dump();
  broadcast_string(comm_, json);
  return std::make_unique<DistributedSimulation>(
      comm_, make_member(comm_, json, std::move(whole), Start::Restore));
}

std::unique_ptr<sim::Simulation> Driver::change(const sim::Simulation& current,
                                                const sim::Scene& scene) {
  const auto* mine = dynamic_cast<const DistributedSimulation*>(&current);
  if (!mine) throw std::invalid_argument("par::Driver::change: not a solver of this driver");
  send_command(comm_, Command::Change);
  std::string json = scene::scene_to_json(scene).dump();
  broadcast_string(comm_, json);
  return std::make_unique<DistributedSimulation>(
      comm_, make_member(comm_, json, mine->local_state(), Start::Continue));
}

std::unique_ptr<sim::Simulation> Driver::restore_file(const sim::Scene& scene,
                                                      const std::filesystem::path& path) {
  send_command(comm_, Command::RestoreFile);
  std::string json = scene::scene_to_json(scene).dump();
  broadcast_string(comm_, json);
  std::string file = path.string();
  broadcast_string(comm_, file);
  return std::make_unique<DistributedSimulation>(
      comm_, make_member(comm_, json, sim::SolverState{}, Start::RestoreFile, file));
}

void serve_commands(MPI_Comm comm) {
  std::unique_ptr<Member> member;
  for (;;) {
    double header[2] = {0.0, 0.0};
    broadcast_header(comm, header);
    const auto command = static_cast<Command>(static_cast<int>(header[0]));
    try {
      switch (command) {
        case Command::Finish:
          return;
        case Command::Make:
        case Command::Restore:
        case Command::RestoreFile:
        case Command::Change: {
          std::string json, file;
          broadcast_string(comm, json);
          if (command == Command::RestoreFile) broadcast_string(comm, file);
          const Start start = command == Command::Make      ? Start::Fresh
                              : command == Command::Restore ? Start::Restore
                              : command == Command::Change  ? Start::Continue
                                                            : Start::RestoreFile;
          if (start == Start::Continue && !member)
            throw std::logic_error("a change before the solver was made");
          // The new solver first, then the old one goes: the order rank 0's Run follows.
          auto fresh = make_member(
              comm, json, start == Start::Continue ? member->local->state() : sim::SolverState{},
              start, file);
          member = std::move(fresh);
          break;
        }
        case Command::SetUp: {
          std::string json, cache;
          broadcast_string(comm, json);
          broadcast_string(comm, cache);
          SetUp setup;
          setup.options.packing_cache_dir = cache;
          auto fresh = make_member(comm, json, sim::SolverState{}, Start::SetUp, {}, &setup);
          member = std::move(fresh);
          break;
        }
        case Command::Step:
          if (member) member->local->step(header[1]);
          break;
        case Command::Gather:
          if (member) gather_state(*member->decomposition, member->local->state(), 0);
          break;
        case Command::Spectrum:
          if (member) member->velocity_spectrum(static_cast<int>(header[1]));
          break;
        case Command::ParticleProducts: {
          const analysis::RanksRequest request = broadcast_request(comm, {});
          if (member) member->particle_products(request);
          break;
        }
        case Command::WriteCheckpoint: {
          std::string path;
          io::CheckpointMetadata metadata;
          broadcast_checkpoint(comm, path, metadata);
          if (member) member->write_checkpoint(path, metadata, static_cast<int>(header[1]));
          break;
        }
        case Command::CaseDiagnostics: {
          std::string json;
          broadcast_string(comm, json);
          if (member)
            member->local->case_diagnostics(scene::parse_scene(nlohmann::json::parse(json)));
          break;
        }
      }
    } catch (const std::exception&) {
      // The same error stopped rank 0's command (every check is collective); rank 0 reports it.
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
