// SPDX-License-Identifier: GPL-3.0-or-later
// Small pieces every MPI exchange of par/ uses: counts checked against MPI's int, and a string
// sent from rank 0 to every rank.
#pragma once

#include <mpi.h>

#include <cstddef>
#include <limits>
#include <stdexcept>
#include <string>

namespace sphles::par {

/// `n` as an MPI count; throws std::length_error naming `what` when it exceeds MPI's int.
inline int mpi_count(std::size_t n, const std::string& what) {
  if (n > static_cast<std::size_t>(std::numeric_limits<int>::max()))
    throw std::length_error(what + ": " + std::to_string(n) + " values exceed MPI's int count");
  return static_cast<int>(n);
}

/// Rank 0's `text` on every rank of `comm` (its size, then its characters). Collective.
inline void broadcast_string(MPI_Comm comm, std::string& text) {
  unsigned long long size = text.size();
  MPI_Bcast(&size, 1, MPI_UNSIGNED_LONG_LONG, 0, comm);
  text.resize(static_cast<std::size_t>(size));
  MPI_Bcast(text.data(), mpi_count(text.size(), "a broadcast string"), MPI_CHAR, 0, comm);
}

}  // namespace sphles::par
