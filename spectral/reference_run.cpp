// SPDX-License-Identifier: GPL-3.0-or-later
#include "spectral/reference_run.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <limits>
#include <numbers>
#include <optional>
#include <sstream>

#include "analysis/spectrum.hpp"
#include "analysis/units.hpp"
#include "analysis/writer.hpp"
#include "io/checkpoint.hpp"
#include "io/hdf5_file.hpp"
#include "logging/logging.hpp"
#include "scene/json_reader.hpp"
#include "sim/cadence.hpp"
#include "sim/initial_conditions.hpp"
#include "spectral/reference_checkpoint.hpp"

namespace sphles::spectral {

using nlohmann::json;

namespace {

// Outputs per run when neither reference.every nor analysis.every sets the cadence.
constexpr double kDefaultOutputsPerRun = 80.0;

std::string number(double v) {
  std::ostringstream s;
  s.precision(17);
  s << v;
  return s.str();
}

void write_json_atomically(const std::filesystem::path& path, const json& j) {
  std::string text = j.dump(2);
  text.push_back('\n');
  io::detail::write_file_atomically(path, text, "run file '" + path.string() + "'");
}

/// The keys a restart may change: when the run ends and how often it writes.
json restart_invariant(json scene) {
  scene.erase("time");
  scene.erase("analysis");
  scene.erase("checkpoint");
  scene.erase("output");
  scene.erase("render");
  scene.erase("name");
  if (scene.contains("reference")) scene["reference"].erase("every");
  if (scene.contains("reference")) scene["reference"].erase("cfl");
  return scene;
}

}  // namespace

ReferenceConfig parse_reference_config(const json& document) {
  ReferenceConfig c;
  static const json kEmpty = json::object();
  const auto it = document.find("reference");
  scene::ObjectReader r(it == document.end() ? kEmpty : *it, "reference");
  r.integer("points_per_side", c.points_per_side);
  r.number("cfl", c.cfl);
  r.number("every", c.every);
  r.reject_unknown();
  if (c.points_per_side % 2 != 0)
    sim::throw_scene_error("reference.points_per_side",
                           "must be even, got " + std::to_string(c.points_per_side));
  return c;
}

json reference_config_to_json(const ReferenceConfig& c) {
  return {{"points_per_side", c.points_per_side}, {"cfl", c.cfl}, {"every", c.every}};
}

FlowParameters flow_of(const sim::Scene& scene) {
  FlowParameters f;
  f.dimension = scene.dimension();
  f.box_length = scene.box_length();
  f.viscosity = scene.fluid.kinematic_viscosity();
  if (scene.case_type == sim::CaseType::Kolmogorov2D) {
    f.friction = scene.forcing.friction;
    f.forcing_amplitude = scene.forcing.amplitude;
    f.forcing_periods = scene.forcing.periods;
  }
  return f;
}

std::array<std::vector<double>, 3> initial_velocity_grid(const sim::Scene& scene, int n,
                                                         int first_plane, int planes) {
  const int dim = scene.dimension();
  const std::size_t plane = static_cast<std::size_t>(n) * n;
  if (dim == 2 || planes < 0) planes = dim == 2 ? 1 : n - first_plane;
  if (dim == 2) first_plane = 0;
  const double h = scene.box_length() / n;
  std::array<std::vector<double>, 3> grid;
  for (int c = 0; c < dim; ++c) grid[c].resize(plane * planes);
  // One plane of nodes at a time, as particles at the nodes: the particle run's own functions
  // give the field (and keep it one definition).
  sim::ParticleArrays p;
  p.dimension = dim;
  p.resize(plane);
  for (int z = 0; z < planes; ++z) {
    const int global_z = first_plane + z;
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        const std::size_t i = static_cast<std::size_t>(x) + static_cast<std::size_t>(n) * y;
        p.position[0][i] = x * h;
        p.position[1][i] = y * h;
        if (dim == 3) p.position[2][i] = global_z * h;
      }
    switch (scene.case_type) {
      case sim::CaseType::TaylorGreen3D:
        sim::set_taylor_green_3d(scene, p);
        break;
      case sim::CaseType::TaylorGreen2D:
        sim::set_taylor_green_2d(scene, p);
        break;
      case sim::CaseType::Kolmogorov2D:
        sim::set_kolmogorov_2d(scene, p);
        break;
    }
    for (int c = 0; c < dim; ++c)
      std::copy(p.velocity[c].begin(), p.velocity[c].end(), grid[c].begin() + plane * z);
  }
  return grid;
}

double reference_output_every(const ReferenceConfig& config, const sim::Scene& scene,
                              const analysis::AnalysisConfig& analysis) {
  if (config.every > 0.0) return config.every;
  if (analysis.every > 0.0) return analysis.every;
  return scene.end_time / kDefaultOutputsPerRun;
}

std::string reference_timeseries_header() {
  return "t,step,dt,E,minus_dE_dt,epsilon,Z,injection,film_dissipation,transfer,max_speed";
}

analysis::AnalysisFrame reference_frame(NavierStokesSolver& solver, const sim::Scene& scene,
                                        const analysis::AnalysisConfig& analysis) {
  const Budget& b = solver.budget();
  const RealFft& fft = solver.fft();
  const int n = fft.n(), half = fft.half(), dim = fft.dimension();
  analysis::AnalysisFrame frame;
  frame.time = solver.time();
  frame.step = solver.step();
  frame.dimension = dim;
  frame.kinetic_energy = b.energy;
  frame.energy_dissipation = -b.rate;
  frame.grid_kinetic_energy = b.energy;

  // The spectrum through the particle analysis' own shell sums (FFTW's unnormalised r2c output
  // is N^d û), each k_y plane's sums taken on its rank, the planes added in order.
  analysis::ShellSums sums = analysis::empty_shell_sums(dim, n);
  const std::size_t shells = sums.modulus2.size();
  const double scale = static_cast<double>(n) * n * (dim == 3 ? n : 1);
  const long rows_per_plane = fft.rows_per_plane();
  std::vector<double> per_plane(static_cast<std::size_t>(fft.planes()) * 2 * shells, 0.0);
#pragma omp parallel for schedule(static)
  for (int p = 0; p < fft.planes(); ++p) {
    double* modulus2 = per_plane.data() + static_cast<std::size_t>(p) * 2 * shells;
    double* k2_modulus2 = modulus2 + shells;
    for (int c = 0; c < dim; ++c) {
      const std::span<const Complex> m = solver.modes(c);
      for (long r = p * rows_per_plane; r < (p + 1) * rows_per_plane; ++r) {
        const auto [my, mz] = fft.row_wavenumbers(r);
        for (int kx = 0; kx < half; ++kx) {
          const double weight = conjugate_weight(kx, n);
          const double z2 = std::norm(m[static_cast<std::size_t>(r) * half + kx] * scale);
          const int q2 = kx * kx + my * my + mz * mz;
          const auto shell = static_cast<std::size_t>(sums.shell_of[static_cast<std::size_t>(q2)]);
          modulus2[shell] += weight * z2;
          k2_modulus2[shell] += weight * z2 * q2;
        }
      }
    }
  }
  const std::vector<double> total = sum_over_planes(fft, per_plane, 2 * shells);
  std::copy(total.begin(), total.begin() + static_cast<std::ptrdiff_t>(shells),
            sums.modulus2.begin());
  std::copy(total.begin() + static_cast<std::ptrdiff_t>(shells), total.end(),
            sums.k2_modulus2.begin());
  analysis::SpectrumProduct sp;
  sp.spectrum = analysis::spectrum_from_shell_sums(sums, scene.box_length());
  sp.kinetic_energy_grid = analysis::spectrum_energy(sp.spectrum);
  const double nu = scene.fluid.kinematic_viscosity();
  sp.dissipation = analysis::spectral_dissipation(sp.spectrum, nu);
  sp.kernel_wavenumber = 2.0 * std::numbers::pi / scene.kernel_diameter();
  sp.resolution_wavenumber = solver.max_wavenumber() * sp.spectrum.delta_k;
  sp.dissipation_resolved = sp.dissipation;
  sp.length_scale = analysis.spectrum_length_scale;
  frame.spectrum = sp;

  analysis::VorticityProduct vp;
  vp.estimate = analysis::VorticityEstimate::Grid;
  vp.mean_vorticity_squared = 2.0 * b.enstrophy;
  vp.dissipation = b.dissipation;
  frame.vorticity = vp;

  // ω² on the grid plane nearest the slice position (3D), or the whole grid (2D). Each rank
  // fills the nodes of its z slab; the sum over ranks adds zeros to the others (exact).
  const std::vector<std::vector<double>> omega = solver.vorticity_grid();
  analysis::SliceProduct s;
  s.field = analysis::SliceField::VorticitySquared;
  s.units = std::string(analysis::slice_field_units(s.field));
  s.spacing = solver.grid_spacing();
  s.width = s.height = n;
  s.values.assign(static_cast<std::size_t>(n) * n, kSumIdentity);
  auto omega2 = [&](std::size_t node) {
    double w2 = 0.0;
    for (const auto& w : omega) w2 += w[node] * w[node];
    return w2;
  };
  if (dim == 3) {
    const int a = analysis.slice.axis;
    const long index = std::lround(analysis.slice.position / s.spacing);
    const int plane = static_cast<int>(((index % n) + n) % n);
    s.normal_axis = a;
    s.position = plane * s.spacing;
    s.axis_u = a == 0 ? 1 : 0;
    s.axis_v = a == 2 ? 1 : 2;
    for (int v = 0; v < n; ++v)
      for (int u = 0; u < n; ++u) {
        std::array<int, 3> ijk{};
        ijk[a] = plane;
        ijk[s.axis_u] = u;
        ijk[s.axis_v] = v;
        const int z = ijk[2] - fft.first_plane();
        if (z < 0 || z >= fft.planes()) continue;
        const std::size_t node = ijk[0] + static_cast<std::size_t>(n) * (ijk[1] + n * z);
        s.values[u + static_cast<std::size_t>(n) * v] = omega2(node);
      }
    fft.exchange().sum(s.values.data(), s.values.size());
  } else {
    s.normal_axis = 2;
    s.axis_u = 0;
    s.axis_v = 1;
    for (std::size_t node = 0; node < s.values.size(); ++node) s.values[node] = omega2(node);
  }
  frame.slices.push_back(std::move(s));
  return frame;
}

namespace {

namespace fs = std::filesystem;

/// The reference checkpoints (ref_*.h5) of `checkpoints`, oldest first (the names hold the
/// step, zero-padded).
std::vector<fs::path> reference_checkpoint_files(const fs::path& checkpoints) {
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(checkpoints))
    if (e.path().extension() == ".h5" && e.path().filename().string().starts_with("ref_"))
      files.push_back(e.path());
  std::sort(files.begin(), files.end());
  return files;
}

/// The newest reference checkpoint of `checkpoints` that reads back valid and belongs to this
/// scene and resolution; damaged ones are skipped with a warning.
ReferenceState newest_valid_checkpoint(const fs::path& checkpoints, const sim::Scene& scene,
                                       const ReferenceConfig& config, const json& scene_document,
                                       logging::RunLog& log) {
  std::vector<fs::path> files = reference_checkpoint_files(checkpoints);
  std::reverse(files.begin(), files.end());
  for (const fs::path& f : files) {
    try {
      ReferenceState st = read_reference_checkpoint(f);
      if (st.points_per_side != config.points_per_side || st.dimension != scene.dimension())
        throw io::CheckpointError(
            "'" + f.string() + "' holds a " + std::to_string(st.points_per_side) + "^" +
            std::to_string(st.dimension) + " state, the scene asks for " +
            std::to_string(config.points_per_side) + "^" + std::to_string(scene.dimension()));
      if (restart_invariant(json::parse(st.scene)) != restart_invariant(scene_document))
        throw io::CheckpointError("'" + f.string() +
                                  "' was written for another scene (only time.end, the output "
                                  "cadences, reference.every and reference.cfl may change)");
      log.info("restart from {} at t = {} (step {})", f.filename().string(), st.time, st.step);
      return st;
    } catch (const io::CheckpointError& e) {
      if (files.size() == 1 || f == files.back()) throw;
      log.warn("skipping checkpoint: {}", e.what());
    }
  }
  throw io::CheckpointError("no reference checkpoint in '" + checkpoints.string() + "'");
}

/// One reference run: the solver, its run directory and, under mpirun, the agreement of the
/// ranks. Every rank steps its slab and takes part in every collective (the budget, the
/// spectra's and slices' sums, the gathered checkpoint); rank 0 alone writes and logs, and tells
/// the others after each step whether to go on (a stop, or a failure of its I/O).
class ReferenceRun {
 public:
  ReferenceRun(const sim::Scene& scene, const analysis::AnalysisConfig& analysis,
               const scene::RunPolicy& policy, const ReferenceConfig& config,
               const json& scene_document, const ReferenceRunOptions& options)
      : scene_(scene),
        analysis_(analysis),
        policy_(policy),
        config_(config),
        scene_document_(scene_document),
        options_(options),
        dir_(options.directory),
        checkpoints_(dir_ / "checkpoints"),
        series_(dir_ / "timeseries.csv"),
        root_(options.exchange == nullptr || options.exchange->rank() == 0),
        alone_(options.exchange == nullptr || options.exchange->ranks() == 1),
        solver_(flow_of(scene), config.points_per_side, options.exchange) {
    if (root_) {
      fs::create_directories(checkpoints_);
      log_.emplace(scene.name.empty() ? "reference" : scene.name, dir_ / "run.log",
                   options.echo_progress);
    }
  }

  ReferenceRunResult run() {
    start();
    open_outputs();
    every_ = reference_output_every(config_, scene_, analysis_);
    t_end_ = scene_.end_time;
    // The points k · every the loop lands on, the same in a fresh and a restarted run; a fresh
    // run also writes its row and frame at t = 0.
    sim::Cadence frames(every_, solver_.time()),
        rows(policy_.output.timeseries_every, solver_.time()),
        checkpoints_due(policy_.checkpoint.every, solver_.time());
    on_root([&] {
      log_->info("reference: {}^{} points, modes |m| <= {}, nu = {}, t = {} to {}{}",
                 config_.points_per_side, scene_.dimension(), solver_.max_wavenumber(),
                 scene_.fluid.kinematic_viscosity(), solver_.time(), t_end_,
                 alone_ ? std::string()
                        : ", " + std::to_string(options_.exchange->ranks()) + " MPI ranks");
      status("running");
    });
    report_step();
    wall_start_ = last_progress_ = std::chrono::steady_clock::now();
    first_step_ = solver_.step();
    if (!options_.restart) {
      write_row();
      write_frame();
    }
    bool row_written = true;
    while (!sim::reached_end(solver_.time(), t_end_)) {
      if (agree(root_ && options_.stop_requested && options_.stop_requested())) {
        result_.stopped = true;
        break;
      }
      const double t = solver_.time();
      budget();
      // The CFL step, cut to land on the end and the next output points; a step that would
      // leave a sliver before a point is split into two equal ones.
      const double target = std::min({t_end_, frames.next(), rows.next(), checkpoints_due.next()});
      const double limit = target - t;
      double dt = solver_.stable_step(config_.cfl);
      const bool lands = dt >= limit;
      if (lands)
        dt = limit;
      else if (2.0 * dt > limit)
        dt = 0.5 * limit;
      solver_.advance(dt);
      if (lands) solver_.set_time(target);
      last_dt_ = dt;
      report_step();
      row_written = false;
      if (!rows.active() || rows.take(solver_.time())) {
        write_row();
        row_written = true;
      }
      if (frames.take(solver_.time())) write_frame();
      if (checkpoints_due.take(solver_.time())) checkpoint();
      budget();  // on every rank: the progress line below reads it on rank 0 alone
      progress(dt);
    }
    if (!row_written) write_row();  // the state the run ends with
    checkpoint();
    agree(false);
    result_.time = solver_.time();
    result_.steps = solver_.step();
    on_root([&] {
      status(result_.stopped ? "stopped" : "done");
      log_->info("reference {} at t = {} after {} steps", result_.stopped ? "stopped" : "done",
                 result_.time, result_.steps);
    });
    agree(false);
    return result_;
  }

 private:
  /// Runs rank 0's I/O; under mpirun its failure waits for the next agree, so that every rank
  /// hears of it there.
  template <class F>
  void on_root(F&& io) {
    if (!root_) return;
    if (alone_) return io();
    try {
      io();
    } catch (...) {
      if (!failure_) failure_ = std::current_exception();
    }
  }

  /// Whether to stop, the same answer on every rank; rethrows rank 0's failure on every rank.
  bool agree(bool stop) {
    double flags[2] = {stop ? 1.0 : 0.0, failure_ ? 1.0 : 0.0};
    if (!alone_) options_.exchange->broadcast(flags, 2);
    if (flags[1] != 0.0) {
      if (failure_) std::rethrow_exception(failure_);
      throw std::runtime_error("reference: rank 0 failed (its error is in its output)");
    }
    return flags[0] != 0.0;
  }

  /// The initial field, or the state of the newest valid checkpoint for a restart.
  void start() {
    if (!options_.restart) {
      solver_.set_velocity(initial_velocity_grid(
          scene_, config_.points_per_side, solver_.fft().first_plane(), solver_.fft().planes()));
      return;
    }
    ReferenceState restored;
    on_root([&] {
      restored = newest_valid_checkpoint(checkpoints_, scene_, config_, scene_document_, *log_);
    });
    agree(false);
    solver_.set_modes(restored.modes, restored.time, restored.step);
  }

  /// scene.json, the writer of the analysis products and the time series; a restart drops the
  /// rows after its checkpoint's time (they are written again).
  void open_outputs() {
    on_root([&] {
      write_json_atomically(dir_ / "scene.json", scene_document_);
      analysis::write_units_file(dir_, analysis::RunKind::Reference, {});
      writer_.emplace(dir_);
      if (options_.restart) analysis::truncate_run_files_after(dir_, solver_.time());
      if (!options_.restart || !std::filesystem::exists(series_))
        std::ofstream(series_) << reference_timeseries_header() << '\n';
      out_.open(series_, std::ios::app);
    });
    agree(false);
  }

  void status(const std::string& state) {
    if (!root_ || failure_) return;
    write_json_atomically(dir_ / "run.json", {{"kind", "reference"},
                                              {"state", state},
                                              {"time", solver_.time()},
                                              {"step", solver_.step()},
                                              {"end_time", t_end_},
                                              {"points_per_side", config_.points_per_side},
                                              {"max_wavenumber", solver_.max_wavenumber()},
                                              {"spectra_every", every_},
                                              {"frames", result_.frames}});
  }

  /// A checkpoint of the gathered modes; the newest checkpoint.keep files are kept.
  void checkpoint() {
    ReferenceState st;
    st.time = solver_.time();
    st.step = solver_.step();
    st.dimension = scene_.dimension();
    st.points_per_side = config_.points_per_side;
    st.scene = scene_document_.dump();
    st.modes = solver_.gathered_modes();
    on_root([&] {
      const fs::path file = checkpoints_ / reference_checkpoint_name(st.step);
      write_reference_checkpoint(file, st);
      const std::vector<fs::path> files = reference_checkpoint_files(checkpoints_);
      const std::size_t keep = static_cast<std::size_t>(std::max(1, policy_.checkpoint.keep));
      for (std::size_t i = 0; i + keep < files.size(); ++i) fs::remove(files[i]);
      log_->info("checkpoint {} at t = {}", file.filename().string(), st.time);
    });
  }

  void report_step() {
    if (root_ && options_.on_step) options_.on_step(solver_.time(), solver_.step());
  }

  /// The energy budget (a collective); a non-finite energy ends the run with what to change.
  const Budget& budget() {
    const Budget& b = solver_.budget();
    if (!std::isfinite(b.energy))
      throw std::runtime_error("reference: the energy is not finite at t = " +
                               number(solver_.time()) + " (step " + std::to_string(solver_.step()) +
                               "); lower reference.cfl or raise reference.points_per_side");
    return b;
  }

  void write_row() {
    const Budget& b = budget();
    on_root([&] {
      out_ << number(solver_.time()) << ',' << solver_.step() << ',' << number(last_dt_) << ','
           << number(b.energy) << ',' << number(-b.rate) << ',' << number(b.dissipation) << ','
           << number(b.enstrophy) << ',' << number(b.injection) << ',' << number(b.film) << ','
           << number(b.transfer) << ',' << number(b.max_speed) << '\n';
      out_.flush();
      if (!out_) throw std::runtime_error("reference: cannot write '" + series_.string() + "'");
    });
  }

  void write_frame() {
    budget();
    auto frame =
        std::make_shared<analysis::AnalysisFrame>(reference_frame(solver_, scene_, analysis_));
    ++result_.frames;
    on_root([&] {
      writer_->write(*frame);
      if (!writer_->last_error().empty())
        throw std::runtime_error("reference: " + writer_->last_error());
      if (options_.on_frame) options_.on_frame(frame);
    });
  }

  void progress(double dt) {
    const auto now = std::chrono::steady_clock::now();
    if (!root_ || std::chrono::duration<double>(now - last_progress_).count() <
                      policy_.output.progress_every_seconds)
      return;
    const double wall = std::chrono::duration<double>(now - wall_start_).count();
    const double steps_per_s = static_cast<double>(solver_.step() - first_step_) / wall;
    log_->progress("t = {:.4f} / {:g}  step {}  dt {:.3e}  E {:.6e}  {:.2f} steps/s",
                   solver_.time(), t_end_, solver_.step(), dt, budget().energy, steps_per_s);
    last_progress_ = now;
  }

  const sim::Scene& scene_;
  const analysis::AnalysisConfig& analysis_;
  const scene::RunPolicy& policy_;
  const ReferenceConfig& config_;
  const json& scene_document_;
  const ReferenceRunOptions& options_;
  const fs::path dir_, checkpoints_, series_;
  const bool root_, alone_;
  NavierStokesSolver solver_;
  std::optional<logging::RunLog> log_;
  std::exception_ptr failure_;  // rank 0's, until the others hear of it
  std::optional<analysis::RunDirectoryWriter> writer_;
  std::ofstream out_;
  ReferenceRunResult result_;
  double every_ = 0.0, t_end_ = 0.0, last_dt_ = 0.0;
  std::chrono::steady_clock::time_point wall_start_, last_progress_;
  std::uint64_t first_step_ = 0;
};

}  // namespace

ReferenceRunResult run_reference(const sim::Scene& scene, const analysis::AnalysisConfig& analysis,
                                 const scene::RunPolicy& policy, const ReferenceConfig& config,
                                 const json& scene_document, const ReferenceRunOptions& options) {
  return ReferenceRun(scene, analysis, policy, config, scene_document, options).run();
}

}  // namespace sphles::spectral
