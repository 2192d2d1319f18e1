// SPDX-License-Identifier: GPL-3.0-or-later
// What one WebSocket client has waiting to be sent, and the RunObserver that fills it.
//
// The observer runs on the solver, analysis and render threads. It only copies (metrics
// samples, shared pointers to frames and PNGs) into this bounded queue under a short mutex and,
// if the client's session is idle, asks it to wake up (a post to its strand); serialisation and
// network I/O happen on the server's threads. Nothing here blocks on a client, so a slow client
// can never slow the solver: when its queue is full the oldest image is dropped (and counted),
// metrics samples are coalesced into one message (the oldest dropped beyond a bound), and only
// the newest spectrum and statistics wait.
#pragma once

#include <atomic>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <variant>
#include <vector>

#include "control/run.hpp"

namespace sphles::server {

struct StreamLimits {
  std::size_t max_images = 4;            // images waiting per client; the oldest is dropped beyond
  std::size_t max_samples = 4096;        // metrics samples waiting per client; the oldest dropped
  std::size_t max_texts = 256;           // state changes and replies waiting per client
  std::size_t max_incoming = 64 * 1024;  // bytes of one client message
};

/// Items in the order they are sent when several wait: text (hello, state, replies), then all
/// waiting metrics samples as one message, then the newest spectrum, the newest statistics,
/// then images oldest first (one per turn, so newer metrics overtake queued images).
struct QueuedText {
  std::string text;
};
struct QueuedMetrics {
  std::vector<control::MetricsSample> samples;
};
struct QueuedSpectrum {
  std::shared_ptr<const analysis::AnalysisFrame> frame;
};
struct QueuedStatistics {
  std::shared_ptr<const analysis::AnalysisFrame> frame;
};
using QueuedItem =
    std::variant<QueuedText, QueuedMetrics, QueuedSpectrum, QueuedStatistics, control::ImageEvent>;

struct QueueCounters {
  std::uint64_t images_dropped = 0;    // oldest images dropped from a full queue
  std::uint64_t samples_dropped = 0;   // oldest metrics samples dropped beyond max_samples
  std::uint64_t frames_coalesced = 0;  // spectra/statistics replaced by a newer one unsent
  std::uint64_t texts_dropped = 0;     // texts dropped beyond max_texts
  std::uint64_t images_queued = 0;     // images accepted
};

class ClientQueue {
 public:
  /// `wake` is called (under the queue's lock, so it must only post) when an item arrives and
  /// the consumer is idle.
  ClientQueue(StreamLimits limits, std::function<void()> wake);

  // Producer side: any thread, never blocks beyond the queue's own short lock.
  void push_text(std::string text);
  void push_metrics(std::span<const control::MetricsSample> batch);
  void push_frame(const std::shared_ptr<const analysis::AnalysisFrame>& frame);
  void push_image(const control::ImageEvent& image);

  /// Consumer side: the next item, or nullopt when empty (then the next push wakes again).
  std::optional<QueuedItem> pop();

  /// Whether images are queued at all (client message {"type":"images","enabled":...}).
  void set_images_enabled(bool enabled);
  bool images_enabled() const { return images_enabled_.load(std::memory_order_relaxed); }

  /// No pushes afterwards, waiting items cleared, the wake function released. Idempotent.
  void close();
  bool closed() const { return closed_flag_.load(std::memory_order_acquire); }

  QueueCounters counters() const;
  std::uint64_t images_dropped() const { return images_dropped_.load(std::memory_order_relaxed); }

 private:
  void wake_locked();

  const StreamLimits limits_;
  mutable std::mutex mutex_;
  std::function<void()> wake_;
  bool wake_pending_ = false;  // the consumer has been woken and has not yet found the queue empty
  bool closed_ = false;
  std::deque<std::string> texts_;
  std::vector<control::MetricsSample> samples_;
  std::shared_ptr<const analysis::AnalysisFrame> spectrum_, statistics_;
  std::deque<control::ImageEvent> images_;
  QueueCounters counters_;
  std::atomic<std::uint64_t> images_dropped_{0};
  std::atomic<bool> images_enabled_{true};
  std::atomic<bool> closed_flag_{false};
};

/// The one RunObserver the server registers with a run: fans each product out to the queues of
/// that run's WebSocket clients. Clients join and leave here, under this object's own lock, so
/// the run's observer list changes once per run rather than with every connect and disconnect
/// (control::Run copies the whole list on each change), and the run makes one call per product
/// however many clients watch. A fan-out outlives the server harmlessly: it holds only queues,
/// which are closed when their sessions end.
class RunFanout final : public control::RunObserver {
 public:
  void add(std::shared_ptr<ClientQueue> queue);
  void remove(const ClientQueue* queue);
  std::size_t size() const;

  void on_metrics(std::span<const control::MetricsSample> batch) override;
  void on_analysis(const std::shared_ptr<const analysis::AnalysisFrame>& frame) override;
  void on_image(const control::ImageEvent& image) override;
  void on_state(control::RunState state, const std::string& reason,
                std::span<const std::string_view> actions) override;
  bool wants_images() const override;

 private:
  template <class F>
  void each(F&& f) const;
  mutable std::mutex mutex_;
  std::vector<std::shared_ptr<ClientQueue>> queues_;
};

}  // namespace sphles::server
