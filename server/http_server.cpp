// SPDX-License-Identifier: GPL-3.0-or-later
// The server as its parts, after Beast's advanced-server and chat-multi examples: what every
// connection shares (SessionContext: options, streams, products, connection table, the worker
// pools, the router; server/http_session.hpp), the listener (server/listener.hpp), and here the
// threads that run them, started and stopped in order.
#include "server/http_server.hpp"

#include <pthread.h>
#include <algorithm>
#include <boost/asio/executor_work_guard.hpp>
#include <boost/asio/io_context.hpp>
#include <chrono>
#include <optional>
#include <stdexcept>
#include <thread>
#include <utility>
#include <vector>

#include "logging/logging.hpp"
#include "server/http_session.hpp"
#include "server/listener.hpp"
#include "server/router.hpp"

namespace sphles::server {

namespace net = boost::asio;

namespace {

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

/// `count` threads (at least one) named `name` for top -H and the benchmark, each running
/// `context`.
void spawn(std::vector<std::thread>& threads, int count, net::io_context& context, const char* name,
           const char* what) {
  for (int k = 0; k < std::max(1, count); ++k)
    threads.emplace_back([&context, name, what] {
      pthread_setname_np(pthread_self(), name);
      run_context(context, what);
    });
}

}  // namespace

struct HttpServer::Impl {
  Impl(control::RunManager& manager, ServerOptions options)
      : shared(manager, std::move(options)), listener(ioc, shared) {}

  // Declaration order is destruction order in reverse: sessions still owned by handlers die with
  // the io_context and unregister from the connection table and the streams, which `shared`
  // holds and which must outlive it.
  SessionContext shared;
  std::optional<net::executor_work_guard<net::io_context::executor_type>> keep_working;
  std::optional<net::executor_work_guard<net::io_context::executor_type>> keep_bulk;
  std::optional<net::executor_work_guard<net::io_context::executor_type>> keep_controlling;
  std::vector<std::thread> worker_threads;
  net::io_context ioc;
  // Keeps the I/O threads running while nothing is pending (e.g. after stop_accepting).
  std::optional<net::executor_work_guard<net::io_context::executor_type>> keep_running;
  Listener listener;
  std::vector<std::thread> threads;
  unsigned short port = 0;
  bool started = false, accepting = false, stopped = false;
};

HttpServer::HttpServer(control::RunManager& manager, ServerOptions options)
    : impl_(std::make_unique<Impl>(manager, std::move(options))) {}

HttpServer::~HttpServer() {
  stop();
}

void HttpServer::start() {
  Impl& s = *impl_;
  const ServerOptions& options = s.shared.options;
  if (s.started) throw std::logic_error("HttpServer::start called twice");
  if (options.max_public_streams >= options.max_connections)
    throw std::invalid_argument(
        "max_public_streams (" + std::to_string(options.max_public_streams) +
        ") must be below max_connections (" + std::to_string(options.max_connections) +
        "): the difference is what read-only streams can never take from API calls and the "
        "token holder");
  s.port = s.listener.listen();
  s.started = true;
  s.accepting = true;
  s.keep_running.emplace(s.ioc.get_executor());
  s.keep_working.emplace(s.shared.work.get_executor());
  s.keep_bulk.emplace(s.shared.bulk.get_executor());
  s.keep_controlling.emplace(s.shared.control.get_executor());
  s.listener.start();
  spawn(s.threads, options.io_threads, s.ioc, "sphles-io", "I/O thread");
  spawn(s.worker_threads, options.worker_threads, s.shared.work, "sphles-worker", "worker thread");
  spawn(s.worker_threads, options.bulk_threads, s.shared.bulk, "sphles-bulk", "bulk read thread");
  spawn(s.worker_threads, options.control_threads, s.shared.control, "sphles-control",
        "control thread");
}

unsigned short HttpServer::port() const {
  return impl_->port;
}

std::string HttpServer::url() const {
  const std::string& host = impl_->shared.options.address;
  const bool v6 = host.find(':') != std::string::npos;
  return "http://" + (v6 ? "[" + host + "]" : host) + ":" + std::to_string(impl_->port) + "/";
}

void HttpServer::stop_accepting() {
  Impl& s = *impl_;
  if (!s.started || !s.accepting) return;
  s.accepting = false;
  s.listener.close();
}

void HttpServer::stop() {
  Impl& s = *impl_;
  if (!s.started || s.stopped) return;
  stop_accepting();
  s.stopped = true;

  s.shared.streams.close_all();
  s.shared.table.close_all();
  // Give close frames and responses in flight a moment, then stop regardless.
  s.shared.table.wait_until_closed(std::chrono::steady_clock::now() + std::chrono::seconds(2));
  // Requests in progress finish (their responses are dropped below).
  s.keep_working.reset();
  s.keep_bulk.reset();
  s.keep_controlling.reset();
  for (std::thread& t : s.worker_threads) t.join();
  s.worker_threads.clear();
  s.keep_running.reset();
  s.ioc.stop();
  for (std::thread& t : s.threads) t.join();
  s.threads.clear();
}

std::size_t HttpServer::connections() const {
  return impl_->shared.table.connections();
}

const Router& HttpServer::router() const {
  return impl_->shared.router;
}

}  // namespace sphles::server
