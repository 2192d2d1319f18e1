// SPDX-License-Identifier: GPL-3.0-or-later
// The newest analysed frame read back from a run directory (analysis/frame_reader.hpp): every
// number the writer wrote, bit for bit, and the frame a crash cut short never taken.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>

#include "analysis/frame_reader.hpp"
#include "analysis/writer.hpp"
#include "scratch_directory.hpp"

namespace sphles::analysis {
namespace {

/// A frame with every product the reader restores, its numbers chosen not to survive a
/// round trip with fewer than 17 digits.
AnalysisFrame awkward_frame(double time, std::uint64_t step, bool two_d) {
  AnalysisFrame f;
  f.time = time;
  f.step = step;
  f.kinetic_energy = 1.0 / 3.0 + time;
  f.energy_dissipation = std::nextafter(0.0123, 1.0);
  f.grid_kinetic_energy = 2.0 / 7.0;
  f.total_seconds = 0.125;
  f.dropped_snapshots = 2;
  SpectrumProduct s;
  s.spectrum.delta_k = 1.0;
  s.spectrum.wavenumber = {0.0, 1.0, 2.0, 3.0};
  s.spectrum.energy = {0.0, 1e-300, 1.0 / 3.0, std::sqrt(2.0) * 1e-9};
  s.kinetic_energy_grid = 2.0 / 7.0;
  s.dissipation = 3.0 / 11.0;
  s.dissipation_resolved = 1.0 / 13.0;
  s.kernel_wavenumber = 2.0 * M_PI / 0.7;
  s.resolution_wavenumber = 16.0;
  s.length_scale = M_PI;
  f.spectrum = s;
  f.vorticity = VorticityProduct{VorticityEstimate::Grid, 5.0 / 9.0, 5.0 / 9.0 * 6.25e-4};
  SubfilterStatisticsProduct st;
  st.max_norm = 0.1 / 3.0;
  st.mean_norm = 0.01 / 7.0;
  st.joint.bins_x = 4;
  st.joint.bins_y = 5;
  st.joint.counts.assign(20, 0);
  st.joint.counts[0] = 90;
  st.joint.counts[3 + 4 * 4] = 7;  // the corner bin (1, 1)
  st.joint.counts[1 + 4 * 2] = 3;
  st.joint.total = 100;
  if (two_d) {
    AngleHistogram a;
    a.bins = 3;
    a.threshold = 0.25;
    a.counts = {4, 0, 6};
    a.total = 10;
    st.alignment = a;
  }
  f.subfilter = st;
  return f;
}

AnalysisConfig config_of_the_run() {
  AnalysisConfig c;
  c.gridding.vorticity = VorticityEstimate::Grid;
  c.angle_threshold = 0.25;
  return c;
}

void expect_same(const AnalysisFrame& a, const AnalysisFrame& b) {
  EXPECT_EQ(a.time, b.time);
  EXPECT_EQ(a.step, b.step);
  EXPECT_EQ(a.kinetic_energy, b.kinetic_energy);
  if (!std::isnan(a.energy_dissipation) || !std::isnan(b.energy_dissipation)) {
    EXPECT_EQ(a.energy_dissipation, b.energy_dissipation);
  }
  EXPECT_EQ(a.grid_kinetic_energy, b.grid_kinetic_energy);
  EXPECT_EQ(a.total_seconds, b.total_seconds);
  EXPECT_EQ(a.dropped_snapshots, b.dropped_snapshots);
  ASSERT_EQ(a.spectrum.has_value(), b.spectrum.has_value());
  if (a.spectrum) {
    const SpectrumProduct &x = *a.spectrum, &y = *b.spectrum;
    EXPECT_EQ(x.spectrum.wavenumber, y.spectrum.wavenumber);
    EXPECT_EQ(x.spectrum.energy, y.spectrum.energy);
    EXPECT_EQ(x.spectrum.delta_k, y.spectrum.delta_k);
    EXPECT_EQ(x.kinetic_energy_grid, y.kinetic_energy_grid);
    EXPECT_EQ(x.dissipation, y.dissipation);
    EXPECT_EQ(x.dissipation_resolved, y.dissipation_resolved);
    EXPECT_EQ(x.kernel_wavenumber, y.kernel_wavenumber);
    EXPECT_EQ(x.resolution_wavenumber, y.resolution_wavenumber);
    EXPECT_EQ(x.length_scale, y.length_scale);
  }
  ASSERT_EQ(a.vorticity.has_value(), b.vorticity.has_value());
  if (a.vorticity) {
    EXPECT_EQ(a.vorticity->estimate, b.vorticity->estimate);
    EXPECT_EQ(a.vorticity->mean_vorticity_squared, b.vorticity->mean_vorticity_squared);
    EXPECT_EQ(a.vorticity->dissipation, b.vorticity->dissipation);
  }
  ASSERT_EQ(a.subfilter.has_value(), b.subfilter.has_value());
  if (a.subfilter) {
    const SubfilterStatisticsProduct &x = *a.subfilter, &y = *b.subfilter;
    EXPECT_EQ(x.max_norm, y.max_norm);
    EXPECT_EQ(x.mean_norm, y.mean_norm);
    EXPECT_EQ(x.joint.bins_x, y.joint.bins_x);
    EXPECT_EQ(x.joint.bins_y, y.joint.bins_y);
    EXPECT_EQ(x.joint.counts, y.joint.counts);
    EXPECT_EQ(x.joint.total, y.joint.total);
    ASSERT_EQ(x.alignment.has_value(), y.alignment.has_value());
    if (x.alignment) {
      EXPECT_EQ(x.alignment->bins, y.alignment->bins);
      EXPECT_EQ(x.alignment->threshold, y.alignment->threshold);
      EXPECT_EQ(x.alignment->counts, y.alignment->counts);
      EXPECT_EQ(x.alignment->total, y.alignment->total);
    }
  }
}

TEST(FrameReader, ReadsTheNewestFrameBackExactly) {
  const auto dir = scratch::scratch_directory("frame_reader", "exact");
  EXPECT_FALSE(read_latest_frame(dir, config_of_the_run()));  // nothing analysed yet
  RunDirectoryWriter writer(dir);
  for (const bool two_d : {true, false}) {
    const AnalysisFrame first = awkward_frame(two_d ? 0.5 : 1.5, two_d ? 10 : 30, two_d);
    const AnalysisFrame second = awkward_frame(two_d ? 1.0 : 2.0, two_d ? 20 : 40, two_d);
    writer.write(first);
    writer.write(second);
    ASSERT_EQ(writer.last_error(), "");
    const auto read = read_latest_frame(dir, config_of_the_run());
    ASSERT_TRUE(read);
    expect_same(*read, second);
  }
}

TEST(FrameReader, AFrameWithoutSpectrumOrStatisticsReadsWithout) {
  const auto dir = scratch::scratch_directory("frame_reader", "energy_only");
  AnalysisFrame f;
  f.time = 0.25;
  f.step = 3;
  f.kinetic_energy = 0.125;
  RunDirectoryWriter(dir).write(f);
  const AnalysisConfig defaults;
  const auto read = read_latest_frame(dir, defaults);
  ASSERT_TRUE(read);
  expect_same(*read, f);
  EXPECT_TRUE(std::isnan(read->energy_dissipation));
}

// A crash while the summary row was appended: the frame before it is the newest whole one.
TEST(FrameReader, ARowCutShortIsNotAFrame) {
  const auto dir = scratch::scratch_directory("frame_reader", "cut");
  RunDirectoryWriter writer(dir);
  const AnalysisFrame first = awkward_frame(0.5, 10, false);
  writer.write(first);
  std::ofstream(dir / "stats" / "snapshots.csv", std::ios::app) << "1,20,0.3";
  const auto read = read_latest_frame(dir, config_of_the_run());
  ASSERT_TRUE(read);
  expect_same(*read, first);
}

TEST(FrameReader, AMissingFileIsNamed) {
  const auto dir = scratch::scratch_directory("frame_reader", "missing");
  RunDirectoryWriter(dir).write(awkward_frame(0.5, 10, false));
  std::filesystem::remove(dir / "spectra" / "E_t0.5000.csv");
  try {
    read_latest_frame(dir, config_of_the_run());
    FAIL() << "a missing spectrum file was not reported";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("E_t0.5000.csv"), std::string::npos) << e.what();
  }
  std::ofstream(dir / "spectra" / "E_t0.5000.csv") << "k,E\n1,many\n";
  try {
    read_latest_frame(dir, config_of_the_run());
    FAIL() << "a spectrum that is not numbers was read";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("'E' is not a number: 'many'"), std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace sphles::analysis
