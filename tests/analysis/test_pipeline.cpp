// SPDX-License-Identifier: GPL-3.0-or-later
// Solver → analysis hand-over (mailbox, pipeline), the analysis configuration, the products a
// scene asks for, the run-directory writer and the dissipation estimator.
#include <gtest/gtest.h>

#include <hdf5.h>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <numeric>
#include <random>

#include <cstdlib>
#include <regex>
#include <sstream>
#include <thread>

#include "analysis/config.hpp"
#include "analysis/mailbox.hpp"
#include "analysis/pipeline.hpp"
#include "analysis/products.hpp"
#include "analysis/timeseries.hpp"
#include "analysis/writer.hpp"
#include "scene/document.hpp"
#include "scratch_directory.hpp"
#include "sim/initial_conditions.hpp"
#include "sim/solver.hpp"

namespace sphles::analysis {
namespace {

using nlohmann::json;

TEST(Mailbox, KeepsNewestAndCountsDrops) {
  LatestValueMailbox<int> box;
  EXPECT_FALSE(box.publish(1));
  EXPECT_TRUE(box.publish(2));
  EXPECT_TRUE(box.publish(3));
  EXPECT_EQ(box.take(), 3);
  box.publish(4);
  box.close();
  EXPECT_EQ(box.take(), 4);  // delivered before closure is reported
  EXPECT_EQ(box.take(), std::nullopt);
  const MailboxCounters c = box.counters();
  EXPECT_EQ(c.published, 4u);
  EXPECT_EQ(c.taken, 2u);
  EXPECT_EQ(c.dropped, 2u);
}

// A consumer that needs 200 µs per value: appends what it takes from `box` to `received` until
// the box is closed.
std::thread slow_consumer(LatestValueMailbox<int>& box, std::vector<int>& received) {
  return std::thread([&box, &received] {
    while (auto v = box.take()) {
      received.push_back(*v);
      std::this_thread::sleep_for(std::chrono::microseconds(200));
    }
  });
}

// A producer thread and a consumer thread: every published value is either taken or dropped,
// values arrive in increasing order, and the producer never waits for the consumer's work.
TEST(Mailbox, ConcurrentProducerAndSlowConsumer) {
  LatestValueMailbox<int> box;
  std::vector<int> received;
  std::thread consumer = slow_consumer(box, received);
  const auto start = std::chrono::steady_clock::now();
  for (int k = 1; k <= 20000; ++k) box.publish(k);
  const double publish_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  box.close();
  consumer.join();
  const MailboxCounters c = box.counters();
  EXPECT_EQ(c.published, 20000u);
  EXPECT_EQ(c.taken + c.dropped, 20000u);
  EXPECT_EQ(c.taken, received.size());
  EXPECT_GT(c.dropped, 0u);
  EXPECT_EQ(received.back(), 20000);
  for (std::size_t k = 1; k < received.size(); ++k) EXPECT_LT(received[k - 1], received[k]);
  // 20000 publishes against a consumer that needs 200 µs per value: if publish waited for the
  // consumer this would take >= 4 s.
  EXPECT_LT(publish_seconds, 2.0);
}

// The lossless hand-over: a slow consumer gets every value, in order, and nothing is dropped.
TEST(Mailbox, PublishWaitingDeliversEveryValueToASlowConsumer) {
  LatestValueMailbox<int> box;
  std::vector<int> received;
  std::thread consumer = slow_consumer(box, received);
  constexpr int kValues = 500;
  for (int k = 1; k <= kValues; ++k) box.publish_waiting(k);
  box.close();
  consumer.join();
  const MailboxCounters c = box.counters();
  EXPECT_EQ(c.published, static_cast<std::uint64_t>(kValues));
  EXPECT_EQ(c.taken, static_cast<std::uint64_t>(kValues));
  EXPECT_EQ(c.dropped, 0u);
  ASSERT_EQ(received.size(), static_cast<std::size_t>(kValues));
  for (int k = 0; k < kValues; ++k) EXPECT_EQ(received[k], k + 1);
}

// A producer waiting for the slot is released by close(), not left hanging.
TEST(Mailbox, CloseReleasesAWaitingProducer) {
  LatestValueMailbox<int> box;
  box.publish(1);  // the slot is taken and nobody consumes
  std::thread producer([&] { box.publish_waiting(2); });
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  box.close();
  producer.join();  // a hang here is the failure
  EXPECT_EQ(box.take(), 2);
  EXPECT_EQ(box.counters().dropped, 1u);
}

// --- configuration ---------------------------------------------------------------------

TEST(AnalysisConfig, DefaultsComputeNothing) {
  const RunConfig c = parse_run_config(json::object());
  EXPECT_FALSE(c.analysis.enabled());
  EXPECT_EQ(c.scene.case_type, sim::CaseType::TaylorGreen3D);
}

TEST(AnalysisConfig, ParsesProductsAndRoundTrips) {
  const json doc = {{"case", "tgv2d"},
                    {"analysis",
                     {{"every", 0.25},
                      {"products", {"spectrum", "sfs_stats"}},
                      {"slice", {{"axis", "z"}, {"fields", {"tau_sfs"}}}},
                      {"histogram_bins", 20}}}};
  const RunConfig c = parse_run_config(doc);
  EXPECT_TRUE(c.analysis.enabled());
  EXPECT_TRUE(c.analysis.wants(Product::Spectrum));
  EXPECT_TRUE(c.analysis.wants(Product::SubfilterStatistics));
  EXPECT_FALSE(c.analysis.wants(Product::Slices));
  EXPECT_EQ(c.analysis.slice.axis, 2);
  EXPECT_EQ(c.analysis.slice.fields, std::set<SliceField>{SliceField::SubfilterStressNorm});
  const json written = run_config_to_json(c);
  EXPECT_EQ(run_config_to_json(parse_run_config(written)), written);
}

TEST(AnalysisConfig, ErrorsNameTheField) {
  const auto error_of = [](const json& analysis) -> std::string {
    try {
      parse_run_config({{"analysis", analysis}});
    } catch (const sim::SceneError& e) {
      return e.what();
    }
    return "";
  };
  EXPECT_NE(error_of({{"products", {"spectrum", "colour"}}, {"every", 1}})
                .find("'analysis.products[1]' must be one of energy, spectrum, vorticity, "
                      "slices, sfs_stats, particles, fields, got 'colour'"),
            std::string::npos);
  EXPECT_NE(error_of({{"products", {"spectrum"}}}).find("'analysis.every' must be > 0"),
            std::string::npos);
  EXPECT_NE(error_of({{"every", -1}}).find("'analysis.every' must be >= 0"), std::string::npos);
  EXPECT_NE(error_of({{"slice", {{"axis", "w"}}}}).find("'analysis.slice.axis' must be one of"),
            std::string::npos);
  EXPECT_NE(error_of({{"slice", {{"fields", {"pressure"}}}}}).find("'analysis.slice.fields[0]'"),
            std::string::npos);
  EXPECT_NE(error_of({{"cadence", 1}}).find("unknown key 'analysis.cadence'"), std::string::npos);
  EXPECT_NE(error_of(3).find("'analysis' must be an object"), std::string::npos);
  EXPECT_NE(error_of({{"every", 1}, {"products", {"slices"}}, {"slice", {{"fields", {"nu_t"}}}}})
                .find("asks for nu_t, but 'subfilter.model' is implicit"),
            std::string::npos);
}

// --- products ----------------------------------------------------------------------------

/// A Taylor-Green state on a packed lattice (a perfect lattice puts grid nodes exactly between
/// particles, where nearest-particle sampling has ties).
SnapshotPtr small_tgv_snapshot(const std::string& case_name, int per_side, double time = 0.0) {
  const json doc = {{"case", case_name},
                    {"particles_per_side", per_side},
                    {"kernel", {{"diameter_over_spacing", 6}}}};
  const sim::Scene scene = scene::parse_scene(doc);
  sim::RunSetup setup = sim::setup_run(
      scene, {.packing_cache_dir = std::filesystem::temp_directory_path() / "sphles_test_packing"});
  auto simulation = sim::make_simulation(setup.solver, std::move(setup.particles));
  while (simulation->time() < time) simulation->step(time - simulation->time());
  return make_snapshot(*simulation);
}

// A snapshot taken for a configuration holds the solver's neighbour list only for the
// "particle" vorticity estimate, its only reader; the products are the same either way.
TEST(Products, SnapshotsHoldTheSolversListOnlyForTheParticleEstimate) {
  const json doc = {{"case", "tgv2d"},
                    {"particles_per_side", 24},
                    {"kernel", {{"diameter_over_spacing", 6}}},
                    {"packing", {{"enabled", false}}}};
  sim::RunSetup setup = sim::setup_run(scene::parse_scene(doc));
  auto simulation = sim::make_simulation(setup.solver, std::move(setup.particles));
  simulation->step();
  AnalysisConfig config;
  config.every = 1.0;
  config.products = {Product::Vorticity, Product::SubfilterStatistics};
  ASSERT_EQ(config.gridding.vorticity, VorticityEstimate::Mls);
  const SnapshotPtr mls = make_snapshot(*simulation, config);
  EXPECT_FALSE(mls->neighbours);
  EXPECT_EQ(mls->size(), simulation->particles().size());
  AnalysisConfig particle = config;
  particle.gridding.vorticity = VorticityEstimate::Particle;
  const SnapshotPtr with_list = make_snapshot(*simulation, particle);
  ASSERT_TRUE(with_list->neighbours);
  EXPECT_EQ(with_list->neighbours.get(), simulation->neighbour_list().get());
  // The particle estimate from a snapshot without the list (a live change after it was taken)
  // builds its own: the same products but for the order of the neighbour sums (round-off).
  const AnalysisFrame own = analyse(*mls, particle);
  const AnalysisFrame shared = analyse(*with_list, particle);
  ASSERT_TRUE(own.vorticity && shared.vorticity && own.subfilter && shared.subfilter);
  EXPECT_GT(shared.vorticity->mean_vorticity_squared, 0.0);
  EXPECT_NEAR(own.vorticity->mean_vorticity_squared, shared.vorticity->mean_vorticity_squared,
              1e-12 * shared.vorticity->mean_vorticity_squared);
  EXPECT_EQ(own.subfilter->joint.total, shared.subfilter->joint.total);
}

/// `gathered` as make_snapshot takes it from a distributed run whose ranks serve every product:
/// no particles, no list, the ranks' products `values`.
SnapshotPtr without_particles(const Snapshot& gathered, RanksProducts values) {
  auto snapshot = std::make_shared<Snapshot>(gathered);
  snapshot->particles = sim::ParticleArrays{};
  snapshot->neighbours.reset();
  snapshot->has_particles = false;
  snapshot->ranks = std::move(values);
  return snapshot;
}

TEST(Products, OnlyRequestedProductsAreComputed) {
  const SnapshotPtr snapshot = small_tgv_snapshot("tgv3d", 16);
  AnalysisConfig config;
  config.every = 1.0;
  config.products = {Product::Spectrum};
  AnalysisFrame frame = analyse(*snapshot, config);
  EXPECT_TRUE(frame.spectrum);
  EXPECT_FALSE(frame.vorticity);
  EXPECT_FALSE(frame.subfilter);
  EXPECT_TRUE(frame.slices.empty());
  for (const auto& [stage, seconds] : frame.timings) {
    EXPECT_NE(stage, "vorticity");
    EXPECT_NE(stage, "subfilter_stress");
  }

  config.products = {Product::Slices};
  config.slice.fields = {SliceField::SubfilterStressNorm};
  frame = analyse(*snapshot, config);
  ASSERT_EQ(frame.slices.size(), 1u);
  EXPECT_EQ(frame.slices[0].field, SliceField::SubfilterStressNorm);
  bool computed_vorticity = false, computed_velocity = false;
  for (const auto& [stage, seconds] : frame.timings) {
    computed_vorticity |= stage == "vorticity";
    computed_velocity |= stage == "grid_velocity";
  }
  EXPECT_FALSE(computed_vorticity) << "a τ_SFS slice needs no vorticity";
  EXPECT_FALSE(computed_velocity) << "a τ_SFS slice needs no gridded velocity";
}

TEST(Products, TaylorGreen3DSpectrumSliceAndStatistics) {
  const SnapshotPtr snapshot = small_tgv_snapshot("tgv3d", 16);
  AnalysisConfig config;
  config.every = 1.0;
  config.products = {Product::Spectrum, Product::Vorticity, Product::Slices,
                     Product::SubfilterStatistics};
  const AnalysisFrame frame = analyse(*snapshot, config);
  ASSERT_TRUE(frame.spectrum);
  // The gridded field carries the particles' kinetic energy: each particle owns about 2^3 nodes.
  EXPECT_NEAR(frame.spectrum->kinetic_energy_grid, snapshot->kinetic_energy, 0.01 * 0.125);
  // The TGV mode (5.1) has |k|² = 3 (k = (±1, ±1, 0) with the cos z factor): the most energetic
  // shell is p = round(sqrt(3)) = 2.
  const auto& e = frame.spectrum->spectrum.energy;
  EXPECT_EQ(std::max_element(e.begin(), e.end()) - e.begin(), 2);
  EXPECT_DOUBLE_EQ(frame.spectrum->kernel_wavenumber, 2.0 * M_PI / (6.0 * 2.0 * M_PI / 16));
  EXPECT_DOUBLE_EQ(frame.spectrum->resolution_wavenumber, 16.0 / 2.0);
  // Slices at x = π: 32 x 32 on a grid of spacing Δl/2; normal x, in-plane y and z.
  ASSERT_EQ(frame.slices.size(), 2u);
  for (const SliceProduct& s : frame.slices) {
    EXPECT_EQ(s.width, 32);
    EXPECT_EQ(s.height, 32);
    EXPECT_EQ(s.normal_axis, 0);
    EXPECT_EQ(s.axis_u, 1);
    EXPECT_EQ(s.axis_v, 2);
    EXPECT_NEAR(s.position, M_PI, 1e-12);
    for (const double v : s.values) EXPECT_GE(v, 0.0);
  }
  ASSERT_TRUE(frame.subfilter);
  EXPECT_EQ(frame.subfilter->joint.total, snapshot->size());
  EXPECT_FALSE(frame.subfilter->alignment) << "the polar histogram is a 2D statistic";
  ASSERT_TRUE(frame.vorticity);
  EXPECT_FALSE(frame.grid_kinetic_energy) << "energy was not requested";
  config.products = {Product::Energy};
  const AnalysisFrame energy_only = analyse(*snapshot, config);
  ASSERT_TRUE(energy_only.grid_kinetic_energy);
  EXPECT_NEAR(*energy_only.grid_kinetic_energy, frame.spectrum->kinetic_energy_grid, 1e-15);
  EXPECT_FALSE(energy_only.spectrum);
  EXPECT_NEAR(frame.vorticity->dissipation,
              snapshot->fluid.kinematic_viscosity() * frame.vorticity->mean_vorticity_squared,
              1e-18);
}

/// A snapshot whose spectrum the ranks computed (Snapshot::velocity_spectrum, make_snapshot of
/// a distributed solver): energy and spectrum come from it and match what the particles give
/// (here the same spectrum computed from them); without particles (nothing gathered), the
/// products that need particles are left out of that frame instead of failing.
TEST(Products, SpectrumComputedOnTheRanksServesEnergyAndSpectrum) {
  const SnapshotPtr gathered = small_tgv_snapshot("tgv3d", 16);
  AnalysisConfig config;
  config.every = 1.0;
  config.products = {Product::Energy, Product::Spectrum};
  const AnalysisFrame whole = analyse(*gathered, config);
  ASSERT_TRUE(whole.spectrum && whole.grid_kinetic_energy);

  auto ranks = std::make_shared<Snapshot>(*gathered);
  ranks->particles = sim::ParticleArrays{};
  ranks->neighbours.reset();
  ranks->has_particles = false;
  ranks->velocity_spectrum = whole.spectrum->spectrum;
  config.products.insert(Product::Vorticity);
  config.products.insert(Product::SubfilterStatistics);
  const AnalysisFrame frame = analyse(*ranks, config);
  ASSERT_TRUE(frame.spectrum && frame.grid_kinetic_energy);
  EXPECT_EQ(frame.spectrum->spectrum.energy, whole.spectrum->spectrum.energy);
  EXPECT_EQ(frame.spectrum->dissipation, whole.spectrum->dissipation);
  EXPECT_EQ(frame.spectrum->dissipation_resolved, whole.spectrum->dissipation_resolved);
  // ½⟨|u'|²⟩ by Parseval from the shells against the sum over the nodes.
  EXPECT_NEAR(*frame.grid_kinetic_energy, *whole.grid_kinetic_energy,
              1e-13 * *whole.grid_kinetic_energy);
  EXPECT_FALSE(frame.vorticity);
  EXPECT_FALSE(frame.subfilter);
  double stages = 0.0;
  for (const auto& [stage, seconds] : frame.timings) stages += seconds;
  EXPECT_GE(frame.total_seconds, stages) << "the total covers the stages it timed";
  for (const auto& [stage, seconds] : frame.timings) {
    EXPECT_NE(stage, "grid_velocity") << "the spectrum was computed on the ranks";
    EXPECT_NE(stage, "grid_map");
  }

  // With particles (another product needed them) the same spectrum and the other products.
  auto both = std::make_shared<Snapshot>(*gathered);
  both->velocity_spectrum = whole.spectrum->spectrum;
  const AnalysisFrame full = analyse(*both, config);
  ASSERT_TRUE(full.spectrum && full.vorticity && full.subfilter);
  EXPECT_EQ(full.spectrum->spectrum.energy, whole.spectrum->spectrum.energy);
}

/// A snapshot carrying the particle products from the ranks (Snapshot::ranks): the vorticity
/// product, both slices and sfs_stats are those values, with or without particles; a request
/// that no longer matches the configuration (a live change moved the slice) is not used:
/// without particles those products are left out, with particles they are computed from them.
TEST(Products, ParticleProductsComputedOnTheRanksServeTheirProducts) {
  const SnapshotPtr gathered = small_tgv_snapshot("tgv2d", 32, 0.2);
  AnalysisConfig config;
  config.every = 1.0;
  config.products = {Product::Vorticity, Product::Slices, Product::SubfilterStatistics};
  ASSERT_EQ(config.gridding.vorticity, VorticityEstimate::Mls);
  for (const Product p : config.products) EXPECT_TRUE(served_by_ranks(config, p));
  const AnalysisFrame whole = analyse(*gathered, config);
  ASSERT_TRUE(whole.vorticity && whole.subfilter && whole.subfilter->alignment);
  ASSERT_EQ(whole.slices.size(), 2u);

  // Values unlike the particles' own, so that the test sees where the frame took them from.
  RanksProducts ranks_values;
  ranks_values.request = ranks_request(*gathered, config);
  ranks_values.mean_vorticity_squared = 2.0 * whole.vorticity->mean_vorticity_squared;
  ranks_values.slice_omega2 = whole.slices[0].values;
  for (double& v : ranks_values.slice_omega2) v += 1.0;
  ranks_values.slice_tau = whole.slices[1].values;
  for (double& v : ranks_values.slice_tau) v += 2.0;
  ranks_values.statistics = *whole.subfilter;
  ranks_values.statistics->max_norm += 1.0;

  const SnapshotPtr ranks = without_particles(*gathered, ranks_values);
  const AnalysisFrame frame = analyse(*ranks, config);
  ASSERT_TRUE(frame.vorticity && frame.subfilter);
  EXPECT_EQ(frame.vorticity->mean_vorticity_squared, ranks_values.mean_vorticity_squared);
  EXPECT_EQ(frame.vorticity->dissipation,
            gathered->fluid.kinematic_viscosity() * ranks_values.mean_vorticity_squared);
  EXPECT_EQ(frame.vorticity->estimate, VorticityEstimate::Mls);
  EXPECT_EQ(frame.subfilter->max_norm, ranks_values.statistics->max_norm);
  EXPECT_EQ(frame.subfilter->joint.counts, whole.subfilter->joint.counts);
  ASSERT_EQ(frame.slices.size(), 2u);
  EXPECT_EQ(frame.slices[0].field, SliceField::VorticitySquared);
  EXPECT_EQ(frame.slices[0].values, ranks_values.slice_omega2);
  EXPECT_EQ(frame.slices[1].field, SliceField::SubfilterStressNorm);
  EXPECT_EQ(frame.slices[1].values, ranks_values.slice_tau);
  EXPECT_EQ(frame.slices[1].units, whole.slices[1].units);
  EXPECT_EQ(frame.slices[0].width, whole.slices[0].width);
  for (const auto& [stage, seconds] : frame.timings) {
    EXPECT_NE(stage, "particle_vorticity") << "computed on the ranks";
    EXPECT_NE(stage, "subfilter_stress") << "computed on the ranks";
  }

  // The configuration changed since the snapshot: without particles nothing of it is used.
  AnalysisConfig moved = config;
  moved.histogram_bins = 10;
  const AnalysisFrame stale = analyse(*ranks, moved);
  EXPECT_FALSE(stale.vorticity || stale.subfilter);
  EXPECT_TRUE(stale.slices.empty());
  // With particles the products come from them.
  auto both = std::make_shared<Snapshot>(*gathered);
  both->ranks = ranks_values;
  const AnalysisFrame mixed = analyse(*both, moved);
  ASSERT_TRUE(mixed.vorticity && mixed.subfilter);
  EXPECT_EQ(mixed.vorticity->mean_vorticity_squared, whole.vorticity->mean_vorticity_squared);
  EXPECT_EQ(mixed.slices[0].values, whole.slices[0].values);

  // Other estimates are not served by the ranks, but for the nearest-particle slices (|τ_SFS|,
  // ν_t), which every estimate shares.
  AnalysisConfig particle = config;
  particle.gridding.vorticity = VorticityEstimate::Particle;
  EXPECT_FALSE(served_by_ranks(particle, Product::Vorticity));
  EXPECT_FALSE(served_by_ranks(particle, Product::SubfilterStatistics));
  EXPECT_FALSE(served_by_ranks(particle, Product::Slices));  // ω² among the fields
  particle.slice.fields = {SliceField::SubfilterStressNorm, SliceField::EddyViscosity};
  EXPECT_TRUE(served_by_ranks(particle, Product::Slices));
  AnalysisConfig eddy = config;
  eddy.slice.fields.insert(SliceField::EddyViscosity);
  EXPECT_TRUE(served_by_ranks(eddy, Product::Slices));
  EXPECT_FALSE(served_by_ranks(config, Product::Particles));  // with no directory to write to
}

// The grid fields the ranks computed (RanksProducts::fields_*) make the product "fields" when
// the ranks serve it: the velocity gridded by nearest particle, ω² of the "mls" estimate.
TEST(Products, GridFieldsComputedOnTheRanksServeTheProduct) {
  const SnapshotPtr gathered = small_tgv_snapshot("tgv2d", 32, 0.2);
  AnalysisConfig config;
  config.every = 1.0;
  config.products = {Product::Energy, Product::Fields};
  config.grid_fields = {SliceField::VorticitySquared, SliceField::SubfilterStressNorm};
  EXPECT_TRUE(served_by_ranks(config, Product::Fields));
  AnalysisConfig shepard = config;
  shepard.gridding.velocity = VelocityGridding::Shepard;
  EXPECT_FALSE(served_by_ranks(shepard, Product::Fields));
  shepard.grid_velocity = false;
  EXPECT_TRUE(served_by_ranks(shepard, Product::Fields));
  AnalysisConfig grid_estimate = config;
  grid_estimate.gridding.vorticity = VorticityEstimate::Grid;
  EXPECT_FALSE(served_by_ranks(grid_estimate, Product::Fields));
  grid_estimate.grid_fields = {SliceField::SubfilterStressNorm};
  EXPECT_TRUE(served_by_ranks(grid_estimate, Product::Fields));

  const AnalysisFrame whole = analyse(*gathered, config);
  ASSERT_TRUE(whole.fields && whole.fields->velocity);
  ASSERT_EQ(whole.fields->scalars.size(), 2u);
  const RanksRequest request = ranks_request(*gathered, config);
  EXPECT_TRUE(request.fields.velocity && request.fields.omega2 && request.fields.tau &&
              !request.fields.eddy);
  // Values unlike the particles' own, so that the test sees where the frame took them from.
  RanksProducts values;
  values.request = request;
  for (int a = 0; a < 2; ++a) {
    values.fields_velocity[static_cast<std::size_t>(a)] =
        whole.fields->velocity->component[static_cast<std::size_t>(a)];
    for (double& v : values.fields_velocity[static_cast<std::size_t>(a)]) v += 1.0;
  }
  values.fields_omega2 = whole.fields->scalars[0].values;
  for (double& v : values.fields_omega2) v *= 2.0;
  values.fields_tau = whole.fields->scalars[1].values;
  for (double& v : values.fields_tau) v *= 3.0;
  const SnapshotPtr ranks = without_particles(*gathered, values);
  const AnalysisFrame frame = analyse(*ranks, config);
  ASSERT_TRUE(frame.fields && frame.fields->velocity);
  EXPECT_EQ(frame.fields->grid.points_per_side, whole.fields->grid.points_per_side);
  EXPECT_EQ(frame.fields->velocity->component[0], values.fields_velocity[0]);
  EXPECT_EQ(frame.fields->velocity->component[1], values.fields_velocity[1]);
  EXPECT_TRUE(frame.fields->velocity->component[2].empty());  // 2D, as analyse's own
  ASSERT_EQ(frame.fields->scalars.size(), 2u);
  EXPECT_EQ(frame.fields->scalars[0].field, SliceField::VorticitySquared);
  EXPECT_EQ(frame.fields->scalars[0].values, values.fields_omega2);
  EXPECT_EQ(frame.fields->scalars[1].values, values.fields_tau);
  EXPECT_EQ(frame.fields->scalars[1].units, whole.fields->scalars[1].units);
  for (const auto& [stage, seconds] : frame.timings) {
    EXPECT_NE(stage, "vorticity") << "computed on the ranks";
    EXPECT_NE(stage, "grid_map") << "computed on the ranks";
  }
}

// A distributed run's ranks write the product "particles" themselves (make_snapshot, with the
// writer's target): the frame names their file and the writer indexes it without writing it.
TEST(Products, AParticleFileTheRanksWroteIsIndexedNotWritten) {
  const SnapshotPtr gathered = small_tgv_snapshot("tgv2d", 32, 0.2);
  AnalysisConfig config;
  config.every = 1.0;
  config.products = {Product::Energy, Product::Particles};
  config.particle_fields = {SliceField::VorticitySquared, SliceField::SubfilterStressNorm};
  EXPECT_TRUE(served_by_ranks(config, Product::Particles, true));
  EXPECT_FALSE(served_by_ranks(config, Product::Particles, false));  // no directory to write to
  AnalysisConfig particle = config;
  particle.gridding.vorticity = VorticityEstimate::Particle;
  EXPECT_FALSE(served_by_ranks(particle, Product::Particles, true));  // ω² of another estimate
  particle.particle_fields = {SliceField::SubfilterStressNorm};
  EXPECT_TRUE(served_by_ranks(particle, Product::Particles, true));

  const std::filesystem::path dir = scratch::scratch_directory("pipeline", "ranks_particles");
  const ParticleFileTarget target{dir / "snapshots", {"{}", "test"}};
  const RanksRequest request = ranks_request(*gathered, config, &target);
  EXPECT_EQ(request.particles.path,
            (dir / "snapshots" / timed_file_name("particles", gathered->time, ".h5")).string());
  EXPECT_TRUE(request.particles.omega2 && request.particles.tau && !request.particles.eddy);
  EXPECT_EQ(request.particles.time, gathered->time);
  EXPECT_EQ(request.particles.metadata, target.metadata);
  EXPECT_TRUE(ranks_request(*gathered, config).particles.path.empty());  // no target, no file

  RanksProducts values;
  values.request = request;
  values.particles = WrittenParticles{
      gathered->size(), {SliceField::VorticitySquared, SliceField::SubfilterStressNorm}};
  const SnapshotPtr ranks = without_particles(*gathered, values);
  const AnalysisFrame frame = analyse(ranks, config);
  ASSERT_TRUE(frame.particles);
  EXPECT_EQ(frame.particles->file, request.particles.path);
  EXPECT_EQ(frame.particles->count, gathered->size());
  ASSERT_EQ(frame.particles->fields.size(), 2u);
  EXPECT_EQ(frame.particles->fields[1].field, SliceField::SubfilterStressNorm);
  EXPECT_EQ(frame.particles->fields[1].units, "Pa");
  EXPECT_TRUE(frame.particles->fields[1].values.empty());
  for (const auto& [stage, seconds] : frame.timings) EXPECT_NE(stage, "subfilter_stress");

  // The writer lists the file in index.csv and the XDMF series and writes no file of its own.
  RunDirectoryWriter writer(dir);
  writer.write(frame);
  EXPECT_EQ(writer.last_error(), "");
  const std::string name = std::filesystem::path(request.particles.path).filename().string();
  EXPECT_FALSE(std::filesystem::exists(dir / "snapshots" / name));
  const auto rows = read_index(dir / "snapshots" / "index.csv");
  ASSERT_EQ(rows.size(), 1u);
  EXPECT_EQ(rows[0].at("file"), name);
  EXPECT_EQ(rows[0].at("particles"), std::to_string(gathered->size()));
  EXPECT_EQ(rows[0].at("fields"), "omega2;tau_sfs");
  std::ifstream xdmf(dir / "snapshots" / "particles.xdmf");
  const std::string series((std::istreambuf_iterator<char>(xdmf)), {});
  EXPECT_NE(series.find(name + ":/tau_sfs"), std::string::npos) << series;

  // A live change that stopped asking for particles after the snapshot: the file is on disk
  // and still indexed.
  AnalysisConfig energy = config;
  energy.products = {Product::Energy};
  const AnalysisFrame later = analyse(ranks, energy);
  ASSERT_TRUE(later.particles);
  EXPECT_EQ(later.particles->file, request.particles.path);
}

TEST(Products, ViewStrideLeavesAtMostTheMaximum) {
  EXPECT_EQ(view_stride(100, 1000), 1u);
  EXPECT_EQ(view_stride(1000, 1000), 1u);
  EXPECT_EQ(view_stride(1001, 1000), 2u);
  EXPECT_EQ(view_stride(3000, 1000), 3u);
  EXPECT_EQ(view_stride(3001, 1000), 4u);
  EXPECT_EQ(view_stride(134217728, 1000000), 135u);  // 512³: 994 225 points
  EXPECT_EQ(view_stride(5, 0), 1u);
  for (const std::uint64_t total : {999ULL, 12345ULL, 884736ULL, 134217728ULL})
    for (const std::uint64_t max : {1000ULL, 4096ULL, 1000000ULL}) {
      const std::uint64_t k = view_stride(total, max);
      EXPECT_LE((total + k - 1) / k, max) << total << " " << max;  // ids 0, k, 2k, ...
      if (k > 1) {                                                 // the smallest such stride
        EXPECT_GT((total + k - 2) / (k - 1), max) << total << " " << max;
      }
    }
}

// The 3D particle view's points: every k-th particle by id, in id order, with the values of
// the field at those particles, whatever order the snapshot holds them in; from the ranks
// they are passed on as they came.
TEST(Products, ViewPointsAreEveryKthParticleByIdInIdOrder) {
  const SnapshotPtr packed = small_tgv_snapshot("tgv3d", 16);
  auto shuffled = std::make_shared<Snapshot>(*packed);
  sim::ParticleArrays& p = shuffled->particles;
  std::vector<std::uint32_t> order(p.size());
  std::iota(order.begin(), order.end(), 0u);
  std::shuffle(order.begin(), order.end(), std::mt19937(7));
  p.reorder(order);
  AnalysisConfig config;
  config.every = 1.0;
  config.products = {Product::Particles};
  config.particle_fields = {SliceField::VorticitySquared, SliceField::SubfilterStressNorm};
  shuffled->view = {1000, SliceField::SubfilterStressNorm};  // 4096 particles: every 5th
  const AnalysisFrame frame = analyse(shuffled, config);
  ASSERT_TRUE(frame.particles && frame.particles->view);
  const ViewPoints& view = *frame.particles->view;
  EXPECT_EQ(view.stride, 5u);
  EXPECT_EQ(view.field, SliceField::SubfilterStressNorm);
  ASSERT_EQ(view.size(), 820u);  // ids 0, 5, ..., 4095
  std::vector<std::size_t> at(p.size());
  for (std::size_t i = 0; i < p.size(); ++i) at[p.id[i]] = i;
  const std::vector<double>& tau = frame.particles->fields[1].values;
  for (std::size_t k = 0; k < view.size(); ++k) {
    const std::size_t i = at[5 * k];
    for (std::size_t a = 0; a < 3; ++a) ASSERT_EQ(view.position[a][k], p.position[a][i]) << k;
    ASSERT_EQ(view.values[k], tau[i]) << k;
  }
  // Below the maximum: every particle; not asked for, or a field the analysis lacks: none.
  shuffled->view = {10000, SliceField::VorticitySquared};
  const AnalysisFrame all = analyse(shuffled, config);
  ASSERT_TRUE(all.particles && all.particles->view);
  EXPECT_EQ(all.particles->view->size(), p.size());
  EXPECT_EQ(all.particles->view->values[0], all.particles->fields[0].values[at[0]]);
  shuffled->view = {};
  EXPECT_FALSE(analyse(shuffled, config).particles->view);
  shuffled->view = {1000, SliceField::EddyViscosity};
  EXPECT_FALSE(analyse(shuffled, config).particles->view);

  // The request carries the view with the product "particles" and its field.
  shuffled->view = {1000, SliceField::SubfilterStressNorm};
  EXPECT_EQ(ranks_request(*shuffled, config).view, shuffled->view);
  AnalysisConfig omega_only = config;
  omega_only.particle_fields = {SliceField::VorticitySquared};
  EXPECT_EQ(ranks_request(*shuffled, omega_only).view, ViewPointsRequest{});
  RanksProducts values;
  values.request = ranks_request(*shuffled, config);
  values.particles = WrittenParticles{p.size(), {SliceField::SubfilterStressNorm}};
  values.view = view;
  const AnalysisFrame ranks = analyse(without_particles(*shuffled, values), config);
  ASSERT_TRUE(ranks.particles && ranks.particles->view);
  EXPECT_EQ(*ranks.particles->view, view);
}

TEST(Products, TwoDimensionalRunHasWholeFieldSliceAndAlignment) {
  const SnapshotPtr snapshot = small_tgv_snapshot("tgv2d", 32, 0.2);
  AnalysisConfig config;
  config.every = 1.0;
  config.products = {Product::Slices, Product::SubfilterStatistics};
  const AnalysisFrame frame = analyse(*snapshot, config);
  ASSERT_EQ(frame.slices.size(), 2u);
  EXPECT_EQ(frame.slices[0].width, 64);
  EXPECT_EQ(frame.slices[0].normal_axis, 2);
  ASSERT_TRUE(frame.subfilter && frame.subfilter->alignment);
  std::uint64_t sum = 0;
  for (const auto c : frame.subfilter->alignment->counts) sum += c;
  EXPECT_EQ(sum, frame.subfilter->alignment->total);
  EXPECT_GT(sum, 0u);
}

TEST(Products, EddyViscositySliceOfAnExplicitModel) {
  const json doc = {{"case", "tgv3d"},
                    {"particles_per_side", 12},
                    {"kernel", {{"diameter_over_spacing", 6}}},
                    {"subfilter", {{"model", "smag"}}},
                    {"packing", {{"enabled", false}}}};
  const sim::Scene scene = scene::parse_scene(doc);
  sim::RunSetup setup = sim::setup_run(scene);
  auto simulation = sim::make_simulation(setup.solver, std::move(setup.particles));
  simulation->step();
  const SnapshotPtr snapshot = make_snapshot(*simulation);
  ASSERT_EQ(snapshot->particles.eddy_viscosity.size(), snapshot->size());
  AnalysisConfig config;
  config.every = 1.0;
  config.products = {Product::Slices};
  config.slice.fields = {SliceField::EddyViscosity};
  const AnalysisFrame frame = analyse(*snapshot, config);
  ASSERT_EQ(frame.slices.size(), 1u);
  EXPECT_EQ(frame.slices[0].units, "m^2/s");
  const auto& nu = snapshot->particles.eddy_viscosity;
  const double max_nu = *std::max_element(nu.begin(), nu.end());
  EXPECT_GT(max_nu, 0.0);
  for (const double v : frame.slices[0].values) {
    EXPECT_GE(v, 0.0);
    EXPECT_LE(v, max_nu);
  }
}

// --- pipeline ----------------------------------------------------------------------------

// A deliberately slow consumer does not change the solver's result: the run with analysis
// (snapshots every step, a sink that sleeps) ends in the bitwise-same state as the run without,
// and the pipeline drops snapshots instead of holding the solver.
TEST(Pipeline, SlowConsumerDropsSnapshotsAndLeavesSolverUntouched) {
  const json doc = {{"case", "tgv2d"},
                    {"particles_per_side", 32},
                    {"kernel", {{"diameter_over_spacing", 6}}},
                    {"packing", {{"enabled", false}}}};
  const sim::Scene scene = scene::parse_scene(doc);
  const auto run = [&](AnalysisPipeline* pipeline) {
    sim::RunSetup setup = sim::setup_run(scene);
    auto simulation = sim::make_simulation(setup.solver, std::move(setup.particles));
    for (int step = 0; step < 60; ++step) {
      simulation->step();
      if (pipeline) pipeline->publish(make_snapshot(*simulation));
    }
    return simulation->particles();
  };
  const sim::ParticleArrays reference = run(nullptr);

  AnalysisConfig config;
  config.every = 1.0;
  config.products = {Product::Spectrum, Product::SubfilterStatistics};
  std::atomic<int> frames{0};
  std::vector<double> times;
  AnalysisPipeline pipeline(config, {[&](const AnalysisFrame& frame) {
                              std::this_thread::sleep_for(std::chrono::milliseconds(30));
                              times.push_back(frame.time);
                              ++frames;
                            }},
                            1, Delivery::LatestOnly);
  const sim::ParticleArrays with_analysis = run(&pipeline);
  pipeline.close(/*drain=*/true);
  EXPECT_TRUE(pipeline.error().empty()) << pipeline.error();
  const PipelineCounters c = pipeline.counters();
  EXPECT_EQ(c.published, 60u);
  EXPECT_EQ(c.analysed + c.dropped, 60u);
  EXPECT_GT(c.dropped, 0u);
  EXPECT_EQ(c.analysed, static_cast<std::uint64_t>(frames.load()));
  for (std::size_t k = 1; k < times.size(); ++k) EXPECT_LT(times[k - 1], times[k]);
  for (int d = 0; d < 2; ++d) {
    EXPECT_EQ(std::memcmp(reference.position[d].data(), with_analysis.position[d].data(),
                          reference.size() * sizeof(double)),
              0);
    EXPECT_EQ(std::memcmp(reference.velocity[d].data(), with_analysis.velocity[d].data(),
                          reference.size() * sizeof(double)),
              0);
  }
}

// Lossless delivery (the default, what saved outputs need): the same slow consumer analyses
// every snapshot, in order, none dropped, and the solver's result is still bitwise the same.
TEST(Pipeline, LosslessDeliveryAnalysesEverySnapshotOfASlowConsumer) {
  const json doc = {{"case", "tgv2d"},
                    {"particles_per_side", 32},
                    {"kernel", {{"diameter_over_spacing", 6}}},
                    {"packing", {{"enabled", false}}}};
  const sim::Scene scene = scene::parse_scene(doc);
  AnalysisConfig config;
  config.every = 1.0;
  config.products = {Product::Spectrum};
  std::vector<double> times;
  constexpr int kSteps = 20;
  sim::ParticleArrays with_analysis, reference;
  for (const bool analyse : {false, true}) {
    AnalysisPipeline pipeline(config, {[&](const AnalysisFrame& frame) {
                                std::this_thread::sleep_for(std::chrono::milliseconds(30));
                                times.push_back(frame.time);
                              }});
    sim::RunSetup setup = sim::setup_run(scene);
    auto simulation = sim::make_simulation(setup.solver, std::move(setup.particles));
    for (int step = 0; step < kSteps; ++step) {
      simulation->step();
      if (analyse) pipeline.publish(make_snapshot(*simulation));
    }
    pipeline.close(/*drain=*/true);
    EXPECT_TRUE(pipeline.error().empty()) << pipeline.error();
    const PipelineCounters c = pipeline.counters();
    EXPECT_EQ(c.published, analyse ? kSteps : 0u);
    EXPECT_EQ(c.analysed, c.published);
    EXPECT_EQ(c.dropped, 0u);
    (analyse ? with_analysis : reference) = simulation->particles();
  }
  ASSERT_EQ(times.size(), static_cast<std::size_t>(kSteps));
  for (std::size_t k = 1; k < times.size(); ++k) EXPECT_LT(times[k - 1], times[k]);
  for (int d = 0; d < 2; ++d)
    EXPECT_EQ(std::memcmp(reference.velocity[d].data(), with_analysis.velocity[d].data(),
                          reference.size() * sizeof(double)),
              0);
}

TEST(Pipeline, CloseWithoutDrainDiscardsAndDestructorJoins) {
  AnalysisConfig config;
  config.every = 1.0;
  config.products = {Product::Spectrum};
  std::atomic<int> frames{0};
  {
    AnalysisPipeline pipeline(config, {[&](const AnalysisFrame&) {
                                std::this_thread::sleep_for(std::chrono::milliseconds(50));
                                ++frames;
                              }});
    const SnapshotPtr snapshot = small_tgv_snapshot("tgv2d", 16);
    for (int k = 0; k < 5; ++k) pipeline.publish(snapshot);
    pipeline.close(/*drain=*/false);
    const PipelineCounters c = pipeline.counters();
    EXPECT_EQ(c.analysed + c.dropped, 5u);
  }
  EXPECT_LE(frames.load(), 5);
}

TEST(Pipeline, AnalysisErrorsAreReportedNotThrownAcrossThreads) {
  AnalysisConfig config;
  config.every = 1.0;
  config.products = {Product::Spectrum};
  AnalysisPipeline pipeline(config, {[](const AnalysisFrame&) {}});
  auto broken = std::make_shared<Snapshot>(*small_tgv_snapshot("tgv2d", 16));
  broken->particles.position[0].clear();  // inconsistent arrays
  broken->particles.velocity[0].clear();
  pipeline.publish(broken);
  pipeline.close(true);
  // Either analysis rejected the snapshot with a message or produced a frame; it never crashed.
  const PipelineCounters c = pipeline.counters();
  EXPECT_EQ(c.analysed, 1u);
}

// --- writer and history ------------------------------------------------------------------

class WriterTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() / ("sphles_writer_" + std::to_string(::getpid()));
    std::filesystem::remove_all(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::filesystem::path dir_;
};

TEST_F(WriterTest, NpyHasNumpyHeaderAndExactData) {
  std::filesystem::create_directories(dir_);
  const std::vector<double> values{1.0, -2.5, 3.25, 1e-300, 0.0, 7.0};
  write_npy(dir_ / "a.npy", values, 2, 3);
  std::ifstream in(dir_ / "a.npy", std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  ASSERT_GE(bytes.size(), 10u);
  EXPECT_EQ(bytes.substr(0, 8), std::string("\x93NUMPY\x01\x00", 8));
  const std::size_t header_length =
      static_cast<unsigned char>(bytes[8]) + 256u * static_cast<unsigned char>(bytes[9]);
  EXPECT_EQ((10 + header_length) % 64, 0u);
  const std::string header = bytes.substr(10, header_length);
  EXPECT_NE(header.find("'descr': '<f8'"), std::string::npos);
  EXPECT_NE(header.find("'shape': (2, 3)"), std::string::npos);
  EXPECT_EQ(header.back(), '\n');
  ASSERT_EQ(bytes.size(), 10 + header_length + values.size() * sizeof(double));
  EXPECT_EQ(
      std::memcmp(bytes.data() + 10 + header_length, values.data(), values.size() * sizeof(double)),
      0);
  EXPECT_THROW(write_npy(dir_ / "b.npy", values, 4, 4), std::invalid_argument);
}

TEST_F(WriterTest, WritesEveryRequestedProduct) {
  const SnapshotPtr snapshot = small_tgv_snapshot("tgv2d", 24, 0.1);
  AnalysisConfig config;
  config.every = 1.0;
  config.products = {Product::Spectrum, Product::Vorticity, Product::Slices,
                     Product::SubfilterStatistics};
  const AnalysisFrame frame = analyse(*snapshot, config);
  RunDirectoryWriter writer(dir_);
  writer.write(frame);
  EXPECT_EQ(writer.last_error(), "");
  const std::string t = "_t0.1000";
  for (const std::string& file : std::vector<std::string>{
           "spectra/E" + t + ".csv", "spectra/index.csv", "slices/omega2" + t + ".npy",
           "slices/tau_sfs" + t + ".npy", "slices/index.csv", "stats/snapshots.csv",
           "stats/joint_tau_omega2" + t + ".csv", "stats/alignment" + t + ".csv"})
    EXPECT_TRUE(std::filesystem::exists(dir_ / file)) << file;
  std::ifstream spectrum(dir_ / ("spectra/E" + t + ".csv"));
  std::string header;
  std::getline(spectrum, header);
  EXPECT_EQ(header, "k,E,k_Lc,E_over_ev_Lc");
  // Histogram file counts add up to the particle count.
  std::ifstream joint(dir_ / ("stats/joint_tau_omega2" + t + ".csv"));
  std::getline(joint, header);
  EXPECT_EQ(header, "tau_lo,tau_hi,omega2_lo,omega2_hi,count");
  std::uint64_t total = 0;
  for (std::string line; std::getline(joint, line);)
    total += std::stoull(line.substr(line.rfind(',') + 1));
  EXPECT_EQ(total, snapshot->size());
  // No temporary file is left behind.
  for (const auto& entry : std::filesystem::recursive_directory_iterator(dir_))
    EXPECT_NE(entry.path().extension(), ".tmp") << entry.path();
}

// stats/snapshots.csv keeps its earlier columns and appends the other two dissipation estimates
// of SPEC §5: -de_v/dt (carried by the snapshot from the time series) and the resolved spectral
// sum, next to ν⟨ω²⟩.
TEST_F(WriterTest, SnapshotStatisticsCarryTheDissipationThreeWays) {
  auto snapshot = std::make_shared<Snapshot>(*small_tgv_snapshot("tgv2d", 24, 0.1));
  snapshot->energy_dissipation = 0.0123;
  AnalysisConfig config;
  config.every = 1.0;
  config.products = {Product::Spectrum, Product::Vorticity};
  const AnalysisFrame frame = analyse(SnapshotPtr(snapshot), config);
  ASSERT_TRUE(frame.spectrum && frame.vorticity);
  EXPECT_EQ(frame.energy_dissipation, 0.0123);
  RunDirectoryWriter writer(dir_);
  writer.write(frame);
  EXPECT_EQ(writer.last_error(), "");
  std::ifstream in(dir_ / "stats" / "snapshots.csv");
  std::string header, row;
  std::getline(in, header);
  std::getline(in, row);
  EXPECT_EQ(header,
            "t,step,e_v,e_v_grid,mean_omega2,dissipation_vorticity,dissipation_spectral,"
            "tau_sfs_max,tau_sfs_mean,analysis_seconds,dropped_snapshots,"
            "dissipation_spectral_resolved,dissipation_energy");
  const auto split = [](const std::string& line) {
    std::vector<std::string> parts;
    std::stringstream stream(line);
    for (std::string part; std::getline(stream, part, ',');) parts.push_back(part);
    return parts;
  };
  const std::vector<std::string> names = split(header), cells = split(row);
  ASSERT_EQ(cells.size(), names.size()) << row;
  const auto column = [&](const std::string& name) {
    const auto it = std::find(names.begin(), names.end(), name);
    return std::stod(cells[static_cast<std::size_t>(it - names.begin())]);
  };
  EXPECT_EQ(column("dissipation_energy"), 0.0123);
  EXPECT_EQ(column("dissipation_vorticity"), frame.vorticity->dissipation);
  EXPECT_EQ(column("dissipation_spectral_resolved"), frame.spectrum->dissipation_resolved);
  EXPECT_EQ(column("dissipation_spectral"), frame.spectrum->dissipation);
}

// Particle snapshots: HDF5 files plus an XDMF series that is well-formed XML (checked by
// Python's XML parser) and whose every DataItem names an existing dataset of the declared shape.
TEST_F(WriterTest, ParticleSnapshotsWithXdmfSeries) {
  AnalysisConfig config;
  config.every = 1.0;
  config.products = {Product::Particles};
  config.particle_fields = {SliceField::VorticitySquared, SliceField::SubfilterStressNorm};
  RunDirectoryWriter writer(dir_, {R"({"case":"tgv2d"})", "test-version"});
  for (const double t : {0.0, 0.05}) {
    const SnapshotPtr snapshot = small_tgv_snapshot("tgv2d", 16, t);
    writer.write(analyse(snapshot, config));
  }
  ASSERT_EQ(writer.last_error(), "");
  const auto xdmf = dir_ / "snapshots" / "particles.xdmf";
  ASSERT_TRUE(std::filesystem::exists(xdmf));
  const std::string check =
      "python3 -c \"import sys, xml.etree.ElementTree as E; "
      "r = E.parse(sys.argv[1]).getroot(); "
      "g = r.find('Domain/Grid'); "
      "assert g.get('CollectionType') == 'Temporal'; "
      "assert len(g.findall('Grid')) == 2\" " +
      xdmf.string();
  EXPECT_EQ(std::system(check.c_str()), 0) << "XDMF is not well-formed or not a 2-step series";
  std::ifstream in(xdmf);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::regex item(
      R"(<DataItem Dimensions="(\d+)( 3)?"[^>]*>([^:<]+):/([a-z_0-9]+)</DataItem>)");
  int items = 0;
  for (auto it = std::sregex_iterator(text.begin(), text.end(), item); it != std::sregex_iterator();
       ++it, ++items) {
    const auto& m = *it;
    const hsize_t rows = std::stoull(m[1].str());
    const bool vector = m[2].matched;
    const auto h5 = dir_ / "snapshots" / m[3].str();
    ASSERT_TRUE(std::filesystem::exists(h5)) << h5;
    const hid_t file = H5Fopen(h5.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    ASSERT_GE(file, 0);
    const hid_t set = H5Dopen2(file, m[4].str().c_str(), H5P_DEFAULT);
    ASSERT_GE(set, 0) << m[4].str();
    const hid_t space = H5Dget_space(set);
    hsize_t dims[2] = {0, 0};
    const int rank = H5Sget_simple_extent_dims(space, dims, nullptr);
    EXPECT_EQ(rank, vector ? 2 : 1) << m[4].str();
    EXPECT_EQ(dims[0], rows);
    if (vector) {
      EXPECT_EQ(dims[1], 3u);
    }
    H5Sclose(space);
    H5Dclose(set);
    H5Fclose(file);
  }
  // Per grid: id (topology and attribute), position, velocity, mass, density, pressure, omega2,
  // tau_sfs.
  EXPECT_EQ(items, 2 * 9);
}

TEST_F(WriterTest, UnwritableDirectoryIsAClearError) {
  std::filesystem::create_directories(dir_);
  std::ofstream(dir_ / "file") << "x";
  try {
    RunDirectoryWriter writer(dir_ / "file" / "run");
    FAIL() << "expected an exception";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("cannot create"), std::string::npos);
  }
}

// A restart from a checkpoint at t writes every later row again: whatever a crash after that
// checkpoint left of them goes, a row cut short goes, the rest stays byte for byte.
TEST_F(WriterTest, RestartTruncationKeepsTheRowsUpToTheCheckpointTime) {
  std::filesystem::create_directories(dir_ / "spectra");
  std::filesystem::create_directories(dir_ / "stats");
  const auto slurp = [](const std::filesystem::path& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  };
  std::ofstream(dir_ / "spectra" / "index.csv", std::ios::binary)
      << "t,step,file\n0,0,E_t0.csv\n0.25,10,E_t0.25.csv\n0.5,20,E_t0.5.csv\n"
         "0.75,30,E_t0.75.csv\n0.7";  // a crash while the 1.0 row was being appended
  std::ofstream(dir_ / "stats" / "snapshots.csv", std::ios::binary) << "t,step";  // no whole line
  truncate_run_files_after(dir_, 0.5);
  EXPECT_EQ(slurp(dir_ / "spectra" / "index.csv"),
            "t,step,file\n0,0,E_t0.csv\n0.25,10,E_t0.25.csv\n0.5,20,E_t0.5.csv\n");
  EXPECT_FALSE(std::filesystem::exists(dir_ / "stats" / "snapshots.csv"));
  EXPECT_FALSE(std::filesystem::exists(dir_ / "fields" / "index.csv"));  // none, none made

  // timeseries.csv: rows without a time go too; 17 significant digits compare exactly.
  const std::filesystem::path series = dir_ / "timeseries.csv";
  std::ofstream(series, std::ios::binary)
      << "t,step,e_v\n0,0,0.125\n0.10000000000000001,1,0.124\nnan,2,0.1\n"
         "0.20000000000000001,2,0.123\n";
  truncate_rows_after(series, 0.1);
  EXPECT_EQ(slurp(series), "t,step,e_v\n0,0,0.125\n0.10000000000000001,1,0.124\n");
  truncate_rows_after(dir_ / "missing.csv", 1.0);
  EXPECT_FALSE(std::filesystem::exists(dir_ / "missing.csv"));
}

TEST(Dissipation, SlopeIsExactForLinearDecayAndWindowed) {
  DissipationEstimator estimator(0.5);
  EXPECT_TRUE(std::isnan(estimator.add(0.0, 1.0)));
  double last = 0.0;
  for (int k = 1; k <= 100; ++k) last = estimator.add(0.01 * k, 1.0 - 0.3 * 0.01 * k);
  EXPECT_NEAR(last, 0.3, 1e-12);
  // Quadratic e(t) = 1 - t²: the trailing-window slope at t is 2(t - w/2) (centred time).
  DissipationEstimator quadratic(0.2);
  for (int k = 0; k <= 1000; ++k) {
    const double t = 0.001 * k;
    last = quadratic.add(t, 1.0 - t * t);
  }
  EXPECT_NEAR(last, 2.0 * (1.0 - 0.1), 1e-9);
}

}  // namespace
}  // namespace sphles::analysis
