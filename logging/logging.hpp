// SPDX-License-Identifier: GPL-3.0-or-later
// Logging: one console on stderr for the process (the service's requests, run state changes,
// warnings) and one run.log per run directory, both through spdlog with the same level.
#pragma once

#include <spdlog/logger.h>

#include <cstddef>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace sphles::logging {

using Level = spdlog::level::level_enum;

/// The names `--log-level` accepts, most verbose first: trace, debug, info, warn, error, off.
const std::vector<std::string>& level_names();

/// The level called `name`; std::invalid_argument naming the accepted ones otherwise.
Level parse_level(std::string_view name);

/// How console lines look: `plain` prints the message alone (warnings and errors prefixed), for
/// a command a person watches (`sphles run`); `timestamped` prefixes the UTC time, the level
/// and the logger's name, for a service's log (`sphles serve`, `sphles worker`).
enum class ConsoleStyle { plain, timestamped };

/// Sets the console's style and level, for every logger, those made before included. Call it
/// once at the start of a command, before other threads log. A run's run.log records at info
/// or the level, whichever is more verbose: `warn` quiets the console, not the run's record.
void configure(ConsoleStyle style, Level level);

/// The console's level (info until configure() says otherwise).
Level level();

/// The console logger called `name` (e.g. "serve", "http", "runs"), made on first use.
std::shared_ptr<spdlog::logger> console(const std::string& name);

/// A run's log: every line goes to `file` (run.log in the run directory, appended, UTC time and
/// level on each line, flushed line by line so that a reader sees it at once). Lines logged with
/// info()/warn()/error() also go to the console under the run's name; progress() lines go to the
/// console only when `echo_progress` (the command line, where the run is the program's output).
/// The file is opened on the first line: a run that logs nothing (a listing of a read-only data
/// directory) creates nothing, and a file that cannot be written is reported once on the console
/// while the run carries on.
class RunLog {
 public:
  RunLog(const std::string& run_id, std::filesystem::path file, bool echo_progress);
  ~RunLog();
  RunLog(const RunLog&) = delete;
  RunLog& operator=(const RunLog&) = delete;

  template <class... Args>
  void progress(fmt::format_string<Args...> format, Args&&... args) {
    progress_->info(format, std::forward<Args>(args)...);
  }
  template <class... Args>
  void info(fmt::format_string<Args...> format, Args&&... args) {
    both_->info(format, std::forward<Args>(args)...);
  }
  template <class... Args>
  void warn(fmt::format_string<Args...> format, Args&&... args) {
    both_->warn(format, std::forward<Args>(args)...);
  }
  template <class... Args>
  void error(fmt::format_string<Args...> format, Args&&... args) {
    both_->error(format, std::forward<Args>(args)...);
  }
  template <class... Args>
  void debug(fmt::format_string<Args...> format, Args&&... args) {
    progress_->debug(format, std::forward<Args>(args)...);
  }

  const std::filesystem::path& file() const { return file_; }

 private:
  std::filesystem::path file_;
  std::shared_ptr<spdlog::logger> progress_, both_;
};

/// The last `lines` lines of a text file, reading at most `max_bytes` from its end (a partial
/// first line is dropped); "" if the file does not exist.
std::string tail_lines(const std::filesystem::path& file, std::size_t lines, std::size_t max_bytes);

}  // namespace sphles::logging
