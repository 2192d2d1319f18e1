// SPDX-License-Identifier: GPL-3.0-or-later
// Particle packing (Colagrossi et al. 2012) and its on-disk cache.
//
// Particles on a lattice, optionally displaced at random by `perturbation` Δl (a counter-based
// draw per particle id: the same displacement whichever process makes the particle), are relaxed by
// a damped fictitious dynamics driven by a constant background pressure p_b:
//   dv_i/dt = -(2 p_b / ρ_i) Σ_j ∇W_ij V_j - β v_i        (the zero-order term (5.7))
// until the residual max_i |Σ_j ∇W_ij V_j| Δl drops below the tolerance. The packed arrangement
// has vanishing discrete background-pressure force, so a flow started on it carries no initial
// particle noise. Units are fictitious (p_b/ρ = 1 m²/s², dt = 0.2 Δl / 1 m/s); only positions
// are kept. The relaxation runs on one process or on the particles of many (sim::Exchange): the
// neighbours' sums come in id order within a cell, so both give the same bits.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>

#include "sim/exchange.hpp"
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

/// Which lattice points a process makes: keep(axis, x) for the coordinate x of a lattice line
/// along `axis` (a process' sub-box); empty keeps every point.
using LatticeFilter = std::function<bool(int axis, double x)>;

/// Particles on a regular lattice of `per_side` points per direction, spacing L/per_side, with
/// the first point at Δl/2 (velocities zero, masses zero), in id order; a point's id is its
/// lattice index ix + n (iy + n iz) whichever points `keep` selects.
ParticleArrays make_lattice(const PeriodicBox& box, int per_side, const LatticeFilter& keep = {});

/// Displaces every particle by perturbation Δl u with u uniform in [-1, 1]^n, drawn from a
/// counter-based generator (Philox4x64, Salmon et al. 2011, Random123) keyed by the seed and
/// counted by the particle id: a function of (seed, id) alone. Positions end wrapped into the box.
void perturb_positions(const PackingConfig& config, const PeriodicBox& box, double spacing,
                       ParticleArrays& particles);

/// Perturbs and relaxes the positions in place. `cancelled` (may be empty) is polled once per
/// iteration; throws SetupCancelled when it returns true. The particles end in id order with
/// zero velocities.
PackingReport relax_particles(const PackingConfig& config, const PeriodicBox& box,
                              KernelType kernel, double support_radius, double spacing,
                              ParticleArrays& particles,
                              const std::function<bool()>& cancelled = {});

/// The same for the particles of one process of many (`exchange`; a lattice share, each particle
/// within a list radius of its owner's part of the box): relaxed with their neighbours on
/// the other processes, ending as the particles this process owns at the last list rebuild, in
/// id order. Every process ends with the same report; the positions are bitwise those of the
/// one-process relaxation. Collective; `cancelled` may differ between processes (any one
/// cancels all). Its list radius is packing_list_radius(box, support_radius).
PackingReport relax_particles(const PackingConfig& config, const PeriodicBox& box,
                              KernelType kernel, double support_radius, double spacing,
                              ParticleArrays& particles, Exchange& exchange,
                              const std::function<bool()>& cancelled = {});

/// The neighbour-list radius of the relaxation in `box` (a distributed one needs halos this
/// wide): H (1 + kPackingSkin), less in a box too small for that skin (VerletNeighbourSearch).
double packing_list_radius(const PeriodicBox& box, double support_radius);

/// Residual max_i |Σ_j ∇W_ij V_j| Δl of an arrangement (0 for a perfect lattice).
double packing_residual(const PeriodicBox& box, KernelType kernel, double support_radius,
                        double spacing, const ParticleArrays& particles);

/// Default cache directory: $XDG_CACHE_HOME/sphles/packing, else $HOME/.cache/sphles/packing.
std::filesystem::path default_packing_cache_dir();

/// Where a scene's packing is cached and how the file is laid out, for the one-process reader
/// and writer here and for processes that read or write their blocks of it (par/). The file is
/// `header` (magic, key, particle count), then x of every particle in id order, then y (then z),
/// 8 bytes each, then the checksum: key_hash plus the checksum() of every axis' values (a sum
/// modulo 2^64, so blocks are checked separately and their sums added).
struct PackingCacheFile {
  std::filesystem::path path;  // empty: the scene does not use the cache
  std::string header;
  std::uint64_t count = 0;
  int dimension = 3;
  std::uint64_t key_hash = 0;

  std::uint64_t offset(int axis, std::uint64_t id) const {
    return header.size() + (static_cast<std::uint64_t>(axis) * count + id) * sizeof(double);
  }
  std::uint64_t checksum_offset() const { return offset(dimension, 0); }
  std::uint64_t file_size() const { return checksum_offset() + sizeof(std::uint64_t); }
  /// The checksum's part for the values of ids [first, first + values.size()) along `axis`.
  std::uint64_t checksum(int axis, std::uint64_t first, std::span<const double> values) const;
};

/// The cache file of a scene's packing (path empty when packing or its cache is off).
PackingCacheFile packing_cache_file(const Scene& scene, const SetupOptions& options);

/// Positions of ids [first, first + count) read from the cache file `f` (particles with those
/// ids), their part of the checksum and the checksum the file stores; nothing when the file is
/// missing, of another size or header, or short. The file is valid when f.key_hash plus the
/// parts of all blocks equals `stored`.
struct PackingCacheBlock {
  ParticleArrays particles;
  std::uint64_t checksum_part = 0;
  std::uint64_t stored = 0;
};
std::optional<PackingCacheBlock> read_packing_cache_block(const PackingCacheFile& f,
                                                          std::uint64_t first, std::uint64_t count);

/// Lattice + relaxation for a scene, reusing a cached result keyed by dimension, N, kernel,
/// D_K/Δl and the packing parameters, in options.packing_cache_dir. Cache files are written
/// atomically (temporary + rename) and carry a checksum; a damaged or mismatching file is ignored
/// and rewritten. Throws SetupCancelled when options.cancelled says so.
ParticleArrays packed_positions(const Scene& scene, PackingReport* report = nullptr,
                                const SetupOptions& options = {});

}  // namespace sphles::sim
