// SPDX-License-Identifier: GPL-3.0-or-later
#include "remote/endpoint.hpp"

#include <limits>
#include <stdexcept>
#include <utility>

#include "scene/document.hpp"

namespace sphles::remote {

namespace {

using Held = Endpoint::Held;

const sim::Scene& scene_of(Held& h, const std::string& json) {
  if (json != h.scene_json || h.scene_json.empty()) {
    h.scene = scene::parse_scene(nlohmann::json::parse(json));
    h.scene_json = json;
  }
  return h.scene;
}

/// Takes `fresh` as the solver (the new one first, then the old one goes) and asks once what it
/// can do beyond sim::Simulation.
void hold(Held& h, std::unique_ptr<sim::Simulation> fresh) {
  h.simulation = std::move(fresh);
  h.products = dynamic_cast<const analysis::DistributedProducts*>(h.simulation.get());
  h.checkpoints = dynamic_cast<const io::DistributedCheckpoints*>(h.simulation.get());
}

sim::Simulation& solver(const Held& h, const char* what) {
  if (!h.simulation) throw std::logic_error(std::string(what) + " before the solver was made");
  return *h.simulation;
}

SolverStatus status(const Held& h) {
  const sim::Simulation& s = *h.simulation;
  return {s.time(), s.step_count(), s.stable_time_step(), s.diagnostics()};
}

Reply on(Held&, Finish&) {
  return std::monostate{};
}

Reply on(Held& h, Make& r) {
  hold(h, h.solvers.make(scene_of(h, r.scene), std::move(r.particles)));
  return status(h);
}

Reply on(Held& h, SetUp& r) {
  if (!h.solvers.set_up) throw std::invalid_argument("the solvers here do not set up runs");
  sim::SetupOptions options;
  options.packing_cache_dir = r.packing_cache_dir;
  options.cancelled = r.cancelled;
  sim::PackingReport report;
  hold(h, h.solvers.set_up(scene_of(h, r.scene), options, report));
  return SetUpStatus{status(h), report};
}

Reply on(Held& h, Restore& r) {
  hold(h, h.solvers.restore(scene_of(h, r.scene), std::move(r.state)));
  return status(h);
}

Reply on(Held& h, RestoreFile& r) {
  if (!h.solvers.restore_file)
    throw std::invalid_argument("the solvers here do not read checkpoint files");
  hold(h, h.solvers.restore_file(scene_of(h, r.scene), r.file));
  return status(h);
}

Reply on(Held& h, Change& r) {
  sim::Simulation& current = solver(h, "a change");
  if (!h.solvers.change) throw std::invalid_argument("the solvers here do not change in place");
  hold(h, h.solvers.change(current, scene_of(h, r.scene)));
  return status(h);
}

Reply on(Held& h, Step& r) {
  solver(h, "a step").step(r.max_dt);
  return status(h);
}

Reply on(Held& h, State&) {
  return solver(h, "a state").state();
}

Reply on(Held& h, CaseDiagnostics& r) {
  return solver(h, "case diagnostics").case_diagnostics(scene_of(h, r.scene));
}

Reply on(Held& h, Spectrum& r) {
  solver(h, "a spectrum");
  if (!h.products || r.points_per_side < 2 ||
      r.points_per_side > static_cast<std::uint64_t>(std::numeric_limits<int>::max()))
    throw std::invalid_argument("the solver here does not compute a spectrum on " +
                                std::to_string(r.points_per_side) + " points per side");
  return h.products->velocity_spectrum(static_cast<int>(r.points_per_side));
}

Reply on(Held& h, ParticleProducts& r) {
  solver(h, "particle products");
  if (!h.products)
    throw std::invalid_argument("the solver here does not compute particle products");
  return h.products->particle_products(r.request);
}

Reply on(Held& h, WriteCheckpoint& r) {
  solver(h, "a checkpoint");
  if (!h.checkpoints || r.gzip_level > 9)
    throw std::invalid_argument("the solver here does not write checkpoints with gzip level " +
                                std::to_string(r.gzip_level));
  h.checkpoints->write_checkpoint(r.path, r.metadata,
                                  {.gzip_level = static_cast<int>(r.gzip_level)});
  return std::monostate{};
}

}  // namespace

Endpoint::Endpoint(sim::SolverFactories solvers) {
  held_.solvers = std::move(solvers);
}

Reply Endpoint::handle(Request request) {
  return std::visit([this](auto& r) { return on(held_, r); }, request);
}

}  // namespace sphles::remote
