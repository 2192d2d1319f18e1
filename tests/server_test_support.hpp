// SPDX-License-Identifier: GPL-3.0-or-later
// Shared pieces of the service's integration tests: real servers on ephemeral loopback ports
// (TestServer), a blocking HTTP client (send, Api), raw sockets (raw_exchange) and a WebSocket
// client (WsClient), scratch directories removed when the test program ends, and tiny scenes.
// Nothing is mocked: every helper speaks to a real sphles::server::HttpServer over TCP.
#pragma once

#include <fcntl.h>
#include <gtest/gtest.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <sys/wait.h>
#include <unistd.h>
#include <array>
#include <boost/asio/connect.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/read.hpp>
#include <boost/asio/write.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "control/run_manager.hpp"
#include "server/client_queue.hpp"
#include "server/http_server.hpp"
#include "server/router.hpp"
#include "server/static_files.hpp"
#include "server/url.hpp"

namespace sphles_server_test {

namespace beast = boost::beast;
namespace http = beast::http;
namespace net = boost::asio;
namespace websocket = beast::websocket;
namespace fs = std::filesystem;
using tcp = net::ip::tcp;
using nlohmann::json;
using namespace std::chrono_literals;
using sphles::server::HttpServer;
using sphles::server::ServerOptions;

constexpr std::string_view kPngSignature("\x89PNG\r\n\x1a\n", 8);
constexpr const char* kSecret = "top-secret-outside-the-web-root";

// --- scenes --------------------------------------------------------------------------------

/// A 16² 2D Taylor-Green run without packing: thousands of steps per second on one thread.
inline json tiny_scene(double end_time = 1000.0, const std::string& name = "tiny") {
  return {{"name", name},
          {"case", "tgv2d"},
          {"particles_per_side", 16},
          {"kernel", {{"type", "wendland_c4"}, {"diameter_over_spacing", 8}}},
          {"packing", {{"enabled", false}}},
          {"time", {{"end", end_time}}}};
}

/// The same with analysis (spectrum, slices, statistics) and rendered ω² images.
inline json rendered_scene(double end_time = 1000.0) {
  json scene = tiny_scene(end_time, "rendered");
  scene["analysis"] = {{"every", 0.05},
                       {"products", {"energy", "spectrum", "vorticity", "slices", "sfs_stats"}},
                       {"slice", {{"fields", {"omega2", "tau_sfs"}}}}};
  scene["render"] = {{"fields", {"omega2"}}, {"width", 128}, {"height", 64}};
  return scene;
}

// --- scratch directories and servers ---------------------------------------------------------

/// Scratch directories, removed when the test program ends (after every server has stopped).
class ScratchDirectories : public ::testing::Environment {
 public:
  static std::vector<fs::path>& all() {
    static std::vector<fs::path> directories;
    return directories;
  }
  void TearDown() override {
    std::error_code ec;
    for (const fs::path& dir : all()) fs::remove_all(dir, ec);
  }
};
inline const auto* const kScratchCleanup =
    ::testing::AddGlobalTestEnvironment(new ScratchDirectories);

inline fs::path scratch(const std::string& name) {
  static int counter = 0;
  const fs::path dir =
      fs::temp_directory_path() / ("sphles-server-test-" + std::to_string(::getpid()) + "-" +
                                   std::to_string(counter++) + "-" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  ScratchDirectories::all().push_back(dir);
  return dir;
}

/// A web root with a few files, a secret next to it and a symbolic link pointing out of it.
inline fs::path make_web_root(const fs::path& base) {
  fs::remove_all(base);
  const fs::path web = base / "web";
  fs::create_directories(web / "sub");
  std::ofstream(web / "index.html") << "<!doctype html><title>sphles</title>";
  std::ofstream(web / "app.js") << "console.log('sphles');";
  std::ofstream(web / "sub" / "style.css") << "body{}";
  std::ofstream(web / ".hidden") << "hidden";
  std::ofstream(base / "secret.txt") << kSecret;
  fs::create_directory_symlink(base, web / "escape");
  return web;
}

struct TestServer {
  /// `configure` may change the server's limits before it starts (tests of server/ limits),
  /// `manage` the run manager's (queue, memory).
  explicit TestServer(fs::path data, std::string token = "", int max_running = 2,
                      const std::function<void(ServerOptions&)>& configure = {},
                      const std::function<void(sphles::control::ManagerOptions&)>& manage = {})
      : data_directory(std::move(data)) {
    sphles::control::ManagerOptions m;
    m.data_directory = data_directory;
    m.max_running = max_running;
    m.run_options.threads = 1;
    m.run_options.metrics_batch_seconds = 0.05;
    if (manage) manage(m);
    manager = std::make_unique<sphles::control::RunManager>(m);
    ServerOptions o;
    o.address = "127.0.0.1";
    o.port = 0;
    o.token = std::move(token);
    o.web_root = make_web_root(data_directory.parent_path() /
                               (data_directory.filename().string() + "-site"));
    if (configure) configure(o);
    http = std::make_unique<HttpServer>(*manager, o);
    http->start();
  }
  ~TestServer() { shutdown(); }
  void shutdown() {
    if (http) http->stop_accepting();
    if (manager) manager->shutdown();
    http.reset();
    manager.reset();
  }
  unsigned short port() const { return http->port(); }

  fs::path data_directory;
  std::unique_ptr<sphles::control::RunManager> manager;
  std::unique_ptr<HttpServer> http;
};

// --- HTTP client -----------------------------------------------------------------------------

inline void set_socket_timeout(tcp::socket& socket, std::chrono::milliseconds timeout) {
  timeval tv{};
  tv.tv_sec = static_cast<time_t>(timeout.count() / 1000);
  tv.tv_usec = static_cast<suseconds_t>((timeout.count() % 1000) * 1000);
  ::setsockopt(socket.native_handle(), SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  ::setsockopt(socket.native_handle(), SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
}

struct Reply {
  int status = 0;
  std::map<std::string, std::string> headers;  // lower-case names
  std::string body;
  json body_json() const { return json::parse(body); }
  std::string header(const std::string& name) const {
    const auto it = headers.find(name);
    return it == headers.end() ? "" : it->second;
  }
};

/// A response as the tests read it: its status, its headers (lower-case names) and `body`.
template <class Body>
Reply reply_of(const http::response<Body>& res, std::string body) {
  Reply reply;
  reply.status = static_cast<int>(res.result_int());
  for (const auto& field : res) {
    std::string name(field.name_string());
    for (char& c : name) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    reply.headers[name] = std::string(field.value());
  }
  reply.body = std::move(body);
  return reply;
}

struct Request {
  Request(http::verb m, std::string t, std::string b = "", std::string type = "application/json",
          std::vector<std::pair<std::string, std::string>> h = {})
      : method(m),
        target(std::move(t)),
        body(std::move(b)),
        content_type(std::move(type)),
        headers(std::move(h)) {}
  http::verb method;
  std::string target;
  std::string body;
  std::string content_type;
  std::vector<std::pair<std::string, std::string>> headers;
};

inline Reply send(unsigned short port, const Request& r) {
  net::io_context ioc;
  tcp::socket socket(ioc);
  socket.connect({net::ip::make_address("127.0.0.1"), port});
  set_socket_timeout(socket, 30s);
  http::request<http::string_body> req{r.method, r.target, 11};
  req.set(http::field::host, "127.0.0.1");
  if (!r.body.empty()) req.set(http::field::content_type, r.content_type);
  for (const auto& [name, value] : r.headers) req.set(name, value);
  req.body() = r.body;
  req.prepare_payload();
  http::write(socket, req);
  beast::flat_buffer buffer;
  http::response_parser<http::string_body> parser;
  parser.body_limit(256u << 20);
  parser.skip(r.method == http::verb::head);  // a HEAD response has a length but no body
  http::read(socket, buffer, parser);
  const auto& res = parser.get();
  return reply_of(res, res.body());
}

/// send(), or nullopt when the server closes or resets the connection instead of answering.
inline std::optional<Reply> try_send(unsigned short port, const Request& r) {
  try {
    return send(port, r);
  } catch (const std::exception&) {
    return std::nullopt;
  }
}

struct Api {
  explicit Api(unsigned short p, std::string t = "") : port(p), token(std::move(t)) {}
  unsigned short port;
  std::string token;

  Request with_token(Request r) const {
    if (!token.empty()) r.headers.emplace_back("Authorization", "Bearer " + token);
    return r;
  }
  Reply get(const std::string& target) const { return send(port, {http::verb::get, target}); }
  Reply post(const std::string& target, const json& body = nullptr) const {
    return send(port, with_token({http::verb::post, target, body.is_null() ? "" : body.dump()}));
  }
  Reply patch(const std::string& target, const json& body) const {
    return send(port, with_token({http::verb::patch, target, body.dump()}));
  }
  Reply remove(const std::string& target) const {
    return send(port, with_token({http::verb::delete_, target, ""}));
  }
  json run(const std::string& id) const {
    const Reply r = get("/api/runs/" + id);
    EXPECT_EQ(r.status, 200) << r.body;
    return r.body_json();
  }
  std::string create(const json& request) const {
    const Reply r = post("/api/runs", request);
    EXPECT_EQ(r.status, 201) << r.body;
    return r.body_json().value("id", "");
  }
};

/// Sends bytes on a fresh connection, optionally half-closes, and returns everything the server
/// sends until it closes (or the timeout).
inline std::string raw_exchange(unsigned short port, const std::string& bytes,
                                bool half_close = true, std::chrono::milliseconds timeout = 10s) {
  net::io_context ioc;
  tcp::socket socket(ioc);
  socket.connect({net::ip::make_address("127.0.0.1"), port});
  set_socket_timeout(socket, timeout);
  beast::error_code ec;
  net::write(socket, net::buffer(bytes), ec);
  if (half_close) socket.shutdown(tcp::socket::shutdown_send, ec);
  std::string received;
  std::array<char, 8192> chunk{};
  while (true) {
    const std::size_t n = socket.read_some(net::buffer(chunk), ec);
    received.append(chunk.data(), n);
    if (ec) break;
  }
  return received;
}

inline int status_of(const std::string& raw) {
  if (raw.rfind("HTTP/1.", 0) != 0 || raw.size() < 12) return 0;
  return std::atoi(raw.substr(9, 3).c_str());
}

inline std::string body_of(const std::string& raw) {
  const std::size_t end = raw.find("\r\n\r\n");
  return end == std::string::npos ? "" : raw.substr(end + 4);
}

// --- WebSocket client ------------------------------------------------------------------------

struct WsMessage {
  bool binary = false;
  std::string data;
  json text() const { return json::parse(data); }
};

class WsClient {
 public:
  WsClient(unsigned short port, const std::string& target) : ws_(ioc_) {
    tcp::socket& socket = ws_.next_layer();
    socket.connect({net::ip::make_address("127.0.0.1"), port});
    set_socket_timeout(socket, 30s);
    ws_.read_message_max(64u << 20);
    ws_.handshake(response_, "127.0.0.1", target);
  }
  ~WsClient() {
    beast::error_code ec;
    ws_.close(websocket::close_code::normal, ec);
  }
  WsMessage read() {
    beast::flat_buffer buffer;
    ws_.read(buffer);
    return {ws_.got_binary(), beast::buffers_to_string(buffer.data())};
  }
  /// Reads until `accept` is true for a message; fails the test after `timeout`.
  WsMessage read_until(const std::function<bool(const WsMessage&)>& accept,
                       std::chrono::seconds timeout = 30s) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < deadline) {
      WsMessage m = read();
      if (accept(m)) return m;
    }
    ADD_FAILURE() << "no matching WebSocket message within " << timeout.count() << " s";
    return {};
  }
  WsMessage read_type(const std::string& type, std::chrono::seconds timeout = 30s) {
    return read_until(
        [&](const WsMessage& m) { return !m.binary && m.text().value("type", "") == type; },
        timeout);
  }
  void send(const json& message) { ws_.write(net::buffer(message.dump())); }
  void send_raw(const std::string& text, bool binary = false) {
    ws_.binary(binary);
    ws_.write(net::buffer(text));
    ws_.text(true);
  }

 private:
  net::io_context ioc_;
  websocket::stream<tcp::socket> ws_;
  websocket::response_type response_;
};

/// Status of the answer to a WebSocket upgrade request (101 when accepted). Raw, because
/// Beast 1.74's client handshake does not hand out the response when it is declined.
inline int upgrade_status(unsigned short port, const std::string& target) {
  const std::string raw = raw_exchange(port,
                                       "GET " + target +
                                           " HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                                           "Connection: Upgrade\r\nUpgrade: websocket\r\n"
                                           "Sec-WebSocket-Version: 13\r\n"
                                           "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n\r\n",
                                       true, 5s);
  return status_of(raw);
}

inline bool wait_until(const std::function<bool()>& condition,
                       std::chrono::milliseconds timeout = 30s) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < deadline) {
    if (condition()) return true;
    std::this_thread::sleep_for(20ms);
  }
  return condition();
}

inline void expect_error(const Reply& r, int status, const std::optional<std::string>& field = {}) {
  EXPECT_EQ(r.status, status) << r.body;
  ASSERT_NE(r.header("content-type").find("application/json"), std::string::npos) << r.body;
  const json body = r.body_json();
  ASSERT_TRUE(body.contains("error")) << r.body;
  EXPECT_EQ(body["error"]["status"], status);
  EXPECT_FALSE(body["error"]["message"].get<std::string>().empty());
  if (field) {
    EXPECT_EQ(body["error"]["field"], *field) << r.body;
  }
}

// --- the real program as a child process -------------------------------------------------------

/// Output of a finished child: exit code (or -signal) and what it wrote.
struct ProcessResult {
  int code = 0;  // exit status, or minus the signal that ended it
  std::string out, err;
};

/// Runs the sphles binary with `args` in `directory` (cwd), stdout and stderr captured, and
/// waits for it (killed after `timeout`, then code = -SIGKILL).
inline ProcessResult run_sphles(const std::vector<std::string>& args,
                                const fs::path& directory = fs::current_path(),
                                std::chrono::seconds timeout = 120s) {
  const fs::path out_file = directory / ".sphles-test-stdout";
  const fs::path err_file = directory / ".sphles-test-stderr";
  // Everything the child needs is prepared before fork: only async-signal-safe calls after it.
  std::vector<char*> argv{const_cast<char*>(SPHLES_BINARY)};
  for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  const pid_t pid = ::fork();
  if (pid == 0) {
    if (::chdir(directory.c_str()) != 0) ::_exit(127);
    const int out = ::open(out_file.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    const int err = ::open(err_file.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    ::dup2(out, 1);
    ::dup2(err, 2);
    ::execv(SPHLES_BINARY, argv.data());
    ::_exit(127);
  }
  ProcessResult result;
  int status = 0;
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (::waitpid(pid, &status, WNOHANG) == 0) {
    if (std::chrono::steady_clock::now() > deadline) {
      ::kill(pid, SIGKILL);
      ::waitpid(pid, &status, 0);
      break;
    }
    std::this_thread::sleep_for(10ms);
  }
  result.code = WIFEXITED(status) ? WEXITSTATUS(status) : -WTERMSIG(status);
  std::ifstream o(out_file), e(err_file);
  result.out.assign(std::istreambuf_iterator<char>(o), std::istreambuf_iterator<char>());
  result.err.assign(std::istreambuf_iterator<char>(e), std::istreambuf_iterator<char>());
  fs::remove(out_file);
  fs::remove(err_file);
  return result;
}

/// `sphles serve --port 0 ARGS...` as a child process: started, its port read from the one line
/// it prints on stdout, signalled and reaped by the test. Killed if the test forgets it.
class ServeProcess {
 public:
  explicit ServeProcess(const std::vector<std::string>& args, const fs::path& stderr_file) {
    int pipe_fds[2];
    if (::pipe(pipe_fds) != 0) throw std::runtime_error("pipe failed");
    std::vector<std::string> all{SPHLES_BINARY, "serve", "--port", "0"};
    all.insert(all.end(), args.begin(), args.end());
    std::vector<char*> argv;
    for (std::string& a : all) argv.push_back(a.data());
    argv.push_back(nullptr);
    pid_ = ::fork();
    if (pid_ == 0) {
      ::close(pipe_fds[0]);
      ::dup2(pipe_fds[1], 1);
      const int err = ::open(stderr_file.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      ::dup2(err, 2);
      ::execv(SPHLES_BINARY, argv.data());
      ::_exit(127);
    }
    ::close(pipe_fds[1]);
    stdout_ = pipe_fds[0];
    // "sphles serve: listening on http://127.0.0.1:PORT/"
    std::string line;
    const auto deadline = std::chrono::steady_clock::now() + 60s;
    while (line.find('\n') == std::string::npos && std::chrono::steady_clock::now() < deadline) {
      pollfd p{stdout_, POLLIN, 0};
      if (::poll(&p, 1, 100) <= 0) continue;
      char c = 0;
      if (::read(stdout_, &c, 1) != 1) break;
      line += c;
    }
    const std::size_t colon = line.rfind(':');
    if (line.find("listening on http://") == std::string::npos || colon == std::string::npos)
      throw std::runtime_error("sphles serve did not start: '" + line + "'");
    port_ = static_cast<unsigned short>(std::atoi(line.c_str() + colon + 1));
  }
  ~ServeProcess() {
    if (pid_ > 0 && !exited_) {
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, nullptr, 0);
    }
    if (stdout_ >= 0) ::close(stdout_);
  }
  ServeProcess(const ServeProcess&) = delete;
  ServeProcess& operator=(const ServeProcess&) = delete;

  unsigned short port() const { return port_; }
  pid_t pid() const { return pid_; }
  void signal(int number) const { ::kill(pid_, number); }
  /// Exit status (or -signal) once the process has ended, nullopt if it has not within `limit`.
  std::optional<int> wait_exit(std::chrono::milliseconds limit) {
    const auto deadline = std::chrono::steady_clock::now() + limit;
    int status = 0;
    while (std::chrono::steady_clock::now() < deadline) {
      if (::waitpid(pid_, &status, WNOHANG) == pid_) {
        exited_ = true;
        return WIFEXITED(status) ? WEXITSTATUS(status) : -WTERMSIG(status);
      }
      std::this_thread::sleep_for(20ms);
    }
    return std::nullopt;
  }

 private:
  pid_t pid_ = -1;
  int stdout_ = -1;
  unsigned short port_ = 0;
  bool exited_ = false;
};

}  // namespace sphles_server_test
