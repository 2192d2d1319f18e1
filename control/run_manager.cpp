// SPDX-License-Identifier: GPL-3.0-or-later
#include "control/run_manager.hpp"

#include <algorithm>
#include <cstdio>
#include <future>
#include <limits>

#include "control/resources.hpp"
#include "control/run_files.hpp"
#include "logging/logging.hpp"
#include "scene/document.hpp"
#include "scene/json_reader.hpp"
#include "scene/presets.hpp"
#include "sim/scene.hpp"

namespace sphles::control {

using nlohmann::json;
using sim::SceneError;

namespace {

/// Analysis frames over a run created without an analysis section (live defaults).
constexpr double kLiveAnalysisFrames = 60.0;

std::string description(const std::string& name, const sim::Scene& s) {
  char text[256];
  std::snprintf(text, sizeof text, "%s: %s, %d^%d particles, %s D_K/dl = %g, %s model",
                name.c_str(), std::string(sim::case_name(s.case_type)).c_str(),
                s.particles_per_side, s.dimension(),
                std::string(sim::kernel_name(s.kernel)).c_str(), s.kernel_diameter_over_spacing,
                std::string(sim::subfilter_model_name(s.subfilter.model)).c_str());
  return text;
}

bool occupies_slot(RunState s) {
  return s == RunState::Running || s == RunState::Paused;
}

}  // namespace

json with_live_defaults(json document) {
  if (!document.is_object() || document.contains("analysis") || document.contains("render"))
    return document;
  const sim::Scene scene = scene::parse_scene(document);  // throws naming the field
  // kLiveAnalysisFrames over the run, but never closer than the time steps allow: a cadence
  // below them would cut every step short (and raising time.end would then make it a stall).
  const double step_bound =
      sim::kMinCadenceOverTimeStep * sim::estimate_initial_time_step(scene).step();
  document["analysis"] = {
      {"every",
       std::min(scene.end_time, std::max(scene.end_time / kLiveAnalysisFrames, step_bound))},
      {"products", {"energy", "spectrum", "vorticity", "slices", "sfs_stats"}},
      {"slice",
       {{"axis", "x"}, {"position", 3.141592653589793}, {"fields", {"omega2", "tau_sfs"}}}}};
  if (scene.dimension() == 2) document["analysis"]["slice"].erase("axis");
  document["render"] = {{"fields", {"omega2", "tau_sfs"}}};
  return document;
}

CreateRequest parse_create_request(const json& body) {
  if (!body.is_object())
    throw SceneError("(body)",
                     "request: '(body)' must be a JSON object, got " + scene::describe_type(body));
  CreateRequest request;
  for (const auto& [key, value] : body.items()) {
    if (key == "preset") {
      if (!value.is_string())
        throw SceneError("preset",
                         "request: 'preset' must be a string, got " + scene::describe_type(value));
      request.preset = value.get<std::string>();
    } else if (key == "scene") {
      if (!value.is_object())
        throw SceneError("scene",
                         "request: 'scene' must be an object, got " + scene::describe_type(value));
      request.scene = value;
    } else if (key == "patch") {
      if (!value.is_object())
        throw SceneError("patch", "request: 'patch' must be an object (a JSON merge patch), got " +
                                      scene::describe_type(value));
      request.patch = value;
    } else if (key == "overrides") {
      if (!value.is_array())
        throw SceneError("overrides",
                         "request: 'overrides' must be an array of \"key=value\" strings, got " +
                             scene::describe_type(value));
      for (std::size_t k = 0; k < value.size(); ++k) {
        if (!value[k].is_string())
          throw SceneError("overrides[" + std::to_string(k) + "]",
                           "request: 'overrides[" + std::to_string(k) +
                               "]' must be a string, got " + scene::describe_type(value[k]));
        request.overrides.push_back(value[k].get<std::string>());
      }
    } else if (key == "name") {
      if (!value.is_string() || value.get<std::string>().empty())
        throw SceneError("name", "request: 'name' must be a non-empty string");
      request.name = value.get<std::string>();
    } else if (key == "ranks") {
      if (!value.is_number_integer() || value.get<long long>() < 1 ||
          value.get<long long>() > std::numeric_limits<int>::max())
        throw SceneError("ranks",
                         "request: 'ranks' must be an integer >= 1 (MPI ranks of the solver), "
                         "got " +
                             value.dump());
      request.ranks = value.get<int>();
    } else if (key == "start") {
      if (!value.is_boolean())
        throw SceneError(
            "start", "request: 'start' must be true or false, got " + scene::describe_type(value));
      request.start = value.get<bool>();
    } else {
      throw SceneError(key, "request: unknown key '" + key +
                                "' (valid: preset, scene, patch, overrides, name, start, ranks)");
    }
  }
  if (request.preset.has_value() == request.scene.has_value())
    throw SceneError("preset", "request: give exactly one of 'preset' and 'scene'");
  return request;
}

/// Wakes the scheduler when a run leaves its slot (called on the run's threads).
class RunManager::SlotObserver : public RunObserver {
 public:
  explicit SlotObserver(std::shared_ptr<Wakeup> wakeup) : wakeup_(std::move(wakeup)) {}
  void on_state(RunState state, const std::string&, std::span<const std::string_view>) override {
    if (!occupies_slot(state) && state != RunState::Queued) wakeup_->notify();
  }

 private:
  std::shared_ptr<Wakeup> wakeup_;
};

RunManager::RunManager(ManagerOptions options)
    : options_(std::move(options)), slot_observer_(std::make_shared<SlotObserver>(wakeup_)) {
  if (options_.max_running < 1)
    throw std::invalid_argument("max_running must be >= 1, got " +
                                std::to_string(options_.max_running));
  if (options_.max_queued < 0 || options_.max_runs < 1)
    throw std::invalid_argument("max_queued must be >= 0 and max_runs >= 1");
  if (options_.max_memory_bytes < 0.0) throw std::invalid_argument("max_memory_bytes must be >= 0");
  if (options_.max_memory_bytes == 0.0)
    options_.max_memory_bytes = static_cast<double>(default_memory_limit_bytes());
  if (options_.rank_memory_bytes < 0.0)
    throw std::invalid_argument("rank_memory_bytes must be >= 0");
  // Live changes are admitted like new runs (a larger render or histogram needs memory too).
  options_.run_options.admit = [this](const RunSpec& spec, int ranks) { admit(spec, ranks); };
  const std::filesystem::path runs = options_.data_directory / "runs";
  std::filesystem::create_directories(runs);
  lock_.emplace(options_.data_directory);  // before anything of another server is touched
  // Deletions a previous process did not finish (remove()).
  std::error_code ignored;
  std::filesystem::remove_all(options_.data_directory / "trash", ignored);
  std::vector<std::filesystem::path> directories;
  for (const auto& entry : std::filesystem::directory_iterator(runs))
    if (entry.is_directory()) directories.push_back(entry.path());
  std::sort(directories.begin(), directories.end());
  for (const auto& directory : directories) {
    const std::string id = directory.filename().string();
    try {
      int ranks = Run::recorded_ranks(directory);
      if (ranks > 1 && !options_.distribute) {
        logging::console("runs")->warn(
            "run {} ran on {} MPI ranks; this server launches no MPI jobs, so it continues in "
            "this process (bitwise the same results)",
            id, ranks);
        ranks = 1;
      }
      auto run = std::shared_ptr<Run>(Run::open(id, directory, run_options_for(ranks, directory)));
      run->add_observer(slot_observer_);
      runs_.push_back(std::move(run));
    } catch (const std::exception& e) {
      logging::console("runs")->warn("skipping run directory {}: {}", directory.string(), e.what());
    }
    next_number_ =
        std::max<std::uint64_t>(next_number_, std::strtoull(id.c_str(), nullptr, 10) + 1);
  }
  references_ = std::make_unique<ReferenceJobs>(options_.data_directory, options_.max_memory_bytes);
  scheduler_ = std::thread([this] { schedule_loop(); });
}

RunManager::~RunManager() {
  shutdown();
  for (const auto& run : runs_) run->remove_observer(slot_observer_.get());
}

void RunManager::Wakeup::notify() {
  {
    std::lock_guard lock(mutex);
    wake = true;
  }
  condition.notify_one();
}

void RunManager::schedule_loop() {
  Wakeup& w = *wakeup_;
  for (;;) {
    {
      std::unique_lock lock(w.mutex);
      w.condition.wait(lock, [&] { return w.wake || w.stop; });
      if (w.stop) return;
      w.wake = false;
    }
    start_queued();
  }
}

bool RunManager::fits_now(const Run* run, double memory) const {
  std::vector<std::shared_ptr<Run>> active;
  {
    std::lock_guard lock(mutex_);
    for (const auto& r : runs_)
      if (r.get() != run && occupies_slot(r->status().state)) active.push_back(r);
  }
  if (static_cast<int>(active.size()) >= options_.max_running) return false;
  if (active.empty()) return true;  // it fits alone: admit() checked that
  double in_use = memory;
  for (const auto& r : active) in_use += memory_here(*r);
  return in_use <= options_.max_memory_bytes;
}

void RunManager::refuse_if_queue_full() const {
  std::lock_guard lock(mutex_);
  if (queue_.size() >= static_cast<std::size_t>(options_.max_queued))
    throw CapacityError("all " + std::to_string(options_.max_running) +
                        " run slots are busy (or the memory is) and " +
                        std::to_string(queue_.size()) +
                        " runs wait already, the limit (--max-queued " +
                        std::to_string(options_.max_queued) + "); try again later");
}

RunSpec RunManager::spec_of(const CreateRequest& request) {
  json document;
  if (request.preset) {
    const auto names = scene::preset_names();
    if (std::find(names.begin(), names.end(), *request.preset) == names.end()) {
      std::string valid;
      for (const auto& n : names) valid += (valid.empty() ? "" : ", ") + n;
      throw SceneError("preset", "request: 'preset' must be one of " + valid + ", got '" +
                                     *request.preset + "'");
    }
    document = {{"preset", *request.preset}};
  } else {
    document = *request.scene;
  }
  document.merge_patch(request.patch);
  for (const std::string& assignment : request.overrides)
    scene::apply_override(document, assignment);
  if (request.name) document["name"] = *request.name;
  RunSpec spec = parse_run_spec(with_live_defaults(document));
  check_run_name(spec.scene.name);
  return spec;
}

std::shared_ptr<Run> RunManager::find_stopped_like(const CreateRequest& request) const {
  const json wanted = run_spec_to_json(spec_of(request));
  std::lock_guard lock(mutex_);
  for (auto it = runs_.rbegin(); it != runs_.rend(); ++it)
    if ((*it)->status().state == RunState::Stopped && (*it)->ranks() == request.ranks &&
        (*it)->document() == wanted)
      return *it;
  return nullptr;
}

RunOptions RunManager::run_options_for(int ranks, const std::filesystem::path& directory) const {
  RunOptions options = options_.run_options;
  options.ranks = ranks;
  if (ranks > 1) options_.distribute(options, ranks, directory);
  return options;
}

std::optional<std::string> RunManager::ranks_refusal(const CreateRequest& request) const {
  if (request.ranks > 1 && !options_.distribute)
    return "request: 'ranks' = " + std::to_string(request.ranks) +
           ": this server launches no MPI jobs (start it with --launcher); use 1";
  if (request.ranks > options_.max_ranks)
    return "request: 'ranks' = " + std::to_string(request.ranks) +
           " exceeds this server's limit (--max-ranks " + std::to_string(options_.max_ranks) + ")";
  return std::nullopt;
}

std::shared_ptr<Run> RunManager::create(const CreateRequest& request) {
  if (const std::optional<std::string> refusal = ranks_refusal(request))
    throw SceneError("ranks", *refusal);
  RunSpec spec = spec_of(request);                   // throws naming the field; nothing created yet
  const double memory = admit(spec, request.ranks);  // throws AdmissionError with the estimate

  // A run to start is created only if it can start or queue: a full queue refuses it whole.
  std::unique_lock<std::mutex> schedule;
  if (request.start) {
    schedule = std::unique_lock(schedule_mutex_);
    if (!fits_now(nullptr, memory)) refuse_if_queue_full();
  }
  std::shared_ptr<Run> run;
  {
    std::lock_guard lock(mutex_);
    if (shut_down_) throw StateError("the server is shutting down");
    if (runs_.size() >= static_cast<std::size_t>(options_.max_runs))
      throw CapacityError("the server holds " + std::to_string(runs_.size()) +
                          " runs, its limit (--max-runs " + std::to_string(options_.max_runs) +
                          "); delete some first");
    char number[32];
    std::snprintf(number, sizeof number, "%04llu", static_cast<unsigned long long>(next_number_++));
    const std::string id = std::string(number) + "-" + directory_name(spec.scene.name);
    const std::filesystem::path directory = options_.data_directory / "runs" / id;
    run = std::make_shared<Run>(id, std::move(spec), directory,
                                run_options_for(request.ranks, directory));
    run->add_observer(slot_observer_);
    runs_.push_back(run);
  }
  logging::console("runs")->info("created run {} in {} ({} MPI rank(s))", run->id(),
                                 run->directory().string(), request.ranks);
  if (request.start) start_locked(run);
  return run;
}

std::vector<std::shared_ptr<Run>> RunManager::list() const {
  std::lock_guard lock(mutex_);
  return runs_;
}

std::shared_ptr<Run> RunManager::get(const std::string& id) const {
  std::lock_guard lock(mutex_);
  for (const auto& run : runs_)
    if (run->id() == id) return run;
  throw UnknownRunError("no run with id '" + id + "'");
}

void RunManager::start(const std::string& id) {
  const std::shared_ptr<Run> run = get(id);
  std::lock_guard schedule(schedule_mutex_);
  start_locked(run);
}

void RunManager::start_locked(const std::shared_ptr<Run>& run) {
  const std::string& id = run->id();
  {
    std::lock_guard lock(mutex_);
    if (shut_down_) throw StateError("the server is shutting down");
  }
  if (fits_now(run.get(), memory_here(*run))) {
    run->start();  // throws StateError naming the state
    std::lock_guard lock(mutex_);
    std::erase(queue_, id);
    return;
  }
  {
    std::lock_guard lock(mutex_);
    if (std::find(queue_.begin(), queue_.end(), id) != queue_.end())
      throw StateError("run " + id + " is already queued");
  }
  refuse_if_queue_full();
  // Not under mutex_: marking may wait for a transition of this run in progress (a stop), and
  // listing runs must not. schedule_mutex_ keeps other starts out meanwhile.
  run->mark_queued();  // throws StateError if the run cannot start
  std::lock_guard lock(mutex_);
  queue_.push_back(id);
}

void RunManager::pause(const std::string& id) {
  get(id)->pause();
}

void RunManager::resume(const std::string& id) {
  const std::shared_ptr<Run> run = get(id);
  if (run->status().state == RunState::Paused)
    run->resume();
  else if (is_terminal(run->status().state))
    start(id);
  else
    run->resume();  // throws StateError naming the state
}

bool RunManager::stop(const std::string& id) {
  const std::shared_ptr<Run> run = get(id);
  {
    std::lock_guard lock(mutex_);
    std::erase(queue_, id);
  }
  return run->stop();
}

void RunManager::remove(const std::string& id) {
  const std::shared_ptr<Run> run = get(id);
  run->retire();  // throws StateError for an active run; no transition is accepted afterwards
  const std::filesystem::path trash =
      options_.data_directory / "trash" / run->directory().filename();
  bool on_disk = true;
  try {
    on_disk = move_to_trash(run->directory(), trash);
  } catch (...) {
    run->reinstate();
    throw;
  }
  {
    std::lock_guard lock(mutex_);
    std::erase(runs_, run);
    std::erase(queue_, id);
  }
  run->remove_observer(slot_observer_.get());
  std::error_code ignored;
  std::filesystem::remove_all(trash, ignored);  // a leftover is removed on the next start
  logging::console("runs")->info("deleted run {}{}", id,
                                 on_disk ? "" : " (its directory was already gone)");
}

void RunManager::start_queued() {
  // On the scheduler thread, after a run left its slot: the oldest queued runs that fit start.
  std::lock_guard schedule(schedule_mutex_);
  for (;;) {
    std::shared_ptr<Run> next;
    std::string id;
    {
      std::lock_guard lock(mutex_);
      if (shut_down_ || queue_.empty()) return;
      id = queue_.front();
      for (const auto& r : runs_)
        if (r->id() == id) next = r;
    }
    // The oldest first: when it does not fit yet (slots or memory), the others wait behind it.
    if (next && next->status().state == RunState::Queued &&
        !fits_now(next.get(), memory_here(*next)))
      return;
    {
      std::lock_guard lock(mutex_);
      std::erase(queue_, id);
    }
    if (!next) continue;
    try {
      next->start_if_queued();  // false: stopped or deleted since it queued
    } catch (const std::exception& e) {
      logging::console("runs")->error("could not start queued run {}: {}", next->id(), e.what());
    }
  }
}

void RunManager::shutdown() {
  std::vector<std::shared_ptr<Run>> runs;
  {
    std::lock_guard schedule(schedule_mutex_);  // no start is half-done while the list is taken
    std::lock_guard lock(mutex_);
    if (shut_down_) return;
    shut_down_ = true;
    queue_.clear();
    runs = runs_;
  }
  {
    std::lock_guard lock(wakeup_->mutex);
    wakeup_->stop = true;
  }
  wakeup_->condition.notify_one();
  if (scheduler_.joinable()) scheduler_.join();
  // All at once: each stop is bounded (RunOptions::stop_grace_seconds), and so is their sum.
  std::vector<std::future<void>> stops;
  for (const auto& run : runs) {
    const RunState s = run->status().state;
    if (s == RunState::Running || s == RunState::Paused || s == RunState::Queued)
      stops.push_back(std::async(std::launch::async, [run] {
        try {
          run->stop("the server shut down; resume continues from the newest checkpoint");
        } catch (const std::exception& e) {
          logging::console("runs")->error("stopping run {}: {}", run->id(), e.what());
        }
      }));
  }
  for (auto& stop : stops) stop.wait();
  references_->shutdown();  // the running reference stops after its step, with a checkpoint
}

namespace {

/// A preset's or scene file's entry: what the form shows, and the whole scene as a run of the
/// service would have it (the live defaults when it has no analysis and render sections).
json scene_entry(const std::string& name, const json& document) {
  const RunSpec spec = parse_run_spec(with_live_defaults(document));
  const sim::Scene& s = spec.scene;
  return {{"name", name},
          {"case", sim::case_name(s.case_type)},
          {"dimension", s.dimension()},
          {"particles_per_side", s.particles_per_side},
          {"kernel", sim::kernel_name(s.kernel)},
          {"kernel_diameter_over_spacing", s.kernel_diameter_over_spacing},
          {"subfilter_model", sim::subfilter_model_name(s.subfilter.model)},
          {"end_time", s.end_time},
          {"description", description(name, s)},
          {"scene", run_spec_to_json(spec)}};
}

}  // namespace

json RunManager::presets() {
  json list = json::array();
  for (const std::string& name : scene::preset_names())
    list.push_back(scene_entry(name, {{"preset", name}}));
  return list;
}

json RunManager::scene_files(const std::filesystem::path& directory) {
  std::vector<std::filesystem::path> files;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(directory, ec))
    if (entry.path().extension() == ".json" && entry.is_regular_file(ec))
      files.push_back(entry.path());
  std::sort(files.begin(), files.end());
  json scenes = json::array();
  json skipped = json::array();
  for (const auto& file : files) {
    try {
      const json document = scene::read_scene_file(file);
      const std::string stem = file.stem().string();
      json entry = scene_entry(document.value("name", stem), document);
      entry["file"] = file.filename().string();
      scenes.push_back(std::move(entry));
    } catch (const std::exception& e) {
      skipped.push_back({{"file", file.filename().string()}, {"error", e.what()}});
    }
  }
  return {{"scenes", std::move(scenes)}, {"skipped", std::move(skipped)}};
}

}  // namespace sphles::control
