// SPDX-License-Identifier: GPL-3.0-or-later
// What a reference run needs before it starts: memory, checkpoint size, the largest wavenumber
// and the steps to the end (docs/reference.md), as `sphles estimate` and the service's admission
// use it.
#include <algorithm>
#include <cmath>

#include "spectral/fourier_terms.hpp"
#include "spectral/reference_run.hpp"

namespace sphles::spectral {

namespace {

// The program's own resident memory (code, VTK and OSMesa for the frames, the MPI and HDF5
// libraries): the peak RSS of an 8³ reference run, 148 MB.
constexpr double kProgramFootprintBytes = 150e6;

}  // namespace

ReferenceEstimate estimate_reference(const sim::Scene& scene, const ReferenceConfig& config,
                                     int ranks) {
  const double n = config.points_per_side, d = scene.dimension();
  // This rank's share: the planes of the largest slab (slab_exchange.hpp).
  const double share = d == 3 ? std::ceil(n / std::max(1, ranks)) / n : 1.0;
  const double complex_size = (n / 2 + 1) * std::pow(n, d - 1), real_size = std::pow(n, d);
  const double vorticity = d == 3 ? 3.0 : 1.0;
  const double complex_bytes = 16.0 * complex_size, real_bytes = 8.0 * real_size;
  // NavierStokesSolver: state, N(û), stage, sum (d each), two transform scratch arrays and the
  // transform's slab (3D), the integrating factors, and the grid velocity and vorticity of the
  // nonlinear term.
  const double solver = (4.0 * d + (d == 3 ? 3.0 : 2.0)) * complex_bytes + 8.0 * complex_size +
                        (d + vorticity) * real_bytes;
  // A frame's vorticity (modes, grid, scratch), or a checkpoint's gathered copy and HDF5 image
  // (the whole state, on rank 0).
  const double frame = (vorticity + 1.0) * complex_bytes + vorticity * real_bytes;
  const double checkpoint = 2.0 * d * complex_bytes;
  ReferenceEstimate e;
  e.memory_bytes = share * solver + std::max(share * frame, checkpoint) + kProgramFootprintBytes;
  e.checkpoint_bytes = d * complex_bytes;
  e.max_wavenumber = dealiased_max_wavenumber(config.points_per_side);
  // The initial largest Σ|u_i|: v0 (Taylor-Green) or the laminar speed the forcing drives
  // (Kolmogorov flow), plus the uniform velocity.
  double speed = std::abs(scene.uniform_velocity[0]) + std::abs(scene.uniform_velocity[1]) +
                 std::abs(scene.uniform_velocity[2]);
  if (scene.case_type == sim::CaseType::Kolmogorov2D) {
    const double k = scene.forcing_wavenumber();
    speed += scene.forcing.amplitude /
             (scene.fluid.kinematic_viscosity() * k * k + scene.forcing.friction);
  } else {
    speed += std::abs(scene.velocity_amplitude);
  }
  const double dt = config.cfl * scene.box_length() / n / std::max(speed, 1e-300);
  e.steps = std::ceil(scene.end_time / dt);
  return e;
}

}  // namespace sphles::spectral
