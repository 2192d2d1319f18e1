// SPDX-License-Identifier: GPL-3.0-or-later
#include "control/reference_jobs.hpp"

#include <algorithm>
#include <array>
#include <cstdio>
#include <cstdlib>

#include "analysis/reference.hpp"
#include "control/render_sink.hpp"
#include "control/resources.hpp"
#include "control/run_files.hpp"
#include "logging/logging.hpp"
#include "scene/document.hpp"
#include "scene/json_reader.hpp"
#include "scene/schema.hpp"
#include "spectral/fourier_terms.hpp"

namespace sphles::control {

namespace fs = std::filesystem;
using nlohmann::json;
using sim::SceneError;

namespace {

constexpr sim::NameTable<JobState, 5> kJobStateNames{{{
    {JobState::Queued, "queued"},
    {JobState::Running, "running"},
    {JobState::Done, "done"},
    {JobState::Stopped, "stopped"},
    {JobState::Failed, "failed"},
}}};

JobState parse_job_state(const std::string& name) {
  if (const std::optional<JobState> state = kJobStateNames.find(name)) return *state;
  throw std::runtime_error("job.json: unknown state '" + name + "'");
}

bool allows(JobState state, std::string_view verb) {
  const std::vector<std::string_view> verbs = job_actions(state);
  return std::ranges::find(verbs, verb) != verbs.end();
}

std::shared_ptr<spdlog::logger> references_log() {
  return logging::console("references");
}

/// The scene schema's rule for reference.KEY as a client reads it: "an even integer in [8,
/// 1024]", "a number in (0, 1.5]".
std::string schema_rule(const std::string& key) {
  const json& node = *scene::scene_schema_node("reference." + key);
  const bool open = node.contains("exclusiveMinimum");
  const double low = node.at(open ? "exclusiveMinimum" : "minimum").get<double>();
  const std::string kind = node.value("multipleOf", 0.0) == 2.0  ? "an even integer"
                           : node.value("type", "") == "integer" ? "an integer"
                                                                 : "a number";
  return kind + " in " + (open ? "(" : "[") + sim::format_number(low) + ", " +
         sim::format_number(node.at("maximum").get<double>()) + "]";
}

/// A request key that sets reference.KEY of the scene: checked by the scene's own reader,
/// refused naming the request's key with the schema's rule.
void check_reference_key(const std::string& key, const json& value) {
  try {
    spectral::parse_reference_config(json{{"reference", {{key, value}}}});
  } catch (const SceneError&) {
    throw SceneError(key, "request: '" + key + "' must be " + schema_rule(key) + " (reference." +
                              key + " in the scene schema), got " + value.dump());
  }
}

/// Why the server refuses a reference, or nothing.
std::optional<std::string> memory_refusal(const ReferencePlan& plan, double max_memory_bytes) {
  if (plan.estimate.memory_bytes <= max_memory_bytes) return std::nullopt;
  return "the reference with points_per_side = " +
         std::to_string(plan.spec.reference.points_per_side) + " needs an estimated " +
         format_bytes(plan.estimate.memory_bytes) + " at its peak, more than the " +
         format_bytes(max_memory_bytes) +
         " the server allows (--max-memory): ask for fewer points_per_side";
}

bool has_checkpoint(const fs::path& directory) {
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(directory / "checkpoints", ec))
    if (e.path().extension() == ".h5" && e.path().filename().string().starts_with("ref_"))
      return true;
  return false;
}

}  // namespace

json reference_estimate_json(const spectral::ReferenceEstimate& e) {
  return {{"memory_bytes", e.memory_bytes},
          {"checkpoint_bytes", e.checkpoint_bytes},
          {"steps", e.steps},
          {"max_wavenumber", e.max_wavenumber}};
}

spectral::ReferenceRunResult run_rendered_reference(const RunSpec& spec, const json& document,
                                                    const spectral::ReferenceRunOptions& options) {
  fs::create_directories(options.directory);
  render::RenderConfig render;
  render.fields = {analysis::SliceField::VorticitySquared};
  render.combined = false;
  render.save = true;
  RenderSink sink(
      render, std::string(sim::case_name(spec.scene.case_type)), options.directory / "frames",
      [](const RenderedImage&) {}, [] { return false; });
  spectral::ReferenceRunOptions rendered = options;
  rendered.on_frame = [&sink, &options](std::shared_ptr<const analysis::AnalysisFrame> frame) {
    if (options.on_frame) options.on_frame(frame);
    sink.post(std::move(frame));
  };
  const spectral::ReferenceRunResult result = spectral::run_reference(
      spec.scene, spec.analysis, spec.policy, spec.reference, document, rendered);
  sink.close(true);
  if (!sink.error().empty()) throw std::runtime_error("rendering: " + sink.error());
  return result;
}

std::vector<std::string_view> job_actions(JobState state) {
  const bool active = state == JobState::Queued || state == JobState::Running;
  std::vector<std::string_view> verbs;
  if (active) verbs.push_back("stop");
  if (state == JobState::Stopped || state == JobState::Failed) verbs.push_back("resume");
  if (!active) verbs.push_back("delete");
  return verbs;
}

std::string_view job_state_name(JobState state) {
  return kJobStateNames.name(state);
}

ReferenceRequest parse_reference_request(const json& body) {
  if (!body.is_object())
    throw SceneError("(body)",
                     "request: '(body)' must be a JSON object, got " + scene::describe_type(body));
  ReferenceRequest request;
  for (const auto& [key, value] : body.items()) {
    if (key == "run") {
      if (!value.is_string() || value.get<std::string>().empty())
        throw SceneError(
            "run", "request: 'run' must be a run id (a non-empty string), got " + value.dump());
      request.run = value.get<std::string>();
    } else if (key == "points_per_side") {
      check_reference_key(key, value);
      request.points_per_side = value.get<int>();
    } else if (key == "cfl") {
      check_reference_key(key, value);
      request.cfl = value.get<double>();
    } else if (key == "dry_run") {
      if (!value.is_boolean())
        throw SceneError("dry_run", "request: 'dry_run' must be true or false, got " +
                                        scene::describe_type(value));
      request.dry_run = value.get<bool>();
    } else {
      throw SceneError(
          key, "request: unknown key '" + key + "' (valid: run, points_per_side, cfl, dry_run)");
    }
  }
  if (request.run.empty())
    throw SceneError("run", "request: 'run' is required: the id of the run whose flow to compute");
  return request;
}

struct ReferenceJobs::Job {
  std::string id, run;
  ReferencePlan plan;
  fs::path directory;
  JobState state = JobState::Queued;
  std::string error;
  double time = 0.0;
  std::uint64_t step = 0;
};

ReferenceJobs::ReferenceJobs(fs::path data_directory, double max_memory_bytes)
    : data_directory_(std::move(data_directory)),
      directory_(data_directory_ / "references"),
      max_memory_bytes_(max_memory_bytes) {
  fs::create_directories(directory_);
  open_existing();
  worker_ = std::thread([this] { work(); });
}

ReferenceJobs::~ReferenceJobs() {
  shutdown();
}

void ReferenceJobs::open_existing() {
  std::vector<fs::path> directories = analysis::reference_run_directories(directory_);
  std::sort(directories.begin(), directories.end());
  for (const fs::path& directory : directories) {
    const std::string id = directory.filename().string();
    try {
      const json record = json::parse(read_text(directory / "job.json"));
      auto job = std::make_shared<Job>();
      job->id = id;
      job->run = record.at("run").get<std::string>();
      job->error = record.value("error", "");
      job->directory = directory;
      job->plan = plan(scene::read_scene_file(directory / "scene.json"), {});
      job->state = parse_job_state(record.at("state").get<std::string>());
      // Queued or running when the previous process ended: nothing runs unasked.
      if (job->state == JobState::Queued || job->state == JobState::Running)
        job->state = JobState::Stopped;
      const std::string progress = read_text(directory / "run.json");
      if (!progress.empty()) {
        const json run = json::parse(progress);
        job->time = run.value("time", 0.0);
        job->step = run.value("step", std::uint64_t{0});
      }
      jobs_.push_back(std::move(job));
    } catch (const std::exception& e) {
      references_log()->warn("skipping reference directory {}: {}", directory.string(), e.what());
    }
    next_number_ =
        std::max<std::uint64_t>(next_number_, std::strtoull(id.c_str(), nullptr, 10) + 1);
  }
}

ReferencePlan ReferenceJobs::plan(json scene_document, const ReferenceRequest& request) {
  if (request.points_per_side)
    scene_document["reference"]["points_per_side"] = *request.points_per_side;
  if (request.cfl) scene_document["reference"]["cfl"] = *request.cfl;
  ReferencePlan p;
  p.spec = parse_run_spec(scene_document);
  p.document = run_spec_to_json(p.spec);
  p.estimate = spectral::estimate_reference(p.spec.scene, p.spec.reference);
  // The solver refuses a forcing it cannot represent; say so before the job is queued.
  const int forcing = spectral::flow_of(p.spec.scene).forcing_periods;
  if (forcing > p.estimate.max_wavenumber) {
    int enough = p.spec.reference.points_per_side;
    while (spectral::dealiased_max_wavenumber(enough) < forcing) enough += 2;
    throw SceneError(
        "points_per_side",
        "request: 'points_per_side' = " + std::to_string(p.spec.reference.points_per_side) +
            " keeps modes up to |m| = " + std::to_string(p.estimate.max_wavenumber) +
            ", below the Kolmogorov forcing's wavenumber " + std::to_string(forcing) +
            " (forcing.periods): take at least " + std::to_string(enough));
  }
  return p;
}

json ReferenceJobs::estimate(const ReferencePlan& plan) const {
  json answer = reference_estimate_json(plan.estimate);
  answer["points_per_side"] = plan.spec.reference.points_per_side;
  answer["cfl"] = plan.spec.reference.cfl;
  answer["end_time"] = plan.spec.scene.end_time;
  answer["memory_limit_bytes"] = max_memory_bytes_;
  const std::optional<std::string> refusal = memory_refusal(plan, max_memory_bytes_);
  answer["admitted"] = !refusal;
  if (refusal) answer["refusal"] = {{"field", "points_per_side"}, {"message", *refusal}};
  return answer;
}

ReferenceJobStatus ReferenceJobs::submit(const std::string& run, const ReferencePlan& plan) {
  if (const std::optional<std::string> refusal = memory_refusal(plan, max_memory_bytes_))
    throw AdmissionError("points_per_side", *refusal);
  std::unique_lock lock(mutex_);
  if (shut_down_) throw StateError("the server is shutting down");
  auto job = std::make_shared<Job>();
  char number[32];
  std::snprintf(number, sizeof number, "%04llu", static_cast<unsigned long long>(next_number_++));
  job->id = std::string(number) + "-" + directory_name(plan.spec.scene.name) + "-n" +
            std::to_string(plan.spec.reference.points_per_side);
  job->run = run;
  job->plan = plan;
  job->directory = directory_ / job->id;
  fs::create_directories(job->directory);
  std::string scene = plan.document.dump(2);
  scene.push_back('\n');
  write_text_atomically(job->directory / "scene.json", scene);
  write_record(*job);
  jobs_.push_back(job);
  queue_.push_back(job->id);
  const ReferenceJobStatus status = status_of(*job);
  lock.unlock();
  changed_.notify_all();
  references_log()->info("reference {} for run {} queued ({}^{} points, about {} steps)", status.id,
                         run, status.points_per_side, plan.spec.scene.dimension(),
                         plan.estimate.steps);
  return status;
}

std::vector<ReferenceJobStatus> ReferenceJobs::list() const {
  std::lock_guard lock(mutex_);
  std::vector<ReferenceJobStatus> all;
  for (const auto& job : jobs_) all.push_back(status_of(*job));
  return all;
}

ReferenceJobStatus ReferenceJobs::get(const std::string& id) const {
  std::lock_guard lock(mutex_);
  return status_of(*find(id));
}

std::vector<fs::path> ReferenceJobs::done_directories() const {
  std::lock_guard lock(mutex_);
  std::vector<fs::path> done;
  for (const auto& job : jobs_)
    if (job->state == JobState::Done) done.push_back(job->directory);
  return done;
}

void ReferenceJobs::stop(const std::string& id) {
  std::unique_lock lock(mutex_);
  const std::shared_ptr<Job> job = find(id);
  if (job->state == JobState::Queued) {
    std::erase(queue_, id);
    job->state = JobState::Stopped;
    write_record(*job);
  } else if (job->state == JobState::Running) {
    stop_running_ = true;
    changed_.wait(lock, [&] { return job->state != JobState::Running; });
  } else {
    throw StateError("reference job " + id + " is " + std::string(job_state_name(job->state)) +
                     ": only a queued or running job stops");
  }
}

void ReferenceJobs::resume(const std::string& id) {
  std::unique_lock lock(mutex_);
  const std::shared_ptr<Job> job = find(id);
  if (shut_down_) throw StateError("the server is shutting down");
  if (!allows(job->state, "resume"))
    throw StateError("reference job " + id + " is " + std::string(job_state_name(job->state)) +
                     ": only a stopped or failed job resumes");
  job->state = JobState::Queued;
  job->error.clear();
  write_record(*job);
  queue_.push_back(id);
  lock.unlock();
  changed_.notify_all();
}

void ReferenceJobs::remove(const std::string& id) {
  // The directory is moved to {data}/trash/ in one rename first, so an interrupted delete never
  // leaves a partial job that a restart would list (the run manager empties trash/ on start).
  const fs::path trash = data_directory_ / "trash" / ("reference-" + id);
  {
    std::lock_guard lock(mutex_);
    const std::shared_ptr<Job> job = find(id);
    if (!allows(job->state, "delete"))
      throw StateError("reference job " + id + " is " + std::string(job_state_name(job->state)) +
                       ": stop it first");
    fs::create_directories(trash.parent_path());
    fs::remove_all(trash);
    fs::rename(job->directory, trash);
    std::erase(jobs_, job);
  }
  std::error_code ignored;
  fs::remove_all(trash, ignored);
  references_log()->info("deleted reference {}", id);
}

void ReferenceJobs::shutdown() {
  {
    std::lock_guard lock(mutex_);
    if (shut_down_) return;
    shut_down_ = true;
    stop_running_ = true;
    for (const std::string& id : queue_) {
      const std::shared_ptr<Job> job = find(id);
      job->state = JobState::Stopped;
      write_record(*job);
    }
    queue_.clear();
  }
  changed_.notify_all();
  if (worker_.joinable()) worker_.join();
}

std::shared_ptr<ReferenceJobs::Job> ReferenceJobs::find(const std::string& id) const {
  for (const auto& job : jobs_)
    if (job->id == id) return job;
  throw UnknownRunError("no reference job with id '" + id + "'");
}

ReferenceJobStatus ReferenceJobs::status_of(const Job& job) const {
  ReferenceJobStatus s;
  s.id = job.id;
  s.run = job.run;
  s.state = job.state;
  s.error = job.error;
  s.time = job.time;
  s.step = job.step;
  s.end_time = job.plan.spec.scene.end_time;
  s.points_per_side = job.plan.spec.reference.points_per_side;
  s.cfl = job.plan.spec.reference.cfl;
  s.estimate = job.plan.estimate;
  s.directory = job.directory;
  return s;
}

void ReferenceJobs::write_record(const Job& job) const {
  json record = {{"run", job.run}, {"state", job_state_name(job.state)}, {"error", job.error}};
  try {
    write_text_atomically(job.directory / "job.json", record.dump(2) + "\n");
  } catch (const std::exception& e) {
    // The state in memory stands; a restart lists the job from its older record.
    references_log()->error("reference {}: {}", job.id, e.what());
  }
}

void ReferenceJobs::work() {
  for (;;) {
    std::shared_ptr<Job> job;
    {
      std::unique_lock lock(mutex_);
      changed_.wait(lock, [&] { return shut_down_ || !queue_.empty(); });
      if (shut_down_) return;
      job = find(queue_.front());
      queue_.pop_front();
      job->state = JobState::Running;
      stop_running_ = false;
      write_record(*job);
    }
    references_log()->info("reference {} running", job->id);
    JobState end = JobState::Done;
    std::string error;
    try {
      if (compute(*job)) end = JobState::Stopped;
    } catch (const std::exception& e) {
      end = JobState::Failed;
      error = e.what();
    }
    {
      std::lock_guard lock(mutex_);
      job->state = end;
      job->error = error;
      write_record(*job);
    }
    changed_.notify_all();
    if (end == JobState::Failed)
      references_log()->error("reference {} failed: {}", job->id, error);
    else
      references_log()->info("reference {} {} at t = {}", job->id, job_state_name(end), job->time);
  }
}

bool ReferenceJobs::compute(Job& job) {
  spectral::ReferenceRunOptions options;
  options.directory = job.directory;
  options.restart = has_checkpoint(job.directory);
  options.echo_progress = false;
  options.stop_requested = [this] { return stop_running_.load(); };
  options.on_step = [this, &job](double time, std::uint64_t step) {
    std::lock_guard lock(mutex_);
    job.time = time;
    job.step = step;
  };
  return run_rendered_reference(job.plan.spec, job.plan.document, options).stopped;
}

}  // namespace sphles::control
