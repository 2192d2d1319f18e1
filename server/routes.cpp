// SPDX-License-Identifier: GPL-3.0-or-later
#include "server/routes.hpp"

#include <algorithm>
#include <array>
#include <cctype>
#include <charconv>
#include <chrono>
#include <cmath>
#include <fstream>
#include <map>
#include <sstream>

#include "analysis/reference.hpp"
#include "analysis/resolved_scales.hpp"
#include "control/scene_schema.hpp"
#include "logging/logging.hpp"
#include "server/auth.hpp"
#include "server/openapi.hpp"
#include "server/run_archive.hpp"
#include "server/url.hpp"
#include "server/websocket_session.hpp"

namespace sphles::server {

namespace http = boost::beast::http;
namespace fs = std::filesystem;

struct Router::Services {
  control::RunManager& manager;
  StreamRegistry& streams;
  ProductCache& products;
  RouterOptions options;
  StaticFiles web;
  std::string presets;  // RunManager::presets(), serialised once
  mutable SeriesIndexCache series;
};

namespace {

constexpr unsigned kStatusUnavailable = 503;
constexpr const char* kRetryAfterSeconds = "1";
constexpr const char* kWebSocketVersion = "13";

struct Context {
  const Request& request;
  std::vector<std::string> params;  // values of the {...} segments, in order
  std::map<std::string, std::string> query;
};

using Handler = Response (*)(const Router::Services&, const Context&);

struct Route {
  RouteInfo info;
  Handler handler;
  bool json_body = false;  // needs Content-Type: application/json and a JSON body
};

Response make_response(const Request& request, http::status status, std::string body,
                       std::string_view content_type) {
  Response res{status, request.version()};
  res.set(http::field::server, "sphles/" SPHLES_VERSION);
  res.set(http::field::content_type, content_type);
  res.set("X-Content-Type-Options", "nosniff");
  res.keep_alive(request.keep_alive());
  res.body() = std::move(body);
  res.prepare_payload();
  return res;
}

Response json_response(const Request& request, const nlohmann::json& body,
                       http::status status = http::status::ok) {
  Response res = make_response(request, status, dump(body), "application/json");
  res.set(http::field::cache_control, "no-store");
  return res;
}

/// 200 with JSON text written by JsonWriter.
Response make_json_text(const Request& request, std::string text) {
  Response res = make_response(request, http::status::ok, std::move(text), "application/json");
  res.set(http::field::cache_control, "no-store");
  return res;
}

/// A whole file (static files, saved frames): nullopt if it cannot be read, ApiError 507 if it is
/// larger than one response may be.
std::optional<std::string> read_file(const fs::path& file, std::size_t max_bytes) {
  std::error_code ec;
  const auto size = fs::file_size(file, ec);
  if (ec) return std::nullopt;
  if (size > max_bytes)
    throw ApiError(507, file.filename().string() + " has " + std::to_string(size) +
                            " bytes, more than the server's response limit of " +
                            std::to_string(max_bytes) + " bytes");
  std::ifstream in(file, std::ios::binary);
  if (!in) return std::nullopt;
  std::string content(static_cast<std::size_t>(size), '\0');
  in.read(content.data(), static_cast<std::streamsize>(size));
  content.resize(static_cast<std::size_t>(in.gcount()));
  return content;
}

/// The JSON body of a request to a JSON route: media type application/json (or +json), an
/// object of at most kMaxJsonDepth levels.
nlohmann::json json_body(const Request& request) {
  if (request.body().empty()) throw ApiError(400, "body: a JSON object is required");
  std::string type(request[http::field::content_type]);
  type = type.substr(0, type.find(';'));
  std::transform(type.begin(), type.end(), type.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  while (!type.empty() && type.back() == ' ') type.pop_back();
  const bool json = type == "application/json" ||
                    (type.size() > 5 && type.compare(type.size() - 5, 5, "+json") == 0);
  if (!json)
    throw ApiError(415, "Content-Type must be application/json (got '" + type + "')",
                   "Content-Type");
  nlohmann::json body = parse_client_json(request.body());
  if (!body.is_object()) throw ApiError(400, "body: must be a JSON object");
  return body;
}

std::shared_ptr<control::Run> find_run(const Router::Services& s, const std::string& id) {
  return s.manager.get(id);  // throws UnknownRunError → 404
}

// --- handlers ---------------------------------------------------------------------------------

Response health(const Router::Services& s, const Context& c) {
  return json_response(
      c.request,
      {{"status", "ok"}, {"version", SPHLES_VERSION}, {"runs", s.manager.list().size()}});
}

Response openapi(const Router::Services&, const Context& c) {
  return make_response(c.request, http::status::ok, served_openapi_document(), "application/json");
}

Response asyncapi(const Router::Services&, const Context& c) {
  return make_response(c.request, http::status::ok, served_asyncapi_document(), "application/json");
}

Response scene_schema(const Router::Services&, const Context& c) {
  return json_response(c.request, control::scene_schema());
}

Response presets(const Router::Services& s, const Context& c) {
  if (!s.presets.empty())
    return make_response(c.request, http::status::ok, s.presets, "application/json");
  return json_response(c.request, control::RunManager::presets());
}

Response list_runs(const Router::Services& s, const Context& c) {
  nlohmann::json runs = nlohmann::json::array();
  for (const auto& run : s.manager.list()) runs.push_back(run_summary_json(*run));
  return json_response(c.request, runs);
}

Response create_run(const Router::Services& s, const Context& c) {
  const nlohmann::json body = json_body(c.request);
  const control::CreateRequest request = control::parse_create_request(body);
  const std::shared_ptr<control::Run> run = s.manager.create(request);
  Response res = json_response(c.request, run_summary_json(*run), http::status::created);
  res.set(http::field::location, "/api/runs/" + run->id());
  return res;
}

/// What a create request would need and take (memory, disk, steps, time per step on this
/// machine), creating nothing: RunManager::estimate.
Response estimate_run(const Router::Services& s, const Context& c) {
  const nlohmann::json body = json_body(c.request);
  return json_response(c.request, s.manager.estimate(control::parse_create_request(body)));
}

/// The reference run of the scene's flow in the server's reference data or among its finished
/// reference jobs: the one with the most grid points.
std::optional<fs::path> reference_run_of(const Router::Services& s, const sim::Scene& scene) {
  std::vector<fs::path> runs = analysis::reference_run_directories(s.options.reference_dir);
  for (fs::path& job : s.manager.references().done_directories()) runs.push_back(std::move(job));
  return analysis::best_reference_run(scene, runs);
}

Response get_run(const Router::Services& s, const Context& c) {
  const auto run = find_run(s, c.params[0]);
  nlohmann::json detail = run_detail_json(*run, s.streams.counters(run->id()));
  // Whether GET resolved answers: a spectrum and a reference run of the run's flow.
  detail["available"]["resolved"] = detail["available"]["spectrum"].get<bool>() &&
                                    reference_run_of(s, run->spec().run.scene).has_value();
  return json_response(c.request, detail);
}

template <void (control::RunManager::*Action)(const std::string&)>
Response transition(const Router::Services& s, const Context& c) {
  const std::string& id = c.params[0];
  (s.manager.*Action)(id);
  return json_response(c.request, run_summary_json(*find_run(s, id)));
}

Response delete_run(const Router::Services& s, const Context& c) {
  const std::string& id = c.params[0];
  s.manager.remove(id);  // 404 unknown, 409 active; the directory goes with it
  return json_response(c.request, {{"deleted", id}});
}

Response change_parameters(const Router::Services& s, const Context& c) {
  const auto run = find_run(s, c.params[0]);
  const nlohmann::json patch = json_body(c.request);
  const std::vector<std::string> changed = run->apply_changes(patch);
  return json_response(c.request, {{"changed", changed}, {"effective", "next step"}});
}

std::uint64_t query_unsigned(const Context& c, const std::string& name, std::uint64_t fallback) {
  const auto it = c.query.find(name);
  if (it == c.query.end()) return fallback;
  std::uint64_t value = 0;
  const std::string& text = it->second;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (text.empty() || ec != std::errc() || end != text.data() + text.size())
    throw ApiError(400, "'" + name + "' must be a non-negative integer", name);
  return value;
}

/// A query parameter that must be a finite number > 0, if given.
std::optional<double> query_positive(const Context& c, const std::string& name) {
  const auto it = c.query.find(name);
  if (it == c.query.end()) return std::nullopt;
  double value = 0.0;
  const std::string& text = it->second;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (text.empty() || ec != std::errc() || end != text.data() + text.size() ||
      !std::isfinite(value) || !(value > 0.0))
    throw ApiError(400, "'" + name + "' must be a number > 0, got '" + text + "'", name);
  return value;
}

/// since_step, limit and (time series only) max_points of a history request; `limit` and
/// `max_points` at most the server's row limit.
HistoryQuery history_query(const Router::Services& s, const Context& c, bool decimation) {
  HistoryQuery q;
  if (c.query.contains("since_step")) q.since_step = query_unsigned(c, "since_step", 0);
  const std::uint64_t max_rows = s.options.limits.max_rows;
  const auto bounded = [&](const std::string& name, std::uint64_t min) -> std::size_t {
    const std::uint64_t v = query_unsigned(c, name, 0);
    if (v < min || v > max_rows)
      throw ApiError(400,
                     "'" + name + "' must be an integer in [" + std::to_string(min) + ", " +
                         std::to_string(max_rows) + "] (the server's rows per answer)",
                     name);
    return static_cast<std::size_t>(v);
  };
  if (c.query.contains("limit")) q.limit = bounded("limit", 1);
  if (decimation && c.query.contains("max_points")) {
    constexpr std::uint64_t kMinPoints = 2;  // the first row and the last
    q.max_points = bounded("max_points", kMinPoints);
    if (q.limit)
      throw ApiError(400, "give either 'limit' (a page) or 'max_points' (decimated), not both",
                     "max_points");
  }
  return q;
}

/// A growing CSV file of the run with a step column, as columns, paged or decimated.
Response csv_history(const Router::Services& s, const Context& c, const fs::path& relative) {
  const auto run = find_run(s, c.params[0]);
  const HistoryQuery query = history_query(s, c, true);
  return make_json_text(
      c.request, timeseries_answer(run->directory() / relative, query, s.options.limits, s.series));
}

Response timeseries(const Router::Services& s, const Context& c) {
  return csv_history(s, c, "timeseries.csv");
}

/// Every analysis frame's scalars so far (stats/snapshots.csv: e_v on the grid, ⟨ω²⟩, the
/// dissipation three ways, max and mean |τ_SFS|), paged or decimated as the time series.
Response analysis_history(const Router::Services& s, const Context& c) {
  return csv_history(s, c, fs::path("stats") / "snapshots.csv");
}

/// The run's reference curve (analysis/reference.hpp): the analytic decay of the 2D TGV, the DNS
/// of the 3D TGV at Re = 1600 and 5000, the laminar Kolmogorov flow; 404 saying why a run has none.
/// `until` ends it early (the analytic curves then sampled over the shorter span).
Response reference(const Router::Services& s, const Context& c) {
  constexpr int kSamples = 201;
  const auto run = find_run(s, c.params[0]);
  const std::optional<double> until = query_positive(c, "until");
  const sim::Scene scene = run->spec().run.scene;
  analysis::ReferenceCurve curve;
  try {
    curve = analysis::reference_curve(scene, s.options.reference_dir, kSamples,
                                      until.value_or(scene.end_time));
  } catch (const std::invalid_argument& e) {
    throw ApiError(404, "run '" + run->id() + "' has no reference: " + e.what());
  } catch (const std::runtime_error& e) {
    throw ApiError(500, e.what());
  }
  return json_response(c.request, {{"label", curve.label},
                                   {"source", curve.source},
                                   {"columns", {"time", "kinetic_energy", "dissipation"}},
                                   {"data", {curve.time, curve.energy, curve.dissipation}}});
}

/// The run's resolved scales against the reference run of its flow in the server's reference
/// data (analysis/resolved_scales.hpp, SPEC §9): at every analysed time the reference covers,
/// and the reference's E(k) at the latest of them; 404 saying why when there is none.
Response resolved(const Router::Services& s, const Context& c) {
  const auto run = find_run(s, c.params[0]);
  const sim::Scene scene = run->spec().run.scene;
  const auto reference = reference_run_of(s, scene);
  if (!reference)
    throw ApiError(404, "run '" + run->id() +
                            "' has no reference run of its flow in the server's reference data "
                            "or done reference jobs (POST /api/references or `sphles reference` "
                            "computes one; docs/reference.md)");
  if (!fs::exists(run->directory() / "spectra" / "index.csv"))
    throw ApiError(404, "run '" + run->id() + "' has no spectra yet");
  std::vector<analysis::ShellSpectrum> ref;
  analysis::ResolvedHistory h;
  try {
    ref = analysis::read_run_spectra(*reference);
    h = analysis::resolved_history(analysis::read_run_spectra(run->directory()), ref);
  } catch (const std::runtime_error& e) {
    throw ApiError(500, e.what());
  }
  if (h.samples.empty())
    throw ApiError(404, "no spectrum of run '" + run->id() + "' lies within the reference's times");
  nlohmann::json body = analysis::resolved_history_to_json(h);
  const analysis::ShellSpectrum latest = analysis::spectrum_at(ref, h.samples.back().time);
  body["reference"] = reference->filename().string();
  body["reference_spectrum"] = {
      {"t", latest.time}, {"k", latest.wavenumber}, {"energy", latest.energy}};
  return json_response(c.request, body);
}

/// The end of the run's run.log as text: the last `lines` lines (default 200, at most the
/// server's rows per answer), "" before the run has logged anything.
Response run_log(const Router::Services& s, const Context& c) {
  constexpr std::uint64_t kDefaultLines = 200;
  const auto run = find_run(s, c.params[0]);
  const std::uint64_t max_rows = s.options.limits.max_rows;
  const std::uint64_t lines = query_unsigned(c, "lines", kDefaultLines);
  if (lines < 1 || lines > max_rows)
    throw ApiError(400,
                   "'lines' must be an integer in [1, " + std::to_string(max_rows) +
                       "] (the server's rows per answer)",
                   "lines");
  Response res = make_response(
      c.request, http::status::ok,
      logging::tail_lines(run->directory() / "run.log", static_cast<std::size_t>(lines),
                          s.options.limits.max_bytes),
      "text/plain; charset=utf-8");
  res.set(http::field::cache_control, "no-store");
  return res;
}

/// A product of the run's latest frame as the frame's one shared text.
Response product(const Router::Services& s, const Context& c, Product which, const char* what) {
  const auto run = find_run(s, c.params[0]);
  const std::shared_ptr<const std::string> text = s.products.get(run->latest_frame(), which);
  if (!text) throw ApiError(404, "run '" + run->id() + "' has no " + what + " yet");
  Response res = make_response(c.request, http::status::ok, std::string(), "application/json");
  res.set(http::field::cache_control, "no-store");
  res.body().share(text);
  res.prepare_payload();
  return res;
}

Response spectrum(const Router::Services& s, const Context& c) {
  return product(s, c, Product::spectrum, "spectrum");
}

Response statistics(const Router::Services& s, const Context& c) {
  return product(s, c, Product::statistics, "sub-filter statistics");
}

bool is_plain_name(std::string_view name, std::size_t max_size) {
  if (name.empty() || name.size() > max_size || name.front() == '.') return false;
  return std::all_of(name.begin(), name.end(), [](unsigned char ch) {
    return std::isalnum(ch) || ch == '_' || ch == '-' || ch == '.' || ch == '+';
  });
}

Response png_response(const Request& request, std::string png) {
  Response res = make_response(request, http::status::ok, std::move(png), "image/png");
  res.set(http::field::cache_control, "no-store");
  return res;
}

Response latest_image(const Router::Services& s, const Context& c) {
  const auto run = find_run(s, c.params[0]);
  const std::string& field = c.params[1];
  if (!is_plain_name(field, 32) || field.find('.') != std::string::npos)
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

Response list_frames(const Router::Services& s, const Context& c) {
  const auto run = find_run(s, c.params[0]);
  FramesPage page = frames_answer(run->directory() / "frames" / "index.csv",
                                  "/api/runs/" + run->id() + "/frames/", history_query(s, c, false),
                                  s.options.limits);
  Response res = make_json_text(c.request, std::move(page.body));
  // The body stays an array; paging travels in the header.
  res.set("X-Sphles-More", page.more ? "true" : "false");
  if (page.last_step) res.set("X-Sphles-Next-Since-Step", std::to_string(*page.last_step));
  return res;
}

Response get_frame(const Router::Services& s, const Context& c) {
  const auto run = find_run(s, c.params[0]);
  const std::string& name = c.params[1];
  if (!is_plain_name(name, 255) || name.find("..") != std::string::npos)
    throw ApiError(400, "'file' must be a frame file name (letters, digits, '_', '-', '.')",
                   "file");
  std::error_code ec;
  const fs::path directory = fs::canonical(run->directory() / "frames", ec);
  if (ec) throw ApiError(404, "run '" + run->id() + "' has no saved frames", "file");
  const fs::path file = fs::canonical(directory / name, ec);
  if (ec || !is_within(directory, file) || !fs::is_regular_file(file, ec))
    throw ApiError(404, "no frame '" + name + "' in run '" + run->id() + "'", "file");
  std::optional<std::string> content = read_file(file, s.options.limits.max_bytes);
  if (!content) throw ApiError(404, "frame '" + name + "' cannot be read", "file");
  return png_response(c.request, std::move(*content));
}

/// A file a run is still writing under a temporary name (renamed into place when complete).
bool is_temporary(const std::string& name) {
  constexpr std::string_view kTmp = ".tmp";
  return name.find(".tmp.") != std::string::npos ||
         (name.size() >= kTmp.size() &&
          name.compare(name.size() - kTmp.size(), kTmp.size(), kTmp) == 0);
}

/// Every file of the run directory and its subdirectories (one level: checkpoints/, spectra/,
/// slices/, stats/, frames/, ...) as (path relative to the directory, file), by path; files under
/// a temporary name are left out.
std::vector<std::pair<std::string, fs::path>> run_files(const fs::path& root) {
  std::vector<std::pair<std::string, fs::path>> files;
  const auto add = [&](const fs::directory_entry& entry, const std::string& relative) {
    std::error_code e;
    if (entry.is_symlink(e) || !entry.is_regular_file(e) ||
        !is_plain_name(entry.path().filename().string(), 255) ||
        is_temporary(entry.path().filename().string()))
      return;
    files.emplace_back(relative, entry.path());
  };
  std::error_code ec;
  for (const fs::directory_entry& entry : fs::directory_iterator(root, ec)) {
    const std::string name = entry.path().filename().string();
    std::error_code e;
    if (entry.is_directory(e) && !entry.is_symlink(e) && is_plain_name(name, 255)) {
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

/// `source` streamed from disk as an attachment named `filename`, never cached.
Response download_response(const Context& c, std::shared_ptr<const ByteSource> source,
                           std::string_view content_type, const std::string& filename) {
  Response res{http::status::ok, c.request.version()};
  res.set(http::field::server, "sphles/" SPHLES_VERSION);
  res.set(http::field::content_type, content_type);
  res.set(http::field::content_disposition, "attachment; filename=\"" + filename + "\"");
  res.set(http::field::cache_control, "no-store");
  res.set("X-Content-Type-Options", "nosniff");
  res.keep_alive(c.request.keep_alive());
  res.body().stream(std::move(source));
  res.prepare_payload();
  return res;
}

/// The run's files for download (run_files): [{"path","bytes","modified","url"}] by path,
/// `modified` in seconds since 1970 UTC.
Response list_files(const Router::Services& s, const Context& c) {
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
Response get_file(const Router::Services& s, const Context& c) {
  const auto run = find_run(s, c.params[0]);
  std::string relative;
  for (std::size_t k = 1; k < c.params.size(); ++k) {
    if (!is_plain_name(c.params[k], 255) || c.params[k] == "..")
      throw ApiError(400, "'path' must name a file of the run as GET files lists it", "path");
    relative += (k > 1 ? "/" : "") + c.params[k];
  }
  std::error_code ec;
  const fs::path root = fs::canonical(run->directory(), ec);
  const fs::path file = ec ? fs::path() : fs::canonical(root / relative, ec);
  const std::string missing = "no file '" + relative + "' in run '" + run->id() + "'";
  if (ec || !is_within(root, file) || is_temporary(file.filename().string()))
    throw ApiError(404, missing, "path");
  std::shared_ptr<const FileSource> source = FileSource::open(file, ec);
  if (!source) throw ApiError(404, missing + " (" + ec.message() + ")", "path");
  return download_response(c, std::move(source), mime_type(file), file.filename().string());
}

/// The whole run directory (the files GET files lists) as one tar archive, RUN_ID.tar with the
/// files under RUN_ID/, streamed: every file is opened first, so the archive holds each file
/// as it was at the request (appended bytes are not sent, a rotated checkpoint is still sent).
Response get_archive(const Router::Services& s, const Context& c) {
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
  return download_response(c, std::make_shared<const TarArchive>(std::move(members)),
                           "application/x-tar", run->id() + ".tar");
}

// --- reference jobs (control/reference_jobs.hpp) ------------------------------------------------

/// A spectral reference of a run's flow: its estimate with "dry_run", else a queued job.
Response create_reference(const Router::Services& s, const Context& c) {
  const control::ReferenceRequest request = control::parse_reference_request(json_body(c.request));
  std::shared_ptr<control::Run> run;
  try {
    run = s.manager.get(request.run);
  } catch (const control::UnknownRunError& e) {
    throw ApiError(404, e.what(), "run");
  }
  control::ReferenceJobs& jobs = s.manager.references();
  const control::ReferencePlan plan = control::ReferenceJobs::plan(run->document(), request);
  if (request.dry_run) return json_response(c.request, jobs.estimate(plan));
  const control::ReferenceJobStatus job = jobs.submit(run->id(), plan);
  Response res = json_response(c.request, reference_job_json(job), http::status::created);
  res.set(http::field::location, "/api/references/" + job.id);
  return res;
}

Response list_references(const Router::Services& s, const Context& c) {
  nlohmann::json jobs = nlohmann::json::array();
  for (const auto& job : s.manager.references().list()) jobs.push_back(reference_job_json(job));
  return json_response(c.request, jobs);
}

Response get_reference(const Router::Services& s, const Context& c) {
  return json_response(c.request, reference_job_json(s.manager.references().get(c.params[0])));
}

template <void (control::ReferenceJobs::*Action)(const std::string&)>
Response reference_transition(const Router::Services& s, const Context& c) {
  control::ReferenceJobs& jobs = s.manager.references();
  (jobs.*Action)(c.params[0]);
  return json_response(c.request, reference_job_json(jobs.get(c.params[0])));
}

Response delete_reference(const Router::Services& s, const Context& c) {
  s.manager.references().remove(c.params[0]);  // 404 unknown, 409 queued or running
  return json_response(c.request, {{"deleted", c.params[0]}});
}

Response stream_without_upgrade(const Router::Services& s, const Context& c) {
  find_run(s, c.params[0]);
  Response res = error_response(
      ApiError(426, "this is a WebSocket endpoint: send an Upgrade: websocket request"),
      c.request.version(), c.request.keep_alive());
  res.set(http::field::upgrade, "websocket");
  return res;
}

const std::vector<Route>& route_table() {
  using V = http::verb;
  using M = control::RunManager;
  using R = control::ReferenceJobs;
  static const std::vector<Route> table = {
      {{V::get, "/api/health", false}, health},
      {{V::get, "/api/openapi.json", false}, openapi},
      {{V::get, "/api/asyncapi.json", false}, asyncapi},
      {{V::get, "/api/presets", false}, presets},
      {{V::get, "/api/schema/scene", false}, scene_schema},
      {{V::get, "/api/runs", false}, list_runs},
      {{V::post, "/api/runs", true}, create_run, true},
      {{V::post, "/api/estimate", true}, estimate_run, true},
      {{V::get, "/api/runs/{id}", false}, get_run},
      {{V::delete_, "/api/runs/{id}", true}, delete_run},
      {{V::post, "/api/runs/{id}/start", true}, transition<&M::start>},
      {{V::post, "/api/runs/{id}/pause", true}, transition<&M::pause>},
      {{V::post, "/api/runs/{id}/resume", true}, transition<&M::resume>},
      {{V::post, "/api/runs/{id}/stop", true}, transition<&M::stop>},
      {{V::patch, "/api/runs/{id}/parameters", true}, change_parameters, true},
      {{V::get, "/api/runs/{id}/timeseries", false}, timeseries},
      {{V::get, "/api/runs/{id}/log", false}, run_log},
      {{V::get, "/api/runs/{id}/analysis", false}, analysis_history},
      {{V::get, "/api/runs/{id}/reference", false}, reference},
      {{V::get, "/api/runs/{id}/resolved", false}, resolved},
      {{V::get, "/api/runs/{id}/files", false}, list_files},
      {{V::get, "/api/runs/{id}/files/{name}", false}, get_file},
      {{V::get, "/api/runs/{id}/files/{dir}/{name}", false}, get_file},
      {{V::get, "/api/runs/{id}/archive", false}, get_archive},
      {{V::get, "/api/runs/{id}/spectrum", false}, spectrum},
      {{V::get, "/api/runs/{id}/statistics", false}, statistics},
      {{V::get, "/api/runs/{id}/images/{field}", false}, latest_image},
      {{V::get, "/api/runs/{id}/frames", false}, list_frames},
      {{V::get, "/api/runs/{id}/frames/{file}", false}, get_frame},
      {{V::get, "/api/runs/{id}/stream", false}, stream_without_upgrade},
      {{V::get, "/api/references", false}, list_references},
      {{V::post, "/api/references", true}, create_reference, true},
      {{V::get, "/api/references/{id}", false}, get_reference},
      {{V::delete_, "/api/references/{id}", true}, delete_reference},
      {{V::post, "/api/references/{id}/stop", true}, reference_transition<&R::stop>},
      {{V::post, "/api/references/{id}/resume", true}, reference_transition<&R::resume>},
  };
  return table;
}

/// Matches decoded segments against a template; fills the {...} values.
bool match(std::string_view pattern, const std::vector<std::string>& segments,
           std::vector<std::string>& params) {
  std::vector<std::string> values;
  std::size_t index = 0;
  std::size_t start = 1;  // skip the leading '/'
  while (start <= pattern.size()) {
    std::size_t end = pattern.find('/', start);
    if (end == std::string_view::npos) end = pattern.size();
    const std::string_view part = pattern.substr(start, end - start);
    if (index >= segments.size()) return false;
    if (!part.empty() && part.front() == '{')
      values.push_back(segments[index]);
    else if (part != segments[index])
      return false;
    ++index;
    start = end + 1;
  }
  if (index != segments.size()) return false;
  params = std::move(values);
  return true;
}

std::string allowed_methods(const std::vector<std::string>& segments) {
  std::string allow;
  std::vector<std::string> unused;
  for (const Route& r : route_table()) {
    if (!match(r.info.path, segments, unused)) continue;
    if (!allow.empty()) allow += ", ";
    allow += std::string(http::to_string(r.info.method));
    if (r.info.method == http::verb::get) allow += ", HEAD";
  }
  return allow;
}

Response serve_static(const Router::Services& s, const Request& request, std::string_view path) {
  if (request.method() != http::verb::get && request.method() != http::verb::head) {
    Response res = error_response(ApiError(405, "static files allow GET and HEAD only", "method"),
                                  request.version(), request.keep_alive());
    res.set(http::field::allow, "GET, HEAD");
    return res;
  }
  const StaticLookup found = s.web.lookup(path);
  if (found.status != 200) throw ApiError(found.status, found.message, "path");
  std::optional<std::string> content = read_file(found.file, s.options.limits.max_bytes);
  if (!content) throw ApiError(404, "path: cannot read the file", "path");
  return make_response(request, http::status::ok, std::move(*content), mime_type(found.file));
}

Response dispatch(const Router::Services& s, const Request& request) {
  const std::optional<Target> target = split_target(request.target());
  if (!target) throw ApiError(400, "request target must be a path starting with '/'", "target");
  const std::optional<std::vector<std::string>> segments = path_segments(target->path);
  if (!segments)
    throw ApiError(400, "path: malformed percent-encoding or an encoded '/', '\\' or NUL", "path");
  if (segments->empty() || (*segments)[0] != "api") return serve_static(s, request, target->path);

  const http::verb method =
      request.method() == http::verb::head ? http::verb::get : request.method();
  bool path_known = false;
  for (const Route& route : route_table()) {
    std::vector<std::string> params;
    if (!match(route.info.path, *segments, params)) continue;
    path_known = true;
    if (route.info.method != method) continue;
    if (route.info.mutating) {
      const std::optional<std::string_view> bearer =
          bearer_token(request[http::field::authorization]);
      if (!authorised(s.options.token, bearer)) {
        Response res = error_response(
            ApiError(401, "this call needs the server's token: Authorization: Bearer TOKEN",
                     "Authorization"),
            request.version(), request.keep_alive());
        res.set(http::field::www_authenticate, "Bearer");
        return res;
      }
    }
    std::optional<std::map<std::string, std::string>> query = parse_query(target->query);
    if (!query) throw ApiError(400, "query: malformed percent-encoding", "query");
    return route.handler(s, Context{request, std::move(params), std::move(*query)});
  }
  if (!path_known) throw ApiError(404, "no API route " + std::string(target->path), "path");
  Response res = error_response(ApiError(405,
                                         "method " + std::string(request.method_string()) +
                                             " is not allowed on " + std::string(target->path),
                                         "method"),
                                request.version(), request.keep_alive());
  res.set(http::field::allow, allowed_methods(*segments));
  return res;
}

}  // namespace

Response error_response(const ApiError& error, unsigned version, bool keep_alive) {
  Response res{static_cast<http::status>(error.status()), version};
  res.set(http::field::server, "sphles/" SPHLES_VERSION);
  res.set(http::field::content_type, "application/json");
  res.set(http::field::cache_control, "no-store");
  // A 503 is a passing condition (memory, a full server): say when to ask again.
  if (error.status() == kStatusUnavailable) res.set(http::field::retry_after, kRetryAfterSeconds);
  res.keep_alive(keep_alive);
  res.body() = dump(error_json(error));
  res.prepare_payload();
  return res;
}

Router::Router(control::RunManager& manager, StreamRegistry& streams, ProductCache& products,
               RouterOptions options)
    : services_(new Services{
          manager, streams, products, options, StaticFiles(options.web_root), {}, {}}) {
  try {
    services_->presets = dump(control::RunManager::presets());
  } catch (const std::exception&) {
    // Served per request instead (and the error reported there).
  }
}

const std::vector<RouteInfo>& Router::routes() {
  static const std::vector<RouteInfo> infos = [] {
    std::vector<RouteInfo> v;
    for (const Route& r : route_table()) v.push_back(r.info);
    return v;
  }();
  return infos;
}

Response Router::handle(const Request& request) const {
  Response res;
  try {
    res = dispatch(*services_, request);
  } catch (const std::exception& e) {
    // Out of memory here throws on (std::bad_alloc): the caller closes the connection.
    res = error_response(to_api_error(e), request.version(), request.keep_alive());
  }
  if (request.method() == http::verb::head) {
    // Same header as GET, no body.
    const std::size_t size = res.body().size();
    res.body().clear();
    res.content_length(size);
  }
  return res;
}

namespace {

/// What Beast's accept would decline, as the documented JSON error (Beast answers in plain
/// text): RFC 6455 §4.2.1. The caller has checked is_upgrade (GET, HTTP/1.1, Connection: Upgrade,
/// Upgrade: websocket).
std::optional<ApiError> handshake_error(const Request& request, bool& wrong_version) {
  wrong_version = false;
  if (request[http::field::host].empty())
    return ApiError(400, "WebSocket handshake: the Host header is missing", "Host");
  const std::string_view key = request[http::field::sec_websocket_key];
  if (key.empty())
    return ApiError(400, "WebSocket handshake: the Sec-WebSocket-Key header is missing",
                    "Sec-WebSocket-Key");
  // base64 of a 16-byte nonce: 22 base64 characters and "==".
  constexpr std::size_t kKeyLength = 24, kKeyCharacters = 22;
  const auto base64 = [](unsigned char ch) { return std::isalnum(ch) || ch == '+' || ch == '/'; };
  if (key.size() != kKeyLength || key.substr(kKeyCharacters) != "==" ||
      !std::all_of(key.begin(), key.begin() + kKeyCharacters, base64))
    return ApiError(400,
                    "WebSocket handshake: Sec-WebSocket-Key must be the base64 of 16 bytes "
                    "(24 characters ending in '==')",
                    "Sec-WebSocket-Key");
  const std::string_view version = request[http::field::sec_websocket_version];
  if (version.empty())
    return ApiError(400, "WebSocket handshake: the Sec-WebSocket-Version header is missing (13)",
                    "Sec-WebSocket-Version");
  if (version != kWebSocketVersion) {
    wrong_version = true;
    return ApiError(426,
                    "WebSocket handshake: protocol version '" + std::string(version) +
                        "' is not supported; this server speaks " + kWebSocketVersion,
                    "Sec-WebSocket-Version");
  }
  return std::nullopt;
}

}  // namespace

Router::StreamTarget Router::stream_target(const Request& request) const {
  StreamTarget t;
  const auto fail = [&](const ApiError& e) {
    t.error = error_response(e, request.version(), false);
    return t;
  };
  bool wrong_version = false;
  if (const std::optional<ApiError> bad = handshake_error(request, wrong_version)) {
    fail(*bad);
    if (wrong_version) t.error->set(http::field::sec_websocket_version, kWebSocketVersion);
    return t;
  }
  const std::optional<Target> target = split_target(request.target());
  const auto segments = target ? path_segments(target->path) : std::nullopt;
  std::vector<std::string> params;
  if (!segments || !match("/api/runs/{id}/stream", *segments, params))
    return fail(ApiError(404, "WebSocket endpoints are /api/runs/{id}/stream only", "path"));
  const auto query = parse_query(target->query);
  if (!query) return fail(ApiError(400, "query: malformed percent-encoding", "query"));
  try {
    t.run = services_->manager.get(params[0]);
  } catch (const std::exception& e) {
    return fail(to_api_error(e));
  }
  std::optional<std::string_view> query_token;
  if (const auto it = query->find("token"); it != query->end()) query_token = it->second;
  const std::optional<std::string_view> header_token =
      bearer_token(request[http::field::authorization]);
  t.authorised = authorised(services_->options.token, header_token, query_token);
  t.token_holder = !services_->options.token.empty() && t.authorised;
  return t;
}

}  // namespace sphles::server
