// SPDX-License-Identifier: GPL-3.0-or-later
// A run's pictures and files (docs/api.md "Products"): the latest image of a field, the saved
// frames, every file of the run directory, and the whole directory as one tar archive. Every
// name from the URL must be a plain name, and every file is canonicalised and must lie inside
// the run's directory, so that no request reads outside it.
#include <algorithm>
#include <cctype>
#include <chrono>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

#include "control/run_files.hpp"
#include "render/movie.hpp"
#include "server/handlers/handlers.hpp"
#include "server/run_archive.hpp"

namespace sphles::server::handlers {

namespace fs = std::filesystem;

namespace {

constexpr std::size_t kMaxFieldName = 32;
constexpr std::size_t kMaxFileName = 255;  // NAME_MAX on Linux file systems

bool is_plain_name(std::string_view name, std::size_t max_size) {
  if (name.empty() || name.size() > max_size || name.front() == '.') return false;
  return std::all_of(name.begin(), name.end(), [](unsigned char ch) {
    return std::isalnum(ch) || ch == '_' || ch == '-' || ch == '.' || ch == '+';
  });
}

/// Every file of the run directory and its subdirectories (one level: checkpoints/, spectra/,
/// slices/, stats/, frames/, ...) as (path relative to the directory, file), by path; files under
/// a temporary name are left out.
std::vector<std::pair<std::string, fs::path>> run_files(const fs::path& root) {
  std::vector<std::pair<std::string, fs::path>> files;
  const auto add = [&](const fs::directory_entry& entry, const std::string& relative) {
    std::error_code e;
    if (entry.is_symlink(e) || !entry.is_regular_file(e) ||
        !is_plain_name(entry.path().filename().string(), kMaxFileName) ||
        control::is_temporary_file(entry.path().filename().string()))
      return;
    files.emplace_back(relative, entry.path());
  };
  std::error_code ec;
  for (const fs::directory_entry& entry : fs::directory_iterator(root, ec)) {
    const std::string name = entry.path().filename().string();
    std::error_code e;
    if (entry.is_directory(e) && !entry.is_symlink(e) && is_plain_name(name, kMaxFileName)) {
      for (const fs::directory_entry& inner : fs::directory_iterator(entry.path(), e))
        add(inner, name + "/" + inner.path().filename().string());
    } else {
      add(entry, name);
    }
  }
  std::sort(files.begin(), files.end());
  return files;
}

/// The run's directory, canonical (404 naming the run when it has none).
fs::path run_root(const control::Run& run) {
  std::error_code ec;
  fs::path root = fs::canonical(run.directory(), ec);
  if (ec) throw ApiError(404, "run '" + run.id() + "' has no directory", "id");
  return root;
}

/// The options of POST movies: {"field": one of the saved image series (default omega2),
/// "fps": 0.1-120 (default 10), "quality": 0-63 (default 32)}; 400 naming the key otherwise.
render::MovieOptions movie_request(const nlohmann::json& body, std::string& field) {
  if (!body.is_object()) throw ApiError(400, "the body must be a JSON object", "(body)");
  render::MovieOptions options;
  field = "omega2";
  for (const auto& [key, value] : body.items()) {
    if (key == "field") {
      static const std::vector<std::string> kFields{"omega2", "tau_sfs", "nu_t", "combined",
                                                    "view3d"};
      if (!value.is_string() ||
          std::find(kFields.begin(), kFields.end(), value.get<std::string>()) == kFields.end())
        throw ApiError(400, "'field' must be omega2, tau_sfs, nu_t, combined or view3d", "field");
      field = value.get<std::string>();
    } else if (key == "fps") {
      if (!value.is_number() || !(value.get<double>() >= 0.1 && value.get<double>() <= 120.0))
        throw ApiError(400, "'fps' must be a number from 0.1 to 120", "fps");
      options.frames_per_second = value.get<double>();
    } else if (key == "quality") {
      if (!value.is_number_integer() || value.get<int>() < 0 || value.get<int>() > 63)
        throw ApiError(400, "'quality' must be an integer from 0 (best) to 63 (smallest)",
                       "quality");
      options.quality = value.get<int>();
    } else {
      throw ApiError(400, "unknown key '" + key + "' (field, fps, quality)", key);
    }
  }
  return options;
}

}  // namespace

Response make_movie(const Services& s, const Context& c) {
  const auto run = find_run(s, c.params[0]);
  std::string field;
  const render::MovieOptions options = movie_request(json_body(c.request), field);
  const fs::path root = run_root(*run);
  std::vector<fs::path> frames;
  try {
    frames = render::saved_frames(root, field);
  } catch (const std::runtime_error& e) {
    throw ApiError(404,
                   "run '" + run->id() + "' has no saved frames of '" + field +
                       "' to make a movie of (the scene's render section saves them)",
                   "field");
  }
  const std::string relative = "movies/" + field + ".webm";
  std::error_code ec;
  fs::create_directories(root / "movies", ec);
  render::MovieSummary made;
  try {
    made = render::write_movie(frames, root / relative, options);
  } catch (const std::exception& e) {
    throw ApiError(500, "the movie of run '" + run->id() + "' failed: " + e.what());
  }
  const std::string url = "/api/runs/" + run->id() + "/files/" + relative;
  Response res = json_response(c.request,
                               {{"path", relative},
                                {"url", url},
                                {"field", field},
                                {"frames", made.frames},
                                {"width", made.width},
                                {"height", made.height},
                                {"duration_seconds", made.duration_seconds},
                                {"bytes", made.bytes}},
                               boost::beast::http::status::created);
  res.set(boost::beast::http::field::location, url);
  return res;
}

Response latest_image(const Services& s, const Context& c) {
  const auto run = find_run(s, c.params[0]);
  const std::string& field = c.params[1];
  if (!is_plain_name(field, kMaxFieldName) || field.find('.') != std::string::npos)
    throw ApiError(400, "'field' must be an image field name such as omega2, tau_sfs, combined",
                   "field");
  const std::optional<control::ImageEvent> image = run->latest_image(field);
  if (!image || !image->png)
    throw ApiError(404, "run '" + run->id() + "' has no image of '" + field + "' yet", "field");
  Response res = png_response(c.request, std::string(image->png->begin(), image->png->end()));
  res.set("X-Sphles-Time", std::to_string(image->time));
  res.set("X-Sphles-Step", std::to_string(image->step));
  return res;
}

Response list_frames(const Services& s, const Context& c) {
  const auto run = find_run(s, c.params[0]);
  FramesPage page =
      frames_answer(run->directory() / "frames" / "index.csv",
                    "/api/runs/" + run->id() + "/frames/", history_query(s, c, false), s.limits);
  Response res = make_json_text(c.request, std::move(page.body));
  // The body stays an array; paging travels in the header.
  res.set("X-Sphles-More", page.more ? "true" : "false");
  if (page.last_step) res.set("X-Sphles-Next-Since-Step", std::to_string(*page.last_step));
  return res;
}

Response get_frame(const Services& s, const Context& c) {
  const auto run = find_run(s, c.params[0]);
  const std::string& name = c.params[1];
  if (!is_plain_name(name, kMaxFileName) || name.find("..") != std::string::npos)
    throw ApiError(400, "'file' must be a frame file name (letters, digits, '_', '-', '.')",
                   "file");
  std::error_code ec;
  const fs::path directory = fs::canonical(run->directory() / "frames", ec);
  if (ec) throw ApiError(404, "run '" + run->id() + "' has no saved frames", "file");
  const fs::path file = fs::canonical(directory / name, ec);
  if (ec || !is_within(directory, file) || !fs::is_regular_file(file, ec))
    throw ApiError(404, "no frame '" + name + "' in run '" + run->id() + "'", "file");
  std::optional<std::string> content = read_file(file, s.limits.max_bytes);
  if (!content) throw ApiError(404, "frame '" + name + "' cannot be read", "file");
  return png_response(c.request, std::move(*content));
}

/// The run's files for download (run_files): [{"path","bytes","modified","url"}] by path,
/// `modified` in seconds since 1970 UTC.
Response list_files(const Services& s, const Context& c) {
  const auto run = find_run(s, c.params[0]);
  const std::vector<std::pair<std::string, fs::path>> files = run_files(run_root(*run));
  nlohmann::json list = nlohmann::json::array();
  for (const auto& [relative, path] : files) {
    std::error_code e;
    const auto bytes = fs::file_size(path, e);
    const auto modified = fs::last_write_time(path, e);
    if (e) continue;  // removed meanwhile (a rotated checkpoint)
    const double seconds =
        std::chrono::duration<double>(std::chrono::file_clock::to_sys(modified).time_since_epoch())
            .count();
    list.push_back({{"path", relative},
                    {"bytes", bytes},
                    {"modified", seconds},
                    {"url", "/api/runs/" + run->id() + "/files/" + relative}});
  }
  return json_response(c.request, list);
}

/// One file of the run directory (GET files/{name} or files/{dir}/{name}), streamed from disk
/// whatever its size, as an attachment named after it.
Response get_file(const Services& s, const Context& c) {
  const auto run = find_run(s, c.params[0]);
  std::string relative;
  for (std::size_t k = 1; k < c.params.size(); ++k) {
    if (!is_plain_name(c.params[k], kMaxFileName) || c.params[k] == "..")
      throw ApiError(400, "'path' must name a file of the run as GET files lists it", "path");
    relative += (k > 1 ? "/" : "") + c.params[k];
  }
  std::error_code ec;
  const fs::path root = fs::canonical(run->directory(), ec);
  const fs::path file = ec ? fs::path() : fs::canonical(root / relative, ec);
  const std::string missing = "no file '" + relative + "' in run '" + run->id() + "'";
  if (ec || !is_within(root, file) || control::is_temporary_file(file.filename().string()))
    throw ApiError(404, missing, "path");
  std::shared_ptr<const FileSource> source = FileSource::open(file, ec);
  if (!source) throw ApiError(404, missing + " (" + ec.message() + ")", "path");
  return download_response(c.request, std::move(source), mime_type(file), file.filename().string());
}

/// The whole run directory (the files GET files lists) as one tar archive, RUN_ID.tar with the
/// files under RUN_ID/, streamed: every file is opened first, so the archive holds each file
/// as it was at the request (appended bytes are not sent, a rotated checkpoint is still sent).
Response get_archive(const Services& s, const Context& c) {
  const auto run = find_run(s, c.params[0]);
  std::vector<ArchiveMember> members;
  std::error_code ec;
  for (const auto& [relative, path] : run_files(run_root(*run))) {
    std::shared_ptr<const FileSource> file = FileSource::open(path, ec);
    if (file) {
      members.push_back({run->id() + "/" + relative, std::move(file)});
    } else if (ec == std::errc::too_many_files_open ||
               ec == std::errc::too_many_files_open_in_system) {
      throw ApiError(503, "run '" + run->id() +
                              "' has more files than this server may hold open (" + ec.message() +
                              "); download them one by one (GET files)");
    }  // else removed since the listing (a rotated checkpoint): not part of the run any more
  }
  return download_response(c.request, std::make_shared<const TarArchive>(std::move(members)),
                           "application/x-tar", run->id() + ".tar");
}

}  // namespace sphles::server::handlers
