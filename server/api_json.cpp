// SPDX-License-Identifier: GPL-3.0-or-later
#include "server/api_json.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <new>

#include "analysis/reference.hpp"
#include "control/resources.hpp"
#include "control/run_manager.hpp"
#include "sim/scene.hpp"

namespace sphles::server {

namespace {

/// Dimension of a scene document's case; the document is complete (every default filled in).
int document_dimension(const nlohmann::json& document) {
  const auto it = document.find("case");
  if (it != document.end() && it->is_string()) {
    for (const sim::CaseType type :
         {sim::CaseType::TaylorGreen3D, sim::CaseType::TaylorGreen2D, sim::CaseType::Kolmogorov2D})
      if (sim::case_name(type) == it->get_ref<const std::string&>())
        return sim::case_dimension(type);
  }
  try {
    return control::parse_run_spec(document).scene.dimension();
  } catch (const std::exception&) {
    return 0;
  }
}

nlohmann::json value_or_null(const nlohmann::json& document, const char* key) {
  const auto it = document.find(key);
  if (it == document.end()) return nullptr;
  return *it;
}

}  // namespace

nlohmann::json metrics_json(const control::MetricsSample& s) {
  nlohmann::json j = {{"time", s.time},
                      {"step", s.step},
                      {"dt", s.dt},
                      {"kinetic_energy", s.kinetic_energy},
                      {"dissipation", s.dissipation},
                      {"max_density_deviation", s.max_density_deviation},
                      {"max_speed", s.max_speed}};
  for (const auto& [name, value] : s.case_values) j[name] = value;
  return j;
}

nlohmann::json reference_job_json(const control::ReferenceJobStatus& job) {
  const double progress = job.end_time > 0.0 ? std::clamp(job.time / job.end_time, 0.0, 1.0) : 0.0;
  return {{"id", job.id},
          {"run", job.run},
          {"state", control::job_state_name(job.state)},
          {"actions", control::job_actions(job.state)},
          {"error", job.error},
          {"time", job.time},
          {"end_time", job.end_time},
          {"step", job.step},
          {"progress", progress},
          {"points_per_side", job.points_per_side},
          {"cfl", job.cfl},
          {"directory", job.directory.filename().string()},
          {"estimate", control::reference_estimate_json(job.estimate)}};
}

nlohmann::json run_summary_json(const control::Run& run) {
  return run_summary_json(run, run.status(), run.document());
}

nlohmann::json run_summary_json(const control::Run& run, const control::RunStatus& status,
                                const nlohmann::json& document) {
  const double progress =
      status.end_time > 0.0 ? std::clamp(status.time / status.end_time, 0.0, 1.0) : 0.0;
  return {{"id", run.id()},
          {"name", value_or_null(document, "name")},
          {"state", control::run_state_name(status.state)},
          {"reason", status.reason},
          {"case", value_or_null(document, "case")},
          {"dimension", document_dimension(document)},
          {"particles_per_side", value_or_null(document, "particles_per_side")},
          {"time", status.time},
          {"end_time", status.end_time},
          {"step", status.step},
          {"progress", progress},
          {"steps_per_second", status.steps_per_second},
          {"wall_seconds", status.wall_seconds},
          {"phase", status.phase},
          {"actions", status.actions},
          {"ranks", run.ranks()}};
}

nlohmann::json run_detail_json(const control::Run& run, const StreamCounters& stream) {
  const control::RunStatus status = run.status();
  nlohmann::json document = run.document();
  nlohmann::json detail = run_summary_json(run, status, document);
  detail["scene"] = std::move(document);
  // What makes the run's answer meaningless although it runs (sim/scene_warnings.hpp).
  detail["warnings"] = control::scene_warnings_to_json(sim::scene_warnings(run.spec().scene));
  detail["latest"] = status.latest ? metrics_json(*status.latest) : nlohmann::json(nullptr);
  detail["changeable"] = control::Run::changeable_fields();
  detail["counters"] = {{"analysis_published", status.analysis_published},
                        {"analysis_dropped", status.analysis_dropped},
                        {"frames_rendered", status.frames_rendered},
                        {"frames_skipped", status.frames_skipped}};
  detail["stream"] = {{"clients", stream.clients}, {"dropped", stream.dropped}};
  // What GET spectrum / statistics / images/{field} would return now, so that a client asks
  // only for products that exist instead of collecting 404s.
  const auto frame = run.latest_frame();
  const bool reference = !analysis::missing_reference(run.spec().scene);
  detail["available"] = {{"spectrum", frame && frame->spectrum.has_value()},
                         {"statistics", frame && frame->subfilter.has_value()},
                         {"images", run.image_fields()},
                         {"reference", reference}};
  return detail;
}

nlohmann::json image_header_json(const std::string& run_id, const control::ImageEvent& image) {
  const std::string base = "/api/runs/" + run_id;
  const auto created_ns =
      std::chrono::duration_cast<std::chrono::nanoseconds>(image.created.time_since_epoch())
          .count();
  return {{"type", "image"},
          {"field", image.field},
          {"time", image.time},
          {"step", image.step},
          {"file", image.file},
          {"url",
           image.file.empty() ? base + "/images/" + image.field : base + "/frames/" + image.file},
          {"created_ns", static_cast<std::int64_t>(created_ns)}};
}

nlohmann::json error_json(const ApiError& error) {
  return {{"error",
           {{"status", error.status()},
            {"message", error.what()},
            {"field", error.field() ? nlohmann::json(*error.field()) : nlohmann::json(nullptr)}}}};
}

ApiError to_api_error(const std::exception& error) {
  if (const auto* e = dynamic_cast<const ApiError*>(&error)) return *e;
  if (dynamic_cast<const control::UnknownRunError*>(&error))
    return ApiError(404, error.what(), "id");
  if (dynamic_cast<const control::StateError*>(&error)) return ApiError(409, error.what());
  if (dynamic_cast<const control::CapacityError*>(&error)) return ApiError(429, error.what());
  if (const auto* e = dynamic_cast<const control::AdmissionError*>(&error))
    return ApiError(422, e->what(), e->field());
  if (const auto* e = dynamic_cast<const control::ChangeError*>(&error))
    return ApiError(400, e->what(), e->field());
  if (const auto* e = dynamic_cast<const sim::SceneError*>(&error))
    return ApiError(400, e->what(),
                    e->field().empty() ? std::nullopt : std::optional<std::string>(e->field()));
  if (dynamic_cast<const std::bad_alloc*>(&error))
    return ApiError(503, "out of memory while answering; try again later");
  return ApiError(500, std::string("internal error: ") + error.what());
}

namespace {

/// True if arrays/objects nest deeper than max_depth (brackets inside strings ignored).
bool nests_deeper_than(std::string_view text, int max_depth) {
  int depth = 0;
  bool in_string = false, escaped = false;
  for (const char c : text) {
    if (in_string) {
      if (escaped)
        escaped = false;
      else if (c == '\\')
        escaped = true;
      else if (c == '"')
        in_string = false;
    } else if (c == '"') {
      in_string = true;
    } else if (c == '[' || c == '{') {
      if (++depth > max_depth) return true;
    } else if (c == ']' || c == '}') {
      --depth;
    }
  }
  return false;
}

}  // namespace

nlohmann::json parse_client_json(std::string_view text, std::string_view what) {
  if (nests_deeper_than(text, kMaxJsonDepth))
    throw ApiError(400, std::string(what) + ": JSON nested deeper than " +
                            std::to_string(kMaxJsonDepth) + " levels");
  try {
    return nlohmann::json::parse(text);
  } catch (const nlohmann::json::parse_error& e) {
    throw ApiError(400, std::string(what) + ": malformed JSON at byte " + std::to_string(e.byte) +
                            ": " + e.what());
  } catch (const nlohmann::json::exception& e) {  // e.g. out_of_range for 1e999
    throw ApiError(400, std::string(what) + ": unusable JSON: " + e.what());
  }
}

std::string dump(const nlohmann::json& value) {
  return value.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

}  // namespace sphles::server
