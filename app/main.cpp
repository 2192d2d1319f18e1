// SPDX-License-Identifier: GPL-3.0-or-later
#include <CLI/CLI.hpp>
#include <csignal>
#include <cstdio>
#include <optional>
#include <set>
#include <string>

#include "app/commands.hpp"
#include "scene/json_reader.hpp"

namespace {

// What `sphles --version` and `sphles version` print: the version, then the licence and the
// absence of warranty, as GNU programs state them (GPL-3.0 section 15; LICENSE).
constexpr const char* kVersionText =
    "sphles " SPHLES_VERSION
    "\n"
    "License GPL-3.0-or-later: GNU GPL version 3 or later <https://gnu.org/licenses/gpl.html>.\n"
    "This is free software: you are free to change and redistribute it.\n"
    "There is NO WARRANTY, to the extent permitted by law.";

}  // namespace

int main(int argc, char** argv) {
  // A file-size limit (ulimit -f, prlimit --fsize) makes a write fail with EFBIG, which every
  // writer reports naming the file, instead of killing the process mid-write.
  std::signal(SIGXFSZ, SIG_IGN);
  namespace app = sphles::app;
  CLI::App cli("sphles " SPHLES_VERSION
               ": SPH-LES turbulence simulations (weakly compressible SPH as an implicit LES), "
               "their in-situ analysis, and a service to watch and steer them from a browser. "
               "Documentation: README.md and docs/ in the source tree.",
               "sphles");
  cli.require_subcommand(1, 1);
  cli.set_version_flag("--version", kVersionText);
  cli.footer(
      "Run 'sphles COMMAND --help' for a command's options. Exit codes: 0 success, 1 "
      "runtime failure (I/O, blow-up), 2 bad command line or scene.");
  int exit_code = app::kExitOk;
  app::add_run_command(cli, exit_code);
  app::add_serve_command(cli, exit_code);
  app::add_presets_command(cli, exit_code);
  app::add_reference_command(cli, exit_code);
  app::add_compare_command(cli, exit_code);
  app::add_movie_command(cli, exit_code);
  app::add_schema_command(cli, exit_code);
  app::add_estimate_command(cli, exit_code);
  app::add_inspect_command(cli, exit_code);
  app::add_calibrate_command(cli, exit_code);
  app::add_worker_command(cli, exit_code);
  app::add_docs_command(cli, exit_code);
  cli.add_subcommand("version", "print the version and the licence")->callback([] {
    std::puts(kVersionText);
  });
  cli.add_subcommand("help", "print this help")->callback([&cli] {
    std::fputs(cli.help().c_str(), stdout);
  });
  // A first word that is no command (a typo, "sphles rn"): CLI11 would only say that a
  // subcommand is required. Name it and the command it is nearest to.
  if (argc > 1 && argv[1][0] != '-') {
    std::set<std::string> commands;
    for (const CLI::App* command : cli.get_subcommands({})) commands.insert(command->get_name());
    if (!commands.contains(argv[1])) {
      const std::optional<std::string> near = sphles::scene::closest_key(argv[1], commands);
      std::fprintf(stderr, "sphles: unknown command '%s'%s; 'sphles help' lists the commands\n",
                   argv[1], near ? (" (did you mean '" + *near + "'?)").c_str() : "");
      return app::kExitUsage;
    }
  }
  try {
    cli.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help and --version exit 0; every other parse error is a usage error (2), reported with
    // CLI11's message and a pointer to --help.
    return cli.exit(e) == 0 ? app::kExitOk : app::kExitUsage;
  }
  return exit_code;
}
