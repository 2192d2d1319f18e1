// SPDX-License-Identifier: GPL-3.0-or-later
// The one lock around the HDF5 library, for every file io/ and the spectral reference write or
// read.
#pragma once

#include <mutex>

namespace sphles::io {

/// Debian's HDF5 is built without thread safety: every HDF5 call in sphles (checkpoints on the
/// solver thread, snapshots on the analysis thread) holds this one mutex.
std::mutex& hdf5_library_mutex();

}  // namespace sphles::io
