// SPDX-License-Identifier: GPL-3.0-or-later
// What a run has computed so far (docs/api.md "Products"): its time series and analysis history
// (paged or decimated), its reference curve and resolved scales, the end of its log, and the
// latest frame's spectrum and sub-filter statistics.
#include <charconv>
#include <cmath>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "analysis/reference.hpp"
#include "analysis/resolved_scales.hpp"
#include "logging/logging.hpp"
#include "server/handlers/handlers.hpp"
#include "server/product_cache.hpp"

namespace sphles::server::handlers {

namespace http = boost::beast::http;
namespace fs = std::filesystem;

namespace {

/// A query parameter that must be a finite number > 0, if given.
std::optional<double> query_positive(const Context& c, const std::string& name) {
  const auto it = c.query.find(name);
  if (it == c.query.end()) return std::nullopt;
  double value = 0.0;
  const std::string& text = it->second;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (text.empty() || ec != std::errc() || end != text.data() + text.size() ||
      !std::isfinite(value) || !(value > 0.0))
    throw ApiError(400, "'" + name + "' must be a number > 0, got '" + text + "'", name);
  return value;
}

/// A growing CSV file of the run with a step column, as columns, paged or decimated.
Response csv_history(const Services& s, const Context& c, const fs::path& relative) {
  const auto run = find_run(s, c.params[0]);
  const HistoryQuery query = history_query(s, c, true);
  return make_json_text(c.request,
                        timeseries_answer(run->directory() / relative, query, s.limits, s.series));
}

/// A product of the run's latest frame as the frame's one shared text.
Response product(const Services& s, const Context& c, Product which, const char* what) {
  const auto run = find_run(s, c.params[0]);
  const std::shared_ptr<const std::string> text = s.products.get(run->latest_frame(), which);
  if (!text) throw ApiError(404, "run '" + run->id() + "' has no " + what + " yet");
  Response res = make_response(c.request, http::status::ok, std::string(), "application/json");
  res.set(http::field::cache_control, "no-store");
  res.body().share(text);
  res.prepare_payload();
  return res;
}

}  // namespace

Response timeseries(const Services& s, const Context& c) {
  return csv_history(s, c, "timeseries.csv");
}

/// Every analysis frame's scalars so far (stats/snapshots.csv: e_v on the grid, ⟨ω²⟩, the
/// dissipation three ways, max and mean |τ_SFS|), paged or decimated as the time series.
Response analysis_history(const Services& s, const Context& c) {
  return csv_history(s, c, fs::path("stats") / "snapshots.csv");
}

/// The run's reference curve (analysis/reference.hpp): the analytic decay of the 2D TGV, the DNS
/// of the 3D TGV at Re = 1600 and 5000, the laminar Kolmogorov flow; 404 saying why a run has none.
/// `until` ends it early (the analytic curves then sampled over the shorter span).
Response reference(const Services& s, const Context& c) {
  constexpr int kSamples = 201;
  const auto run = find_run(s, c.params[0]);
  const std::optional<double> until = query_positive(c, "until");
  const sim::Scene scene = run->spec().scene;
  analysis::ReferenceCurve curve;
  try {
    curve =
        analysis::reference_curve(scene, s.reference_dir, kSamples, until.value_or(scene.end_time));
  } catch (const std::invalid_argument& e) {
    throw ApiError(404, "run '" + run->id() + "' has no reference: " + e.what());
  } catch (const std::runtime_error& e) {
    throw ApiError(500, e.what());
  }
  return json_response(c.request, {{"label", curve.label},
                                   {"source", curve.source},
                                   {"columns", {"time", "kinetic_energy", "dissipation"}},
                                   {"data", {curve.time, curve.energy, curve.dissipation}}});
}

/// The run's resolved scales against the reference run of its flow in the server's reference
/// data (analysis/resolved_scales.hpp, SPEC §9): at every analysed time the reference covers,
/// and the reference's E(k) at the latest of them; 404 saying why when there is none.
Response resolved(const Services& s, const Context& c) {
  const auto run = find_run(s, c.params[0]);
  const sim::Scene scene = run->spec().scene;
  // ?filter=kernel judges against the reference filtered by the run's kernel (compare --filter).
  const auto filter_it = c.query.find("filter");
  const std::string filter = filter_it == c.query.end() ? "none" : filter_it->second;
  if (filter != "none" && filter != "kernel")
    throw ApiError(400, "'filter' must be none or kernel, got '" + filter + "'", "filter");
  const auto reference = reference_run_of(s, scene);
  if (!reference)
    throw ApiError(404, "run '" + run->id() +
                            "' has no reference run of its flow in the server's reference data "
                            "or done reference jobs (POST /api/references or `sphles reference` "
                            "computes one; docs/reference.md)");
  if (!fs::exists(run->directory() / "spectra" / "index.csv"))
    throw ApiError(404, "run '" + run->id() + "' has no spectra yet");
  std::vector<analysis::ShellSpectrum> ref;
  analysis::ResolvedHistory h;
  try {
    ref = analysis::read_run_spectra(*reference);
    if (filter == "kernel") ref = analysis::kernel_filtered(std::move(ref), scene);
    h = analysis::resolved_history(analysis::read_run_spectra(run->directory()), ref);
  } catch (const std::runtime_error& e) {
    throw ApiError(500, e.what());
  }
  if (h.samples.empty())
    throw ApiError(404, "no spectrum of run '" + run->id() + "' lies within the reference's times");
  nlohmann::json body = analysis::resolved_history_to_json(h);
  const analysis::ShellSpectrum latest = analysis::spectrum_at(ref, h.samples.back().time);
  body["reference"] = reference->filename().string();
  body["filter"] = filter;
  body["reference_spectrum"] = {
      {"t", latest.time}, {"k", latest.wavenumber}, {"energy", latest.energy}};
  return json_response(c.request, body);
}

/// The end of the run's run.log as text: the last `lines` lines (default 200, at most the
/// server's rows per answer), "" before the run has logged anything.
Response run_log(const Services& s, const Context& c) {
  constexpr std::uint64_t kDefaultLines = 200;
  const auto run = find_run(s, c.params[0]);
  const std::uint64_t max_rows = s.limits.max_rows;
  const std::uint64_t lines = query_unsigned(c, "lines", kDefaultLines);
  if (lines < 1 || lines > max_rows)
    throw ApiError(400,
                   "'lines' must be an integer in [1, " + std::to_string(max_rows) +
                       "] (the server's rows per answer)",
                   "lines");
  Response res =
      make_response(c.request, http::status::ok,
                    logging::tail_lines(run->directory() / "run.log",
                                        static_cast<std::size_t>(lines), s.limits.max_bytes),
                    "text/plain; charset=utf-8");
  res.set(http::field::cache_control, "no-store");
  return res;
}

Response spectrum(const Services& s, const Context& c) {
  return product(s, c, Product::spectrum, "spectrum");
}

Response statistics(const Services& s, const Context& c) {
  return product(s, c, Product::statistics, "sub-filter statistics");
}

}  // namespace sphles::server::handlers
