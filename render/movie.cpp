// SPDX-License-Identifier: GPL-3.0-or-later
#include "render/movie.hpp"

#include <fcntl.h>
#include <png.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <map>
#include <memory>
#include <stdexcept>
#include <system_error>

#include "analysis/writer.hpp"

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavformat/avformat.h>
#include <libavutil/opt.h>
#include <libswscale/swscale.h>
}

namespace sphles::render {

namespace fs = std::filesystem;

namespace {

struct RgbImage {
  int width = 0;
  int height = 0;
  std::vector<std::uint8_t> pixels;  // row-major RGB, 3 bytes per pixel
};

RgbImage read_png(const fs::path& path) {
  png_image image{};
  image.version = PNG_IMAGE_VERSION;
  if (png_image_begin_read_from_file(&image, path.c_str()) == 0)
    throw std::runtime_error(path.string() + ": not a readable PNG (" + image.message + ")");
  image.format = PNG_FORMAT_RGB;
  RgbImage rgb{static_cast<int>(image.width), static_cast<int>(image.height), {}};
  rgb.pixels.resize(PNG_IMAGE_SIZE(image));
  if (png_image_finish_read(&image, nullptr, rgb.pixels.data(), 0, nullptr) == 0) {
    const std::string why = image.message;
    png_image_free(&image);
    throw std::runtime_error(path.string() + ": cannot decode the PNG (" + why + ")");
  }
  return rgb;
}

std::string av_error(int code) {
  char text[AV_ERROR_MAX_STRING_SIZE] = {};
  av_strerror(code, text, sizeof text);
  return text;
}

void check_av(int code, const fs::path& out, const char* what) {
  if (code < 0) throw std::runtime_error(out.string() + ": " + what + " failed: " + av_error(code));
}

struct FormatDeleter {
  void operator()(AVFormatContext* f) const {
    if (f->pb != nullptr) avio_closep(&f->pb);
    avformat_free_context(f);
  }
};
struct CodecDeleter {
  void operator()(AVCodecContext* c) const { avcodec_free_context(&c); }
};
struct FrameDeleter {
  void operator()(AVFrame* f) const { av_frame_free(&f); }
};
struct PacketDeleter {
  void operator()(AVPacket* p) const { av_packet_free(&p); }
};
struct ScaleDeleter {
  void operator()(SwsContext* s) const { sws_freeContext(s); }
};

/// The encoder's side of the video: one VP9 stream in a WebM container at `path`.
class WebmEncoder {
 public:
  WebmEncoder(const fs::path& path, int width, int height, const MovieOptions& options)
      : path_(path) {
    const AVCodec* codec = avcodec_find_encoder_by_name("libvpx-vp9");
    if (codec == nullptr)
      throw std::runtime_error(
          "this libavcodec has no VP9 encoder (libvpx-vp9): install Debian's libavcodec59");
    AVFormatContext* format = nullptr;
    check_av(avformat_alloc_output_context2(&format, nullptr, "webm", path.c_str()), path,
             "setting up the WebM container");
    format_.reset(format);
    stream_ = avformat_new_stream(format, nullptr);
    codec_.reset(avcodec_alloc_context3(codec));
    if (stream_ == nullptr || !codec_) throw std::runtime_error(path.string() + ": out of memory");
    AVCodecContext* c = codec_.get();
    c->width = width;
    c->height = height;
    c->pix_fmt = AV_PIX_FMT_YUV420P;
    c->time_base = av_d2q(1.0 / options.frames_per_second, 100000);
    c->framerate = av_inv_q(c->time_base);
    c->bit_rate = 0;  // constant quality: crf alone sets the size
    c->thread_count = 2;
    if ((format->oformat->flags & AVFMT_GLOBALHEADER) != 0) c->flags |= AV_CODEC_FLAG_GLOBAL_HEADER;
    av_opt_set_int(c->priv_data, "crf", options.quality, 0);
    // libvpx's fast "good" setting: a 100-frame 1200x600 series encodes in seconds.
    av_opt_set(c->priv_data, "deadline", "good", 0);
    av_opt_set_int(c->priv_data, "cpu-used", 5, 0);
    av_opt_set_int(c->priv_data, "row-mt", 1, 0);
    check_av(avcodec_open2(c, codec, nullptr), path, "opening the VP9 encoder");
    check_av(avcodec_parameters_from_context(stream_->codecpar, c), path,
             "the stream's parameters");
    stream_->time_base = c->time_base;
    check_av(avio_open(&format->pb, path.c_str(), AVIO_FLAG_WRITE), path, "opening the file");
    check_av(avformat_write_header(format, nullptr), path, "writing the WebM header");
    frame_.reset(av_frame_alloc());
    packet_.reset(av_packet_alloc());
    if (!frame_ || !packet_) throw std::runtime_error(path.string() + ": out of memory");
    frame_->format = c->pix_fmt;
    frame_->width = width;
    frame_->height = height;
    check_av(av_frame_get_buffer(frame_.get(), 0), path, "allocating a frame");
  }

  /// Scales (to the video's size) and converts one RGB image, then encodes it.
  void add(const RgbImage& rgb) {
    AVCodecContext* c = codec_.get();
    scale_.reset(sws_getCachedContext(scale_.release(), rgb.width, rgb.height, AV_PIX_FMT_RGB24,
                                      c->width, c->height, AV_PIX_FMT_YUV420P, SWS_BICUBIC, nullptr,
                                      nullptr, nullptr));
    if (!scale_) throw std::runtime_error(path_.string() + ": no colour conversion for a frame");
    check_av(av_frame_make_writable(frame_.get()), path_, "preparing a frame");
    const std::uint8_t* source[1] = {rgb.pixels.data()};
    const int stride[1] = {3 * rgb.width};
    sws_scale(scale_.get(), source, stride, 0, rgb.height, frame_->data, frame_->linesize);
    frame_->pts = next_pts_++;
    check_av(avcodec_send_frame(c, frame_.get()), path_, "encoding a frame");
    drain();
  }

  /// Flushes the encoder and writes the container's end.
  void finish() {
    check_av(avcodec_send_frame(codec_.get(), nullptr), path_, "flushing the encoder");
    drain();
    check_av(av_write_trailer(format_.get()), path_, "writing the WebM index");
    check_av(avio_closep(&format_->pb), path_, "closing the file");
  }

 private:
  void drain() {
    for (;;) {
      const int got = avcodec_receive_packet(codec_.get(), packet_.get());
      if (got == AVERROR(EAGAIN) || got == AVERROR_EOF) return;
      check_av(got, path_, "encoding");
      av_packet_rescale_ts(packet_.get(), codec_->time_base, stream_->time_base);
      packet_->stream_index = stream_->index;
      check_av(av_interleaved_write_frame(format_.get(), packet_.get()), path_, "writing a frame");
    }
  }

  fs::path path_;
  std::unique_ptr<AVFormatContext, FormatDeleter> format_;
  AVStream* stream_ = nullptr;  // owned by format_
  std::unique_ptr<AVCodecContext, CodecDeleter> codec_;
  std::unique_ptr<AVFrame, FrameDeleter> frame_;
  std::unique_ptr<AVPacket, PacketDeleter> packet_;
  std::unique_ptr<SwsContext, ScaleDeleter> scale_;
  std::int64_t next_pts_ = 0;
};

void sync_file(const fs::path& path) {
  const int fd = ::open(path.c_str(), O_RDONLY);
  if (fd < 0 || ::fsync(fd) != 0) {
    const std::error_code error(errno, std::generic_category());
    if (fd >= 0) ::close(fd);
    throw std::runtime_error(path.string() + ": cannot sync: " + error.message());
  }
  ::close(fd);
}

}  // namespace

std::vector<fs::path> saved_frames(const fs::path& run_directory, const std::string& field) {
  const fs::path index = run_directory / "frames" / "index.csv";
  std::map<double, fs::path> by_time;  // a time drawn again after a restart: its last row
  for (const auto& row : analysis::read_index(index)) {
    const auto f = row.find("field");
    const auto file = row.find("file");
    if (f == row.end() || f->second != field || file == row.end()) continue;
    by_time[analysis::index_number(row, "time", index)] = run_directory / "frames" / file->second;
  }
  if (by_time.empty())
    throw std::runtime_error(index.string() + ": no saved frame of field '" + field +
                             "' (the scene's render section saves the fields it lists)");
  std::vector<fs::path> frames;
  for (const auto& [time, path] : by_time) {
    if (!fs::is_regular_file(path))
      throw std::runtime_error(path.string() + ": listed in " + index.string() + " but missing");
    frames.push_back(path);
  }
  return frames;
}

MovieSummary write_movie(const std::vector<fs::path>& frames, const fs::path& out,
                         const MovieOptions& options) {
  if (!(options.frames_per_second >= 0.1 && options.frames_per_second <= 120.0))
    throw std::invalid_argument("fps: must be between 0.1 and 120, got " +
                                std::to_string(options.frames_per_second));
  if (options.quality < 0 || options.quality > 63)
    throw std::invalid_argument("quality: must be between 0 and 63, got " +
                                std::to_string(options.quality));
  if (frames.empty()) throw std::invalid_argument("frames: no frame to encode");
  av_log_set_level(AV_LOG_ERROR);  // libvpx's version banner is no news to the user
  const RgbImage first = read_png(frames.front());
  // yuv420p halves the chroma planes: even sizes.
  const int width = first.width & ~1;
  const int height = first.height & ~1;
  if (width < 2 || height < 2)
    throw std::runtime_error(frames.front().string() + ": " + std::to_string(first.width) + "x" +
                             std::to_string(first.height) + " px is too small for a video");
  // A name of its own per call (two requests may encode one field at once), in the run
  // directories' temporary pattern (NAME.tmp.*), which a restart clears.
  static std::atomic<unsigned> counter{0};
  std::string temporary_name = out.filename().string();
  temporary_name += ".tmp." + std::to_string(::getpid()) + "." + std::to_string(counter++);
  const fs::path temporary = out.parent_path() / temporary_name;
  try {
    WebmEncoder encoder(temporary, width, height, options);
    encoder.add(first);
    for (std::size_t i = 1; i < frames.size(); ++i) encoder.add(read_png(frames[i]));
    encoder.finish();
    sync_file(temporary);
    fs::rename(temporary, out);
  } catch (...) {
    std::error_code ignored;
    fs::remove(temporary, ignored);
    throw;
  }
  MovieSummary summary;
  summary.frames = frames.size();
  summary.width = width;
  summary.height = height;
  summary.duration_seconds = static_cast<double>(frames.size()) / options.frames_per_second;
  summary.bytes = fs::file_size(out);
  return summary;
}

}  // namespace sphles::render
