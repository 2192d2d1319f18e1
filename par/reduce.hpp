// Reductions over the ranks of a Decomposition whose results do not depend on the rank count
// (issue 19: diagnostics the same bits for any number of ranks).
#pragma once

#include <span>

#include "par/decomposition.hpp"
#include "sim/reduction.hpp"

namespace sphles::par {

/// The exact sum (sim::ExactSum) of every rank's partial sum, on every rank: the same bits as one
/// process adding all the values, whatever the split. Collective over d.comm().
sim::ExactSum allreduce(const Decomposition& d, sim::ExactSum partial);
/// The same for several sums at once (one message), in place.
void allreduce(const Decomposition& d, std::span<sim::ExactSum> partial);

}  // namespace sphles::par
