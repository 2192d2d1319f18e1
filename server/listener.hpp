// SPDX-License-Identifier: GPL-3.0-or-later
// The service's listening socket, after Beast's advanced-server example's listener: accepts
// connections on the I/O threads, admits each through the connection table (ServerOptions,
// docs/api.md "Limits") and starts an HttpSession for it, evicting the connection the table
// chose, or refuses it with a 503 written at once. Failures to accept (out of file descriptors)
// are retried shortly rather than in a spin.
#pragma once

#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/beast/core/error.hpp>
#include <string>

#include "server/http_session.hpp"

namespace sphles::server {

class Listener {
 public:
  /// Sessions run on `ioc`; `sessions` must outlive the listener.
  Listener(boost::asio::io_context& ioc, SessionContext& sessions);

  /// Opens, binds and listens on the options' address and port; the bound port. Throws
  /// std::runtime_error naming the address and the reason if it cannot.
  unsigned short listen();
  /// Accepts on the I/O threads from now on.
  void start();
  /// Closes the listening socket and waits until it is closed; not from an I/O thread.
  void close();

 private:
  void do_accept();
  void on_accept(boost::beast::error_code ec, boost::asio::ip::tcp::socket socket);
  void refuse(boost::asio::ip::tcp::socket& socket, const std::string& reason);

  boost::asio::io_context& ioc_;
  SessionContext& sessions_;
  boost::asio::ip::tcp::acceptor acceptor_;
  boost::asio::steady_timer accept_retry_;
};

}  // namespace sphles::server
