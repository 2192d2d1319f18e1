// SPDX-License-Identifier: GPL-3.0-or-later
// The start-up check of the processor's extensions (app/cpu_check.hpp): which of a build's
// required extensions a processor lacks, and the message that names them. The refusal itself,
// on an emulated processor without them, is tests/cli/check_cpu_check.py.
#include <gtest/gtest.h>

#include <set>
#include <string>

#include "app/cpu_check.hpp"

namespace sphles::app {
namespace {

TEST(CpuCheck, MissingFeaturesAreThoseThePredicateDenies) {
  const std::set<std::string> present{"sse4.2", "avx", "avx2", "fma"};
  const auto has = [&](std::string_view f) { return present.contains(std::string(f)); };
  EXPECT_EQ(missing_cpu_features("sse4.2 avx avx2 fma avx512f avx512bw", has),
            (std::vector<std::string>{"avx512f", "avx512bw"}));
  EXPECT_TRUE(missing_cpu_features("avx2 fma", has).empty());
  EXPECT_TRUE(missing_cpu_features("", has).empty()) << "a build without extensions";
  EXPECT_EQ(missing_cpu_features("  avx512vl  avx ", has), (std::vector<std::string>{"avx512vl"}));
}

TEST(CpuCheck, MessageNamesWhatIsMissingAndHowToBuild) {
  const std::string m = missing_cpu_features_message({"avx512f", "avx512bw"});
  EXPECT_EQ(m.rfind("sphles: this processor lacks avx512f avx512bw, ", 0), 0u) << m;
  EXPECT_NE(m.find("-march=native"), std::string::npos) << m;
  EXPECT_NE(m.find("-DSPHLES_NATIVE=OFF"), std::string::npos) << m;
  EXPECT_EQ(m.back(), '\n');
}

TEST(CpuCheck, AnswersAsGccAndPassesUnknownNames) {
  // cpu_supports answers what GCC's own check answers for the names it knows.
  EXPECT_TRUE(cpu_supports("no-such-extension")) << "an unknown name is not checked";
  EXPECT_EQ(cpu_supports("avx512f"), __builtin_cpu_supports("avx512f") != 0);
  EXPECT_EQ(cpu_supports("avx2"), __builtin_cpu_supports("avx2") != 0);
}

}  // namespace
}  // namespace sphles::app
