// SPDX-License-Identifier: GPL-3.0-or-later
#include "analysis/grid.hpp"

#include "analysis/cell_list.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <type_traits>

#include "sim/reduction.hpp"

namespace sphles::analysis {

namespace {

/// Squared distances within this factor of the smallest one count as ties (the smaller id wins).
/// The window is far above the round-off of |Δx|² (a few 1e-16, which depends on the compiler's
/// choice of fused multiply-adds) and far below any physical scale, so that near-equidistant
/// particles (lattices, duplicates, symmetric sets) are decided by id and not by rounding: the map
/// is the same for any particle order, thread count and build.
constexpr double kTieFactor = 1.0 + 1e-12;

/// Margin (relative to L) on the search bound, which is computed differently from the distances.
constexpr double kBoundMargin = 1e-12;

struct Candidate {
  double r2;
  std::uint64_t id;
  std::uint32_t index;
};

/// Nearest particle to the point x by expanding rings of cells around x's cell: the particle of
/// smallest id among those with |Δx|² <= kTieFactor min |Δx|² (minimum image). `candidates` is
/// scratch space, reused between calls.
///
/// Each axis offset is taken from the window [-(C-1)/2, C/2], which holds every cell residue
/// exactly once, so no cell is scanned twice even when the rings wrap around a small box. Ring r
/// holds the offsets with max_d |o_d| = r. After rings 0..r, an unscanned cell differs from x's
/// cell c by more than r cells along some axis d in every periodic image, so all its particles are
/// at least r w + min(x_d - c_d w, (c_d + 1) w - x_d) away (the "bound"); the search stops when
/// the whole tie window is below the bound, or when r >= C/2 (every cell scanned).
template <int Dim>
std::uint32_t nearest_to_point(const CellList& cells, const std::array<double, 3>& x, double length,
                               std::vector<Candidate>& candidates) {
  const int c_side = cells.cells_per_side;
  const double w = cells.cell_size;
  const double half_length = 0.5 * length;
  const double margin = kBoundMargin * length;
  const int window_lo = -((c_side - 1) / 2);
  const int window_hi = c_side / 2;

  std::array<int, 3> home{0, 0, 0};
  double face_distance = std::numeric_limits<double>::max();
  for (int d = 0; d < Dim; ++d) {
    home[d] = cells.cell_of(x[d]);
    face_distance = std::min({face_distance, x[d] - home[d] * w, (home[d] + 1) * w - x[d]});
  }
  face_distance = std::max(face_distance, 0.0);

  // Every particle within the tie window of the current minimum is kept; the window only shrinks.
  double best_r2 = std::numeric_limits<double>::infinity();
  candidates.clear();

  const auto wrap = [c_side](int k) { return k < 0 ? k + c_side : (k >= c_side ? k - c_side : k); };
  const auto scan_cell = [&](int ox, int oy, int oz) {
    std::size_t c = static_cast<std::size_t>(wrap(home[0] + ox));
    if constexpr (Dim == 3) {
      c += static_cast<std::size_t>(c_side) *
           (static_cast<std::size_t>(wrap(home[1] + oy)) +
            static_cast<std::size_t>(c_side) * static_cast<std::size_t>(wrap(home[2] + oz)));
    } else {
      (void)oz;
      c += static_cast<std::size_t>(c_side) * static_cast<std::size_t>(wrap(home[1] + oy));
    }
    for (std::size_t k = cells.cell_start[c]; k < cells.cell_start[c + 1]; ++k) {
      double r2 = 0.0;
      for (int d = 0; d < Dim; ++d) {
        const double dx =
            sim::minimum_image(x[d] - cells.sorted_position[d][k], length, half_length);
        r2 += dx * dx;
      }
      if (r2 <= best_r2 * kTieFactor) {
        if (r2 < best_r2) {
          best_r2 = r2;
          const double window = best_r2 * kTieFactor;
          std::erase_if(candidates, [window](const Candidate& c) { return c.r2 > window; });
        }
        candidates.push_back({r2, cells.sorted_id[k], cells.sorted_index[k]});
      }
    }
  };

  for (int r = 0;; ++r) {
    const int lo = std::max(window_lo, -r);
    const int hi = std::min(window_hi, r);
    const int z_lo = Dim == 3 ? lo : 0;
    const int z_hi = Dim == 3 ? hi : 0;
    for (int oz = z_lo; oz <= z_hi; ++oz) {
      for (int oy = lo; oy <= hi; ++oy) {
        const bool on_shell = r == 0 || oy == -r || oy == r || (Dim == 3 && (oz == -r || oz == r));
        if (on_shell) {
          for (int ox = lo; ox <= hi; ++ox) scan_cell(ox, oy, oz);
        } else {
          if (-r >= window_lo) scan_cell(-r, oy, oz);
          if (r <= window_hi) scan_cell(r, oy, oz);
        }
      }
    }
    if (r >= window_hi) break;  // every cell scanned
    const double bound = r * w + face_distance - margin;
    if (bound > 0.0 && best_r2 * kTieFactor < bound * bound) break;
  }
  const auto winner =
      std::min_element(candidates.begin(), candidates.end(),
                       [](const Candidate& a, const Candidate& b) { return a.id < b.id; });
  return winner->index;
}

/// The nearest particle of every node of `block` (x fastest), and the largest squared distance
/// to a nearest particle (minimum image).
template <int Dim>
NearestInBlock fill_block(const CellList& cells, const sim::ParticleArrays& particles,
                          const Grid& grid, const NodeBlock& block) {
  const double h = grid.spacing();
  const double length = grid.length;
  const double half_length = 0.5 * length;
  NearestInBlock result;
  result.particle.assign(block.size(), 0);
  const auto row_length = static_cast<std::size_t>(block.count[0]);
  const std::ptrdiff_t rows = static_cast<std::ptrdiff_t>(block.count[1]) * block.count[2];
  double max_r2 = 0.0;
  // Nodes are independent: any schedule gives the same map. Dynamic rows balance clustered sets.
#pragma omp parallel reduction(max : max_r2)
  {
    std::vector<Candidate> candidates;
#pragma omp for schedule(dynamic, 1)
    for (std::ptrdiff_t row = 0; row < rows; ++row) {
      const int j = block.first[1] + static_cast<int>(row % block.count[1]);
      const int k = block.first[2] + static_cast<int>(row / block.count[1]);
      std::array<double, 3> x{0.0, j * h, k * h};
      std::uint32_t* nearest = result.particle.data() + static_cast<std::size_t>(row) * row_length;
      for (std::size_t a = 0; a < row_length; ++a) {
        x[0] = (block.first[0] + static_cast<int>(a)) * h;
        const std::uint32_t p = nearest_to_point<Dim>(cells, x, length, candidates);
        nearest[a] = p;
        double r2 = 0.0;
        for (int d = 0; d < Dim; ++d) {
          const double dx = sim::minimum_image(
              x[static_cast<std::size_t>(d)] - particles.position[static_cast<std::size_t>(d)][p],
              length, half_length);
          r2 += dx * dx;
        }
        max_r2 = std::max(max_r2, r2);
      }
    }
  }
  result.max_distance2 = max_r2;
  return result;
}

NearestInBlock nearest_in_block(const Grid& grid, const sim::ParticleArrays& particles,
                                const NodeBlock& block, int cells_per_side, const char* what) {
  check_particles(grid, particles, what);
  if (particles.id.size() != particles.size())
    throw std::invalid_argument(std::string(what) + ": particle ids missing");
  for (int d = 0; d < 3; ++d) {
    const auto k = static_cast<std::size_t>(d);
    const int side = d < grid.dimension ? grid.points_per_side : 1;
    if (block.first[k] < 0 || block.count[k] < 0 || block.first[k] + block.count[k] > side)
      throw std::invalid_argument(std::string(what) + ": node block outside the grid (axis " +
                                  std::to_string(d) + ")");
  }
  const CellList cells = build_cell_list(grid, particles, std::max(cells_per_side, 1));
  return grid.dimension == 3 ? fill_block<3>(cells, particles, grid, block)
                             : fill_block<2>(cells, particles, grid, block);
}

}  // namespace

NearestInBlock nearest_particles_in_block(const Grid& grid, const sim::ParticleArrays& particles,
                                          const NodeBlock& block, int cells_per_side) {
  return nearest_in_block(grid, particles, block, cells_per_side, "nearest_particles_in_block");
}

NearestParticleMap nearest_particle_map(const Grid& grid, const sim::ParticleArrays& particles) {
  // About one particle per cell: C = N^(1/n) cells per side.
  const double per_side = std::pow(static_cast<double>(particles.size()), 1.0 / grid.dimension);
  NodeBlock all;
  for (int d = 0; d < grid.dimension; ++d)
    all.count[static_cast<std::size_t>(d)] = grid.points_per_side;
  NearestParticleMap map;
  map.grid = grid;
  map.particle = nearest_in_block(grid, particles, all, static_cast<int>(std::lround(per_side)),
                                  "nearest_particle_map")
                     .particle;
  return map;
}

VectorField sample_velocity(const NearestParticleMap& map, const sim::ParticleArrays& particles,
                            bool remove_mean) {
  const std::size_t nodes = map.particle.size();
  if (nodes > 0 && *std::max_element(map.particle.begin(), map.particle.end()) >= particles.size())
    throw std::invalid_argument("sample_velocity: the map refers to missing particles");
  VectorField field;
  field.grid = map.grid;
  const auto signed_nodes = static_cast<std::ptrdiff_t>(nodes);
  for (int d = 0; d < map.grid.dimension; ++d) {
    if (particles.velocity[d].size() != particles.size())
      throw std::invalid_argument("sample_velocity: velocity arrays do not match the particles");
    const std::vector<double>& v = particles.velocity[d];
    std::vector<double>& u = field.component[d];
    u.resize(nodes);
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t n = 0; n < signed_nodes; ++n) u[n] = v[map.particle[n]];
  }
  if (remove_mean) remove_spatial_mean(field);
  return field;
}

void remove_spatial_mean(VectorField& field) {
  const std::size_t nodes = field.grid.size();
  if (nodes == 0) return;
  const auto signed_nodes = static_cast<std::ptrdiff_t>(nodes);
  for (int d = 0; d < field.grid.dimension; ++d) {
    std::vector<double>& u = field.component[d];
    if (u.size() != nodes)
      throw std::invalid_argument("remove_spatial_mean: component size does not match the grid");
    // Spatial mean over the nodes (SPEC §5: spectra and vorticity of the fluctuation).
    const double mean = sim::deterministic_sum(nodes, [&](std::size_t n) { return u[n]; }) / nodes;
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t n = 0; n < signed_nodes; ++n) u[n] -= mean;
  }
}

namespace {

/// A particle near a node row: its cell along x, x itself, its squared distance to the row's
/// axis (the y, z part of |x_n - x_j|², the same for every node of the row) and its index.
struct RowCandidate {
  double x;
  double transverse_r2;
  std::uint32_t index;
};

/// Shepard sums of every node in gather form, row by row (fixed j, k). A row first collects the
/// particles within H of its axis from the cell columns around it, grouped by x cell (ascending),
/// so that each node only looks at the x cells within reach and one coordinate. Per node the
/// order is fixed (x-cell offset ascending; within a cell: z, y offsets, then ascending particle
/// index), so the sums do not depend on the thread count.
template <int Dim, class KernelT>
void shepard_fill(const KernelT& kernel, const CellList& cells, const Grid& grid,
                  const sim::ParticleArrays& particles,
                  std::span<const std::span<const double>> fields,
                  std::vector<std::vector<double>>& out) {
  const int m = grid.points_per_side;
  const double h = grid.spacing();
  const double length = grid.length;
  const double half_length = 0.5 * length;
  const double support2 = kernel.support_radius() * kernel.support_radius();
  const int c_side = cells.cells_per_side;
  const auto side = static_cast<std::size_t>(c_side);
  const std::vector<int> offsets = gather_offsets(cells);
  const std::vector<int> no_offset{0};
  const std::vector<int>& z_offsets = Dim == 3 ? offsets : no_offset;
  const double* volume = particles.volume.data();
  const std::size_t num_fields = fields.size();
  const auto wrap = [c_side](int k) { return ((k % c_side) + c_side) % c_side; };
  const std::ptrdiff_t rows = Dim == 3 ? static_cast<std::ptrdiff_t>(m) * m : m;

#pragma omp parallel
  {
    std::vector<double> sums(num_fields);
    std::vector<RowCandidate> candidates;
    std::vector<std::size_t> x_cell_start(side + 1);
#pragma omp for schedule(dynamic, 1)
    for (std::ptrdiff_t row = 0; row < rows; ++row) {
      const int j = static_cast<int>(row % m);
      const int k = static_cast<int>(row / m);
      const double y = j * h, z = k * h;
      const int home_y = cells.cell_of(y);
      const int home_z = Dim == 3 ? cells.cell_of(z) : 0;
      // The row's candidates, grouped by x cell.
      candidates.clear();
      for (std::size_t cx = 0; cx < side; ++cx) {
        x_cell_start[cx] = candidates.size();
        for (const int oz : z_offsets)
          for (const int oy : offsets) {
            std::size_t c = cx + side * static_cast<std::size_t>(wrap(home_y + oy));
            if constexpr (Dim == 3) c += side * side * static_cast<std::size_t>(wrap(home_z + oz));
            for (std::size_t s = cells.cell_start[c]; s < cells.cell_start[c + 1]; ++s) {
              const double dy =
                  sim::minimum_image(y - cells.sorted_position[1][s], length, half_length);
              double transverse = dy * dy;
              if constexpr (Dim == 3) {
                const double dz =
                    sim::minimum_image(z - cells.sorted_position[2][s], length, half_length);
                transverse += dz * dz;
              }
              if (transverse < support2)
                candidates.push_back(
                    {cells.sorted_position[0][s], transverse, cells.sorted_index[s]});
            }
          }
      }
      x_cell_start[side] = candidates.size();

      const std::size_t row_start = grid.index(0, j, k);
      for (int i = 0; i < m; ++i) {
        const double x = i * h;
        const int home_x = cells.cell_of(x);
        std::fill(sums.begin(), sums.end(), 0.0);
        double weight_sum = 0.0;
        for (const int ox : offsets) {
          const auto cx = static_cast<std::size_t>(wrap(home_x + ox));
          for (std::size_t q = x_cell_start[cx]; q < x_cell_start[cx + 1]; ++q) {
            const RowCandidate& candidate = candidates[q];
            const double dx = sim::minimum_image(x - candidate.x, length, half_length);
            const double r2 = dx * dx + candidate.transverse_r2;
            if (!(r2 < support2)) continue;
            const std::uint32_t p = candidate.index;
            const double weight = kernel.value(std::sqrt(r2)) * volume[p];  // W(x_n - x_j) V_j
            weight_sum += weight;
            for (std::size_t f = 0; f < num_fields; ++f) sums[f] += fields[f][p] * weight;
          }
        }
        const std::size_t node = row_start + static_cast<std::size_t>(i);
        for (std::size_t f = 0; f < num_fields; ++f)
          out[f][node] = shepard_value(sums[f], weight_sum);
      }
    }
  }
}

}  // namespace

std::vector<std::vector<double>> shepard_sample(const Grid& grid,
                                                const sim::ParticleArrays& particles,
                                                const InterpolationKernel& kernel,
                                                std::span<const std::span<const double>> fields) {
  check_particles(grid, particles, "shepard_sample");
  const std::size_t n = particles.size();
  if (particles.volume.size() != n)
    throw std::invalid_argument("shepard_sample: particle volumes missing");
  for (const std::span<const double> f : fields)
    if (f.size() != n)
      throw std::invalid_argument("shepard_sample: a field does not have one value per particle");
  if (!(kernel.support_radius > 0.0))
    throw std::invalid_argument("shepard_sample: kernel support radius must be > 0");

  const CellList cells = build_gather_cell_list(grid, particles, kernel.support_radius);
  std::vector<std::vector<double>> out(fields.size(), std::vector<double>(grid.size(), 0.0));
  sim::with_kernel(kernel.type, grid.dimension, kernel.support_radius, [&](const auto& k) {
    constexpr int kDim = std::remove_cvref_t<decltype(k)>::dimension;
    shepard_fill<kDim>(k, cells, grid, particles, fields, out);
  });
  return out;
}

VectorField shepard_velocity(const Grid& grid, const sim::ParticleArrays& particles,
                             const InterpolationKernel& kernel, bool remove_mean) {
  std::vector<std::span<const double>> fields;
  for (int d = 0; d < grid.dimension; ++d) {
    if (particles.velocity[d].size() != particles.size())
      throw std::invalid_argument("shepard_velocity: velocity arrays do not match the particles");
    fields.emplace_back(particles.velocity[d]);
  }
  std::vector<std::vector<double>> sampled = shepard_sample(grid, particles, kernel, fields);
  VectorField field;
  field.grid = grid;
  for (int d = 0; d < grid.dimension; ++d) field.component[d] = std::move(sampled[d]);
  if (remove_mean) remove_spatial_mean(field);
  return field;
}

std::vector<double> sample_scalar(const NearestParticleMap& map,
                                  std::span<const double> per_particle) {
  const std::size_t nodes = map.particle.size();
  if (nodes > 0 &&
      *std::max_element(map.particle.begin(), map.particle.end()) >= per_particle.size())
    throw std::invalid_argument("sample_scalar: fewer values than particles in the map");
  std::vector<double> values(nodes);
  const auto signed_nodes = static_cast<std::ptrdiff_t>(nodes);
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t n = 0; n < signed_nodes; ++n) values[n] = per_particle[map.particle[n]];
  return values;
}

std::vector<std::size_t> nearest_node(const Grid& grid, const sim::ParticleArrays& particles) {
  check_grid(grid);
  if (particles.dimension != grid.dimension)
    throw std::invalid_argument("nearest_node: grid and particle dimensions differ");
  const int m = grid.points_per_side;
  const double inv_h = 1.0 / grid.spacing();
  const std::size_t n = particles.size();
  std::vector<std::size_t> node(n);
  const auto signed_n = static_cast<std::ptrdiff_t>(n);
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t p = 0; p < signed_n; ++p) {
    std::array<int, 3> ijk{0, 0, 0};
    for (int d = 0; d < grid.dimension; ++d) {
      // round(x/h) mod M: a particle just below L belongs to node 0.
      const auto k = static_cast<long long>(std::floor(particles.position[d][p] * inv_h + 0.5));
      ijk[d] = static_cast<int>(((k % m) + m) % m);
    }
    node[p] = grid.index(ijk[0], ijk[1], ijk[2]);
  }
  return node;
}

}  // namespace sphles::analysis
