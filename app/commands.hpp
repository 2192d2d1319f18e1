// Subcommands of the sphles program. Each returns the process exit code.
#pragma once

#include <string>
#include <vector>

namespace sphles::app {

/// Exit codes: 0 success, 1 runtime failure (I/O, blow-up), 2 bad command line or scene.
inline constexpr int kExitOk = 0;
inline constexpr int kExitFailure = 1;
inline constexpr int kExitUsage = 2;

/// sphles run SCENE.json [--set key=value ...] [--out DIR] [--threads N]
int run_command(const std::vector<std::string>& args);

}  // namespace sphles::app
