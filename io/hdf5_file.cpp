// SPDX-License-Identifier: GPL-3.0-or-later
#include "io/hdf5_file.hpp"

#include <fcntl.h>
#include <sys/resource.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <mutex>

#include "io/checkpoint_error.hpp"
#include "io/hdf5_library.hpp"

namespace sphles::io {

std::mutex& hdf5_library_mutex() {
  static std::mutex m;
  return m;
}

}  // namespace sphles::io

namespace sphles::io::detail {

namespace {

/// The in-memory file grows in steps of this size (glibc moves large blocks with mremap, so
/// growing costs no copy); it bounds the memory allocated beyond the file's own size.
constexpr std::size_t kMemoryFileIncrement = std::size_t{1} << 20;

/// Permissions of a new file before the umask, as open(2) and HDF5's sec2 driver use them.
constexpr mode_t kNewFileMode = 0666;

std::string reason(int error) {
  return std::strerror(error);
}

/// Removes the temporary and reports `what` with the reason of `error` (an errno value).
[[noreturn]] void fail(const std::string& temporary, const std::string& label,
                       const std::string& what, int error) {
  ::unlink(temporary.c_str());
  throw CheckpointError(label + ": " + what + ": " + reason(error));
}

void fsync_directory(const std::filesystem::path& file) {
  const std::filesystem::path directory =
      file.parent_path().empty() ? std::filesystem::path(".") : file.parent_path();
  const int fd = ::open(directory.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return;  // best effort: the rename itself has succeeded
  ::fsync(fd);
  ::close(fd);
}

}  // namespace

void silence_hdf5() {
  static std::once_flag once;
  std::call_once(once, [] { H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr); });
}

void write_string_attribute(hid_t object, const char* name, const std::string& value,
                            const std::string& label) {
  const Handle type(H5Tcopy(H5T_C_S1), H5Tclose);
  const Handle space(H5Screate(H5S_SCALAR), H5Sclose);
  if (!type.valid() || !space.valid() ||
      H5Tset_size(type.get(), std::max<std::size_t>(value.size(), 1)) < 0 ||
      H5Tset_strpad(type.get(), H5T_STR_NULLPAD) < 0)
    throw CheckpointError(label + ": cannot write attribute '" + name + "'");
  const Handle attribute(
      H5Acreate2(object, name, type.get(), space.get(), H5P_DEFAULT, H5P_DEFAULT), H5Aclose);
  const std::string padded = value.empty() ? std::string(1, '\0') : value;
  if (!attribute.valid() || H5Awrite(attribute.get(), type.get(), padded.data()) < 0)
    throw CheckpointError(label + ": cannot write attribute '" + name + "'");
}

void write_scalar_attribute(hid_t object, const char* name, hid_t type, const void* value,
                            const std::string& label) {
  const Handle space(H5Screate(H5S_SCALAR), H5Sclose);
  const Handle attribute(
      space.valid() ? H5Acreate2(object, name, type, space.get(), H5P_DEFAULT, H5P_DEFAULT) : -1,
      H5Aclose);
  if (!attribute.valid() || H5Awrite(attribute.get(), type, value) < 0)
    throw CheckpointError(label + ": cannot write attribute '" + name + "'");
}

MemoryFile::MemoryFile(const std::filesystem::path& destination, std::string label)
    : label_(std::move(label)) {
  silence_hdf5();
  const Handle access(H5Pcreate(H5P_FILE_ACCESS), H5Pclose);
  if (!access.valid() ||
      H5Pset_fapl_core(access.get(), kMemoryFileIncrement, /*backing_store=*/0) < 0 ||
      H5Pset_fclose_degree(access.get(), H5F_CLOSE_STRONG) < 0)
    throw CheckpointError(label_ + ": cannot set up the HDF5 file access properties");
  // The name only identifies the file inside HDF5; with no backing store nothing is created.
  file_ = H5Fcreate(destination.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, access.get());
  if (file_ < 0) throw CheckpointError(label_ + ": cannot create the HDF5 file in memory");
}

MemoryFile::~MemoryFile() {
  close();
}

void MemoryFile::close() {
  if (file_ < 0) return;
  // In memory, closing does no I/O; with H5F_CLOSE_STRONG it also closes any object of the file
  // that is still open.
  H5Fclose(file_);
  file_ = -1;
}

FileImage MemoryFile::finish() {
  if (H5Fflush(file_, H5F_SCOPE_GLOBAL) < 0)
    throw CheckpointError(label_ + ": cannot flush the HDF5 file");
  const ssize_t size = H5Fget_file_image(file_, nullptr, 0);
  if (size <= 0) throw CheckpointError(label_ + ": cannot take the HDF5 file image");
  FileImage image{std::make_unique_for_overwrite<char[]>(static_cast<std::size_t>(size)),
                  static_cast<std::size_t>(size)};
  if (H5Fget_file_image(file_, image.bytes.get(), image.size) != size)
    throw CheckpointError(label_ + ": cannot take the HDF5 file image");
  close();
  return image;
}

std::string temporary_name(const std::filesystem::path& path) {
  return path.string() + ".tmp." + std::to_string(static_cast<long>(::getpid()));
}

void check_file_size_limit(std::uint64_t bytes, const std::string& label) {
  rlimit limit{};
  if (::getrlimit(RLIMIT_FSIZE, &limit) == 0 && limit.rlim_cur != RLIM_INFINITY &&
      limit.rlim_cur < bytes)
    throw CheckpointError(label + ": the file needs up to " + std::to_string(bytes) +
                          " bytes, above the file-size limit of " + std::to_string(limit.rlim_cur) +
                          " bytes (RLIMIT_FSIZE, ulimit -f)");
}

void check_free_space(const std::filesystem::path& file, std::uint64_t bytes,
                      const std::string& label) {
  const std::filesystem::path directory =
      file.parent_path().empty() ? std::filesystem::path(".") : file.parent_path();
  struct statvfs fs {};
  if (::statvfs(directory.c_str(), &fs) < 0) {
    const int error = errno;
    throw CheckpointError(label + ": cannot query the free space of '" + directory.string() +
                          "': " + reason(error));
  }
  const std::uint64_t free_bytes = static_cast<std::uint64_t>(fs.f_bavail) * fs.f_frsize;
  if (free_bytes < bytes)
    throw CheckpointError(label + ": the file needs up to " + std::to_string(bytes) +
                          " bytes, and the file system of '" + directory.string() + "' has " +
                          std::to_string(free_bytes) + " free: " + reason(ENOSPC));
}

void reserve_space(const std::string& file, std::uint64_t bytes, const std::string& label) {
  const int fd = ::open(file.c_str(), O_WRONLY | O_CLOEXEC);
  if (fd < 0) {
    const int error = errno;
    throw CheckpointError(label + ": cannot open '" + file + "': " + reason(error));
  }
  const int result = ::fallocate(fd, FALLOC_FL_KEEP_SIZE, 0, static_cast<off_t>(bytes));
  const int error = result < 0 ? errno : 0;
  ::close(fd);
  if (result < 0 && error != EOPNOTSUPP)
    throw CheckpointError(label + ": cannot reserve " + std::to_string(bytes) + " bytes for '" +
                          file + "': " + reason(error));
}

void commit_temporary(const std::string& temporary, const std::filesystem::path& path,
                      const std::string& label) {
  const int fd = ::open(temporary.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    const int error = errno;
    fail(temporary, label, "cannot open '" + temporary + "'", error);
  }
  if (::fsync(fd) < 0) {
    const int error = errno;
    ::close(fd);
    fail(temporary, label, "cannot fsync '" + temporary + "'", error);
  }
  ::close(fd);
  if (::rename(temporary.c_str(), path.c_str()) < 0) {
    const int error = errno;
    fail(temporary, label, "cannot rename '" + temporary + "' to '" + path.string() + "'", error);
  }
  fsync_directory(path);
}

void write_file_atomically(const std::filesystem::path& path, std::string_view bytes,
                           const std::string& label) {
  const std::string temporary = temporary_name(path);
  const int fd = ::open(temporary.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, kNewFileMode);
  if (fd < 0) {
    const int error = errno;
    throw CheckpointError(label + ": cannot create '" + temporary + "': " + reason(error));
  }
  std::size_t written = 0;
  while (written < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + written, bytes.size() - written);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      // write(2) returns 0 only for a zero count; treat it as "no space" to avoid looping.
      const int error = n < 0 ? errno : ENOSPC;
      ::close(fd);
      fail(temporary, label,
           "cannot write '" + temporary + "' (" + std::to_string(written) + " of " +
               std::to_string(bytes.size()) + " bytes written)",
           error);
    }
    written += static_cast<std::size_t>(n);
  }
  if (::fsync(fd) < 0) {
    const int error = errno;
    ::close(fd);
    fail(temporary, label, "cannot fsync '" + temporary + "'", error);
  }
  if (::close(fd) < 0) {
    const int error = errno;
    fail(temporary, label, "cannot close '" + temporary + "'", error);
  }
  if (::rename(temporary.c_str(), path.c_str()) < 0) {
    const int error = errno;
    fail(temporary, label, "cannot rename '" + temporary + "' to '" + path.string() + "'", error);
  }
  fsync_directory(path);
}

}  // namespace sphles::io::detail
