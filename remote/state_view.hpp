// SPDX-License-Identifier: GPL-3.0-or-later
// A solver seen through copies of its whole state (a distributed solver gathered to rank 0,
// par/driver.hpp; a solver in another process, launch/): the state of the current step fetched
// once when asked for, and a Verlet list over it for the analysis, built once per step.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>

#include "sim/neighbour_search.hpp"
#include "sim/solver.hpp"

namespace sphles::remote {

class StateView {
 public:
  explicit StateView(const sim::SolverConfig& config) : config_(config) {}

  /// The state at `step`: `fetch()` the first time it is asked for at this step.
  const sim::SolverState& state(std::uint64_t step,
                                const std::function<sim::SolverState()>& fetch) const {
    if (!state_ || state_step_ != step) {
      state_.reset();
      state_ = fetch();
      state_step_ = step;
    }
    return *state_;
  }

  /// A list over `particles` (the state at `step`), built once per step asked for.
  std::shared_ptr<const sim::NeighbourList> neighbour_list(
      std::uint64_t step, const sim::ParticleArrays& particles) const {
    if (!search_ || list_step_ != step) {
      search_ = std::make_unique<sim::VerletNeighbourSearch>(
          config_.box, config_.support_radius, config_.neighbour_skin * config_.support_radius);
      search_->build(sim::view_positions(particles));
      list_step_ = step;
    }
    return search_->shared_list();
  }

 private:
  const sim::SolverConfig& config_;
  mutable std::optional<sim::SolverState> state_;
  mutable std::uint64_t state_step_ = 0;
  mutable std::unique_ptr<sim::VerletNeighbourSearch> search_;
  mutable std::uint64_t list_step_ = 0;
};

}  // namespace sphles::remote
