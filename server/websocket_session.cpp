// SPDX-License-Identifier: GPL-3.0-or-later
#include "server/websocket_session.hpp"

#include <array>
#include <boost/asio/bind_executor.hpp>
#include <boost/asio/post.hpp>
#include <boost/beast/core/bind_handler.hpp>
#include <boost/beast/core/buffers_to_string.hpp>
#include <boost/beast/version.hpp>
#include <boost/beast/websocket.hpp>
#include <type_traits>
#include <utility>

namespace sphles::server {

namespace beast = boost::beast;
namespace http = beast::http;
namespace net = boost::asio;
namespace websocket = beast::websocket;

namespace {

template <class... F>
struct Overloaded : F... {
  using F::operator()...;
};
template <class... F>
Overloaded(F...) -> Overloaded<F...>;

/// 4-byte big-endian length of the JSON header, then the header (docs/api.md).
std::string binary_head(const std::string& header) {
  const auto n = static_cast<std::uint32_t>(header.size());
  std::string head(4, '\0');
  head[0] = static_cast<char>((n >> 24) & 0xff);
  head[1] = static_cast<char>((n >> 16) & 0xff);
  head[2] = static_cast<char>((n >> 8) & 0xff);
  head[3] = static_cast<char>(n & 0xff);
  return head + header;
}

}  // namespace

WebSocketSession::WebSocketSession(beast::tcp_stream&& stream, std::shared_ptr<control::Run> run,
                                   StreamRegistry& registry, ProductCache& products,
                                   net::any_io_executor workers, StreamLimits limits,
                                   bool authorised, StreamTicket ticket)
    : ws_(std::move(stream)),
      run_(std::move(run)),
      registry_(registry),
      products_(products),
      workers_(std::move(workers)),
      limits_(limits),
      authorised_(authorised),
      ticket_(std::move(ticket)) {}

WebSocketSession::~WebSocketSession() {
  if (queue_) queue_->close();
  if (fanout_) fanout_->remove(queue_.get());
  registry_.remove(*this);
}

void WebSocketSession::start(http::request<http::string_body> upgrade) {
  // The websocket stream keeps its own timers: handshake 30 s, idle pings.
  beast::get_lowest_layer(ws_).expires_never();
  ws_.set_option(websocket::stream_base::timeout::suggested(beast::role_type::server));
  ws_.set_option(websocket::stream_base::decorator([](websocket::response_type& res) {
    res.set(http::field::server, "sphles/" SPHLES_VERSION);
  }));
  ws_.read_message_max(limits_.max_incoming);
  ws_.auto_fragment(false);
  ws_.async_accept(upgrade,
                   beast::bind_front_handler(&WebSocketSession::on_accept, shared_from_this()));
}

void WebSocketSession::on_accept(beast::error_code ec) {
  if (ec) return finish();
  // The wake posts to this session's strand and holds it only weakly: the run's threads never
  // own (and so never destroy) a session.
  std::weak_ptr<WebSocketSession> weak = weak_from_this();
  auto executor = ws_.get_executor();
  queue_ = std::make_shared<ClientQueue>(limits_, [weak, executor] {
    net::post(executor, [weak] {
      if (auto self = weak.lock()) self->on_wake();
    });
  });
  registry_.add(shared_from_this());
  fanout_ = registry_.fanout(run_);
  fanout_->add(queue_);  // from here on, items queue up behind the hello

  nlohmann::json hello = {{"type", "hello"},
                          {"run", run_detail_json(*run_, registry_.counters(run_->id()))}};
  out_head_ = dump(hello);
  out_png_.reset();
  out_shared_.reset();
  writing_ = true;
  ws_.text(true);
  write_out();
  do_read();
}

void WebSocketSession::on_wake() {
  if (started_ && !writing_ && !closing_) send_next();
}

void WebSocketSession::set_product(const std::shared_ptr<const analysis::AnalysisFrame>& frame,
                                   Product product, const char* type) {
  // {"type":"spectrum", + the shared body after its '{': no copy of the body per client.
  out_shared_ = products_.get(frame, product);
  out_head_ = std::string("{\"type\":\"") + type + "\",";
}

void WebSocketSession::send_next() {
  std::optional<QueuedItem> item = queue_->pop();
  if (!item) {
    writing_ = false;
    return;
  }
  writing_ = true;
  out_png_.reset();
  out_shared_.reset();
  bool binary = false;
  try {
    std::visit(
        Overloaded{
            [&](QueuedText& t) { out_head_ = std::move(t.text); },
            [&](QueuedMetrics& m) {
              nlohmann::json samples = nlohmann::json::array();
              for (const control::MetricsSample& s : m.samples) samples.push_back(metrics_json(s));
              out_head_ = dump({{"type", "metrics"}, {"samples", std::move(samples)}});
            },
            [&](QueuedSpectrum& s) { set_product(s.frame, Product::spectrum, "spectrum"); },
            [&](QueuedStatistics& s) { set_product(s.frame, Product::statistics, "statistics"); },
            [&](control::ImageEvent& image) {
              out_head_ = binary_head(dump(image_header_json(run_->id(), image)));
              out_png_ = std::move(image.png);
              binary = true;
            },
        },
        *item);
  } catch (const std::exception& e) {
    // A product too large for the server's limit (507) or no memory for it (503): the client
    // gets the error in its place and the stream goes on.
    out_png_.reset();
    out_shared_.reset();
    binary = false;
    try {
      out_head_ = dump({{"type", "error"}, {"error", error_json(to_api_error(e))["error"]}});
    } catch (const std::exception&) {
      return abort();
    }
  }
  ws_.binary(binary);
  write_out();
}

void WebSocketSession::write_out() {
  net::const_buffer tail;
  if (out_png_) tail = net::buffer(*out_png_);
  if (out_shared_ && !out_shared_->empty())
    tail = net::buffer(out_shared_->data() + 1, out_shared_->size() - 1);
  const std::array<net::const_buffer, 2> buffers{net::buffer(out_head_), tail};
  try {
    ws_.async_write(buffers,
                    beast::bind_front_handler(&WebSocketSession::on_write, shared_from_this()));
  } catch (const std::exception&) {
    abort();
  }
}

void WebSocketSession::abort() {
  finish();
  beast::error_code ec;
  beast::get_lowest_layer(ws_).socket().close(ec);
}

void WebSocketSession::on_write(beast::error_code ec, std::size_t) {
  out_png_.reset();
  out_shared_.reset();
  if (ec) return finish();
  started_ = true;
  if (closing_) {
    writing_ = false;
    return do_close();
  }
  send_next();
}

void WebSocketSession::close() {
  if (queue_) queue_->close();
  net::post(ws_.get_executor(), [self = shared_from_this()] {
    self->closing_ = true;
    if (!self->writing_) self->do_close();
  });
}

void WebSocketSession::do_close() {
  if (close_sent_ || finished_) return;
  close_sent_ = true;
  if (!ws_.is_open()) return finish();
  ws_.async_close(websocket::close_code::going_away,
                  [self = shared_from_this()](beast::error_code) { self->finish(); });
}

void WebSocketSession::do_read() {
  ws_.async_read(in_, beast::bind_front_handler(&WebSocketSession::on_read, shared_from_this()));
}

void WebSocketSession::on_read(beast::error_code ec, std::size_t) {
  if (ec) return finish();
  if (ws_.got_text())
    handle_message(beast::buffers_to_string(in_.data()));
  else
    reply_error(ApiError(400, "message: binary messages are not accepted"));
  in_.consume(in_.size());
  do_read();
}

void WebSocketSession::reply_error(const ApiError& error) {
  queue_->push_text(dump({{"type", "error"}, {"error", error_json(error)["error"]}}));
}

void WebSocketSession::handle_message(const std::string& text) {
  try {
    const nlohmann::json message = parse_client_json(text, "message");
    if (!message.is_object()) throw ApiError(400, "message: must be a JSON object");
    const auto type = message.find("type");
    if (type == message.end() || !type->is_string())
      throw ApiError(400, "'type' must be a string: parameters or images", "type");
    const std::string& kind = type->get_ref<const std::string&>();
    const auto only = [&](std::initializer_list<const char*> keys) {
      for (const auto& [key, value] : message.items()) {
        bool known = false;
        for (const char* k : keys) known |= key == k;
        if (!known)
          throw ApiError(400, "'" + key + "' is not a field of a '" + kind + "' message", key);
      }
    };
    if (kind == "parameters") {
      only({"type", "patch"});
      if (!authorised_)
        throw ApiError(401, "parameter changes need the token (connect with ?token=TOKEN)");
      const auto patch = message.find("patch");
      if (patch == message.end() || !patch->is_object())
        throw ApiError(400, "'patch' must be a JSON object (a merge patch over the scene)",
                       "patch");
      // apply_changes validates the whole scene: off the I/O threads.
      net::post(workers_, [run = run_, queue = queue_, patch = *patch] {
        try {
          const std::vector<std::string> changed = run->apply_changes(patch);
          queue->push_text(
              dump({{"type", "changed"}, {"changed", changed}, {"effective", "next step"}}));
        } catch (const std::exception& e) {
          queue->push_text(
              dump({{"type", "error"}, {"error", error_json(to_api_error(e))["error"]}}));
        }
      });
    } else if (kind == "images") {
      only({"type", "enabled"});
      const auto enabled = message.find("enabled");
      if (enabled == message.end() || !enabled->is_boolean())
        throw ApiError(400, "'enabled' must be true or false", "enabled");
      queue_->set_images_enabled(enabled->get<bool>());
    } else {
      throw ApiError(400, "'type' must be one of: parameters, images (got '" + kind + "')", "type");
    }
  } catch (const ApiError& e) {
    reply_error(e);
  } catch (const std::exception& e) {
    reply_error(to_api_error(e));
  }
}

void WebSocketSession::finish() {
  if (finished_) return;
  finished_ = true;
  if (queue_) queue_->close();
  if (fanout_) fanout_->remove(queue_.get());
  registry_.remove(*this);
}

// ---------------------------------------------------------------------------------------------

StreamTicket& StreamTicket::operator=(StreamTicket&& other) noexcept {
  if (this != &other) {
    release();
    registry_ = std::exchange(other.registry_, nullptr);
    address_ = std::move(other.address_);
    public_ = other.public_;
  }
  return *this;
}

void StreamTicket::release() noexcept {
  if (registry_) std::exchange(registry_, nullptr)->release(address_, public_);
}

StreamTicket StreamRegistry::admit(const std::string& address, bool public_stream) {
  std::lock_guard lock(mutex_);
  if (public_stream) {
    if (public_ >= quota_.max_public)
      throw ApiError(503,
                     "too many WebSocket streams without the token: " + std::to_string(public_) +
                         " open, the server's limit " + std::to_string(quota_.max_public) +
                         " (the rest is kept for the token holder); try again later");
    const auto it = public_by_address_.find(address);
    const std::size_t mine = it == public_by_address_.end() ? 0 : it->second;
    if (mine >= quota_.max_public_per_address)
      throw ApiError(503, "too many WebSocket streams from " + address + ": " +
                              std::to_string(mine) +
                              " open without the token, the limit per "
                              "address; close one first");
    ++public_by_address_[address];
    ++public_;
  }
  ++admitted_;
  return StreamTicket(this, address, public_stream);
}

void StreamRegistry::release(const std::string& address, bool public_stream) noexcept {
  std::lock_guard lock(mutex_);
  --admitted_;
  if (!public_stream) return;
  --public_;
  const auto it = public_by_address_.find(address);
  if (it != public_by_address_.end() && --it->second == 0) public_by_address_.erase(it);
}

std::size_t StreamRegistry::admitted() const {
  std::lock_guard lock(mutex_);
  return admitted_;
}

void StreamRegistry::add(const std::shared_ptr<WebSocketSession>& session) {
  std::lock_guard lock(mutex_);
  live_[session.get()] = Entry{session->run()->id(), session, session->queue()};
}

void StreamRegistry::remove(const WebSocketSession& session) {
  std::lock_guard lock(mutex_);
  const auto it = live_.find(&session);
  if (it == live_.end()) return;
  try {  // called from a destructor: a failed insertion loses a count, never the process
    closed_dropped_[it->second.run_id] += it->second.queue->images_dropped();
  } catch (const std::exception&) {
  }
  live_.erase(it);
}

StreamCounters StreamRegistry::counters(const std::string& run_id) const {
  std::lock_guard lock(mutex_);
  StreamCounters c;
  if (const auto it = closed_dropped_.find(run_id); it != closed_dropped_.end())
    c.dropped = it->second;
  for (const auto& [session, entry] : live_) {
    if (entry.run_id != run_id) continue;
    ++c.clients;
    c.dropped += entry.queue->images_dropped();
  }
  return c;
}

std::shared_ptr<RunFanout> StreamRegistry::fanout(const std::shared_ptr<control::Run>& run) {
  std::shared_ptr<RunFanout> created;
  {
    std::lock_guard lock(mutex_);
    auto& entry = fanouts_[run->id()];
    if (entry) return entry;
    entry = created = std::make_shared<RunFanout>();
  }
  run->add_observer(created);  // outside our lock: the run may call observers meanwhile
  return created;
}

std::size_t StreamRegistry::size() const {
  std::lock_guard lock(mutex_);
  return live_.size();
}

void StreamRegistry::close_all() {
  std::vector<std::shared_ptr<WebSocketSession>> sessions;
  {
    std::lock_guard lock(mutex_);
    for (auto& [key, entry] : live_) {
      entry.queue->close();
      if (auto s = entry.session.lock()) sessions.push_back(std::move(s));
    }
  }
  for (const auto& s : sessions) s->close();
}

}  // namespace sphles::server
