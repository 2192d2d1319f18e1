// SPDX-License-Identifier: GPL-3.0-or-later
// The run archive (server/run_archive.hpp): a tar composed of open files, read back by real
// readers (Python's tarfile, GNU tar) and compared byte for byte with the files.
#include "server/run_archive.hpp"

#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using sphles::server::ArchiveMember;
using sphles::server::FileSource;
using sphles::server::tar_member_header;
using sphles::server::TarArchive;

namespace {

fs::path scratch(const std::string& name) {
  const fs::path dir =
      fs::temp_directory_path() / ("sphles_archive_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

void write(const fs::path& file, const std::string& bytes) {
  std::ofstream(file, std::ios::binary) << bytes;
}

std::string bytes_of(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), {});
}

std::shared_ptr<const FileSource> open(const fs::path& file) {
  std::error_code ec;
  auto source = FileSource::open(file, ec);
  EXPECT_TRUE(source) << file << ": " << ec.message();
  return source;
}

/// The archive's bytes read in chunks of `chunk` (odd sizes cross every segment boundary).
std::string read_all(const TarArchive& archive, std::size_t chunk) {
  std::string out;
  std::vector<char> buffer(chunk);
  while (out.size() < archive.size()) {
    const ssize_t got = archive.read(buffer.data(), chunk, out.size());
    if (got <= 0) break;
    out.append(buffer.data(), static_cast<std::size_t>(got));
  }
  return out;
}

/// Output and exit status of a shell command.
std::pair<int, std::string> run(const std::string& command) {
  std::string out;
  FILE* pipe = popen((command + " 2>&1").c_str(), "r");
  if (!pipe) return {-1, "popen failed"};
  char buffer[4096];
  while (std::fgets(buffer, sizeof buffer, pipe)) out += buffer;
  return {pclose(pipe), out};
}

}  // namespace

TEST(RunArchive, HeaderIsUstarWithChecksumAndOctalFields) {
  const std::string h = tar_member_header("run/timeseries.csv", 1234, 1700000000);
  ASSERT_EQ(h.size(), 512u);
  EXPECT_EQ(h.substr(0, 19), std::string("run/timeseries.csv\0", 19));
  EXPECT_EQ(h.substr(124, 12), std::string("00000002322\0", 12));  // 1234 in octal
  EXPECT_EQ(h.substr(136, 12), std::string("14524770400\0", 12));  // 1700000000
  EXPECT_EQ(h[156], '0');
  EXPECT_EQ(h.substr(257, 8), std::string("ustar\0"
                                          "00",
                                          8));
  unsigned sum = 0;
  for (std::size_t k = 0; k < h.size(); ++k)
    sum += (k >= 148 && k < 156) ? ' ' : static_cast<unsigned char>(h[k]);
  EXPECT_EQ(std::stoul(h.substr(148, 6), nullptr, 8), sum);
  // What ustar cannot hold goes into a pax extended header before it.
  const std::string long_name = "run/" + std::string(150, 'a') + ".csv";
  const std::string pax = tar_member_header(long_name, 10, 0);
  ASSERT_EQ(pax.size(), 3 * 512u);
  EXPECT_EQ(pax[156], 'x');
  EXPECT_NE(pax.find(" path=" + long_name + "\n"), std::string::npos);
  const std::string big = tar_member_header("run/big.h5", 10'000'000'000ULL, 0);
  EXPECT_NE(big.find(" size=10000000000\n"), std::string::npos);
  EXPECT_THROW(tar_member_header("", 1, 0), std::invalid_argument);
}

// Files of every size class (empty, one byte short of a block, a block, many blocks, a name
// over 100 bytes), read in several chunk sizes: Python's tarfile and GNU tar list the members
// and extract every file byte for byte.
TEST(RunArchive, RealReadersExtractEveryFileWhole) {
  const fs::path dir = scratch("readers");
  fs::create_directories(dir / "run" / "checkpoints");
  std::mt19937 random(7);
  const auto noise = [&](std::size_t n) {
    std::string s(n, '\0');
    for (char& c : s) c = static_cast<char>(random() & 0xFF);
    return s;
  };
  const std::vector<std::pair<std::string, std::string>> files = {
      {"run/empty.txt", ""},
      {"run/scene.json", "{\"case\": \"tgv2d\"}\n"},
      {"run/block.bin", noise(512)},
      {"run/short.bin", noise(511)},
      {"run/checkpoints/ckpt_000010.h5", noise(300'001)},
      {"run/" + std::string(120, 'n') + ".csv", "t,e\n0,1\n"},
  };
  std::vector<ArchiveMember> members;
  for (const auto& [name, bytes] : files) {
    write(dir / name, bytes);
    members.push_back({name, open(dir / name)});
  }
  const TarArchive archive(members);
  std::uint64_t content = 0;
  for (const auto& [name, bytes] : files) content += bytes.size();
  EXPECT_GT(archive.size(), content);
  EXPECT_EQ(archive.size() % 512, 0u);
  const std::string whole = read_all(archive, 1 << 20);
  ASSERT_EQ(whole.size(), archive.size());
  for (const std::size_t chunk : {1u, 511u, 4096u, 65537u})
    EXPECT_TRUE(read_all(archive, chunk) == whole) << "chunk " << chunk;
  const fs::path tar = dir / "run.tar";
  write(tar, whole);

  const auto [py_status, py_out] =
      run("python3 -c \"import sys, tarfile; t = tarfile.open(sys.argv[1], 'r:'); "
          "[print(m.name, m.size, m.isfile()) for m in t.getmembers()]\" " +
          tar.string());
  ASSERT_EQ(py_status, 0) << py_out;
  std::string expected;
  for (const auto& [name, bytes] : files)
    expected += name + " " + std::to_string(bytes.size()) + " True\n";
  EXPECT_EQ(py_out, expected);

  const fs::path out = dir / "extracted";
  fs::create_directories(out);
  const auto [tar_status, tar_out] = run("tar -xf " + tar.string() + " -C " + out.string());
  ASSERT_EQ(tar_status, 0) << tar_out;
  for (const auto& [name, bytes] : files)
    EXPECT_TRUE(bytes_of(out / name) == bytes) << name << " differs after GNU tar extracted it";
  fs::remove_all(dir);
}

// Each file is as it was when opened: bytes appended afterwards are not in the archive, and a
// file removed afterwards (a rotated checkpoint) is still in it whole.
TEST(RunArchive, FilesAreTakenAsTheyWereWhenOpened) {
  const fs::path dir = scratch("snapshot");
  write(dir / "timeseries.csv", "t,e\n0,1\n");
  write(dir / "ckpt.h5", std::string(2000, 'c'));
  const TarArchive archive(
      {{"r/timeseries.csv", open(dir / "timeseries.csv")}, {"r/ckpt.h5", open(dir / "ckpt.h5")}});
  std::ofstream(dir / "timeseries.csv", std::ios::app) << "1,0.5\n";
  fs::remove(dir / "ckpt.h5");
  const std::string whole = read_all(archive, 777);
  ASSERT_EQ(whole.size(), archive.size());
  write(dir / "r.tar", whole);
  const auto [status, out] =
      run("python3 -c \"import sys, tarfile; t = tarfile.open(sys.argv[1]); "
          "print(repr(t.extractfile('r/timeseries.csv').read())); "
          "print(len(t.extractfile('r/ckpt.h5').read()))\" " +
          (dir / "r.tar").string());
  ASSERT_EQ(status, 0) << out;
  EXPECT_EQ(out, "b't,e\\n0,1\\n'\n2000\n");
  // A file truncated under the archive is an error, not silently short data.
  write(dir / "shrinks.bin", std::string(5000, 's'));
  const TarArchive shrinking({{"r/shrinks.bin", open(dir / "shrinks.bin")}});
  write(dir / "shrinks.bin", "");
  EXPECT_LT(read_all(shrinking, 4096).size(), shrinking.size());
  fs::remove_all(dir);
}
