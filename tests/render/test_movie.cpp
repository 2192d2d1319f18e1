// SPDX-License-Identifier: GPL-3.0-or-later
// The WebM videos of saved series (render/movie.hpp), read back with libavformat/libavcodec's
// decoder (frame count, size, rate, brightness against the PNGs encoded), and the labels the
// pictures print.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <iterator>
#include <stdexcept>
#include <string>
#include <vector>

#include "render/movie.hpp"
#include "render/png_encode.hpp"
#include "render/vtk_window.hpp"
#include "tests/scratch_directory.hpp"

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavformat/avformat.h>
}

namespace {

namespace fs = std::filesystem;
using sphles::render::MovieOptions;

/// A frame whose grey level is `level` everywhere: a video of them has known luma per frame.
void write_grey_png(const fs::path& path, int width, int height, unsigned char level) {
  const std::vector<unsigned char> rgb(static_cast<std::size_t>(3 * width * height), level);
  const auto png =
      sphles::render::encode_png_rgb(rgb, width, height, 1, sphles::render::PngFilter::None);
  std::ofstream(path, std::ios::binary)
      .write(reinterpret_cast<const char*>(png.data()), static_cast<std::streamsize>(png.size()));
}

struct Decoded {
  std::string codec;
  int width = 0, height = 0;
  double frame_rate = 0.0;
  std::vector<double> mean_luma;  // per decoded frame, of the Y plane
};

/// The video as a player sees it: demuxed and decoded by FFmpeg's own VP9 decoder.
Decoded decode(const fs::path& path) {
  AVFormatContext* format = nullptr;
  if (avformat_open_input(&format, path.c_str(), nullptr, nullptr) < 0)
    throw std::runtime_error("cannot open " + path.string());
  avformat_find_stream_info(format, nullptr);
  const AVStream* stream = format->streams[0];
  const AVCodec* codec = avcodec_find_decoder(stream->codecpar->codec_id);
  AVCodecContext* context = avcodec_alloc_context3(codec);
  avcodec_parameters_to_context(context, stream->codecpar);
  avcodec_open2(context, codec, nullptr);
  Decoded d{avcodec_get_name(stream->codecpar->codec_id),
            stream->codecpar->width,
            stream->codecpar->height,
            av_q2d(stream->avg_frame_rate),
            {}};
  AVPacket* packet = av_packet_alloc();
  AVFrame* frame = av_frame_alloc();
  auto receive = [&] {
    while (avcodec_receive_frame(context, frame) == 0) {
      double sum = 0.0;
      for (int y = 0; y < frame->height; ++y)
        for (int x = 0; x < frame->width; ++x) sum += frame->data[0][y * frame->linesize[0] + x];
      d.mean_luma.push_back(sum / (frame->width * frame->height));
    }
  };
  while (av_read_frame(format, packet) >= 0) {
    avcodec_send_packet(context, packet);
    av_packet_unref(packet);
    receive();
  }
  avcodec_send_packet(context, nullptr);
  receive();
  av_frame_free(&frame);
  av_packet_free(&packet);
  avcodec_free_context(&context);
  avformat_close_input(&format);
  return d;
}

/// BT.601 limited-range luma of a grey level (swscale's RGB → YUV420P).
double luma_of_grey(unsigned char level) {
  return 16.0 + 219.0 * level / 255.0;
}

class Movie : public ::testing::Test {
 protected:
  /// frames/ with `count` grey frames of width x height (the last `resized` ones twice as large),
  /// listed in frames/index.csv; returns the grey levels in time order.
  std::vector<unsigned char> make_series(int count, int width, int height, int resized = 0) {
    fs::create_directories(dir_ / "frames");
    std::ofstream index(dir_ / "frames" / "index.csv");
    index << "time,step,field,file\n";
    std::vector<unsigned char> levels;
    for (int i = 0; i < count; ++i) {
      const auto level = static_cast<unsigned char>(20 + 200 * i / (count - 1));
      levels.push_back(level);
      const std::string file = "omega2_t" + std::to_string(i) + ".png";
      const int scale = i >= count - resized ? 2 : 1;
      write_grey_png(dir_ / "frames" / file, scale * width, scale * height, level);
      index << 0.5 * i << "," << 10 * i << ",omega2," << file << "\n";
      index << 0.5 * i << "," << 10 * i << ",tau_sfs,tau_sfs_t" << i << ".png\n";
    }
    return levels;
  }

  void SetUp() override {
    dir_ = sphles::scratch::scratch_directory(
        "movie", ::testing::UnitTest::GetInstance()->current_test_info()->name());
  }

  fs::path dir_;
};

TEST_F(Movie, TheSeriesPlaysBackAsWrittenFrameByFrame) {
  const auto levels = make_series(12, 101, 61, 2);  // odd sizes; the last two frames larger
  const auto frames = sphles::render::saved_frames(dir_, "omega2");
  ASSERT_EQ(frames.size(), 12u);
  const fs::path out = dir_ / "omega2.webm";
  MovieOptions options;
  options.frames_per_second = 8.0;
  options.quality = 10;
  const auto summary = sphles::render::write_movie(frames, out, options);
  EXPECT_EQ(summary.frames, 12u);
  EXPECT_EQ(summary.width, 100);  // yuv420p: rounded down to even
  EXPECT_EQ(summary.height, 60);
  EXPECT_DOUBLE_EQ(summary.duration_seconds, 1.5);
  EXPECT_EQ(summary.bytes, fs::file_size(out));
  EXPECT_EQ(std::distance(fs::directory_iterator(dir_), fs::directory_iterator()), 2)
      << "frames/ and the video, no temporary file";

  const Decoded d = decode(out);
  EXPECT_EQ(d.codec, "vp9");
  EXPECT_EQ(d.width, 100);
  EXPECT_EQ(d.height, 60);
  EXPECT_NEAR(d.frame_rate, 8.0, 1e-9);
  ASSERT_EQ(d.mean_luma.size(), 12u);
  for (std::size_t i = 0; i < levels.size(); ++i)
    EXPECT_NEAR(d.mean_luma[i], luma_of_grey(levels[i]), 2.0) << "frame " << i;
}

TEST_F(Movie, ATimeDrawnAgainAfterARestartIsTakenOnceFromItsLastRow) {
  make_series(3, 16, 16);
  write_grey_png(dir_ / "frames" / "omega2_again.png", 16, 16, 0);
  std::ofstream(dir_ / "frames" / "index.csv", std::ios::app) << "0.5,10,omega2,omega2_again.png\n";
  const auto frames = sphles::render::saved_frames(dir_, "omega2");
  ASSERT_EQ(frames.size(), 3u);
  EXPECT_EQ(frames[1].filename(), "omega2_again.png");
  EXPECT_EQ(frames[2].filename(), "omega2_t2.png");
}

TEST_F(Movie, MissingFramesBadOptionsAndBrokenImagesAreErrorsThatLeaveNoFile) {
  make_series(3, 16, 16);
  try {
    sphles::render::saved_frames(dir_, "combined");
    FAIL() << "no combined frames listed";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("no saved frame of field 'combined'"), std::string::npos)
        << e.what();
  }
  fs::remove(dir_ / "frames" / "omega2_t1.png");
  try {
    sphles::render::saved_frames(dir_, "omega2");
    FAIL() << "a listed frame is missing";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("omega2_t1.png: listed in"), std::string::npos)
        << e.what();
  }
  std::ofstream(dir_ / "frames" / "omega2_t1.png") << "not a png";
  const auto frames = sphles::render::saved_frames(dir_, "omega2");
  const fs::path out = dir_ / "broken.webm";
  try {
    sphles::render::write_movie(frames, out, MovieOptions{});
    FAIL() << "a broken frame";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("omega2_t1.png: not a readable PNG"), std::string::npos)
        << e.what();
  }
  EXPECT_FALSE(fs::exists(out));
  EXPECT_EQ(std::distance(fs::directory_iterator(dir_), fs::directory_iterator()), 1)
      << "frames/ alone, no temporary file";
  MovieOptions bad;
  bad.frames_per_second = 0.0;
  EXPECT_THROW(sphles::render::write_movie(frames, out, bad), std::invalid_argument);
  bad = MovieOptions{};
  bad.quality = 64;
  EXPECT_THROW(sphles::render::write_movie(frames, out, bad), std::invalid_argument);
}

}  // namespace

namespace {

// The pictures print the docs' notation (DejaVu Sans has the glyphs; scripts/setup.sh installs
// fonts-dejavu-core); the files keep the ASCII names scripts match.
TEST(PictureLabels, UseTheGreekLettersAndSuperscriptsOfTheDocs) {
  using sphles::analysis::SliceField;
  namespace detail = sphles::render::detail;
  EXPECT_EQ(detail::field_label(SliceField::VorticitySquared), "\u03c9\u00b2 [s\u207b\u00b2]");
  EXPECT_EQ(detail::field_label(SliceField::SubfilterStressNorm), "|\u03c4_SFS| [Pa]");
  EXPECT_EQ(detail::field_label(SliceField::EddyViscosity), "\u03bd_t [m\u00b2/s]");
  EXPECT_EQ(sphles::analysis::slice_field_units(SliceField::VorticitySquared), "1/s^2");
}

}  // namespace
