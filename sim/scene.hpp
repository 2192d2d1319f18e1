// SPDX-License-Identifier: GPL-3.0-or-later
// The scene: one validated configuration object for a run (docs/scenes.md), as plain data. Its
// JSON document, the schema and the presets live in scene/ (scene/document.hpp); every key has a
// default (which may depend on "case"); a scene that cannot run raises SceneError naming the
// field and the reason.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "sim/health.hpp"
#include "sim/kernels.hpp"
#include "sim/name_table.hpp"
#include "sim/physics/thesis_passes.hpp"
#include "sim/scheme.hpp"
#include "sim/subfilter.hpp"
#include "sim/time_step.hpp"

namespace sphles::sim {

/// A scene (or request) that does not describe a valid run. `field` is the dotted key at fault
/// ("time.end"; "(top level)" or "(body)" for the document as a whole), what() the whole message,
/// which names it too, so that a caller reports the field without reading the text. An empty
/// field means the error names none (a command line missing its scene).
class SceneError : public std::runtime_error {
 public:
  SceneError(std::string field, const std::string& message)
      : std::runtime_error(message), field_(std::move(field)) {}
  /// Empty when the error names no field.
  const std::string& field() const noexcept { return field_; }

 private:
  std::string field_;
};

/// Throws SceneError for `field` with the message "scene: 'field' <reason>".
[[noreturn]] inline void throw_scene_error(const std::string& field, const std::string& reason) {
  throw SceneError(field, "scene: '" + field + "' " + reason);
}

/// The value `name` names in `table`; SceneError for `field` otherwise, listing the names.
template <class Enum, std::size_t N>
Enum parse_name(const NameTable<Enum, N>& table, const std::string& name,
                const std::string& field) {
  if (const std::optional<Enum> value = table.find(name)) return *value;
  throw_scene_error(field, "must be one of " + table.list() + ", got '" + name + "'");
}

enum class CaseType { TaylorGreen3D, TaylorGreen2D, Kolmogorov2D };

inline constexpr NameTable<CaseType, 3> kCaseNames{{{
    {CaseType::TaylorGreen3D, "tgv3d"},
    {CaseType::TaylorGreen2D, "tgv2d"},
    {CaseType::Kolmogorov2D, "kolmogorov2d"},
}}};
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

/// How the initial masses are set (docs/scenes.md, "initial"):
/// - Summation: M_i = ρ0_i V_i with V_i = 1/Σ_j W_ij (A.1) on the packed arrangement, so that the
///   summed density (A.2) equals the prescribed ρ0_i of the case exactly and the start is in
///   discrete equilibrium with the model (no sound radiated by mass errors);
/// - Lattice: the thesis' M0 = ρ0 Δl^n (SPEC §6.1), whose summed density differs from ρ0 by the
///   arrangement's deviation of Σ_j W_ij from 1/Δl^n.
enum class InitialMass { Summation, Lattice };

/// Scene names: "summation", "lattice".
inline constexpr NameTable<InitialMass, 2> kInitialMassNames{{{
    {InitialMass::Summation, "summation"},
    {InitialMass::Lattice, "lattice"},
}}};
std::string_view initial_mass_name(InitialMass mass);

struct InitialConfig {
  InitialMass mass = InitialMass::Summation;
};

/// Kolmogorov forcing a = χ sin(k_y y) e_x and linear friction -μ v (SPEC §6.3).
struct KolmogorovForcing {
  double amplitude = 1.8;  // χ [m/s²]
  int periods = 7;         // k_y = 2π periods / L (7 periods in 0.042 m: k_y = 1047.2 1/m)
  double friction = 0.7;   // μ [1/s]
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
  SchemeConfig scheme;       // SPH scheme (docs/models.md); the thesis model by default
  SubfilterConfig subfilter;
  KolmogorovForcing forcing;     // kolmogorov2d only
  double neighbour_skin = 0.15;  // fraction of H
  PackingConfig packing;
  InitialConfig initial;

  int dimension() const { return case_dimension(case_type); }
  double box_length() const { return box_length_; }  // L [m]
  double forcing_wavenumber() const;                 // k_y [1/m] (kolmogorov2d)
  double particle_spacing() const;                   // Δl = L / particles_per_side [m]
  double kernel_diameter() const;                    // D_K [m]
  std::size_t num_particles() const;
};

/// Bounds of scene keys are declared by the scene schema (scene/scene.schema.json, its "$comment"s
/// say why; docs/scenes.md, "Limits").
/// A non-zero cadence (output.timeseries_every, checkpoint.every, analysis.every) shorter than
/// a step cuts every step short to land on the next cadence point, so the run takes one step per
/// point: a cadence of 1e-9 s stalls it. A cadence is accepted when it is at least this fraction
/// of the estimated initial time step (the margin below 1 covers the estimate's error: exact
/// for the acoustic and viscous limits, approximate for the force limit), or when it has at
/// most kMaxShortCadencePoints points up to time.end (at most that many extra steps; the run
/// manager's live analysis default of 60 frames per run is one such cadence).
inline constexpr double kMinCadenceOverTimeStep = 0.5;
inline constexpr double kMaxShortCadencePoints = 1000.0;
/// The estimated initial time step must be at least this fraction of time.end: below it,
/// t + dt near the end time keeps fewer than 12 of dt's 53 significant bits (double precision),
/// and the run needs more than 2^40 steps.
inline constexpr double kMinTimeStepOverEndTime = 0x1p-40;

/// The solver's time-step limits (time_step_limits) at t = 0 for the scene's initial field,
/// without building it: |v|max <= |v0| + |U|; |a|max from the initial pressure gradient (5.2)
/// and viscous term of the Taylor-Green fields, or the forcing amplitude and the friction of
/// the uniform velocity (Kolmogorov flow, which starts at rest). The acoustic and viscous
/// limits are the solver's to round-off; the force limit leaves out the discretisation error of
/// the SPH sums.
struct TimeStepEstimate {
  TimeStepLimits limits;
  double max_speed = 0.0;         // [m/s]
  double max_acceleration = 0.0;  // [m/s²]
  double step() const { return limits.step(); }
};
TimeStepEstimate estimate_initial_time_step(const Scene& scene);

/// The smallest non-zero cadence accepted: the smaller of kMinCadenceOverTimeStep x the
/// estimated initial step and time.end / kMaxShortCadencePoints.
double min_cadence(const Scene& scene);

/// Throws SceneError naming `field` when 0 < every < min_cadence(scene) (0 keeps its meaning:
/// every step, or off).
void check_cadence(const Scene& scene, const std::string& field, double every);

/// The checks of a whole scene after its sections are read: the kernel fits in the box and the
/// estimated initial time step can advance time.end. Throws SceneError naming the field.
void check_scene(const Scene& scene);

/// The scene of a case with every key at its default (SPEC §6.1-6.3).
Scene case_defaults(CaseType type);

}  // namespace sphles::sim
