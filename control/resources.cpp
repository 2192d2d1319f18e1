// SPDX-License-Identifier: GPL-3.0-or-later
// The resource model follows what the code allocates (sizes from the types it stores):
//   solver        sim/solver.cpp, sim/particles.hpp, sim/neighbour_search.cpp
//   set-up        sim/packing.cpp (lattice, relaxation with its own Verlet list)
//   checkpoints   control/run.cpp (a SolverState copy), io/checkpoint.cpp (the datasets)
//   analysis      analysis/pipeline.cpp, snapshot.cpp, products.cpp, grid.cpp, spectrum.cpp,
//                 subfilter_stress.cpp, statistics.cpp, writer.cpp
//   rendering     control/render_sink.cpp, render/ (measured per pixel, see below)
// docs/scenes.md ("Resource estimate") lists what is counted and how the estimate compares with
// the peak RSS of real runs (tests/test_resources.cpp).
#include "control/resources.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <numbers>

#include "analysis/config.hpp"
#include "analysis/snapshot.hpp"
#include "sim/neighbour_search.hpp"
#include "sim/packing.hpp"
#include "sim/pair_loop.hpp"
#include "sim/process_grid.hpp"
#include "sim/subfilter.hpp"

namespace sphles::control {

namespace {

using analysis::Product;
using analysis::SliceField;

constexpr double kDouble = sizeof(double);
constexpr double kIndex = sizeof(std::uint32_t);  // NeighbourList::indices, grid maps
constexpr double kSize = sizeof(std::size_t);     // NeighbourList::offsets, cell starts
constexpr double kId = sizeof(std::uint64_t);

/// A Verlet build (sim/neighbour_search.cpp) writes each thread's lists straight into its region
/// of the list, sized with a margin over the entries expected (VerletNeighbourSearch::
/// kRegionMargin); beside the list it needs only the cell sort's arrays.

/// Up to this list radius (in units of Δl) a lattice start (packing disabled) counts its lattice
/// neighbours exactly; beyond it, and for packed starts, the list ball's volume is used.
constexpr double kExactLatticeCountRadius = 24.0;  // in units of Δl

/// Snapshots in the analysis pipeline: one waiting in the mailbox, one being analysed.
constexpr double kSnapshotsInPipeline = 2.0;
/// Analysis frames kept while the next is computed: the run's latest frame; with rendering also
/// the one being rendered (the render mailbox holds the latest).
constexpr double kFramesRetained = 1.0;
constexpr double kFramesRetainedWhileRendering = 2.0;
/// While a frame goes to its sinks it exists twice: the analysed frame and the shared copy that
/// becomes the latest frame (control/run.cpp).
constexpr double kFramesInSink = 2.0;

/// The analysis thread's own stack, malloc arena and FFTW plans (about 1 MiB over the
/// products on a 2D 32² run, where the products are smallest).
constexpr double kAnalysisThreadBytes = 1024.0 * 1024;

/// Text bytes of one number in the CSV files ("%.17g" and a separator).
constexpr double kCsvNumberBytes = 25.0;
/// Header of a 2D .npy file (padded to a multiple of 64 bytes, analysis/writer.cpp).
constexpr double kNpyHeaderBytes = 128.0;
constexpr double kVtkImageWriterBytes = 3.5 * 1024 * 1024;  // VTK XML image writer at work
/// HDF5 per dataset and per file (object headers, chunk index, checksums), an upper bound
/// for the files sphles writes (measured against real checkpoints, tests/test_resources.cpp).
constexpr double kHdf5BytesPerDataset = 4096.0;
constexpr double kHdf5BytesPerFile = 8192.0;

/// Rendering (Mesa llvmpipe through OSMesa, VTK 9.1 on Debian 12), measured with `sphles run`
/// on 2D slices: combined frames of 2400 x 1200 and 4800 x 2400 px raised the peak RSS by 168
/// and 576 MiB, i.e. about 50 B per pixel (OSMesa colour and depth buffers, VTK's frame
/// buffer, the slice texture, read-back and PNG encoding), plus 32 to 40 MiB for the renderer
/// set-up (llvmpipe threads and shader cache, VTK's text rendering). Each frame size in use has
/// its own renderer, kept for the life of the render thread.
constexpr double kRenderSetupBytes = 40.0 * 1024 * 1024;
constexpr double kRenderBytesPerPixel = 50.0;
/// The 3D view: the particle cloud copied for VTK (position, value) plus VTK's point, scalar
/// and colour arrays and their vertex buffers.
constexpr double kView3dBytesPerParticle = 4 * kDouble + 64.0;

/// Tracks live bytes along a sequence of allocations and frees and remembers the peak.
class Timeline {
 public:
  void hold(double bytes) {
    live_ += bytes;
    peak_ = std::max(peak_, live_);
  }
  void release(double bytes) { live_ -= bytes; }
  /// Allocated and freed again before the next step.
  void transient(double bytes) { peak_ = std::max(peak_, live_ + bytes); }
  double live() const { return live_; }
  double peak() const { return peak_; }

 private:
  double live_ = 0.0;
  double peak_ = 0.0;
};

std::string count_text(double x) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.4g", x);
  return buffer;
}

/// Ball of radius r (in units of Δl): its volume, or the lattice points 0 < |o| < r.
double neighbours_in_radius(int dim, double radius, bool lattice) {
  if (lattice && radius <= kExactLatticeCountRadius) {
    const int reach = static_cast<int>(std::ceil(radius));
    const double r2 = radius * radius;
    double count = 0.0;
    for (int i = -reach; i <= reach; ++i)
      for (int j = -reach; j <= reach; ++j) {
        if (dim == 2) {
          const double d2 = static_cast<double>(i * i + j * j);
          count += (d2 > 0.0 && d2 < r2) ? 1.0 : 0.0;
          continue;
        }
        for (int k = -reach; k <= reach; ++k) {
          const double d2 = static_cast<double>(i * i + j * j + k * k);
          count += (d2 > 0.0 && d2 < r2) ? 1.0 : 0.0;
        }
      }
    return count;
  }
  return dim == 2 ? std::numbers::pi * radius * radius
                  : 4.0 / 3.0 * std::numbers::pi * radius * radius * radius;
}

/// A Verlet list of one search (sim/neighbour_search.cpp) with the given skin fraction.
struct ListModel {
  double neighbours = 0.0;  // per particle
  double list_bytes = 0.0;
  double build_bytes = 0.0;  // transient of a build beside the list
  double cells = 0.0;
  /// The solver's InteractionList (sim/pair_loop.hpp): the in-support pairs the density pass
  /// compacts, with headroom, and its own offsets and counts.
  double interaction_bytes = 0.0;
};

ListModel list_model(const sim::Scene& s, double skin_fraction) {
  const int dim = s.dimension();
  const double n = static_cast<double>(s.particles_per_side);
  const double particles = std::pow(n, dim);
  const double spacing = s.particle_spacing();
  const double cutoff = 0.5 * s.kernel_diameter();
  // The search shrinks the skin so that minimum-image lists stay within half a box.
  const double skin =
      std::max(0.0, std::min(skin_fraction * cutoff, 0.5 * s.box_length() - cutoff));
  const double radius = cutoff + skin;
  ListModel m;
  m.neighbours =
      std::min(neighbours_in_radius(dim, radius / spacing, !s.packing.enabled), particles - 1.0);
  const double pairs = particles * m.neighbours;
  // Start and count per particle; the indices with the build's margin.
  const double indices = sim::VerletNeighbourSearch::kRegionMargin * pairs * kIndex;
  m.list_bytes = particles * (kSize + kIndex) + indices;
  const double in_support =
      std::min(neighbours_in_radius(dim, cutoff / spacing, !s.packing.enabled), particles - 1.0);
  m.interaction_bytes = particles * (kSize + kIndex) +
                        sim::InteractionList::kMargin * particles * in_support * kIndex;
  const double cell_size = radius / sim::VerletNeighbourSearch::kCellsPerRadius;
  m.cells = std::pow(std::max(1.0, std::floor(s.box_length() / cell_size)), dim);
  // Cell starts and their fill; per particle its cell, the cell-sorted members, their ranks and
  // the visiting order, and the positions in cell order (sim/neighbour_search.cpp's scratch).
  // The locality order and the reorder scratch before it are smaller.
  m.build_bytes = 2.0 * (m.cells + 1.0) * kSize + particles * (4.0 * kIndex + dim * kDouble);
  return m;
}

/// Bytes per particle of sim::ParticleArrays as the solver fills it.
double particle_array_bytes(const sim::Scene& s) {
  const bool explicit_model = s.subfilter.model != sim::SubfilterModel::Implicit;
  // position, velocity, acceleration; mass, volume, density, pressure; ν_t; id.
  return kDouble * (3.0 * s.dimension() + 4.0 + (explicit_model ? 1.0 : 0.0)) + kId;
}

/// What analyse() (analysis/products.cpp) computes for a configuration.
struct AnalysisNeeds {
  bool map = false, velocity = false, vorticity = false, stress = false;
  bool particle_vorticity = false, statistics = false, spectrum = false;
  bool shepard_velocity = false;  // the velocity gridded by Shepard interpolation
  bool particle_gradient = false, shepard_omega2 = false;  // the particle vorticity estimate
  int slices = 0, scalar_slices = 0;  // all slices; those sampled from particles (τ, ν_t)
  int particle_fields = 0;
  bool particles = false;
  int field_doubles = 0;  // doubles per grid node the "fields" product keeps and writes
};

AnalysisNeeds analysis_needs(const analysis::AnalysisConfig& c, bool explicit_model) {
  AnalysisNeeds a;
  const bool slices = c.wants(Product::Slices);
  const bool omega_slice = slices && c.slice.fields.contains(SliceField::VorticitySquared);
  const bool stress_slice = slices && c.slice.fields.contains(SliceField::SubfilterStressNorm);
  const bool eddy_slice =
      slices && c.slice.fields.contains(SliceField::EddyViscosity) && explicit_model;
  a.particles = c.wants(Product::Particles);
  const auto particle_field = [&](SliceField f) {
    return a.particles && c.particle_fields.contains(f);
  };
  a.statistics = c.wants(Product::SubfilterStatistics);
  a.spectrum = c.wants(Product::Spectrum);
  const bool fields = c.wants(Product::Fields);
  const auto grid_field = [&](SliceField f) { return fields && c.grid_fields.contains(f); };
  const bool stress_grid = stress_slice || grid_field(SliceField::SubfilterStressNorm);
  const bool eddy_grid = explicit_model && (eddy_slice || grid_field(SliceField::EddyViscosity));
  a.field_doubles = (fields && c.grid_velocity ? 3 : 0) +
                    (grid_field(SliceField::VorticitySquared) ? 1 : 0) +
                    (grid_field(SliceField::SubfilterStressNorm) ? 1 : 0) +
                    (grid_field(SliceField::EddyViscosity) && explicit_model ? 1 : 0);
  a.stress = a.statistics || stress_grid || particle_field(SliceField::SubfilterStressNorm);
  const bool grid_omega2 =
      c.wants(Product::Vorticity) || omega_slice || grid_field(SliceField::VorticitySquared);
  const bool particle_omega2 = a.statistics || particle_field(SliceField::VorticitySquared);
  const bool particle_estimate = c.gridding.vorticity == analysis::VorticityEstimate::Particle;
  a.particle_gradient = particle_estimate && (grid_omega2 || particle_omega2);
  a.shepard_omega2 = particle_estimate && grid_omega2;
  a.vorticity = !particle_estimate && (grid_omega2 || particle_omega2);  // central differences
  a.velocity = c.wants(Product::Energy) || a.spectrum || a.vorticity || (fields && c.grid_velocity);
  a.shepard_velocity = a.velocity && c.gridding.velocity == analysis::VelocityGridding::Shepard;
  a.map = (a.velocity && !a.shepard_velocity) || stress_grid || eddy_grid;
  a.particle_vorticity = a.vorticity && particle_omega2;  // nearest-node lookup of ω²
  a.slices = (omega_slice ? 1 : 0) + (stress_slice ? 1 : 0) + (eddy_slice ? 1 : 0);
  a.scalar_slices = a.slices - (omega_slice ? 1 : 0);
  a.particle_fields = (particle_field(SliceField::VorticitySquared) ? 1 : 0) +
                      (particle_field(SliceField::SubfilterStressNorm) ? 1 : 0) +
                      (particle_field(SliceField::EddyViscosity) && explicit_model ? 1 : 0);
  return a;
}

struct AnalysisModel {
  double work_bytes = 0.0;   // peak inside analyse(), frame included
  double frame_bytes = 0.0;  // the products a frame carries
  double writer_bytes = 0.0;
  double file_bytes = 0.0;  // written per frame
  double grid_points = 0.0;
};

AnalysisModel analysis_model(const sim::Scene& s, const analysis::AnalysisConfig& c) {
  const int dim = s.dimension();
  const double particles = std::pow(static_cast<double>(s.particles_per_side), dim);
  const double m = static_cast<double>(c.grid_points_per_spacing) * s.particles_per_side;
  const double nodes = std::pow(m, dim);
  const double slice_nodes = m * m;
  const bool explicit_model = s.subfilter.model != sim::SubfilterModel::Implicit;
  const AnalysisNeeds a = analysis_needs(c, explicit_model);
  AnalysisModel model;
  Timeline t;
  if (a.map) {
    // Cell list of nearest_particle_map (about one cell per particle): cell index, starts,
    // fill, sorted positions, ids and indices; then the node → particle map.
    const double cells = particles * (3.0 * kSize + dim * kDouble + kId + kIndex);
    t.hold(cells);
    t.hold(nodes * kIndex);
    t.release(cells);
    model.grid_points = nodes;
  }
  // Cell list of the Shepard gather (no more cells than particles for D_K >= 2Δl).
  const double shepard_cells = particles * (3.0 * kSize + dim * kDouble + kId + kIndex);
  if (a.velocity) {
    if (a.shepard_velocity) t.transient(shepard_cells + dim * nodes * kDouble);
    t.hold(dim * nodes * kDouble);
    model.grid_points = nodes;
  }
  const double shells = std::floor(std::sqrt(static_cast<double>(dim)) * (m / 2.0)) + 1.0;
  if (a.spectrum) {
    // FFTW r2c input and half-spectrum output, one component at a time.
    const double complex_nodes = nodes / m * (std::floor(m / 2.0) + 1.0);
    t.transient(nodes * kDouble + complex_nodes * 2.0 * kDouble);
    t.hold(3.0 * shells * kDouble);  // wavenumber, E, k² E
    model.frame_bytes += 3.0 * shells * kDouble;
  }
  if (a.vorticity) {
    const double components = dim == 3 ? 3.0 : 1.0;  // 2D: ω_z only
    t.hold(components * nodes * kDouble);
    t.hold(nodes * kDouble);  // ω²
    t.release(components * nodes * kDouble);
  }
  if (a.particle_gradient) {
    // J_i (9 doubles), the components of ω_i, then ω_i² (kept).
    t.transient(particles * (9.0 + 3.0) * kDouble);
    t.hold(particles * kDouble);
  }
  if (a.shepard_omega2) {
    t.transient(shepard_cells);
    t.hold(nodes * kDouble);
    model.grid_points = nodes;
  }
  if (a.stress) {
    using Stress = analysis::SubfilterStressField;
    t.hold(particles * (sizeof(Stress::tensor[0]) + sizeof(Stress::norm[0]) +
                        sizeof(Stress::principal[0]) + sizeof(Stress::direction[0])));
    // The sums gather from the analysis' cell list (analysis/subfilter_stress.hpp).
    t.transient(shepard_cells);
  }
  if (a.particle_vorticity) {
    t.hold(particles * kSize);  // nearest node of each particle
    t.hold(particles * kDouble);
    t.release(particles * kSize);
  }
  double histogram = 0.0;
  if (a.statistics) {
    histogram = static_cast<double>(c.histogram_bins) * c.histogram_bins * kId +
                (dim == 2 ? static_cast<double>(c.angle_bins) * kId : 0.0);
    t.hold(histogram);
    model.frame_bytes += histogram;
  }
  const double slice_bytes = (dim == 3 ? slice_nodes : nodes) * kDouble;
  if (a.scalar_slices > 0) t.transient(nodes * kDouble);  // the field sampled on the whole grid
  t.hold(a.slices * slice_bytes);
  model.frame_bytes += a.slices * slice_bytes;
  t.hold(a.particle_fields * particles * kDouble);
  model.frame_bytes += a.particle_fields * particles * kDouble;
  const double field_bytes = a.field_doubles * nodes * kDouble;  // the "fields" product
  t.hold(field_bytes);
  model.frame_bytes += field_bytes;
  if (a.field_doubles > 0) model.grid_points = nodes;
  model.work_bytes = t.peak();

  // Writer (analysis/writer.cpp): one file's text or buffer at a time.
  const double joint_rows =
      std::min(particles, static_cast<double>(c.histogram_bins) * c.histogram_bins);
  const double joint_text = a.statistics ? joint_rows * 5.0 * kCsvNumberBytes : 0.0;
  const double particle_file_doubles = (3.0 + 3.0 + 3.0 + a.particle_fields) * particles;
  model.writer_bytes =
      std::max({a.slices > 0 ? slice_bytes + kNpyHeaderBytes : 0.0,
                2.0 * joint_text,  // the string stream and its copy
                a.particles ? (6.0 + a.particle_fields) * particles * kDouble : 0.0,
                2.0 * field_bytes});  // VTK's arrays and the compressed blocks
  // VTK's XML image writer (slices and fields as .vti): its objects, zlib state and buffers,
  // measured as the growth of a 2D 32² run's peak RSS when the .vti writer was added.
  if (a.slices > 0 || a.field_doubles > 0) model.writer_bytes += kVtkImageWriterBytes;

  // Files per frame: spectrum CSV, slices, histograms, particle snapshot, one stats row.
  if (a.spectrum) model.file_bytes += shells * 4.0 * kCsvNumberBytes + 10.0 * kCsvNumberBytes;
  model.file_bytes += a.slices * (slice_bytes + kNpyHeaderBytes + 14.0 * kCsvNumberBytes);
  model.file_bytes += joint_text;
  if (a.statistics && dim == 2) model.file_bytes += c.angle_bins * 4.0 * kCsvNumberBytes;
  if (a.particles)
    model.file_bytes += particle_file_doubles * kDouble +
                        (5.0 + a.particle_fields) * kHdf5BytesPerDataset + kHdf5BytesPerFile;
  model.file_bytes += field_bytes;  // uncompressed, an upper bound
  model.file_bytes += 11.0 * kCsvNumberBytes;
  return model;
}

double render_pixels(const render::RenderConfig& r) {
  double pixels = 0.0;
  if (!r.fields.empty() && r.single) pixels += static_cast<double>(r.height) * r.height;
  if (!r.fields.empty() && r.combined) pixels += static_cast<double>(r.width) * r.height;
  if (r.view3d.enabled) pixels += static_cast<double>(r.view3d.width) * r.view3d.height;
  return pixels;
}

/// The split of a run over `ranks` (sim::process_grid, as par::Decomposition makes it), its
/// largest sub-box and halo, and the refusal the run would give.
RankEstimate rank_split(const sim::Scene& s, int ranks) {
  RankEstimate r;
  r.ranks = ranks;
  const int dim = s.dimension();
  r.dimension = dim;
  r.grid = sim::process_grid(ranks, dim);
  const double support = 0.5 * s.kernel_diameter();
  const double skin = std::max(s.neighbour_skin, s.packing.enabled ? sim::kPackingSkin : 0.0);
  r.halo_width = (1.0 + skin) * support;
  const double spacing = s.particle_spacing();
  const double halo = r.halo_width / spacing;  // in particles
  double with_halo = 1.0;
  r.owned = 1.0;
  for (int a = 0; a < dim; ++a) {
    const int across = r.grid[static_cast<std::size_t>(a)];
    const double side = std::ceil(static_cast<double>(s.particles_per_side) / across);
    r.owned *= side;
    // An axis split among ranks has a halo on both faces; an axis one rank spans, none.
    with_halo *= across > 1 ? side + 2.0 * halo : side;
  }
  const double length = s.box_length();
  r.refusal = sim::split_refusal(ranks, dim, {length, length, length}, r.halo_width, spacing);
  r.halo_per_owned = with_halo / r.owned - 1.0;
  return r;
}

}  // namespace

namespace {

double total(const std::vector<MemoryPart>& parts) {
  double sum = 0.0;
  for (const MemoryPart& p : parts) sum += p.bytes;
  return sum;
}

/// The analysis thread's snapshots and working set (memory parts "snapshots" and "analysis"),
/// and the analysis' grid, frame and disk figures in `e`.
std::vector<MemoryPart> analysis_parts(const sim::Scene& s, const analysis::AnalysisConfig& a,
                                       bool rendering, double per_particle, const ListModel& list,
                                       ResourceEstimate& e) {
  const double n = e.particles;
  const std::string n_text = count_text(n) + " particles";
  const AnalysisModel am = analysis_model(s, a);
  e.analysis_grid_points = am.grid_points;
  const double retained = rendering ? kFramesRetainedWhileRendering : kFramesRetained;
  // A snapshot copies the particle arrays and, for the "particle" vorticity estimate only,
  // shares the solver's list, which becomes its own once the solver rebuilds; the
  // "particles" product keeps a snapshot in every frame.
  const double count = kSnapshotsInPipeline + (a.wants(Product::Particles) ? retained : 0.0);
  const bool with_list = a.gridding.vorticity == analysis::VorticityEstimate::Particle;
  const double snapshots = count * (n * per_particle + (with_list ? list.list_bytes : 0.0));
  const std::string snapshot_text = count_text(count) + " x (" + n_text + " x " +
                                    count_text(per_particle) + " B" +
                                    (with_list ? " + a neighbour list)" : ")");
  const double computing = am.work_bytes + retained * am.frame_bytes;
  const double sinking = (retained + kFramesInSink) * am.frame_bytes + am.writer_bytes;
  const double analysis_bytes = kAnalysisThreadBytes + std::max(computing, sinking);
  const std::string analysis_text = "grid " + count_text(am.grid_points) + " nodes; working set " +
                                    format_bytes(am.work_bytes) + ", frame " +
                                    format_bytes(am.frame_bytes);
  e.analysis_frame_bytes = am.file_bytes;
  e.analysis_frames = std::floor(s.end_time / a.every) + 1.0;
  e.analysis_disk_bytes = e.analysis_frame_bytes * e.analysis_frames;
  return {{"snapshots", snapshots, snapshot_text, PartScope::Gathered},
          {"analysis", analysis_bytes, analysis_text, PartScope::Service}};
}

/// One rank of `ranks` (of `n` particles in all): the solver's parts scaled to its sub-box, and
/// what the service holds.
RankEstimate rank_estimate(const sim::Scene& s, const analysis::AnalysisConfig& a, int ranks,
                           double n, const std::vector<MemoryPart>& run_parts,
                           const std::vector<MemoryPart>& setup_parts) {
  // One rank: the solver's parts scaled to its sub-box, arrays over its owned particles and
  // halo copies, lists over its owned particles (par/, docs/scaling.md).
  RankEstimate r = rank_split(s, ranks);
  const double held = (r.owned * (1.0 + r.halo_per_owned)) / n, listed = r.owned / n;
  const auto scaled = [&](const std::vector<MemoryPart>& parts) {
    std::vector<MemoryPart> out;
    for (const MemoryPart& p : parts) {
      if (p.scope == PartScope::Owned)
        out.push_back({p.name, p.bytes * listed, "of the owned particles", p.scope});
      else if (p.scope == PartScope::OwnedAndHalo)
        out.push_back({p.name, p.bytes * held, "of the owned particles and halo copies", p.scope});
    }
    return out;
  };
  const std::vector<MemoryPart> run_rank = scaled(run_parts), setup_rank = scaled(setup_parts);
  r.memory = total(setup_rank) > total(run_rank) ? setup_rank : run_rank;
  r.memory_bytes = total(r.memory);
  // The ranks write the particle file into the run directory (control's run loop).
  const bool gathers = std::ranges::any_of(
      a.products, [&](Product p) { return !analysis::served_by_ranks(a, p, true); });
  for (const MemoryPart& p : run_parts)
    if (p.scope == PartScope::Service || (p.scope == PartScope::Gathered && gathers))
      r.service.push_back(p);
  r.service_bytes = total(r.service);
  return r;
}

}  // namespace

ResourceEstimate estimate_resources(const RunSpec& spec, int ranks) {
  const sim::Scene& s = spec.scene;
  const analysis::AnalysisConfig& a = spec.analysis;
  const int dim = s.dimension();
  const bool explicit_model = s.subfilter.model != sim::SubfilterModel::Implicit;
  ResourceEstimate e;
  e.particles = std::pow(static_cast<double>(s.particles_per_side), dim);
  const double n = e.particles;
  const std::string n_text = count_text(n) + " particles";

  // Solver: particle arrays, predicted velocity, list reference positions, ν_t scratch, the
  // scheme's fields (TVF: background acceleration and transport shift; particle shifting:
  // shifting velocity and transport shift; sim/scheme.hpp SchemeFields).
  const double per_particle = particle_array_bytes(s);
  const double scheme_fields =
      sim::scheme_uses_transport_velocity(s.scheme.type) ? 2.0 * dim * kDouble : 0.0;
  const double solver_per_particle = per_particle + 2.0 * dim * kDouble + scheme_fields +
                                     (explicit_model ? sizeof(sim::VelocityGradient) : 0.0);
  const ListModel list = list_model(s, s.neighbour_skin);
  e.neighbours_per_particle = list.neighbours;
  const std::string list_text = n_text + " x " + count_text(list.neighbours) + " neighbours";
  // Checkpoint file (io/checkpoint.cpp): position, velocity, acceleration and list reference
  // per axis, mass, volume, density, pressure, id, ν_t; the scene JSON as an attribute.
  const double datasets = 4.0 * dim + 5.0 + (explicit_model ? 1.0 : 0.0);
  const double scene_text = static_cast<double>(run_spec_to_json(spec).dump().size());
  e.checkpoint_file_bytes = n * (kDouble * (datasets - 1.0) + kId) +
                            datasets * kHdf5BytesPerDataset + kHdf5BytesPerFile + scene_text;
  // Checkpoints (and a stop) copy the solver state on the solver thread: arrays and reference
  // positions. Rebuilds happen on the same thread, so the larger of both counts.
  // Writing a checkpoint also holds the file twice: HDF5 assembles it
  // in memory (io/hdf5_file.hpp, so that a failed disk write cannot break the library) and its
  // image is copied out before it is written.
  const double state_copy = n * (per_particle + dim * kDouble) + 2.0 * e.checkpoint_file_bytes;
  const bool build_larger = list.build_bytes >= state_copy;

  // Analysis on its own thread, concurrent with the solver.
  const bool rendering = spec.render.enabled();
  const std::vector<MemoryPart> analysis_memory =
      a.enabled() ? analysis_parts(s, a, rendering, per_particle, list, e)
                  : std::vector<MemoryPart>{};
  double render_bytes = 0.0;
  if (rendering) {
    render_bytes = kRenderSetupBytes + kRenderBytesPerPixel * render_pixels(spec.render) +
                   (spec.render.view3d.enabled
                        ? kView3dBytesPerParticle *
                              std::min(n, static_cast<double>(spec.render.view3d.max_points))
                        : 0.0);
  }

  std::vector<MemoryPart> run_parts{
      {"particles", n * solver_per_particle,
       n_text + " x " + count_text(solver_per_particle) + " B", PartScope::OwnedAndHalo},
      {"neighbour_list", list.list_bytes, list_text + " x 4 B", PartScope::Owned},
      {"interaction_list", list.interaction_bytes,
       "pairs inside the support, with a tenth more room", PartScope::Owned},
      build_larger
          ? MemoryPart{"neighbour_build", list.build_bytes,
                       "the cell sort of a rebuild, " + count_text(list.cells) + " cells",
                       PartScope::OwnedAndHalo}
          : MemoryPart{"checkpoint_copy", state_copy,
                       "solver state copied to write, and the file assembled in memory twice",
                       PartScope::Owned},
  };
  for (const MemoryPart& p : analysis_memory)
    if (p.bytes > 0.0) run_parts.push_back(p);
  if (render_bytes > 0.0)
    run_parts.push_back({"rendering", render_bytes,
                         count_text(render_pixels(spec.render)) + " px and the renderer set-up",
                         PartScope::Service});

  // Set-up: the lattice and the packing's own Verlet list (before the solver exists).
  std::vector<MemoryPart> setup_parts;
  if (s.packing.enabled) {
    const ListModel packing = list_model(s, sim::kPackingSkin);
    setup_parts = {
        {"particles", n * per_particle, n_text + " (packing)", PartScope::OwnedAndHalo},
        {"packing_list", packing.list_bytes, "packing Verlet list", PartScope::Owned},
        {"packing_build", packing.build_bytes, "packing list rebuild", PartScope::OwnedAndHalo}};
  }
  e.memory = total(setup_parts) > total(run_parts) ? setup_parts : run_parts;
  e.memory_bytes = total(e.memory);
  if (ranks > 1) e.per_rank = rank_estimate(s, a, ranks, n, run_parts, setup_parts);
  e.checkpoint_disk_bytes =
      e.checkpoint_file_bytes * (s.checkpoint.enabled() ? s.checkpoint.keep + 1.0 : 1.0);

  e.time_step = sim::estimate_initial_time_step(s);
  e.steps = std::ceil(s.end_time / e.time_step.step());
  return e;
}

namespace {

nlohmann::json parts_to_json(const std::vector<MemoryPart>& memory) {
  nlohmann::json parts = nlohmann::json::array();
  for (const MemoryPart& p : memory)
    parts.push_back({{"name", p.name}, {"bytes", p.bytes}, {"detail", p.detail}});
  return parts;
}

nlohmann::json rank_estimate_to_json(const RankEstimate& r) {
  nlohmann::json grid = nlohmann::json::array();
  for (int a = 0; a < r.dimension; ++a) grid.push_back(r.grid[static_cast<std::size_t>(a)]);
  return {{"ranks", r.ranks},
          {"grid", grid},
          {"owned", r.owned},
          {"halo_per_owned", r.halo_per_owned},
          {"halo_width", r.halo_width},
          {"memory_bytes", r.memory_bytes},
          {"memory", parts_to_json(r.memory)},
          {"service_bytes", r.service_bytes},
          {"service", parts_to_json(r.service)},
          {"refusal", r.refusal.empty() ? nlohmann::json(nullptr) : nlohmann::json(r.refusal)}};
}

}  // namespace

nlohmann::json resource_estimate_to_json(const ResourceEstimate& e) {
  const auto finite = [](double x) { return std::isfinite(x) ? nlohmann::json(x) : nullptr; };
  const nlohmann::json parts = parts_to_json(e.memory);
  const sim::TimeStepLimits& l = e.time_step.limits;
  return {{"particles", e.particles},
          {"neighbours_per_particle", e.neighbours_per_particle},
          {"analysis_grid_points", e.analysis_grid_points},
          {"memory_bytes", e.memory_bytes},
          {"memory", parts},
          {"checkpoint_file_bytes", e.checkpoint_file_bytes},
          {"checkpoint_disk_bytes", e.checkpoint_disk_bytes},
          {"analysis_frame_bytes", e.analysis_frame_bytes},
          {"analysis_frames", e.analysis_frames},
          {"analysis_disk_bytes", e.analysis_disk_bytes},
          {"time_step",
           {{"initial", e.time_step.step()},
            {"limit", std::string(l.binding())},
            {"acoustic", finite(l.acoustic)},
            {"viscous", finite(l.viscous)},
            {"force", finite(l.force)},
            {"fixed", l.fixed > 0.0 ? nlohmann::json(l.fixed) : nullptr},
            {"max_speed", e.time_step.max_speed},
            {"max_acceleration", e.time_step.max_acceleration}}},
          {"steps", e.steps},
          {"per_rank", e.per_rank ? rank_estimate_to_json(*e.per_rank) : nlohmann::json(nullptr)}};
}

std::string format_bytes(double bytes) {
  static constexpr std::array<const char*, 7> kUnits{"B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"};
  std::size_t unit = 0;
  while (bytes >= 1024.0 && unit + 1 < kUnits.size()) {
    bytes /= 1024.0;
    ++unit;
  }
  char buffer[48];
  if (unit == 0)
    std::snprintf(buffer, sizeof buffer, "%.0f B", bytes);
  else
    std::snprintf(buffer, sizeof buffer, "%.3g %s", bytes, kUnits[unit]);
  return buffer;
}

std::string describe_memory(const ResourceEstimate& e, std::size_t parts) {
  std::vector<MemoryPart> sorted = e.memory;
  std::sort(sorted.begin(), sorted.end(),
            [](const MemoryPart& a, const MemoryPart& b) { return a.bytes > b.bytes; });
  std::string text = "an estimated " + format_bytes(e.memory_bytes) + " at its peak (";
  for (std::size_t k = 0; k < sorted.size() && k < parts; ++k)
    text += (k ? ", " : "") + sorted[k].name + " " + format_bytes(sorted[k].bytes);
  return text + ")";
}

std::optional<std::string> check_memory(const ResourceEstimate& e, double limit_bytes,
                                        const std::string& limit_name) {
  if (e.memory_bytes <= limit_bytes) return std::nullopt;
  return "the run needs " + describe_memory(e) + " of memory, more than the " +
         format_bytes(limit_bytes) + " " + limit_name;
}

}  // namespace sphles::control
