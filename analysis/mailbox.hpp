// SPDX-License-Identifier: GPL-3.0-or-later
// Single-slot hand-over from one producer to one consumer. publish() never blocks the producer
// on the consumer's work: it replaces a value the consumer has not taken yet and counts it as
// dropped, so the consumer always gets the newest value (live viewers). publish_waiting() is the
// lossless hand-over (outputs a scene asks for): it waits until the consumer has taken the
// previous value, so at most one value waits while the consumer works on another.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <optional>
#include <utility>

namespace sphles::analysis {

struct MailboxCounters {
  std::uint64_t published = 0;
  std::uint64_t taken = 0;
  std::uint64_t dropped = 0;  // replaced before the consumer took them
};

template <class T>
class LatestValueMailbox {
 public:
  /// Stores value as the newest; returns true if it replaced an untaken one.
  bool publish(T value) {
    bool replaced = false;
    {
      std::lock_guard lock(mutex_);
      replaced = pending_.has_value();
      pending_ = std::move(value);
      ++counters_.published;
      if (replaced) ++counters_.dropped;
    }
    ready_.notify_one();
    return replaced;
  }

  /// Stores value once the slot is free (the consumer took the previous one) or the mailbox is
  /// closed; drops nothing unless closed. Returns true if it replaced an untaken one.
  bool publish_waiting(T value) {
    {
      std::unique_lock lock(mutex_);
      taken_.wait(lock, [&] { return !pending_.has_value() || closed_; });
    }
    return publish(std::move(value));
  }

  /// Waits for a value or close(); returns nothing once closed and empty.
  std::optional<T> take() {
    std::unique_lock lock(mutex_);
    ready_.wait(lock, [&] { return pending_.has_value() || closed_; });
    if (!pending_) return std::nullopt;
    std::optional<T> value = std::move(pending_);
    pending_.reset();
    ++counters_.taken;
    lock.unlock();
    taken_.notify_all();
    return value;
  }

  /// Wakes the consumer; a pending value is still delivered before take() reports closure.
  void close() {
    {
      std::lock_guard lock(mutex_);
      closed_ = true;
    }
    ready_.notify_all();
    taken_.notify_all();
  }

  MailboxCounters counters() const {
    std::lock_guard lock(mutex_);
    return counters_;
  }

 private:
  mutable std::mutex mutex_;
  std::condition_variable ready_;
  std::condition_variable taken_;
  std::optional<T> pending_;
  bool closed_ = false;
  MailboxCounters counters_;
};

}  // namespace sphles::analysis
