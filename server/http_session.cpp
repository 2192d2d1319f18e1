// SPDX-License-Identifier: GPL-3.0-or-later
#include "server/http_session.hpp"

#include <boost/asio/bind_executor.hpp>
#include <boost/asio/dispatch.hpp>
#include <boost/asio/post.hpp>
#include <boost/beast/core/bind_handler.hpp>
#include <boost/beast/http/read.hpp>
#include <boost/beast/http/write.hpp>
#include <boost/beast/websocket/rfc6455.hpp>
#include <filesystem>
#include <utility>

#include "logging/logging.hpp"
#include "server/url.hpp"

namespace sphles::server {

namespace beast = boost::beast;
namespace http = beast::http;
namespace net = boost::asio;
using tcp = net::ip::tcp;

SessionContext::SessionContext(control::RunManager& manager, ServerOptions opts)
    : options(std::move(opts)),
      log(logging::console("http")),
      streams(StreamQuota{options.max_public_streams, options.max_public_streams_per_address}),
      products(options.responses.max_bytes),
      table(options, streams),
      bulk_reads(options.max_bulk_reads_per_address),
      router(
          manager, streams, products,
          RouterOptions{options.token, options.web_root, options.responses,
                        options.reference_dir.empty() ? std::filesystem::path(SPHLES_REFERENCE_DIR)
                                                      : options.reference_dir,
                        options.scenes_dir.empty() ? std::filesystem::path(SPHLES_SCENES_DIR)
                                                   : options.scenes_dir}) {}

HttpSession::HttpSession(tcp::socket&& socket, SessionContext& server)
    : stream_(std::move(socket)), executor_(stream_.get_executor()), server_(server) {}

HttpSession::~HttpSession() {
  server_.table.release_response(reserved_);
  server_.table.remove(this);
}

void HttpSession::start(std::string address) {
  address_ = address;
  server_.table.add(this, weak_from_this(), std::move(address));
  net::dispatch(stream_.get_executor(),
                beast::bind_front_handler(&HttpSession::do_read, shared_from_this()));
}

void HttpSession::close() {
  net::post(executor_, [self = shared_from_this()] {
    if (self->upgraded_) return;
    self->close_now();
  });
}

void HttpSession::evict() {
  net::post(executor_, [self = shared_from_this()] {
    const Phase p = self->phase();
    if (self->upgraded_ || (p != Phase::reading && p != Phase::lingering))
      return self->server_.table.spare(self.get());
    self->close_now();
  });
}

void HttpSession::close_now() {
  beast::error_code ec;
  stream_.socket().shutdown(tcp::socket::shutdown_both, ec);
  stream_.close();
}

void HttpSession::do_read() {
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

void HttpSession::on_header(beast::error_code ec, std::size_t) {
  if (ec) return on_read_error(ec);
  if (parser_->is_done()) return on_request();
  stream_.expires_after(server_.options.request_timeout);
  http::async_read(stream_, buffer_, *parser_,
                   beast::bind_front_handler(&HttpSession::on_body, shared_from_this()));
}

void HttpSession::on_body(beast::error_code ec, std::size_t) {
  if (ec) return on_read_error(ec);
  on_request();
}

void HttpSession::on_read_error(beast::error_code ec) {
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

void HttpSession::on_request() {
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
  const bool bulk = server_.router.is_bulk(request);
  std::shared_ptr<void> slot;
  if (bulk && !(slot = server_.bulk_reads.acquire(address_))) {
    Response busy = error_response(
        ApiError(429, std::to_string(server_.bulk_reads.per_address()) +
                          " large reads (time series, files, logs, movies) from " + address_ +
                          " are in progress, the most one address may have at once; retry when "
                          "one has been answered"),
        request.version(), request.keep_alive());
    busy.set(http::field::retry_after, "1");
    return send(std::move(busy));
  }
  net::post(
      bulk   ? server_.bulk
      : read ? server_.work
             : server_.control,
      [self = shared_from_this(), request = std::move(request), slot = std::move(slot)] {
        try {
          ConnectionTable& table = self->server_.table;
          auto response = std::make_shared<Response>(self->server_.router.handle(request));
          std::size_t bytes = response->body().owned_bytes();
          if (!table.reserve_response(bytes)) {
            *response = error_response(
                ApiError(503, "the server holds " + std::to_string(table.pending_response_bytes()) +
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

void HttpSession::upgrade(Request request) {
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
      server_.control.get_executor(), server_.options.stream, target.authorised, std::move(ticket));
  session->start(std::move(request));
  // This HttpSession ends here; the connection belongs to the WebSocket session now.
}

void HttpSession::send(Response response) {
  enter(Phase::writing);
  response_ = std::move(response);
  const bool close = !response_->keep_alive();
  stream_.expires_after(server_.options.request_timeout);
  http::async_write(stream_, *response_,
                    beast::bind_front_handler(&HttpSession::on_write, shared_from_this(), close));
}

void HttpSession::on_write(bool close, beast::error_code ec, std::size_t bytes) {
  log_request(response_->result_int(), bytes);
  response_.reset();
  server_.table.release_response(std::exchange(reserved_, 0));
  if (ec) return shutdown();
  if (close) return linger();
  do_read();
}

void HttpSession::shutdown() {
  beast::error_code ec;
  stream_.socket().shutdown(tcp::socket::shutdown_send, ec);
}

/// After a "Connection: close" response: half-close, then read and discard what the client is
/// still sending (say the rest of a body that drew a 413) for up to 2 s or 8 MiB. Closing with
/// unread data would send a reset, and the client could lose the response (lingering close).
void HttpSession::linger() {
  enter(Phase::lingering);
  shutdown();
  stream_.expires_after(std::chrono::seconds(2));
  drain(0);
}

void HttpSession::drain(std::size_t drained) {
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
void HttpSession::note_request() {
  request_started_ = Clock::now();
  if (parser_ && parser_->is_header_done()) {
    const auto& header = parser_->get();
    request_line_ = std::string(header.method_string()) + " " +
                    loggable_target(std::string_view(header.target()));
  } else {
    request_line_ = "-";
  }
}

/// One line per answered request: peer, request, status, bytes written, time from the complete
/// request to the written response. Reads that succeed (a dashboard's polls: most of the lines)
/// at debug; changes and refusals at info; 5xx at warn.
void HttpSession::log_request(unsigned status, std::size_t bytes) {
  const double ms =
      std::chrono::duration<double, std::milli>(Clock::now() - request_started_).count();
  const bool read = request_line_.starts_with("GET ") || request_line_.starts_with("HEAD ");
  const spdlog::level::level_enum level = status >= 500          ? spdlog::level::warn
                                          : read && status < 400 ? spdlog::level::debug
                                                                 : spdlog::level::info;
  server_.log->log(level, "{} \"{}\" {} {} B {:.1f} ms", address_, request_line_, status, bytes,
                   ms);
}

}  // namespace sphles::server
