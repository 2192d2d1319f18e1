// SPDX-License-Identifier: GPL-3.0-or-later
#include "server/http_server.hpp"

#include <pthread.h>
#include <atomic>
#include <boost/asio/bind_executor.hpp>
#include <boost/asio/dispatch.hpp>
#include <boost/asio/executor_work_guard.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/asio/strand.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket/rfc6455.hpp>
#include <condition_variable>
#include <cstdio>
#include <future>
#include <map>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <thread>
#include <utility>
#include <vector>

#include "logging/logging.hpp"
#include "server/router.hpp"
#include "server/url.hpp"
#include "server/websocket_session.hpp"

namespace sphles::server {

namespace beast = boost::beast;
namespace http = beast::http;
namespace net = boost::asio;
using tcp = net::ip::tcp;

class HttpSession;

namespace {

using Clock = std::chrono::steady_clock;

/// Where an HTTP connection is; eviction takes lingering ones first, then reading ones (oldest
/// first), never one whose request is being handled or whose response is being written.
enum class Phase : int { reading, handling, writing, lingering };

std::int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch())
      .count();
}

/// Runs an io_context until it is stopped or out of work. An exception from a handler ends
/// that handler only (its connection closes as its last owner goes); the thread carries on.
void run_context(net::io_context& context, const char* what) noexcept {
  for (;;) {
    try {
      context.run();
      return;
    } catch (const std::exception& e) {
      logging::console("http")->error("{}: a handler failed: {}", what, e.what());
    } catch (...) {
      logging::console("http")->error("{}: a handler failed", what);
    }
  }
}

}  // namespace

struct HttpServer::Impl {
  Impl(control::RunManager& manager, ServerOptions opts)
      : options(std::move(opts)),
        streams(StreamQuota{options.max_public_streams, options.max_public_streams_per_address}),
        products(options.responses.max_bytes),
        acceptor(net::make_strand(ioc)),
        router(manager, streams, products,
               RouterOptions{options.token, options.web_root, options.responses,
                             options.reference_dir.empty()
                                 ? std::filesystem::path(SPHLES_REFERENCE_DIR)
                                 : options.reference_dir}) {}

  void do_accept();
  void on_accept(beast::error_code ec, tcp::socket socket);
  void add(HttpSession* session, std::weak_ptr<HttpSession> weak, std::string address);
  void remove(HttpSession* session);
  void spare(HttpSession* session);  // an eviction that found the session busy
  std::size_t connections() const;
  /// Room for a response body of `bytes` among the unsent ones (max_pending_response_bytes).
  bool reserve_response(std::size_t bytes);
  void release_response(std::size_t bytes);

  // Declaration order is destruction order in reverse: sessions still owned by handlers die with
  // the io_context and unregister from `sessions` and `streams`, which must outlive it.
  ServerOptions options;
  std::shared_ptr<spdlog::logger> http_log = logging::console("http");
  StreamRegistry streams;
  ProductCache products;
  struct Entry {
    std::weak_ptr<HttpSession> session;
    std::string address;
    bool evicting = false;  // told to close; no longer counted
  };
  mutable std::mutex mutex;  // guards sessions
  std::condition_variable sessions_changed;
  std::map<HttpSession*, Entry> sessions;
  std::atomic<std::size_t> pending_response_bytes{0};
  // Request handlers, off the I/O threads: reads on `work`, run control (which may block: a stop
  // writes a checkpoint) on `control`, so that reads never queue behind it.
  net::io_context work;
  net::io_context control;
  std::optional<net::executor_work_guard<net::io_context::executor_type>> keep_working;
  std::optional<net::executor_work_guard<net::io_context::executor_type>> keep_controlling;
  std::vector<std::thread> worker_threads;
  net::io_context ioc;
  // Keeps the I/O threads running while nothing is pending (e.g. after stop_accepting).
  std::optional<net::executor_work_guard<net::io_context::executor_type>> keep_running;
  tcp::acceptor acceptor;
  net::steady_timer accept_retry{acceptor.get_executor()};
  Router router;
  std::vector<std::thread> threads;
  unsigned short port = 0;
  bool started = false, accepting = false, stopped = false;

 private:
  HttpSession* victim(const std::string* address) const;  // under `mutex`
  void refuse(tcp::socket& socket, const std::string& reason);
};

/// One HTTP connection: reads a request (limits from ServerOptions), hands it to the router on
/// the worker pool, writes the response, and repeats while keep-alive; or hands the connection
/// to a WebSocketSession on an upgrade.
class HttpSession : public std::enable_shared_from_this<HttpSession> {
 public:
  HttpSession(tcp::socket&& socket, HttpServer::Impl& server)
      : stream_(std::move(socket)), executor_(stream_.get_executor()), server_(server) {}
  ~HttpSession() {
    server_.release_response(reserved_);
    server_.remove(this);
  }

  void start(std::string address) {
    address_ = address;
    server_.add(this, weak_from_this(), std::move(address));
    net::dispatch(stream_.get_executor(),
                  beast::bind_front_handler(&HttpSession::do_read, shared_from_this()));
  }

  /// Any thread: ends the connection (pending operations fail and release the session).
  void close() {
    net::post(executor_, [self = shared_from_this()] {
      if (self->upgraded_) return;
      self->close_now();
    });
  }

  /// Any thread: closes the connection if it is still only reading or lingering (a newcomer
  /// needs its place); otherwise leaves it alone.
  void evict() {
    net::post(executor_, [self = shared_from_this()] {
      const Phase p = self->phase();
      if (self->upgraded_ || (p != Phase::reading && p != Phase::lingering))
        return self->server_.spare(self.get());
      self->close_now();
    });
  }

  Phase phase() const { return static_cast<Phase>(phase_.load(std::memory_order_acquire)); }
  std::int64_t phase_since() const { return phase_since_.load(std::memory_order_acquire); }

 private:
  void enter(Phase p) {
    phase_since_.store(now_ns(), std::memory_order_release);
    phase_.store(static_cast<int>(p), std::memory_order_release);
  }

  void close_now() {
    beast::error_code ec;
    stream_.socket().shutdown(tcp::socket::shutdown_both, ec);
    stream_.close();
  }

  void do_read() {
    enter(Phase::reading);
    parser_.emplace();
    parser_->body_limit(server_.options.body_limit);
    parser_->header_limit(static_cast<std::uint32_t>(server_.options.header_limit));
    // The header has header_timeout from now (slowloris); the body, once the header is in, the
    // longer request_timeout.
    stream_.expires_after(server_.options.header_timeout);
    http::async_read_header(stream_, buffer_, *parser_,
                            beast::bind_front_handler(&HttpSession::on_header, shared_from_this()));
  }

  void on_header(beast::error_code ec, std::size_t) {
    if (ec) return on_read_error(ec);
    if (parser_->is_done()) return on_request();
    stream_.expires_after(server_.options.request_timeout);
    http::async_read(stream_, buffer_, *parser_,
                     beast::bind_front_handler(&HttpSession::on_body, shared_from_this()));
  }

  void on_body(beast::error_code ec, std::size_t) {
    if (ec) return on_read_error(ec);
    on_request();
  }

  void on_read_error(beast::error_code ec) {
    if (ec == http::error::end_of_stream) return shutdown();
    note_request();
    // Malformed HTTP is answered (then the connection closes: its framing is lost);
    // network errors and timeouts just close.
    if (ec.category() != http::make_error_code(http::error::end_of_stream).category())
      return shutdown();
    if (ec == http::error::body_limit)
      return send(error_response(ApiError(413,
                                          "request body larger than " +
                                              std::to_string(server_.options.body_limit) + " bytes",
                                          "body"),
                                 11, false));
    if (ec == http::error::header_limit)
      return send(
          error_response(ApiError(431, "request header larger than " +
                                           std::to_string(server_.options.header_limit) + " bytes"),
                         11, false));
    send(error_response(ApiError(400, "malformed HTTP request: " + ec.message()), 11, false));
  }

  void on_request() {
    enter(Phase::handling);
    stream_.expires_never();  // the worker may take a while (stop writes a checkpoint)
    note_request();
    Request request = parser_->release();
    if (beast::websocket::is_upgrade(request)) return upgrade(std::move(request));

    // Run control may block (stop writes a checkpoint): handle on a worker pool, write here.
    // Reads and run control have pools of their own. Nothing may escape (it would end a worker
    // thread's handler): if even an error response cannot be made, the connection closes as the
    // last owner of the session goes.
    const bool read = request.method() == http::verb::get || request.method() == http::verb::head;
    net::post(read ? server_.work : server_.control, [self = shared_from_this(),
                                                      request = std::move(request)] {
      try {
        auto response = std::make_shared<Response>(self->server_.router.handle(request));
        std::size_t bytes = response->body().owned_bytes();
        if (!self->server_.reserve_response(bytes)) {
          *response = error_response(
              ApiError(503, "the server holds " +
                                std::to_string(self->server_.pending_response_bytes.load()) +
                                " bytes of responses not yet sent (its limit is " +
                                std::to_string(self->server_.options.max_pending_response_bytes) +
                                "); try again shortly"),
              request.version(), request.keep_alive());
          bytes = 0;
        }
        net::post(self->executor_, [self, response, bytes] {
          self->reserved_ = bytes;
          self->send(std::move(*response));
        });
      } catch (...) {
      }
    });
  }

  void upgrade(Request request) {
    Router::StreamTarget target = server_.router.stream_target(request);
    if (target.error) return send(std::move(*target.error));
    StreamTicket ticket;
    try {
      ticket = server_.streams.admit(address_, !target.token_holder);
    } catch (const ApiError& e) {
      return send(error_response(e, request.version(), false));
    }
    upgraded_ = true;
    log_request(101, 0);
    auto session = std::make_shared<WebSocketSession>(
        std::move(stream_), std::move(target.run), server_.streams, server_.products,
        server_.control.get_executor(), server_.options.stream, target.authorised,
        std::move(ticket));
    session->start(std::move(request));
    // This HttpSession ends here; the connection belongs to the WebSocket session now.
  }

  void send(Response response) {
    enter(Phase::writing);
    response_ = std::move(response);
    const bool close = !response_->keep_alive();
    stream_.expires_after(server_.options.request_timeout);
    http::async_write(stream_, *response_,
                      beast::bind_front_handler(&HttpSession::on_write, shared_from_this(), close));
  }

  void on_write(bool close, beast::error_code ec, std::size_t bytes) {
    log_request(response_->result_int(), bytes);
    response_.reset();
    server_.release_response(std::exchange(reserved_, 0));
    if (ec) return shutdown();
    if (close) return linger();
    do_read();
  }

  void shutdown() {
    beast::error_code ec;
    stream_.socket().shutdown(tcp::socket::shutdown_send, ec);
  }

  /// After a "Connection: close" response: half-close, then read and discard what the client is
  /// still sending (say the rest of a body that drew a 413) for up to 2 s or 8 MiB. Closing with
  /// unread data would send a reset, and the client could lose the response (lingering close).
  void linger() {
    enter(Phase::lingering);
    shutdown();
    stream_.expires_after(std::chrono::seconds(2));
    drain(0);
  }
  void drain(std::size_t drained) {
    constexpr std::size_t kMaxDrain = 8u << 20;
    if (drained > kMaxDrain) return;
    drain_buffer_.resize(64u << 10);
    stream_.async_read_some(net::buffer(drain_buffer_), [self = shared_from_this(), drained](
                                                            beast::error_code ec, std::size_t n) {
      if (!ec) self->drain(drained + n);
    });
  }

  /// What the request log says of the request being handled: its method and target (a token
  /// in the query hidden), or "-" when the header could not be read; and when handling began.
  void note_request() {
    request_started_ = Clock::now();
    if (parser_ && parser_->is_header_done()) {
      const auto& header = parser_->get();
      request_line_ = std::string(header.method_string()) + " " +
                      loggable_target(std::string_view(header.target()));
    } else {
      request_line_ = "-";
    }
  }
  /// One line per answered request at info (5xx at warn): peer, request, status, bytes written,
  /// time from the complete request to the written response.
  void log_request(unsigned status, std::size_t bytes) {
    const double ms =
        std::chrono::duration<double, std::milli>(Clock::now() - request_started_).count();
    server_.http_log->log(status >= 500 ? spdlog::level::warn : spdlog::level::info,
                          "{} \"{}\" {} {} B {:.1f} ms", address_, request_line_, status, bytes,
                          ms);
  }

  beast::tcp_stream stream_;
  beast::tcp_stream::executor_type executor_;  // the connection's strand, kept after an upgrade
  HttpServer::Impl& server_;
  std::string address_;  // the peer's
  std::string request_line_ = "-";
  Clock::time_point request_started_ = Clock::now();
  bool upgraded_ = false;
  std::atomic<int> phase_{static_cast<int>(Phase::reading)};
  std::atomic<std::int64_t> phase_since_{now_ns()};
  std::size_t reserved_ = 0;  // of pending_response_bytes, for the response being written
  beast::flat_buffer buffer_;
  std::optional<http::request_parser<http::string_body>> parser_;
  std::optional<Response> response_;
  std::vector<char> drain_buffer_;
};

void HttpServer::Impl::add(HttpSession* session, std::weak_ptr<HttpSession> weak,
                           std::string address) {
  std::lock_guard lock(mutex);
  sessions[session] = Entry{std::move(weak), std::move(address), false};
}

void HttpServer::Impl::remove(HttpSession* session) {
  {
    std::lock_guard lock(mutex);
    sessions.erase(session);
  }
  sessions_changed.notify_all();
}

void HttpServer::Impl::spare(HttpSession* session) {
  std::lock_guard lock(mutex);
  if (const auto it = sessions.find(session); it != sessions.end()) it->second.evicting = false;
}

std::size_t HttpServer::Impl::connections() const {
  std::size_t http_sessions = 0;
  {
    std::lock_guard lock(mutex);
    http_sessions = sessions.size();
  }
  return http_sessions + streams.admitted();
}

bool HttpServer::Impl::reserve_response(std::size_t bytes) {
  if (bytes == 0) return true;
  std::size_t held = pending_response_bytes.load();
  do {
    if (held + bytes > options.max_pending_response_bytes) return false;
  } while (!pending_response_bytes.compare_exchange_weak(held, held + bytes));
  return true;
}

void HttpServer::Impl::release_response(std::size_t bytes) {
  if (bytes > 0) pending_response_bytes.fetch_sub(bytes);
}

HttpSession* HttpServer::Impl::victim(const std::string* address) const {
  // Lingering first, then reading, each the longest in its phase first.
  HttpSession* best = nullptr;
  std::pair<int, std::int64_t> best_rank{};
  for (const auto& [session, entry] : sessions) {
    if (entry.evicting || (address && entry.address != *address)) continue;
    const Phase p = session->phase();
    if (p != Phase::lingering && p != Phase::reading) continue;
    const std::pair<int, std::int64_t> rank{p == Phase::lingering ? 0 : 1, session->phase_since()};
    if (!best || rank < best_rank) {
      best = session;
      best_rank = rank;
    }
  }
  return best;
}

void HttpServer::Impl::refuse(tcp::socket& socket, const std::string& reason) {
  // Written at once, without reading the request (a fresh socket's send buffer takes it); a
  // client that has already sent its request may see a reset instead.
  beast::error_code no_peer;
  const auto peer = socket.remote_endpoint(no_peer);
  http_log->warn("{} refused with 503: {}", no_peer ? std::string("-") : peer.address().to_string(),
                 reason);
  try {
    const std::string body = dump(error_json(ApiError(503, reason)));
    const std::string response =
        "HTTP/1.1 503 Service Unavailable\r\nContent-Type: application/json\r\n"
        "Cache-Control: no-store\r\nRetry-After: 1\r\nConnection: close\r\nContent-Length: " +
        std::to_string(body.size()) + "\r\n\r\n" + body;
    beast::error_code ec;
    socket.non_blocking(true, ec);
    socket.write_some(net::buffer(response), ec);
    socket.shutdown(tcp::socket::shutdown_both, ec);
  } catch (const std::exception&) {
  }
  beast::error_code ignored;
  socket.close(ignored);
}

void HttpServer::Impl::do_accept() {
  acceptor.async_accept(net::make_strand(ioc), [this](beast::error_code ec, tcp::socket socket) {
    on_accept(ec, std::move(socket));
  });
}

void HttpServer::Impl::on_accept(beast::error_code ec, tcp::socket socket) {
  if (ec == net::error::operation_aborted || !acceptor.is_open()) return;
  if (ec) {
    // E.g. out of file descriptors: try again shortly rather than spin.
    accept_retry.expires_after(std::chrono::milliseconds(100));
    accept_retry.async_wait([this](beast::error_code wait_ec) {
      if (!wait_ec) do_accept();
    });
    return;
  }
  try {
    beast::error_code peer_ec;
    const tcp::endpoint peer = socket.remote_endpoint(peer_ec);
    if (peer_ec) {
      socket.close(peer_ec);
      return do_accept();
    }
    const std::string address = peer.address().to_string();
    std::shared_ptr<HttpSession> evicted;
    std::string refusal;
    {
      std::lock_guard lock(mutex);
      std::size_t open = 0, mine = 0;
      for (const auto& [session, entry] : sessions) {
        if (entry.evicting) continue;
        ++open;
        if (entry.address == address) ++mine;
      }
      open += streams.admitted();
      HttpSession* chosen = nullptr;
      if (mine >= options.max_connections_per_address) {
        chosen = victim(&address);
        if (!chosen)
          refusal = "too many connections from " + address + " (" + std::to_string(mine) +
                    ", the limit per address), all of them busy; try again shortly";
      } else if (open >= options.max_connections) {
        chosen = victim(nullptr);
        if (!chosen)
          refusal = "the server is full (" + std::to_string(open) +
                    " connections), all of them busy; try again shortly";
      }
      if (chosen) {
        auto& entry = sessions[chosen];
        evicted = entry.session.lock();
        entry.evicting = true;
      }
    }
    if (!refusal.empty()) {
      refuse(socket, refusal);
    } else {
      std::make_shared<HttpSession>(std::move(socket), *this)->start(address);
      if (evicted) evicted->evict();
    }
  } catch (const std::exception& e) {
    // Out of memory for a new session: this connection goes, the server stays.
    beast::error_code ignored;
    socket.close(ignored);
  }
  do_accept();
}

HttpServer::HttpServer(control::RunManager& manager, ServerOptions options)
    : impl_(std::make_unique<Impl>(manager, std::move(options))) {}

HttpServer::~HttpServer() {
  stop();
}

void HttpServer::start() {
  Impl& s = *impl_;
  if (s.started) throw std::logic_error("HttpServer::start called twice");
  if (s.options.max_public_streams >= s.options.max_connections)
    throw std::invalid_argument(
        "max_public_streams (" + std::to_string(s.options.max_public_streams) +
        ") must be below max_connections (" + std::to_string(s.options.max_connections) +
        "): the difference is what read-only streams can never take from API calls and the "
        "token holder");
  beast::error_code ec;
  const net::ip::address address = net::ip::make_address(s.options.address, ec);
  if (ec) throw std::runtime_error("'--bind " + s.options.address + "' is not an IP address");
  const tcp::endpoint endpoint{address, s.options.port};
  const auto fail = [&](const char* what) {
    throw std::runtime_error("cannot " + std::string(what) + " " + s.options.address + ":" +
                             std::to_string(s.options.port) + ": " + ec.message());
  };
  s.acceptor.open(endpoint.protocol(), ec);
  if (ec) fail("open a socket for");
  s.acceptor.set_option(net::socket_base::reuse_address(true), ec);
  s.acceptor.bind(endpoint, ec);
  if (ec) fail("bind to");
  s.acceptor.listen(net::socket_base::max_listen_connections, ec);
  if (ec) fail("listen on");
  s.port = s.acceptor.local_endpoint().port();
  s.started = true;
  s.accepting = true;
  s.keep_running.emplace(s.ioc.get_executor());
  s.keep_working.emplace(s.work.get_executor());
  s.keep_controlling.emplace(s.control.get_executor());
  s.do_accept();
  const int n = std::max(1, s.options.io_threads);
  for (int k = 0; k < n; ++k)
    s.threads.emplace_back([&s] {
      pthread_setname_np(pthread_self(), "sphles-io");  // for top -H and the benchmark
      run_context(s.ioc, "I/O thread");
    });
  for (int k = 0; k < std::max(1, s.options.worker_threads); ++k)
    s.worker_threads.emplace_back([&s] {
      pthread_setname_np(pthread_self(), "sphles-worker");
      run_context(s.work, "worker thread");
    });
  for (int k = 0; k < std::max(1, s.options.control_threads); ++k)
    s.worker_threads.emplace_back([&s] {
      pthread_setname_np(pthread_self(), "sphles-control");
      run_context(s.control, "control thread");
    });
}

unsigned short HttpServer::port() const {
  return impl_->port;
}

std::string HttpServer::url() const {
  const std::string& host = impl_->options.address;
  const bool v6 = host.find(':') != std::string::npos;
  return "http://" + (v6 ? "[" + host + "]" : host) + ":" + std::to_string(impl_->port) + "/";
}

void HttpServer::stop_accepting() {
  Impl& s = *impl_;
  if (!s.started || !s.accepting) return;
  s.accepting = false;
  std::promise<void> done;
  net::post(s.acceptor.get_executor(), [&s, &done] {
    beast::error_code ec;
    s.acceptor.close(ec);
    s.accept_retry.cancel();
    done.set_value();
  });
  done.get_future().wait();
}

void HttpServer::stop() {
  Impl& s = *impl_;
  if (!s.started || s.stopped) return;
  stop_accepting();
  s.stopped = true;

  s.streams.close_all();
  std::vector<std::shared_ptr<HttpSession>> open;
  {
    std::lock_guard lock(s.mutex);
    for (auto& [key, entry] : s.sessions)
      if (auto session = entry.session.lock()) open.push_back(std::move(session));
  }
  for (const auto& session : open) session->close();
  open.clear();

  // Give close frames and responses in flight a moment, then stop regardless.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(2);
  {
    std::unique_lock lock(s.mutex);
    while ((!s.sessions.empty() || s.streams.admitted() > 0) &&
           std::chrono::steady_clock::now() < deadline)
      s.sessions_changed.wait_for(lock, std::chrono::milliseconds(20));
  }
  // Requests in progress finish (their responses are dropped below).
  s.keep_working.reset();
  s.keep_controlling.reset();
  for (std::thread& t : s.worker_threads) t.join();
  s.worker_threads.clear();
  s.keep_running.reset();
  s.ioc.stop();
  for (std::thread& t : s.threads) t.join();
  s.threads.clear();
}

std::size_t HttpServer::connections() const {
  return impl_->connections();
}

const Router& HttpServer::router() const {
  return impl_->router;
}

}  // namespace sphles::server
