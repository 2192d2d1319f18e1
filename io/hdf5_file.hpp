// SPDX-License-Identifier: GPL-3.0-or-later
// HDF5 plumbing shared by the checkpoint and snapshot writers (private to io/: nothing outside
// the module includes this header).
//
// Why files are assembled in memory: HDF5 1.10 cannot survive a failed close. When the disk is
// full (or a file-size limit is hit), the metadata flush inside H5Fclose fails, the library keeps
// the file identifier but has already freed part of the file's state, and H5_term_library at
// process exit then crashes on it (SIGSEGV in H5F__close_cb, or "infinite loop closing library").
// No close degree avoids this. So the writers build the file with the core driver and no backing
// store, where no HDF5 call touches the disk and closing cannot fail for disk reasons, take the
// finished image and write it with plain POSIX calls, whose errors are reported and cleaned up
// here (docs/checkpoints.md, "When a write fails").
#pragma once

#include <hdf5.h>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>

namespace sphles::io::detail {

/// Owns an HDF5 identifier and closes it with the matching function.
class Handle {
 public:
  Handle(hid_t id, herr_t (*close)(hid_t)) : id_(id), close_(close) {}
  ~Handle() {
    if (id_ >= 0) close_(id_);
  }
  Handle(const Handle&) = delete;
  Handle& operator=(const Handle&) = delete;
  hid_t get() const { return id_; }
  bool valid() const { return id_ >= 0; }

 private:
  hid_t id_;
  herr_t (*close_)(hid_t);
};

/// HDF5 prints its own error stack by default; sphles reports errors itself. Call with
/// hdf5_library_mutex() held.
void silence_hdf5();

/// A fixed-length, null-padded string attribute (h5py reads it as bytes). Throws
/// CheckpointError "LABEL: cannot write attribute 'NAME'".
void write_string_attribute(hid_t object, const char* name, const std::string& value,
                            const std::string& label);

/// A scalar attribute of HDF5 type `type` holding `value`. Throws like write_string_attribute.
void write_scalar_attribute(hid_t object, const char* name, hid_t type, const void* value,
                            const std::string& label);
template <class T>
void write_scalar_attribute(hid_t object, const char* name, hid_t type, T value,
                            const std::string& label) {
  write_scalar_attribute(object, name, type, static_cast<const void*>(&value), label);
}

/// The bytes of a complete HDF5 file.
struct FileImage {
  std::unique_ptr<char[]> bytes;
  std::size_t size = 0;
};

/// An HDF5 file that lives in memory until finish(). Its file access property list closes every
/// object still open in the file when the file is closed (H5F_CLOSE_STRONG), so an exception
/// thrown between creation and finish() cannot leave an identifier behind. Use with
/// hdf5_library_mutex() held; `label` prefixes error messages ("checkpoint 'FILE'").
class MemoryFile {
 public:
  MemoryFile(const std::filesystem::path& destination, std::string label);
  ~MemoryFile();
  MemoryFile(const MemoryFile&) = delete;
  MemoryFile& operator=(const MemoryFile&) = delete;

  hid_t get() const { return file_; }

  /// Flushes the file, copies its image out and closes it. Throws CheckpointError.
  FileImage finish();

 private:
  void close();
  hid_t file_ = -1;
  std::string label_;
};

/// Writes `bytes` to `path` atomically: NAME.tmp.PID in the same directory, written, fsync'ed
/// and closed, then renamed over `path`, then the directory fsync'ed. On any failure the
/// temporary is removed, `path` is left as it was, and CheckpointError names the file and the
/// reason (strerror). Needs no HDF5 lock.
void write_file_atomically(const std::filesystem::path& path, std::string_view bytes,
                           const std::string& label);

/// NAME.tmp.PID beside `path`, with this process' PID: where write_file_atomically and the
/// collective checkpoint writer put a file before it is complete.
std::string temporary_name(const std::filesystem::path& path);

/// Throws CheckpointError when this process' file-size limit (RLIMIT_FSIZE, `ulimit -f`) is
/// below `bytes`: a write past it fails with EFBIG (or kills the process with SIGXFSZ).
void check_file_size_limit(std::uint64_t bytes, const std::string& label);

/// Throws CheckpointError when the file system that holds `file` has less than `bytes` free for
/// this user (statvfs).
void check_free_space(const std::filesystem::path& file, std::uint64_t bytes,
                      const std::string& label);

/// Reserves the disk blocks of the first `bytes` of the existing file `file` without changing its
/// size (fallocate, FALLOC_FL_KEEP_SIZE), so that writes there cannot fail for want of space.
/// Where the file system cannot reserve (EOPNOTSUPP), does nothing: check_free_space has been
/// called before. Throws CheckpointError naming the file and the reason.
void reserve_space(const std::string& file, std::uint64_t bytes, const std::string& label);

/// The end of an atomic write: fsyncs `temporary`, renames it over `path`, fsyncs the directory.
/// On failure removes the temporary, leaves `path` as it was and throws CheckpointError.
void commit_temporary(const std::string& temporary, const std::filesystem::path& path,
                      const std::string& label);

inline void write_file_atomically(const std::filesystem::path& path, const FileImage& image,
                                  const std::string& label) {
  write_file_atomically(path, std::string_view(image.bytes.get(), image.size), label);
}

}  // namespace sphles::io::detail
