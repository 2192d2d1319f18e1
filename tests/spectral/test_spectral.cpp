// SPDX-License-Identifier: GPL-3.0-or-later
// The spectral reference solver (spectral/): analytic solutions, the energy budget, spectral
// accuracy, determinism over thread counts, checkpoints and the `sphles reference` command.
#include <gtest/gtest.h>
#include <omp.h>

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <numbers>
#include <sstream>

#include "analysis/reference.hpp"
#include "analysis/writer.hpp"
#include "scene/document.hpp"
#include "scratch_directory.hpp"
#include "sim/initial_conditions.hpp"
#include "spectral/navier_stokes.hpp"
#include "spectral/reference_checkpoint.hpp"
#include "spectral/reference_run.hpp"

namespace sphles::spectral {
namespace {

constexpr double kPi = std::numbers::pi;

std::array<std::vector<double>, 3> taylor_green_grid(int dimension, int n, double v0) {
  std::array<std::vector<double>, 3> g;
  const std::size_t size =
      dimension == 3 ? static_cast<std::size_t>(n) * n * n : static_cast<std::size_t>(n) * n;
  for (int c = 0; c < dimension; ++c) g[c].resize(size);
  const double h = 2.0 * kPi / n;
  for (std::size_t i = 0; i < size; ++i) {
    const double x = (i % n) * h, y = (i / n % n) * h, z = dimension == 3 ? (i / n / n) * h : 0.0;
    g[0][i] = v0 * std::sin(x) * std::cos(y) * std::cos(z);
    g[1][i] = -v0 * std::cos(x) * std::sin(y) * std::cos(z);
    if (dimension == 3) g[2][i] = 0.0;
  }
  return g;
}

FlowParameters box(int dimension, double nu) {
  FlowParameters f;
  f.dimension = dimension;
  f.viscosity = nu;
  return f;
}

void run_steps(NavierStokesSolver& s, int steps, double cfl = 0.5) {
  for (int i = 0; i < steps; ++i) s.advance(s.stable_step(cfl));
}

// The transforms against each other: backward(forward(u)) = N^d u, and the pruned transforms
// (the 2/3 rule's cube) give the full ones' modes inside the cube, zero outside, for any thread
// count. n = 50 in 3D exercises the last, narrower batch of columns.
TEST(RealFft, RoundTripAndPruning) {
  for (const auto& [dimension, n] : {std::pair{2, 34}, std::pair{3, 50}}) {
    SCOPED_TRACE(std::to_string(dimension) + "D, n = " + std::to_string(n));
    const RealFft full(dimension, n);
    const int kept = dealiased_max_wavenumber(n);
    const RealFft pruned(dimension, n, kept);
    std::vector<double> u(full.real_size()), back(full.real_size());
    for (std::size_t i = 0; i < u.size(); ++i) u[i] = std::sin(0.37 * i) + std::cos(1e-3 * i * i);
    std::vector<Complex> a(full.complex_size()), b(full.complex_size()),
        scratch(full.complex_size());
    full.forward(u.data(), a.data());
    full.backward(a.data(), back.data(), scratch.data());
    double worst = 0.0;
    for (std::size_t i = 0; i < u.size(); ++i)
      worst = std::max(worst, std::abs(back[i] / static_cast<double>(u.size()) - u[i]));
    EXPECT_LT(worst, 1e-12);
    for (int threads : {1, 2, 3}) {
      omp_set_num_threads(threads);
      pruned.forward(u.data(), b.data());
      std::size_t inside = 0;
      for (std::size_t i = 0; i < a.size(); ++i) {
        const int ix = static_cast<int>(i % full.half());
        const auto [my, mz] = full.row_wavenumbers(static_cast<long>(i / full.half()));
        if (kept_mode(ix, my, mz, kept)) {
          ++inside;
          ASSERT_LT(std::abs(b[i] - a[i]), 1e-9) << i;
        } else {
          ASSERT_EQ(b[i], Complex(0.0, 0.0)) << i;
        }
      }
      EXPECT_GT(inside, 0u);
      // Backward of the cube's modes: the same as the full transform of the same input.
      std::vector<double> p(full.real_size()), q(full.real_size());
      pruned.backward(b.data(), p.data(), scratch.data());
      full.backward(b.data(), q.data(), scratch.data());
      for (std::size_t i = 0; i < p.size(); ++i) ASSERT_NEAR(p[i], q[i], 1e-9) << i;
    }
    omp_set_num_threads(2);
  }
}

// SPEC §6.2: the 2D Taylor-Green vortex decays as e^(-2νt) with no change of shape; its
// nonlinear term is a pure gradient, removed by the projection, and the integrating factor
// integrates the viscous term exactly, so the solver follows the solution to round-off.
TEST(SpectralSolver, TaylorGreen2dDecaysAsTheAnalyticSolution) {
  const double nu = 0.05, v0 = 1.0;
  NavierStokesSolver s(box(2, nu), 32);
  s.set_velocity(taylor_green_grid(2, 32, v0));
  run_steps(s, 40);
  const double t = s.time();
  ASSERT_GT(t, 1.0);
  const double e = sim::taylor_green_2d_energy(v0, nu, t);
  EXPECT_NEAR(s.budget().energy / e, 1.0, 1e-13);
  EXPECT_NEAR(s.budget().rate / (-4.0 * nu * e), 1.0, 1e-12);
  const auto u = s.velocity_grid();
  const double h = 2.0 * kPi / 32;
  double worst = 0.0;
  for (std::size_t i = 0; i < u[0].size(); ++i) {
    const auto exact = sim::taylor_green_2d_velocity(v0, nu, t, (i % 32) * h, (i / 32) * h);
    worst = std::max({worst, std::abs(u[0][i] - exact[0]), std::abs(u[1][i] - exact[1])});
  }
  EXPECT_LT(worst, 1e-13);
}

// SPEC §6.3: v_x = χ sin(k_y y)/(ν k_y² + μ) is a steady state of the forced flow with friction:
// its injection equals its viscous and film dissipation, and it stays put.
TEST(SpectralSolver, KolmogorovLaminarStateIsSteady) {
  FlowParameters f;
  f.dimension = 2;
  f.box_length = 0.042;
  f.viscosity = 1.6e-6;
  f.friction = 0.7;
  f.forcing_amplitude = 0.1;
  f.forcing_periods = 7;
  const int n = 32;
  const double ky = 2.0 * kPi * 7 / 0.042;
  const double amplitude = f.forcing_amplitude / (f.viscosity * ky * ky + f.friction);
  std::array<std::vector<double>, 3> g;
  g[0].resize(n * n);
  g[1].assign(n * n, 0.0);
  for (int i = 0; i < n * n; ++i) g[0][i] = amplitude * std::sin(ky * (i / n) * 0.042 / n);
  NavierStokesSolver s(f, n);
  s.set_velocity(g);
  const Budget b0 = s.budget();
  EXPECT_NEAR(b0.injection / (b0.dissipation + b0.film), 1.0, 1e-13);
  EXPECT_NEAR(b0.rate / b0.injection, 0.0, 1e-13);
  const double e0 = b0.energy;
  run_steps(s, 200);
  EXPECT_GT(s.time(), 0.5);
  EXPECT_NEAR(s.budget().energy / e0, 1.0, 1e-12);
  const auto u = s.velocity_grid();
  double worst = 0.0;
  for (int i = 0; i < n * n; ++i)
    worst = std::max({worst, std::abs(u[0][i] - g[0][i]), std::abs(u[1][i])});
  EXPECT_LT(worst / amplitude, 1e-12);
}

// The dealiased nonlinear term moves energy between modes and adds none: its transfer vanishes to
// round-off; without viscosity the energy is conserved up to RK4's O(dt⁴) error, and with it the
// energy follows ∫ dE/dt dt of the exact rates.
TEST(SpectralSolver, EnergyBudgetCloses) {
  NavierStokesSolver inviscid(box(3, 0.0), 24);
  inviscid.set_velocity(taylor_green_grid(3, 24, 1.0));
  const double e0 = inviscid.budget().energy;
  EXPECT_NEAR(e0, 0.125, 1e-15);
  for (int i = 0; i < 60; ++i) {
    const Budget& b = inviscid.budget();
    EXPECT_LT(std::abs(b.transfer), 1e-15) << "step " << i;
    inviscid.advance(inviscid.stable_step(0.5));
  }
  EXPECT_GT(inviscid.time(), 2.0);  // past the start: the field has many modes by now
  // RK4 damps an oscillation by O((ωh)⁶) per step: the loss is small and falls fast with h.
  const double loss = 1.0 - inviscid.budget().energy / e0;
  EXPECT_LT(std::abs(loss), 2e-6);
  NavierStokesSolver finer(box(3, 0.0), 24);
  finer.set_velocity(taylor_green_grid(3, 24, 1.0));
  while (finer.time() < inviscid.time()) finer.advance(finer.stable_step(0.25));
  EXPECT_GT(loss / std::abs(1.0 - finer.budget().energy / e0), 10.0);

  // Viscous: E(t1) - E(t0) against the trapezoidal sum of the exact rates, which is O(dt²);
  // halving dt must cut the misfit about fourfold.
  auto misfit = [](double dt) {
    NavierStokesSolver s(box(3, 1.0 / 400), 24);
    s.set_velocity(taylor_green_grid(3, 24, 1.0));
    const double start = s.budget().energy;
    double integral = 0.0;
    for (int i = 0; i < static_cast<int>(std::lround(1.0 / dt)); ++i) {
      const double r0 = s.budget().rate;
      s.advance(dt);
      integral += 0.5 * dt * (r0 + s.budget().rate);
    }
    return std::abs(s.budget().energy - start - integral);
  };
  const double coarse = misfit(0.05), fine = misfit(0.025);
  EXPECT_LT(coarse, 1e-5);
  EXPECT_NEAR(coarse / fine, 4.0, 0.4);
}

// A smooth flow is resolved exponentially fast: at Re = 100 the energy at t = 1 on 16³, 24³ and
// 32³ points differs from 48³ by 2·10⁻⁷, 8·10⁻⁹ and 8·10⁻¹¹ (relative).
TEST(SpectralSolver, SpectralAccuracyOfTheTaylorGreenVortex) {
  auto energy_at_one = [](int n) {
    NavierStokesSolver s(box(3, 0.01), n);
    s.set_velocity(taylor_green_grid(3, n, 1.0));
    for (int i = 0; i < 40; ++i) s.advance(0.025);
    return s.budget().energy;
  };
  const double e16 = energy_at_one(16), e24 = energy_at_one(24), e32 = energy_at_one(32),
               e48 = energy_at_one(48);
  EXPECT_NEAR(e32 / e48, 1.0, 1e-9);
  EXPECT_GT(std::abs(e16 - e48), 10.0 * std::abs(e24 - e48));
  EXPECT_GT(std::abs(e24 - e48), 10.0 * std::abs(e32 - e48));
  EXPECT_LT(e48, 0.125);
}

std::array<std::vector<Complex>, 3> state_after(int threads, int dimension, int n, int steps) {
  const int saved = omp_get_max_threads();
  omp_set_num_threads(threads);
  NavierStokesSolver s(box(dimension, 1.0 / 1600), n);
  s.set_velocity(taylor_green_grid(dimension, n, 1.0));
  run_steps(s, steps);
  omp_set_num_threads(saved);
  std::array<std::vector<Complex>, 3> m;
  for (int c = 0; c < dimension; ++c) m[c].assign(s.modes(c).begin(), s.modes(c).end());
  return m;
}

// Determinism: every transform is made of the same one-dimensional plans whatever the thread
// count, and every sum is taken in a fixed order (real_fft.hpp). n = 50 has a last, narrower
// batch of columns.
TEST(SpectralSolver, SameBitsForAnyThreadCount) {
  for (int dimension : {2, 3}) {
    const auto one = state_after(1, dimension, 50, 6);
    for (int threads : {2, 3}) {
      const auto many = state_after(threads, dimension, 50, 6);
      for (int c = 0; c < dimension; ++c)
        EXPECT_EQ(0, std::memcmp(one[c].data(), many[c].data(), one[c].size() * sizeof(Complex)))
            << dimension << "D, " << threads << " threads, component " << c;
    }
  }
}

TEST(SpectralSolver, CheckpointRestartIsBitwise) {
  const std::filesystem::path dir = scratch::scratch_directory("spectral", "checkpoint");
  NavierStokesSolver straight(box(3, 1.0 / 1600), 16);
  straight.set_velocity(taylor_green_grid(3, 16, 1.0));
  run_steps(straight, 4);
  ReferenceState st;
  st.time = straight.time();
  st.step = straight.step();
  st.points_per_side = 16;
  st.scene = "{}";
  st.modes = straight.gathered_modes();  // the canonical layout of FFTW's r2c output
  write_reference_checkpoint(dir / "a.h5", st);
  const ReferenceState back = read_reference_checkpoint(dir / "a.h5");
  EXPECT_EQ(back.time, st.time);
  EXPECT_EQ(back.step, st.step);
  NavierStokesSolver resumed(box(3, 1.0 / 1600), 16);
  resumed.set_modes(back.modes, back.time, back.step);
  run_steps(straight, 4);
  run_steps(resumed, 4);
  EXPECT_EQ(straight.time(), resumed.time());
  for (int c = 0; c < 3; ++c)
    EXPECT_EQ(0, std::memcmp(straight.modes(c).data(), resumed.modes(c).data(),
                             straight.modes(c).size() * sizeof(Complex)));
  // A file that is not a reference checkpoint is refused with its name.
  std::ofstream(dir / "junk.h5") << "not hdf5";
  try {
    read_reference_checkpoint(dir / "junk.h5");
    ADD_FAILURE() << "junk accepted";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("junk.h5"), std::string::npos) << e.what();
  }
}

TEST(SpectralSolver, RejectsBadParameters) {
  EXPECT_THROW(NavierStokesSolver(box(3, 0.01), 15), std::invalid_argument);
  EXPECT_THROW(NavierStokesSolver(box(4, 0.01), 16), std::invalid_argument);
  EXPECT_THROW(NavierStokesSolver(box(2, -1.0), 16), std::invalid_argument);
  FlowParameters f = box(2, 0.01);
  f.forcing_amplitude = 1.0;
  f.forcing_periods = 7;  // 16 points keep |m| <= 5
  EXPECT_THROW(NavierStokesSolver(f, 16), std::invalid_argument);
}

std::string read_file(const std::filesystem::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

int run(const std::string& args, const std::filesystem::path& log) {
  const std::string cmd = std::string(SPHLES_BINARY) + " " + args + " > " + log.string() + " 2>&1";
  return WEXITSTATUS(std::system(cmd.c_str()));
}

// The command: a 2D Taylor-Green reference run writes the time series (analytic to round-off),
// the spectra through the particle analysis' writer, ω² frames, and a checkpoint to continue from.
TEST(ReferenceCommand, WritesARunDirectoryAndRestarts) {
  const std::filesystem::path dir = scratch::scratch_directory("spectral", "command");
  const std::filesystem::path out = dir / "ref";
  ASSERT_EQ(0, run("reference tgv2d --set reference.points_per_side=32 --set time.end=0.5 "
                   "--set reference.every=0.25 --set fluid.dynamic_viscosity=0.02 --out " +
                       out.string(),
                   dir / "log.txt"))
      << read_file(dir / "log.txt");
  std::ifstream series(out / "timeseries.csv");
  std::string line;
  std::getline(series, line);
  EXPECT_EQ(line, reference_timeseries_header());
  double t = 0.0, e = 0.0;
  int rows = 0;
  while (std::getline(series, line)) {
    std::stringstream row(line);
    std::string cell;
    std::vector<double> v;
    while (std::getline(row, cell, ',')) v.push_back(std::stod(cell));
    t = v[0];
    e = v[3];
    EXPECT_NEAR(e / sim::taylor_green_2d_energy(1.0, 0.02, t), 1.0, 1e-12) << line;
    ++rows;
  }
  EXPECT_EQ(t, 0.5);
  EXPECT_GT(rows, 3);
  const auto spectra = analysis::read_index(out / "spectra" / "index.csv");
  ASSERT_EQ(spectra.size(), 3u);  // t = 0, 0.25, 0.5
  EXPECT_EQ(std::stod(spectra[1].at("t")), 0.25);
  EXPECT_TRUE(
      std::filesystem::exists(out / "frames" / analysis::timed_file_name("omega2", 0.5, ".png")));
  EXPECT_TRUE(std::filesystem::exists(out / "run.json"));

  // Continue to t = 1 from the checkpoint at 0.5: the same rows, bit for bit, as a run straight
  // to t = 1.
  ASSERT_EQ(0, run("reference --restart " + out.string() + " --set time.end=1", dir / "log2.txt"))
      << read_file(dir / "log2.txt");
  EXPECT_EQ(analysis::read_index(out / "spectra" / "index.csv").size(), 5u);
  EXPECT_EQ(analysis::read_index(out / "frames" / "index.csv").size(), 5u);
  const std::filesystem::path straight = dir / "straight";
  ASSERT_EQ(0, run("reference tgv2d --set reference.points_per_side=32 --set time.end=1 "
                   "--set reference.every=0.25 --set fluid.dynamic_viscosity=0.02 --out " +
                       straight.string(),
                   dir / "log4.txt"))
      << read_file(dir / "log4.txt");
  EXPECT_EQ(read_file(out / "timeseries.csv"), read_file(straight / "timeseries.csv"));
  EXPECT_EQ(read_file(out / "spectra" / "E_t1.0000.csv"),
            read_file(straight / "spectra" / "E_t1.0000.csv"));

  // The run is found as the reference of its flow, and of no other.
  const sim::Scene same = scene::parse_scene(
      {{"preset", "tgv2d"}, {"fluid", {{"dynamic_viscosity", 0.02}}}, {"particles_per_side", 16}});
  EXPECT_EQ(analysis::find_reference_run(same, dir), out);
  sim::Scene other = same;
  other.fluid.dynamic_viscosity = 0.021;
  EXPECT_FALSE(analysis::find_reference_run(other, dir));

  // Bad input: the field and the reason, exit 2, nothing written.
  EXPECT_EQ(
      2, run("reference tgv2d --set reference.points_per_side=33 --out " + (dir / "bad").string(),
             dir / "log3.txt"));
  EXPECT_NE(read_file(dir / "log3.txt").find("reference.points_per_side"), std::string::npos)
      << read_file(dir / "log3.txt");
  EXPECT_FALSE(std::filesystem::exists(dir / "bad"));
}

}  // namespace
}  // namespace sphles::spectral
