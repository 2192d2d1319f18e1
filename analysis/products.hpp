// SPDX-License-Identifier: GPL-3.0-or-later
// Analysis products: plain data with a time stamp, computed from one snapshot and consumed by
// writers, the renderer and the server. Only requested products are computed; intermediates that
// several products share (gridded velocity, vorticity, τ_SFS) are computed once per snapshot.
#pragma once

#include <limits>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "analysis/config.hpp"
#include "analysis/snapshot.hpp"
#include "analysis/spectrum.hpp"
#include "analysis/statistics.hpp"

namespace sphles::analysis {

struct SpectrumProduct {
  EnergySpectrum spectrum;
  double kinetic_energy_grid = 0.0;    // ½⟨|u'|²⟩ on the grid = Σ E Δk
  double dissipation = 0.0;            // 2ν Σ k² E Δk (4.6) over all shells [m²/s³]
  double dissipation_resolved = 0.0;   // the same over k <= k_res = π/Δl [m²/s³]
  double kernel_wavenumber = 0.0;      // k_kern = 2π / D_K [1/m]
  double resolution_wavenumber = 0.0;  // k_res = π / Δl [1/m]
  double length_scale = 0.0;           // L_c for normalisation [m]
};

struct VorticityProduct {
  VorticityEstimate estimate = VorticityEstimate::Particle;  // how ω was computed
  double mean_vorticity_squared = 0.0;  // ⟨ω²⟩ over the grid nodes [1/s²]
  double dissipation = 0.0;             // ε_v = ν ⟨ω²⟩ (4.6) [m²/s³]
};

/// A 2D array of one field on a grid plane. values[iu + width * iv], where u and v are the two
/// box axes in the plane in increasing order (3D, normal x: u = y, v = z; 2D: u = x, v = y).
struct SliceProduct {
  SliceField field = SliceField::VorticitySquared;
  int normal_axis = 0;    // 0, 1, 2; 2 for a 2D run
  double position = 0.0;  // of the grid plane [m]
  int axis_u = 1, axis_v = 2;
  int width = 0, height = 0;
  double spacing = 0.0;  // grid spacing [m]; node (iu, iv) sits at (iu h, iv h)
  std::vector<double> values;
  std::string units;  // "1/s^2" or "Pa"
};

/// The whole analysis grid (product "fields"): node (i, j, k) at (i h, j h, k h), index
/// i + M (j + M k) (VTK's point order).
struct GridScalarField {
  SliceField field = SliceField::VorticitySquared;
  std::string units;
  std::vector<double> values;
};
struct GridFieldsProduct {
  Grid grid;
  std::optional<VectorField> velocity;  // the gridded velocity with its mean [m/s]
  std::vector<GridScalarField> scalars;
};

/// Per-particle data for an HDF5/XDMF snapshot: the snapshot itself plus requested fields.
struct ParticleFieldProduct {
  SliceField field = SliceField::VorticitySquared;
  std::string units;
  std::vector<double> values;  // in the snapshot's particle order
};

struct ParticlesProduct {
  SnapshotPtr snapshot;
  std::vector<ParticleFieldProduct> fields;
  /// Set when the ranks of a distributed run wrote the snapshot file themselves
  /// (RanksProducts::particles): its path and particle count; `fields` then name the fields
  /// it holds, without values, and the snapshot holds no particles.
  std::string file;
  std::uint64_t count = 0;
  /// The 3D particle view's points the snapshot asked for (Snapshot::view), from the ranks or
  /// selected here; none when not asked for or when the run lacks the field (ν_t).
  std::optional<ViewPoints> view;
};

struct AnalysisFrame {
  double time = 0.0;
  std::uint64_t step = 0;
  int dimension = 3;
  double kinetic_energy = 0.0;  // e_v from the particles (5.3)
  /// ε = -de_v/dt (5.4) from the run's time series (Snapshot::energy_dissipation); NaN when
  /// unknown. The other two dissipation estimates of SPEC §5 are vorticity->dissipation (ν⟨ω²⟩)
  /// and spectrum->dissipation_resolved (2ν Σ_{k <= k_res} k² E Δk).
  double energy_dissipation = std::numeric_limits<double>::quiet_NaN();
  /// ½⟨|u'|²⟩ of the gridded, mean-removed velocity (products "energy" and "spectrum").
  std::optional<double> grid_kinetic_energy;
  std::optional<SpectrumProduct> spectrum;
  std::optional<VorticityProduct> vorticity;
  std::vector<SliceProduct> slices;
  std::optional<SubfilterStatisticsProduct> subfilter;
  std::optional<ParticlesProduct> particles;
  std::optional<GridFieldsProduct> fields;
  /// Wall time per stage, in the order computed: ("grid", s), ("spectrum", s), ...
  std::vector<std::pair<std::string, double>> timings;
  double total_seconds = 0.0;
  std::uint64_t dropped_snapshots = 0;  // dropped by the pipeline before this frame
};

/// Computes the products the configuration asks for. Pure: depends on its inputs only.
AnalysisFrame analyse(const Snapshot& snapshot, const AnalysisConfig& config);
/// The same, keeping a reference to the snapshot for the "particles" product (the overload
/// above refers to its argument without owning it: the frame must not outlive it).
AnalysisFrame analyse(const SnapshotPtr& snapshot, const AnalysisConfig& config);

/// The grid node of every value of a slice (SliceProduct::values' order, u fastest): the plane
/// of `config` nearest its position (3D), the whole grid (2D).
std::vector<std::size_t> slice_nodes(const Grid& grid, const SliceConfig& config);

}  // namespace sphles::analysis
