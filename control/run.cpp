#include "control/run.hpp"

#include <omp.h>

#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <fstream>
#include <limits>
#include <set>

#include "analysis/pipeline.hpp"
#include "analysis/snapshot.hpp"
#include "analysis/timeseries.hpp"
#include "analysis/writer.hpp"
#include "control/render_sink.hpp"
#include "io/checkpoint.hpp"
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

std::string utc_now() {
  const std::time_t now = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&now, &tm);
  char text[32];
  std::strftime(text, sizeof text, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return text;
}

// Live changes (docs/rendering.md): fields the run may change between two steps, and why the
// others may not. A path is allowed if an entry equals it or is a prefix of it.
const std::vector<std::string> kChangeable = {
    "name",
    "time.end",
    "time.cfl_acoustic",
    "time.cfl_viscous",
    "time.cfl_force",
    "time.fixed_step",
    "fluid.reference_pressure",
    "fluid.dynamic_viscosity",
    "subfilter.smagorinsky_constant",
    "subfilter.sigma_constant",
    "subfilter.filter_width",
    "forcing.amplitude",
    "forcing.friction",
    "analysis.every",
    "analysis.products",
    "analysis.slice",
    "analysis.particle_fields",
    "analysis.grid_points_per_spacing",
    "analysis.histogram_bins",
    "analysis.angle_bins",
    "analysis.angle_threshold",
    "analysis.spectrum_length_scale",
    "render",
    "checkpoint",
    "output.timeseries_every",
    "output.progress_every_seconds",
};

const std::vector<std::pair<std::string, std::string>> kFixedReasons = {
    {"case", "fixes the flow being simulated; create a new run"},
    {"preset", "fixes the flow being simulated; create a new run"},
    {"particles_per_side", "fixes the particle set; create a new run"},
    {"box_length", "fixes the particle set; create a new run"},
    {"kernel", "fixes the interaction stencil and the neighbour list; create a new run"},
    {"fluid.sound_speed",
     "sets the equation of state: changing it mid-run sends pressure waves through the flow; "
     "create a new run"},
    {"fluid.reference_density", "sets the particle masses; create a new run"},
    {"subfilter.model",
     "switching the sub-filter model mid-run is not supported; create a new run"},
    {"flow", "applies to the initial condition only"},
    {"packing", "applies to the initial condition only"},
    {"neighbours", "fixes the neighbour list that a bitwise restart relies on"},
    {"analysis.dissipation_window", "is fixed for the run's dissipation estimate"},
};

bool has_prefix(const std::string& path, const std::string& prefix) {
  return path == prefix ||
         (path.size() > prefix.size() && path.compare(0, prefix.size(), prefix) == 0 &&
          path[prefix.size()] == '.');
}

/// Dotted field of a JSON-pointer path from json::diff, cut at array indices ("/a/b/2" → "a.b").
std::string dotted_field(const std::string& pointer) {
  std::string field;
  std::size_t start = 1;
  while (start <= pointer.size()) {
    std::size_t end = pointer.find('/', start);
    if (end == std::string::npos) end = pointer.size();
    const std::string token = pointer.substr(start, end - start);
    if (!token.empty() && token.find_first_not_of("0123456789") == std::string::npos) break;
    field += (field.empty() ? "" : ".") + token;
    start = end + 1;
  }
  return field;
}

/// Which parts of a run a change touches.
struct ChangeScope {
  bool solver = false, analysis = false, render = false, other = false;
};

ChangeScope scope_of(const std::vector<std::string>& fields) {
  ChangeScope s;
  for (const std::string& f : fields) {
    if (has_prefix(f, "analysis"))
      s.analysis = true;
    else if (has_prefix(f, "render"))
      s.render = true;
    else if (has_prefix(f, "time") || has_prefix(f, "fluid") || has_prefix(f, "subfilter") ||
             has_prefix(f, "forcing"))
      s.solver = true;
    else
      s.other = true;
  }
  return s;
}

}  // namespace

const std::vector<std::string>& Run::changeable_fields() {
  return kChangeable;
}

// ---------------------------------------------------------------------------------------------
// The run

struct Run::Impl {
  std::string id;
  std::filesystem::path directory;
  RunOptions options;

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
  void refuse_if_retired(const std::string& run_id) const {
    if (retired) throw StateError("run " + run_id + " has been deleted");
  }
  std::thread thread;
  double time = 0.0, end_time = 0.0;
  std::uint64_t step = 0;
  double wall_seconds = 0.0, steps_per_second = 0.0;
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
    const json j = {{"id", id},
                    {"name", spec.run.scene.name},
                    {"state", run_state_name(state)},
                    {"reason", reason},
                    {"created", created},
                    {"updated", utc_now()},
                    {"time", time},
                    {"step", step}};
    write_text_atomically(directory / "run.json", j.dump(2) + "\n");
  }
  void write_scene_file_locked() const {
    write_text_atomically(directory / "scene.json", run_spec_to_json(spec).dump(2) + "\n");
  }

  /// Sets the state (caller holds the lock), persists it, and tells observers after unlocking.
  void set_state(std::unique_lock<std::mutex>& lock, RunState s, std::string why = {}) {
    state = s;
    reason = std::move(why);
    try {
      write_run_file_locked();
    } catch (const std::exception& e) {
      std::fprintf(stderr, "run %s: %s\n", id.c_str(), e.what());
    }
    const std::string r = reason;
    changed.notify_all();
    lock.unlock();
    for_each_observer([&](RunObserver& o) { o.on_state(s, r); });
    lock.lock();
  }

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
  if (checkpoint) {
    const io::Checkpoint c = io::read_checkpoint(*checkpoint);
    document = json::parse(c.metadata.scene_json);
    impl->start_checkpoint = checkpoint;
    impl->time = c.state.time;
    impl->step = c.state.step;
  } else {
    const std::filesystem::path scene = directory / "scene.json";
    if (!std::filesystem::exists(scene))
      throw std::runtime_error("'" + directory.string() +
                               "' is not a run directory (no scene.json)");
    document = sim::read_scene_file(scene.string());
  }
  for (const std::string& assignment : overrides) sim::apply_override(document, assignment);
  impl->spec = parse_run_spec(document);
  impl->end_time = impl->spec.run.scene.end_time;
  impl->continue_from_checkpoint = true;
  impl->state = RunState::Stopped;
  impl->created = utc_now();
  if (std::ifstream in(directory / "run.json"); in) {
    try {
      const json run = json::parse(in);
      impl->created = run.value("created", impl->created);
      impl->reason = run.value("reason", std::string());
      impl->state = run_state_from_name(run.value("state", std::string("stopped")));
      if (!checkpoint) {
        impl->time = run.value("time", 0.0);
        impl->step = run.value("step", std::uint64_t{0});
      }
    } catch (const std::exception& e) {
      impl->reason = std::string("run.json unreadable: ") + e.what();
    }
  }
  if (impl->state == RunState::Created || impl->state == RunState::Queued) {
    // Never started: it starts afresh.
    impl->state = RunState::Created;
    impl->continue_from_checkpoint = false;
  } else if (!is_terminal(impl->state)) {
    impl->reason = "the process ended while the run was " +
                   std::string(run_state_name(impl->state)) +
                   "; resume continues from the newest checkpoint";
    impl->state = RunState::Stopped;
  }
  std::unique_ptr<Run> run(new Run(std::move(id), directory, options, std::move(impl)));
  std::unique_lock lock(run->impl_->mutex);
  run->impl_->write_scene_file_locked();
  run->impl_->write_run_file_locked();
  return run;
}

Run::~Run() {
  try {
    const RunState s = status().state;
    if (s == RunState::Running || s == RunState::Paused) stop("the run object was destroyed");
  } catch (...) {
  }
  if (impl_->thread.joinable()) impl_->thread.join();
}

void Run::start() {
  std::unique_lock lock(impl_->mutex);
  Impl& r = *impl_;
  r.refuse_if_retired(id_);
  switch (r.state) {
    case RunState::Running:
    case RunState::Paused:
      throw StateError("run " + id_ + " is already " + std::string(run_state_name(r.state)));
    case RunState::Stopped:
    case RunState::Failed:
    case RunState::Finished:
      if (r.time >= r.spec.run.scene.end_time * (1.0 - 1e-12))
        throw StateError("run " + id_ + " has reached time.end = " +
                         sim::format_number(r.spec.run.scene.end_time) +
                         "; raise 'time.end' to continue it");
      r.continue_from_checkpoint = true;
      break;
    case RunState::Created:
    case RunState::Queued:
      break;
  }
  if (r.thread.joinable()) {
    lock.unlock();
    r.thread.join();
    lock.lock();
  }
  r.stop_requested = false;
  r.set_state(lock, RunState::Running);
  r.thread = std::thread([&r] { r.execute(); });
}

void Run::mark_queued() {
  std::unique_lock lock(impl_->mutex);
  impl_->refuse_if_retired(id_);
  if (impl_->state != RunState::Created && !is_terminal(impl_->state))
    throw StateError("run " + id_ + " is " + std::string(run_state_name(impl_->state)) +
                     " and cannot be queued");
  if (is_terminal(impl_->state)) impl_->continue_from_checkpoint = true;
  impl_->set_state(lock, RunState::Queued);
}

void Run::pause() {
  std::unique_lock lock(impl_->mutex);
  if (impl_->state != RunState::Running)
    throw StateError("run " + id_ + " is " + std::string(run_state_name(impl_->state)) +
                     "; only a running run can be paused");
  impl_->attention = true;
  impl_->set_state(lock, RunState::Paused);
}

void Run::resume() {
  std::unique_lock lock(impl_->mutex);
  impl_->refuse_if_retired(id_);
  if (impl_->state == RunState::Paused) {
    impl_->set_state(lock, RunState::Running);
    return;
  }
  if (impl_->state == RunState::Stopped || impl_->state == RunState::Failed ||
      impl_->state == RunState::Finished) {
    lock.unlock();
    start();
    return;
  }
  throw StateError("run " + id_ + " is " + std::string(run_state_name(impl_->state)) +
                   "; only a paused or stopped run can be resumed");
}

void Run::stop(const std::string& reason) {
  std::unique_lock lock(impl_->mutex);
  Impl& r = *impl_;
  if (is_terminal(r.state))
    throw StateError("run " + id_ + " is already " + std::string(run_state_name(r.state)));
  if (r.state == RunState::Created || r.state == RunState::Queued) {
    r.set_state(lock, RunState::Stopped, reason);
    return;
  }
  r.stop_requested = true;
  r.stop_reason = reason;
  r.attention = true;
  r.changed.notify_all();
  r.changed.wait(lock, [&] { return is_terminal(r.state); });
  if (r.thread.joinable() && r.thread.get_id() != std::this_thread::get_id()) {
    lock.unlock();
    r.thread.join();
  }
}

void Run::retire() {
  std::unique_lock lock(impl_->mutex);
  Impl& r = *impl_;
  if (r.state != RunState::Created && !is_terminal(r.state))
    throw StateError("run " + id_ + " is " + std::string(run_state_name(r.state)) +
                     "; stop it before deleting it");
  r.retired = true;
  // A finished solver thread may still be returning; nothing of it may outlive the directory.
  if (r.thread.joinable() && r.thread.get_id() != std::this_thread::get_id()) {
    lock.unlock();
    r.thread.join();
  }
}

void Run::reinstate() {
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
    std::unique_lock lock(impl_->mutex);
    impl_->refuse_if_retired(id_);
    if (impl_->state == RunState::Running || impl_->state == RunState::Paused)
      throw StateError("run " + id_ + " is already running");
    if (is_terminal(impl_->state)) impl_->continue_from_checkpoint = true;
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
  r.refuse_if_retired(id_);
  const RunSpec& base = r.pending ? *r.pending : r.spec;
  const json before = run_spec_to_json(base);
  json after = before;
  after.merge_patch(patch);
  RunSpec next;
  try {
    next = parse_run_spec(after);
  } catch (const sim::SceneError& e) {
    // "scene: 'a.b' must ..." → field a.b.
    std::string message = e.what();
    std::string field = "(body)";
    if (const auto open = message.find('\''); open != std::string::npos)
      if (const auto close = message.find('\'', open + 1); close != std::string::npos)
        field = message.substr(open + 1, close - open - 1);
    const std::string prefix = "scene: '" + field + "' ";
    throw ChangeError(field,
                      message.rfind(prefix, 0) == 0 ? message.substr(prefix.size()) : message);
  }
  const json normalised = run_spec_to_json(next);
  std::set<std::string> fields;
  for (const json& op : json::diff(before, normalised))
    fields.insert(dotted_field(op.at("path").get<std::string>()));
  for (const std::string& field : fields) {
    bool allowed = false;
    for (const std::string& c : kChangeable) allowed = allowed || has_prefix(field, c);
    if (allowed) continue;
    for (const auto& [prefix, why] : kFixedReasons)
      if (has_prefix(field, prefix))
        throw ChangeError(field, "cannot change while a run exists: " + why);
    throw ChangeError(field, "cannot change while a run exists");
  }
  if (fields.contains("time.end") && next.run.scene.end_time <= r.time)
    throw ChangeError("time.end", "must be after the current time " + sim::format_number(r.time));
  std::vector<std::string> list(fields.begin(), fields.end());
  if (list.empty()) return list;
  const bool active = r.state == RunState::Running || r.state == RunState::Paused;
  if (active) {
    r.pending = std::move(next);
    r.pending_fields.insert(r.pending_fields.end(), list.begin(), list.end());
    r.attention = true;
  } else {
    r.spec = std::move(next);
    r.end_time = r.spec.run.scene.end_time;
    ++r.revision;
  }
  r.write_scene_file_locked();
  if (!active) r.write_run_file_locked();
  if (active) {
    // scene.json shows the pending document: the solver thread applies it at the next step.
    write_text_atomically(r.directory / "scene.json", run_spec_to_json(*r.pending).dump(2) + "\n");
  }
  return list;
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
  s.latest = r.latest;
  s.analysis_published = r.analysis_published;
  s.analysis_dropped = r.analysis_dropped;
  s.frames_rendered = r.frames_rendered;
  s.frames_skipped = r.frames_skipped;
  return s;
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
  } catch (const std::exception& e) {
    std::unique_lock lock(mutex);
    std::string why = e.what();
    const auto files = io::list_checkpoints(directory / "checkpoints");
    why += files.empty()
               ? "; no checkpoint was written"
               : "; last valid checkpoint: checkpoints/" + files.front().filename().string();
    if (options.log_progress) std::fprintf(stderr, "run %s failed: %s\n", id.c_str(), why.c_str());
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
  // Temporaries of a write that a crash interrupted are never valid checkpoints: remove them.
  if (std::filesystem::exists(checkpoint_dir))
    for (const auto& entry : std::filesystem::directory_iterator(checkpoint_dir))
      if (entry.path().filename().string().find(".h5.tmp.") != std::string::npos)
        std::filesystem::remove(entry.path());

  std::optional<io::Checkpoint> checkpoint;
  if (resumed) {
    std::filesystem::path file;
    if (start_checkpoint) {
      file = *start_checkpoint;
    } else if (!io::list_checkpoints(checkpoint_dir).empty()) {
      std::vector<std::string> rejected;
      file = io::newest_valid_checkpoint(checkpoint_dir, &rejected);
      for (const std::string& why : rejected) std::fprintf(stderr, "skipped: %s\n", why.c_str());
    }
    if (!file.empty()) {
      checkpoint = io::read_checkpoint(file);
      if (options.log_progress)
        std::fprintf(stderr, "restart: %s at t = %.17g, step %llu\n", file.c_str(),
                     checkpoint->state.time,
                     static_cast<unsigned long long>(checkpoint->state.step));
    }
  }
  const sim::Scene& scene0 = current.run.scene;
  if (options.log_progress)
    std::fprintf(stderr,
                 "sphles run: %s (%s), %zu particles, kernel %s, D_K/dl = %g, %d threads -> %s\n",
                 scene0.name.c_str(), std::string(sim::case_name(scene0.case_type)).c_str(),
                 scene0.num_particles(), std::string(sim::kernel_name(scene0.kernel)).c_str(),
                 scene0.kernel_diameter_over_spacing, omp_get_max_threads(), directory.c_str());
  if (checkpoint) {
    packing = checkpoint->metadata.packing;
    simulation =
        sim::restore_simulation(sim::make_solver_config(scene0), std::move(checkpoint->state));
    truncate_timeseries_after(directory / "timeseries.csv", simulation->time());
    RenderSink::truncate_index_after(frames_dir, simulation->time());
  } else {
    std::error_code ignored;
    std::filesystem::remove(directory / "timeseries.csv", ignored);
    std::filesystem::remove(frames_dir / "index.csv", ignored);
    const auto setup_start = Clock::now();
    sim::RunSetup setup = sim::setup_run(scene0);
    const double setup_seconds = std::chrono::duration<double>(Clock::now() - setup_start).count();
    char text[512];
    std::snprintf(text, sizeof text,
                  "%s; iterations %d; residual %.6g -> %.6g; from cache %s; cache file %s",
                  scene0.packing.enabled ? "Colagrossi packing" : "lattice (packing disabled)",
                  setup.packing.iterations, setup.packing.initial_residual,
                  setup.packing.final_residual, setup.packing.from_cache ? "yes" : "no",
                  setup.packing.cache_file.empty() ? "-" : setup.packing.cache_file.c_str());
    packing = text;
    if (scene0.packing.enabled && options.log_progress)
      std::fprintf(stderr, "packing: %s, %d iterations, residual %.3g -> %.3g (%.1f s)%s%s\n",
                   setup.packing.from_cache  ? "from cache"
                   : setup.packing.converged ? "converged"
                                             : "NOT converged (max_iterations reached)",
                   setup.packing.iterations, setup.packing.initial_residual,
                   setup.packing.final_residual, setup_seconds,
                   setup.packing.cache_file.empty() ? "" : ", cache ",
                   setup.packing.cache_file.c_str());
    simulation = sim::make_simulation(setup.solver, std::move(setup.particles));
  }

  analysis::TimeSeriesWriter timeseries(directory / "timeseries.csv",
                                        sim::case_diagnostic_names(scene0), checkpoint.has_value());
  analysis::DissipationEstimator dissipation(current.run.analysis.dissipation_window);
  // A resumed run refills the trailing window from its time series, so that ε(t) continues as
  // in an uninterrupted run.
  if (checkpoint) seed_dissipation(directory / "timeseries.csv", simulation->time(), dissipation);
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
    const std::vector<double> values =
        sim::case_diagnostics(current.run.scene, simulation->particles());
    const double epsilon = dissipation.add(d.time, d.kinetic_energy);
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
    io::write_checkpoint(checkpoint_dir / io::checkpoint_file_name(simulation->step_count()),
                         simulation->state(), metadata,
                         {.gzip_level = current.run.scene.checkpoint.compression});
    const auto files = io::list_checkpoints(checkpoint_dir);
    for (std::size_t k = static_cast<std::size_t>(current.run.scene.checkpoint.keep);
         k < files.size(); ++k)
      std::filesystem::remove(files[k]);
    last_checkpoint_wall = Clock::now();
    last_checkpoint_step = simulation->step_count();
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
      writer = std::make_unique<analysis::RunDirectoryWriter>(directory,
                                                              run_spec_to_json(current).dump());
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
  if (pipeline && !checkpoint) pipeline->publish(analysis::make_snapshot(*simulation));

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
        if (scope.solver)
          simulation = sim::restore_simulation(sim::make_solver_config(current.run.scene),
                                               simulation->state());
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
      pipeline->publish(analysis::make_snapshot(*simulation));
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
    if (std::chrono::duration<double>(Clock::now() - last_flush).count() >=
        options.metrics_batch_seconds)
      flush_metrics();
    if (const std::string line = progress->update(d); !line.empty() && options.log_progress)
      std::fprintf(stderr, "%s\n", line.c_str());
  }

  if (options.log_progress)
    std::fprintf(stderr, "%s\n", progress->update(simulation->diagnostics(), true).c_str());
  flush_metrics();
  if (stopped || current.run.scene.checkpoint.enabled()) save_checkpoint();
  if (pipeline) {
    pipeline->close(/*drain=*/!stopped);
    if (options.log_progress) {
      const analysis::PipelineCounters c = pipeline->counters();
      std::fprintf(
          stderr, "analysis: %llu snapshots published, %llu analysed, %llu dropped, %.1f s busy\n",
          static_cast<unsigned long long>(c.published), static_cast<unsigned long long>(c.analysed),
          static_cast<unsigned long long>(c.dropped), c.busy_seconds);
    }
  }
  if (renderer) renderer->close(/*drain=*/!stopped);
  publish_progress(true);
  if (pipeline && !pipeline->error().empty())
    throw std::runtime_error("analysis failed: " + pipeline->error());
  if (writer && !writer->last_error().empty())
    throw std::runtime_error("writing analysis products failed: " + writer->last_error());
  if (renderer && !renderer->error().empty())
    throw std::runtime_error("rendering failed: " + renderer->error());
  std::unique_lock lock(mutex);
  if (stopped) {
    set_state(lock, RunState::Stopped, stopped_reason);
  } else {
    if (options.log_progress)
      std::fprintf(stderr, "sphles run: finished, outputs in %s\n", directory.c_str());
    set_state(lock, RunState::Finished);
  }
}

}  // namespace sphles::control
