// SPDX-License-Identifier: GPL-3.0-or-later
#include "server/client_queue.hpp"

#include <nlohmann/json.hpp>

#include "server/api_json.hpp"

namespace sphles::server {

ClientQueue::ClientQueue(StreamLimits limits, std::function<void()> wake)
    : limits_(limits), wake_(std::move(wake)) {}

void ClientQueue::wake_locked() {
  if (wake_pending_ || !wake_) return;
  wake_();  // may throw (no memory for the post): then the next push tries again
  wake_pending_ = true;
}

void ClientQueue::push_text(std::string text) {
  std::lock_guard lock(mutex_);
  if (closed_) return;
  texts_.push_back(std::move(text));
  while (texts_.size() > limits_.max_texts) {
    texts_.pop_front();
    ++counters_.texts_dropped;
  }
  wake_locked();
}

void ClientQueue::push_metrics(std::span<const control::MetricsSample> batch) {
  if (batch.empty()) return;
  std::lock_guard lock(mutex_);
  if (closed_) return;
  // Keep the newest max_samples: skip what would be dropped at once, then trim the front.
  const std::size_t keep = std::min(batch.size(), limits_.max_samples);
  counters_.samples_dropped += batch.size() - keep;
  samples_.insert(samples_.end(), batch.end() - static_cast<std::ptrdiff_t>(keep), batch.end());
  if (samples_.size() > limits_.max_samples) {
    const std::size_t excess = samples_.size() - limits_.max_samples;
    samples_.erase(samples_.begin(), samples_.begin() + static_cast<std::ptrdiff_t>(excess));
    counters_.samples_dropped += excess;
  }
  wake_locked();
}

void ClientQueue::push_frame(const std::shared_ptr<const analysis::AnalysisFrame>& frame) {
  if (!frame || (!frame->spectrum && !frame->subfilter)) return;
  std::lock_guard lock(mutex_);
  if (closed_) return;
  if (frame->spectrum) {
    if (spectrum_) ++counters_.frames_coalesced;
    spectrum_ = frame;
  }
  if (frame->subfilter) {
    if (statistics_) ++counters_.frames_coalesced;
    statistics_ = frame;
  }
  wake_locked();
}

void ClientQueue::push_image(const control::ImageEvent& image) {
  if (!images_enabled() || !image.png) return;
  std::lock_guard lock(mutex_);
  if (closed_) return;
  images_.push_back(image);
  ++counters_.images_queued;
  while (images_.size() > limits_.max_images) {
    images_.pop_front();
    ++counters_.images_dropped;
    images_dropped_.fetch_add(1, std::memory_order_relaxed);
  }
  wake_locked();
}

std::optional<QueuedItem> ClientQueue::pop() {
  std::lock_guard lock(mutex_);
  if (!texts_.empty()) {
    QueuedText item{std::move(texts_.front())};
    texts_.pop_front();
    return item;
  }
  if (!samples_.empty()) {
    QueuedMetrics item;
    item.samples.swap(samples_);
    return item;
  }
  if (spectrum_) return QueuedSpectrum{std::move(spectrum_)};
  if (statistics_) return QueuedStatistics{std::move(statistics_)};
  if (!images_.empty()) {
    control::ImageEvent image = std::move(images_.front());
    images_.pop_front();
    return image;
  }
  wake_pending_ = false;
  return std::nullopt;
}

void ClientQueue::set_images_enabled(bool enabled) {
  images_enabled_.store(enabled, std::memory_order_relaxed);
  if (enabled) return;
  std::lock_guard lock(mutex_);
  images_.clear();
}

void ClientQueue::close() {
  std::function<void()> wake;
  {
    std::lock_guard lock(mutex_);
    closed_ = true;
    closed_flag_.store(true, std::memory_order_release);
    texts_.clear();
    samples_.clear();
    spectrum_.reset();
    statistics_.reset();
    images_.clear();
    wake.swap(wake_);
  }
  // `wake` (holding the session's executor) is released here, outside the lock.
}

QueueCounters ClientQueue::counters() const {
  std::lock_guard lock(mutex_);
  return counters_;
}

void RunFanout::add(std::shared_ptr<ClientQueue> queue) {
  std::lock_guard lock(mutex_);
  queues_.push_back(std::move(queue));
}

void RunFanout::remove(const ClientQueue* queue) {
  std::lock_guard lock(mutex_);
  std::erase_if(queues_, [&](const auto& q) { return q.get() == queue; });
}

std::size_t RunFanout::size() const {
  std::lock_guard lock(mutex_);
  return queues_.size();
}

// Called on the run's threads. Each push only copies under the queue's short lock (never the
// other way round: no queue lock is held while this lock is taken), and nothing may throw into
// the run: a failure (allocation) drops the item for that client.
template <class F>
void RunFanout::each(F&& f) const {
  std::lock_guard lock(mutex_);
  for (const auto& queue : queues_) {
    try {
      f(*queue);
    } catch (...) {
    }
  }
}

void RunFanout::on_metrics(std::span<const control::MetricsSample> batch) {
  each([&](ClientQueue& q) { q.push_metrics(batch); });
}

void RunFanout::on_analysis(const std::shared_ptr<const analysis::AnalysisFrame>& frame) {
  each([&](ClientQueue& q) { q.push_frame(frame); });
}

void RunFanout::on_image(const control::ImageEvent& image) {
  each([&](ClientQueue& q) { q.push_image(image); });
}

void RunFanout::on_state(control::RunState state, const std::string& reason,
                         std::span<const std::string_view> actions) {
  std::string text;
  try {
    text = dump({{"type", "state"},
                 {"state", control::run_state_name(state)},
                 {"reason", reason},
                 {"actions", std::vector<std::string_view>(actions.begin(), actions.end())}});
  } catch (...) {
    return;
  }
  each([&](ClientQueue& q) { q.push_text(text); });
}

bool RunFanout::wants_images() const {
  std::lock_guard lock(mutex_);
  for (const auto& queue : queues_)
    if (queue->images_enabled() && !queue->closed()) return true;
  return false;
}

}  // namespace sphles::server
