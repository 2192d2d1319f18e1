#include <csignal>
#include <cstdio>
#include <string>
#include <vector>

#include "app/commands.hpp"

namespace {

constexpr const char* kUsage =
    "usage: sphles <command> [options]\n"
    "\n"
    "commands:\n"
    "  run SCENE.json|PRESET [--set key=value ...] [--out DIR] [--threads N]\n"
    "      [--packing-cache DIR]\n"
    "      run a scene (or a preset, see 'presets') to its end time, printing progress and\n"
    "      writing DIR/timeseries.csv, DIR/scene.json and the requested analysis products\n"
    "  run --restart CHECKPOINT.h5|RUN_DIR [--set key=value ...] [--out DIR] [--threads N]\n"
    "      continue a run from a checkpoint (a directory: its newest valid checkpoint); --set\n"
    "      may change what a live change may (time.end, viscosity, C_S, ...), nothing else\n"
    "  inspect CHECKPOINT.h5|SNAPSHOT.h5\n"
    "      validate a checkpoint or a particle snapshot and print what it holds\n"
    "  presets\n"
    "      list the presets (the 21 Taylor-Green cases of the thesis, kolmogorov2d);\n"
    "      scale one down with --set particles_per_side=N\n"
    "  calibrate SCENE.json|PRESET --target-urms U [--time T] [--average-from T0]\n"
    "            [--initial CHI] [--tries N] [--tolerance F] [--set key=value ...] [--threads N]\n"
    "      find the Kolmogorov forcing amplitude chi giving <u_rms> = U by secant iterations\n"
    "  estimate SCENE.json|PRESET [--set key=value ...] [--json]\n"
    "      estimate the peak memory, checkpoint and analysis disk, initial time step and steps\n"
    "      of a run without running it\n"
    "  serve [--port 8080] [--bind 127.0.0.1] [--data DIR] [--token TOKEN] [--web DIR]\n"
    "        [--max-running N] [--max-queued N] [--max-runs N] [--max-memory SIZE] [--threads N]\n"
    "        [--packing-cache DIR] [--launcher 'mpirun -n {ranks}'] [--job-address IP]\n"
    "        [--max-ranks N]\n"
    "        [--start-run PRESET|SCENE.json [--set key=value ...]]\n"
    "      the HTTP/WebSocket service and browser dashboard (docs/api.md); runs live in\n"
    "      DIR/runs/ and survive restarts; prints 'sphles serve: listening on URL'; a run\n"
    "      created with \"ranks\": N > 1 runs its solver in an MPI job started by the\n"
    "      launcher ('' : none; docs/scaling.md)\n"
    "  help       print this text\n"
    "  version    print the version\n";

}  // namespace

int main(int argc, char** argv) {
  // A file-size limit (ulimit -f, prlimit --fsize) makes a write fail with EFBIG, which every
  // writer reports naming the file, instead of killing the process mid-write.
  std::signal(SIGXFSZ, SIG_IGN);
  std::vector<std::string> args(argv + 1, argv + argc);
  if (args.empty() || args[0] == "help" || args[0] == "--help" || args[0] == "-h") {
    std::fputs(kUsage, args.empty() ? stderr : stdout);
    return args.empty() ? sphles::app::kExitUsage : sphles::app::kExitOk;
  }
  const std::string command = args[0];
  args.erase(args.begin());
  if (command == "run") return sphles::app::run_command(args);
  if (command == "presets") return sphles::app::presets_command(args);
  if (command == "inspect") return sphles::app::inspect_command(args);
  if (command == "calibrate") return sphles::app::calibrate_command(args);
  if (command == "estimate") return sphles::app::estimate_command(args);
  if (command == "serve") return sphles::app::serve_command(args);
  if (command == "worker") return sphles::app::worker_command(args);
  if (command == "version" || command == "--version") {
    std::puts("sphles " SPHLES_VERSION);
    return sphles::app::kExitOk;
  }
  std::fprintf(stderr, "sphles: unknown command '%s'\n\n%s", command.c_str(), kUsage);
  return sphles::app::kExitUsage;
}
