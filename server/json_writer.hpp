// SPDX-License-Identifier: GPL-3.0-or-later
// JSON text written straight into a string, for the server's large bodies (histograms of
// millions of counts, time series of a million rows): no nlohmann document is built, so memory
// is the text itself and nothing is allocated when it is released (an nlohmann array allocates a
// stack as large as itself in its destructor, which is noexcept: out of memory there terminates
// the process). The text never grows past a byte limit: the writer throws ApiError 507 instead.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "server/api_json.hpp"

namespace sphles::server {

class JsonWriter {
 public:
  /// `what` names the body in the 507 message ("the statistics of step 12"), `hint` follows the
  /// limit there (what the client can do about it, e.g. "; lower analysis.histogram_bins").
  JsonWriter(std::size_t max_bytes, std::string what, std::string hint = "");

  /// Throws ApiError 507 if the body is known to need at least `bytes`; otherwise reserves that
  /// much (so the text grows once). std::bad_alloc propagates (callers answer 503).
  void expect_at_least(std::size_t bytes);

  JsonWriter& begin_object();
  JsonWriter& end_object();
  JsonWriter& begin_array();
  JsonWriter& end_array();
  JsonWriter& key(std::string_view name);

  JsonWriter& value(double number);  // NaN and infinities are null, as nlohmann writes them
  JsonWriter& value(std::uint64_t number);
  JsonWriter& value(std::int64_t number);
  JsonWriter& value(int number) { return value(static_cast<std::int64_t>(number)); }
  JsonWriter& value(bool flag);
  JsonWriter& value(std::string_view text);  // escaped; invalid UTF-8 replaced
  JsonWriter& value(const char* text) { return value(std::string_view(text)); }
  JsonWriter& null();
  /// Already serialised JSON (a value from nlohmann, say), inserted as one value.
  JsonWriter& raw(std::string_view json);

  template <class T>
  JsonWriter& array(std::span<const T> values) {
    begin_array();
    for (const T& v : values) value(v);
    return end_array();
  }

  std::size_t size() const { return text_.size(); }
  std::string take() { return std::move(text_); }

  /// The shortest text that reads back as `number` (what nlohmann writes): "0.1", "1.0", "1e-07".
  static void append_number(std::string& out, double number);

 private:
  void separate();  // a comma before the second and later items of an array or object
  void append(std::string_view text);
  void check();

  std::size_t max_bytes_;
  std::string what_, hint_;
  std::string text_;
  std::vector<bool> first_;  // per open array/object: no item written yet
  bool after_key_ = false;
};

}  // namespace sphles::server
