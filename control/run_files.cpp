// SPDX-License-Identifier: GPL-3.0-or-later
#include "control/run_files.hpp"

#include <sys/stat.h>

#include <algorithm>
#include <cstdlib>
#include <ctime>
#include <fstream>
#include <iterator>
#include <stdexcept>
#include <string_view>
#include <system_error>
#include <vector>

#include "analysis/writer.hpp"
#include "io/checkpoint.hpp"

namespace sphles::control {

using nlohmann::json;

std::string read_text(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

void write_text_atomically(const std::filesystem::path& path, const std::string& text) {
  const std::filesystem::path temporary = path.string() + ".tmp";
  {
    std::ofstream out(temporary, std::ios::trunc);
    out << text;
    out.flush();
    if (!out) throw std::runtime_error("cannot write '" + temporary.string() + "'");
  }
  std::filesystem::rename(temporary, path);
}

void seed_dissipation(const std::filesystem::path& path, double time,
                      analysis::DissipationEstimator& estimator) {
  std::ifstream in(path);
  std::string line;
  std::getline(in, line);  // header: t,step,dt,e_v,...
  while (std::getline(in, line)) {
    double values[4];
    const char* p = line.c_str();
    char* end = nullptr;
    for (double& v : values) {
      v = std::strtod(p, &end);
      p = *end == ',' ? end + 1 : end;
    }
    if (values[0] >= time - estimator.window() && values[0] <= time)
      estimator.add(values[0], values[3]);
  }
}

bool is_temporary_file(const std::string& name) {
  constexpr std::string_view kTmp = ".tmp";
  return name.find(".tmp.") != std::string::npos ||
         (name.size() >= kTmp.size() &&
          name.compare(name.size() - kTmp.size(), kTmp.size(), kTmp) == 0);
}

void remove_interrupted_writes(const std::filesystem::path& dir) {
  namespace fs = std::filesystem;
  std::error_code ec;
  std::vector<fs::path> doomed;
  for (fs::recursive_directory_iterator it(dir, fs::directory_options::skip_permission_denied, ec),
       end;
       !ec && it != end; it.increment(ec))
    if (it->is_regular_file(ec) && is_temporary_file(it->path().filename().string()))
      doomed.push_back(it->path());
  for (const fs::path& file : doomed) fs::remove(file, ec);
}

std::string checkpoints_left(const std::filesystem::path& checkpoint_dir) {
  try {
    const auto files = io::list_checkpoints(checkpoint_dir);
    if (files.empty()) return "; no checkpoint was written";
    try {  // the newest that reads whole, not merely the newest name
      return "; last valid checkpoint: checkpoints/" +
             io::newest_valid_checkpoint(checkpoint_dir).filename().string();
    } catch (const io::CheckpointError&) {
      return "; no valid checkpoint is left (" + std::to_string(files.size()) +
             " file(s) in checkpoints/, none reads whole)";
    }
  } catch (const std::exception& listing) {
    return std::string("; the checkpoints cannot be listed: ") + listing.what();
  }
}

bool move_to_trash(const std::filesystem::path& dir, const std::filesystem::path& trash) {
  std::error_code ec;
  if (!std::filesystem::exists(std::filesystem::symlink_status(dir, ec))) return false;
  std::filesystem::create_directories(trash.parent_path());
  std::filesystem::remove_all(trash);
  std::filesystem::rename(dir, trash);
  return true;
}

std::optional<std::pair<dev_t, ino_t>> directory_identity(const std::filesystem::path& path) {
  struct stat info {};
  if (::stat(path.c_str(), &info) != 0 || !S_ISDIR(info.st_mode)) return std::nullopt;
  return std::pair{info.st_dev, info.st_ino};
}

json outputs_json(const std::filesystem::path& dir) {
  const auto series = [&](const std::filesystem::path& index, const char* time_key,
                          const char* group_key) {
    json by_group = json::object();
    for (const auto& row : analysis::read_index(dir / index)) {
      if (!row.contains(time_key)) continue;
      const std::string group = group_key && row.contains(group_key) ? row.at(group_key) : "";
      json& entry = by_group[group];
      if (entry.is_null()) entry = {{"count", 0}, {"times", json::array()}};
      entry["count"] = entry["count"].get<int>() + 1;
      entry["times"].push_back(std::stod(row.at(time_key)));
    }
    json out = group_key ? json{{"index", index.string()}, {"by_field", by_group}}
                         : (by_group.contains("") ? by_group[""] : json{{"count", 0}});
    if (!group_key) out["index"] = index.string();
    return out;
  };
  json outputs = {{"timeseries", series("timeseries.csv", "t", nullptr)},
                  {"spectra", series("spectra/index.csv", "t", nullptr)},
                  {"statistics", series("stats/snapshots.csv", "t", nullptr)},
                  {"snapshots", series("snapshots/index.csv", "t", nullptr)},
                  {"fields", series("fields/index.csv", "t", nullptr)},
                  {"slices", series("slices/index.csv", "t", "field")},
                  {"frames", series("frames/index.csv", "time", "field")}};
  json checkpoints = json::array();
  for (const auto& file : io::list_checkpoints(dir / "checkpoints"))
    checkpoints.push_back(file.filename().string());
  outputs["checkpoints"] = {{"count", checkpoints.size()}, {"files", checkpoints}};
  return outputs;
}

std::string outputs_summary(const json& outputs) {
  std::string line = "written:";
  const auto count = [](const json& j) { return j.value("count", 0); };
  for (const char* kind :
       {"timeseries", "spectra", "statistics", "snapshots", "fields", "checkpoints"}) {
    // Appended piece by piece: GCC 12's -Wrestrict misreads the chained temporaries here.
    line.append(" ").append(std::to_string(count(outputs[kind]))).append(" ").append(kind);
    line.append(",");
  }
  for (const char* kind : {"slices", "frames"}) {
    line += std::string(" ") + kind;
    if (outputs[kind]["by_field"].empty()) line += " 0";
    for (const auto& [field, entry] : outputs[kind]["by_field"].items())
      line += " " + field + " " + std::to_string(count(entry));
    line += ",";
  }
  line.pop_back();
  return line;
}

std::optional<MetricsSample> last_metrics(const std::filesystem::path& path) {
  constexpr std::streamoff kTail = 1 << 16;  // far more than a row of full-precision numbers
  std::ifstream in(path, std::ios::binary);
  std::string header;
  if (!std::getline(in, header)) return std::nullopt;
  const auto split = [](const std::string& text) {
    std::vector<std::string> cells;
    std::size_t begin = 0;
    for (std::size_t comma; (comma = text.find(',', begin)) != std::string::npos; begin = comma + 1)
      cells.push_back(text.substr(begin, comma - begin));
    cells.push_back(text.substr(begin));
    return cells;
  };
  const std::vector<std::string> columns = split(header);
  const std::streamoff body = in.tellg();
  in.seekg(0, std::ios::end);
  const std::streamoff end = in.tellg();
  const std::streamoff from = std::max(body, end - kTail);
  std::string tail(static_cast<std::size_t>(end - from), '\0');
  in.seekg(from);
  in.read(tail.data(), static_cast<std::streamsize>(tail.size()));
  // The last row ending in a newline: a row without one is being written (or was cut short).
  const std::size_t last_newline = tail.rfind('\n');
  if (last_newline == std::string::npos || last_newline == 0) return std::nullopt;
  const std::size_t start = tail.rfind('\n', last_newline - 1);
  if (start == std::string::npos && from != body) return std::nullopt;
  const std::size_t first = start == std::string::npos ? 0 : start + 1;
  const std::vector<std::string> cells = split(tail.substr(first, last_newline - first));
  // The columns of analysis::TimeSeriesWriter::kHeader, then the case's own.
  constexpr std::size_t kFixed = 7;
  if (header.rfind(analysis::TimeSeriesWriter::kHeader, 0) != 0 || columns.size() < kFixed ||
      cells.size() != columns.size())
    return std::nullopt;
  std::vector<double> values;
  std::uint64_t step = 0;
  try {
    for (const std::string& cell : cells) values.push_back(std::stod(cell));
    step = std::stoull(cells[1]);
  } catch (const std::exception&) {
    return std::nullopt;  // not a row of numbers
  }
  MetricsSample m{values[0], step, values[2], values[3], values[4], values[5], values[6], {}};
  for (std::size_t c = kFixed; c < columns.size(); ++c)
    m.case_values.emplace_back(columns[c], values[c]);
  return m;
}

std::map<std::string, ImageEvent> saved_images(const std::filesystem::path& dir) {
  std::map<std::string, ImageEvent> images;
  const std::filesystem::path frames = dir / "frames";
  for (const auto& row : analysis::read_index(frames / "index.csv")) {
    if (!row.contains("file") || row.at("file").empty()) continue;  // a row being appended
    if (!std::filesystem::exists(frames / row.at("file"))) continue;
    ImageEvent image;
    image.field = row.at("field");
    image.file = row.at("file");
    try {
      image.time = std::stod(row.at("time"));
      image.step = std::stoull(row.at("step"));
    } catch (const std::exception&) {
      continue;  // not a row the renderer wrote
    }
    images[image.field] = std::move(image);
  }
  return images;
}

std::string utc_now() {
  const std::time_t now = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&now, &tm);
  char text[32];
  std::strftime(text, sizeof text, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return text;
}

}  // namespace sphles::control
