// SPDX-License-Identifier: GPL-3.0-or-later
#include "analysis/subfilter_stress.hpp"

#include "sim/eigen.hpp"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <type_traits>

#include "analysis/cell_list.hpp"
#include "sim/kernels.hpp"
#include "sim/particles.hpp"

namespace sphles::analysis {
namespace {

// Tensor slot of the symmetric component (a, b), a, b < 3.
constexpr int kSlot[3][3] = {{kXX, kXY, kXZ}, {kXY, kYY, kYZ}, {kXZ, kYZ, kZZ}};

/// Frobenius norm (4.7) and principal stresses/directions (4.8) of one tensor.
template <int Dim>
void principal_axes(const std::array<double, 6>& t, double& norm, std::array<double, 3>& values,
                    std::array<std::array<double, 3>, 3>& directions) {
  using Matrix = Eigen::Matrix<double, Dim, Dim>;
  // 64-byte aligned: the same address-dependent loop splitting in Eigen on every thread's stack
  // (thread-count determinism; see directional_weight in sim/physics/viscous_operator.hpp).
  alignas(64) Matrix m;
  double squares = 0.0;
  for (int a = 0; a < Dim; ++a) {
    for (int b = 0; b < Dim; ++b) {
      m(a, b) = t[kSlot[a][b]];
      squares += m(a, b) * m(a, b);
    }
  }
  norm = std::sqrt(squares);  // (4.7)

  // Iterative (not closed-form) solver: reconstruction accurate to round-off.
  alignas(64) const Eigen::SelfAdjointEigenSolver<Matrix> solver(m, Eigen::ComputeEigenvectors);
  values.fill(0.0);
  for (auto& direction : directions) direction.fill(0.0);
  for (int a = 0; a < Dim; ++a) {
    const int k = Dim - 1 - a;  // Eigen sorts ascending; principal stresses are descending
    values[a] = solver.eigenvalues()(k);
    double largest = 0.0;
    for (int d = 0; d < Dim; ++d)
      largest = std::max(largest, std::abs(solver.eigenvectors()(d, k)));
    // Sign convention: the first non-negligible component is positive (deterministic output).
    double sign = 1.0;
    for (int d = 0; d < Dim; ++d) {
      const double c = solver.eigenvectors()(d, k);
      if (std::abs(c) > 1e-12 * largest) {
        sign = c < 0.0 ? -1.0 : 1.0;
        break;
      }
    }
    for (int d = 0; d < Dim; ++d) directions[a][d] = sign * solver.eigenvectors()(d, k);
  }
}

}  // namespace

SubfilterStressField implicit_subfilter_stress(const sim::ParticleArrays& p,
                                               const sim::PeriodicBox& box, sim::KernelType kernel,
                                               double support_radius, std::size_t centres) {
  const int dim = box.dimension;
  if (dim != 2 && dim != 3) throw std::invalid_argument("sub-filter stress: dimension must be 2/3");
  if (p.dimension != dim)
    throw std::invalid_argument("sub-filter stress: particle and box dimensions differ");
  centres = std::min(centres, p.size());
  SubfilterStressField field;
  field.dimension = dim;
  field.tensor.resize(centres);
  field.norm.resize(centres);
  field.principal.resize(centres);
  field.direction.resize(centres);
  if (centres == 0) return field;

  // The neighbours within H from the analysis' cell list (cells of side >= H/2, a cell's members
  // in id order): an order set by positions and ids alone, and no list to hold.
  Grid grid;
  grid.dimension = dim;
  grid.points_per_side = 1;
  grid.length = box.length[0];
  const CellList cells = build_gather_cell_list(grid, p, support_radius);
  const std::vector<int> offsets = gather_offsets(cells);
  sim::with_kernel(kernel, dim, support_radius, [&](const auto& w) {
    constexpr int kDim = std::remove_cvref_t<decltype(w)>::dimension;
    const auto n = static_cast<std::ptrdiff_t>(centres);
#pragma omp parallel for schedule(dynamic, 256)
    for (std::ptrdiff_t si = 0; si < n; ++si) {
      const auto i = static_cast<std::size_t>(si);
      std::array<double, 3> x{0.0, 0.0, 0.0}, v{0.0, 0.0, 0.0};
      for (int d = 0; d < kDim; ++d) {
        x[d] = p.position[d][i];
        v[d] = p.velocity[d][i];
      }
      // τ_SFS,i = Σ_j (v_j - v_i)(v_j - v_i)ᵀ W_ij M_j (3.27); j = i adds nothing, a particle on
      // top of another counts.
      std::array<double, 6>& t = field.tensor[i];
      t.fill(0.0);
      for_each_particle_within<kDim>(cells, offsets, x, support_radius, grid.length,
                                     [&](std::uint32_t j, const std::array<double, 3>&, double r2) {
                                       if (j == i) return;
                                       const double weight =
                                           w.value(std::sqrt(r2)) * p.mass[j];  // W_ij M_j
                                       double dv[3] = {0.0, 0.0, 0.0};
                                       for (int d = 0; d < kDim; ++d)
                                         dv[d] = p.velocity[d][j] - v[d];
                                       for (int a = 0; a < kDim; ++a)
                                         for (int b = a; b < kDim; ++b)
                                           t[kSlot[a][b]] += dv[a] * dv[b] * weight;
                                     });
      principal_axes<kDim>(t, field.norm[i], field.principal[i], field.direction[i]);
    }
  });
  return field;
}

SubfilterStressField implicit_subfilter_stress(const Snapshot& snapshot) {
  return implicit_subfilter_stress(snapshot.particles, snapshot.box, snapshot.kernel,
                                   snapshot.support_radius, snapshot.size());
}

}  // namespace sphles::analysis
