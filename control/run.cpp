#include "control/run.hpp"

#include "control/scene_schema.hpp"

#include <omp.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <fstream>
#include <limits>

#include <sys/stat.h>

#include "analysis/pipeline.hpp"
#include "analysis/snapshot.hpp"
#include "analysis/timeseries.hpp"
#include "analysis/writer.hpp"
#include "control/live_changes.hpp"
#include "control/render_sink.hpp"
#include "io/checkpoint.hpp"
#include "logging/logging.hpp"
#include "sim/initial_conditions.hpp"
#include "sim/json_reader.hpp"
#include "sim/run_log.hpp"
#include "sim/solver.hpp"

#ifndef SPHLES_VERSION
#define SPHLES_VERSION "unknown"
#endif

namespace sphles::control {

using nlohmann::json;
using Clock = std::chrono::steady_clock;

// ---------------------------------------------------------------------------------------------
// Scene documents

RunSpec parse_run_spec(const json& document) {
  if (!document.is_object())
    throw sim::SceneError("scene: '(top level)' must be an object, got " +
                          sim::describe_type(document));
  json rest = document;
  json render_section;
  const bool has_render = document.contains("render");
  if (has_render) {
    render_section = document.at("render");
    rest.erase("render");
  }
  RunSpec spec;
  spec.run = analysis::parse_run_config(rest);
  spec.render =
      render::parse_render_config(has_render ? &render_section : nullptr, spec.run.analysis);
  // The readers apply the schema's keys, types and bounds with their own messages; the whole
  // schema (every keyword, by valijson) is the last word.
  if (const std::optional<std::string> violation = schema_violation(document))
    throw sim::SceneError("scene: " + *violation);
  return spec;
}

json run_spec_to_json(const RunSpec& spec) {
  json j = analysis::run_config_to_json(spec.run);
  j["render"] = render::render_config_to_json(spec.render);
  return j;
}

std::string_view run_state_name(RunState state) {
  switch (state) {
    case RunState::Created:
      return "created";
    case RunState::Queued:
      return "queued";
    case RunState::Running:
      return "running";
    case RunState::Paused:
      return "paused";
    case RunState::Finished:
      return "finished";
    case RunState::Stopped:
      return "stopped";
    case RunState::Failed:
      return "failed";
  }
  return "unknown";
}

bool is_terminal(RunState state) {
  return state == RunState::Finished || state == RunState::Stopped || state == RunState::Failed;
}

namespace {

RunState run_state_from_name(const std::string& name) {
  for (RunState s : {RunState::Created, RunState::Queued, RunState::Running, RunState::Paused,
                     RunState::Finished, RunState::Stopped, RunState::Failed})
    if (run_state_name(s) == name) return s;
  throw std::runtime_error("run.json: unknown state '" + name + "'");
}

/// The whole content of a text file; empty if it cannot be read.
std::string read_text(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

void write_text_atomically(const std::filesystem::path& path, const std::string& text) {
  const std::filesystem::path temporary = path.string() + ".tmp";
  {
    std::ofstream out(temporary, std::ios::trunc);
    out << text;
    out.flush();
    if (!out) throw std::runtime_error("cannot write '" + temporary.string() + "'");
  }
  std::filesystem::rename(temporary, path);
}

/// Keeps the rows of an existing timeseries.csv up to `time` (a restart continues it).
void truncate_timeseries_after(const std::filesystem::path& path, double time) {
  std::ifstream in(path);
  if (!in) return;
  std::string text, line;
  if (std::getline(in, line)) text += line + "\n";
  while (std::getline(in, line))
    if (std::strtod(line.c_str(), nullptr) <= time) text += line + "\n";
  in.close();
  write_text_atomically(path, text);
}

/// Index of the last cadence point at or before t (cadence points are k * every, computed the
/// same way in a fresh and in a restarted run, so both take the same steps).
std::uint64_t cadence_count(double t, double every) {
  return every > 0.0 ? static_cast<std::uint64_t>(std::floor(t / every + 1e-9)) : 0;
}

/// Feeds the (t, e_v) rows of a time series inside the estimator's window before `time`.
void seed_dissipation(const std::filesystem::path& path, double time,
                      analysis::DissipationEstimator& estimator) {
  std::ifstream in(path);
  std::string line;
  std::getline(in, line);  // header: t,step,dt,e_v,...
  while (std::getline(in, line)) {
    double values[4];
    const char* p = line.c_str();
    char* end = nullptr;
    for (double& v : values) {
      v = std::strtod(p, &end);
      p = *end == ',' ? end + 1 : end;
    }
    if (values[0] >= time - estimator.window() && values[0] <= time)
      estimator.add(values[0], values[3]);
  }
}

/// Device and inode of a directory; nullopt if it does not exist.
std::optional<std::pair<dev_t, ino_t>> directory_identity(const std::filesystem::path& path) {
  struct stat info {};
  if (::stat(path.c_str(), &info) != 0 || !S_ISDIR(info.st_mode)) return std::nullopt;
  return std::pair{info.st_dev, info.st_ino};
}

/// What the run directory holds, from its indexes (so every session of a restarted run counts):
/// for each kind of output, how many and at which times, and the index listing the files
/// (run.json "outputs", docs/analysis.md).
json outputs_json(const std::filesystem::path& dir) {
  const auto series = [&](const std::filesystem::path& index, const char* time_key,
                          const char* group_key) {
    json by_group = json::object();
    for (const auto& row : analysis::read_index(dir / index)) {
      if (!row.contains(time_key)) continue;
      const std::string group = group_key && row.contains(group_key) ? row.at(group_key) : "";
      json& entry = by_group[group];
      if (entry.is_null()) entry = {{"count", 0}, {"times", json::array()}};
      entry["count"] = entry["count"].get<int>() + 1;
      entry["times"].push_back(std::stod(row.at(time_key)));
    }
    json out = group_key ? json{{"index", index.string()}, {"by_field", by_group}}
                         : (by_group.contains("") ? by_group[""] : json{{"count", 0}});
    if (!group_key) out["index"] = index.string();
    return out;
  };
  json outputs = {{"timeseries", series("timeseries.csv", "t", nullptr)},
                  {"spectra", series("spectra/index.csv", "t", nullptr)},
                  {"statistics", series("stats/snapshots.csv", "t", nullptr)},
                  {"snapshots", series("snapshots/index.csv", "t", nullptr)},
                  {"fields", series("fields/index.csv", "t", nullptr)},
                  {"slices", series("slices/index.csv", "t", "field")},
                  {"frames", series("frames/index.csv", "time", "field")}};
  json checkpoints = json::array();
  for (const auto& file : io::list_checkpoints(dir / "checkpoints"))
    checkpoints.push_back(file.filename().string());
  outputs["checkpoints"] = {{"count", checkpoints.size()}, {"files", checkpoints}};
  return outputs;
}

/// One line: "written: 3 spectra, 3 snapshots, slices omega2 3 tau_sfs 3, ...".
std::string outputs_summary(const json& outputs) {
  std::string line = "written:";
  const auto count = [](const json& j) { return j.value("count", 0); };
  for (const char* kind :
       {"timeseries", "spectra", "statistics", "snapshots", "fields", "checkpoints"}) {
    // Appended piece by piece: GCC 12's -Wrestrict misreads the chained temporaries here.
    line.append(" ").append(std::to_string(count(outputs[kind]))).append(" ").append(kind);
    line.append(",");
  }
  for (const char* kind : {"slices", "frames"}) {
    line += std::string(" ") + kind;
    if (outputs[kind]["by_field"].empty()) line += " 0";
    for (const auto& [field, entry] : outputs[kind]["by_field"].items())
      line += " " + field + " " + std::to_string(count(entry));
    line += ",";
  }
  line.pop_back();
  return line;
}

std::string utc_now() {
  const std::time_t now = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&now, &tm);
  char text[32];
  std::strftime(text, sizeof text, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return text;
}

}  // namespace

const std::vector<std::string>& Run::changeable_fields() {
  return control::changeable_fields();
}

std::string directory_name(const std::string& name) {
  std::string out;
  for (const char c : name) {
    const bool plain = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
                       c == '-' || c == '_' || c == '.';
    out += plain ? c : '-';
    if (out.size() >= kMaxDirectoryName) break;
  }
  while (!out.empty() && out.front() == '.') out.erase(out.begin());
  return out.empty() ? "run" : out;
}

// ---------------------------------------------------------------------------------------------
// The run

struct Run::Impl {
  std::string id;
  std::filesystem::path directory;
  RunOptions options;

  // Serialises the transitions that spawn or join the solver thread (start, stop, mark_queued,
  // retire, destruction), so that exactly one caller ever joins it and a second request finds
  // the state the first one left. Taken before `mutex`, never by the solver thread.
  std::mutex transition_mutex;

  mutable std::mutex mutex;  // guards everything below up to "solver thread only"
  std::condition_variable changed;
  RunSpec spec;
  std::uint64_t revision = 0;      // number of change sets applied to spec
  std::optional<RunSpec> pending;  // changes the solver thread has not applied yet
  std::vector<std::string> pending_fields;
  RunState state = RunState::Created;
  std::string reason;
  bool holding = false;
  std::string created;
  bool stop_requested = false;
  std::string stop_reason;
  std::optional<std::filesystem::path> start_checkpoint;  // explicit restart file
  bool continue_from_checkpoint = false;
  bool retired = false;  // being deleted: every transition and change is refused
  void refuse_if_retired() const {
    if (retired) throw StateError("run " + id + " has been deleted");
  }
  std::unique_ptr<logging::RunLog> log;  // run.log (and the console)
  std::thread thread;
  std::string last_checkpoint;  // file name under checkpoints/ of the newest one written
  json outputs;                 // what the run directory holds, set when the run ends
  double time = 0.0, end_time = 0.0;
  std::uint64_t step = 0;
  double wall_seconds = 0.0, steps_per_second = 0.0;
  std::string phase;  // RunStatus::phase while the solver thread runs
  void set_phase(const char* p) {
    std::lock_guard lock(mutex);
    phase = p;
  }
  std::optional<MetricsSample> latest;
  std::shared_ptr<const analysis::AnalysisFrame> latest_frame;
  std::map<std::string, ImageEvent> latest_images;
  std::uint64_t analysis_published = 0, analysis_dropped = 0, frames_rendered = 0,
                frames_skipped = 0;
  std::atomic<bool> attention{false};  // a request waits for the solver thread

  mutable std::mutex observer_mutex;
  std::shared_ptr<const std::vector<std::shared_ptr<RunObserver>>> observers =
      std::make_shared<const std::vector<std::shared_ptr<RunObserver>>>();

  std::shared_ptr<const std::vector<std::shared_ptr<RunObserver>>> observer_list() const {
    std::lock_guard lock(observer_mutex);
    return observers;
  }
  /// Calls f on every observer. The list is held by a local so that it outlives the loop (a
  /// range-for over `*observer_list()` would destroy the temporary before the body runs).
  template <class F>
  void for_each_observer(F&& f) const {
    const auto list = observer_list();
    for (const auto& o : *list) f(*o);
  }
  bool wants_images() const {
    const auto list = observer_list();
    for (const auto& o : *list)
      if (o->wants_images()) return true;
    return false;
  }

  void write_run_file_locked() const {
    json j = {{"schema", "sphles-run"},
              {"code_version", SPHLES_VERSION},
              {"id", id},
              {"name", spec.run.scene.name},
              {"state", run_state_name(state)},
              {"reason", reason},
              {"created", created},
              {"updated", utc_now()},
              {"time", time},
              {"step", step},
              {"checkpoint", last_checkpoint},
              {"ranks", options.ranks},
              {"wall_seconds", wall_seconds}};
    if (!outputs.is_null()) j["outputs"] = outputs;
    write_text_atomically(directory / "run.json", j.dump(2) + "\n");
  }
  /// run.json, where a failure to write it must not change what happens (the state in memory is
  /// right; the file catches up at the next write).
  void try_write_run_file_locked() const {
    try {
      write_run_file_locked();
    } catch (const std::exception& e) {
      log->warn("{}", e.what());
    }
  }
  void write_scene_file_locked() const {
    write_text_atomically(directory / "scene.json", run_spec_to_json(spec).dump(2) + "\n");
  }

  /// Sets the state (caller holds the lock), persists it, and tells observers after unlocking.
  void set_state(std::unique_lock<std::mutex>& lock, RunState s, std::string why = {}) {
    const RunState before = state;
    state = s;
    reason = std::move(why);
    if (s == RunState::Failed)
      log->error("state: {} -> failed: {}", run_state_name(before), reason);
    else if (reason.empty())
      log->info("state: {} -> {}", run_state_name(before), run_state_name(s));
    else
      log->info("state: {} -> {} ({})", run_state_name(before), run_state_name(s), reason);
    try_write_run_file_locked();
    const std::string r = reason;
    changed.notify_all();
    lock.unlock();
    for_each_observer([&](RunObserver& o) { o.on_state(s, r); });
    lock.lock();
  }

  // Transitions; the caller holds transition_mutex (and not `mutex`).
  void prepare_start_locked();  // checks a start or queueing is allowed; caller holds `mutex`
  void start_locked();
  void stop_locked(const std::string& why);
  void join_solver();

  void execute();
  void solve(std::unique_ptr<sim::Simulation>& simulation, std::string& packing_provenance,
             bool resumed);
};

Run::Run(std::string id, std::filesystem::path directory, RunOptions options,
         std::unique_ptr<Impl> impl)
    : id_(std::move(id)), directory_(std::move(directory)), impl_(std::move(impl)) {
  impl_->id = id_;
  impl_->directory = directory_;
  impl_->options = options;
  impl_->log = std::make_unique<logging::RunLog>(id_, directory_ / "run.log", options.log_progress);
}

Run::Run(std::string id, RunSpec spec, std::filesystem::path directory, RunOptions options)
    : Run(std::move(id), std::move(directory), options, std::make_unique<Impl>()) {
  if (std::filesystem::exists(directory_ / "run.json") ||
      std::filesystem::exists(directory_ / "checkpoints"))
    throw std::runtime_error("run directory '" + directory_.string() +
                             "' already holds a run; open it instead");
  std::filesystem::create_directories(directory_);
  std::unique_lock lock(impl_->mutex);
  impl_->spec = std::move(spec);
  impl_->end_time = impl_->spec.run.scene.end_time;
  impl_->created = utc_now();
  impl_->write_scene_file_locked();
  impl_->write_run_file_locked();
}

std::unique_ptr<Run> Run::open(std::string id, const std::filesystem::path& directory,
                               RunOptions options, const std::vector<std::string>& overrides,
                               std::optional<std::filesystem::path> checkpoint) {
  auto impl = std::make_unique<Impl>();
  json document;
  std::string source;  // where the stored document came from, for error messages
  if (checkpoint) {
    const io::Checkpoint c = io::read_checkpoint(*checkpoint);
    source = "checkpoint '" + checkpoint->string() + "'";
    try {
      document = json::parse(c.metadata.scene_json);
    } catch (const json::exception& e) {
      throw std::runtime_error(source + ": attribute 'scene' is not a JSON document: " + e.what());
    }
    impl->start_checkpoint = checkpoint;
    impl->time = c.state.time;
    impl->step = c.state.step;
  } else {
    const std::filesystem::path scene = directory / "scene.json";
    if (!std::filesystem::exists(scene))
      throw std::runtime_error("'" + directory.string() +
                               "' is not a run directory (no scene.json)");
    source = "'" + scene.string() + "'";
    document = sim::read_scene_file(scene.string());
  }
  // Documents written before the packing cache became a program setting name it; it applied to
  // the initial condition only, so a stored run ignores it.
  if (document.is_object() && document.contains("packing") && document["packing"].is_object())
    document["packing"].erase("cache_dir");
  RunSpec stored;
  try {
    stored = parse_run_spec(document);
  } catch (const sim::SceneError& e) {
    throw sim::SceneError(source + ": " + e.what());
  }
  if (overrides.empty()) {
    impl->spec = std::move(stored);
  } else {
    // A restart continues the stored particles: it accepts exactly what a live change accepts,
    // and refuses the rest with the same message (the particle set, kernel, case, ...).
    const json before = run_spec_to_json(stored);
    json after = before;
    for (const std::string& assignment : overrides) sim::apply_override(after, assignment);
    impl->spec = check_change(before, after).spec;
  }
  impl->end_time = impl->spec.run.scene.end_time;
  impl->continue_from_checkpoint = true;
  impl->state = RunState::Stopped;
  impl->created = utc_now();
  bool record_changed = true;  // run.json must be (re)written
  if (std::ifstream in(directory / "run.json"); in) {
    try {
      const json run = json::parse(in);
      impl->created = run.value("created", impl->created);
      impl->reason = run.value("reason", std::string());
      impl->state = run_state_from_name(run.value("state", std::string("stopped")));
      impl->last_checkpoint = run.value("checkpoint", std::string());
      // Wall time spent stepping, over every start of the run (not reset by a resume or a
      // restart of the server; what was stepped after the newest record is not counted).
      impl->wall_seconds = run.value("wall_seconds", 0.0);
      if (!checkpoint) {
        // Written at every state change and after every checkpoint: after a crash it holds the
        // time of the newest checkpoint, where a resume continues.
        impl->time = run.value("time", 0.0);
        impl->step = run.value("step", std::uint64_t{0});
      }
      record_changed = checkpoint.has_value();
    } catch (const std::exception& e) {
      impl->reason = std::string("run.json unreadable: ") + e.what();
    }
  }
  if (impl->state == RunState::Created || impl->state == RunState::Queued) {
    // Never started: it starts afresh.
    record_changed = record_changed || impl->state == RunState::Queued;
    impl->state = RunState::Created;
    impl->continue_from_checkpoint = false;
  } else if (!is_terminal(impl->state)) {
    impl->reason = "the process ended while the run was " +
                   std::string(run_state_name(impl->state)) +
                   "; resume continues from the newest checkpoint";
    impl->state = RunState::Stopped;
    record_changed = true;
  }
  std::unique_ptr<Run> run(new Run(std::move(id), directory, options, std::move(impl)));
  Impl& r = *run->impl_;
  std::unique_lock lock(r.mutex);
  // Opening writes only what changed, so that a read-only data directory still lists its runs.
  // A restart with a checkpoint or overrides must record its scene; a listing need not.
  const std::string scene_text = run_spec_to_json(r.spec).dump(2) + "\n";
  const bool must_write = checkpoint.has_value() || !overrides.empty();
  try {
    if (must_write || read_text(directory / "scene.json") != scene_text)
      write_text_atomically(directory / "scene.json", scene_text);
    if (record_changed) r.write_run_file_locked();
  } catch (const std::exception& e) {
    if (must_write) throw;
    r.log->warn("{} (listed as it is; it cannot run until this is fixed)", e.what());
  }
  return run;
}

Run::~Run() {
  std::lock_guard transition(impl_->transition_mutex);
  try {
    const RunState s = status().state;
    if (s == RunState::Running || s == RunState::Paused)
      impl_->stop_locked("the run object was destroyed");
  } catch (...) {
  }
  impl_->join_solver();
}

void Run::Impl::join_solver() {
  if (thread.joinable() && thread.get_id() != std::this_thread::get_id()) thread.join();
}

void Run::Impl::prepare_start_locked() {
  refuse_if_retired();
  switch (state) {
    case RunState::Running:
    case RunState::Paused:
    case RunState::Queued:
      throw StateError("run " + id + " is already " + std::string(run_state_name(state)));
    case RunState::Stopped:
    case RunState::Failed:
    case RunState::Finished: {
      if (time >= spec.run.scene.end_time * (1.0 - 1e-12))
        throw StateError("run " + id +
                         " has reached time.end = " + sim::format_number(spec.run.scene.end_time) +
                         "; raise 'time.end' to continue it");
      // A run that has stepped continues from a checkpoint and never silently starts again at
      // t = 0 (that would overwrite its time series and frames); one that never stepped (stopped
      // while created, queued or packing) starts afresh.
      const bool has_checkpoint =
          start_checkpoint || !io::list_checkpoints(directory / "checkpoints").empty();
      if (step > 0 && !has_checkpoint)
        throw StateError("run " + id + " stepped to t = " + sim::format_number(time) +
                         " but has no checkpoint to continue from (its scene writes none); "
                         "create a new run");
      continue_from_checkpoint = step > 0 || has_checkpoint;
      break;
    }
    case RunState::Created:
      break;
  }
}

void Run::Impl::start_locked() {
  std::unique_lock lock(mutex);
  if (state != RunState::Queued) prepare_start_locked();
  refuse_if_retired();
  lock.unlock();
  join_solver();  // the previous solver thread has ended (terminal state); reap it
  lock.lock();
  stop_requested = false;
  set_state(lock, RunState::Running);
  thread = std::thread([this] { execute(); });
}

void Run::start() {
  std::lock_guard transition(impl_->transition_mutex);
  impl_->start_locked();
}

bool Run::start_if_queued() {
  std::lock_guard transition(impl_->transition_mutex);
  {
    std::lock_guard lock(impl_->mutex);
    if (impl_->state != RunState::Queued || impl_->retired) return false;
  }
  impl_->start_locked();
  return true;
}

void Run::mark_queued() {
  std::lock_guard transition(impl_->transition_mutex);
  std::unique_lock lock(impl_->mutex);
  impl_->prepare_start_locked();
  impl_->set_state(lock, RunState::Queued);
}

void Run::pause() {
  std::unique_lock lock(impl_->mutex);
  impl_->refuse_if_retired();
  if (impl_->state != RunState::Running)
    throw StateError("run " + id_ + " is " + std::string(run_state_name(impl_->state)) +
                     "; only a running run can be paused");
  impl_->attention = true;
  impl_->set_state(lock, RunState::Paused);
}

void Run::resume() {
  {
    std::unique_lock lock(impl_->mutex);
    impl_->refuse_if_retired();
    if (impl_->state == RunState::Paused) {
      impl_->set_state(lock, RunState::Running);
      return;
    }
    if (!is_terminal(impl_->state))
      throw StateError("run " + id_ + " is " + std::string(run_state_name(impl_->state)) +
                       "; only a paused or stopped run can be resumed");
  }
  start();  // re-checks the state under the transition lock
}

void Run::Impl::stop_locked(const std::string& why) {
  std::unique_lock lock(mutex);
  refuse_if_retired();
  if (is_terminal(state))
    throw StateError("run " + id + " is already " + std::string(run_state_name(state)));
  if (state == RunState::Created || state == RunState::Queued) {
    set_state(lock, RunState::Stopped, why);
    return;
  }
  stop_requested = true;
  stop_reason = why;
  attention = true;
  changed.notify_all();
  changed.wait(lock, [&] { return is_terminal(state); });
  lock.unlock();
  join_solver();
}

void Run::stop(const std::string& reason) {
  std::lock_guard transition(impl_->transition_mutex);
  impl_->stop_locked(reason);
}

void Run::retire() {
  std::lock_guard transition(impl_->transition_mutex);
  {
    std::lock_guard lock(impl_->mutex);
    Impl& r = *impl_;
    r.refuse_if_retired();
    if (r.state != RunState::Created && !is_terminal(r.state))
      throw StateError("run " + id_ + " is " + std::string(run_state_name(r.state)) +
                       "; stop it before deleting it");
    r.retired = true;
  }
  // A finished solver thread may still be returning; nothing of it may outlive the directory.
  impl_->join_solver();
}

void Run::reinstate() {
  std::lock_guard transition(impl_->transition_mutex);
  std::lock_guard lock(impl_->mutex);
  impl_->retired = false;
}

void Run::wait() {
  std::unique_lock lock(impl_->mutex);
  impl_->changed.wait(lock, [&] {
    return is_terminal(impl_->state) || impl_->state == RunState::Created ||
           impl_->state == RunState::Queued;
  });
}

RunState Run::run_here() {
  {
    // The transition lock covers the check only: the run then executes on this thread, and a
    // stop from another thread (a signal) must get through while it does.
    std::lock_guard transition(impl_->transition_mutex);
    std::unique_lock lock(impl_->mutex);
    impl_->prepare_start_locked();
    impl_->stop_requested = false;
    impl_->set_state(lock, RunState::Running);
  }
  impl_->execute();
  return status().state;
}

std::vector<std::string> Run::apply_changes(const json& patch) {
  if (!patch.is_object())
    throw ChangeError("(body)", "must be a JSON object (a merge patch of the scene), got " +
                                    std::string(patch.type_name()));
  std::unique_lock lock(impl_->mutex);
  Impl& r = *impl_;
  r.refuse_if_retired();
  const json before = run_spec_to_json(r.pending ? *r.pending : r.spec);
  json after = before;
  after.merge_patch(patch);
  CheckedChange change = check_change(before, after);
  if (change.fields.empty()) return {};
  if (r.options.admit) r.options.admit(change.spec);  // throws AdmissionError
  if (std::find(change.fields.begin(), change.fields.end(), "time.end") != change.fields.end() &&
      change.spec.run.scene.end_time <= r.time)
    throw ChangeError("time.end", "must be after the current time " + sim::format_number(r.time));
  // Persist first: a change that cannot be written would be lost at a restart, so it is not made
  // (the write error is thrown and nothing changes). scene.json shows the document the solver
  // thread applies at its next step.
  write_text_atomically(r.directory / "scene.json", run_spec_to_json(change.spec).dump(2) + "\n");
  const bool active = r.state == RunState::Running || r.state == RunState::Paused;
  if (active) {
    r.pending = std::move(change.spec);
    r.pending_fields.insert(r.pending_fields.end(), change.fields.begin(), change.fields.end());
    r.attention = true;
  } else {
    r.spec = std::move(change.spec);
    r.end_time = r.spec.run.scene.end_time;
    ++r.revision;
    r.try_write_run_file_locked();  // the name may have changed
  }
  std::string fields;
  for (const std::string& f : change.fields) fields += (fields.empty() ? "" : ", ") + f;
  r.log->info("changed {} by {} ({})", fields, patch.dump(),
              active ? "applied at the next step" : "stored for the next start");
  return change.fields;
}

RunStatus Run::status() const {
  std::lock_guard lock(impl_->mutex);
  const Impl& r = *impl_;
  RunStatus s;
  s.state = r.state;
  s.reason = r.reason;
  s.holding = r.holding;
  s.time = r.time;
  s.end_time = r.end_time;
  s.step = r.step;
  s.wall_seconds = r.wall_seconds;
  s.steps_per_second = r.steps_per_second;
  if (r.state == RunState::Running || r.state == RunState::Paused) s.phase = r.phase;
  s.latest = r.latest;
  s.analysis_published = r.analysis_published;
  s.analysis_dropped = r.analysis_dropped;
  s.frames_rendered = r.frames_rendered;
  s.frames_skipped = r.frames_skipped;
  return s;
}

int Run::ranks() const {
  return impl_->options.ranks;
}

int Run::recorded_ranks(const std::filesystem::path& directory) {
  std::ifstream in(directory / "run.json");
  if (!in) return 1;
  const json record = json::parse(in, nullptr, false);
  if (!record.is_object() || !record.contains("ranks") || !record["ranks"].is_number_integer())
    return 1;
  return std::max(1, record["ranks"].get<int>());
}

json Run::document() const {
  std::lock_guard lock(impl_->mutex);
  return run_spec_to_json(impl_->pending ? *impl_->pending : impl_->spec);
}

std::shared_ptr<const analysis::AnalysisFrame> Run::latest_frame() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->latest_frame;
}

std::optional<ImageEvent> Run::latest_image(const std::string& field) const {
  std::lock_guard lock(impl_->mutex);
  const auto it = impl_->latest_images.find(field);
  if (it == impl_->latest_images.end()) return std::nullopt;
  return it->second;
}

std::vector<std::string> Run::image_fields() const {
  std::lock_guard lock(impl_->mutex);
  std::vector<std::string> fields;
  for (const auto& [field, image] : impl_->latest_images)
    if (image.png) fields.push_back(field);
  return fields;
}

void Run::add_observer(std::shared_ptr<RunObserver> observer) {
  std::lock_guard lock(impl_->observer_mutex);
  auto list = std::make_shared<std::vector<std::shared_ptr<RunObserver>>>(*impl_->observers);
  list->push_back(std::move(observer));
  impl_->observers = std::move(list);
}

void Run::remove_observer(const RunObserver* observer) {
  std::lock_guard lock(impl_->observer_mutex);
  auto list = std::make_shared<std::vector<std::shared_ptr<RunObserver>>>();
  for (const auto& o : *impl_->observers)
    if (o.get() != observer) list->push_back(o);
  impl_->observers = std::move(list);
}

// ---------------------------------------------------------------------------------------------
// The solver thread

void Run::Impl::execute() {
  if (options.threads > 0) omp_set_num_threads(options.threads);
  std::unique_ptr<sim::Simulation> simulation;
  std::string packing;
  bool resumed = false;
  {
    std::lock_guard lock(mutex);
    resumed = continue_from_checkpoint;
  }
  try {
    solve(simulation, packing, resumed);
  } catch (const sim::SetupCancelled& e) {
    // A stop during the set-up: nothing was stepped, so a later start begins afresh.
    std::unique_lock lock(mutex);
    continue_from_checkpoint = false;
    set_state(lock, RunState::Stopped, stop_reason + " (" + e.what() + ", before the first step)");
  } catch (const std::exception& e) {
    std::unique_lock lock(mutex);
    std::string why = e.what();
    try {
      const auto files = io::list_checkpoints(directory / "checkpoints");
      why += files.empty()
                 ? "; no checkpoint was written"
                 : "; last valid checkpoint: checkpoints/" + files.front().filename().string();
    } catch (const std::exception& listing) {
      why += std::string("; the checkpoints cannot be listed: ") + listing.what();
    }
    set_state(lock, RunState::Failed, why);
  }
}

void Run::Impl::solve(std::unique_ptr<sim::Simulation>& simulation, std::string& packing,
                      bool resumed) {
  RunSpec current;
  {
    std::lock_guard lock(mutex);
    current = spec;
  }
  const std::filesystem::path checkpoint_dir = directory / "checkpoints";
  const std::filesystem::path frames_dir = directory / "frames";
  const auto restore_solver = [this](const sim::Scene& scene, sim::SolverState state) {
    return options.solvers.restore
               ? options.solvers.restore(scene, std::move(state))
               : sim::restore_simulation(sim::make_solver_config(scene), std::move(state));
  };
  // Temporaries of a write that a crash interrupted are never valid checkpoints: remove them.
  if (std::filesystem::exists(checkpoint_dir))
    for (const auto& entry : std::filesystem::directory_iterator(checkpoint_dir))
      if (entry.path().filename().string().find(".h5.tmp.") != std::string::npos)
        std::filesystem::remove(entry.path());

  std::optional<io::Checkpoint> checkpoint;
  set_phase(resumed ? "restoring" : current.run.scene.packing.enabled ? "packing" : "setting up");
  if (resumed) {
    std::filesystem::path file;
    if (start_checkpoint) {
      file = *start_checkpoint;
    } else if (!io::list_checkpoints(checkpoint_dir).empty()) {
      std::vector<std::string> rejected;
      file = io::newest_valid_checkpoint(checkpoint_dir, &rejected);
      for (const std::string& why : rejected) log->warn("skipped: {}", why);
    }
    if (file.empty())
      throw std::runtime_error(
          "cannot continue: no checkpoint in checkpoints/ (a run that has stepped never starts "
          "again from t = 0)");
    {
      checkpoint = io::read_checkpoint(file);
      log->progress("restart: {} at t = {:.17g}, step {}", file.string(), checkpoint->state.time,
                    checkpoint->state.step);
    }
  }
  const sim::Scene& scene0 = current.run.scene;
  log->progress("sphles run: {} ({}), {} particles, kernel {}, D_K/dl = {:g}, {} threads -> {}",
                scene0.name, sim::case_name(scene0.case_type), scene0.num_particles(),
                sim::kernel_name(scene0.kernel), scene0.kernel_diameter_over_spacing,
                omp_get_max_threads(), directory.string());
  if (checkpoint) {
    packing = checkpoint->metadata.packing;
    simulation = restore_solver(scene0, std::move(checkpoint->state));
    truncate_timeseries_after(directory / "timeseries.csv", simulation->time());
    RenderSink::truncate_index_after(frames_dir, simulation->time());
  } else {
    std::error_code ignored;
    std::filesystem::remove(directory / "timeseries.csv", ignored);
    std::filesystem::remove(frames_dir / "index.csv", ignored);
    const auto setup_start = Clock::now();
    sim::SetupOptions setup_options;
    setup_options.packing_cache_dir = options.packing_cache_dir;
    setup_options.cancelled = [this] {
      std::lock_guard lock(mutex);
      return stop_requested;
    };
    sim::RunSetup setup = sim::setup_run(scene0, setup_options);
    const double setup_seconds = std::chrono::duration<double>(Clock::now() - setup_start).count();
    char text[512];
    std::snprintf(text, sizeof text,
                  "%s; iterations %d; residual %.6g -> %.6g; from cache %s; cache file %s",
                  scene0.packing.enabled ? "Colagrossi packing" : "lattice (packing disabled)",
                  setup.packing.iterations, setup.packing.initial_residual,
                  setup.packing.final_residual, setup.packing.from_cache ? "yes" : "no",
                  setup.packing.cache_file.empty() ? "-" : setup.packing.cache_file.c_str());
    packing = text;
    if (scene0.packing.enabled)
      log->progress("packing: {}, {} iterations, residual {:.3g} -> {:.3g} ({:.1f} s){}{}",
                    setup.packing.from_cache  ? "from cache"
                    : setup.packing.converged ? "converged"
                                              : "NOT converged (max_iterations reached)",
                    setup.packing.iterations, setup.packing.initial_residual,
                    setup.packing.final_residual, setup_seconds,
                    setup.packing.cache_file.empty() ? "" : ", cache ", setup.packing.cache_file);
    set_phase("setting up");  // the solver (and any MPI job) from the packed particles
    simulation = options.solvers.make
                     ? options.solvers.make(scene0, std::move(setup.particles))
                     : sim::make_simulation(setup.solver, std::move(setup.particles));
  }
  set_phase("stepping");

  // Every output goes to the run directory: if it is deleted or replaced while the run goes on,
  // further writes would vanish into unlinked files, so the run fails instead, saying why.
  const auto identity = directory_identity(directory);
  auto last_directory_check = Clock::now();
  const auto check_directory = [&] {
    if (std::chrono::duration<double>(Clock::now() - last_directory_check).count() <
        options.directory_check_seconds)
      return;
    last_directory_check = Clock::now();
    if (directory_identity(directory) != identity)
      throw std::runtime_error("the run directory '" + directory.string() +
                               "' was deleted or replaced while the run was running; its "
                               "outputs could no longer be written");
  };
  analysis::TimeSeriesWriter timeseries(directory / "timeseries.csv",
                                        sim::case_diagnostic_names(scene0), checkpoint.has_value());
  analysis::DissipationEstimator dissipation(current.run.analysis.dissipation_window);
  // A resumed run refills the trailing window from its time series, so that ε(t) continues as
  // in an uninterrupted run.
  if (checkpoint) seed_dissipation(directory / "timeseries.csv", simulation->time(), dissipation);
  // -de_v/dt of the last row written: travels with each analysis snapshot (SPEC §5, the first of
  // the three dissipation estimates of stats/snapshots.csv).
  double latest_dissipation = std::numeric_limits<double>::quiet_NaN();
  std::vector<MetricsSample> batch;
  auto last_flush = Clock::now();
  const auto flush_metrics = [&] {
    if (batch.empty()) return;
    {
      std::lock_guard lock(mutex);
      latest = batch.back();
    }
    for_each_observer([&](RunObserver& o) { o.on_metrics(batch); });
    batch.clear();
    last_flush = Clock::now();
  };
  const auto record = [&](const sim::StepDiagnostics& d) {
    // Summed where the particles live (a distributed run gathers nothing for them).
    const std::vector<double> values = sim::case_diagnostic_names(current.run.scene).empty()
                                           ? std::vector<double>{}
                                           : simulation->case_diagnostics(current.run.scene);
    const double epsilon = dissipation.add(d.time, d.kinetic_energy);
    latest_dissipation = epsilon;
    timeseries.write(d, epsilon, values);
    MetricsSample m{d.time,      d.step, d.dt, d.kinetic_energy, epsilon, d.max_density_deviation,
                    d.max_speed, {}};
    const std::vector<std::string> names = sim::case_diagnostic_names(current.run.scene);
    for (std::size_t k = 0; k < names.size() && k < values.size(); ++k)
      m.case_values.emplace_back(names[k], values[k]);
    batch.push_back(std::move(m));
  };
  if (!checkpoint) record(simulation->diagnostics());

  // Checkpoints at multiples of checkpoint.every and/or every checkpoint.every_seconds of wall
  // time, the newest checkpoint.keep kept; always one when the run is stopped (to resume it).
  auto last_checkpoint_wall = Clock::now();
  std::uint64_t last_checkpoint_step = std::numeric_limits<std::uint64_t>::max();
  const auto save_checkpoint = [&] {
    if (simulation->step_count() == last_checkpoint_step) return;
    std::filesystem::create_directories(checkpoint_dir);
    const io::CheckpointMetadata metadata{run_spec_to_json(current).dump(), SPHLES_VERSION,
                                          packing};
    const auto file = checkpoint_dir / io::checkpoint_file_name(simulation->step_count());
    io::write_checkpoint(file, simulation->state(), metadata,
                         {.gzip_level = current.run.scene.checkpoint.compression});
    io::write_checkpoint_xdmf(file, simulation->state());
    const auto files = io::list_checkpoints(checkpoint_dir);
    for (std::size_t k = static_cast<std::size_t>(current.run.scene.checkpoint.keep);
         k < files.size(); ++k) {
      std::filesystem::remove(files[k]);
      std::filesystem::remove(io::checkpoint_xdmf_path(files[k]));
    }
    last_checkpoint_wall = Clock::now();
    last_checkpoint_step = simulation->step_count();
    // run.json follows the checkpoints: after a crash it says where a resume continues.
    std::lock_guard lock(mutex);
    time = simulation->time();
    step = simulation->step_count();
    last_checkpoint = io::checkpoint_file_name(simulation->step_count());
    try_write_run_file_locked();
  };

  // Consumers on their own threads, created when the scene first needs them.
  // Destroyed in reverse order: the pipeline (which feeds the renderer) stops first.
  std::unique_ptr<analysis::RunDirectoryWriter> writer;
  std::unique_ptr<RenderSink> renderer;
  std::atomic<RenderSink*> render_target{nullptr};  // read by the analysis thread
  std::unique_ptr<analysis::AnalysisPipeline> pipeline;
  const auto on_image = [this](const RenderedImage& image) {
    ImageEvent event{image.field, image.time, image.step, image.file, image.png, Clock::now()};
    {
      std::lock_guard lock(mutex);
      latest_images[image.field] = event;
    }
    for_each_observer([&](RunObserver& o) { o.on_image(event); });
  };
  const auto ensure_consumers = [&] {
    if (current.render.enabled() && !renderer) {
      renderer = std::make_unique<RenderSink>(current.render, current.run.scene.name, frames_dir,
                                              on_image, [this] { return wants_images(); });
      render_target = renderer.get();
    }
    if (current.run.analysis.enabled() && !pipeline) {
      writer = std::make_unique<analysis::RunDirectoryWriter>(
          directory, io::SnapshotMetadata{run_spec_to_json(current).dump(), SPHLES_VERSION});
      pipeline = std::make_unique<analysis::AnalysisPipeline>(
          current.run.analysis,
          std::vector<analysis::FrameSink>{
              [this, w = writer.get(), &render_target](const analysis::AnalysisFrame& frame) {
                w->write(frame);
                auto shared = std::make_shared<const analysis::AnalysisFrame>(frame);
                {
                  std::lock_guard lock(mutex);
                  latest_frame = shared;
                }
                if (RenderSink* target = render_target.load()) target->post(shared);
                for_each_observer([&](RunObserver& o) { o.on_analysis(shared); });
              }});
    }
  };
  ensure_consumers();
  if (pipeline && !checkpoint)
    pipeline->publish(analysis::make_snapshot(*simulation, latest_dissipation));

  const auto cadence = [&] {
    return std::tuple<std::uint64_t, std::uint64_t, std::uint64_t>{
        cadence_count(simulation->time(), current.run.scene.output.timeseries_every),
        cadence_count(simulation->time(), current.run.analysis.every),
        cadence_count(simulation->time(), current.run.scene.checkpoint.every)};
  };
  auto [output_count, snapshot_count, checkpoint_count] = cadence();
  auto progress = std::make_unique<sim::ProgressReporter>(
      current.run.scene.end_time, current.run.scene.output.progress_every_seconds);
  progress->update(simulation->diagnostics());
  auto rate_wall = Clock::now();
  std::uint64_t rate_step = simulation->step_count();
  const auto publish_progress = [&](bool force) {
    const auto now = Clock::now();
    const double span = std::chrono::duration<double>(now - rate_wall).count();
    std::lock_guard lock(mutex);
    time = simulation->time();
    step = simulation->step_count();
    if (span >= 1.0 || force) {
      if (span > 0.0 && step > rate_step)
        steps_per_second = static_cast<double>(step - rate_step) / span;
      rate_wall = now;
      rate_step = step;
    }
    if (pipeline) {
      const analysis::PipelineCounters c = pipeline->counters();
      analysis_published = c.published;
      analysis_dropped = c.dropped;
    }
    if (renderer) {
      const RenderCounters c = renderer->counters();
      frames_rendered = c.frames_rendered;
      frames_skipped = c.frames_skipped;
    }
  };

  bool stopped = false;
  std::string stopped_reason;
  for (;;) {
    if (attention.load(std::memory_order_relaxed)) {
      std::unique_lock lock(mutex);
      if (pending) {
        const ChangeScope scope = scope_of(pending_fields);
        spec = std::move(*pending);
        pending.reset();
        pending_fields.clear();
        ++revision;
        end_time = spec.run.scene.end_time;
        current = spec;
        lock.unlock();
        if (scope.solver) simulation = restore_solver(current.run.scene, simulation->state());
        if (scope.analysis && pipeline) pipeline->set_config(current.run.analysis);
        if (scope.render && renderer) renderer->set_config(current.render);
        ensure_consumers();
        std::tie(output_count, snapshot_count, checkpoint_count) = cadence();
        progress = std::make_unique<sim::ProgressReporter>(
            current.run.scene.end_time, current.run.scene.output.progress_every_seconds);
        lock.lock();
      }
      if (state == RunState::Paused && !stop_requested) {
        lock.unlock();
        flush_metrics();
        lock.lock();
        const auto paused_at = Clock::now();
        holding = true;
        changed.wait(lock, [&] { return state != RunState::Paused || stop_requested || pending; });
        holding = false;
        rate_wall += Clock::now() - paused_at;
      }
      if (stop_requested) {
        stopped = true;
        stopped_reason = stop_reason;
      }
      attention = pending.has_value() || state == RunState::Paused || stop_requested;
      if (pending && !stopped) continue;
    }
    if (stopped) break;
    const double end = current.run.scene.end_time;
    if (simulation->time() >= end - 1e-12 * end) break;

    const double every = current.run.scene.output.timeseries_every;
    const double analysis_every = current.run.analysis.every;
    const double checkpoint_every = current.run.scene.checkpoint.every;
    const double next_output = static_cast<double>(output_count + 1) * every;
    const double next_snapshot = static_cast<double>(snapshot_count + 1) * analysis_every;
    const double next_checkpoint = static_cast<double>(checkpoint_count + 1) * checkpoint_every;
    double max_dt = end - simulation->time();
    if (every > 0.0) max_dt = std::min(max_dt, next_output - simulation->time());
    if (pipeline && analysis_every > 0.0)
      max_dt = std::min(max_dt, next_snapshot - simulation->time());
    if (checkpoint_every > 0.0) max_dt = std::min(max_dt, next_checkpoint - simulation->time());
    const auto step_start = Clock::now();
    simulation->step(max_dt);
    const sim::StepDiagnostics& d = simulation->diagnostics();
    if (every <= 0.0 || d.time >= next_output - 1e-12 * every) {
      record(d);
      if (every > 0.0) ++output_count;
    }
    if (pipeline && analysis_every > 0.0 && d.time >= next_snapshot - 1e-12 * analysis_every) {
      pipeline->publish(analysis::make_snapshot(*simulation, latest_dissipation));
      ++snapshot_count;
    }
    bool checkpoint_due = false;
    if (checkpoint_every > 0.0 && d.time >= next_checkpoint - 1e-12 * checkpoint_every) {
      ++checkpoint_count;
      checkpoint_due = true;
    }
    const double every_seconds = current.run.scene.checkpoint.every_seconds;
    if (every_seconds > 0.0 &&
        std::chrono::duration<double>(Clock::now() - last_checkpoint_wall).count() >= every_seconds)
      checkpoint_due = true;
    if (checkpoint_due) save_checkpoint();
    {
      std::lock_guard lock(mutex);
      wall_seconds += std::chrono::duration<double>(Clock::now() - step_start).count();
    }
    publish_progress(false);
    check_directory();
    if (std::chrono::duration<double>(Clock::now() - last_flush).count() >=
        options.metrics_batch_seconds)
      flush_metrics();
    if (const std::string line = progress->update(d); !line.empty()) log->progress("{}", line);
  }

  log->progress("{}", progress->update(simulation->diagnostics(), true));
  flush_metrics();
  // Every run ends with a checkpoint, stopped or finished, so that it can be continued (raise
  // time.end) and never has to start again from t = 0.
  save_checkpoint();
  if (pipeline) {
    pipeline->close(/*drain=*/!stopped);
    const analysis::PipelineCounters c = pipeline->counters();
    log->progress("analysis: {} snapshots published, {} analysed, {} dropped, {:.1f} s busy",
                  c.published, c.analysed, c.dropped, c.busy_seconds);
  }
  if (renderer) renderer->close(/*drain=*/!stopped);
  publish_progress(true);
  if (pipeline && !pipeline->error().empty())
    throw std::runtime_error("analysis failed: " + pipeline->error());
  if (writer && !writer->last_error().empty())
    throw std::runtime_error("writing analysis products failed: " + writer->last_error());
  if (renderer && !renderer->error().empty())
    throw std::runtime_error("rendering failed: " + renderer->error());
  json written = outputs_json(directory);
  log->progress("{}", outputs_summary(written));
  std::unique_lock lock(mutex);
  outputs = std::move(written);
  if (stopped) {
    set_state(lock, RunState::Stopped, stopped_reason);
  } else {
    log->progress("sphles run: finished, outputs in {}", directory.string());
    set_state(lock, RunState::Finished);
  }
}

}  // namespace sphles::control
