// SPDX-License-Identifier: GPL-3.0-or-later
// The "analysis" section of a scene: which products a run needs and how often (docs/analysis.md).
#pragma once

#include <nlohmann/json.hpp>
#include <set>
#include <string>

#include "scene/document.hpp"
#include "sim/name_table.hpp"
#include "sim/scene.hpp"

namespace sphles::analysis {

enum class Product { Energy, Spectrum, Vorticity, Slices, SubfilterStatistics, Particles, Fields };

/// Scene names: "energy", "spectrum", "vorticity", "slices", "sfs_stats", "particles",
/// "fields" (the whole analysis grid as VTK image data).
std::string_view product_name(Product product);
inline constexpr sim::NameTable<Product, 7> kProductNames{{{
    {Product::Energy, "energy"},
    {Product::Spectrum, "spectrum"},
    {Product::Vorticity, "vorticity"},
    {Product::Slices, "slices"},
    {Product::SubfilterStatistics, "sfs_stats"},
    {Product::Particles, "particles"},
    {Product::Fields, "fields"},
}}};

enum class SliceField { VorticitySquared, SubfilterStressNorm, EddyViscosity };
/// "omega2", "tau_sfs", "nu_t" (ν_t of an explicit sub-filter model).
std::string_view slice_field_name(SliceField field);
inline constexpr sim::NameTable<SliceField, 3> kSliceFieldNames{{{
    {SliceField::VorticitySquared, "omega2"},
    {SliceField::SubfilterStressNorm, "tau_sfs"},
    {SliceField::EddyViscosity, "nu_t"},
}}};
/// The field's SI units: "1/s^2", "Pa", "m^2/s".
std::string_view slice_field_units(SliceField field);

/// How the velocity reaches the grid (products "energy" and "spectrum", and the grid vorticity):
/// "nearest" (SPEC §5, the thesis: every node takes the velocity of the nearest particle) or
/// "shepard" (kernel-weighted average of the particles within H, with the run's kernel).
enum class VelocityGridding { Nearest, Shepard };
/// How ω is estimated (products "vorticity", "slices" ω², "sfs_stats", "particles" ω²):
/// "particle" (the curl of the (A.20) gradient on each particle, the vorticity of the
/// kernel-filtered velocity; on the grid by Shepard interpolation of ω²), "grid" (SPEC §5, the
/// thesis: central differences of the gridded velocity; per particle, the value at its nearest
/// node) or "mls" (the default: the curl of a local cubic least-squares fit to the particle
/// velocities within gridding.fit_radius, which does not attenuate the scales it resolves; on
/// the grid a local quadratic fit of ω, and ⟨ω²⟩ as the volume-weighted mean over the
/// particles; local_fit.hpp).
enum class VorticityEstimate { Particle, Grid, Mls };
std::string_view velocity_gridding_name(VelocityGridding gridding);
std::string_view vorticity_estimate_name(VorticityEstimate estimate);
inline constexpr sim::NameTable<VelocityGridding, 2> kVelocityGriddingNames{{{
    {VelocityGridding::Nearest, "nearest"},
    {VelocityGridding::Shepard, "shepard"},
}}};
inline constexpr sim::NameTable<VorticityEstimate, 3> kVorticityEstimateNames{{{
    {VorticityEstimate::Particle, "particle"},
    {VorticityEstimate::Grid, "grid"},
    {VorticityEstimate::Mls, "mls"},
}}};
/// The slice's normal axis (AnalysisConfig::slice.axis) by name.
inline constexpr sim::NameTable<int, 3> kAxisNames{{{{0, "x"}, {1, "y"}, {2, "z"}}}};

struct GriddingConfig {
  VelocityGridding velocity = VelocityGridding::Nearest;
  VorticityEstimate vorticity = VorticityEstimate::Mls;
  /// R / H of the "mls" estimate's local fits (local_fit.hpp): by default the fits reach as far
  /// as the kernel, so they see the scales the model resolves and not the particle-scale noise
  /// below them (docs/analysis.md).
  double fit_radius = 1.0;
};

struct SliceConfig {
  int axis = 0;  // 0 = x, 1 = y, 2 = z: the slice is normal to this axis (3D)
  double position = 3.14159265358979323846;  // [m], snapped to the nearest grid plane
  std::set<SliceField> fields{SliceField::VorticitySquared, SliceField::SubfilterStressNorm};
};

struct AnalysisConfig {
  double every = 0.0;  // simulated time between snapshots; 0 = no snapshot analysis
  std::set<Product> products;
  SliceConfig slice;
  /// Extra per-particle fields of the "particles" product (HDF5 + XDMF snapshots): any of
  /// omega2, tau_sfs, nu_t.
  std::set<SliceField> particle_fields{SliceField::VorticitySquared,
                                       SliceField::SubfilterStressNorm};
  /// What the "fields" product writes on the whole grid: the gridded velocity (scene name
  /// "velocity") and any of omega2, tau_sfs, nu_t.
  bool grid_velocity = true;
  std::set<SliceField> grid_fields{SliceField::VorticitySquared};
  GriddingConfig gridding;
  int grid_points_per_spacing = 2;  // grid spacing Δl / 2 (SPEC §5)
  int histogram_bins = 50;          // bivariate (τ*, ω²*) histogram, per axis
  int angle_bins = 18;              // polar histogram of γ ∈ [0, π/2]
  double angle_threshold = 0.1;     // τ* above which particles enter the polar histogram
  double dissipation_window = 0.2;  // [s] trailing window of the -de_v/dt least-squares slope
  double spectrum_length_scale = 3.14159265358979323846;  // L_c for the normalised spectrum

  bool wants(Product p) const { return products.contains(p); }
  bool enabled() const { return every > 0.0 && !products.empty(); }
};

/// Parses the "analysis" object (missing: defaults, nothing computed). Throws sim::SceneError
/// naming the field, e.g. "scene: 'analysis.products[1]' must be one of ...".
AnalysisConfig parse_analysis_config(const nlohmann::json* section);
nlohmann::json analysis_config_to_json(const AnalysisConfig& config);

/// A whole scene file but its render and reference sections: the solver's part and when the run
/// writes (scene::parse_scene_and_policy), and the analysis section.
struct RunConfig {
  sim::Scene scene;
  AnalysisConfig analysis;
  scene::RunPolicy policy;  // "output", "checkpoint"
};

RunConfig parse_run_config(const nlohmann::json& document);
nlohmann::json run_config_to_json(const RunConfig& config);

}  // namespace sphles::analysis
