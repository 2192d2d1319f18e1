// SPDX-License-Identifier: GPL-3.0-or-later
#include "server/json_writer.hpp"

#include <array>
#include <charconv>
#include <cmath>
#include <nlohmann/json.hpp>

namespace sphles::server {

namespace {

/// Room for any number std::to_chars writes (a double's shortest form is at most 24 chars).
constexpr std::size_t kNumberChars = 32;

std::string limit_text(std::size_t max_bytes) {
  return "the server's response limit of " + std::to_string(max_bytes) + " bytes";
}

}  // namespace

JsonWriter::JsonWriter(std::size_t max_bytes, std::string what, std::string hint)
    : max_bytes_(max_bytes), what_(std::move(what)), hint_(std::move(hint)) {}

void JsonWriter::expect_at_least(std::size_t bytes) {
  if (bytes > max_bytes_)
    throw ApiError(507, what_ + " needs at least " + std::to_string(bytes) + " bytes, more than " +
                            limit_text(max_bytes_) + hint_);
  text_.reserve(bytes);
}

void JsonWriter::check() {
  if (text_.size() > max_bytes_)
    throw ApiError(507, what_ + " is larger than " + limit_text(max_bytes_) + hint_);
}

void JsonWriter::append(std::string_view text) {
  text_.append(text);
  check();
}

void JsonWriter::separate() {
  if (after_key_) {
    after_key_ = false;
    return;
  }
  if (first_.empty()) return;
  if (!first_.back()) text_.push_back(',');
  first_.back() = false;
}

JsonWriter& JsonWriter::begin_object() {
  separate();
  text_.push_back('{');
  first_.push_back(true);
  return *this;
}

JsonWriter& JsonWriter::end_object() {
  text_.push_back('}');
  first_.pop_back();
  check();
  return *this;
}

JsonWriter& JsonWriter::begin_array() {
  separate();
  text_.push_back('[');
  first_.push_back(true);
  return *this;
}

JsonWriter& JsonWriter::end_array() {
  text_.push_back(']');
  first_.pop_back();
  check();
  return *this;
}

JsonWriter& JsonWriter::key(std::string_view name) {
  value(name);
  text_.push_back(':');
  after_key_ = true;
  return *this;
}

void JsonWriter::append_number(std::string& out, double number) {
  if (!std::isfinite(number)) {
    out += "null";
    return;
  }
  std::array<char, kNumberChars> buffer{};
  const auto [end, ec] = std::to_chars(buffer.data(), buffer.data() + buffer.size(), number);
  const std::string_view text(buffer.data(), ec == std::errc() ? end - buffer.data() : 0);
  out += text;
  // nlohmann marks an integral double as one ("1.0"); keep the same text.
  if (text.find_first_of(".e") == std::string_view::npos) out += ".0";
}

JsonWriter& JsonWriter::value(double number) {
  separate();
  append_number(text_, number);
  check();
  return *this;
}

JsonWriter& JsonWriter::value(std::uint64_t number) {
  separate();
  std::array<char, kNumberChars> buffer{};
  const auto [end, ec] = std::to_chars(buffer.data(), buffer.data() + buffer.size(), number);
  append(std::string_view(buffer.data(), ec == std::errc() ? end - buffer.data() : 0));
  return *this;
}

JsonWriter& JsonWriter::value(std::int64_t number) {
  separate();
  std::array<char, kNumberChars> buffer{};
  const auto [end, ec] = std::to_chars(buffer.data(), buffer.data() + buffer.size(), number);
  append(std::string_view(buffer.data(), ec == std::errc() ? end - buffer.data() : 0));
  return *this;
}

JsonWriter& JsonWriter::value(bool flag) {
  separate();
  append(flag ? "true" : "false");
  return *this;
}

JsonWriter& JsonWriter::value(std::string_view text) {
  separate();
  append(dump(nlohmann::json(text)));  // short strings (names, files): nlohmann escapes them
  return *this;
}

JsonWriter& JsonWriter::null() {
  separate();
  append("null");
  return *this;
}

JsonWriter& JsonWriter::raw(std::string_view json) {
  separate();
  append(json);
  return *this;
}

}  // namespace sphles::server
