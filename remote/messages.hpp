// SPDX-License-Identifier: GPL-3.0-or-later
// What one side of a run asks of a solver that lives elsewhere, and what it answers: the
// vocabulary every transport carries (par/driver.hpp: rank 0 to the other MPI ranks;
// launch/job.hpp: the service to the MPI job that holds a run's solver). A request is one struct;
// its Reply names the answer's type, `what` says in words what it does (for a failure's message)
// and fields() lists what travels, in order (remote/codec.hpp encodes it from that).
//
// A new capability of a solver elsewhere is one struct here (and its line in Request), its
// handling in remote/endpoint.cpp and the proxy's method in remote/proxy.cpp.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <tuple>
#include <variant>
#include <vector>

#include "analysis/snapshot.hpp"
#include "analysis/spectrum.hpp"
#include "io/checkpoint_data.hpp"
#include "remote/codec.hpp"
#include "sim/packing.hpp"
#include "sim/solver.hpp"

namespace sphles::remote {

/// The status of a new run's solver and its packing's report.
struct SetUpStatus {
  SolverStatus status;
  sim::PackingReport packing;
  template <class Self>
  static auto fields(Self& s) {
    return std::tie(s.status, s.packing);
  }
};

// Every scene travels as its JSON text (scene::scene_to_json) and is parsed where the solver is
// made, so that every process of a distributed solver reads the same bits.

/// A new solver for `scene` starting from all its particles.
struct Make {
  using Reply = SolverStatus;
  static constexpr const char* what = "setting up the solver";
  std::string scene;
  sim::ParticleArrays particles;
  template <class Self>
  static auto fields(Self& s) {
    return std::tie(s.scene, s.particles);
  }
};

/// A new run whose particles the solver's side makes and packs (sim::SolverFactories::set_up).
struct SetUp {
  using Reply = SetUpStatus;
  static constexpr const char* what = "setting up the run on the ranks";
  std::string scene;
  std::string packing_cache_dir;
  /// Polled by the side that waits for the set-up; does not travel.
  std::function<bool()> cancelled;
  template <class Self>
  static auto fields(Self& s) {
    return std::tie(s.scene, s.packing_cache_dir);
  }
};

/// A solver continuing a saved state of all particles.
struct Restore {
  using Reply = SolverStatus;
  static constexpr const char* what = "restoring the solver";
  std::string scene;
  sim::SolverState state;
  template <class Self>
  static auto fields(Self& s) {
    return std::tie(s.scene, s.state);
  }
};

/// A solver continuing the checkpoint `file`, read on the solver's side (the same path there).
struct RestoreFile {
  using Reply = SolverStatus;
  static constexpr const char* what = "restoring the solver from its checkpoint";
  std::string scene;
  std::string file;
  template <class Self>
  static auto fields(Self& s) {
    return std::tie(s.scene, s.file);
  }
};

/// A live change: a solver for `scene` continuing the current one where its particles are.
struct Change {
  using Reply = SolverStatus;
  static constexpr const char* what = "changing the solver";
  std::string scene;
  template <class Self>
  static auto fields(Self& s) {
    return std::tie(s.scene);
  }
};

struct Step {
  using Reply = SolverStatus;
  static constexpr const char* what = "a step";
  double max_dt = 0.0;
  template <class Self>
  static auto fields(Self& s) {
    return std::tie(s.max_dt);
  }
};

/// The complete state (every particle, in the solver's order).
struct State {
  using Reply = sim::SolverState;
  static constexpr const char* what = "fetching the state";
  template <class Self>
  static auto fields(Self&) {
    return std::tie();
  }
};

/// sim::Simulation::case_diagnostics for `scene`.
struct CaseDiagnostics {
  using Reply = std::vector<double>;
  static constexpr const char* what = "case diagnostics";
  std::string scene;
  template <class Self>
  static auto fields(Self& s) {
    return std::tie(s.scene);
  }
};

/// analysis::DistributedProducts::velocity_spectrum.
struct Spectrum {
  using Reply = analysis::EnergySpectrum;
  static constexpr const char* what = "the spectrum";
  std::uint64_t points_per_side = 0;
  template <class Self>
  static auto fields(Self& s) {
    return std::tie(s.points_per_side);
  }
};

/// analysis::DistributedProducts::particle_products.
struct ParticleProducts {
  using Reply = analysis::RanksProducts;
  static constexpr const char* what = "the particle products";
  analysis::RanksRequest request;
  template <class Self>
  static auto fields(Self& s) {
    return std::tie(s.request);
  }
};

/// io::DistributedCheckpoints::write_checkpoint into `path` (the same path on the solver's
/// side).
struct WriteCheckpoint {
  using Reply = std::monostate;
  static constexpr const char* what = "writing a checkpoint";
  std::string path;
  io::CheckpointMetadata metadata;
  std::uint64_t gzip_level = 0;
  template <class Self>
  static auto fields(Self& s) {
    return std::tie(s.path, s.metadata, s.gzip_level);
  }
};

/// The solver's side ends its service (no reply).
struct Finish {
  using Reply = std::monostate;
  static constexpr const char* what = "finishing";
  template <class Self>
  static auto fields(Self&) {
    return std::tie();
  }
};

using Request = std::variant<Finish, Make, SetUp, Restore, RestoreFile, Change, Step, State,
                             CaseDiagnostics, Spectrum, ParticleProducts, WriteCheckpoint>;
using Reply = std::variant<std::monostate, SolverStatus, SetUpStatus, sim::SolverState,
                           std::vector<double>, analysis::EnergySpectrum, analysis::RanksProducts>;

/// What `request` does, in words.
inline const char* what(const Request& request) {
  return std::visit([](const auto& r) { return r.what; }, request);
}

}  // namespace sphles::remote
