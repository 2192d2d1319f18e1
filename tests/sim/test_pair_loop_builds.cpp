// SPDX-License-Identifier: GPL-3.0-or-later
// The solver built with vectorised pair sums (SIMD lanes) and the one built with SPHLES_SIMD=OFF
// (every particle's pairs summed in list order) give the same 2D and 3D Taylor-Green flows after
// 100 steps to 1e-12 relative: the two builds differ only in the order of additions.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace {

std::vector<double> run_probe(const std::string& probe, const std::string& scene,
                              const std::filesystem::path& out) {
  const std::string command = probe + " '" + scene + "' 100 " + out.string();
  const int status = std::system(command.c_str());
  EXPECT_EQ(status, 0) << command;
  std::ifstream file(out, std::ios::binary | std::ios::ate);
  const auto bytes = static_cast<std::size_t>(file.tellg());
  std::vector<double> values(bytes / sizeof(double));
  file.seekg(0);
  file.read(reinterpret_cast<char*>(values.data()), static_cast<std::streamsize>(bytes));
  return values;
}

void compare(const std::string& name, const std::string& scene) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("sphles-pair-loop-builds-" + name);
  std::filesystem::create_directories(dir);
  const std::vector<double> lanes = run_probe(SPHLES_PROBE, scene, dir / "lanes.bin");
  const std::vector<double> ordered = run_probe(SPHLES_PROBE_ORDERED, scene, dir / "ordered.bin");
  ASSERT_EQ(lanes.size(), ordered.size());
  ASSERT_FALSE(lanes.empty());
  double worst = 0.0, scale = 0.0, identical = 0.0;
  for (std::size_t k = 0; k < lanes.size(); ++k) {
    worst = std::max(worst, std::abs(lanes[k] - ordered[k]));
    scale = std::max(scale, std::abs(ordered[k]));
    identical += lanes[k] == ordered[k];
  }
  std::printf("%s: max difference %.2e of max |value| %.3g (%.0f of %zu values bitwise equal)\n",
              name.c_str(), worst, scale, identical, lanes.size());
  EXPECT_LT(worst / scale, 1e-12) << name;
  EXPECT_LT(identical, static_cast<double>(lanes.size()))
      << "every value bitwise equal: the two builds did not sum differently";
  std::filesystem::remove_all(dir);
}

TEST(PairLoopBuilds, TaylorGreen2DAgreesAfter100Steps) {
  compare(
      "tgv2d",
      R"({"name": "tgv2d", "case": "tgv2d", "particles_per_side": 32, "packing": {"enabled": false},
              "kernel": {"type": "wendland_c4", "diameter_over_spacing": 8}})");
}

TEST(PairLoopBuilds, TaylorGreen3DAgreesAfter100Steps) {
  compare(
      "tgv3d",
      R"({"name": "tgv3d", "case": "tgv3d", "particles_per_side": 12, "packing": {"enabled": false},
              "kernel": {"type": "wendland_c4", "diameter_over_spacing": 8}})");
}

}  // namespace
