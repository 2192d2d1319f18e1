// SPDX-License-Identifier: GPL-3.0-or-later
// The run manager's admission (control/run_manager.hpp): what a run or a live change takes of
// this machine's memory and disk by its resource estimate (control/resources.hpp), whether that
// fits the server's limits, and the answer of POST /api/runs/estimate.
#include <omp.h>
#include <sys/statvfs.h>

#include <optional>
#include <string>
#include <vector>

#include "control/resources.hpp"
#include "control/run_manager.hpp"
#include "control/step_time.hpp"

namespace sphles::control {

using nlohmann::json;

namespace {

/// The scene key that drives a memory component of the estimate, for the error's field.
std::string field_of(const std::string& part) {
  if (part == "analysis" || part == "snapshots") return "analysis";
  if (part == "rendering") return "render";
  return "particles_per_side";
}

/// Bytes free for an unprivileged writer on the file system of `directory`; nullopt if unknown.
std::optional<double> free_disk_bytes(const std::filesystem::path& directory) {
  struct statvfs info {};
  if (::statvfs(directory.c_str(), &info) != 0) return std::nullopt;
  return static_cast<double>(info.f_bavail) * static_cast<double>(info.f_frsize);
}

/// What a run takes of this machine's memory: the whole estimate in one process. With ranks,
/// the server's share (RankEstimate::service: analysis, rendering, gathered snapshots) and,
/// when the ranks run here (no rank memory given), every rank's estimate as one part.
ResourceEstimate on_this_machine(ResourceEstimate estimate, double rank_memory_bytes) {
  if (!estimate.per_rank) return estimate;
  const RankEstimate& rank = *estimate.per_rank;
  std::vector<MemoryPart> parts = rank.service;
  if (rank_memory_bytes <= 0.0)
    parts.push_back({"mpi_ranks", rank.ranks * rank.memory_bytes,
                     std::to_string(rank.ranks) + " ranks on this machine, " +
                         format_bytes(rank.memory_bytes) + " each (per_rank)"});
  estimate.memory = std::move(parts);
  estimate.memory_bytes = 0.0;
  for (const MemoryPart& part : estimate.memory) estimate.memory_bytes += part.bytes;
  return estimate;
}

}  // namespace

double RunManager::admit(const RunSpec& spec, int ranks) const {
  return admit(estimate_resources(spec, ranks));
}

double RunManager::memory_here(const Run& run) const {
  try {
    return on_this_machine(estimate_resources(run.spec(), run.ranks()), options_.rank_memory_bytes)
        .memory_bytes;
  } catch (const std::exception&) {
    return 0.0;  // a document that no longer parses cannot run either
  }
}

double RunManager::admit(const ResourceEstimate& whole) const {
  const std::optional<RankEstimate>& rank = whole.per_rank;
  if (rank && options_.rank_memory_bytes > 0.0 && rank->memory_bytes > options_.rank_memory_bytes)
    throw AdmissionError(
        "ranks", "each of the run's " + std::to_string(rank->ranks) +
                     " MPI ranks needs an estimated " + format_bytes(rank->memory_bytes) +
                     " at its peak, more than the " + format_bytes(options_.rank_memory_bytes) +
                     " a rank may use (--rank-memory): more ranks or fewer particles");
  const ResourceEstimate estimate = on_this_machine(whole, options_.rank_memory_bytes);
  if (const std::optional<std::string> refusal =
          check_memory(estimate, options_.max_memory_bytes)) {
    // The solver's own parts (particles, lists, checkpoint copy) already beyond the limit: the
    // particle count is what to change. Otherwise the largest part names the scene key.
    double solver_bytes = 0.0;
    for (const MemoryPart& part : estimate.memory)
      if (field_of(part.name) == "particles_per_side") solver_bytes += part.bytes;
    std::string field = "particles_per_side";
    double largest = -1.0;
    if (solver_bytes <= options_.max_memory_bytes)
      for (const MemoryPart& part : estimate.memory)
        if (part.bytes > largest) {
          largest = part.bytes;
          field = field_of(part.name);
        }
    throw AdmissionError(field, *refusal);
  }
  const std::optional<double> free = free_disk_bytes(options_.data_directory);
  if (free && estimate.checkpoint_disk_bytes > *free)
    throw AdmissionError(
        "checkpoint.keep",
        "the run's checkpoints need an estimated " + format_bytes(estimate.checkpoint_disk_bytes) +
            " (" + format_bytes(estimate.checkpoint_file_bytes) + " each), more than the " +
            format_bytes(*free) + " free in the data directory");
  return estimate.memory_bytes;
}

nlohmann::json RunManager::estimate(const CreateRequest& request) const {
  const RunSpec spec = spec_of(request);
  const ResourceEstimate resources = estimate_resources(spec, request.ranks);
  json answer = resource_estimate_to_json(resources);
  answer["memory_limit_bytes"] = options_.max_memory_bytes;
  answer["rank_memory_limit_bytes"] =
      options_.rank_memory_bytes > 0.0 ? json(options_.rank_memory_bytes) : json(nullptr);
  // Ranks this server cannot launch, or a split the run would refuse: not admitted.
  std::optional<std::string> ranks = ranks_refusal(request);
  if (!ranks && resources.per_rank && !resources.per_rank->refusal.empty())
    ranks =
        "request: 'ranks' = " + std::to_string(request.ranks) + ": " + resources.per_rank->refusal;
  if (ranks) {
    answer["admitted"] = false;
    answer["refusal"] = {{"field", "ranks"}, {"message", *ranks}};
    return answer;
  }
  try {
    answer["memory_here_bytes"] = admit(resources);
    answer["admitted"] = true;
  } catch (const AdmissionError& e) {
    answer["admitted"] = false;
    answer["refusal"] = {{"field", e.field()}, {"message", e.what()}};
    return answer;
  }
  if (options_.run_options.threads > 0) omp_set_num_threads(options_.run_options.threads);
  answer["time"] = step_time_to_json(
      estimate_step_time(spec, resources, 10, options_.run_options.packing_cache_dir));
  return answer;
}

}  // namespace sphles::control
