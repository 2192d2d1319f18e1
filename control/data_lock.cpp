// SPDX-License-Identifier: GPL-3.0-or-later
#include "control/data_lock.hpp"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <stdexcept>
#include <string>

namespace sphles::control {

DataDirectoryLock::DataDirectoryLock(const std::filesystem::path& directory) {
  const std::filesystem::path file = directory / "sphles.lock";
  // O_CLOEXEC: the MPI jobs and launchers the server starts must not inherit the lock and keep
  // the directory taken after the server has ended.
  fd_ = ::open(file.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd_ < 0)
    throw std::runtime_error("cannot open the lock file '" + file.string() +
                             "': " + std::strerror(errno));
  if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
    const int error = errno;
    char text[32] = {};
    const ssize_t n = ::pread(fd_, text, sizeof text - 1, 0);
    std::string holder = n > 0 ? std::string(text, static_cast<std::size_t>(n)) : std::string();
    while (!holder.empty() && (holder.back() == '\n' || holder.back() == ' ')) holder.pop_back();
    ::close(fd_);
    fd_ = -1;
    if (error != EWOULDBLOCK)
      throw std::runtime_error("cannot lock '" + file.string() + "': " + std::strerror(error));
    throw std::runtime_error(
        "the data directory '" + directory.string() + "' is in use by another sphles server" +
        (holder.empty() ? std::string() : " (process " + holder + ")") +
        ": a data directory holds the runs of one server; stop that server or choose another "
        "--data directory");
  }
  const std::string pid = std::to_string(::getpid()) + "\n";
  if (::ftruncate(fd_, 0) != 0 ||
      ::pwrite(fd_, pid.data(), pid.size(), 0) != static_cast<ssize_t>(pid.size())) {
    // The lock holds without the id; a refused server then names no process.
  }
}

DataDirectoryLock::~DataDirectoryLock() {
  if (fd_ >= 0) ::close(fd_);  // releases the lock; the file stays for the next server
}

}  // namespace sphles::control
