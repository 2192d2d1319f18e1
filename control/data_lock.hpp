// SPDX-License-Identifier: GPL-3.0-or-later
// One server per data directory. Two servers on one directory would run the same runs, write
// the same checkpoints and run.json and delete each other's runs; the run manager therefore
// holds an exclusive lock (flock) on DIR/sphles.lock for as long as it lives. The kernel
// releases it when the process ends, however it ends, so a killed server leaves no stale lock;
// the file holds the holder's process id for the message of the server that is refused.
#pragma once

#include <filesystem>

namespace sphles::control {

class DataDirectoryLock {
 public:
  /// Takes the lock of `directory` (which exists). Throws std::runtime_error naming the
  /// directory and the process that holds it, or why the lock file cannot be used.
  explicit DataDirectoryLock(const std::filesystem::path& directory);
  ~DataDirectoryLock();
  DataDirectoryLock(const DataDirectoryLock&) = delete;
  DataDirectoryLock& operator=(const DataDirectoryLock&) = delete;

 private:
  int fd_ = -1;
};

}  // namespace sphles::control
