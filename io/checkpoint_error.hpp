// SPDX-License-Identifier: GPL-3.0-or-later
// The error of every file io/ writes or reads (checkpoints, particle snapshots, the HDF5 and
// MPI-IO plumbing beneath them), on its own so that the plumbing needs nothing of the formats.
#pragma once

#include <stdexcept>

namespace sphles::io {

/// Raised for every unreadable or invalid checkpoint; the message names the file and the reason.
class CheckpointError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

}  // namespace sphles::io
