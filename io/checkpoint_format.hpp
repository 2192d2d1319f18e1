// SPDX-License-Identifier: GPL-3.0-or-later
// The layout of a checkpoint file (docs/checkpoints.md): its attributes and particle datasets,
// written and read for one process (checkpoint.cpp) or every process of a distributed run
// through MPI-IO (checkpoint_collective.cpp). Internal to io.
#pragma once

#include <hdf5.h>

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "io/checkpoint_data.hpp"
#include "io/checkpoint_error.hpp"
#include "sim/scene.hpp"

namespace sphles::io::checkpoint_format {

/// Where this process' particles go in the file's datasets: entries [first, first + count) of
/// `total`, written with the data transfer properties `transfer` (collective for MPI-IO).
struct Placement {
  hsize_t first = 0;
  hsize_t total = 0;
  hid_t transfer = H5P_DEFAULT;
  bool eddy_viscosity = false;  // whether the run has ν_t (a process may hold no particles)
};

/// Entries [first, first + count) of a dataset that must hold `expected` entries, read with the
/// data transfer properties `transfer` (collective for MPI-IO).
struct Range {
  hsize_t first = 0;
  hsize_t count = 0;
  hid_t transfer = H5P_DEFAULT;
};

/// What the stored scene says about the particle set: box, dimension, particle count.
struct SceneGeometry {
  std::optional<sim::Scene> scene;  // set when the scene names a case this sphles knows
  std::string unknown;              // otherwise why not
};

/// The attributes of an open checkpoint, validated (structure and the time counters; the
/// scene's box and particle count against dimension and num_particles).
struct Header {
  Checkpoint checkpoint;  // metadata, time, step, builds; no particles
  int dimension = 3;
  std::uint64_t count = 0;
  SceneGeometry geometry;
};

/// Entries per chunk for a dataset of `size` entries: the fewest chunks of at most 65 536, of
/// equal length (HDF5 allocates the last chunk whole, so 70 000 entries in chunks of 65 536 would
/// take 131 072 entries of space; in two chunks of 35 000 they take 70 000).
hsize_t chunk_entries(hsize_t size);

/// Throws CheckpointError unless the options' gzip level is in [0, 9].
void check_gzip_level(const CheckpointWriteOptions& options);

/// The whole checkpoint under `root`: its attributes, then the particle datasets with this
/// process' particles (`state`) at `block`. Every process of a collective write makes the same
/// calls with the same attribute values.
void write_contents(hid_t root, const sim::SolverState& state, const CheckpointMetadata& metadata,
                    const CheckpointWriteOptions& options, const std::string& label,
                    const Placement& block);

/// Shortest text that reads back as the same double (1e+300, -1, 6.283185307179586).
std::string number(double value);

/// Particle ids are a permutation of 0..N-1 (sim::make_lattice numbers them; the solver only
/// reorders). One pass; a second one only to name the first copy of a duplicate.
void require_permutation(const std::vector<std::uint64_t>& ids, const std::string& file);

/// The attributes of the open checkpoint `root` (file name `file`, for the messages), validated.
Header read_header(hid_t root, const std::string& file);

/// Particles [range.first, range.first + range.count) of the file into h.checkpoint's state,
/// every value checked (finite; mass, volume, density positive; positions in the scene's box;
/// ids below the count). The ids' permutation is the caller's to check.
void read_particles(hid_t root, Header& h, const Range& range, const std::string& file);

}  // namespace sphles::io::checkpoint_format
