// SPDX-License-Identifier: GPL-3.0-or-later
// The server's open HTTP connections, counted for admission (ServerOptions, docs/api.md
// "Limits"): connections in total (WebSocket streams included) and per peer address. A newcomer
// beyond a limit evicts the least valuable HTTP connection, lingering after its last response,
// else the one that has waited for or read its current request longest, and is refused only when
// every connection is busy: a slow or idle client cannot keep an active one out. Also the budget
// of response bytes built and not yet sent, all connections together.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "server/server_options.hpp"

namespace sphles::server {

class StreamRegistry;

/// Where an HTTP connection is; eviction takes lingering ones first, then reading ones (oldest
/// first), never one whose request is being handled or whose response is being written.
enum class Phase : int { reading, handling, writing, lingering };

/// What the table knows of a connection (HttpSession is the one kind): its phase and since when,
/// which any thread may read, and how to end it.
class Connection {
 public:
  virtual ~Connection() = default;

  /// Any thread: ends the connection (pending operations fail and release it).
  virtual void close() = 0;
  /// Any thread: closes the connection if it is still only reading or lingering (a newcomer
  /// needs its place); otherwise leaves it alone and tells the table (ConnectionTable::spare).
  virtual void evict() = 0;

  Phase phase() const { return static_cast<Phase>(phase_.load(std::memory_order_acquire)); }
  std::int64_t phase_since() const { return phase_since_.load(std::memory_order_acquire); }

 protected:
  Connection();
  void enter(Phase p);

 private:
  std::atomic<int> phase_{static_cast<int>(Phase::reading)};
  std::atomic<std::int64_t> phase_since_;  // steady clock, nanoseconds
};

class ConnectionTable {
 public:
  /// The limits are `options`'; `streams` counts the WebSocket streams (it must outlive this).
  ConnectionTable(const ServerOptions& options, const StreamRegistry& streams);

  void add(Connection* connection, std::weak_ptr<Connection> weak, std::string address);
  void remove(Connection* connection);
  void spare(Connection* connection);  // an eviction that found the connection busy
  std::size_t connections() const;     // open HTTP connections plus WebSocket streams

  /// For a newcomer from `address`: nothing when there is room; else the connection to evict
  /// (no longer counted; the caller evicts it once the newcomer has its place), or when every
  /// connection is busy, why the newcomer is refused.
  struct Admission {
    std::shared_ptr<Connection> evicted;
    std::string refusal;  // empty: admitted
  };
  Admission admit(const std::string& address);

  /// Tells every open connection to close.
  void close_all();
  /// Returns once no HTTP connection is open and no stream admitted, or at `deadline`.
  void wait_until_closed(std::chrono::steady_clock::time_point deadline);

  /// Room for a response body of `bytes` among the unsent ones (max_pending_response_bytes).
  bool reserve_response(std::size_t bytes);
  void release_response(std::size_t bytes);
  std::size_t pending_response_bytes() const { return pending_response_bytes_.load(); }

 private:
  struct Entry {
    std::weak_ptr<Connection> connection;
    std::string address;
    bool evicting = false;  // told to close; no longer counted
  };

  Connection* victim(const std::string* address) const;  // under mutex_

  const std::size_t max_connections_;
  const std::size_t max_connections_per_address_;
  const std::size_t max_pending_response_bytes_;
  const StreamRegistry& streams_;
  mutable std::mutex mutex_;  // guards entries_
  std::condition_variable changed_;
  std::map<Connection*, Entry> entries_;
  std::atomic<std::size_t> pending_response_bytes_{0};
};

}  // namespace sphles::server
