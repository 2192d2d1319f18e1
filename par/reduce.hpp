// SPDX-License-Identifier: GPL-3.0-or-later
// Reductions over the ranks of a Decomposition whose results do not depend on the rank count, so
// that diagnostics are the same bits for any number of ranks.
#pragma once

#include <cstdint>
#include <span>

#include "par/decomposition.hpp"
#include "sim/reduction.hpp"

namespace sphles::par {

/// The exact sum (sim::ExactSum) of every rank's partial sum, on every rank: the same bits as one
/// process adding all the values, whatever the split. Collective over d.comm().
sim::ExactSum allreduce(const Decomposition& d, sim::ExactSum partial);
/// The same for several sums at once (one message), in place.
void allreduce(const Decomposition& d, std::span<sim::ExactSum> partial);

/// True on every rank when `ok` holds on every rank of d (a check every rank must agree on
/// before a collective call that one of them cannot make). Collective over d.comm().
bool on_every_rank(const Decomposition& d, bool ok);

/// Every rank's counts added, element by element, on every rank. Collective over d.comm().
void allreduce_counts(const Decomposition& d, std::span<std::uint64_t> counts);

}  // namespace sphles::par
