// SPDX-License-Identifier: GPL-3.0-or-later
#include "control/render_sink.hpp"

#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>

#include "analysis/writer.hpp"
#include "render/frame_images.hpp"
#include "render/render.hpp"

namespace sphles::control {

namespace {
/// Rendering only for live viewers yields the cores to the solver, like LatestOnly analysis
/// (analysis/pipeline.cpp); saved frames render at the solver's priority, since it waits for them.
constexpr int kLiveOnlyRenderNice = 19;
constexpr int kSavingRenderNice = 0;
constexpr const char* kIndexHeader = "time,step,field,file\n";
}  // namespace

RenderSink::RenderSink(render::RenderConfig config, std::string case_name,
                       std::filesystem::path frames_dir, ImageCallback on_image,
                       std::function<bool()> wants_live_images)
    : config_(std::move(config)),
      case_name_(std::move(case_name)),
      frames_dir_(std::move(frames_dir)),
      on_image_(std::move(on_image)),
      wants_live_images_(std::move(wants_live_images)) {
  worker_ = std::thread([this] { run(); });
}

RenderSink::~RenderSink() {
  close(false);
}

void RenderSink::post(std::shared_ptr<const analysis::AnalysisFrame> frame) {
  bool save = false;
  {
    std::lock_guard lock(mutex_);
    save = config_.save;
  }
  if (save)
    mailbox_.publish_waiting(std::move(frame));
  else
    mailbox_.publish(std::move(frame));
}

void RenderSink::set_config(render::RenderConfig config) {
  std::lock_guard lock(mutex_);
  config_ = std::move(config);
}

void RenderSink::close(bool drain) {
  if (closed_.exchange(true)) return;
  discard_ = !drain;
  mailbox_.close();
  if (worker_.joinable()) worker_.join();
}

RenderCounters RenderSink::counters() const {
  std::lock_guard lock(mutex_);
  RenderCounters c = counters_;
  c.frames_dropped = mailbox_.counters().dropped;
  return c;
}

std::string RenderSink::error() const {
  std::lock_guard lock(mutex_);
  return error_;
}

void RenderSink::run() {
  int nice = -1;  // none set yet
  while (auto frame = mailbox_.take()) {
    if (discard_) break;
    bool save = false;
    {
      std::lock_guard lock(mutex_);
      save = config_.save;
    }
    // Raising the priority back (a live change to saving) needs privileges a user may not
    // have; then the thread stays at the lower one, still rendering every saved frame.
    if (const int wanted = save ? kSavingRenderNice : kLiveOnlyRenderNice; wanted != nice) {
      setpriority(PRIO_PROCESS, static_cast<id_t>(::syscall(SYS_gettid)), wanted);
      nice = wanted;
    }
    const auto start = std::chrono::steady_clock::now();
    try {
      render_one(**frame);
    } catch (const std::exception& e) {
      std::lock_guard lock(mutex_);
      if (error_.empty()) error_ = e.what();
    }
    std::lock_guard lock(mutex_);
    counters_.busy_seconds +=
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
}

void RenderSink::render_one(const analysis::AnalysisFrame& frame) {
  render::RenderConfig config;
  {
    std::lock_guard lock(mutex_);
    config = config_;
  }
  if (!config.enabled() || (!config.save && !(wants_live_images_ && wants_live_images_()))) {
    std::lock_guard lock(mutex_);
    ++counters_.frames_skipped;
    return;
  }
  const bool view3d_due = config.view3d.enabled && render::has_view3d_input(frame, config.view3d) &&
                          (last_view3d_time_ < 0.0 ||
                           frame.time >= last_view3d_time_ + config.view3d.every * (1.0 - 1e-9));
  if (view3d_due) last_view3d_time_ = frame.time;
  std::vector<render::FrameImage> images =
      render::render_frame_images(frame, config, case_name_, view3d_due);
  std::string index_rows;
  for (render::FrameImage& image : images) {
    RenderedImage out;
    out.field = image.field;
    out.time = frame.time;
    out.step = frame.step;
    if (config.save) {
      out.file = analysis::timed_file_name(image.field, frame.time, ".png");
      std::filesystem::create_directories(frames_dir_);
      render::write_png_file(frames_dir_ / out.file, image.png);
      char row[160];
      std::snprintf(row, sizeof row, "%.17g,%llu,%s,", frame.time,
                    static_cast<unsigned long long>(frame.step), image.field.c_str());
      index_rows += row + out.file + "\n";
    }
    out.png = std::make_shared<const std::vector<unsigned char>>(std::move(image.png));
    if (on_image_) on_image_(out);
  }
  if (!index_rows.empty()) {
    const std::filesystem::path index = frames_dir_ / "index.csv";
    const bool fresh = !std::filesystem::exists(index);
    std::ofstream out(index, std::ios::app);
    if (fresh) out << kIndexHeader;
    out << index_rows;
    if (!out.flush()) throw std::runtime_error("cannot append to '" + index.string() + "'");
  }
  std::lock_guard lock(mutex_);
  ++counters_.frames_rendered;
  counters_.images += images.size();
}

}  // namespace sphles::control
