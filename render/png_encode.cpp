// SPDX-License-Identifier: GPL-3.0-or-later
#include "render/png_encode.hpp"

#include <png.h>

#include <csetjmp>
#include <stdexcept>
#include <string>

namespace sphles::render {
namespace {

void append_bytes(png_structp png, png_bytep data, png_size_t length) {
  auto* out = static_cast<std::vector<unsigned char>*>(png_get_io_ptr(png));
  out->insert(out->end(), data, data + length);
}

void flush_nothing(png_structp) {}

int filter_flags(PngFilter filter) {
  switch (filter) {
    case PngFilter::None:
      return PNG_FILTER_NONE;
    case PngFilter::Sub:
      return PNG_FILTER_SUB;
    case PngFilter::Up:
      return PNG_FILTER_UP;
    case PngFilter::Paeth:
      return PNG_FILTER_PAETH;
    case PngFilter::Adaptive:
      return PNG_ALL_FILTERS;
  }
  return PNG_ALL_FILTERS;
}

// Only trivially destructible locals here: libpng reports errors by longjmp to this frame.
bool encode(const unsigned char* rgb, png_bytep* rows, int width, int height, int level,
            int filters, std::vector<unsigned char>* out) {
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  if (png == nullptr) return false;
  png_infop info = png_create_info_struct(png);
  if (info == nullptr || setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    return false;
  }
  png_set_write_fn(png, out, append_bytes, flush_nothing);
  png_set_compression_level(png, level);
  png_set_filter(png, PNG_FILTER_TYPE_BASE, filters);
  png_set_IHDR(png, info, static_cast<png_uint_32>(width), static_cast<png_uint_32>(height), 8,
               PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_BASE,
               PNG_FILTER_TYPE_BASE);
  const std::size_t row_bytes = static_cast<std::size_t>(width) * 3;
  for (int y = 0; y < height; ++y) {
    // PNG rows go top first; the input is bottom row first.
    rows[y] = const_cast<png_bytep>(rgb + static_cast<std::size_t>(height - 1 - y) * row_bytes);
  }
  png_set_rows(png, info, rows);
  png_write_png(png, info, PNG_TRANSFORM_IDENTITY, nullptr);
  png_destroy_write_struct(&png, &info);
  return true;
}

}  // namespace

std::vector<unsigned char> encode_png_rgb(std::span<const unsigned char> rgb_bottom_up, int width,
                                          int height, int compression_level, PngFilter filter) {
  if (width <= 0 || height <= 0 ||
      rgb_bottom_up.size() !=
          static_cast<std::size_t>(width) * static_cast<std::size_t>(height) * 3) {
    throw std::invalid_argument("encode_png_rgb: pixel count does not match width x height");
  }
  std::vector<unsigned char> out;
  out.reserve(rgb_bottom_up.size() / 4);
  std::vector<png_bytep> rows(static_cast<std::size_t>(height));
  if (!encode(rgb_bottom_up.data(), rows.data(), width, height, compression_level,
              filter_flags(filter), &out)) {
    throw std::runtime_error("encode_png_rgb: libpng failed for " + std::to_string(width) + "x" +
                             std::to_string(height));
  }
  return out;
}

}  // namespace sphles::render
