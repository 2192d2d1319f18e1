// SPDX-License-Identifier: GPL-3.0-or-later
// What a run will ask of the machine, estimated from its scene before it starts (docs/scenes.md,
// "Resource estimate"): peak resident memory with a breakdown by component, disk per checkpoint
// and per analysis frame, the initial time step and the number of steps. The estimate is
// arithmetic on the spec only (no particle set is built), in double precision, so it neither
// allocates nor overflows for 4096³ particles or a tiny kernel.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "control/run.hpp"
#include "sim/scene.hpp"
#include "sim/scene_warnings.hpp"

namespace sphles::control {

/// Where a component of the memory estimate lives in a distributed run (RankEstimate): on
/// every rank, for its owned particles and their halo copies (particle arrays, the list
/// build's cell sort) or for its owned particles only (neighbour lists, the checkpoint's
/// copy); or beside the ranks in the service (or rank 0 under mpirun): the analysis and
/// rendering always, snapshots of the particles only when a product is gathered for.
enum class PartScope { OwnedAndHalo, Owned, Service, Gathered };

/// One component of the memory estimate.
struct MemoryPart {
  std::string name;    // e.g. "neighbour_list"
  double bytes = 0.0;  // [B]
  std::string detail;  // how it was counted
  PartScope scope = PartScope::OwnedAndHalo;
};

/// What each process of a distributed run holds (docs/scaling.md): the solver's parts for the
/// largest sub-box of the split the run will use (sim::process_grid), its owned particles and
/// the halo copies around them. The analysis, rendering and snapshots are not in it: they are
/// rank 0's (`mpirun sphles run`) or the service's.
struct RankEstimate {
  int ranks = 1;
  int dimension = 3;
  std::array<int, 3> grid{1, 1, 1};  // processes per axis (the first `dimension`)
  double owned = 0.0;                // particles of the largest sub-box
  double halo_per_owned = 0.0;       // halo copies per owned particle
  double halo_width = 0.0;           // [m]: the neighbour-list radius (the packing's if larger)
  double memory_bytes = 0.0;         // the sum of `memory`
  std::vector<MemoryPart> memory;    // the set-up's peak or the run's, whichever is larger
  /// What the service (or rank 0 under mpirun) holds beside the ranks: the analysis, the
  /// rendering, and snapshots of every particle only when a product asked for is one the ranks
  /// do not serve (analysis::served_by_ranks: the particles are gathered for it).
  double service_bytes = 0.0;  // the sum of `service`
  std::vector<MemoryPart> service;
  /// Non-empty when the run would refuse the split: a sub-box narrower than the halo.
  std::string refusal;
};

struct ResourceEstimate {
  double particles = 0.0;                // N^n
  double neighbours_per_particle = 0.0;  // inside the Verlet list radius H (1 + skin)
  double analysis_grid_points = 0.0;     // M^n of the analysis grid; 0 without gridded products

  /// Peak resident memory of the run [B], above what the sphles process holds without it
  /// (libraries, threads). The sum of `memory`; what the service admits by (its own process
  /// exists already).
  double memory_bytes = 0.0;
  /// What `sphles run` of it holds at its peak: memory_bytes and the program's own footprint
  /// (kProgramBytes) [B].
  double process_peak_bytes = 0.0;
  /// What makes the run's answer meaningless although it runs (sim::scene_warnings).
  std::vector<sim::SceneWarning> warnings;
  /// The components that coexist at the peak: the peak of the set-up (packing) or of the run,
  /// whichever is larger.
  std::vector<MemoryPart> memory;

  double checkpoint_file_bytes = 0.0;  // one checkpoint, uncompressed (an upper bound) [B]
  /// Checkpoint files on disk at once: checkpoint.keep + 1 while a new one is written before
  /// the oldest is removed; 1 when checkpoints are off (a stopped run still writes one) [B].
  double checkpoint_disk_bytes = 0.0;
  double analysis_frame_bytes = 0.0;  // files written per analysis frame (spectra, slices, ...)
  double analysis_frames = 0.0;       // analysis frames to the end time
  double analysis_disk_bytes = 0.0;   // analysis_frame_bytes x analysis_frames [B]

  sim::TimeStepEstimate time_step;  // at t = 0 (sim::estimate_initial_time_step)
  double steps = 0.0;               // time.end / initial step

  /// With more than one rank: what each holds.
  std::optional<RankEstimate> per_rank;
};

/// The estimate for a parsed spec, on `ranks` MPI ranks. Cheap (no allocation proportional to
/// the run).
ResourceEstimate estimate_resources(const RunSpec& spec, int ranks = 1);

/// [{"field", "message"}] of sim::scene_warnings.
nlohmann::json scene_warnings_to_json(const std::vector<sim::SceneWarning>& warnings);

/// {"memory_bytes", "memory": [{"name", "bytes", "detail"}], "checkpoint_file_bytes", ...,
///  "time_step": {"initial", "limit", "acoustic", "viscous", "force", "fixed"}, "steps"}, and
/// with ranks "per_rank": {"ranks", "grid", "owned", "halo_per_owned", "halo_width",
/// "memory_bytes", "memory", "refusal"}; limits that do not apply are null.
nlohmann::json resource_estimate_to_json(const ResourceEstimate& estimate);

/// "1.5 GiB", "12 MiB", "512 B" (binary units, 3 significant digits).
std::string format_bytes(double bytes);

/// "an estimated 12.3 GiB at its peak (neighbour_list 6.1 GiB, neighbour_build 4.5 GiB, ...)"
/// listing the `parts` largest components.
std::string describe_memory(const ResourceEstimate& estimate, std::size_t parts = 3);

/// The reason a run does not fit, or nothing: "the run needs an estimated 12.3 GiB of memory
/// at its peak (...), more than the 6.2 GiB the server allows (--max-memory)".
/// `limit_name` says whose limit it is.
std::optional<std::string> check_memory(
    const ResourceEstimate& estimate, double limit_bytes,
    const std::string& limit_name = "the server allows (--max-memory)");

/// Memory the machine gives this process [B]: the cgroup limit if one is set (v2 memory.max,
/// v1 memory.limit_in_bytes, the smallest along the cgroup's path), else MemTotal of
/// /proc/meminfo; the smaller of both when both are known. 0 if neither can be read.
std::uint64_t machine_memory_bytes();

/// The same from other files (tests): `self_cgroup` in the format of /proc/self/cgroup,
/// `cgroup_root` the cgroup mount (v2 files directly below it, v1 under memory/), `meminfo` in
/// the format of /proc/meminfo.
std::uint64_t machine_memory_bytes(const std::filesystem::path& self_cgroup,
                                   const std::filesystem::path& cgroup_root,
                                   const std::filesystem::path& meminfo);

/// Share of machine_memory_bytes() a server allows its runs by default: the rest is left to the
/// server process itself (about 80 MiB), the operating system and the page cache that
/// checkpoints and analysis files go through.
inline constexpr double kDefaultMemoryFraction = 0.8;
/// The sphles program's own resident memory before it holds a run (its libraries: VTK, OSMesa,
/// HDF5, FFTW, OpenMPI): the peak RSS of `sphles run tgv2d` at 16² to t = 0.01, 91.7 MiB
/// (Debian 12; the 2 rank processes of the same run under mpiexec, 96.3-97.4 MiB).
inline constexpr double kProgramBytes = 92.0 * 1024 * 1024;

/// kDefaultMemoryFraction x machine_memory_bytes() (the default of --max-memory).
std::uint64_t default_memory_limit_bytes();

}  // namespace sphles::control
