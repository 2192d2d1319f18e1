#include "analysis/grid.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

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

void check_grid(const Grid& grid) {
  if (grid.dimension != 2 && grid.dimension != 3)
    throw std::invalid_argument("grid: dimension must be 2 or 3");
  if (grid.points_per_side <= 0) throw std::invalid_argument("grid: points_per_side must be > 0");
  if (!(grid.length > 0.0)) throw std::invalid_argument("grid: length must be > 0");
}

/// Periodic cell list of C^n cubic cells of side w = L/C ≈ Δl, particle data copied in
/// cell-major order so that a cell's members are contiguous.
struct CellList {
  int cells_per_side = 1;                              // C
  double cell_size = 0.0;                              // w [m]
  std::vector<std::size_t> cell_start;                 // members of c: [start[c], start[c+1])
  std::array<std::vector<double>, 3> sorted_position;  // x of the members, cell-major
  std::vector<std::uint64_t> sorted_id;
  std::vector<std::uint32_t> sorted_index;  // index into ParticleArrays

  int cell_of(double x) const {
    return std::clamp(static_cast<int>(std::floor(x / cell_size)), 0, cells_per_side - 1);
  }
};

CellList build_cell_list(const Grid& grid, const sim::ParticleArrays& particles) {
  const int dim = grid.dimension;
  const std::size_t n = particles.size();
  CellList cells;
  // About one particle per cell: C = N^(1/n) cells per side.
  const double per_side = std::pow(static_cast<double>(n), 1.0 / dim);
  cells.cells_per_side = std::max(1, static_cast<int>(std::lround(per_side)));
  cells.cell_size = grid.length / cells.cells_per_side;
  const auto c_side = static_cast<std::size_t>(cells.cells_per_side);
  std::size_t num_cells = 1;
  for (int d = 0; d < dim; ++d) num_cells *= c_side;

  std::vector<std::size_t> cell(n);
  for (std::size_t i = 0; i < n; ++i) {
    std::size_t c = 0;
    for (int d = dim - 1; d >= 0; --d)
      c = c * c_side + static_cast<std::size_t>(cells.cell_of(particles.position[d][i]));
    cell[i] = c;
  }
  // Counting sort by cell (stable; the order within a cell does not affect the result).
  cells.cell_start.assign(num_cells + 1, 0);
  for (std::size_t i = 0; i < n; ++i) ++cells.cell_start[cell[i] + 1];
  for (std::size_t c = 0; c < num_cells; ++c) cells.cell_start[c + 1] += cells.cell_start[c];
  std::vector<std::size_t> fill(cells.cell_start.begin(), cells.cell_start.end() - 1);
  for (int d = 0; d < dim; ++d) cells.sorted_position[d].resize(n);
  cells.sorted_id.resize(n);
  cells.sorted_index.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t k = fill[cell[i]]++;
    for (int d = 0; d < dim; ++d) cells.sorted_position[d][k] = particles.position[d][i];
    cells.sorted_id[k] = particles.id[i];
    cells.sorted_index[k] = static_cast<std::uint32_t>(i);
  }
  return cells;
}

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

template <int Dim>
void fill_map(const CellList& cells, NearestParticleMap& map) {
  const Grid& grid = map.grid;
  const int m = grid.points_per_side;
  const double h = grid.spacing();
  const std::ptrdiff_t rows = Dim == 3 ? static_cast<std::ptrdiff_t>(m) * m : m;
  // Nodes are independent: any schedule gives the same map. Dynamic rows balance clustered sets.
#pragma omp parallel
  {
    std::vector<Candidate> candidates;
#pragma omp for schedule(dynamic, 1)
    for (std::ptrdiff_t row = 0; row < rows; ++row) {
      const int j = static_cast<int>(row % m);
      const int k = static_cast<int>(row / m);
      std::array<double, 3> x{0.0, j * h, k * h};
      const std::size_t row_start = grid.index(0, j, k);
      for (int i = 0; i < m; ++i) {
        x[0] = i * h;
        map.particle[row_start + static_cast<std::size_t>(i)] =
            nearest_to_point<Dim>(cells, x, grid.length, candidates);
      }
    }
  }
}

}  // namespace

NearestParticleMap nearest_particle_map(const Grid& grid, const sim::ParticleArrays& particles) {
  check_grid(grid);
  if (particles.dimension != grid.dimension)
    throw std::invalid_argument("nearest_particle_map: grid and particle dimensions differ");
  const std::size_t n = particles.size();
  if (n == 0) throw std::invalid_argument("nearest_particle_map: no particles");
  if (n > std::numeric_limits<std::uint32_t>::max())
    throw std::invalid_argument("nearest_particle_map: too many particles for 32-bit indices");
  if (particles.id.size() != n)
    throw std::invalid_argument("nearest_particle_map: particle ids missing");
  for (int d = 0; d < grid.dimension; ++d) {
    const auto [lo, hi] =
        std::minmax_element(particles.position[d].begin(), particles.position[d].end());
    if (*lo < 0.0 || *hi > grid.length)
      throw std::invalid_argument("nearest_particle_map: positions must lie in [0, L] (axis " +
                                  std::to_string(d) + ")");
  }

  const CellList cells = build_cell_list(grid, particles);
  NearestParticleMap map;
  map.grid = grid;
  map.particle.assign(grid.size(), 0);
  if (grid.dimension == 3) {
    fill_map<3>(cells, map);
  } else {
    fill_map<2>(cells, map);
  }
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
    if (remove_mean && nodes > 0) {
      // Spatial mean over the nodes (SPEC §5: spectra and vorticity of the fluctuation).
      const double mean =
          sim::deterministic_sum(nodes, [&](std::size_t n) { return u[n]; }) / nodes;
#pragma omp parallel for schedule(static)
      for (std::ptrdiff_t n = 0; n < signed_nodes; ++n) u[n] -= mean;
    }
  }
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
