// SPDX-License-Identifier: GPL-3.0-or-later
#include "analysis/pipeline.hpp"

#include <omp.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <chrono>

namespace sphles::analysis {

/// Scheduling priority of a LatestOnly analysis thread: the lowest, so it runs on cycles the
/// solver leaves idle (the solver's passes use dynamic scheduling and so absorb a preempted
/// thread). A Lossless one keeps the solver's priority: the solver waits for it when it falls
/// behind, and at the lowest priority on a loaded machine it would get almost no cycles (a
/// 32³ run on a machine with three busy processes per core analysed 8 of its 16 snapshots).
constexpr int kLatestOnlyAnalysisNice = 19;

AnalysisPipeline::AnalysisPipeline(AnalysisConfig config, std::vector<FrameSink> sinks,
                                   int analysis_threads, Delivery delivery)
    : config_(std::move(config)), sinks_(std::move(sinks)), delivery_(delivery) {
  worker_ = std::thread([this, analysis_threads] { run(analysis_threads); });
}

AnalysisPipeline::~AnalysisPipeline() {
  close(false);
}

void AnalysisPipeline::publish(SnapshotPtr snapshot) {
  if (delivery_ == Delivery::Lossless)
    mailbox_.publish_waiting(std::move(snapshot));
  else
    mailbox_.publish(std::move(snapshot));
}

void AnalysisPipeline::close(bool drain) {
  if (closed_) return;
  closed_ = true;
  discard_ = !drain;
  mailbox_.close();
  if (worker_.joinable()) worker_.join();
  stopped_ = true;
}

PipelineCounters AnalysisPipeline::counters() const {
  const MailboxCounters m = mailbox_.counters();
  PipelineCounters c;
  c.published = m.published;
  c.dropped = m.dropped;
  c.analysed = analysed_.load();
  c.busy_seconds = busy_seconds_.load();
  // Once the worker has stopped, every snapshot not analysed was dropped: replaced in the
  // mailbox, taken but discarded by close(false), or still waiting when close(false) came.
  if (stopped_.load()) c.dropped = m.published - c.analysed;
  return c;
}

AnalysisConfig AnalysisPipeline::config() const {
  std::lock_guard lock(config_mutex_);
  return config_;
}

void AnalysisPipeline::set_config(AnalysisConfig config) {
  std::lock_guard lock(config_mutex_);
  config_ = std::move(config);
}

std::string AnalysisPipeline::error() const {
  std::lock_guard lock(error_mutex_);
  return error_;
}

void AnalysisPipeline::run(int analysis_threads) {
  // Analysis yields the cores to the solver: a bounded OpenMP team inside analysis and, when
  // the solver never waits for it, the lowest scheduling priority for this thread only (Linux
  // applies nice values per thread).
  if (delivery_ == Delivery::LatestOnly)
    setpriority(PRIO_PROCESS, static_cast<id_t>(::syscall(SYS_gettid)), kLatestOnlyAnalysisNice);
  omp_set_num_threads(analysis_threads > 0 ? analysis_threads : 1);
  while (std::optional<SnapshotPtr> snapshot = mailbox_.take()) {
    if (discard_) break;
    const auto start = std::chrono::steady_clock::now();
    try {
      AnalysisFrame frame = analyse(*snapshot, config());
      frame.dropped_snapshots = mailbox_.counters().dropped;
      for (const FrameSink& sink : sinks_) sink(frame);
    } catch (const std::exception& e) {
      std::lock_guard lock(error_mutex_);
      if (error_.empty()) error_ = e.what();
    }
    busy_seconds_ = busy_seconds_.load() +
                    std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    ++analysed_;
  }
}

}  // namespace sphles::analysis
