// SPDX-License-Identifier: GPL-3.0-or-later
#include "server/history.hpp"

#include <sys/stat.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>
#include <memory>
#include <string_view>

#include "server/api_json.hpp"
#include "server/json_writer.hpp"

namespace sphles::server {

namespace fs = std::filesystem;

namespace {

constexpr std::size_t kChunkBytes = 1u << 20;     // read at a time
constexpr std::size_t kMaxLineBytes = 1u << 20;   // longer lines are not rows: skipped
constexpr std::uint64_t kMarkBytes = 256u << 10;  // index granularity: a page reads at most this
                                                  // much before its first row
constexpr std::size_t kNoColumn = static_cast<std::size_t>(-1);
constexpr std::size_t kMinBytesPerNumber = 2;  // a digit and a comma

struct FileIdentity {
  std::uint64_t device = 0, inode = 0, size = 0;
};

/// nullopt if the file does not exist; ApiError 500 for any other failure.
std::optional<FileIdentity> identify(const fs::path& file) {
  struct stat st {};
  if (::stat(file.c_str(), &st) != 0) {
    if (errno == ENOENT || errno == ENOTDIR) return std::nullopt;
    throw ApiError(500, "cannot read " + file.filename().string() + ": " + std::strerror(errno));
  }
  return FileIdentity{static_cast<std::uint64_t>(st.st_dev), static_cast<std::uint64_t>(st.st_ino),
                      static_cast<std::uint64_t>(st.st_size)};
}

/// The complete lines of bytes [from, to) of a file, in chunks: a line without its '\n' yet (the
/// writer is still at it) is not returned; nor are lines longer than kMaxLineBytes.
class LineReader {
 public:
  LineReader(const fs::path& file, std::uint64_t from, std::uint64_t to)
      : name_(file.filename().string()), offset_(from), remaining_(to > from ? to - from : 0) {
    file_ = std::fopen(file.c_str(), "rb");
    if (!file_) {
      if (errno == ENOENT) return;
      throw ApiError(500, "cannot open " + name_ + ": " + std::strerror(errno));
    }
    if (from > 0 && std::fseek(file_, static_cast<long>(from), SEEK_SET) != 0)
      throw ApiError(500, "cannot seek in " + name_ + ": " + std::strerror(errno));
  }
  ~LineReader() {
    if (file_) std::fclose(file_);
  }
  LineReader(const LineReader&) = delete;
  LineReader& operator=(const LineReader&) = delete;

  bool is_open() const { return file_ != nullptr; }

  struct Line {
    std::string_view text;
    std::uint64_t offset = 0;  // of its first byte
    std::uint64_t end = 0;     // just after its '\n'
  };

  std::optional<Line> next() {
    while (file_) {
      const std::size_t newline = buffer_.find('\n', pos_);
      if (newline != std::string::npos) {
        Line line{std::string_view(buffer_).substr(pos_, newline - pos_), offset_ + pos_,
                  offset_ + newline + 1};
        pos_ = newline + 1;
        if (skipping_) {  // the tail of an over-long line
          skipping_ = false;
          continue;
        }
        if (!line.text.empty() && line.text.back() == '\r') line.text.remove_suffix(1);
        if (line.text.size() > kMaxLineBytes) continue;
        return line;
      }
      // Keep the partial line, read on.
      offset_ += pos_;
      buffer_.erase(0, pos_);
      pos_ = 0;
      if (buffer_.size() > kMaxLineBytes) {
        offset_ += buffer_.size();
        buffer_.clear();
        skipping_ = true;
      }
      if (remaining_ == 0) return std::nullopt;
      const std::size_t want =
          static_cast<std::size_t>(std::min<std::uint64_t>(kChunkBytes, remaining_));
      const std::size_t old = buffer_.size();
      buffer_.resize(old + want);
      const std::size_t got = std::fread(buffer_.data() + old, 1, want, file_);
      buffer_.resize(old + got);
      remaining_ -= got;
      if (got < want) {
        if (std::ferror(file_)) throw ApiError(500, "cannot read " + name_ + ": read error");
        remaining_ = 0;
      }
      if (got == 0) return std::nullopt;
    }
    return std::nullopt;
  }

 private:
  std::string name_;
  std::FILE* file_ = nullptr;
  std::string buffer_;
  std::size_t pos_ = 0;
  std::uint64_t offset_;  // of buffer_[0]
  std::uint64_t remaining_;
  bool skipping_ = false;
};

std::vector<std::string_view> split(std::string_view line, char separator) {
  std::vector<std::string_view> fields;
  std::size_t start = 0;
  while (true) {
    const std::size_t end = line.find(separator, start);
    fields.push_back(line.substr(start, end == std::string_view::npos ? end : end - start));
    if (end == std::string_view::npos) break;
    start = end + 1;
  }
  return fields;
}

std::optional<double> parse_number(std::string_view text) {
  while (!text.empty() && (text.back() == '\r' || text.back() == ' ')) text.remove_suffix(1);
  if (text == "nan" || text == "-nan" || text == "NaN") return std::nan("");
  double value = 0.0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (ec != std::errc() || end != text.data() + text.size()) return std::nullopt;
  return value;
}

/// Appends the row's numbers to `out`; false (and `out` unchanged) if the line is not a row of
/// `columns` numbers (a half-written line, say).
bool parse_row(std::string_view line, std::size_t columns, std::vector<double>& out) {
  if (line.empty()) return false;
  const std::size_t old = out.size();
  std::size_t start = 0;
  for (std::size_t k = 0; k < columns; ++k) {
    const std::size_t end = line.find(',', start);
    const bool last = k + 1 == columns;
    if ((end == std::string_view::npos) != last) {
      out.resize(old);
      return false;
    }
    const std::optional<double> v =
        parse_number(line.substr(start, last ? std::string_view::npos : end - start));
    if (!v) {
      out.resize(old);
      return false;
    }
    out.push_back(*v);
    start = end + 1;
  }
  return true;
}

std::uint64_t as_step(double value) {
  return value > 0.0 ? static_cast<std::uint64_t>(value) : 0;
}

constexpr const char* kPagingHint =
    "; page with limit= and since_step=, or decimate with max_points=";

std::string with_limits_hint(const std::string& text) {
  return text + kPagingHint;
}

}  // namespace

// --- the index --------------------------------------------------------------------------------

struct SeriesIndexCache::Index {
  FileIdentity identity;
  std::uint64_t indexed = 0;     // bytes covered: the end of the last complete line read
  std::uint64_t data_start = 0;  // just after the header
  bool has_header = false;
  std::vector<std::string> columns;
  std::size_t step_column = kNoColumn;
  bool monotonic = true;  // every row's step above the previous row's
  std::optional<std::uint64_t> last_step;
  std::uint64_t rows = 0;  // rows that parse
  struct Mark {
    std::uint64_t step, offset, row;  // a row's step, its first byte, its number
  };
  std::vector<Mark> marks;  // one at least every kMarkBytes

  void extend(const fs::path& file, std::uint64_t to) {
    LineReader reader(file, indexed, to);
    if (!reader.is_open()) return;
    std::vector<double> row;
    while (const auto line = reader.next()) {
      indexed = line->end;
      if (!has_header) {
        has_header = true;
        data_start = line->end;
        for (const auto f : split(line->text, ',')) columns.emplace_back(f);
        for (std::size_t k = 0; k < columns.size(); ++k)
          if (columns[k] == "step") step_column = k;
        if (step_column == kNoColumn) monotonic = false;
        continue;
      }
      row.clear();
      if (!parse_row(line->text, columns.size(), row)) continue;
      if (step_column != kNoColumn) {
        const std::uint64_t step = as_step(row[step_column]);
        if (last_step && step <= *last_step) monotonic = false;
        last_step = step;
        if (marks.empty() || line->offset - marks.back().offset >= kMarkBytes)
          marks.push_back({step, line->offset, rows});
      }
      ++rows;
    }
  }
};

std::shared_ptr<const SeriesIndexCache::Index> SeriesIndexCache::update(const fs::path& file) {
  const std::optional<FileIdentity> id = identify(file);
  if (!id) return nullptr;
  std::shared_ptr<Index> known;
  {
    std::lock_guard lock(mutex_);
    for (auto it = files_.begin(); it != files_.end(); ++it)
      if (it->first == file) {
        known = it->second;
        files_.splice(files_.begin(), files_, it);
        break;
      }
  }
  const bool same = known && known->identity.device == id->device &&
                    known->identity.inode == id->inode && id->size >= known->indexed;
  if (same && known->indexed == id->size) return known;
  // Extend a copy (outside the lock: the first read of a long file takes a while).
  auto index = same ? std::make_shared<Index>(*known) : std::make_shared<Index>();
  index->identity = *id;
  index->extend(file, id->size);
  std::lock_guard lock(mutex_);
  std::erase_if(files_, [&](const auto& entry) { return entry.first == file; });
  files_.emplace_front(file, index);
  while (files_.size() > kMaxFiles) files_.pop_back();
  return index;
}

// --- time series --------------------------------------------------------------------------------

namespace {

/// Selected rows, row-major.
struct SeriesRows {
  std::vector<double> values;
  std::size_t rows = 0;
  bool more = false;
  std::size_t stride = 1;
};

/// Keeps the rows of a decimation: every `stride`-th from the first, and the last.
class Decimator {
 public:
  Decimator(std::size_t columns, std::size_t stride) : columns_(columns), stride_(stride) {}
  void add(const double* row) {
    if (position_ % stride_ == 0) {
      out_.values.insert(out_.values.end(), row, row + columns_);
      ++out_.rows;
      last_is_kept_ = true;
    } else {
      last_.assign(row, row + columns_);
      last_is_kept_ = false;
    }
    ++position_;
  }
  SeriesRows finish() {
    if (!last_is_kept_ && !last_.empty()) {
      out_.values.insert(out_.values.end(), last_.begin(), last_.end());
      ++out_.rows;
    }
    out_.stride = stride_;
    return std::move(out_);
  }

 private:
  std::size_t columns_, stride_;
  std::size_t position_ = 0;
  SeriesRows out_;
  std::vector<double> last_;
  bool last_is_kept_ = true;
};

/// Stride that keeps at most `max_points` of `count` rows, first and last included.
std::size_t stride_for(std::uint64_t count, std::size_t max_points) {
  if (count <= max_points) return 1;
  if (max_points <= 2) return static_cast<std::size_t>(count);  // first, then the last
  const std::uint64_t gaps = max_points - 2;  // multiples of the stride after the first
  return static_cast<std::size_t>((count - 1 + gaps - 1) / gaps);
}

/// Rows of a file whose steps only increase (or without steps): read from the index mark before
/// the first wanted row, stop after the page.
SeriesRows read_monotonic(const fs::path& file, const SeriesIndexCache::Index& index,
                          const HistoryQuery& q, std::size_t cap) {
  const std::size_t n = index.columns.size();
  std::uint64_t start = index.data_start, row_base = 0;
  if (q.since_step && !index.marks.empty()) {
    const auto after = std::upper_bound(
        index.marks.begin(), index.marks.end(), *q.since_step,
        [](std::uint64_t since, const SeriesIndexCache::Index::Mark& m) { return since < m.step; });
    if (after != index.marks.begin()) {
      start = std::prev(after)->offset;
      row_base = std::prev(after)->row;
    }
  }
  LineReader reader(file, start, index.indexed);
  std::vector<double> row;
  std::optional<Decimator> decimator;
  SeriesRows out;
  std::uint64_t seen = 0;  // rows from `start` on, wanted or not
  while (const auto line = reader.next()) {
    row.clear();
    if (!parse_row(line->text, n, row)) continue;
    ++seen;
    if (q.since_step && index.step_column != kNoColumn &&
        as_step(row[index.step_column]) <= *q.since_step)
      continue;
    if (q.max_points) {
      if (!decimator) {  // the first wanted row: the index knows how many follow
        const std::uint64_t position = row_base + seen - 1;
        const std::uint64_t count = index.rows > position ? index.rows - position : 1;
        decimator.emplace(n, stride_for(count, *q.max_points));
      }
      decimator->add(row.data());
      continue;
    }
    if (out.rows == cap) {
      out.more = true;
      break;
    }
    out.values.insert(out.values.end(), row.begin(), row.end());
    ++out.rows;
  }
  if (decimator) return decimator->finish();
  return out;
}

/// Rows of a file that repeats steps (a restart without a final checkpoint): later rows win, so
/// every row must be seen before any is final. Keeps at most limits.max_rows rows.
SeriesRows read_with_repeats(const fs::path& file, const SeriesIndexCache::Index& index,
                             const HistoryQuery& q, std::size_t cap, const ResponseLimits& limits) {
  const std::size_t n = index.columns.size();
  const std::size_t sc = index.step_column;
  LineReader reader(file, index.data_start, index.indexed);
  std::vector<double> kept;  // row-major, steps increasing
  std::size_t rows = 0;
  std::vector<double> row;
  while (const auto line = reader.next()) {
    row.clear();
    if (!parse_row(line->text, n, row)) continue;
    const std::uint64_t step = as_step(row[sc]);
    while (rows > 0 && as_step(kept[(rows - 1) * n + sc]) >= step) --rows;
    kept.resize(rows * n);
    if (q.since_step && step <= *q.since_step) continue;
    if (rows == limits.max_rows)
      throw ApiError(507, with_limits_hint("timeseries.csv repeats steps and has more than " +
                                           std::to_string(limits.max_rows) +
                                           " rows to sort out (the server's row limit)"));
    kept.insert(kept.end(), row.begin(), row.end());
    ++rows;
  }
  SeriesRows out;
  if (q.max_points) {
    Decimator d(n, stride_for(rows, *q.max_points));
    for (std::size_t r = 0; r < rows; ++r) d.add(&kept[r * n]);
    return d.finish();
  }
  out.rows = std::min(rows, cap);
  out.more = rows > cap;
  kept.resize(out.rows * n);
  out.values = std::move(kept);
  return out;
}

}  // namespace

std::string timeseries_answer(const fs::path& file, const HistoryQuery& query,
                              const ResponseLimits& limits, SeriesIndexCache& cache) {
  const std::shared_ptr<const SeriesIndexCache::Index> index = cache.update(file);
  const bool implicit = !query.limit && !query.max_points;
  const std::size_t cap = query.limit.value_or(limits.max_rows);
  SeriesRows rows;
  std::vector<std::string> columns;
  std::size_t step_column = kNoColumn;
  if (index && !index->columns.empty()) {
    columns = index->columns;
    step_column = index->step_column;
    rows = index->monotonic ? read_monotonic(file, *index, query, cap)
                            : read_with_repeats(file, *index, query, cap, limits);
  }
  if (implicit && rows.more)
    throw ApiError(
        507,
        with_limits_hint("the time series has more than " + std::to_string(limits.max_rows) +
                         " rows after since_step, the server's limit for one answer"),
        "limit");

  const std::size_t n = columns.size();
  JsonWriter w(limits.max_bytes, "the time series answer of " + std::to_string(rows.rows) + " rows",
               kPagingHint);
  w.expect_at_least(kMinBytesPerNumber * rows.rows * n);
  static const std::map<std::string, std::string, std::less<>> renamed = {
      {"t", "time"}, {"e_v", "kinetic_energy"}};
  w.begin_object();
  w.key("columns").begin_array();
  for (const std::string& c : columns) {
    const auto it = renamed.find(c);
    w.value(std::string_view(it == renamed.end() ? c : it->second));
  }
  w.end_array();
  w.key("data").begin_array();
  for (std::size_t k = 0; k < n; ++k) {
    w.begin_array();
    for (std::size_t r = 0; r < rows.rows; ++r) {
      const double v = rows.values[r * n + k];
      if (k == step_column)
        w.value(as_step(v));
      else
        w.value(v);  // NaN is written as null
    }
    w.end_array();
  }
  w.end_array();
  w.key("more").value(rows.more);
  w.key("next_since_step");
  if (rows.rows > 0 && step_column != kNoColumn)
    w.value(as_step(rows.values[(rows.rows - 1) * n + step_column]));
  else if (query.since_step)
    w.value(*query.since_step);
  else
    w.null();
  w.key("stride").value(static_cast<std::uint64_t>(rows.stride));
  w.end_object();
  return w.take();
}

// --- frames index -------------------------------------------------------------------------------

FramesPage frames_answer(const fs::path& index_file, const std::string& url_base,
                         const HistoryQuery& query, const ResponseLimits& limits) {
  FramesPage page;
  const std::optional<FileIdentity> id = identify(index_file);
  const bool implicit = !query.limit;
  const std::size_t cap = query.limit.value_or(limits.max_rows);
  JsonWriter w(limits.max_bytes, "the frames answer", "; page with limit= and since_step=");
  w.begin_array();
  if (id) {
    LineReader reader(index_file, 0, id->size);
    std::vector<std::string> columns;
    bool header = true;
    std::size_t rows = 0;
    while (const auto line = reader.next()) {
      if (line->text.empty()) continue;
      const std::vector<std::string_view> fields = split(line->text, ',');
      if (header) {
        for (const auto f : fields) columns.emplace_back(f);
        header = false;
        continue;
      }
      if (fields.size() != columns.size()) continue;
      std::optional<std::uint64_t> step;
      for (std::size_t k = 0; k < columns.size(); ++k)
        if (columns[k] == "step")
          if (const auto v = parse_number(fields[k])) step = as_step(*v);
      if (query.since_step && (!step || *step <= *query.since_step)) continue;
      // A page ends between two steps, never inside one (a step has one row per field).
      if (rows >= cap && step != page.last_step) {
        page.more = true;
        break;
      }
      w.begin_object();
      std::optional<std::string_view> file;
      for (std::size_t k = 0; k < columns.size(); ++k) {
        const std::string& column = columns[k];
        const std::optional<double> number = parse_number(fields[k]);
        w.key(column);
        if (column == "step" && number)
          w.value(as_step(*number));
        else if (column == "time" && number)
          w.value(*number);
        else
          w.value(fields[k]);
        if (column == "file") file = fields[k];
      }
      if (file) w.key("url").value(url_base + std::string(*file));
      w.end_object();
      page.last_step = step;
      ++rows;
    }
  }
  w.end_array();
  if (implicit && page.more)
    throw ApiError(
        507,
        with_limits_hint("the frames index has more than " + std::to_string(limits.max_rows) +
                         " rows after since_step, the server's limit for one answer"),
        "limit");
  page.body = w.take();
  return page;
}

}  // namespace sphles::server
