// SPDX-License-Identifier: GPL-3.0-or-later
// A solver elsewhere (remote/): every request and reply crosses the codec as it was sent, and a
// proxy whose requests travel through the codec to an endpoint in this process steps, restores
// and fails exactly as the solver it stands for.
#include <gtest/gtest.h>

#include <cstring>
#include <stdexcept>

#include "remote/codec.hpp"
#include "remote/endpoint.hpp"
#include "remote/messages.hpp"
#include "remote/proxy.hpp"
#include "scene/document.hpp"
#include "sim/initial_conditions.hpp"

namespace sphles::remote {
namespace {

bool same_bits(const std::vector<double>& a, const std::vector<double>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(double)) == 0;
}

void expect_same_state(const sim::SolverState& a, const sim::SolverState& b) {
  ASSERT_EQ(a.particles.dimension, b.particles.dimension);
  const auto fa = a.particles.double_fields();
  const auto fb = b.particles.double_fields();
  ASSERT_EQ(fa.size(), fb.size());
  for (std::size_t f = 0; f < fa.size(); ++f) EXPECT_TRUE(same_bits(*fa[f], *fb[f])) << f;
  EXPECT_EQ(a.particles.id, b.particles.id);
  for (std::size_t axis = 0; axis < 3; ++axis)
    EXPECT_TRUE(same_bits(a.list_reference_positions[axis], b.list_reference_positions[axis]));
  EXPECT_EQ(a.time, b.time);
  EXPECT_EQ(a.step, b.step);
  EXPECT_EQ(a.neighbour_builds, b.neighbour_builds);
}

template <class T>
T round_trip(const T& value) {
  Encoder e;
  encode(e, value);
  return decode_all<T>(e.bytes());
}

sim::Scene small_tgv2d() {
  return scene::parse_scene({{"preset", "tgv2d"},
                             {"particles_per_side", 16},
                             {"packing", {{"enabled", false}}},
                             {"time", {{"end", 1.0}}}});
}

TEST(RemoteCodec, EveryRequestCrossesAsItWasSent) {
  const sim::RunSetup setup = sim::setup_run(small_tgv2d());
  const std::string json = scene::scene_to_json(small_tgv2d()).dump();

  const Request make = round_trip(Request{Make{json, setup.particles}});
  ASSERT_TRUE(std::holds_alternative<Make>(make));
  EXPECT_EQ(std::get<Make>(make).scene, json);
  sim::SolverState sent, back;
  sent.particles = setup.particles;
  back.particles = std::get<Make>(make).particles;
  expect_same_state(sent, back);

  const Request step = round_trip(Request{Step{0.125}});
  EXPECT_EQ(std::get<Step>(step).max_dt, 0.125);
  const Request set_up = round_trip(Request{remote::SetUp{json, "cache/dir", [] { return true; }}});
  EXPECT_EQ(std::get<remote::SetUp>(set_up).packing_cache_dir, "cache/dir");
  EXPECT_FALSE(std::get<remote::SetUp>(set_up).cancelled);  // the callback stays where it was made
  const Request file = round_trip(Request{RestoreFile{json, "checkpoints/c.h5"}});
  EXPECT_EQ(std::get<RestoreFile>(file).file, "checkpoints/c.h5");
  const Request write = round_trip(Request{WriteCheckpoint{"c.h5", {"{}", "1.2.3", "packed"}, 7}});
  EXPECT_EQ(std::get<WriteCheckpoint>(write).metadata.code_version, "1.2.3");
  EXPECT_EQ(std::get<WriteCheckpoint>(write).metadata.packing, "packed");
  EXPECT_EQ(std::get<WriteCheckpoint>(write).gzip_level, 7u);
  analysis::RanksRequest products;
  products.points_per_side = 32;
  products.slice_omega2 = true;
  products.view.max_points = 1000;
  EXPECT_TRUE(std::get<ParticleProducts>(round_trip(Request{ParticleProducts{products}})).request ==
              products);
  EXPECT_TRUE(std::holds_alternative<Finish>(round_trip(Request{Finish{}})));
  EXPECT_TRUE(std::holds_alternative<State>(round_trip(Request{State{}})));
}

TEST(RemoteCodec, EveryReplyCrossesAsItWasSent) {
  sim::PackingReport packing{12, 0.5, 1e-4, true, false, "cache.h5"};
  const Reply set_up = round_trip(Reply{SetUpStatus{{1.5, 42, 0.01, {}}, packing}});
  const auto& s = std::get<SetUpStatus>(set_up);
  EXPECT_EQ(s.status.step, 42u);
  EXPECT_EQ(s.packing.iterations, 12);
  EXPECT_EQ(s.packing.cache_file, "cache.h5");
  analysis::EnergySpectrum spectrum{1.0, {1.0, 2.0}, {0.5, 0.25}, {0.5, 1.0}};
  const Reply back = round_trip(Reply{spectrum});
  EXPECT_EQ(std::get<analysis::EnergySpectrum>(back).energy, spectrum.energy);
  EXPECT_EQ(std::get<analysis::EnergySpectrum>(back).k2_energy, spectrum.k2_energy);
  EXPECT_EQ(std::get<std::vector<double>>(round_trip(Reply{std::vector<double>{3.0}})),
            std::vector<double>{3.0});
}

TEST(RemoteCodec, AnUnknownKindAndLeftOverBytesAreRefused) {
  Encoder unknown;
  unknown.u64(std::variant_size_v<Request>);
  EXPECT_THROW(decode_all<Request>(unknown.bytes()), ProtocolError);
  Encoder longer;
  encode(longer, Request{Step{1.0}});
  longer.u64(0);
  EXPECT_THROW(decode_all<Request>(longer.bytes()), ProtocolError);
}

/// A transport that carries each request through the codec to an endpoint in this process, and
/// its reply or error back the same way.
class Loopback final : public Transport {
 public:
  explicit Loopback(sim::SolverFactories solvers) : endpoint_(std::move(solvers)) {}
  Reply call(Request request) override {
    Encoder sent;
    encode(sent, request);
    Encoder answer;
    bool failed = false;
    try {
      encode(answer, endpoint_.handle(decode_all<Request>(sent.bytes())));
    } catch (const std::exception& e) {
      failed = true;
      answer = Encoder{};
      encode_error(answer, e);
    }
    if (failed) {
      Decoder d(answer.bytes());
      throw_error(d);
    }
    return decode_all<Reply>(answer.bytes());
  }

 private:
  Endpoint endpoint_;
};

/// One process' solvers, as a run without factories makes them.
sim::SolverFactories local_solvers() {
  sim::SolverFactories solvers;
  solvers.make = [](const sim::Scene& scene, sim::ParticleArrays particles) {
    return sim::make_simulation(sim::make_solver_config(scene), std::move(particles));
  };
  solvers.restore = [](const sim::Scene& scene, sim::SolverState state) {
    return sim::restore_simulation(sim::make_solver_config(scene), std::move(state));
  };
  return solvers;
}

TEST(RemoteSolver, AProxyStepsAndRestoresBitwiseLikeTheSolverItStandsFor) {
  const sim::Scene scene = small_tgv2d();
  const sim::RunSetup setup = sim::setup_run(scene);
  auto transport = std::make_shared<Loopback>(local_solvers());
  const sim::SolverFactories remote = remote_solvers([transport] { return transport; });

  auto here = sim::make_simulation(setup.solver, setup.particles);
  auto there = remote.make(scene, setup.particles);
  for (int k = 0; k < 5; ++k) {
    here->step();
    there->step();
  }
  EXPECT_EQ(there->time(), here->time());
  EXPECT_EQ(there->step_count(), 5u);
  EXPECT_EQ(there->diagnostics().kinetic_energy, here->diagnostics().kinetic_energy);
  EXPECT_EQ(there->stable_time_step(), here->stable_time_step());
  expect_same_state(there->state(), here->state());
  EXPECT_EQ(there->case_diagnostics(scene), here->case_diagnostics(scene));

  // A restore across the transport continues bitwise; the solver before it is stale.
  auto restored = remote.restore(scene, there->state());
  EXPECT_THROW(there->step(), std::logic_error);
  restored->step();
  here->step();
  expect_same_state(restored->state(), here->state());

  // What the solver's side cannot do fails with its own error type, and the current solver
  // stays in use.
  EXPECT_THROW(remote.change(*restored, scene), std::invalid_argument);
  const auto* products = dynamic_cast<const analysis::DistributedProducts*>(restored.get());
  ASSERT_NE(products, nullptr);
  EXPECT_THROW(products->velocity_spectrum(16), std::invalid_argument);
  restored->step();
  here->step();
  expect_same_state(restored->state(), here->state());
}

}  // namespace
}  // namespace sphles::remote
