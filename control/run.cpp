// SPDX-License-Identifier: GPL-3.0-or-later
#include "control/run.hpp"

#include <algorithm>
#include <fstream>
#include <stdexcept>

#include "control/live_changes.hpp"
#include "control/run_files.hpp"
#include "control/run_impl.hpp"
#include "io/checkpoint.hpp"
#include "scene/document.hpp"
#include "scene/json_reader.hpp"
#include "sim/format.hpp"

namespace sphles::control {

using nlohmann::json;

namespace {

constexpr sim::NameTable<RunState, 7> kRunStateNames{{{
    {RunState::Created, "created"},
    {RunState::Queued, "queued"},
    {RunState::Running, "running"},
    {RunState::Paused, "paused"},
    {RunState::Finished, "finished"},
    {RunState::Stopped, "stopped"},
    {RunState::Failed, "failed"},
}}};

}  // namespace

std::string_view run_state_name(RunState state) {
  return kRunStateNames.name(state);
}

bool is_terminal(RunState state) {
  return state == RunState::Finished || state == RunState::Stopped || state == RunState::Failed;
}

RunState run_state_from_name(const std::string& name) {
  if (const std::optional<RunState> state = kRunStateNames.find(name)) return *state;
  throw std::runtime_error("run.json: unknown state '" + name + "'");
}

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

void check_run_name(const std::string& name) {
  if (directory_name(name) != name)
    throw sim::SceneError(
        "name", "scene: 'name' must be 1 to " + std::to_string(kMaxDirectoryName) +
                    " letters, digits, '-', '_' or '.', not starting with '.' (it names the "
                    "run's directory), got '" +
                    name.substr(0, 2 * kMaxDirectoryName) + "'");
}

// ---------------------------------------------------------------------------------------------

Run::Run(std::string id, std::filesystem::path directory, RunOptions options,
         std::unique_ptr<RunImpl> impl)
    : id_(std::move(id)), directory_(std::move(directory)), impl_(std::move(impl)) {
  impl_->id = id_;
  impl_->directory = directory_;
  impl_->options = options;
  impl_->log = std::make_unique<logging::RunLog>(id_, directory_ / "run.log", options.log_progress);
}

Run::Run(std::string id, RunSpec spec, std::filesystem::path directory, RunOptions options)
    : Run(std::move(id), std::move(directory), options, std::make_unique<RunImpl>()) {
  if (std::filesystem::exists(directory_ / "run.json") ||
      std::filesystem::exists(directory_ / "checkpoints"))
    throw std::runtime_error("run directory '" + directory_.string() +
                             "' already holds a run; open it instead");
  std::filesystem::create_directories(directory_);
  std::unique_lock lock(impl_->mutex);
  impl_->spec = std::move(spec);
  impl_->end_time = impl_->spec.scene.end_time;
  impl_->created = utc_now();
  impl_->write_scene_file_locked();
  impl_->write_run_file_locked();
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

void RunImpl::join_solver() {
  if (thread.joinable() && thread.get_id() != std::this_thread::get_id()) thread.join();
}

std::optional<std::string> RunImpl::start_refusal(bool* continues) const {
  if (retired) return "run " + id + " has been deleted";
  switch (state) {
    case RunState::Running:
    case RunState::Paused:
    case RunState::Queued:
      return "run " + id + " is already " + std::string(run_state_name(state));
    case RunState::Stopped:
    case RunState::Failed:
    case RunState::Finished: {
      if (time >= spec.scene.end_time * (1.0 - 1e-12))
        return "run " + id + " has reached time.end = " + sim::format_number(spec.scene.end_time) +
               "; raise 'time.end' to continue it";
      // A run that has stepped continues from a checkpoint and never silently starts again at
      // t = 0 (that would overwrite its time series and frames); one that never stepped (stopped
      // while created, queued or packing) starts afresh.
      const bool has_checkpoint =
          start_checkpoint || !io::list_checkpoints(directory / "checkpoints").empty();
      if (step > 0 && !has_checkpoint)
        return "run " + id + " stepped to t = " + sim::format_number(time) +
               " but has no checkpoint to continue from: its checkpoints/ holds none (removed, "
               "or the run ended before it wrote one); create a new run";
      if (continues) *continues = step > 0 || has_checkpoint;
      return std::nullopt;
    }
    case RunState::Created:
      break;
  }
  return std::nullopt;
}

void RunImpl::prepare_start_locked() {
  refuse_if_retired();
  bool continues = continue_from_checkpoint;
  if (auto refusal = start_refusal(&continues)) throw StateError(*refusal);
  continue_from_checkpoint = continues;
}

std::vector<std::string_view> RunImpl::actions_locked() const {
  std::vector<std::string_view> verbs;
  if (retired) return verbs;
  if (!start_refusal(nullptr)) verbs.push_back("start");
  if (state == RunState::Running) verbs.push_back("pause");
  if (state == RunState::Paused) verbs.push_back("resume");
  if (!is_terminal(state)) verbs.push_back("stop");
  if (state == RunState::Created || is_terminal(state)) verbs.push_back("delete");
  return verbs;
}

void RunImpl::start_locked() {
  std::unique_lock lock(mutex);
  if (state != RunState::Queued) prepare_start_locked();
  refuse_if_retired();
  lock.unlock();
  join_solver();  // the previous solver thread has ended (terminal state); reap it
  lock.lock();
  stop_requested = false;
  solver_given_up = false;
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

bool RunImpl::stop_locked(const std::string& why) {
  std::unique_lock lock(mutex);
  refuse_if_retired();
  if (is_terminal(state))
    throw StateError("run " + id + " is already " + std::string(run_state_name(state)));
  if (state == RunState::Created || state == RunState::Queued) {
    set_state(lock, RunState::Stopped, why);
    return true;
  }
  stop_requested = true;
  stop_reason = why;
  attention = true;
  changed.notify_all();
  const auto ended = [&] { return is_terminal(state); };
  const auto seconds = [](double s) {
    return std::chrono::duration_cast<std::chrono::steady_clock::duration>(
        std::chrono::duration<double>(s));
  };
  // A set-up cannot be left half-way: a solver's job still being launched (a batch queue that
  // has not started it) or setting up is given up at once, as a local packing is cancelled.
  const bool setting_up = phase != "stepping";
  bool done = setting_up && options.end_solver_job
                  ? false
                  : changed.wait_for(lock, seconds(options.stop_grace_seconds), ended);
  if (!done && options.end_solver_job) {
    solver_given_up = true;
    const std::string cause = setting_up ? "a stop during its set-up"
                                         : "it did not reach its next step within " +
                                               sim::format_number(options.stop_grace_seconds) +
                                               " s of a stop";
    lock.unlock();
    options.end_solver_job(cause);
    lock.lock();
    done = changed.wait_for(lock, seconds(kJobEndSeconds), ended);
  }
  lock.unlock();
  if (done) join_solver();
  return done;
}

bool Run::stop(const std::string& reason) {
  {
    // A stop already under way: answered at once, so that repeated stops of one run never hold
    // run-control callers while it ends.
    std::lock_guard lock(impl_->mutex);
    if (impl_->stop_requested && !is_terminal(impl_->state) && impl_->state != RunState::Created &&
        impl_->state != RunState::Queued)
      return false;
  }
  std::lock_guard transition(impl_->transition_mutex);
  return impl_->stop_locked(reason);
}

void Run::retire() {
  std::lock_guard transition(impl_->transition_mutex);
  {
    // A change being written finishes first; none starts after (refuse_if_retired).
    std::lock_guard serial(impl_->change_mutex);
    std::lock_guard lock(impl_->mutex);
    RunImpl& r = *impl_;
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
  RunImpl& r = *impl_;
  // Parsing, validation, admission and the file write run outside the state lock, which the
  // solver thread takes every step; change_mutex keeps concurrent changes in order.
  std::lock_guard serial(r.change_mutex);
  json before;
  {
    std::lock_guard lock(r.mutex);
    r.refuse_if_retired();
    before = run_spec_to_json(r.pending ? *r.pending : r.spec);
  }
  json after = before;
  after.merge_patch(patch);
  CheckedChange change = check_change(before, after);
  if (change.fields.empty()) return {};
  if (std::find(change.fields.begin(), change.fields.end(), "name") != change.fields.end())
    check_run_name(change.spec.scene.name);
  if (r.options.admit) r.options.admit(change.spec, r.options.ranks);  // throws AdmissionError
  const bool end_changes =
      std::find(change.fields.begin(), change.fields.end(), "time.end") != change.fields.end();
  const auto refuse_past_end = [&] {
    if (end_changes && change.spec.scene.end_time <= r.time)
      throw ChangeError("time.end", "must be after the current time " + sim::format_number(r.time));
  };
  {
    std::lock_guard lock(r.mutex);
    refuse_past_end();
  }
  // Persist first: a change that cannot be written would be lost at a restart, so it is not made
  // (the write error is thrown and nothing changes). scene.json shows the document the solver
  // thread applies at its next step.
  write_text_atomically(r.directory / "scene.json", run_spec_to_json(change.spec).dump(2) + "\n");
  std::unique_lock lock(r.mutex);
  try {
    refuse_past_end();  // the run went on while the document was written
  } catch (const ChangeError&) {
    lock.unlock();
    write_text_atomically(r.directory / "scene.json", before.dump(2) + "\n");
    throw;
  }
  const bool active = r.state == RunState::Running || r.state == RunState::Paused;
  if (active) {
    r.pending = std::move(change.spec);
    r.pending_fields.insert(r.pending_fields.end(), change.fields.begin(), change.fields.end());
    r.attention = true;
  } else {
    r.spec = std::move(change.spec);
    r.end_time = r.spec.scene.end_time;
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
  const RunImpl& r = *impl_;
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
  s.actions = r.actions_locked();
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

RunSpec Run::spec() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->pending ? *impl_->pending : impl_->spec;
}

json Run::document() const {
  return run_spec_to_json(spec());
}

std::shared_ptr<const analysis::AnalysisFrame> Run::latest_frame() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->latest_frame;
}

std::optional<ImageEvent> Run::latest_image(const std::string& field) const {
  ImageEvent image;
  {
    std::lock_guard lock(impl_->mutex);
    const auto it = impl_->latest_images.find(field);
    if (it == impl_->latest_images.end()) return std::nullopt;
    image = it->second;
  }
  if (image.png || image.file.empty()) return image;
  // A saved image of an earlier process (saved_images): read once, outside the lock.
  const std::string bytes = read_text(directory_ / "frames" / image.file);
  if (bytes.empty()) return image;
  image.png = std::make_shared<const std::vector<unsigned char>>(bytes.begin(), bytes.end());
  std::lock_guard lock(impl_->mutex);
  ImageEvent& stored = impl_->latest_images[field];
  if (!stored.png && stored.file == image.file) stored.png = image.png;
  return image;
}

std::vector<std::string> Run::image_fields() const {
  std::lock_guard lock(impl_->mutex);
  std::vector<std::string> fields;
  for (const auto& [field, image] : impl_->latest_images)
    if (image.png || !image.file.empty()) fields.push_back(field);
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

}  // namespace sphles::control
