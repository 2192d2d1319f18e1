// SPDX-License-Identifier: GPL-3.0-or-later
// A whole run as one download: a POSIX tar archive (pax interchange format, IEEE Std 1003.1-2017,
// "pax"), composed on the fly of the run's files held open. Each member is a header block, the
// file's bytes as they were when opened and zero padding to 512 bytes; two zero blocks end it.
//
// The headers are written here rather than by libarchive because the archive is served as a
// random-access composition of open files: its exact size is known before the first byte (the
// response's Content-Length), nothing is copied or staged in a temporary file, and a file that a
// run rotates away (an old checkpoint) is still read whole through its descriptor. libarchive's
// writer pushes a stream and cannot give that. The format is checked by real readers in the
// tests (Python's tarfile, GNU tar).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "server/byte_source.hpp"

namespace sphles::server {

/// The header blocks of one regular-file member: a ustar header, preceded by a pax extended
/// header carrying the name or the size where they do not fit ustar's fields (a name longer
/// than 100 bytes, a file of 8 GiB or more). A multiple of 512 bytes.
std::string tar_member_header(const std::string& name, std::uint64_t size, std::int64_t modified);

struct ArchiveMember {
  std::string name;  // path inside the archive, '/'-separated, relative
  std::shared_ptr<const FileSource> file;
};

class TarArchive final : public ByteSource {
 public:
  explicit TarArchive(std::vector<ArchiveMember> members);
  std::uint64_t size() const override { return size_; }
  ssize_t read(char* out, std::size_t n, std::uint64_t offset) const override;

 private:
  /// A run of bytes of the archive: header (or padding and trailer) text, or a file's bytes.
  struct Segment {
    std::uint64_t offset;
    std::uint64_t size;
    std::string bytes;                       // when not a file
    std::shared_ptr<const FileSource> file;  // when a file
  };
  std::vector<Segment> segments_;
  std::uint64_t size_ = 0;
};

}  // namespace sphles::server
