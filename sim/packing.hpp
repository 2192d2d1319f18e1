// Particle packing (Colagrossi et al. 2012) and its on-disk cache.
//
// Particles on a lattice, optionally displaced at random by `perturbation` Δl, are relaxed by a
// damped fictitious dynamics driven by a constant background pressure p_b:
//   dv_i/dt = -(2 p_b / ρ_i) Σ_j ∇W_ij V_j - β v_i        (the zero-order term (5.7))
// until the residual max_i |Σ_j ∇W_ij V_j| Δl drops below the tolerance. The packed arrangement
// has vanishing discrete background-pressure force, so a flow started on it carries no initial
// particle noise. Units are fictitious (p_b/ρ = 1 m²/s², dt = 0.2 Δl / 1 m/s); only positions
// are kept.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <stdexcept>
#include <string>

#include "sim/kernels.hpp"
#include "sim/particles.hpp"
#include "sim/scene.hpp"

namespace sphles::sim {

/// Verlet skin of the packing's neighbour search, as a fraction of H.
inline constexpr double kPackingSkin = 0.1;

struct PackingReport {
  int iterations = 0;
  double initial_residual = 0.0;
  double final_residual = 0.0;
  bool converged = false;
  bool from_cache = false;
  std::string cache_file;  // empty when the cache was not used
};

/// How a scene's initial state is built beyond the scene itself. Both are settings of the program
/// that builds it, never of the scene: a scene sent by a client must not choose where the server
/// writes files.
struct SetupOptions {
  std::filesystem::path packing_cache_dir = {};  // empty: default_packing_cache_dir()
  /// Polled between packing iterations; when it returns true the set-up ends with SetupCancelled
  /// (a stop request or a signal need not wait for a long packing to converge).
  std::function<bool()> cancelled = {};
};

/// The set-up was abandoned because SetupOptions::cancelled said so; nothing was cached.
class SetupCancelled : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Particles on a regular lattice of `per_side` points per direction, spacing L/per_side, with
/// the first point at Δl/2 (velocities zero, masses zero).
ParticleArrays make_lattice(const PeriodicBox& box, int per_side);

/// Perturbs and relaxes the positions in place. `cancelled` (may be empty) is polled once per
/// iteration; throws SetupCancelled when it returns true.
PackingReport relax_particles(const PackingConfig& config, const PeriodicBox& box,
                              KernelType kernel, double support_radius, double spacing,
                              ParticleArrays& particles,
                              const std::function<bool()>& cancelled = {});

/// Residual max_i |Σ_j ∇W_ij V_j| Δl of an arrangement (0 for a perfect lattice).
double packing_residual(const PeriodicBox& box, KernelType kernel, double support_radius,
                        double spacing, const ParticleArrays& particles);

/// Default cache directory: $XDG_CACHE_HOME/sphles/packing, else $HOME/.cache/sphles/packing.
std::filesystem::path default_packing_cache_dir();

/// Lattice + relaxation for a scene, reusing a cached result keyed by dimension, N, kernel,
/// D_K/Δl and the packing parameters, in options.packing_cache_dir. Cache files are written
/// atomically (temporary + rename) and carry a checksum; a damaged or mismatching file is ignored
/// and rewritten. Throws SetupCancelled when options.cancelled says so.
ParticleArrays packed_positions(const Scene& scene, PackingReport* report = nullptr,
                                const SetupOptions& options = {});

}  // namespace sphles::sim
