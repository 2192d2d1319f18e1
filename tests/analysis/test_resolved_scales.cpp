// SPDX-License-Identifier: GPL-3.0-or-later
// Resolved-scale measures (analysis/resolved_scales.hpp, SPEC §9) on spectra with known sums.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <numbers>

#include "analysis/resolved_scales.hpp"
#include "analysis/writer.hpp"
#include "scratch_directory.hpp"
#include "sim/kernels.hpp"

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

TEST(ResolvedScales, WindowRatioWeighsByEnergyAndTheKernelFilterScalesTheReference) {
  // Shell 2 holds 1 and 3 in the run, 2 and 4 in the reference: the window's ratio is 4/6, not
  // the mean of 0.5 and 0.75; shell 1 is empty in the reference and has none.
  const std::vector<ShellSpectrum> run = {spectrum(1.0, {0.0, 0.5, 1.0}),
                                          spectrum(2.0, {0.0, 0.5, 3.0})};
  const std::vector<ShellSpectrum> ref = {spectrum(1.0, {0.0, 0.0, 2.0}),
                                          spectrum(2.0, {0.0, 0.0, 4.0})};
  const ResolvedHistory h = resolved_history(run, ref);
  ASSERT_EQ(h.mean_shell.size(), 2u);
  EXPECT_TRUE(std::isnan(h.mean_shell_ratio[0]));
  EXPECT_DOUBLE_EQ(h.mean_shell_ratio[1], 4.0 / 6.0);
  const nlohmann::json j = resolved_history_to_json(h);
  EXPECT_TRUE(j.at("mean_shell_ratio").at("ratio")[0].is_null());
  EXPECT_DOUBLE_EQ(j.at("mean_shell_ratio").at("ratio")[1].get<double>(), 4.0 / 6.0);

  // The filtered reference is E_ref(k) Ŵ(k)² of the scene's kernel at its D_K; against it a run
  // that carries exactly that spectrum has ratio 1 in every shell.
  sim::Scene scene;
  scene.case_type = sim::CaseType::TaylorGreen3D;
  scene.box_length_ = 2.0 * std::numbers::pi;
  scene.particles_per_side = 32;
  scene.kernel = sim::KernelType::WendlandC6;
  scene.kernel_diameter_over_spacing = 8.0;
  const std::vector<ShellSpectrum> filtered =
      kernel_filtered({spectrum(1.0, {0.0, 1.0, 2.0, 3.0, 4.0})}, scene);
  for (std::size_t p = 0; p < 5; ++p) {
    const double w = sim::kernel_transfer(sim::KernelType::WendlandC6, 3,
                                          0.5 * scene.kernel_diameter(), static_cast<double>(p));
    EXPECT_DOUBLE_EQ(filtered[0].energy[p], static_cast<double>(p) * w * w);
  }
  EXPECT_LT(filtered[0].energy[4], 0.9 * 4.0);  // k = 4 = k_kern: the filter takes a third
  const ResolvedScales r = resolved_scales(filtered[0], filtered[0], 4.0);
  for (double ratio : r.shell_ratio) EXPECT_DOUBLE_EQ(ratio, 1.0);
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
