// SPDX-License-Identifier: GPL-3.0-or-later
#include "server/listener.hpp"

#include <boost/asio/post.hpp>
#include <boost/asio/strand.hpp>
#include <exception>
#include <future>
#include <memory>
#include <stdexcept>
#include <utility>

namespace sphles::server {

namespace beast = boost::beast;
namespace net = boost::asio;
using tcp = net::ip::tcp;

Listener::Listener(net::io_context& ioc, SessionContext& sessions)
    : ioc_(ioc),
      sessions_(sessions),
      acceptor_(net::make_strand(ioc)),
      accept_retry_(acceptor_.get_executor()) {}

unsigned short Listener::listen() {
  const ServerOptions& options = sessions_.options;
  beast::error_code ec;
  const net::ip::address address = net::ip::make_address(options.address, ec);
  if (ec) throw std::runtime_error("'--bind " + options.address + "' is not an IP address");
  const tcp::endpoint endpoint{address, options.port};
  const auto fail = [&](const char* what) {
    throw std::runtime_error("cannot " + std::string(what) + " " + options.address + ":" +
                             std::to_string(options.port) + ": " + ec.message());
  };
  acceptor_.open(endpoint.protocol(), ec);
  if (ec) fail("open a socket for");
  acceptor_.set_option(net::socket_base::reuse_address(true), ec);
  acceptor_.bind(endpoint, ec);
  if (ec) fail("bind to");
  acceptor_.listen(net::socket_base::max_listen_connections, ec);
  if (ec) fail("listen on");
  return acceptor_.local_endpoint().port();
}

void Listener::start() {
  do_accept();
}

void Listener::close() {
  std::promise<void> done;
  net::post(acceptor_.get_executor(), [this, &done] {
    beast::error_code ec;
    acceptor_.close(ec);
    accept_retry_.cancel();
    done.set_value();
  });
  done.get_future().wait();
}

void Listener::do_accept() {
  acceptor_.async_accept(net::make_strand(ioc_), [this](beast::error_code ec, tcp::socket socket) {
    on_accept(ec, std::move(socket));
  });
}

void Listener::on_accept(beast::error_code ec, tcp::socket socket) {
  if (ec == net::error::operation_aborted || !acceptor_.is_open()) return;
  if (ec) {
    // E.g. out of file descriptors: try again shortly rather than spin.
    accept_retry_.expires_after(std::chrono::milliseconds(100));
    accept_retry_.async_wait([this](beast::error_code wait_ec) {
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
    const ConnectionTable::Admission admission = sessions_.table.admit(address);
    if (!admission.refusal.empty()) {
      refuse(socket, admission.refusal);
    } else {
      std::make_shared<HttpSession>(std::move(socket), sessions_)->start(address);
      if (admission.evicted) admission.evicted->evict();
    }
  } catch (const std::exception& e) {
    // Out of memory for a new session: this connection goes, the server stays.
    beast::error_code ignored;
    socket.close(ignored);
  }
  do_accept();
}

void Listener::refuse(tcp::socket& socket, const std::string& reason) {
  // Written at once, without reading the request (a fresh socket's send buffer takes it); a
  // client that has already sent its request may see a reset instead.
  beast::error_code no_peer;
  const auto peer = socket.remote_endpoint(no_peer);
  sessions_.log->warn("{} refused with 503: {}",
                      no_peer ? std::string("-") : peer.address().to_string(), reason);
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

}  // namespace sphles::server
