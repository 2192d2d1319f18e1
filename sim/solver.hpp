// SPDX-License-Identifier: GPL-3.0-or-later
// Run-control interface of the solver and its configuration.
//
// Time integration (documented in docs/numerics.md): kick-drift-kick leapfrog with a predicted
// end-of-step velocity for the velocity-dependent (viscous) force, second order in dt:
//   v^{n+1/2} = v^n + dt/2 a^n,   x^{n+1} = x^n + dt v^{n+1/2},
//   v*        = v^{n+1/2} + dt/2 a^n,   a^{n+1} = a(x^{n+1}, v*, t^{n+1}),
//   v^{n+1}   = v^{n+1/2} + dt/2 a^{n+1}.
// One density pass and one force pass per step. A scheme with transport velocity (scheme.hpp)
// drifts with ṽ = v^{n+1/2} + δv instead, δv formed by the scheme from a field of the last force
// evaluation: the TVF δv = dt/2 ã^n (ã^n its background acceleration, evaluating forces with
// that shift), particle shifting δv = δv^n (the shifting velocity at x^n).
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "sim/exchange.hpp"
#include "sim/health.hpp"
#include "sim/kernels.hpp"
#include "sim/neighbour_search.hpp"
#include "sim/particles.hpp"
#include "sim/physics/thesis_passes.hpp"
#include "sim/scheme.hpp"
#include "sim/subfilter.hpp"
#include "sim/time_step.hpp"

namespace sphles::sim {

struct Scene;  // scene.hpp

/// Adds an external acceleration a_ext (3.25) to every particle; called once per force
/// evaluation, after the pair forces, with the velocity at which forces are evaluated.
using ExternalAcceleration =
    std::function<void(double time, const ParticleArrays& particles, const VelocityView& velocity,
                       std::array<std::vector<double>, 3>& acceleration)>;

struct SolverConfig {
  PeriodicBox box;
  KernelType kernel = KernelType::WendlandC4;
  double support_radius = 0.0;    // H = D_K / 2 [m]
  double particle_spacing = 0.0;  // Δl [m], sets the time-step limits
  FluidParameters fluid;
  TimeStepConfig time_step;
  SchemeConfig scheme;            // SPH scheme (scheme.hpp); the thesis model by default
  SubfilterConfig subfilter;      // explicit sub-filter model (SPEC §4); implicit by default
  double neighbour_skin = 0.15;   // Verlet skin as a fraction of H
  ExternalAcceleration external;  // optional
  BlowUpThresholds blow_up;       // runaway-energy test after every step (health.hpp)
};

/// Per-step health and energy figures (SPEC §5: e_v of (5.3)).
struct StepDiagnostics {
  double time = 0.0;
  std::uint64_t step = 0;
  double dt = 0.0;                     // step just taken (0 before the first)
  double kinetic_energy = 0.0;         // e_v = ½ Σ M v² / Σ M (5.3) [m²/s²]
  double max_density_deviation = 0.0;  // max |ρ_i - ρ_ref| / ρ_ref
  double max_speed = 0.0;              // max |v_i| [m/s]
  double total_mass = 0.0;
  std::array<double, 3> momentum{0.0, 0.0, 0.0};  // Σ M v [kg m/s]
  std::size_t neighbour_builds = 0;
  double mean_neighbours = 0.0;  // mean list length (inside list radius H(1+skin))
};

/// Thrown when the state becomes non-finite; says where.
class SimulationError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Thrown by Simulation::step (and by construction) when the state blows up: a non-finite value
/// or runaway kinetic energy (BlowUpThresholds). The message names the time, step, quantity,
/// value and the first bad particle id; the same facts are available as fields. The solver's
/// state after the throw is not valid: stop, and keep the last checkpoint written before.
class BlowUpError : public SimulationError {
 public:
  BlowUpError(const std::string& message, double time, std::uint64_t step, std::string quantity,
              double value, std::uint64_t particle_id)
      : SimulationError(message),
        time_(time),
        step_(step),
        quantity_(std::move(quantity)),
        value_(value),
        particle_id_(particle_id) {}

  double time() const { return time_; }
  std::uint64_t step() const { return step_; }
  /// "kinetic energy" (runaway or non-finite sum), or the first non-finite particle field such
  /// as "velocity[0]" or "density".
  const std::string& quantity() const { return quantity_; }
  double value() const { return value_; }
  std::uint64_t particle_id() const { return particle_id_; }

 private:
  double time_;
  std::uint64_t step_;
  std::string quantity_;
  double value_;
  std::uint64_t particle_id_;
};

/// Everything a bitwise-exact restart needs: the particle arrays in their current order (with
/// the acceleration a^n the next kick uses), the positions the current Verlet list was built
/// from (rebuilding from them gives the identical list, hence identical summation order), the
/// time, the step and the build counter. A scheme's own fields (SchemeFields: the background
/// acceleration of the TVF, the shifting velocity of particle shifting) are functions of the
/// positions and are recomputed on restore.
struct SolverState {
  ParticleArrays particles;
  std::array<std::vector<double>, 3> list_reference_positions;
  double time = 0.0;
  std::uint64_t step = 0;
  std::uint64_t neighbour_builds = 0;
};

/// The narrow interface the rest of sphles uses to drive a run.
class Simulation {
 public:
  virtual ~Simulation() = default;
  /// Advances one step of size min(limit from TimeStepConfig, max_dt). Throws BlowUpError when
  /// the new state is non-finite or its kinetic energy runs away (SolverConfig::blow_up).
  virtual void step(double max_dt = std::numeric_limits<double>::infinity()) = 0;
  virtual double time() const = 0;
  virtual std::uint64_t step_count() const = 0;
  virtual const StepDiagnostics& diagnostics() const = 0;
  /// The particles this process holds: every particle of a one-process run; in a distributed
  /// run (sim/exchange.hpp) the owned ones at [0, owned_count()), then halo copies.
  virtual const ParticleArrays& particles() const = 0;
  virtual std::size_t owned_count() const = 0;
  virtual const SolverConfig& config() const = 0;
  /// Verlet list of the current state (all pairs closer than the kernel support are in it, with
  /// indices into particles()); shared read-only, never modified after this call.
  virtual std::shared_ptr<const NeighbourList> neighbour_list() const = 0;
  /// A copy of the complete state (for checkpoints).
  virtual SolverState state() const = 0;
  /// The step the limits allow for the current state (before max_dt).
  virtual double stable_time_step() const = 0;
  /// The case's own diagnostics of the current state (case_diagnostics, initial_conditions.hpp)
  /// for `scene`, the scene this solver was made from: summed over every particle of a
  /// distributed run without gathering them, bitwise as one process sums them. Collective.
  virtual std::vector<double> case_diagnostics(const Scene& scene) const = 0;
};

/// Builds a solver for the configured dimension and kernel. `initial` needs positions, velocities
/// and masses; volume, density, pressure and acceleration are computed here. With a distributed
/// `exchange` (par/), this process' share of the particles: each process passes the particles
/// of its part of the box (those at most one part away along each axis migrate to their owner
/// first), and the run's particle states are bitwise those of one process holding them all.
/// Collective then.
std::unique_ptr<Simulation> make_simulation(const SolverConfig& config, ParticleArrays initial,
                                            double start_time = 0.0, std::uint64_t start_step = 0,
                                            std::shared_ptr<Exchange> exchange = nullptr);

/// Continues from a saved state: no force evaluation, no reordering; the next step() is
/// bitwise identical to the step the saving run took next. With a distributed `exchange`,
/// `state` is this process' share (par::share_of) of a state of all particles, written by any
/// number of processes (par::gather_state), and the run continues bitwise as well. Throws
/// std::invalid_argument if the state does not fit the configuration.
std::unique_ptr<Simulation> restore_simulation(const SolverConfig& config, SolverState state,
                                               std::shared_ptr<Exchange> exchange = nullptr);

}  // namespace sphles::sim
