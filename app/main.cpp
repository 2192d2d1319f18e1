#include <cstdio>
#include <string>
#include <vector>

#include "app/commands.hpp"

namespace {

constexpr const char* kUsage =
    "usage: sphles <command> [options]\n"
    "\n"
    "commands:\n"
    "  run SCENE.json [--set key=value ...] [--out DIR] [--threads N]\n"
    "      run a scene to its end time, printing progress and writing DIR/timeseries.csv\n"
    "      and DIR/scene.json (the scene with every default filled in)\n"
    "  help       print this text\n"
    "  version    print the version\n";

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> args(argv + 1, argv + argc);
  if (args.empty() || args[0] == "help" || args[0] == "--help" || args[0] == "-h") {
    std::fputs(kUsage, args.empty() ? stderr : stdout);
    return args.empty() ? sphles::app::kExitUsage : sphles::app::kExitOk;
  }
  const std::string command = args[0];
  args.erase(args.begin());
  if (command == "run") return sphles::app::run_command(args);
  if (command == "version" || command == "--version") {
    std::puts("sphles " SPHLES_VERSION);
    return sphles::app::kExitOk;
  }
  std::fprintf(stderr, "sphles: unknown command '%s'\n\n%s", command.c_str(), kUsage);
  return sphles::app::kExitUsage;
}
