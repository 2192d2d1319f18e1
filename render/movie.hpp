// SPDX-License-Identifier: GPL-3.0-or-later
// A run's saved image series as a video a browser plays: WebM with VP9 (libvpx through
// libavcodec, which VTK's packages already pull in), so that watching a series needs no
// separate tool.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace sphles::render {

struct MovieOptions {
  double frames_per_second = 10.0;  // of the video, 0.1 to 120
  /// VP9's constant quality (its crf): 0 is the best, 63 the smallest file. 32 keeps a
  /// colour-mapped slice's fine structure at a tenth of the PNGs' size.
  int quality = 32;
};

struct MovieSummary {
  std::size_t frames = 0;
  int width = 0;   // [px] of the video: the first frame's, rounded down to even
  int height = 0;  // [px]
  double duration_seconds = 0.0;
  std::uintmax_t bytes = 0;
};

/// The saved frames of `field` (omega2, tau_sfs, nu_t, combined, view3d) of a run directory,
/// in time order, from frames/index.csv (one file per time: the last row of a time wins).
/// Throws std::runtime_error naming the index and the field when it lists none, and the file
/// when a listed one is missing.
std::vector<std::filesystem::path> saved_frames(const std::filesystem::path& run_directory,
                                                const std::string& field);

/// Encodes the PNG images `frames`, in order, as a WebM (VP9, yuv420p) at `out`, written to a
/// temporary name and renamed: no reader sees half a video. A frame of another size is scaled
/// to the first one's. Throws std::invalid_argument naming the option for bad options, and
/// std::runtime_error naming the file and the reason for an unreadable frame or an encoder
/// failure.
MovieSummary write_movie(const std::vector<std::filesystem::path>& frames,
                         const std::filesystem::path& out, const MovieOptions& options);

}  // namespace sphles::render
