// An immutable copy of the particle state handed from the solver to analysis (SPEC §5 inputs).
#pragma once

#include <array>
#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

#include "sim/kernels.hpp"
#include "sim/neighbour_search.hpp"
#include "sim/particles.hpp"
#include "sim/physics.hpp"

namespace sphles::sim {
class Simulation;
}

namespace sphles::analysis {

struct Snapshot {
  double time = 0.0;
  std::uint64_t step = 0;
  sim::PeriodicBox box;
  sim::KernelType kernel = sim::KernelType::WendlandC4;
  double support_radius = 0.0;    // H [m]
  double particle_spacing = 0.0;  // Δl [m]
  sim::FluidParameters fluid;
  double kinetic_energy = 0.0;  // e_v (5.3) from the solver's diagnostics
  /// ε = -de_v/dt (5.4) of the run's time series at its last row at or before `time` (the
  /// trailing-window slope of DissipationEstimator); NaN when unknown (fewer than two rows).
  double energy_dissipation = std::numeric_limits<double>::quiet_NaN();
  /// Positions, velocities, masses, densities (volume, pressure and ids as well) at `time`.
  sim::ParticleArrays particles;
  /// The solver's Verlet list for these positions (covers the kernel support), or null; lets
  /// τ_SFS skip its own neighbour search.
  std::shared_ptr<const sim::NeighbourList> neighbours;

  int dimension() const { return box.dimension; }
  std::size_t size() const { return particles.size(); }
};

using SnapshotPtr = std::shared_ptr<const Snapshot>;

/// Copies what analysis needs out of a running simulation; `energy_dissipation` is the run's
/// current -de_v/dt (the simulation does not keep a history).
SnapshotPtr make_snapshot(const sim::Simulation& simulation,
                          double energy_dissipation = std::numeric_limits<double>::quiet_NaN());

}  // namespace sphles::analysis
