// SPDX-License-Identifier: GPL-3.0-or-later
// Bytes a response streams from disk without holding them: one file (FileSource), or a whole run
// as a tar archive composed of open files (server/run_archive.hpp). A source has a fixed size,
// known before the first byte is sent (the response's Content-Length), and is read at offsets.
#pragma once

#include <fcntl.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <unistd.h>

#include <cerrno>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <system_error>

namespace sphles::server {

class ByteSource {
 public:
  virtual ~ByteSource() = default;
  /// Bytes in the source, fixed when it was made.
  virtual std::uint64_t size() const = 0;
  /// Up to `n` bytes at `offset` (< size()) into `out`; the count read (0 when a file shrank
  /// under the source), or -1 on an error (errno says which).
  virtual ssize_t read(char* out, std::size_t n, std::uint64_t offset) const = 0;
};

/// An open regular file and its size when opened (bytes appended later are not sent; a file
/// replaced or removed meanwhile is still read whole: the descriptor keeps it).
class FileSource final : public ByteSource {
 public:
  static std::shared_ptr<const FileSource> open(const std::filesystem::path& file,
                                                std::error_code& ec) {
    const int fd = ::open(file.c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW);
    struct stat st {};
    if (fd < 0 || ::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
      ec = std::error_code(fd < 0 ? errno : EISDIR, std::generic_category());
      if (fd >= 0) ::close(fd);
      return nullptr;
    }
    ec = {};
    return std::shared_ptr<const FileSource>(new FileSource(
        fd, static_cast<std::uint64_t>(st.st_size), static_cast<std::int64_t>(st.st_mtime)));
  }
  ~FileSource() override { ::close(fd_); }
  FileSource(const FileSource&) = delete;
  FileSource& operator=(const FileSource&) = delete;
  std::uint64_t size() const override { return size_; }
  /// Last modification, seconds since 1970 UTC, when opened.
  std::int64_t modified() const { return modified_; }
  ssize_t read(char* out, std::size_t n, std::uint64_t offset) const override {
    ssize_t got;
    do {
      got = ::pread(fd_, out, n, static_cast<off_t>(offset));
    } while (got < 0 && errno == EINTR);
    return got;
  }

 private:
  FileSource(int fd, std::uint64_t size, std::int64_t modified)
      : fd_(fd), size_(size), modified_(modified) {}
  int fd_;
  std::uint64_t size_;
  std::int64_t modified_;
};

}  // namespace sphles::server
