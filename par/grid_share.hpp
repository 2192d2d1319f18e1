// SPDX-License-Identifier: GPL-3.0-or-later
// A rank's share of the analysis grid (docs/scaling.md): the nodes inside its sub-box and their
// nearest particles, checked to be the whole run's.
#pragma once

#include <cstdint>
#include <string>

#include "analysis/grid.hpp"
#include "par/decomposition.hpp"
#include "sim/particles.hpp"

namespace sphles::par {

/// The nodes of `grid` (over the decomposition's box) whose positions lie in this rank's
/// sub-box: along each axis a contiguous range, since the sub-box bounds increase with the
/// coordinate (first 0 when a range is empty).
analysis::NodeBlock own_block(const Decomposition& d, const analysis::Grid& grid);

/// The nearest particle of every node of `block` (grid nodes inside this rank's sub-box) among
/// `local` (this rank's particles and its halo; `total` particles over all ranks), checked to be
/// the whole set's. Refuses on every rank, with std::invalid_argument naming `who` and the halo
/// width, when the particles leave a void wider than the halo: a rank with nodes and no
/// particle, or a node whose nearest particle here lies further than the halo width (one of
/// another rank may be nearer; along an axis a rank is alone on, none is left out). Without
/// `nearest`, only the first check, and the answer is empty. Collective over d.comm().
analysis::NearestInBlock nearest_within_halo(const Decomposition& d, const analysis::Grid& grid,
                                             const sim::ParticleArrays& local,
                                             const analysis::NodeBlock& block, std::uint64_t total,
                                             const std::string& who, bool nearest = true);

}  // namespace sphles::par
