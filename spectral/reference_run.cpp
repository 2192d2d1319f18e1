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
#include "analysis/writer.hpp"
#include "io/checkpoint.hpp"
#include "io/hdf5_file.hpp"
#include "logging/logging.hpp"
#include "sim/cadence.hpp"
#include "sim/initial_conditions.hpp"
#include "sim/json_reader.hpp"
#include "spectral/reference_checkpoint.hpp"

namespace sphles::spectral {

using nlohmann::json;

namespace {

// The program's own resident memory (code, VTK and OSMesa for the frames, the MPI and HDF5
// libraries): the peak RSS of an 8³ reference run, 148 MB.
constexpr double kProgramFootprintBytes = 150e6;
// Outputs per run when neither reference.every nor analysis.every sets the cadence.
constexpr double kDefaultOutputsPerRun = 80.0;

std::string number(double v) {
  std::ostringstream s;
  s.precision(17);
  s << v;
  return s.str();
}

/// Keeps the header and the rows of a CSV whose first column is at most `time` (a restart
/// writes the later rows again).
void truncate_rows_after(const std::filesystem::path& path, double time) {
  std::ifstream in(path);
  if (!in) return;
  std::string line, kept;
  bool header = true;
  while (std::getline(in, line)) {
    if (header || line.empty() || std::stod(line.substr(0, line.find(','))) <= time)
      kept += line + '\n';
    header = false;
  }
  in.close();
  io::detail::write_file_atomically(path, kept, "index '" + path.string() + "'");
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
  sim::ObjectReader r(it == document.end() ? kEmpty : *it, "reference");
  r.integer("points_per_side", c.points_per_side);
  r.number("cfl", c.cfl);
  r.number("every", c.every);
  r.reject_unknown();
  if (c.points_per_side % 2 != 0)
    throw sim::SceneError("scene: 'reference.points_per_side' must be even, got " +
                          std::to_string(c.points_per_side));
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

ReferenceEstimate estimate_reference(const sim::Scene& scene, const ReferenceConfig& config,
                                     int ranks) {
  const double n = config.points_per_side, d = scene.dimension();
  // This rank's share: the planes of the largest slab (slab_exchange.hpp).
  const double share = d == 3 ? std::ceil(n / std::max(1, ranks)) / n : 1.0;
  const double complex_size = (n / 2 + 1) * std::pow(n, d - 1), real_size = std::pow(n, d);
  const double vorticity = d == 3 ? 3.0 : 1.0;
  const double complex_bytes = 16.0 * complex_size, real_bytes = 8.0 * real_size;
  // NavierStokesSolver: state, N(û), stage, sum (d each), two transform scratch arrays and the
  // transform's slab (3D), the integrating factors, and the grid velocity and vorticity of the
  // nonlinear term.
  const double solver = (4.0 * d + (d == 3 ? 3.0 : 2.0)) * complex_bytes + 8.0 * complex_size +
                        (d + vorticity) * real_bytes;
  // A frame's vorticity (modes, grid, scratch), or a checkpoint's gathered copy and HDF5 image
  // (the whole state, on rank 0).
  const double frame = (vorticity + 1.0) * complex_bytes + vorticity * real_bytes;
  const double checkpoint = 2.0 * d * complex_bytes;
  ReferenceEstimate e;
  e.memory_bytes = share * solver + std::max(share * frame, checkpoint) + kProgramFootprintBytes;
  e.checkpoint_bytes = d * complex_bytes;
  e.max_wavenumber = dealiased_max_wavenumber(config.points_per_side);
  // The initial largest Σ|u_i|: v0 (Taylor-Green) or the laminar speed the forcing drives
  // (Kolmogorov flow), plus the uniform velocity.
  double speed = std::abs(scene.uniform_velocity[0]) + std::abs(scene.uniform_velocity[1]) +
                 std::abs(scene.uniform_velocity[2]);
  if (scene.case_type == sim::CaseType::Kolmogorov2D) {
    const double k = scene.forcing_wavenumber();
    speed += scene.forcing.amplitude /
             (scene.fluid.kinematic_viscosity() * k * k + scene.forcing.friction);
  } else {
    speed += std::abs(scene.velocity_amplitude);
  }
  const double dt = config.cfl * scene.box_length() / n / std::max(speed, 1e-300);
  e.steps = std::ceil(scene.end_time / dt);
  return e;
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

ReferenceRunResult run_reference(const sim::Scene& scene, const analysis::AnalysisConfig& analysis,
                                 const ReferenceConfig& config, const json& scene_document,
                                 const ReferenceRunOptions& options) {
  namespace fs = std::filesystem;
  const fs::path dir = options.directory;
  const fs::path checkpoints = dir / "checkpoints";
  // Under mpirun every rank steps its slab and takes part in every collective (the budget, the
  // spectra's and slices' sums, the gathered checkpoint); rank 0 alone writes and logs, and
  // tells the others after each step whether to go on (a stop, or a failure of its I/O).
  const bool root = options.exchange == nullptr || options.exchange->rank() == 0;
  const bool alone = options.exchange == nullptr || options.exchange->ranks() == 1;
  std::optional<logging::RunLog> log;
  if (root) {
    fs::create_directories(checkpoints);
    log.emplace(scene.name.empty() ? "reference" : scene.name, dir / "run.log",
                options.echo_progress);
  }
  std::exception_ptr failure;  // rank 0's, until the others hear of it
  auto on_root = [&](auto&& io) {
    if (!root) return;
    if (alone) return io();
    try {
      io();
    } catch (...) {
      if (!failure) failure = std::current_exception();
    }
  };
  // Whether to stop, the same answer on every rank; rethrows rank 0's failure on every rank.
  auto agree = [&](bool stop) {
    double flags[2] = {stop ? 1.0 : 0.0, failure ? 1.0 : 0.0};
    if (!alone) options.exchange->broadcast(flags, 2);
    if (flags[1] != 0.0) {
      if (failure) std::rethrow_exception(failure);
      throw std::runtime_error("reference: rank 0 failed (its error is in its output)");
    }
    return flags[0] != 0.0;
  };

  NavierStokesSolver solver(flow_of(scene), config.points_per_side, options.exchange);
  ReferenceRunResult result;
  if (options.restart) {
    ReferenceState restored_state;
    on_root([&] {
      // The newest checkpoint that reads back valid; damaged ones are skipped with a warning.
      std::vector<fs::path> files;
      for (const auto& e : fs::directory_iterator(checkpoints))
        if (e.path().extension() == ".h5" && e.path().filename().string().starts_with("ref_"))
          files.push_back(e.path());
      std::sort(files.rbegin(), files.rend());
      bool restored = false;
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
          log->info("restart from {} at t = {} (step {})", f.filename().string(), st.time, st.step);
          restored_state = std::move(st);
          restored = true;
          break;
        } catch (const io::CheckpointError& e) {
          if (files.size() == 1 || f == files.back()) throw;
          log->warn("skipping checkpoint: {}", e.what());
        }
      }
      if (!restored)
        throw io::CheckpointError("no reference checkpoint in '" + checkpoints.string() + "'");
    });
    agree(false);
    solver.set_modes(restored_state.modes, restored_state.time, restored_state.step);
  } else {
    solver.set_velocity(initial_velocity_grid(scene, config.points_per_side,
                                              solver.fft().first_plane(), solver.fft().planes()));
  }

  const fs::path series = dir / "timeseries.csv";
  std::optional<analysis::RunDirectoryWriter> writer;
  std::ofstream out;
  on_root([&] {
    write_json_atomically(dir / "scene.json", scene_document);
    writer.emplace(dir);
    if (options.restart) {
      truncate_rows_after(series, solver.time());
      truncate_rows_after(dir / "spectra" / "index.csv", solver.time());
      truncate_rows_after(dir / "slices" / "index.csv", solver.time());
      truncate_rows_after(dir / "stats" / "snapshots.csv", solver.time());
      truncate_rows_after(dir / "frames" / "index.csv", solver.time());
    } else {
      std::ofstream(series) << reference_timeseries_header() << '\n';
    }
    out.open(series, std::ios::app);
  });
  agree(false);

  const double every = reference_output_every(config, scene, analysis);
  const double t_end = scene.end_time;
  // The points k · every the loop lands on, the same in a fresh and a restarted run; a fresh
  // run also writes its row and frame at t = 0.
  sim::Cadence frames(every, solver.time()), rows(scene.output.timeseries_every, solver.time()),
      checkpoints_due(scene.checkpoint.every, solver.time());
  double last_dt = 0.0;

  auto status = [&](const std::string& state) {
    if (!root || failure) return;
    write_json_atomically(dir / "run.json", {{"kind", "reference"},
                                             {"state", state},
                                             {"time", solver.time()},
                                             {"step", solver.step()},
                                             {"end_time", t_end},
                                             {"points_per_side", config.points_per_side},
                                             {"max_wavenumber", solver.max_wavenumber()},
                                             {"spectra_every", every},
                                             {"frames", result.frames}});
  };
  auto checkpoint = [&] {
    ReferenceState st;
    st.time = solver.time();
    st.step = solver.step();
    st.dimension = scene.dimension();
    st.points_per_side = config.points_per_side;
    st.scene = scene_document.dump();
    st.modes = solver.gathered_modes();
    on_root([&] {
      const fs::path file = checkpoints / reference_checkpoint_name(st.step);
      write_reference_checkpoint(file, st);
      // Keep the newest checkpoint.keep files.
      std::vector<fs::path> files;
      for (const auto& e : fs::directory_iterator(checkpoints))
        if (e.path().extension() == ".h5" && e.path().filename().string().starts_with("ref_"))
          files.push_back(e.path());
      std::sort(files.begin(), files.end());
      const std::size_t keep = static_cast<std::size_t>(std::max(1, scene.checkpoint.keep));
      for (std::size_t i = 0; i + keep < files.size(); ++i) fs::remove(files[i]);
      log->info("checkpoint {} at t = {}", file.filename().string(), st.time);
    });
  };

  on_root([&] {
    log->info(
        "reference: {}^{} points, modes |m| <= {}, nu = {}, t = {} to {}{}", config.points_per_side,
        scene.dimension(), solver.max_wavenumber(), scene.fluid.kinematic_viscosity(),
        solver.time(), t_end,
        alone ? std::string() : ", " + std::to_string(options.exchange->ranks()) + " MPI ranks");
    status("running");
  });
  const auto report_step = [&] {
    if (root && options.on_step) options.on_step(solver.time(), solver.step());
  };
  report_step();
  const auto wall_start = std::chrono::steady_clock::now();
  auto last_progress = wall_start;
  const std::uint64_t first_step = solver.step();
  auto budget = [&]() -> const Budget& {
    const Budget& b = solver.budget();
    if (!std::isfinite(b.energy))
      throw std::runtime_error("reference: the energy is not finite at t = " +
                               number(solver.time()) + " (step " + std::to_string(solver.step()) +
                               "); lower reference.cfl or raise reference.points_per_side");
    return b;
  };
  auto write_row = [&] {
    const Budget& b = budget();
    on_root([&] {
      out << number(solver.time()) << ',' << solver.step() << ',' << number(last_dt) << ','
          << number(b.energy) << ',' << number(-b.rate) << ',' << number(b.dissipation) << ','
          << number(b.enstrophy) << ',' << number(b.injection) << ',' << number(b.film) << ','
          << number(b.transfer) << ',' << number(b.max_speed) << '\n';
      out.flush();
      if (!out) throw std::runtime_error("reference: cannot write '" + series.string() + "'");
    });
  };
  auto write_frame = [&] {
    budget();
    auto frame =
        std::make_shared<analysis::AnalysisFrame>(reference_frame(solver, scene, analysis));
    ++result.frames;
    on_root([&] {
      writer->write(*frame);
      if (!writer->last_error().empty())
        throw std::runtime_error("reference: " + writer->last_error());
      if (options.on_frame) options.on_frame(frame);
    });
  };
  if (!options.restart) {
    write_row();
    write_frame();
  }
  bool row_written = true;
  while (!sim::reached_end(solver.time(), t_end)) {
    if (agree(root && options.stop_requested && options.stop_requested())) {
      result.stopped = true;
      break;
    }
    const double t = solver.time();
    budget();
    // The CFL step, cut to land on the end and the next output points; a step that would leave
    // a sliver before a point is split into two equal ones.
    const double target = std::min({t_end, frames.next(), rows.next(), checkpoints_due.next()});
    const double limit = target - t;
    double dt = solver.stable_step(config.cfl);
    const bool lands = dt >= limit;
    if (lands)
      dt = limit;
    else if (2.0 * dt > limit)
      dt = 0.5 * limit;
    solver.advance(dt);
    if (lands) solver.set_time(target);
    last_dt = dt;
    report_step();
    row_written = false;
    if (!rows.active() || rows.take(solver.time())) {
      write_row();
      row_written = true;
    }
    if (frames.take(solver.time())) write_frame();
    if (checkpoints_due.take(solver.time())) checkpoint();
    budget();  // on every rank: the progress line below reads it on rank 0 alone
    const auto now = std::chrono::steady_clock::now();
    if (root && std::chrono::duration<double>(now - last_progress).count() >=
                    scene.output.progress_every_seconds) {
      const double wall = std::chrono::duration<double>(now - wall_start).count();
      const double steps_per_s = static_cast<double>(solver.step() - first_step) / wall;
      log->progress("t = {:.4f} / {:g}  step {}  dt {:.3e}  E {:.6e}  {:.2f} steps/s",
                    solver.time(), t_end, solver.step(), dt, budget().energy, steps_per_s);
      last_progress = now;
    }
  }
  if (!row_written) write_row();  // the state the run ends with
  checkpoint();
  agree(false);
  result.time = solver.time();
  result.steps = solver.step();
  on_root([&] {
    status(result.stopped ? "stopped" : "done");
    log->info("reference {} at t = {} after {} steps", result.stopped ? "stopped" : "done",
              result.time, result.steps);
  });
  agree(false);
  return result;
}

}  // namespace sphles::spectral
