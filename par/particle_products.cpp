// SPDX-License-Identifier: GPL-3.0-or-later
#include "par/particle_products.hpp"

#include <mpi.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "analysis/grid.hpp"
#include "analysis/products.hpp"
#include "analysis/statistics.hpp"
#include "analysis/subfilter_stress.hpp"
#include "analysis/vorticity.hpp"
#include "io/particle_snapshot_collective.hpp"
#include "par/grid_share.hpp"
#include "par/halo.hpp"
#include "par/reduce.hpp"
#include "par/state.hpp"
#include "sim/reduction.hpp"

namespace sphles::par {

namespace {

/// The slice's nodes inside this rank's sub-box, as a block of the grid (one plane thick along
/// the slice's normal in 3D, every node of the sub-box in 2D), and where each of its nodes (x
/// fastest) sits in the slice (analysis::slice_nodes order).
struct SliceShare {
  analysis::NodeBlock block;
  std::vector<std::size_t> nodes;  // grid node indices, block order
  std::vector<int> where;          // positions in the slice, block order
  std::size_t slice_size = 0;
};

SliceShare slice_share(const Decomposition& d, const analysis::Grid& grid,
                       const analysis::RanksRequest& request) {
  const int dim = grid.dimension;
  analysis::SliceConfig config;
  config.axis = request.slice_axis;
  config.position = request.slice_position;
  const std::vector<std::size_t> slice = analysis::slice_nodes(grid, config);
  SliceShare share;
  share.slice_size = slice.size();
  share.block = own_block(d, grid);
  const auto m = static_cast<std::size_t>(grid.points_per_side);
  if (dim == 3) {
    // The slice's plane along its normal: that of its first node.
    const auto normal = static_cast<std::size_t>(config.axis);
    const std::array<std::size_t, 3> at{slice[0] % m, (slice[0] / m) % m, slice[0] / (m * m)};
    const auto plane = static_cast<int>(at[normal]);
    const bool mine = plane >= share.block.first[normal] &&
                      plane < share.block.first[normal] + share.block.count[normal];
    share.block.first[normal] = mine ? plane : 0;
    share.block.count[normal] = mine ? 1 : 0;
  }
  std::vector<std::pair<std::size_t, int>> position(slice.size());
  for (std::size_t k = 0; k < slice.size(); ++k) position[k] = {slice[k], static_cast<int>(k)};
  std::sort(position.begin(), position.end());
  const analysis::NodeBlock& b = share.block;
  for (int z = 0; z < b.count[2]; ++z)
    for (int y = 0; y < b.count[1]; ++y)
      for (int x = 0; x < b.count[0]; ++x) {
        const std::size_t node = grid.index(b.first[0] + x, b.first[1] + y, b.first[2] + z);
        const auto found = std::lower_bound(position.begin(), position.end(),
                                            std::pair<std::size_t, int>{node, -1});
        share.nodes.push_back(node);
        share.where.push_back(found->second);
      }
  return share;
}

/// Rank 0 receives every rank's values and puts each at its position in the slice; the other
/// ranks get an empty vector. Collective over d.comm().
std::vector<double> gather_slice(const Decomposition& d, const SliceShare& share,
                                 const std::vector<double>& values) {
  const int sent = static_cast<int>(share.where.size());
  std::vector<int> counts(static_cast<std::size_t>(d.size())), offsets(counts.size(), 0);
  MPI_Gather(&sent, 1, MPI_INT, counts.data(), 1, MPI_INT, 0, d.comm());
  for (std::size_t r = 1; r < counts.size(); ++r) offsets[r] = offsets[r - 1] + counts[r - 1];
  const bool root = d.rank() == 0;
  std::vector<int> where(root ? share.slice_size : 0);
  std::vector<double> received(root ? share.slice_size : 0);
  MPI_Gatherv(share.where.data(), sent, MPI_INT, where.data(), counts.data(), offsets.data(),
              MPI_INT, 0, d.comm());
  MPI_Gatherv(values.data(), sent, MPI_DOUBLE, received.data(), counts.data(), offsets.data(),
              MPI_DOUBLE, 0, d.comm());
  std::vector<double> slice(root ? share.slice_size : 0);
  for (std::size_t k = 0; k < received.size(); ++k)
    slice[static_cast<std::size_t>(where[k])] = received[k];
  return slice;
}

/// max over the ranks of each value, on every rank.
void allreduce_max(const Decomposition& d, std::span<double> values) {
  MPI_Allreduce(MPI_IN_PLACE, values.data(), static_cast<int>(values.size()), MPI_DOUBLE, MPI_MAX,
                d.comm());
}

/// The particle snapshot request.particles.path from the own particles (the first `mine` of
/// `local`) and their fields, each rank its equal id block (par::columns_in_id_block) written
/// into the one file. Collective over d.comm().
analysis::WrittenParticles write_particles(const Decomposition& d, const sim::ParticleArrays& local,
                                           std::size_t mine, const std::vector<double>& omega2,
                                           const std::vector<double>& tau, bool eddy,
                                           const analysis::RanksRequest& request) {
  const int dim = d.dimension();
  analysis::WrittenParticles written;
  std::vector<std::pair<analysis::SliceField, const std::vector<double>*>> asked;
  if (request.particles.omega2) asked.emplace_back(analysis::SliceField::VorticitySquared, &omega2);
  if (request.particles.tau) asked.emplace_back(analysis::SliceField::SubfilterStressNorm, &tau);
  if (eddy) asked.emplace_back(analysis::SliceField::EddyViscosity, &local.eddy_viscosity);
  // The own particles' columns (the first `mine` entries of each array): position and velocity
  // per axis, mass, density, pressure, the fields.
  std::vector<std::span<const double>> columns;
  const auto column = [&](const std::vector<double>& values) {
    columns.emplace_back(values.data(), mine);
  };
  for (int a = 0; a < dim; ++a) column(local.position[a]);
  for (int a = 0; a < dim; ++a) column(local.velocity[a]);
  column(local.mass);
  column(local.density);
  column(local.pressure);
  for (const auto& [field, values] : asked) column(*values);
  IdBlockColumns block =
      columns_in_id_block(d, std::span<const std::uint64_t>(local.id.data(), mine), columns);
  sim::ParticleArrays rows;
  rows.dimension = dim;
  const std::size_t count = block.columns.empty() ? 0 : block.columns[0].size();
  rows.resize(count);
  std::size_t c = 0;
  for (int a = 0; a < dim; ++a) rows.position[a].swap(block.columns[c++]);
  for (int a = 0; a < dim; ++a) rows.velocity[a].swap(block.columns[c++]);
  rows.mass.swap(block.columns[c++]);
  rows.density.swap(block.columns[c++]);
  rows.pressure.swap(block.columns[c++]);
  std::iota(rows.id.begin(), rows.id.end(), block.first);
  std::vector<io::ParticleField> extra;
  for (const auto& [field, values] : asked) {
    extra.push_back({std::string(analysis::slice_field_name(field)),
                     std::string(analysis::slice_field_units(field)),
                     std::move(block.columns[c++])});
    written.fields.push_back(field);
  }
  io::write_particle_snapshot_collective(d.comm(), request.particles.path, rows, block.first,
                                         block.total, request.particles.time,
                                         request.particles.step, extra, request.particles.metadata);
  written.count = block.total;
  return written;
}

/// Every node of the grid inside this rank's sub-box, each at its own index (the whole grid as
/// one "slice": gather_slice then assembles the grid on rank 0). Throws std::invalid_argument
/// when the grid's nodes exceed MPI's int counts.
SliceShare grid_share(const Decomposition& d, const analysis::Grid& grid) {
  if (grid.size() > static_cast<std::size_t>(std::numeric_limits<int>::max()))
    throw std::invalid_argument("distributed particle products: a grid of " +
                                std::to_string(grid.size()) +
                                " nodes exceeds MPI's int counts for gathering it");
  SliceShare share;
  share.slice_size = grid.size();
  share.block = own_block(d, grid);
  const analysis::NodeBlock& b = share.block;
  for (int z = 0; z < b.count[2]; ++z)
    for (int y = 0; y < b.count[1]; ++y)
      for (int x = 0; x < b.count[0]; ++x) {
        const std::size_t node = grid.index(b.first[0] + x, b.first[1] + y, b.first[2] + z);
        share.nodes.push_back(node);
        share.where.push_back(static_cast<int>(node));
      }
  return share;
}

/// What the values at nodes come from: this rank's particles and halo (`local`, with ω and
/// |τ_SFS| of the halo filled in where asked), the fits and the particle count.
struct NodeSources {
  const Decomposition& d;
  const analysis::Grid& grid;
  const sim::ParticleArrays& local;
  const analysis::FitSettings& fit;
  const analysis::ParticleVorticity& omega;
  const std::vector<double>& norm;
  std::uint64_t total;
};

/// Values at a share's nodes, on rank 0 in the share's order (empty on the others, and unless
/// asked): ω² fitted there, and |τ_SFS|, ν_t and the velocity of each node's nearest particle.
struct NodeValues {
  std::vector<double> omega2, tau, eddy;
  std::array<std::vector<double>, 3> velocity;
};

NodeValues node_values(const NodeSources& s, const SliceShare& share, bool omega2, bool tau,
                       bool eddy, bool velocity) {
  const Decomposition& d = s.d;
  const int dim = d.dimension();
  // The nodes' nearest particles (for |τ_SFS|, ν_t and the velocity), and the refusal of a void
  // wider than the halo (for the fits too: a rank with nodes and no particle).
  const analysis::NearestInBlock nearest =
      nearest_within_halo(d, s.grid, s.local, share.block, s.total, "distributed particle products",
                          tau || eddy || velocity);
  NodeValues v;
  if (omega2) {
    std::vector<double> values;
    if (!share.nodes.empty())
      values = analysis::fitted_vorticity_squared(s.grid, s.local, s.fit, s.omega, share.nodes);
    v.omega2 = gather_slice(d, share, values);
  }
  if (!tau && !eddy && !velocity) return v;
  const auto at_nearest = [&](const std::vector<double>& field) {
    std::vector<double> values(share.nodes.size());
    for (std::size_t k = 0; k < values.size(); ++k) values[k] = field[nearest.particle[k]];
    return gather_slice(d, share, values);
  };
  if (tau) v.tau = at_nearest(s.norm);
  if (eddy) v.eddy = at_nearest(s.local.eddy_viscosity);
  if (velocity)
    for (int a = 0; a < dim; ++a)
      v.velocity[static_cast<std::size_t>(a)] = at_nearest(s.local.velocity[a]);
  return v;
}

/// The 3D particle view's points on rank 0 (empty on the others): each rank selects its own
/// particles (the first `mine` of `local`) whose id is a multiple of the stride, rank 0
/// receives them and sorts them by id, as analysis::select_view_points does for all particles.
/// Collective over d.comm().
analysis::ViewPoints gather_view_points(const Decomposition& d, const sim::ParticleArrays& local,
                                        std::size_t mine, std::span<const double> values,
                                        analysis::SliceField field, std::uint64_t total,
                                        std::uint64_t max_points) {
  const int dim = d.dimension();
  const std::uint64_t stride = analysis::view_stride(total, max_points);
  const std::vector<std::size_t> chosen = analysis::view_point_indices(local, mine, stride);
  const analysis::ViewPoints own = analysis::view_points_at(local, chosen, values, field, stride);
  // Ids and the columns of the selected particles, rank by rank to rank 0.
  std::vector<std::uint64_t> ids;
  for (const std::size_t i : chosen) ids.push_back(local.id[i]);
  const int sent = static_cast<int>(ids.size());
  std::vector<int> counts(static_cast<std::size_t>(d.size())), offsets(counts.size(), 0);
  MPI_Gather(&sent, 1, MPI_INT, counts.data(), 1, MPI_INT, 0, d.comm());
  for (std::size_t r = 1; r < counts.size(); ++r) offsets[r] = offsets[r - 1] + counts[r - 1];
  const bool root = d.rank() == 0;
  const std::size_t received = root ? static_cast<std::size_t>(offsets.back() + counts.back()) : 0;
  std::vector<std::uint64_t> all_ids(received);
  MPI_Gatherv(ids.data(), sent, MPI_UINT64_T, all_ids.data(), counts.data(), offsets.data(),
              MPI_UINT64_T, 0, d.comm());
  const auto gather = [&](const std::vector<double>& column) {
    std::vector<double> all(received);
    MPI_Gatherv(column.data(), sent, MPI_DOUBLE, all.data(), counts.data(), offsets.data(),
                MPI_DOUBLE, 0, d.comm());
    return all;
  };
  std::array<std::vector<double>, 3> position;
  for (int a = 0; a < dim; ++a)
    position[static_cast<std::size_t>(a)] = gather(own.position[static_cast<std::size_t>(a)]);
  const std::vector<double> all_values = gather(own.values);
  analysis::ViewPoints v;
  v.field = field;
  v.stride = stride;
  if (!root) return v;
  std::vector<std::size_t> order(received);
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::sort(order.begin(), order.end(),
            [&](std::size_t a, std::size_t b) { return all_ids[a] < all_ids[b]; });
  for (int a = 0; a < dim; ++a) {
    const auto axis = static_cast<std::size_t>(a);
    for (const std::size_t k : order) v.position[axis].push_back(position[axis][k]);
  }
  for (const std::size_t k : order) v.values.push_back(all_values[k]);
  return v;
}

/// What a request needs: the particle file, what is computed at the particles, and a slice.
struct Needs {
  bool particles = false;  // the particle snapshot file
  bool fits = false;       // ω fitted at the particles (the "mls" estimate)
  bool stress = false;     // τ_SFS at the particles
  bool slice = false;      // a slice of ω², |τ_SFS| or ν_t
};

/// What `request` needs; throws std::invalid_argument (on every rank alike) when the ranks cannot
/// answer it: a box that is not a cube, no grid, or a fit radius outside (0, L/2] or (with more
/// than one rank along an axis) wider than the halo.
Needs needs_of(const Decomposition& d, const analysis::RanksRequest& request) {
  const int dim = d.dimension();
  const sim::PeriodicBox& box = d.box();
  for (int a = 1; a < dim; ++a)
    if (box.length[static_cast<std::size_t>(a)] != box.length[0])
      throw std::invalid_argument("distributed particle products: the box must be a cube");
  Needs needs;
  needs.particles = !request.particles.path.empty();
  const analysis::ViewPointsRequest& view = request.view;
  const auto view_of = [&](analysis::SliceField f) {
    return view.max_points > 0 && view.field == f;
  };
  needs.fits = request.vorticity || request.slice_omega2 || request.statistics ||
               (needs.particles && request.particles.omega2) || request.fields.omega2 ||
               view_of(analysis::SliceField::VorticitySquared);
  needs.stress = request.slice_tau || request.statistics ||
                 (needs.particles && request.particles.tau) || request.fields.tau ||
                 view_of(analysis::SliceField::SubfilterStressNorm);
  needs.slice = request.slice_omega2 || request.slice_tau || request.slice_eddy;
  if (request.points_per_side < 1 ||
      (needs.fits && (!(request.fit_radius > 0.0) || 2.0 * request.fit_radius > box.length[0])))
    throw std::invalid_argument(
        "distributed particle products: needs points_per_side >= 1 and a fit radius in (0, L/2]");
  bool alone = true;
  for (int a = 0; a < dim; ++a) alone = alone && d.dims()[static_cast<std::size_t>(a)] == 1;
  if (needs.fits && !alone && request.fit_radius > d.halo_width())
    throw std::invalid_argument(
        "distributed particle products: the fits' radius " + std::to_string(request.fit_radius) +
        " m reaches further than the halo (" + std::to_string(d.halo_width()) + " m)");
  return needs;
}

/// This rank's particles, own first and then the halo, and how many particles all ranks hold.
struct RankParticles {
  const Decomposition& d;
  const sim::ParticleArrays& local;
  const Halo& halo;
  std::uint64_t total;
};

/// The chapter-4 statistics as analyse computes sfs_stats: maxima, an exact sum, counts
/// (analysis/products.cpp), over the ranks.
analysis::SubfilterStatisticsProduct subfilter_statistics(
    const RankParticles& p, const analysis::SubfilterStressField& stress,
    const std::vector<double>& omega2, const analysis::RanksRequest& request) {
  const Decomposition& d = p.d;
  std::array<double, 2> maxima{analysis::max_value(stress.norm), analysis::max_value(omega2)};
  allreduce_max(d, maxima);
  const std::vector<double>& norm = stress.norm;
  sim::ExactSum sum = sim::exact_sum(norm.size(), [&](std::size_t i) { return norm[i]; });
  sum = allreduce(d, sum);
  analysis::SubfilterStatisticsProduct s;
  s.max_norm = maxima[0];
  s.mean_norm = p.total == 0 ? 0.0 : sum.value() / static_cast<double>(p.total);
  s.joint = analysis::bivariate_histogram(norm, omega2, maxima[0], maxima[1],
                                          request.histogram_bins, request.histogram_bins);
  allreduce_counts(d, s.joint.counts);
  s.joint.total = p.total;
  if (d.dimension() == 2) {
    analysis::AngleHistogram a = analysis::principal_direction_alignment(
        stress, p.local, request.angle_bins, request.angle_threshold, maxima[0]);
    allreduce_counts(d, a.counts);
    allreduce_counts(d, std::span<std::uint64_t>(&a.total, 1));
    s.alignment = std::move(a);
  }
  return s;
}

/// Whether the run has ν_t: only with an explicit model, on every rank alike (a rank may hold no
/// particles). ν_t travels with the particles (the halo holds the owners' values).
bool has_eddy_viscosity(const RankParticles& p) {
  return !on_every_rank(p.d,
                        p.local.eddy_viscosity.size() != p.local.size() || p.local.size() == 0);
}

/// The slice and the grid fields (products "slices" and "fields") into `result`, from the fits
/// and the nodes' nearest particles.
void node_products(const RankParticles& p, const analysis::Grid& grid,
                   const analysis::FitSettings& fit, analysis::ParticleVorticity& omega,
                   const analysis::SubfilterStressField& stress, const Needs& needs,
                   const analysis::RanksRequest& request, analysis::RanksProducts& result) {
  const Decomposition& d = p.d;
  const int dim = d.dimension();
  const analysis::GridFieldsRequest& fields = request.fields;
  // The halo's ω and |τ_SFS| from their owners, for the nodes' fits and nearest particles.
  const bool omega2_at_nodes = request.slice_omega2 || fields.omega2;
  const bool tau_at_nodes = request.slice_tau || fields.tau;
  if (omega2_at_nodes) {
    std::vector<std::vector<double>*> components;
    for (std::size_t c = dim == 3 ? 0 : 2; c < 3; ++c) {
      omega.component[c].resize(p.local.size());
      components.push_back(&omega.component[c]);
    }
    p.halo.update(d, components);
  }
  std::vector<double> norm = stress.norm;
  if (tau_at_nodes) {
    norm.resize(p.local.size());
    std::vector<double>* halo_fields[] = {&norm};
    p.halo.update(d, halo_fields);
  }
  const bool has_eddy = has_eddy_viscosity(p);
  const NodeSources sources{d, grid, p.local, fit, omega, norm, p.total};
  if (needs.slice) {
    const SliceShare share = slice_share(d, grid, request);
    NodeValues v = node_values(sources, share, request.slice_omega2, request.slice_tau,
                               request.slice_eddy && has_eddy, false);
    result.slice_omega2 = std::move(v.omega2);
    result.slice_tau = std::move(v.tau);
    result.slice_eddy = std::move(v.eddy);
  }
  if (fields.any()) {
    NodeValues v = node_values(sources, grid_share(d, grid), fields.omega2, fields.tau,
                               fields.eddy && has_eddy, fields.velocity);
    result.fields_omega2 = std::move(v.omega2);
    result.fields_tau = std::move(v.tau);
    result.fields_eddy = std::move(v.eddy);
    result.fields_velocity = std::move(v.velocity);
  }
}

}  // namespace

analysis::RanksProducts distributed_particle_products(const Decomposition& d,
                                                      const sim::ParticleArrays& owned,
                                                      sim::KernelType kernel, double support_radius,
                                                      const analysis::RanksRequest& request) {
  const int dim = d.dimension();
  const sim::PeriodicBox& box = d.box();
  const Needs needs = needs_of(d, request);
  analysis::Grid grid;
  grid.dimension = dim;
  grid.points_per_side = request.points_per_side;
  grid.length = box.length[0];
  const analysis::FitSettings fit{kernel, request.fit_radius};

  // This rank's particles (those that left its sub-box since the last migration moved to their
  // owners), then the halo around its sub-box at their own positions in [0, L).
  sim::ParticleArrays local = owned;
  migrate(d, local);
  const Halo halo = Halo::build(d, local, HaloPositions::Wrapped);
  const std::size_t mine = halo.owned();
  std::uint64_t total = mine;
  allreduce_counts(d, std::span<std::uint64_t>(&total, 1));
  const RankParticles rank{d, local, halo, total};

  analysis::RanksProducts result;
  result.request = request;
  // ω and ω² at the own particles (the "mls" estimate).
  analysis::ParticleVorticity omega;
  omega.dimension = dim;
  if (needs.fits && mine > 0) omega = analysis::fitted_particle_vorticity(local, grid, fit, mine);
  const std::vector<double> omega2 = needs.fits ? omega.squared_magnitude() : std::vector<double>{};
  if (request.vorticity) {
    std::array<sim::ExactSum, 2> sums = analysis::volume_weighted_sums(local, omega2);
    allreduce(d, std::span<sim::ExactSum>(sums));
    result.mean_vorticity_squared = sums[0].value() / sums[1].value();
  }
  // τ_SFS at the own particles.
  analysis::SubfilterStressField stress;
  if (needs.stress)
    stress = analysis::implicit_subfilter_stress(local, box, kernel, support_radius, mine);

  if (request.statistics) result.statistics = subfilter_statistics(rank, stress, omega2, request);
  if (needs.slice || request.fields.any())
    node_products(rank, grid, fit, omega, stress, needs, request, result);
  const analysis::ViewPointsRequest& view = request.view;
  if (view.max_points > 0) {
    // ν_t only when the run has an explicit model, on every rank alike (as for the file).
    const bool eddy = view.field == analysis::SliceField::EddyViscosity;
    if (!eddy || has_eddy_viscosity(rank)) {
      const std::vector<double>& values = eddy ? local.eddy_viscosity
                                          : view.field == analysis::SliceField::VorticitySquared
                                              ? omega2
                                              : stress.norm;
      result.view = gather_view_points(d, local, mine, values, view.field, total, view.max_points);
    }
  }
  if (needs.particles) {
    // Written last: every refusal above comes before the file. ν_t only when the run has it.
    const bool eddy = request.particles.eddy && has_eddy_viscosity(rank);
    result.particles = write_particles(d, local, mine, omega2, stress.norm, eddy, request);
  }
  return result;
}

}  // namespace sphles::par
