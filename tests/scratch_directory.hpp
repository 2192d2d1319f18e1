// SPDX-License-Identifier: GPL-3.0-or-later
// Scratch directories of a test program under the system's temporary directory: fresh when made,
// removed when the program ends with every test passed, kept (for a look) when one failed.
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <mutex>
#include <string>
#include <vector>

namespace sphles::scratch {

namespace scratch_detail {

class Registry {
 public:
  ~Registry() {
    if (!::testing::UnitTest::GetInstance()->Passed()) return;
    std::error_code ignored;
    for (const std::filesystem::path& dir : dirs_) std::filesystem::remove_all(dir, ignored);
  }
  void add(const std::filesystem::path& dir) {
    const std::lock_guard lock(mutex_);
    dirs_.push_back(dir);
  }

 private:
  std::mutex mutex_;
  std::vector<std::filesystem::path> dirs_;
};

inline Registry& registry() {
  static Registry instance;  // made after gtest's UnitTest, so destroyed before it
  return instance;
}

}  // namespace scratch_detail

/// TMPDIR/sphles_PREFIX_NAME_PID, emptied; created when `create`.
inline std::filesystem::path scratch_directory(const std::string& prefix, const std::string& name,
                                               bool create = true) {
  ::testing::UnitTest::GetInstance();  // constructed before the registry
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() /
      ("sphles_" + prefix + "_" + name + "_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  if (create) std::filesystem::create_directories(dir);
  scratch_detail::registry().add(dir);
  return dir;
}

}  // namespace sphles::scratch
