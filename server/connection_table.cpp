// SPDX-License-Identifier: GPL-3.0-or-later
#include "server/connection_table.hpp"

#include <utility>

#include "server/websocket_session.hpp"

namespace sphles::server {

namespace {

std::int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

}  // namespace

Connection::Connection() : phase_since_(now_ns()) {}

void Connection::enter(Phase p) {
  phase_since_.store(now_ns(), std::memory_order_release);
  phase_.store(static_cast<int>(p), std::memory_order_release);
}

ConnectionTable::ConnectionTable(const ServerOptions& options, const StreamRegistry& streams)
    : max_connections_(options.max_connections),
      max_connections_per_address_(options.max_connections_per_address),
      max_pending_response_bytes_(options.max_pending_response_bytes),
      streams_(streams) {}

void ConnectionTable::add(Connection* connection, std::weak_ptr<Connection> weak,
                          std::string address) {
  std::lock_guard lock(mutex_);
  entries_[connection] = Entry{std::move(weak), std::move(address), false};
}

void ConnectionTable::remove(Connection* connection) {
  {
    std::lock_guard lock(mutex_);
    entries_.erase(connection);
  }
  changed_.notify_all();
}

void ConnectionTable::spare(Connection* connection) {
  std::lock_guard lock(mutex_);
  if (const auto it = entries_.find(connection); it != entries_.end()) it->second.evicting = false;
}

std::size_t ConnectionTable::connections() const {
  std::size_t http_connections = 0;
  {
    std::lock_guard lock(mutex_);
    http_connections = entries_.size();
  }
  return http_connections + streams_.admitted();
}

Connection* ConnectionTable::victim(const std::string* address) const {
  // Lingering first, then reading, each the longest in its phase first.
  Connection* best = nullptr;
  std::pair<int, std::int64_t> best_rank{};
  for (const auto& [connection, entry] : entries_) {
    if (entry.evicting || (address && entry.address != *address)) continue;
    const Phase p = connection->phase();
    if (p != Phase::lingering && p != Phase::reading) continue;
    const std::pair<int, std::int64_t> rank{p == Phase::lingering ? 0 : 1,
                                            connection->phase_since()};
    if (!best || rank < best_rank) {
      best = connection;
      best_rank = rank;
    }
  }
  return best;
}

ConnectionTable::Admission ConnectionTable::admit(const std::string& address) {
  Admission admission;
  std::lock_guard lock(mutex_);
  std::size_t open = 0, mine = 0;
  for (const auto& [connection, entry] : entries_) {
    if (entry.evicting) continue;
    ++open;
    if (entry.address == address) ++mine;
  }
  open += streams_.admitted();
  Connection* chosen = nullptr;
  if (mine >= max_connections_per_address_) {
    chosen = victim(&address);
    if (!chosen)
      admission.refusal = "too many connections from " + address + " (" + std::to_string(mine) +
                          ", the limit per address), all of them busy; try again shortly";
  } else if (open >= max_connections_) {
    chosen = victim(nullptr);
    if (!chosen)
      admission.refusal = "the server is full (" + std::to_string(open) +
                          " connections), all of them busy; try again shortly";
  }
  if (chosen) {
    Entry& entry = entries_[chosen];
    admission.evicted = entry.connection.lock();
    entry.evicting = true;
  }
  return admission;
}

void ConnectionTable::close_all() {
  std::vector<std::shared_ptr<Connection>> open;
  {
    std::lock_guard lock(mutex_);
    for (auto& [key, entry] : entries_)
      if (auto connection = entry.connection.lock()) open.push_back(std::move(connection));
  }
  for (const auto& connection : open) connection->close();
}

void ConnectionTable::wait_until_closed(std::chrono::steady_clock::time_point deadline) {
  std::unique_lock lock(mutex_);
  while ((!entries_.empty() || streams_.admitted() > 0) &&
         std::chrono::steady_clock::now() < deadline)
    changed_.wait_for(lock, std::chrono::milliseconds(20));
}

bool ConnectionTable::reserve_response(std::size_t bytes) {
  if (bytes == 0) return true;
  std::size_t held = pending_response_bytes_.load();
  do {
    if (held + bytes > max_pending_response_bytes_) return false;
  } while (!pending_response_bytes_.compare_exchange_weak(held, held + bytes));
  return true;
}

void ConnectionTable::release_response(std::size_t bytes) {
  if (bytes > 0) pending_response_bytes_.fetch_sub(bytes);
}

}  // namespace sphles::server
