#include "analysis/subfilter_stress.hpp"

// GCC 12 with -march=native (AVX-512) reports a false -Wmaybe-uninitialized inside its own
// avx512fintrin.h when Eigen's fixed-size eigen-solvers are inlined. The diagnostic is located in
// the intrinsics header, which Eigen includes first here.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <Eigen/Eigenvalues>
#pragma GCC diagnostic pop

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <type_traits>

#include "sim/kernels.hpp"
#include "sim/particles.hpp"

namespace sphles::analysis {
namespace {

// Tensor slot of the symmetric component (a, b), a, b < 3.
constexpr int kSlot[3][3] = {{kXX, kXY, kXZ}, {kXY, kYY, kYZ}, {kXZ, kYZ, kZZ}};

/// τ_SFS,i = Σ_j (v_j - v_i)(v_j - v_i)ᵀ W_ij M_j (3.27) in gather form: each particle sums over
/// its own neighbours in list order, so the result does not depend on the thread count. The self
/// pair (absent from the list) would contribute zero.
template <int Dim, class KernelT>
void stress_pass(const KernelT& kernel, const sim::PeriodicBox& box,
                 const sim::NeighbourList& neighbours, const sim::ParticleArrays& p,
                 std::vector<std::array<double, 6>>& tensor) {
  const double support2 = kernel.support_radius() * kernel.support_radius();
  double length[Dim], half_length[Dim];
  const double* x[Dim];
  const double* v[Dim];
  for (int d = 0; d < Dim; ++d) {
    length[d] = box.length[d];
    half_length[d] = 0.5 * box.length[d];
    x[d] = p.position[d].data();
    v[d] = p.velocity[d].data();
  }
  const double* mass = p.mass.data();
  const auto n = static_cast<std::ptrdiff_t>(p.size());
#pragma omp parallel for schedule(static, 512)
  for (std::ptrdiff_t si = 0; si < n; ++si) {
    const auto i = static_cast<std::size_t>(si);
    double xi[Dim], vi[Dim];
    for (int d = 0; d < Dim; ++d) {
      xi[d] = x[d][i];
      vi[d] = v[d][i];
    }
    double sum[Dim][Dim] = {};  // upper triangle used
    for (const std::uint32_t j : neighbours.of(i)) {
      double r2 = 0.0;
      for (int d = 0; d < Dim; ++d) {
        const double dx = sim::minimum_image(xi[d] - x[d][j], length[d], half_length[d]);
        r2 += dx * dx;
      }
      if (!(r2 < support2)) continue;
      const double weight = kernel.value(std::sqrt(r2)) * mass[j];  // W_ij M_j
      double dv[Dim];
      for (int d = 0; d < Dim; ++d) dv[d] = v[d][j] - vi[d];
      for (int a = 0; a < Dim; ++a)
        for (int b = a; b < Dim; ++b) sum[a][b] += dv[a] * dv[b] * weight;
    }
    std::array<double, 6>& t = tensor[i];
    t.fill(0.0);
    for (int a = 0; a < Dim; ++a)
      for (int b = a; b < Dim; ++b) t[kSlot[a][b]] = sum[a][b];
  }
}

/// Frobenius norm (4.7) and principal stresses/directions (4.8) of one tensor.
template <int Dim>
void principal_axes(const std::array<double, 6>& t, double& norm, std::array<double, 3>& values,
                    std::array<std::array<double, 3>, 3>& directions) {
  using Matrix = Eigen::Matrix<double, Dim, Dim>;
  Matrix m;
  double squares = 0.0;
  for (int a = 0; a < Dim; ++a) {
    for (int b = 0; b < Dim; ++b) {
      m(a, b) = t[kSlot[a][b]];
      squares += m(a, b) * m(a, b);
    }
  }
  norm = std::sqrt(squares);  // (4.7)

  // Iterative (not closed-form) solver: reconstruction accurate to round-off.
  const Eigen::SelfAdjointEigenSolver<Matrix> solver(m, Eigen::ComputeEigenvectors);
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

SubfilterStressField implicit_subfilter_stress(const Snapshot& snapshot,
                                               const sim::NeighbourList& neighbours) {
  const sim::ParticleArrays& p = snapshot.particles;
  const int dim = snapshot.dimension();
  if (dim != 2 && dim != 3) throw std::invalid_argument("sub-filter stress: dimension must be 2/3");
  if (p.dimension != dim)
    throw std::invalid_argument("sub-filter stress: particle and box dimensions differ");
  if (neighbours.num_particles() != p.size())
    throw std::invalid_argument("sub-filter stress: neighbour list does not match the particles");

  SubfilterStressField field;
  field.dimension = dim;
  field.tensor.resize(p.size());
  field.norm.resize(p.size());
  field.principal.resize(p.size());
  field.direction.resize(p.size());

  sim::with_kernel(snapshot.kernel, dim, snapshot.support_radius, [&](const auto& kernel) {
    constexpr int kDim = std::remove_cvref_t<decltype(kernel)>::dimension;
    stress_pass<kDim>(kernel, snapshot.box, neighbours, p, field.tensor);
    const auto n = static_cast<std::ptrdiff_t>(p.size());
#pragma omp parallel for schedule(static, 512)
    for (std::ptrdiff_t si = 0; si < n; ++si) {
      const auto i = static_cast<std::size_t>(si);
      principal_axes<kDim>(field.tensor[i], field.norm[i], field.principal[i], field.direction[i]);
    }
  });
  return field;
}

SubfilterStressField implicit_subfilter_stress(const Snapshot& snapshot) {
  sim::VerletNeighbourSearch search(snapshot.box, snapshot.support_radius, 0.0);
  search.build(sim::view_positions(snapshot.particles));
  return implicit_subfilter_stress(snapshot, search.list());
}

}  // namespace sphles::analysis
