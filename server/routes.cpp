#include "server/routes.hpp"

#include <algorithm>
#include <array>
#include <cctype>
#include <charconv>
#include <cmath>
#include <fstream>
#include <map>
#include <sstream>

#include "server/auth.hpp"
#include "server/openapi.hpp"
#include "server/url.hpp"
#include "server/websocket_session.hpp"

namespace sphles::server {

namespace http = boost::beast::http;
namespace fs = std::filesystem;

struct Router::Services {
  control::RunManager& manager;
  StreamRegistry& streams;
  RouterOptions options;
  StaticFiles web;
  std::string presets;  // RunManager::presets(), serialised once
};

namespace {

constexpr std::size_t kMaxFileBytes = 64u << 20;  // static files, frames, time series

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

std::optional<std::string> read_file(const fs::path& file) {
  std::error_code ec;
  const auto size = fs::file_size(file, ec);
  if (ec || size > kMaxFileBytes) return std::nullopt;
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
  return make_response(c.request, http::status::ok, std::string(openapi_document()),
                       "application/json");
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

Response get_run(const Router::Services& s, const Context& c) {
  const auto run = find_run(s, c.params[0]);
  return json_response(c.request, run_detail_json(*run, s.streams.counters(run->id())));
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

std::vector<std::string_view> split(std::string_view line, char separator) {
  std::vector<std::string_view> fields;
  std::size_t start = 0;
  while (true) {
    const std::size_t end = line.find(separator, start);
    fields.push_back(line.substr(start, end == std::string_view::npos ? end : end - start));
    if (end == std::string_view::npos) break;
    start = end + 1;
  }
  return fields;
}

std::optional<double> parse_number(std::string_view text) {
  while (!text.empty() && (text.back() == '\r' || text.back() == ' ')) text.remove_suffix(1);
  if (text == "nan" || text == "-nan" || text == "NaN") return std::nan("");
  double value = 0.0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (ec != std::errc() || end != text.data() + text.size()) return std::nullopt;
  return value;
}

/// A CSV file with a header row: column names and rows of numbers (rows that do not parse, such
/// as a half-written last line, are skipped).
struct Csv {
  std::vector<std::string> columns;
  std::vector<std::vector<std::string_view>> rows;
  std::string text;
};

std::optional<Csv> read_csv(const fs::path& file) {
  std::optional<std::string> text = read_file(file);
  if (!text) return std::nullopt;
  Csv csv;
  csv.text = std::move(*text);
  std::string_view rest = csv.text;
  bool header = true;
  while (!rest.empty()) {
    const std::size_t newline = rest.find('\n');
    if (newline == std::string_view::npos) break;  // no newline yet: still being written
    std::string_view line = rest.substr(0, newline);
    rest.remove_prefix(newline + 1);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    if (line.empty()) continue;
    std::vector<std::string_view> fields = split(line, ',');
    if (header) {
      for (const auto f : fields) csv.columns.emplace_back(f);
      header = false;
    } else if (fields.size() == csv.columns.size()) {
      csv.rows.push_back(std::move(fields));
    }
  }
  return csv;
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

Response timeseries(const Router::Services& s, const Context& c) {
  const auto run = find_run(s, c.params[0]);
  const std::uint64_t since = query_unsigned(c, "since_step", 0);
  const bool has_since = c.query.contains("since_step");
  nlohmann::json columns = nlohmann::json::array();
  nlohmann::json data = nlohmann::json::array();
  const std::optional<Csv> csv = read_csv(run->directory() / "timeseries.csv");
  if (csv && !csv->columns.empty()) {
    const std::map<std::string, std::string> renamed = {{"t", "time"}, {"e_v", "kinetic_energy"}};
    std::size_t step_column = csv->columns.size();
    for (std::size_t k = 0; k < csv->columns.size(); ++k) {
      const auto it = renamed.find(csv->columns[k]);
      columns.push_back(it == renamed.end() ? csv->columns[k] : it->second);
      if (csv->columns[k] == "step") step_column = k;
    }
    // Parse rows; a restart without a final checkpoint repeats steps: the later rows win.
    std::vector<std::vector<double>> rows;
    for (const auto& fields : csv->rows) {
      std::vector<double> row;
      row.reserve(fields.size());
      for (const auto f : fields) {
        const std::optional<double> v = parse_number(f);
        if (!v) break;
        row.push_back(*v);
      }
      if (row.size() != fields.size()) continue;
      if (step_column < row.size())
        while (!rows.empty() && rows.back()[step_column] >= row[step_column]) rows.pop_back();
      rows.push_back(std::move(row));
    }
    for (std::size_t k = 0; k < csv->columns.size(); ++k) data.push_back(nlohmann::json::array());
    for (const auto& row : rows) {
      if (has_since && step_column < row.size() && !(row[step_column] > static_cast<double>(since)))
        continue;
      for (std::size_t k = 0; k < row.size(); ++k) {
        if (k == step_column)
          data[k].push_back(static_cast<std::uint64_t>(row[k]));
        else
          data[k].push_back(row[k]);  // NaN is written as null
      }
    }
  }
  return json_response(c.request, {{"columns", columns}, {"data", data}});
}

Response spectrum(const Router::Services& s, const Context& c) {
  const auto frame = find_run(s, c.params[0])->latest_frame();
  std::optional<nlohmann::json> body = frame ? spectrum_json(*frame) : std::nullopt;
  if (!body) throw ApiError(404, "run '" + c.params[0] + "' has no spectrum yet");
  return json_response(c.request, *body);
}

Response statistics(const Router::Services& s, const Context& c) {
  const auto frame = find_run(s, c.params[0])->latest_frame();
  std::optional<nlohmann::json> body = frame ? statistics_json(*frame) : std::nullopt;
  if (!body) throw ApiError(404, "run '" + c.params[0] + "' has no sub-filter statistics yet");
  return json_response(c.request, *body);
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
  nlohmann::json frames = nlohmann::json::array();
  const std::optional<Csv> csv = read_csv(run->directory() / "frames" / "index.csv");
  if (csv) {
    for (const auto& row : csv->rows) {
      nlohmann::json frame = nlohmann::json::object();
      for (std::size_t k = 0; k < csv->columns.size(); ++k) {
        const std::string& column = csv->columns[k];
        const std::optional<double> number = parse_number(row[k]);
        if (column == "step" && number)
          frame[column] = static_cast<std::uint64_t>(*number);
        else if (column == "time" && number)
          frame[column] = *number;
        else
          frame[column] = std::string(row[k]);
      }
      if (frame.contains("file") && frame["file"].is_string())
        frame["url"] = "/api/runs/" + run->id() + "/frames/" + frame["file"].get<std::string>();
      frames.push_back(std::move(frame));
    }
  }
  return json_response(c.request, frames);
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
  std::optional<std::string> content = read_file(file);
  if (!content) throw ApiError(404, "frame '" + name + "' cannot be read", "file");
  return png_response(c.request, std::move(*content));
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
  static const std::vector<Route> table = {
      {{V::get, "/api/health", false}, health},
      {{V::get, "/api/openapi.json", false}, openapi},
      {{V::get, "/api/presets", false}, presets},
      {{V::get, "/api/runs", false}, list_runs},
      {{V::post, "/api/runs", true}, create_run, true},
      {{V::get, "/api/runs/{id}", false}, get_run},
      {{V::delete_, "/api/runs/{id}", true}, delete_run},
      {{V::post, "/api/runs/{id}/start", true}, transition<&M::start>},
      {{V::post, "/api/runs/{id}/pause", true}, transition<&M::pause>},
      {{V::post, "/api/runs/{id}/resume", true}, transition<&M::resume>},
      {{V::post, "/api/runs/{id}/stop", true}, transition<&M::stop>},
      {{V::patch, "/api/runs/{id}/parameters", true}, change_parameters, true},
      {{V::get, "/api/runs/{id}/timeseries", false}, timeseries},
      {{V::get, "/api/runs/{id}/spectrum", false}, spectrum},
      {{V::get, "/api/runs/{id}/statistics", false}, statistics},
      {{V::get, "/api/runs/{id}/images/{field}", false}, latest_image},
      {{V::get, "/api/runs/{id}/frames", false}, list_frames},
      {{V::get, "/api/runs/{id}/frames/{file}", false}, get_frame},
      {{V::get, "/api/runs/{id}/stream", false}, stream_without_upgrade},
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
  std::optional<std::string> content = read_file(found.file);
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
  res.keep_alive(keep_alive);
  res.body() = dump(error_json(error));
  res.prepare_payload();
  return res;
}

Router::Router(control::RunManager& manager, StreamRegistry& streams, RouterOptions options)
    : services_(std::make_shared<Services>(
          Services{manager, streams, options, StaticFiles(options.web_root), {}})) {
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

Router::StreamTarget Router::stream_target(const Request& request) const {
  StreamTarget t;
  const auto fail = [&](const ApiError& e) {
    t.error = error_response(e, request.version(), false);
    return t;
  };
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
  t.authorised = authorised(services_->options.token,
                            bearer_token(request[http::field::authorization]), query_token);
  return t;
}

}  // namespace sphles::server
