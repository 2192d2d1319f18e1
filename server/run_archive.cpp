// SPDX-License-Identifier: GPL-3.0-or-later
#include "server/run_archive.hpp"

#include <algorithm>
#include <cstring>
#include <stdexcept>
#include <string_view>
#include <utility>

namespace sphles::server {
namespace {

constexpr std::size_t kBlock = 512;
// ustar header fields (offset, length), pax "ustar Interchange Format".
constexpr std::size_t kNameAt = 0, kNameLength = 100;
constexpr std::size_t kModeAt = 100, kUidAt = 108, kGidAt = 116, kIdLength = 8;
constexpr std::size_t kSizeAt = 124, kTimeAt = 136, kNumberLength = 12;
constexpr std::size_t kChecksumAt = 148, kChecksumLength = 8;
constexpr std::size_t kTypeAt = 156;
constexpr std::size_t kMagicAt = 257;
// The largest size and time an 11-digit octal field holds (8 GiB - 1 bytes; the year 2242).
constexpr std::uint64_t kMaxOctal11 = 077777777777ULL;

std::uint64_t padded(std::uint64_t bytes) {
  return (bytes + kBlock - 1) / kBlock * kBlock;
}

/// `value` in octal, zero-filled to width - 1 digits and a NUL, at `at`.
void put_octal(std::string& block, std::size_t at, std::size_t width, std::uint64_t value) {
  for (std::size_t k = width - 1; k-- > 0; value >>= 3) block[at + k] = char('0' + (value & 7));
  block[at + width - 1] = '\0';
}

/// One ustar header block of a member of type `type` ('0' a file, 'x' pax extended records).
std::string ustar_block(std::string_view name, std::uint64_t size, std::uint64_t modified,
                        char type) {
  std::string block(kBlock, '\0');
  block.replace(kNameAt, std::min(name.size(), kNameLength), name.substr(0, kNameLength));
  put_octal(block, kModeAt, kIdLength, 0644);
  put_octal(block, kUidAt, kIdLength, 0);
  put_octal(block, kGidAt, kIdLength, 0);
  put_octal(block, kSizeAt, kNumberLength, std::min(size, kMaxOctal11));
  put_octal(block, kTimeAt, kNumberLength, std::min(modified, kMaxOctal11));
  block[kTypeAt] = type;
  block.replace(kMagicAt, 8,
                std::string_view("ustar\0"
                                 "00",
                                 8));
  // Checksum: the sum of the header's bytes with the checksum field as spaces; six octal
  // digits, NUL, space.
  block.replace(kChecksumAt, kChecksumLength, kChecksumLength, ' ');
  unsigned sum = 0;
  for (const char c : block) sum += static_cast<unsigned char>(c);
  put_octal(block, kChecksumAt, kChecksumLength - 1, sum);
  block[kChecksumAt + kChecksumLength - 1] = ' ';
  return block;
}

/// A pax extended-header record "LEN key=value\n", LEN counting the whole record in decimal.
std::string pax_record(std::string_view key, std::string_view value) {
  const std::size_t body = key.size() + value.size() + 3;  // ' ', '=', '\n'
  std::size_t length = body + 1;
  while (std::to_string(length).size() + body != length) ++length;
  return std::to_string(length) + " " + std::string(key) + "=" + std::string(value) + "\n";
}

}  // namespace

std::string tar_member_header(const std::string& name, std::uint64_t size, std::int64_t modified) {
  if (name.empty() || name.find('\0') != std::string::npos)
    throw std::invalid_argument("tar member name must be non-empty text");
  const std::uint64_t time = modified > 0 ? static_cast<std::uint64_t>(modified) : 0;
  std::string records;
  if (name.size() > kNameLength) records += pax_record("path", name);
  if (size > kMaxOctal11) records += pax_record("size", std::to_string(size));
  if (time > kMaxOctal11) records += pax_record("mtime", std::to_string(time));
  std::string header;
  if (!records.empty()) {
    const std::size_t slash = name.rfind('/');
    const std::string base = slash == std::string::npos ? name : name.substr(slash + 1);
    header = ustar_block("PaxHeaders/" + base, records.size(), time, 'x');
    records.resize(padded(records.size()), '\0');
    header += records;
  }
  return header + ustar_block(name, size, time, '0');
}

TarArchive::TarArchive(std::vector<ArchiveMember> members) {
  const auto add_text = [&](std::string bytes) {
    if (bytes.empty()) return;
    const std::uint64_t n = bytes.size();
    if (!segments_.empty() && !segments_.back().file) {  // join with the text before
      segments_.back().bytes += bytes;
      segments_.back().size += n;
    } else {
      segments_.push_back({size_, n, std::move(bytes), nullptr});
    }
    size_ += n;
  };
  for (ArchiveMember& m : members) {
    const std::uint64_t bytes = m.file->size();
    add_text(tar_member_header(m.name, bytes, m.file->modified()));
    if (bytes > 0) {
      segments_.push_back({size_, bytes, {}, std::move(m.file)});
      size_ += bytes;
    }
    add_text(std::string(padded(bytes) - bytes, '\0'));
  }
  add_text(std::string(2 * kBlock, '\0'));  // end of archive
}

ssize_t TarArchive::read(char* out, std::size_t n, std::uint64_t offset) const {
  // The segment holding `offset`: the last one starting at or before it.
  const auto after =
      std::upper_bound(segments_.begin(), segments_.end(), offset,
                       [](std::uint64_t o, const Segment& s) { return o < s.offset; });
  if (after == segments_.begin() || offset >= size_) return 0;
  const Segment& s = *(after - 1);
  const std::uint64_t within = offset - s.offset;
  const std::size_t count = static_cast<std::size_t>(std::min<std::uint64_t>(n, s.size - within));
  if (s.file) return s.file->read(out, count, within);
  std::memcpy(out, s.bytes.data() + within, count);
  return static_cast<ssize_t>(count);
}

}  // namespace sphles::server
