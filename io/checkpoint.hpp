// SPDX-License-Identifier: GPL-3.0-or-later
// HDF5 checkpoints: the complete solver state in one file, written atomically, validated on
// read (docs/checkpoints.md).
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "io/checkpoint_data.hpp"
#include "io/checkpoint_error.hpp"
#include "io/hdf5_library.hpp"
#include "sim/solver.hpp"

namespace sphles::io {

/// Writes `path` atomically: the file is assembled in memory, written to a temporary file in the
/// same directory, fsync'ed, then renamed over `path`. A crash at any point leaves either the old
/// file or the new complete one. A failed write (full disk, file-size limit, unwritable
/// directory) throws CheckpointError naming the file and the reason, removes the temporary,
/// leaves `path` as it was and leaves no HDF5 object open. Datasets carry Fletcher-32 checksums.
void write_checkpoint(const std::filesystem::path& path, const sim::SolverState& state,
                      const CheckpointMetadata& metadata,
                      const CheckpointWriteOptions& options = {});

/// The XDMF side file of a checkpoint: the same name with extension .xdmf2 (XDMF 2, the
/// extension by which ParaView picks its XDMF 2 reader; docs/checkpoints.md).
std::filesystem::path checkpoint_xdmf_path(const std::filesystem::path& checkpoint);

/// What the XDMF side file says of a checkpoint's particles.
struct CheckpointShape {
  int dimension = 3;
  std::uint64_t particles = 0;
  double time = 0.0;
  bool eddy_viscosity = false;
  static CheckpointShape of(const sim::SolverState& state);
};

/// Writes (atomically) checkpoint_xdmf_path(checkpoint): an XDMF 2 polyvertex grid over the
/// checkpoint's particle datasets (vectors joined from their components), so ParaView opens a
/// checkpoint as particles. Throws CheckpointError.
void write_checkpoint_xdmf(const std::filesystem::path& checkpoint, const sim::SolverState& state);
void write_checkpoint_xdmf(const std::filesystem::path& checkpoint, const CheckpointShape& shape);

/// A solver whose particles live on several processes (par::Driver's) writes its checkpoints
/// from there, each process its own particles, instead of gathering them into one process'
/// state() (io/checkpoint_collective.hpp). The file is the one write_checkpoint writes for the
/// gathered state; the XDMF side file is written with it.
class DistributedCheckpoints {
 public:
  virtual ~DistributedCheckpoints();  // out of line: one vtable and typeinfo for dynamic_cast
  /// Collective over the solver's processes; throws CheckpointError as write_checkpoint does,
  /// on every process alike.
  virtual void write_checkpoint(const std::filesystem::path& path,
                                const CheckpointMetadata& metadata,
                                const CheckpointWriteOptions& options) const = 0;
};

/// Reads and validates. Structure: existence, HDF5 readability, schema name and version,
/// dimension, particle count and array lengths, checksums. Content: the `scene` attribute is a
/// JSON object; time finite and >= 0; step and neighbour_builds consistent with it; every value
/// finite; when the scene names a case this sphles knows, dimension and particle count match it
/// and positions lie in its periodic box [0, L); mass, volume and density > 0; ids a permutation
/// of 0..N-1. Linear in the particle count. Throws CheckpointError naming the file, the attribute
/// or dataset and the reason.
Checkpoint read_checkpoint(const std::filesystem::path& path);

/// What a checkpoint says of itself without its particles: the attributes read_checkpoint
/// validates (schema and version, dimension, particle count, time, step and build counter, the
/// scene against them), the particle group's presence and whether ν_t is stored. Reads no
/// particle data, so it costs the same at any size. Throws CheckpointError.
struct CheckpointHeader {
  CheckpointMetadata metadata;
  CheckpointShape shape;
  std::uint64_t step = 0;
  std::uint64_t neighbour_builds = 0;
};
CheckpointHeader read_checkpoint_header(const std::filesystem::path& path);
/// The header of a checkpoint read whole.
CheckpointHeader header_of(const Checkpoint& checkpoint);

/// Checkpoint files of a run directory (checkpoints/ckpt_*.h5), newest step first.
std::vector<std::filesystem::path> list_checkpoints(const std::filesystem::path& directory);

/// How much of a checkpoint newest_valid_checkpoint reads: all of it (read_checkpoint), or its
/// header only (read_checkpoint_header: a distributed run whose ranks read and validate the
/// particles themselves, io/checkpoint_collective.hpp).
enum class CheckpointCheck { Whole, Header };

/// The newest checkpoint in `directory` that reads and validates and that `accept` (when given)
/// takes, shown the file and the header just read: it rejects a valid file by throwing
/// CheckpointError with the reason. `rejected` receives one line per newer file that was not
/// taken. Throws CheckpointError when none is.
using CheckpointAccept = std::function<void(const std::filesystem::path&, const CheckpointHeader&)>;
std::filesystem::path newest_valid_checkpoint(const std::filesystem::path& directory,
                                              std::vector<std::string>* rejected = nullptr,
                                              CheckpointCheck check = CheckpointCheck::Whole,
                                              const CheckpointAccept& accept = {});

/// The same with CheckpointCheck::Whole, returning the file and what was read (a resume needs
/// both, and the file read once).
std::pair<std::filesystem::path, Checkpoint> read_newest_valid_checkpoint(
    const std::filesystem::path& directory, std::vector<std::string>* rejected = nullptr,
    const CheckpointAccept& accept = {});

/// A human-readable listing of a checkpoint file (for `sphles inspect`). Throws CheckpointError.
std::string describe_checkpoint(const std::filesystem::path& path);

/// File name for a step: ckpt_0000001234.h5.
std::string checkpoint_file_name(std::uint64_t step);

}  // namespace sphles::io
