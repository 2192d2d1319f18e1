// SPDX-License-Identifier: GPL-3.0-or-later
// The solver → analysis hand-over: the solver thread publishes snapshots; one analysis thread
// takes them, computes the requested products and hands each frame to the sinks (writer,
// renderer, server). Delivery::Lossless (what a run's saved outputs need: no analysis time may
// be missing, docs/analysis.md): publish waits while an earlier snapshot still waits, so every
// snapshot is analysed and the solver is held only when analysis falls more than one snapshot
// behind. Delivery::LatestOnly (live viewing only): a snapshot published while an older one
// still waits replaces it and is counted as dropped; the solver never waits.
#pragma once

#include <atomic>
#include <functional>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "analysis/config.hpp"
#include "analysis/mailbox.hpp"
#include "analysis/products.hpp"

namespace sphles::analysis {

/// Receives every analysed frame on the analysis thread. Must not throw; a sink that fails
/// reports it through its own channel (see RunDirectoryWriter::last_error).
using FrameSink = std::function<void(const AnalysisFrame&)>;

struct PipelineCounters {
  std::uint64_t published = 0;
  std::uint64_t analysed = 0;
  std::uint64_t dropped = 0;
  double busy_seconds = 0.0;  // wall time spent analysing and in sinks
};

enum class Delivery { Lossless, LatestOnly };

class AnalysisPipeline {
 public:
  /// Starts the analysis thread. `analysis_threads` OpenMP threads are used inside analysis
  /// (1 leaves the cores to the solver).
  AnalysisPipeline(AnalysisConfig config, std::vector<FrameSink> sinks, int analysis_threads = 1,
                   Delivery delivery = Delivery::Lossless);
  ~AnalysisPipeline();  // close(false)
  AnalysisPipeline(const AnalysisPipeline&) = delete;
  AnalysisPipeline& operator=(const AnalysisPipeline&) = delete;

  /// Hands over a snapshot: at once with LatestOnly; with Lossless once the previous one has
  /// been taken.
  void publish(SnapshotPtr snapshot);

  /// Stops the thread. With drain, a snapshot still waiting is analysed first (end of a run);
  /// without, it is discarded. Idempotent.
  void close(bool drain);

  PipelineCounters counters() const;
  /// The configuration the next analysis uses.
  AnalysisConfig config() const;
  /// Replaces the configuration (a live change); the snapshot being analysed keeps the old one.
  void set_config(AnalysisConfig config);
  /// Message of the first exception thrown by analysis, empty if none.
  std::string error() const;

 private:
  void run(int analysis_threads);

  mutable std::mutex config_mutex_;
  AnalysisConfig config_;
  std::vector<FrameSink> sinks_;
  Delivery delivery_;
  LatestValueMailbox<SnapshotPtr> mailbox_;
  std::atomic<bool> discard_{false};
  std::atomic<std::uint64_t> analysed_{0};
  std::atomic<double> busy_seconds_{0.0};
  mutable std::mutex error_mutex_;
  std::string error_;
  std::thread worker_;
  std::atomic<bool> closed_{false};
  std::atomic<bool> stopped_{false};  // the worker has been joined
};

}  // namespace sphles::analysis
