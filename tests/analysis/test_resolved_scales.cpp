// SPDX-License-Identifier: GPL-3.0-or-later
// Resolved-scale measures (analysis/resolved_scales.hpp, SPEC §9) on spectra with known sums.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>

#include "analysis/resolved_scales.hpp"
#include "analysis/writer.hpp"
#include "scratch_directory.hpp"

namespace sphles::analysis {
namespace {

ShellSpectrum spectrum(double time, std::vector<double> energy, double kernel = 4.0) {
  ShellSpectrum s;
  s.time = time;
  s.delta_k = 1.0;
  s.kernel_wavenumber = kernel;
  for (std::size_t p = 0; p < energy.size(); ++p) s.wavenumber.push_back(static_cast<double>(p));
  s.energy = std::move(energy);
  return s;
}

TEST(ResolvedScales, SumsRatiosAndTheEnergyAboveTheKernel) {
  // k_kern = 4, k_SPH = 2: E_res sums shells 0-2, the noise shells 5 and 6.
  const ShellSpectrum run = spectrum(8.0, {0.0, 0.01, 0.02, 0.03, 0.04, 0.05, 0.06});
  const ShellSpectrum ref = spectrum(8.0, {0.0, 0.0, 0.04, 0.03, 0.08, 0.01, 0.001});
  const ResolvedScales r = resolved_scales(run, ref, 4.0);
  EXPECT_DOUBLE_EQ(r.sph_wavenumber, 2.0);
  EXPECT_DOUBLE_EQ(r.resolved_energy, 0.03);
  EXPECT_DOUBLE_EQ(r.reference_resolved_energy, 0.04);
  EXPECT_DOUBLE_EQ(r.energy_above_kernel, 0.11);
  EXPECT_DOUBLE_EQ(r.reference_energy_above_kernel, 0.011);
  ASSERT_EQ(r.shell.size(), 4u);              // shells 1-4
  EXPECT_TRUE(std::isnan(r.shell_ratio[0]));  // the reference's shell 1 is empty
  EXPECT_DOUBLE_EQ(r.shell_ratio[1], 0.5);
  EXPECT_DOUBLE_EQ(r.shell_ratio[2], 1.0);
  EXPECT_DOUBLE_EQ(r.shell_ratio[3], 0.5);
  ShellSpectrum other_box = ref;
  other_box.delta_k = 2.0;
  EXPECT_THROW(resolved_scales(run, other_box, 4.0), std::invalid_argument);
}

TEST(ResolvedScales, HistoryInterpolatesTheReferenceAndFindsTheFluxPeak) {
  // The reference loses its resolved energy as 0.1 - 0.01 t² (flux 0.02 t), written every 0.5;
  // the run at every 0.25 has 90 % of it.
  std::vector<ShellSpectrum> ref, run;
  for (int i = 0; i <= 8; ++i) {
    const double t = 0.5 * i, e = 0.1 - 0.01 * t * t;
    ref.push_back(spectrum(t, {0.0, 0.0, e}));
  }
  for (int i = 0; i <= 16; ++i) {
    const double t = 0.25 * i, e = 0.1 - 0.01 * t * t;
    run.push_back(spectrum(t, {0.0, 0.0, 0.9 * e}));
  }
  const ResolvedHistory h = resolved_history(run, ref);
  ASSERT_EQ(h.samples.size(), 17u);
  // Between two reference times the reference is linear in time: at t = 0.25 it is the mean of
  // 0.1 and 0.0975.
  EXPECT_NEAR(h.samples[1].reference_resolved_energy, 0.09875, 1e-15);
  EXPECT_NEAR(h.samples[2].reference_resolved_energy, 0.0975, 1e-15);
  EXPECT_NEAR(h.max_relative_error, 0.1, 0.01);
  EXPECT_GT(h.l2_misfit, 0.09);
  EXPECT_LT(h.l2_misfit, 0.11);
  EXPECT_DOUBLE_EQ(h.flux_peak_time, 3.75);  // the last interior sample
  EXPECT_NEAR(h.flux_peak, 0.9 * 0.02 * 3.75, 1e-12);
  // A reference without resolved energy (every shell above k_SPH) has no misfit.
  std::vector<ShellSpectrum> wide_run, wide_ref;
  for (int i = 0; i <= 2; ++i) {
    wide_run.push_back(spectrum(i, {0.0, 0.0, 0.1}, 2.0));
    wide_ref.push_back(spectrum(i, {1e-40, 0.0, 0.1}, 2.0));
  }
  EXPECT_TRUE(std::isnan(resolved_history(wide_run, wide_ref).l2_misfit));
  // A window that the reference does not cover gives no samples.
  EXPECT_TRUE(resolved_history(run, ref, 5.0, 6.0).samples.empty());
}

TEST(ResolvedScales, ReadsARunDirectoryAndNamesWhatIsMissing) {
  const std::filesystem::path dir = scratch::scratch_directory("resolved", "read");
  EXPECT_THROW(read_run_spectra(dir), std::runtime_error);
  RunDirectoryWriter writer(dir);
  AnalysisFrame frame;
  frame.time = 1.5;
  SpectrumProduct p;
  p.spectrum.delta_k = 1.0;
  p.spectrum.wavenumber = {0.0, 1.0, 2.0};
  p.spectrum.energy = {0.0, 0.25, 0.5};
  p.kernel_wavenumber = 2.0;
  p.kinetic_energy_grid = 0.75;
  p.length_scale = 3.14;
  frame.spectrum = p;
  writer.write(frame);
  ASSERT_EQ(writer.last_error(), "");
  const std::vector<ShellSpectrum> read = read_run_spectra(dir);
  ASSERT_EQ(read.size(), 1u);
  EXPECT_EQ(read[0].time, 1.5);
  EXPECT_EQ(read[0].kernel_wavenumber, 2.0);
  EXPECT_EQ(read[0].energy, p.spectrum.energy);
}

}  // namespace
}  // namespace sphles::analysis
