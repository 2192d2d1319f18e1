// SPDX-License-Identifier: GPL-3.0-or-later
// What the machine has for runs: its memory, or the memory cgroup's limit when smaller (the
// other side of control/resources.cpp's estimates; docs/scenes.md, "Limits").
#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <limits>
#include <optional>
#include <sstream>
#include <string>

#include "control/resources.hpp"

namespace sphles::control {

namespace {

/// Reads the first number of a file; nothing for "max", a missing file or other text.
std::optional<std::uint64_t> read_limit(const std::filesystem::path& file) {
  std::ifstream in(file);
  std::string word;
  if (!(in >> word) || word.empty() || word.find_first_not_of("0123456789") != std::string::npos)
    return std::nullopt;
  try {
    return std::stoull(word);
  } catch (const std::exception&) {
    return std::nullopt;
  }
}

/// cgroup v1 reports "no limit" as a huge number (LONG_MAX rounded down to a page).
constexpr std::uint64_t kUnlimitedAbove = std::uint64_t{1} << 62;

/// Smallest limit in `file_name` from `directory` up to `root` (a parent's limit applies to its
/// children); also the file directly in `root` when the path is not visible (a namespaced
/// cgroup mount shows the process's own cgroup at the root).
std::optional<std::uint64_t> smallest_limit(const std::filesystem::path& root,
                                            const std::string& cgroup_path,
                                            const std::string& file_name) {
  std::optional<std::uint64_t> best;
  const auto consider = [&](const std::filesystem::path& file) {
    const auto value = read_limit(file);
    if (value && *value < kUnlimitedAbove && (!best || *value < *best)) best = value;
  };
  std::filesystem::path relative = std::filesystem::path(cgroup_path).relative_path();
  while (true) {
    consider(root / relative / file_name);
    if (relative.empty()) break;
    relative = relative.parent_path();
  }
  return best;
}

}  // namespace

std::uint64_t machine_memory_bytes(const std::filesystem::path& self_cgroup,
                                   const std::filesystem::path& cgroup_root,
                                   const std::filesystem::path& meminfo) {
  std::optional<std::uint64_t> limit;
  const auto take = [&](std::optional<std::uint64_t> value) {
    if (value && (!limit || *value < *limit)) limit = value;
  };
  std::ifstream cgroups(self_cgroup);
  for (std::string line; std::getline(cgroups, line);) {
    // "hierarchy-id:controllers:path"; v2 is "0::path".
    const auto first = line.find(':');
    const auto second = first == std::string::npos ? first : line.find(':', first + 1);
    if (second == std::string::npos) continue;
    const std::string controllers = line.substr(first + 1, second - first - 1);
    const std::string path = line.substr(second + 1);
    if (line.substr(0, first) == "0" && controllers.empty()) {
      take(smallest_limit(cgroup_root, path, "memory.max"));
    } else {
      std::stringstream list(controllers);
      for (std::string c; std::getline(list, c, ',');)
        if (c == "memory")
          take(smallest_limit(cgroup_root / "memory", path, "memory.limit_in_bytes"));
    }
  }
  std::optional<std::uint64_t> total;
  std::ifstream info(meminfo);
  for (std::string key; info >> key;) {
    if (key == "MemTotal:") {
      std::uint64_t kib = 0;
      if (info >> kib) total = kib * 1024;
      break;
    }
    info.ignore(std::numeric_limits<std::streamsize>::max(), '\n');
  }
  if (limit && total) return std::min(*limit, *total);
  if (limit) return *limit;
  return total.value_or(0);
}

std::uint64_t machine_memory_bytes() {
  return machine_memory_bytes("/proc/self/cgroup", "/sys/fs/cgroup", "/proc/meminfo");
}

std::uint64_t default_memory_limit_bytes() {
  return static_cast<std::uint64_t>(kDefaultMemoryFraction *
                                    static_cast<double>(machine_memory_bytes()));
}

}  // namespace sphles::control
