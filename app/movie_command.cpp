// SPDX-License-Identifier: GPL-3.0-or-later
// sphles movie RUN [--field F] [--fps N] [--quality Q] [--out FILE]: a run's saved image series
// as a WebM video a browser plays (render/movie.hpp).
#include <cstdio>
#include <filesystem>
#include <memory>
#include <stdexcept>
#include <string>

#include "app/commands.hpp"
#include "render/movie.hpp"

namespace sphles::app {

namespace {

struct MovieCommandOptions {
  std::string run;
  std::string field = "omega2";
  std::string out;  // default RUN/movies/FIELD.webm
  render::MovieOptions movie;
};

int movie_command(const MovieCommandOptions& o) {
  const std::filesystem::path run = o.run;
  if (!std::filesystem::is_regular_file(run / "run.json")) {
    std::fprintf(stderr, "sphles movie: 'run': %s is not a run directory (no run.json)\n",
                 o.run.c_str());
    return kExitUsage;
  }
  const std::filesystem::path out =
      o.out.empty() ? run / "movies" / (o.field + ".webm") : std::filesystem::path(o.out);
  try {
    const auto frames = render::saved_frames(run, o.field);
    if (!out.parent_path().empty()) std::filesystem::create_directories(out.parent_path());
    const render::MovieSummary s = render::write_movie(frames, out, o.movie);
    std::printf("sphles movie: %zu frames of %s, %dx%d px, %.1f s at %g frames/s, %.1f KiB -> %s\n",
                s.frames, o.field.c_str(), s.width, s.height, s.duration_seconds,
                o.movie.frames_per_second, static_cast<double>(s.bytes) / 1024.0, out.c_str());
    return kExitOk;
  } catch (const std::invalid_argument& e) {
    std::fprintf(stderr, "sphles movie: %s\n", e.what());
    return kExitUsage;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "sphles movie: %s\n", e.what());
    return kExitFailure;
  }
}

}  // namespace

void add_movie_command(CLI::App& app, int& exit_code) {
  auto o = std::make_shared<MovieCommandOptions>();
  CLI::App* cmd =
      app.add_subcommand("movie", "a run's saved image series as a video a browser plays (WebM)");
  cmd->footer(
      "Encodes the run's saved frames of one field (frames/index.csv, in time order) as WebM "
      "(VP9): by default RUN/movies/FIELD.webm. The scene's render section saves the frames "
      "(docs/rendering.md); pin the colour range (render.colour.FIELD.min/max) so that colours "
      "mean the same in every frame.");
  cmd->add_option("run", o->run, "run directory")->required()->type_name("RUN");
  cmd->add_option("--field", o->field,
                  "field of the series: omega2, tau_sfs, nu_t, combined, view3d")
      ->check(CLI::IsMember({"omega2", "tau_sfs", "nu_t", "combined", "view3d"}))
      ->capture_default_str();
  cmd->add_option("--fps", o->movie.frames_per_second, "frames per second of the video")
      ->check(CLI::Range(0.1, 120.0))
      ->capture_default_str();
  cmd->add_option("--quality", o->movie.quality, "VP9 constant quality: 0 best, 63 smallest")
      ->check(CLI::Range(0, 63))
      ->capture_default_str();
  cmd->add_option("--out", o->out, "video file (default RUN/movies/FIELD.webm)")->type_name("FILE");
  cmd->callback([o, &exit_code] { exit_code = movie_command(*o); });
}

}  // namespace sphles::app
