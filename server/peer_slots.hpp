// SPDX-License-Identifier: GPL-3.0-or-later
// How many requests of one kind each peer address has in progress, bounded (docs/api.md
// "Limits"): the large reads of a run's files (server/router.hpp, RouteInfo::bulk) take a slot
// while their answer is built, so that one address cannot occupy every thread that builds them.
#pragma once

#include <cstddef>
#include <map>
#include <memory>
#include <mutex>
#include <string>

namespace sphles::server {

class PeerSlots {
 public:
  explicit PeerSlots(std::size_t per_address) : per_address_(per_address) {}

  /// A slot of `address`, given back when the returned lease goes; null when the address holds
  /// all of its slots already.
  std::shared_ptr<void> acquire(const std::string& address) {
    std::lock_guard lock(mutex_);
    std::size_t& held = held_[address];
    if (held >= per_address_) return nullptr;
    ++held;
    // Not null (the lease is tested as a pointer); the deleter gives the slot back.
    return std::shared_ptr<void>(static_cast<void*>(this),
                                 [this, address](void*) { release(address); });
  }

  std::size_t per_address() const { return per_address_; }

 private:
  void release(const std::string& address) {
    std::lock_guard lock(mutex_);
    const auto it = held_.find(address);
    if (it != held_.end() && --it->second == 0) held_.erase(it);
  }

  const std::size_t per_address_;
  std::mutex mutex_;
  std::map<std::string, std::size_t> held_;
};

}  // namespace sphles::server
