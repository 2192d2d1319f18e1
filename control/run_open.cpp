// SPDX-License-Identifier: GPL-3.0-or-later
// Opening a stored run (Run::open): its scene or a checkpoint's, its record in run.json, its
// newest checkpoint and what it computed before, so that a restarted process lists, serves and
// continues it where it stood.
#include <fstream>
#include <stdexcept>

#include "analysis/frame_reader.hpp"
#include "control/live_changes.hpp"
#include "control/run.hpp"
#include "control/run_files.hpp"
#include "control/run_impl.hpp"
#include "io/checkpoint.hpp"
#include "scene/document.hpp"
#include "scene/json_reader.hpp"

namespace sphles::control {

using nlohmann::json;

namespace {

/// Reads run.json into `impl` (state, reason, creation, wall time; with no explicit checkpoint
/// also time and step); whether run.json must be written again.
bool read_run_record(const std::filesystem::path& directory, RunImpl& impl,
                     bool explicit_checkpoint) {
  std::ifstream in(directory / "run.json");
  if (!in) return true;
  try {
    const json run = json::parse(in);
    impl.created = run.value("created", impl.created);
    impl.reason = run.value("reason", std::string());
    impl.state = run_state_from_name(run.value("state", std::string("stopped")));
    impl.last_checkpoint = run.value("checkpoint", std::string());
    // Wall time spent stepping, over every start of the run (not reset by a resume or a
    // restart of the server; what was stepped after the newest record is not counted).
    impl.wall_seconds = run.value("wall_seconds", 0.0);
    if (!explicit_checkpoint) {
      // Written at every state change and after every checkpoint.
      impl.time = run.value("time", 0.0);
      impl.step = run.value("step", std::uint64_t{0});
    }
    return explicit_checkpoint;
  } catch (const std::exception& e) {
    impl.reason = std::string("run.json unreadable: ") + e.what();
    return true;
  }
}

/// run.json follows each checkpoint, but a kill between a checkpoint's rename and run.json's
/// write leaves it one checkpoint behind: the newest checkpoint (by its header; a resume reads
/// it whole) decides where the run stands. Whether it moved the run on.
bool follow_newest_checkpoint(const std::filesystem::path& directory, RunImpl& impl) {
  try {
    io::CheckpointHeader h;
    const std::filesystem::path newest = io::newest_valid_checkpoint(
        directory / "checkpoints", nullptr, io::CheckpointCheck::Header,
        [&h, of_this_run = checkpoints_of_run(directory)](const std::filesystem::path& file,
                                                          const io::CheckpointHeader& read) {
          of_this_run(file, read);
          h = read;
        });
    if (!(h.shape.time > impl.time)) return false;
    impl.time = h.shape.time;
    impl.step = h.step;
    impl.last_checkpoint = newest.filename().string();
    return true;
  } catch (const std::exception&) {
    return false;  // no checkpoint (or none readable): run.json's record stands
  }
}

}  // namespace

void check_checkpoint_belongs(const std::filesystem::path& directory,
                              const json& checkpoint_scene) {
  const std::filesystem::path own = directory / "scene.json";
  if (!std::filesystem::exists(own)) return;
  json before;
  try {
    json document = scene::read_scene_file(own);
    if (document.is_object() && document.contains("packing") && document["packing"].is_object())
      document["packing"].erase("cache_dir");
    before = run_spec_to_json(parse_run_spec(document));
  } catch (const sim::SceneError&) {
    return;  // no readable scene of its own: the checkpoint's is the run's
  }
  try {
    check_change(before, run_spec_to_json(parse_run_spec(checkpoint_scene)));
  } catch (const std::exception& e) {
    throw std::runtime_error("not a checkpoint of the run in '" + directory.string() +
                             "': " + e.what());
  }
}

std::function<void(const std::filesystem::path&, const io::CheckpointHeader&)> checkpoints_of_run(
    std::filesystem::path directory) {
  return [directory = std::move(directory)](const std::filesystem::path& file,
                                            const io::CheckpointHeader& header) {
    try {
      check_checkpoint_belongs(directory, json::parse(header.metadata.scene_json));
    } catch (const std::exception& e) {
      throw io::CheckpointError("checkpoint '" + file.string() + "' is " + e.what());
    }
  };
}

std::unique_ptr<Run> Run::open(std::string id, const std::filesystem::path& directory,
                               RunOptions options, const std::vector<std::string>& overrides,
                               std::optional<std::filesystem::path> checkpoint) {
  // What writes a crash interrupted left (run.json.tmp, NAME.xdmf2.tmp, frames' and checkpoints'
  // temporaries) is never a valid output. Nothing of this run writes yet: the server writes
  // scene.json and run.json of a run it holds through temporaries too, so this runs here only.
  remove_interrupted_writes(directory);
  auto impl = std::make_unique<RunImpl>();
  json document;
  std::string source;  // where the stored document came from, for error messages
  if (checkpoint) {
    // A solver that reads its checkpoint on its ranks needs only the attributes here (no
    // process reads the whole file); one process validates all of it before it starts.
    const io::CheckpointHeader header = options.solvers.restore_file
                                            ? io::read_checkpoint_header(*checkpoint)
                                            : io::header_of(io::read_checkpoint(*checkpoint));
    source = "checkpoint '" + checkpoint->string() + "'";
    try {
      document = json::parse(header.metadata.scene_json);
    } catch (const json::exception& e) {
      throw std::runtime_error(source + ": attribute 'scene' is not a JSON document: " + e.what());
    }
    try {
      check_checkpoint_belongs(directory, document);
    } catch (const std::runtime_error& e) {
      throw std::runtime_error(source + " is " + e.what());
    }
    impl->start_checkpoint = checkpoint;
    impl->time = header.shape.time;
    impl->step = header.step;
  } else {
    const std::filesystem::path scene = directory / "scene.json";
    if (!std::filesystem::exists(scene))
      throw std::runtime_error("'" + directory.string() +
                               "' is not a run directory (no scene.json)");
    // Appended, not "'" + ...: GCC 12 reports a false -Wrestrict there (GCC bug 105329).
    source.append("'").append(scene.string()).append("'");
    document = scene::read_scene_file(scene.string());
  }
  // Documents written before the packing cache became a program setting name it; it applied to
  // the initial condition only, so a stored run ignores it.
  if (document.is_object() && document.contains("packing") && document["packing"].is_object())
    document["packing"].erase("cache_dir");
  RunSpec stored;
  try {
    stored = parse_run_spec(document);
  } catch (const sim::SceneError& e) {
    throw sim::SceneError(e.field(), source + ": " + e.what());
  }
  if (overrides.empty()) {
    impl->spec = std::move(stored);
  } else {
    // A restart continues the stored particles: it accepts exactly what a live change accepts,
    // and refuses the rest with the same message (the particle set, kernel, case, ...).
    const json before = run_spec_to_json(stored);
    json after = before;
    for (const std::string& assignment : overrides) scene::apply_override(after, assignment);
    impl->spec = check_change(before, after).spec;
  }
  impl->end_time = impl->spec.scene.end_time;
  impl->continue_from_checkpoint = true;
  impl->state = RunState::Stopped;
  impl->created = utc_now();
  bool record_changed = read_run_record(directory, *impl, checkpoint.has_value());
  if (!checkpoint && follow_newest_checkpoint(directory, *impl)) record_changed = true;
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
  // What the run computed before is served again: its newest analysed frame and saved images.
  std::string products_error;
  try {
    if (auto frame = analysis::read_latest_frame(directory, impl->spec.analysis))
      impl->latest_frame = std::make_shared<const analysis::AnalysisFrame>(std::move(*frame));
  } catch (const std::exception& e) {
    products_error = e.what();
  }
  impl->latest_images = saved_images(directory);
  impl->latest = last_metrics(directory / "timeseries.csv");
  std::unique_ptr<Run> run(new Run(std::move(id), directory, options, std::move(impl)));
  RunImpl& r = *run->impl_;
  if (!products_error.empty())
    r.log->warn("its newest analysis does not read back ({}); it is shown again after the next",
                products_error);
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

}  // namespace sphles::control
