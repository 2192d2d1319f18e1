// SPDX-License-Identifier: GPL-3.0-or-later
// Rendering on its own thread: renders the images the render configuration asks for, saves
// them as an image series and hands them on. When the configuration saves images every frame is
// rendered (post waits while an earlier frame still waits, so that the series misses no
// analysis time); when images are only for live viewers it takes the newest frame (older ones
// still waiting are dropped and counted, so the solver and the analysis never wait for it).
//   frames/{field}_t{time}.png   frames/index.csv (time,step,field,file)
#pragma once

#include <atomic>
#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "analysis/mailbox.hpp"
#include "analysis/products.hpp"
#include "render/config.hpp"

namespace sphles::control {

struct RenderedImage {
  std::string field;
  double time = 0.0;
  std::uint64_t step = 0;
  std::string file;  // name under frames/ if saved, else empty
  std::shared_ptr<const std::vector<unsigned char>> png;
};

struct RenderCounters {
  std::uint64_t frames_rendered = 0;  // analysis frames turned into images
  std::uint64_t frames_dropped = 0;   // replaced by a newer frame before rendering
  std::uint64_t frames_skipped = 0;   // nobody needed images of them (no save, no viewer)
  std::uint64_t images = 0;
  double busy_seconds = 0.0;
};

class RenderSink {
 public:
  using ImageCallback = std::function<void(const RenderedImage&)>;
  /// `wants_live_images` is asked per frame when the configuration does not save images.
  RenderSink(render::RenderConfig config, std::string case_name, std::filesystem::path frames_dir,
             ImageCallback on_image, std::function<bool()> wants_live_images);
  ~RenderSink();  // close(false)
  RenderSink(const RenderSink&) = delete;
  RenderSink& operator=(const RenderSink&) = delete;

  /// Hands over a frame: waits for the previous one to be taken when images are saved,
  /// else replaces a frame still waiting.
  void post(std::shared_ptr<const analysis::AnalysisFrame> frame);
  void set_config(render::RenderConfig config);
  /// Stops the thread; with drain, a frame still waiting is rendered first. Idempotent.
  void close(bool drain);
  RenderCounters counters() const;
  std::string error() const;  // first failure, empty if none

 private:
  void run();
  void render_one(const analysis::AnalysisFrame& frame);

  mutable std::mutex mutex_;
  render::RenderConfig config_;
  std::string case_name_;
  std::filesystem::path frames_dir_;
  ImageCallback on_image_;
  std::function<bool()> wants_live_images_;
  analysis::LatestValueMailbox<std::shared_ptr<const analysis::AnalysisFrame>> mailbox_;
  RenderCounters counters_;
  std::string error_;
  double last_view3d_time_ = -1.0;
  std::atomic<bool> discard_{false};
  std::atomic<bool> closed_{false};
  std::thread worker_;
};

}  // namespace sphles::control
