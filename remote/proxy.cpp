// SPDX-License-Identifier: GPL-3.0-or-later
#include "remote/proxy.hpp"

#include <stdexcept>
#include <string>
#include <utility>

#include "remote/state_view.hpp"
#include "scene/document.hpp"
#include "sim/initial_conditions.hpp"

namespace sphles::remote {

Transport::~Transport() = default;

void Transport::require_current(std::uint64_t generation) const {
  if (generation != generation_)
    throw std::logic_error("a solver elsewhere was used after a newer one was made");
}

namespace {

/// The reply `transport` gives to `request`, as the request's reply type.
template <class R>
typename R::Reply ask(Transport& transport, R request) {
  Reply reply = transport.call(std::move(request));
  auto* typed = std::get_if<typename R::Reply>(&reply);
  if (!typed) throw ProtocolError(std::string("an unexpected reply to ") + R::what);
  return std::move(*typed);
}

std::string json_of(const sim::Scene& scene) {
  return scene::scene_to_json(scene).dump();
}

/// The solver across a transport.
class RemoteSimulation final : public sim::Simulation,
                               public analysis::DistributedProducts,
                               public io::DistributedCheckpoints {
 public:
  RemoteSimulation(std::shared_ptr<Transport> transport, sim::SolverConfig config,
                   SolverStatus status)
      : transport_(std::move(transport)),
        generation_(transport_->next_generation()),
        config_(std::move(config)),
        status_(std::move(status)) {}

  void step(double max_dt) override { status_ = ask(Step{max_dt}); }
  double time() const override { return status_.time; }
  std::uint64_t step_count() const override { return status_.step; }
  const sim::StepDiagnostics& diagnostics() const override { return status_.diagnostics; }
  const sim::SolverConfig& config() const override { return config_; }
  double stable_time_step() const override { return status_.stable_time_step; }
  std::vector<double> case_diagnostics(const sim::Scene& scene) const override {
    return ask(CaseDiagnostics{json_of(scene)});
  }

  /// Computed where the particles live; only the spectrum crosses.
  analysis::EnergySpectrum velocity_spectrum(int points_per_side) const override {
    return ask(Spectrum{static_cast<std::uint64_t>(points_per_side)});
  }

  analysis::RanksProducts particle_products(const analysis::RanksRequest& request) const override {
    analysis::RanksProducts result = ask(ParticleProducts{request});
    if (!(result.request == request)) throw ProtocolError("the solver answered another request");
    return result;
  }

  /// Written where the particles live, into `path` on the file system both sides share; no
  /// state crosses.
  void write_checkpoint(const std::filesystem::path& path, const io::CheckpointMetadata& metadata,
                        const io::CheckpointWriteOptions& options) const override {
    ask(WriteCheckpoint{path.string(), metadata, static_cast<std::uint64_t>(options.gzip_level)});
  }

  const sim::ParticleArrays& particles() const override { return whole().particles; }
  std::size_t owned_count() const override { return particles().size(); }
  sim::SolverState state() const override { return whole(); }
  std::shared_ptr<const sim::NeighbourList> neighbour_list() const override {
    return view_.neighbour_list(step_count(), particles());
  }

  const Transport* transport() const { return transport_.get(); }

 private:
  template <class R>
  typename R::Reply ask(R request) const {
    transport_->require_current(generation_);
    return remote::ask(*transport_, std::move(request));
  }

  /// Every particle, fetched once per step asked for.
  const sim::SolverState& whole() const {
    return view_.state(step_count(), [this] { return ask(State{}); });
  }

  std::shared_ptr<Transport> transport_;
  std::uint64_t generation_;
  sim::SolverConfig config_;
  SolverStatus status_;
  StateView view_{config_};
};

/// A solver made by `request` across `transport`: the generation is taken once the solver's
/// side has made it, so a failed request leaves the current solver in use.
template <class R>
std::unique_ptr<sim::Simulation> made(std::shared_ptr<Transport> transport, const sim::Scene& scene,
                                      R request, sim::PackingReport* report = nullptr) {
  auto reply = ask(*transport, std::move(request));
  SolverStatus status;
  if constexpr (std::is_same_v<typename R::Reply, SetUpStatus>) {
    status = reply.status;
    *report = reply.packing;
  } else {
    status = reply;
  }
  return std::make_unique<RemoteSimulation>(std::move(transport), sim::make_solver_config(scene),
                                            std::move(status));
}

}  // namespace

sim::SolverFactories remote_solvers(std::function<std::shared_ptr<Transport>()> transport) {
  sim::SolverFactories solvers;
  solvers.make = [transport](const sim::Scene& scene, sim::ParticleArrays particles) {
    return made(transport(), scene, Make{json_of(scene), std::move(particles)});
  };
  solvers.restore = [transport](const sim::Scene& scene, sim::SolverState state) {
    return made(transport(), scene, Restore{json_of(scene), std::move(state)});
  };
  // Read where the particles will live, each process its part: the file must be at the same
  // path there (this node or a shared file system).
  solvers.restore_file = [transport](const sim::Scene& scene, const std::filesystem::path& file) {
    return made(transport(), scene, RestoreFile{json_of(scene), file.string()});
  };
  solvers.change = [transport](const sim::Simulation& current, const sim::Scene& scene) {
    const auto* remote = dynamic_cast<const RemoteSimulation*>(&current);
    std::shared_ptr<Transport> t = transport();
    if (!remote || remote->transport() != t.get())
      throw std::invalid_argument("a live change of a solver these factories did not make");
    return made(std::move(t), scene, Change{json_of(scene)});
  };
  // Made, packed and set up where the particles will live; the packing cache directory must be
  // the same path there (as restore_file's file).
  solvers.set_up = [transport](const sim::Scene& scene, const sim::SetupOptions& options,
                               sim::PackingReport& report) {
    return made(transport(), scene,
                SetUp{json_of(scene), options.packing_cache_dir.string(), options.cancelled},
                &report);
  };
  return solvers;
}

}  // namespace sphles::remote
