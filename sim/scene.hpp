// Scene files: one validated configuration object for a run (docs/scenes.md).
//
// A scene is JSON. Every key has a default (which may depend on "case"); unknown keys, wrong
// types and out-of-range values raise SceneError naming the field and the reason.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "sim/kernels.hpp"
#include "sim/physics.hpp"
#include "sim/solver.hpp"

namespace sphles::sim {

class SceneError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

enum class CaseType { TaylorGreen3D, TaylorGreen2D, Kolmogorov2D };

std::string_view case_name(CaseType type);
int case_dimension(CaseType type);

/// Relaxation of the initial lattice (Colagrossi et al. 2012), see initial_conditions.hpp.
struct PackingConfig {
  bool enabled = true;
  bool cache = true;
  double perturbation = 0.05;  // random lattice displacement before relaxation, in units of Δl
  int max_iterations = 400;
  double tolerance = 1e-3;  // stop when max_i |Σ_j ∇W_ij V_j| Δl falls below
  std::uint64_t seed = 1;
};

/// Kolmogorov forcing a = χ sin(k_y y) e_x and linear friction -μ v (SPEC §6.3).
struct KolmogorovForcing {
  double amplitude = 1.8;  // χ [m/s²]
  int periods = 7;         // k_y = 2π periods / L (7 periods in 0.042 m: k_y = 1047.2 1/m)
  double friction = 0.7;   // μ [1/s]
};

/// Checkpoints (docs/checkpoints.md): at a cadence in simulated and/or wall time, keeping the
/// newest `keep` files.
struct CheckpointConfig {
  double every = 0.0;          // simulated time between checkpoints [s]; 0 = none by sim time
  double every_seconds = 0.0;  // wall time between checkpoints [s]; 0 = none by wall time
  int keep = 3;                // newest files kept
  int compression = 0;         // gzip level 0-9 (0 = none)
  bool enabled() const { return every > 0.0 || every_seconds > 0.0; }
};

struct OutputConfig {
  double timeseries_every = 0.0;        // simulated time between rows; 0 writes every step
  double progress_every_seconds = 1.0;  // wall time between progress lines
};

struct Scene {
  std::string name;
  std::string preset;  // preset the scene was built from, empty if none
  CaseType case_type = CaseType::TaylorGreen3D;
  double box_length_ = 0.0;  // L [m]; 2π for the Taylor-Green cases
  int particles_per_side = 32;
  KernelType kernel = KernelType::WendlandC4;
  double kernel_diameter_over_spacing = 8.0;  // D_K / Δl
  FluidParameters fluid;
  double velocity_amplitude = 1.0;                        // v0 [m/s]
  std::array<double, 3> uniform_velocity{0.0, 0.0, 0.0};  // added to the initial field [m/s]
  double end_time = 15.0;                                 // [s]
  TimeStepConfig time_step;
  BlowUpThresholds blow_up;  // runaway-energy test after every step (docs/stability.md)
  SubfilterConfig subfilter;
  KolmogorovForcing forcing;     // kolmogorov2d only
  double neighbour_skin = 0.15;  // fraction of H
  PackingConfig packing;
  OutputConfig output;
  CheckpointConfig checkpoint;

  int dimension() const { return case_dimension(case_type); }
  double box_length() const { return box_length_; }  // L [m]
  double forcing_wavenumber() const;                 // k_y [1/m] (kolmogorov2d)
  double particle_spacing() const;                   // Δl = L / particles_per_side [m]
  double kernel_diameter() const;                    // D_K [m]
  std::size_t num_particles() const;
};

/// Names of the built-in presets: tgv2d (64², Re = 100), tgv3d (32³), tgv3d-case1 ...
/// tgv3d-case21 (SPEC Table 5.1), kolmogorov2d.
std::vector<std::string> preset_names();

/// The scene document of a preset; throws SceneError for an unknown name.
nlohmann::json preset_document(const std::string& name);

/// Parses and validates a scene; throws SceneError. A "preset" key starts from that preset's
/// document, and the other keys override it (JSON merge patch).
Scene parse_scene(const nlohmann::json& document);

/// Reads a JSON file; throws SceneError naming the file on I/O or syntax errors.
nlohmann::json read_scene_file(const std::filesystem::path& path);

/// Applies "dotted.key=value" to a scene document. The value is parsed as JSON when it is valid
/// JSON, otherwise taken as a string. Throws SceneError on a malformed assignment.
void apply_override(nlohmann::json& document, const std::string& assignment);

/// The complete scene with every default filled in (written next to each run's output).
nlohmann::json scene_to_json(const Scene& scene);

}  // namespace sphles::sim
