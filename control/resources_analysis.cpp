// SPDX-License-Identifier: GPL-3.0-or-later
// The analysis' part of the resource estimate (control/resources_analysis.hpp), following what
// the analysis allocates and writes: analysis/products.cpp, grid.cpp, spectrum.cpp,
// subfilter_stress.cpp, statistics.cpp, writer.cpp.
#include "control/resources_analysis.hpp"

#include <algorithm>
#include <cmath>

#include "analysis/snapshot.hpp"
#include "analysis/subfilter_stress.hpp"

namespace sphles::control {

namespace {

using analysis::Product;
using analysis::SliceField;

/// Text bytes of one number in the CSV files ("%.17g" and a separator).
constexpr double kCsvNumberBytes = 25.0;
/// Header of a 2D .npy file (padded to a multiple of 64 bytes, analysis/writer.cpp).
constexpr double kNpyHeaderBytes = 128.0;
constexpr double kVtkImageWriterBytes = 3.5 * 1024 * 1024;  // VTK XML image writer at work

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

}  // namespace

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

}  // namespace sphles::control
