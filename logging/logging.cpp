// SPDX-License-Identifier: GPL-3.0-or-later
#include "logging/logging.hpp"

#include <spdlog/pattern_formatter.h>
#include <spdlog/sinks/base_sink.h>
#include <spdlog/sinks/stdout_color_sinks.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <map>
#include <mutex>
#include <stdexcept>

namespace sphles::logging {

namespace {

// ISO 8601 in UTC with milliseconds, as run.json's times.
constexpr const char* kFilePattern = "%Y-%m-%dT%H:%M:%S.%eZ %& %v";
constexpr const char* kTimestampedPattern = "%Y-%m-%dT%H:%M:%S.%eZ %^%&%$ %n: %v";
constexpr const char* kPlainPattern = "%*%v";

/// '%*' in a plain pattern: "warning: " or "error: " before the message, nothing for info.
class LevelPrefix : public spdlog::custom_flag_formatter {
 public:
  void format(const spdlog::details::log_msg& msg, const std::tm&,
              spdlog::memory_buf_t& dest) override {
    std::string_view prefix;
    if (msg.level == spdlog::level::warn) prefix = "warning: ";
    if (msg.level >= spdlog::level::err && msg.level != spdlog::level::off) prefix = "error: ";
    if (msg.level <= spdlog::level::debug) prefix = "debug: ";
    dest.append(prefix.data(), prefix.data() + prefix.size());
  }
  std::unique_ptr<custom_flag_formatter> clone() const override {
    return std::make_unique<LevelPrefix>();
  }
};

/// '%&': the level as --log-level names it, padded to 5 characters ("warn ", "error").
class LevelName : public spdlog::custom_flag_formatter {
 public:
  void format(const spdlog::details::log_msg& msg, const std::tm&,
              spdlog::memory_buf_t& dest) override {
    static const char* const names[] = {"trace", "debug", "info ", "warn ",
                                        "error", "crit ", "off  "};
    const std::string_view name = names[static_cast<int>(msg.level)];
    dest.append(name.data(), name.data() + name.size());
  }
  std::unique_ptr<custom_flag_formatter> clone() const override {
    return std::make_unique<LevelName>();
  }
};

std::unique_ptr<spdlog::formatter> make_formatter(const char* pattern) {
  auto f = std::make_unique<spdlog::pattern_formatter>(spdlog::pattern_time_type::utc);
  f->add_flag<LevelPrefix>('*').add_flag<LevelName>('&').set_pattern(pattern);
  return f;
}

struct Console {
  std::mutex mutex;  // guards loggers
  std::map<std::string, std::shared_ptr<spdlog::logger>> loggers;
  std::shared_ptr<spdlog::sinks::stderr_color_sink_mt> sink =
      std::make_shared<spdlog::sinks::stderr_color_sink_mt>(spdlog::color_mode::automatic);
  std::atomic<Level> level{Level::info};
  Console() { sink->set_formatter(make_formatter(kTimestampedPattern)); }
};

Console& the_console() {
  static Console console;
  return console;
}

/// run.log: opened (appending, close-on-exec so that launched jobs do not inherit it) on the
/// first line; a file that cannot be opened or written is reported once and then skipped.
class RunFileSink : public spdlog::sinks::base_sink<std::mutex> {
 public:
  RunFileSink(std::string run_id, std::filesystem::path file)
      : run_id_(std::move(run_id)), file_(std::move(file)) {
    set_formatter_(make_formatter(kFilePattern));
  }
  ~RunFileSink() override {
    if (out_) std::fclose(out_);
  }

 protected:
  void sink_it_(const spdlog::details::log_msg& msg) override {
    if (failed_) return;
    if (!out_) {
      out_ = std::fopen(file_.c_str(), "ae");
      if (!out_) return fail(std::strerror(errno));
    }
    spdlog::memory_buf_t line;
    formatter_->format(msg, line);
    if (std::fwrite(line.data(), 1, line.size(), out_) != line.size() || std::fflush(out_) != 0)
      fail(std::strerror(errno));
  }
  void flush_() override {
    if (out_) std::fflush(out_);
  }

 private:
  void fail(const char* why) {
    failed_ = true;
    console("run " + run_id_)
        ->warn("cannot write {}: {}; this run's log goes to the console only", file_.string(), why);
  }
  std::string run_id_;
  std::filesystem::path file_;
  std::FILE* out_ = nullptr;
  bool failed_ = false;
};

}  // namespace

const std::vector<std::string>& level_names() {
  static const std::vector<std::string> names = {"trace", "debug", "info", "warn", "error", "off"};
  return names;
}

Level parse_level(std::string_view name) {
  static const Level levels[] = {Level::trace, Level::debug, Level::info,
                                 Level::warn,  Level::err,   Level::off};
  const auto& names = level_names();
  for (std::size_t i = 0; i < names.size(); ++i)
    if (names[i] == name) return levels[i];
  std::string accepted;
  for (const std::string& n : names) accepted += (accepted.empty() ? "" : ", ") + n;
  throw std::invalid_argument("log level '" + std::string(name) + "': expected one of " + accepted);
}

void configure(ConsoleStyle style, Level level) {
  Console& c = the_console();
  c.sink->set_formatter(
      make_formatter(style == ConsoleStyle::plain ? kPlainPattern : kTimestampedPattern));
  c.level = level;
  c.sink->set_level(level);
  std::lock_guard lock(c.mutex);
  for (auto& [name, logger] : c.loggers) logger->set_level(level);
}

Level level() {
  return the_console().level.load();
}

std::shared_ptr<spdlog::logger> console(const std::string& name) {
  Console& c = the_console();
  std::lock_guard lock(c.mutex);
  auto& logger = c.loggers[name];
  if (!logger) {
    logger = std::make_shared<spdlog::logger>(name, c.sink);
    logger->set_level(c.level.load());
  }
  return logger;
}

RunLog::RunLog(const std::string& run_id, std::filesystem::path file, bool echo_progress)
    : file_(std::move(file)) {
  const std::string name = "run " + run_id;
  auto sink = std::make_shared<RunFileSink>(run_id, file_);
  const auto console_sink = the_console().sink;
  both_ = std::make_shared<spdlog::logger>(name, spdlog::sinks_init_list{sink, console_sink});
  progress_ = echo_progress ? both_ : std::make_shared<spdlog::logger>(name, sink);
  // run.log keeps the run's record at info whatever the console shows (more when the level is
  // more verbose); the console sink filters by the level itself.
  const Level file_level = std::min(level(), Level::info);
  both_->set_level(file_level);
  progress_->set_level(file_level);
}

RunLog::~RunLog() = default;

std::string tail_lines(const std::filesystem::path& file, std::size_t lines,
                       std::size_t max_bytes) {
  std::ifstream in(file, std::ios::binary);
  if (!in || lines == 0) return {};
  in.seekg(0, std::ios::end);
  const auto size = static_cast<std::size_t>(std::max<std::streamoff>(in.tellg(), 0));
  // One byte before the last max_bytes is read too: it tells whether the first of them starts
  // a line (it follows a newline) or is the end of a longer one, which is dropped.
  const std::size_t start = size > max_bytes ? size - max_bytes - 1 : 0;
  in.seekg(static_cast<std::streamoff>(start));
  std::string text(size - start, '\0');
  in.read(text.data(), static_cast<std::streamsize>(text.size()));
  text.resize(static_cast<std::size_t>(in.gcount()));
  std::size_t begin = 0;
  if (start > 0) {
    const std::size_t newline = text.find('\n');
    begin = newline == std::string::npos ? text.size() : newline + 1;
  }
  // Walk back over `lines` line ends (the file's final newline ends the last line).
  std::size_t from = text.size();
  if (from > begin && text[from - 1] == '\n') --from;
  std::size_t found = 0;
  while (from > begin) {
    const std::size_t newline = text.rfind('\n', from - 1);
    if (newline == std::string::npos || newline < begin) {
      from = begin;
      break;
    }
    if (++found == lines) {
      from = newline + 1;
      break;
    }
    from = newline;
  }
  return text.substr(from);
}

}  // namespace sphles::logging
