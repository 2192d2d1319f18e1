// SPDX-License-Identifier: GPL-3.0-or-later
// An immutable copy of the particle state handed from the solver to analysis (SPEC §5 inputs).
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "analysis/config.hpp"
#include "analysis/histograms.hpp"
#include "analysis/spectrum.hpp"
#include "io/particle_snapshot.hpp"
#include "sim/kernels.hpp"
#include "sim/neighbour_search.hpp"
#include "sim/particles.hpp"
#include "sim/physics/thesis_passes.hpp"

namespace sphles::sim {
class Simulation;
}

namespace sphles::analysis {

/// The particle snapshot io::write_particle_snapshot would write, written by the ranks at `path`
/// ("" for none), each its block of the particles in id order, with ω² (the "mls" estimate),
/// |τ_SFS| and ν_t (when the run has it) as asked.
struct ParticleFileRequest {
  std::string path;
  bool omega2 = false;
  bool tau = false;
  bool eddy = false;
  double time = 0.0;  // the file's time and step attributes (the snapshot's)
  std::uint64_t step = 0;
  io::SnapshotMetadata metadata;
  bool operator==(const ParticleFileRequest&) const = default;
};

/// Product "fields" (the whole analysis grid) as the ranks compute it: the velocity (with its
/// mean) and |τ_SFS| and ν_t of each node's nearest particle, ω² fitted at each node ("mls").
struct GridFieldsRequest {
  bool velocity = false;
  bool omega2 = false;
  bool tau = false;
  bool eddy = false;  // answered only when the run has an explicit model
  bool any() const { return velocity || omega2 || tau || eddy; }
  bool operator==(const GridFieldsRequest&) const = default;
};

/// The points of the 3D particle view (render.view3d): at most `max_points` particles, those
/// whose id is a multiple of view_stride(N, max_points), with one field's values. 0: no view.
struct ViewPointsRequest {
  std::uint64_t max_points = 0;
  SliceField field = SliceField::VorticitySquared;
  bool operator==(const ViewPointsRequest&) const = default;
};

/// The view's points in id order: positions per axis of the run's dimension and the field's
/// values; every `stride`-th particle by id.
struct ViewPoints {
  SliceField field = SliceField::VorticitySquared;
  std::uint64_t stride = 1;
  std::array<std::vector<double>, 3> position;
  std::vector<double> values;
  std::size_t size() const { return values.size(); }
  bool operator==(const ViewPoints&) const = default;
};

/// The id stride that leaves at most `max_points` of `total` particles (ids 0 … total-1):
/// ceil(total / max_points), at least 1.
std::uint64_t view_stride(std::uint64_t total, std::uint64_t max_points);

/// The indices among the first `count` particles of `p` (in any order) whose id is a multiple
/// of `stride`, in ascending id order.
std::vector<std::size_t> view_point_indices(const sim::ParticleArrays& p, std::size_t count,
                                            std::uint64_t stride);

/// The view points at `chosen` (view_point_indices) with their `values`, in that order.
ViewPoints view_points_at(const sim::ParticleArrays& p, std::span<const std::size_t> chosen,
                          std::span<const double> values, SliceField field, std::uint64_t stride);

/// The view points among the first `count` particles of `p` (in any order) and their
/// `values`: those of view_point_indices, in id order.
ViewPoints select_view_points(const sim::ParticleArrays& p, std::size_t count,
                              std::span<const double> values, SliceField field,
                              std::uint64_t stride);

/// The particle products a distributed solver's ranks compute where the particles live
/// (DistributedProducts::particle_products), as a run's configuration asks for them: the
/// "mls" vorticity (the default estimate, config.hpp), the ω², |τ_SFS| and ν_t slices and the
/// chapter-4 statistics.
struct RanksRequest {
  int points_per_side = 0;    // M of the analysis grid
  double fit_radius = 0.0;    // R [m] of the local fits (gridding.fit_radius · H)
  bool vorticity = false;     // product "vorticity": ⟨ω²⟩
  bool slice_omega2 = false;  // product "slices": ω² (fitted), |τ_SFS| and ν_t (nearest particle)
  bool slice_tau = false;
  bool slice_eddy = false;  // ν_t: answered only when the run has an explicit model
  int slice_axis = 0;       // SliceConfig::axis and position (3D), when a slice is asked
  double slice_position = 0.0;
  bool statistics = false;  // product "sfs_stats", with its bins and threshold
  int histogram_bins = 0;
  int angle_bins = 0;
  double angle_threshold = 0.0;
  /// Product "particles": the file the ranks write (ParticleFileRequest), none by default.
  ParticleFileRequest particles;
  GridFieldsRequest fields;  // product "fields"
  ViewPointsRequest view;    // the 3D particle view's points (with product "particles")
  bool operator==(const RanksRequest&) const = default;
};

/// The particle snapshot the ranks wrote for a RanksRequest: its particle count and the extra
/// fields it holds, in the file's order (ν_t only when the run has it).
struct WrittenParticles {
  std::uint64_t count = 0;
  std::vector<SliceField> fields;
  bool operator==(const WrittenParticles&) const = default;
};

/// What the ranks return for a RanksRequest: the same bits as analyse computes from all
/// particles in one process.
struct RanksProducts {
  RanksRequest request;
  double mean_vorticity_squared = 0.0;  // Σ_i V_i ω_i² / Σ_i V_i over every particle [1/s²]
  /// ω², |τ_SFS| and ν_t at the slice's nodes (slice_nodes, products.hpp), in that order; each
  /// empty unless asked (ν_t also when the particles carry none: an implicit run).
  std::vector<double> slice_omega2;
  std::vector<double> slice_tau;
  std::vector<double> slice_eddy;
  std::optional<SubfilterStatisticsProduct> statistics;
  std::optional<WrittenParticles> particles;  // when request.particles.path was given
  /// Product "fields" on rank 0 (empty on the others and unless asked): the grid's values in
  /// node order (analysis::Grid::index), velocity per axis of the run's dimension.
  std::array<std::vector<double>, 3> fields_velocity;
  std::vector<double> fields_omega2;
  std::vector<double> fields_tau;
  std::vector<double> fields_eddy;
  /// The 3D particle view's points on rank 0, when request.view asked for them (and the field
  /// exists: ν_t only in a run with an explicit model).
  std::optional<ViewPoints> view;
};

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
  /// the "particle" vorticity estimate skip its own neighbour search (make_snapshot with a
  /// configuration takes it only for that estimate).
  std::shared_ptr<const sim::NeighbourList> neighbours;
  /// The velocity spectrum of SPEC §5 on analysis_grid's nodes, computed where the particles
  /// live by a solver spread over MPI ranks (DistributedProducts); the products "energy" and
  /// "spectrum" take it instead of gridding `particles`. Empty otherwise.
  std::optional<EnergySpectrum> velocity_spectrum;
  /// The particle products computed where the particles live (DistributedProducts); the
  /// products "vorticity", "slices" and "sfs_stats" take them when their request is the one
  /// the analysis' configuration makes (ranks_request). Empty otherwise.
  std::optional<RanksProducts> ranks;
  /// False when make_snapshot left `particles` (and `neighbours`) empty because every product
  /// asked for came from the ranks (velocity_spectrum): nothing was gathered. The products that
  /// need particles are then skipped for this snapshot (a live change asked for them after it
  /// was taken).
  bool has_particles = true;
  /// The 3D particle view's points the renderer asks for with this snapshot (make_snapshot):
  /// the product "particles" carries them (ParticlesProduct::view).
  ViewPointsRequest view;

  int dimension() const { return box.dimension; }
  std::size_t size() const { return particles.size(); }
};

using SnapshotPtr = std::shared_ptr<const Snapshot>;

/// What a solver spread over MPI ranks computes where its particles live, so that analysis need
/// not gather them to one process (docs/scaling.md). A sim::Simulation that also derives from this
/// (remote's proxy of a solver on MPI ranks) is passed to make_snapshot.
class DistributedProducts {
 public:
  virtual ~DistributedProducts();  // out of line: one vtable and typeinfo for dynamic_cast
  /// The spectrum of SPEC §5 of the current velocity on M^n nodes over the box (M =
  /// points_per_side): nearest-particle gridding, the spatial mean removed; equal to
  /// energy_spectrum(sample_velocity(nearest_particle_map(...), particles, true)) of all
  /// particles to round-off. Throws std::invalid_argument when the ranks cannot compute it
  /// (a void in the particles wider than their halo); make_snapshot then gathers.
  virtual EnergySpectrum velocity_spectrum(int points_per_side) const = 0;
  /// The particle products of `request` (ranks_request): each rank computes them for its own
  /// particles and slice nodes from its particles and their halo, and the ranks reduce. Throws
  /// std::invalid_argument when the ranks cannot (fits wider than the halo, a void wider than
  /// the halo); make_snapshot then gathers.
  virtual RanksProducts particle_products(const RanksRequest& request) const = 0;
};

/// Whether DistributedProducts can serve product p as `config` asks for it: energy and spectrum
/// gridded by nearest particle; vorticity, the ω² and |τ_SFS| slices and sfs_stats with the
/// "mls" vorticity estimate; particles (the ranks write the file) when `particle_file` (a run
/// directory to write it to) and ω² is not asked for or is the "mls" estimate's; fields when
/// the velocity, if asked for, is gridded by nearest particle and ω², if asked for, is the
/// "mls" estimate's. A snapshot for products all served needs no particles.
bool served_by_ranks(const AnalysisConfig& config, Product p, bool particle_file = false);

/// Grid of the snapshot: M = grid_points_per_spacing * round(L / Δl) points per side.
Grid analysis_grid(const Snapshot& snapshot, const AnalysisConfig& config);

/// "{prefix}_t{time with 4 decimals}{extension}", e.g. E_t14.0000.csv: the name of a product's
/// file of one analysis time in a run directory.
std::string timed_file_name(const std::string& prefix, double time, const std::string& extension);

/// Where the ranks write a snapshot's particle file (product "particles"): a run directory's
/// snapshots/ and the metadata the file carries (RunDirectoryWriter::particle_target).
struct ParticleFileTarget {
  std::filesystem::path directory;
  io::SnapshotMetadata metadata;
};

/// The RanksRequest of `config` for the snapshot's grid and kernel; with `particles` and the
/// product "particles" asked for, the particle file directory/particles_t{time}.h5 with the
/// fields config.particle_fields names.
RanksRequest ranks_request(const Snapshot& snapshot, const AnalysisConfig& config,
                           const ParticleFileTarget* particles = nullptr);

/// Copies what analysis needs out of a running simulation; `energy_dissipation` is the run's
/// current -de_v/dt (the simulation does not keep a history).
SnapshotPtr make_snapshot(const sim::Simulation& simulation,
                          double energy_dissipation = std::numeric_limits<double>::quiet_NaN());

/// The same for the products `config` asks for: with `ranks` (the simulation's
/// DistributedProducts, which the caller asked for once when it received the solver) and the
/// velocity gridded by nearest particle on a cubic box, the energy and spectrum come from the
/// ranks; when every product asked for is served_by_ranks, the others come from the ranks too
/// and nothing is gathered (the ranks write the particle file into particles->directory, when
/// given, as RunDirectoryWriter would); otherwise the particles are gathered for them.
/// `view`: the 3D particle view's points to carry with the product "particles" (the ranks
/// select and send only those).
SnapshotPtr make_snapshot(const sim::Simulation& simulation, const AnalysisConfig& config,
                          double energy_dissipation = std::numeric_limits<double>::quiet_NaN(),
                          const ParticleFileTarget* particles = nullptr,
                          const ViewPointsRequest& view = {},
                          const DistributedProducts* ranks = nullptr);

}  // namespace sphles::analysis
