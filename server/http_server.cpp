#include "server/http_server.hpp"

#include <pthread.h>
#include <boost/asio/bind_executor.hpp>
#include <boost/asio/dispatch.hpp>
#include <boost/asio/executor_work_guard.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/asio/strand.hpp>
#include <boost/asio/thread_pool.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket/rfc6455.hpp>
#include <condition_variable>
#include <future>
#include <map>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <thread>
#include <vector>

#include "server/routes.hpp"
#include "server/websocket_session.hpp"

namespace sphles::server {

namespace beast = boost::beast;
namespace http = beast::http;
namespace net = boost::asio;
using tcp = net::ip::tcp;

class HttpSession;

struct HttpServer::Impl {
  Impl(control::RunManager& manager, ServerOptions opts)
      : options(std::move(opts)),
        workers(static_cast<std::size_t>(std::max(1, options.worker_threads))),
        acceptor(net::make_strand(ioc)),
        router(manager, streams, RouterOptions{options.token, options.web_root}) {}

  void do_accept();
  void on_accept(beast::error_code ec, tcp::socket socket);
  void add(HttpSession* session, std::weak_ptr<HttpSession> weak);
  void remove(HttpSession* session);
  std::size_t connections() const;

  // Declaration order is destruction order in reverse: sessions still owned by handlers die with
  // the io_context and unregister from `sessions` and `streams`, which must outlive it.
  ServerOptions options;
  StreamRegistry streams;
  mutable std::mutex mutex;  // guards sessions
  std::condition_variable sessions_changed;
  std::map<HttpSession*, std::weak_ptr<HttpSession>> sessions;
  net::thread_pool workers;
  net::io_context ioc;
  // Keeps the I/O threads running while nothing is pending (e.g. after stop_accepting).
  std::optional<net::executor_work_guard<net::io_context::executor_type>> keep_running;
  tcp::acceptor acceptor;
  net::steady_timer accept_retry{acceptor.get_executor()};
  Router router;
  std::vector<std::thread> threads;
  unsigned short port = 0;
  bool started = false, accepting = false, stopped = false;
};

/// One HTTP connection: reads a request (limits from ServerOptions), hands it to the router on
/// the worker pool, writes the response, and repeats while keep-alive; or hands the connection
/// to a WebSocketSession on an upgrade.
class HttpSession : public std::enable_shared_from_this<HttpSession> {
 public:
  HttpSession(tcp::socket&& socket, HttpServer::Impl& server)
      : stream_(std::move(socket)), executor_(stream_.get_executor()), server_(server) {}
  ~HttpSession() { server_.remove(this); }

  void start() {
    server_.add(this, weak_from_this());
    net::dispatch(stream_.get_executor(),
                  beast::bind_front_handler(&HttpSession::do_read, shared_from_this()));
  }

  /// Any thread: ends the connection (pending operations fail and release the session).
  void close() {
    net::post(executor_, [self = shared_from_this()] {
      if (self->upgraded_) return;
      beast::error_code ec;
      self->stream_.socket().shutdown(tcp::socket::shutdown_both, ec);
      self->stream_.close();
    });
  }

 private:
  void do_read() {
    parser_.emplace();
    parser_->body_limit(server_.options.body_limit);
    parser_->header_limit(static_cast<std::uint32_t>(server_.options.header_limit));
    stream_.expires_after(server_.options.request_timeout);
    http::async_read(stream_, buffer_, *parser_,
                     beast::bind_front_handler(&HttpSession::on_read, shared_from_this()));
  }

  void on_read(beast::error_code ec, std::size_t) {
    if (ec == http::error::end_of_stream) return shutdown();
    if (ec) {
      // Malformed HTTP is answered (then the connection closes: its framing is lost);
      // network errors and timeouts just close.
      if (ec.category() != http::make_error_code(http::error::end_of_stream).category())
        return shutdown();
      if (ec == http::error::body_limit)
        return send(error_response(
            ApiError(
                413,
                "request body larger than " + std::to_string(server_.options.body_limit) + " bytes",
                "body"),
            11, false));
      if (ec == http::error::header_limit)
        return send(error_response(
            ApiError(431, "request header larger than " +
                              std::to_string(server_.options.header_limit) + " bytes"),
            11, false));
      return send(
          error_response(ApiError(400, "malformed HTTP request: " + ec.message()), 11, false));
    }
    Request request = parser_->release();
    if (beast::websocket::is_upgrade(request)) return upgrade(std::move(request));

    // Run control may block (stop writes a checkpoint): handle on the worker pool, write here.
    net::post(server_.workers, [self = shared_from_this(), request = std::move(request)] {
      auto response = std::make_shared<Response>(self->server_.router.handle(request));
      net::post(self->stream_.get_executor(),
                [self, response] { self->send(std::move(*response)); });
    });
  }

  void upgrade(Request request) {
    Router::StreamTarget target = server_.router.stream_target(request);
    if (target.error) return send(std::move(*target.error));
    upgraded_ = true;
    auto session = std::make_shared<WebSocketSession>(
        std::move(stream_), std::move(target.run), server_.streams, server_.workers.get_executor(),
        server_.options.stream, target.authorised);
    session->start(std::move(request));
    // This HttpSession ends here; the connection belongs to the WebSocket session now.
  }

  void send(Response response) {
    response_ = std::move(response);
    const bool close = !response_->keep_alive();
    stream_.expires_after(server_.options.request_timeout);
    http::async_write(stream_, *response_,
                      beast::bind_front_handler(&HttpSession::on_write, shared_from_this(), close));
  }

  void on_write(bool close, beast::error_code ec, std::size_t) {
    response_.reset();
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

  beast::tcp_stream stream_;
  beast::tcp_stream::executor_type executor_;  // the connection's strand, kept after an upgrade
  HttpServer::Impl& server_;
  bool upgraded_ = false;
  beast::flat_buffer buffer_;
  std::optional<http::request_parser<http::string_body>> parser_;
  std::optional<Response> response_;
  std::vector<char> drain_buffer_;
};

void HttpServer::Impl::add(HttpSession* session, std::weak_ptr<HttpSession> weak) {
  std::lock_guard lock(mutex);
  sessions[session] = std::move(weak);
}

void HttpServer::Impl::remove(HttpSession* session) {
  {
    std::lock_guard lock(mutex);
    sessions.erase(session);
  }
  sessions_changed.notify_all();
}

std::size_t HttpServer::Impl::connections() const {
  std::size_t http_sessions = 0;
  {
    std::lock_guard lock(mutex);
    http_sessions = sessions.size();
  }
  return http_sessions + streams.size();
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
  if (connections() >= options.max_connections) {
    beast::error_code ignored;
    socket.close(ignored);
  } else {
    std::make_shared<HttpSession>(std::move(socket), *this)->start();
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
  s.do_accept();
  const int n = std::max(1, s.options.io_threads);
  for (int k = 0; k < n; ++k)
    s.threads.emplace_back([&s] {
      pthread_setname_np(pthread_self(), "sphles-io");  // for top -H and the benchmark
      s.ioc.run();
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
    for (auto& [key, weak] : s.sessions)
      if (auto session = weak.lock()) open.push_back(std::move(session));
  }
  for (const auto& session : open) session->close();
  open.clear();

  // Give close frames and responses in flight a moment, then stop regardless.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(2);
  {
    std::unique_lock lock(s.mutex);
    while ((!s.sessions.empty() || s.streams.size() > 0) &&
           std::chrono::steady_clock::now() < deadline)
      s.sessions_changed.wait_for(lock, std::chrono::milliseconds(20));
  }
  s.workers.join();  // requests in progress finish (their responses are dropped below)
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
