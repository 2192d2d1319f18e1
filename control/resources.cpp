// SPDX-License-Identifier: GPL-3.0-or-later
// The resource model follows what the code allocates (sizes from the types it stores):
//   solver        sim/solver.cpp, sim/particles.hpp, sim/neighbour_search.cpp
//   set-up        sim/packing.cpp (lattice, relaxation with its own Verlet list)
//   checkpoints   control/run.cpp (a SolverState copy), io/checkpoint.cpp (the datasets)
//   analysis      analysis/pipeline.cpp, snapshot.cpp, products.cpp, grid.cpp, spectrum.cpp,
//                 subfilter_stress.cpp, statistics.cpp, writer.cpp (what analyse() and the
//                 writer hold and write: control/resources_analysis.cpp)
//   rendering     control/render_sink.cpp, render/ (measured per pixel, see below)
// docs/scenes.md ("Resource estimate") lists what is counted and how the estimate compares with
// the peak RSS of real runs (tests/control/test_resources.cpp).
#include "control/resources.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <numbers>

#include "analysis/config.hpp"
#include "analysis/snapshot.hpp"
#include "control/resources_analysis.hpp"
#include "sim/neighbour_search.hpp"
#include "sim/packing.hpp"
#include "sim/pair_loop.hpp"
#include "sim/process_grid.hpp"
#include "sim/subfilter.hpp"

namespace sphles::control {

namespace {

using analysis::Product;

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

/// Rendering (Mesa llvmpipe through OSMesa, VTK 9.1 on Debian 12), measured with `sphles run`
/// on 2D slices: combined frames of 2400 x 1200 and 4800 x 2400 px raised the peak RSS by 168
/// and 576 MiB, i.e. about 50 B per pixel (OSMesa colour and depth buffers, VTK's frame
/// buffer, the slice texture, read-back and PNG encoding), plus 32 to 40 MiB for the renderer
/// set-up (llvmpipe threads and shader cache, VTK's text rendering). Each frame size in use has
/// its own renderer, kept for the life of the render thread.
constexpr double kRenderSetupBytes = 40.0 * 1024 * 1024;
constexpr double kRenderBytesPerPixel = 50.0;
/// What each rank process of an MPI job holds before its particles: the sphles program (its
/// libraries: VTK, OSMesa, HDF5, FFTW) and the MPI runtime. Measured: the peak RSS of every rank
/// of `mpiexec -n 2` and `-n 3 sphles run tgv2d` at 16² and 24² (256 and 576 particles) was
/// 96.3-97.4 MiB (OpenMPI 4.1, Debian 12); one process without MPI holds 92 MiB.
constexpr double kRankProcessBytes = 97.0 * 1024 * 1024;
/// The 3D view: the particle cloud copied for VTK (position, value) plus VTK's point, scalar
/// and colour arrays and their vertex buffers.
constexpr double kView3dBytesPerParticle = 4 * kDouble + 64.0;

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
  // Every rank is a process of its own (the service's job, or `mpirun sphles run`).
  r.memory.push_back({"rank_process", kRankProcessBytes,
                      "the sphles program and the MPI runtime in the rank's process (measured)",
                      PartScope::Owned});
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
  e.process_peak_bytes = e.memory_bytes + kProgramBytes;
  e.warnings = sim::scene_warnings(s);
  if (ranks > 1) e.per_rank = rank_estimate(s, a, ranks, n, run_parts, setup_parts);
  e.checkpoint_disk_bytes =
      e.checkpoint_file_bytes *
      (spec.policy.checkpoint.enabled() ? spec.policy.checkpoint.keep + 1.0 : 1.0);

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

nlohmann::json scene_warnings_to_json(const std::vector<sim::SceneWarning>& warnings) {
  nlohmann::json list = nlohmann::json::array();
  for (const sim::SceneWarning& w : warnings)
    list.push_back({{"field", w.field}, {"message", w.message}});
  return list;
}

nlohmann::json resource_estimate_to_json(const ResourceEstimate& e) {
  const auto finite = [](double x) { return std::isfinite(x) ? nlohmann::json(x) : nullptr; };
  const nlohmann::json parts = parts_to_json(e.memory);
  const sim::TimeStepLimits& l = e.time_step.limits;
  return {{"particles", e.particles},
          {"neighbours_per_particle", e.neighbours_per_particle},
          {"analysis_grid_points", e.analysis_grid_points},
          {"memory_bytes", e.memory_bytes},
          {"process_peak_bytes", e.process_peak_bytes},
          {"warnings", scene_warnings_to_json(e.warnings)},
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
