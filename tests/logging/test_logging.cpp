// SPDX-License-Identifier: GPL-3.0-or-later
// logging/: level names, run.log lines (format, level, append, lazy creation, unwritable file)
// and the tail the service serves. Real files.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "logging/logging.hpp"
#include "scratch_directory.hpp"

namespace sphles::logging {
namespace {

namespace fs = std::filesystem;

fs::path fresh_directory(const std::string& name) {
  return sphles::scratch::scratch_directory("logging", name);
}

std::string text_of(const fs::path& file) {
  std::ifstream in(file);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

/// Sets a level for one test and restores info after it.
struct LevelScope {
  explicit LevelScope(Level l) { configure(ConsoleStyle::timestamped, l); }
  ~LevelScope() { configure(ConsoleStyle::timestamped, Level::info); }
};

TEST(Logging, LevelNamesRoundTripAndOthersAreRefusedByName) {
  for (const std::string& name : level_names())
    EXPECT_EQ(spdlog::level::to_string_view(parse_level(name)),
              name == "warn" ? "warning" : (name == "error" ? "error" : name));
  EXPECT_EQ(parse_level("error"), Level::err);
  try {
    parse_level("verbose");
    FAIL() << "accepted 'verbose'";
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(),
                 "log level 'verbose': expected one of trace, debug, info, warn, error, off");
  }
}

TEST(Logging, RunLogAppendsStampedLinesAndOnlyCreatesTheFileWhenItLogs) {
  const fs::path dir = fresh_directory("append");
  const fs::path file = dir / "run.log";
  {
    RunLog log("r", file, /*echo_progress=*/false);
    EXPECT_FALSE(fs::exists(file)) << "nothing logged, nothing created";
    log.progress("step {} of {}", 1, 2);
    log.warn("disk {}% full", 95);
    // Each line is on disk as soon as it is logged (the service serves the file live).
    EXPECT_EQ(text_of(file).size(), text_of(file).find("full\n") + 5);
  }
  {
    RunLog again("r", file, false);
    again.error("failed: {}", "why");
  }
  std::istringstream lines(text_of(file));
  std::string line;
  std::vector<std::string> all;
  while (std::getline(lines, line)) all.push_back(line);
  ASSERT_EQ(all.size(), 3u);
  const std::string stamp = "0000-00-00T00:00:00.000Z ";
  for (const std::string& l : all) {
    ASSERT_GT(l.size(), stamp.size());
    EXPECT_EQ(l[4], '-');
    EXPECT_EQ(l[10], 'T');
    EXPECT_EQ(l[stamp.size() - 2], 'Z');
  }
  EXPECT_EQ(all[0].substr(stamp.size()), "info  step 1 of 2");
  EXPECT_EQ(all[1].substr(stamp.size()), "warn  disk 95% full");
  EXPECT_EQ(all[2].substr(stamp.size()), "error failed: why");
}

TEST(Logging, RunLogKeepsInfoAndAddsDebugWhenAsked) {
  const fs::path dir = fresh_directory("level");
  {
    LevelScope scope(Level::warn);  // a quiet console does not thin the run's record
    RunLog log("r", dir / "run.log", false);
    log.progress("progress");
    log.info("state");
    log.debug("not at warn");
    log.warn("warned");
  }
  const std::string text = text_of(dir / "run.log");
  EXPECT_NE(text.find("info  progress\n"), std::string::npos) << text;
  EXPECT_NE(text.find("info  state\n"), std::string::npos) << text;
  EXPECT_EQ(text.find("not at warn"), std::string::npos) << text;
  EXPECT_NE(text.find("warn  warned\n"), std::string::npos) << text;
  {
    LevelScope scope(Level::debug);
    RunLog log("r", dir / "run.log", false);
    log.debug("details");
  }
  EXPECT_NE(text_of(dir / "run.log").find("debug details\n"), std::string::npos);
}

TEST(Logging, AnUnwritableRunLogIsSkippedWithoutFailingTheCaller) {
  const fs::path dir = fresh_directory("unwritable");
  const fs::path missing = dir / "no" / "such" / "run.log";  // its directory does not exist
  RunLog log("r", missing, false);
  EXPECT_NO_THROW(log.info("first"));
  EXPECT_NO_THROW(log.error("second"));
  EXPECT_FALSE(fs::exists(missing));
}

TEST(Logging, TailReturnsTheLastLinesWithinTheByteLimit) {
  const fs::path dir = fresh_directory("tail");
  const fs::path file = dir / "log.txt";
  EXPECT_EQ(tail_lines(file, 5, 1000), "") << "a missing file is an empty log";
  std::ofstream(file) << "one\ntwo\nthree\nfour\n";
  EXPECT_EQ(tail_lines(file, 2, 1000), "three\nfour\n");
  EXPECT_EQ(tail_lines(file, 1, 1000), "four\n");
  EXPECT_EQ(tail_lines(file, 4, 1000), "one\ntwo\nthree\nfour\n");
  EXPECT_EQ(tail_lines(file, 100, 1000), "one\ntwo\nthree\nfour\n");
  EXPECT_EQ(tail_lines(file, 0, 1000), "");
  // At most max_bytes from the end, whole lines only: the last 12 bytes are "\nthree\nfour\n"
  // (the empty end of "two" dropped), the last 11 "three\nfour\n" (it follows a newline), the
  // last 10 "hree\nfour\n" (the end of a longer line, dropped).
  EXPECT_EQ(tail_lines(file, 100, 12), "three\nfour\n");
  EXPECT_EQ(tail_lines(file, 100, 11), "three\nfour\n");
  EXPECT_EQ(tail_lines(file, 100, 10), "four\n");
  EXPECT_EQ(tail_lines(file, 1, 11), "four\n");
  EXPECT_EQ(tail_lines(file, 100, 4), "");  // "our\n": the end of a longer line
  std::ofstream(file) << "alpha\nbeta";     // no final newline
  EXPECT_EQ(tail_lines(file, 1, 1000), "beta");
  EXPECT_EQ(tail_lines(file, 2, 1000), "alpha\nbeta");
}

}  // namespace
}  // namespace sphles::logging
