#include "analysis/subfilter_stress.hpp"

#include "sim/eigen.hpp"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <type_traits>

#include "sim/kernels.hpp"
#include "sim/pair_loop.hpp"
#include "sim/particles.hpp"

namespace sphles::analysis {
namespace {

// Tensor slot of the symmetric component (a, b), a, b < 3.
constexpr int kSlot[3][3] = {{kXX, kXY, kXZ}, {kXY, kYY, kYZ}, {kXZ, kYZ, kZZ}};

/// τ_SFS,i = Σ_j (v_j - v_i)(v_j - v_i)ᵀ W_ij M_j (3.27) as an evaluator of the pair loop
/// (sim/pair_loop.hpp; outputs: the upper triangle, row by row). The self pair (absent from the
/// list) would contribute zero; a particle on top of another counts.
template <int Dim, class KernelT>
struct StressSum {
  static constexpr int outputs = Dim * (Dim + 1) / 2;
  static constexpr bool coincident_pairs = true;
  struct Own {
    double v[Dim];
  };

  StressSum(const KernelT& kernel, const sim::ParticleArrays& p,
            std::vector<std::array<double, 6>>& tensor)
      : kernel_(kernel), mass_(p.mass.data()), tensor_(tensor.data()) {
    for (int d = 0; d < Dim; ++d) v_[d] = p.velocity[d].data();
  }

  Own own(std::size_t i) const {
    Own o;
    for (int d = 0; d < Dim; ++d) o.v[d] = v_[d][i];
    return o;
  }
  void pair(const Own& o, const sim::Pair<Dim>& q, double (&out)[outputs]) const {
    const double weight = kernel_.value(q.r) * mass_[q.j];  // W_ij M_j
    double dv[Dim];
    for (int d = 0; d < Dim; ++d) dv[d] = v_[d][q.j] - o.v[d];
    int slot = 0;
    for (int a = 0; a < Dim; ++a)
      for (int b = a; b < Dim; ++b) out[slot++] = dv[a] * dv[b] * weight;
  }
  void finish(std::size_t i, const Own&, const double (&sum)[outputs]) const {
    std::array<double, 6>& t = tensor_[i];
    t.fill(0.0);
    int slot = 0;
    for (int a = 0; a < Dim; ++a)
      for (int b = a; b < Dim; ++b) t[kSlot[a][b]] = sum[slot++];
  }

 private:
  KernelT kernel_;
  const double* v_[Dim];
  const double* mass_;
  std::array<double, 6>* tensor_;
};

/// Frobenius norm (4.7) and principal stresses/directions (4.8) of one tensor.
template <int Dim>
void principal_axes(const std::array<double, 6>& t, double& norm, std::array<double, 3>& values,
                    std::array<std::array<double, 3>, 3>& directions) {
  using Matrix = Eigen::Matrix<double, Dim, Dim>;
  // 64-byte aligned: the same address-dependent loop splitting in Eigen on every thread's stack
  // (thread-count determinism; see directional_weight in sim/viscous_operator.hpp).
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
  sim::VerletNeighbourSearch search(box, support_radius, 0.0);
  search.build(sim::view_positions(p), sim::order_by_key(p.id), centres);
  const sim::NeighbourList& neighbours = search.list();

  SubfilterStressField field;
  field.dimension = dim;
  field.tensor.resize(centres);
  field.norm.resize(centres);
  field.principal.resize(centres);
  field.direction.resize(centres);

  sim::with_kernel(kernel, dim, support_radius, [&](const auto& w) {
    constexpr int kDim = std::remove_cvref_t<decltype(w)>::dimension;
    sim::pair_pass<kDim>(StressSum<kDim, std::remove_cvref_t<decltype(w)>>(w, p, field.tensor),
                         sim::PeriodicGeometry<kDim>(box, p), neighbours, w.support_radius(), 0,
                         centres);
    const auto n = static_cast<std::ptrdiff_t>(centres);
#pragma omp parallel for schedule(static, 512)
    for (std::ptrdiff_t si = 0; si < n; ++si) {
      const auto i = static_cast<std::size_t>(si);
      principal_axes<kDim>(field.tensor[i], field.norm[i], field.principal[i], field.direction[i]);
    }
  });
  return field;
}

SubfilterStressField implicit_subfilter_stress(const Snapshot& snapshot) {
  return implicit_subfilter_stress(snapshot.particles, snapshot.box, snapshot.kernel,
                                   snapshot.support_radius, snapshot.size());
}

}  // namespace sphles::analysis
