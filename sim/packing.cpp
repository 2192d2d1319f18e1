// SPDX-License-Identifier: GPL-3.0-or-later
#include "sim/packing.hpp"

#include <unistd.h>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>

#include <Random123/philox.h>
#include <Random123/uniform.hpp>

#include "sim/neighbour_search.hpp"
#include "sim/physics/thesis_passes.hpp"
#include "sim/reduction.hpp"
#include "sim/scheme.hpp"

namespace sphles::sim {

namespace {

// Fictitious units of the packing dynamics (see packing.hpp).
constexpr double kBackgroundPressureOverDensity = 1.0;  // p_b / ρ [m²/s²]
constexpr double kStepOverSpacing = 0.2;                // dt = 0.2 Δl / (1 m/s)
constexpr double kDampingPerStep = 0.1;                 // β dt

/// Fluid whose pressure is the constant background p_b (no EOS term, no viscosity).
FluidParameters background_fluid() {
  return {.reference_density = 1.0,
          .sound_speed = 0.0,
          .reference_pressure = 0.5 * kBackgroundPressureOverDensity,  // 2 p_b appears in (A.9)
          .dynamic_viscosity = 0.0};
}

/// Evaluates a = -(2 p_b/ρ) Σ_j ∇W_ij V_j into p.acceleration of the first `owned` particles
/// (the rest: halo copies of other processes' particles, whose V and ρ it refreshes) and returns
/// the residual max_i |Σ_j ∇W_ij V_j| Δl over every process. `still`: zero velocities for every
/// particle (the background fluid has no viscosity; the force pass reads them all the same).
template <class KernelT>
double background_force(const KernelT& kernel, const PeriodicBox& box, const NeighbourList& list,
                        double spacing, const VelocityView& still, std::size_t owned,
                        const Exchange& exchange, InteractionList& pairs, ParticleArrays& p) {
  constexpr int Dim = KernelT::dimension;
  const FluidParameters fluid = background_fluid();
  density_pass<Dim>(kernel, box, list, fluid, p, &pairs);
  std::vector<double>* written[] = {&p.volume, &p.density, &p.pressure};
  exchange.refresh(written);
  force_pass<Dim>(kernel, box, pairs, fluid, still, p);
  // a_i = -2 p_b Σ_j ∇W_ij V_j / ρ_i with 2 p_b = 1, hence |Σ ∇W V| = |a_i| ρ_i.
  return spacing * std::sqrt(exchange.max(parallel_max(owned, [&](std::size_t i) {
           double a2 = 0.0;
           for (int d = 0; d < Dim; ++d) a2 += p.acceleration[d][i] * p.acceleration[d][i];
           return a2 * p.density[i] * p.density[i];
         })));
}

void fill_packing_arrays(ParticleArrays& p, double spacing) {
  const double cell_volume = std::pow(spacing, p.dimension);
  for (double& m : p.mass) m = cell_volume;  // ρ = 1 in the fictitious units
  for (int d = 0; d < p.dimension; ++d) {
    p.velocity[d].assign(p.size(), 0.0);
    p.acceleration[d].assign(p.size(), 0.0);
  }
}

std::uint64_t fnv1a(const void* data, std::size_t size,
                    std::uint64_t hash = 1469598103934665603ULL) {
  const auto* bytes = static_cast<const unsigned char*>(data);
  for (std::size_t k = 0; k < size; ++k) {
    hash ^= bytes[k];
    hash *= 1099511628211ULL;
  }
  return hash;
}

// Version 2: positions relaxed with id-ordered sums from a counter-based perturbation, and an
// order-independent checksum (PackingCacheFile).
constexpr char kCacheMagic[8] = {'S', 'P', 'H', 'P', 'A', 'C', 'K', '2'};

/// SplitMix64's finaliser (Steele, Lea & Flood 2014): a bijective mix of 64 bits.
std::uint64_t mix64(std::uint64_t z) {
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

std::string cache_key(const Scene& s) {
  std::ostringstream key;
  key.precision(17);
  key << "dim=" << s.dimension() << ";n=" << s.particles_per_side
      << ";kernel=" << kernel_name(s.kernel) << ";dk=" << s.kernel_diameter_over_spacing
      << ";L=" << s.box_length() << ";perturbation=" << s.packing.perturbation
      << ";seed=" << s.packing.seed << ";tol=" << s.packing.tolerance << ";maxit="
      << s.packing.max_iterations
      // The arithmetic of the packing's passes: a packing made by another summation order is
      // equally packed but not bitwise the state this build would make.
      << ";sums=" << pair_loop_summation();
  return key.str();
}

std::optional<ParticleArrays> read_cache(const PackingCacheFile& f) {
  std::optional<PackingCacheBlock> all = read_packing_cache_block(f, 0, f.count);
  if (!all || f.key_hash + all->checksum_part != all->stored) return std::nullopt;
  return std::move(all->particles);
}

void write_cache(const PackingCacheFile& f, const ParticleArrays& p) {
  std::error_code ec;
  std::filesystem::create_directories(f.path.parent_path(), ec);
  const std::filesystem::path temporary =
      f.path.string() + ".tmp." + std::to_string(static_cast<long>(::getpid()));
  {
    std::ofstream out(temporary, std::ios::binary | std::ios::trunc);
    if (!out) return;  // the cache is an optimisation: an unwritable directory is not an error
    out.write(f.header.data(), static_cast<std::streamsize>(f.header.size()));
    std::uint64_t sum = f.key_hash;
    for (int d = 0; d < p.dimension; ++d) {
      out.write(reinterpret_cast<const char*>(p.position[d].data()),
                static_cast<std::streamsize>(p.size() * sizeof(double)));
      sum += f.checksum(d, 0, p.position[d]);
    }
    out.write(reinterpret_cast<const char*>(&sum), sizeof sum);
    out.flush();
    if (!out) {
      std::filesystem::remove(temporary, ec);
      return;
    }
  }
  std::filesystem::rename(temporary, f.path, ec);
  if (ec) std::filesystem::remove(temporary, ec);
}

}  // namespace

ParticleArrays make_lattice(const PeriodicBox& box, int per_side, const LatticeFilter& keep) {
  const auto n = static_cast<std::size_t>(per_side);
  // The lattice lines each axis keeps, ascending.
  std::array<std::vector<std::size_t>, 3> lines;
  std::size_t count = 1;
  for (int d = 0; d < box.dimension; ++d) {
    const double spacing = box.length[d] / per_side;
    for (std::size_t i = 0; i < n; ++i)
      if (!keep || keep(d, (static_cast<double>(i) + 0.5) * spacing)) lines[d].push_back(i);
    count *= lines[d].size();
  }
  ParticleArrays p;
  p.dimension = box.dimension;
  p.resize(count);
  for (std::size_t k = 0; k < count; ++k) {
    std::size_t rest = k, id = 0, stride = 1;
    for (int d = 0; d < box.dimension; ++d) {
      const std::size_t index = lines[d][rest % lines[d].size()];
      rest /= lines[d].size();
      p.position[d][k] = (static_cast<double>(index) + 0.5) * (box.length[d] / per_side);
      id += index * stride;
      stride *= n;
    }
    p.id[k] = id;
  }
  return p;
}

void perturb_positions(const PackingConfig& config, const PeriodicBox& box, double spacing,
                       ParticleArrays& p) {
  using Philox = r123::Philox4x64;
  const Philox generator;
  const Philox::key_type key = {{config.seed, 0}};
  for (std::size_t i = 0; i < p.size(); ++i) {
    const Philox::ctr_type draw = generator({{p.id[i], 0, 0, 0}}, key);
    for (int d = 0; d < p.dimension; ++d) {
      const double u = r123::uneg11<double>(draw[static_cast<std::size_t>(d)]);  // [-1, 1]
      p.position[d][i] =
          wrap_periodic(p.position[d][i] + config.perturbation * spacing * u, box.length[d]);
    }
  }
}

double packing_residual(const PeriodicBox& box, KernelType kernel, double support_radius,
                        double spacing, const ParticleArrays& particles) {
  ParticleArrays p = particles;
  fill_packing_arrays(p, spacing);
  return with_kernel(kernel, box.dimension, support_radius, [&](const auto& k) {
    VerletNeighbourSearch search(box, support_radius, 0.0);
    search.build(view_positions(p), order_by_key(p.id));
    const std::array<std::vector<double>, 3> zero = p.velocity;
    InteractionList pairs;
    return background_force(k, box, search.list(), spacing, view_of(zero, p.dimension), p.size(),
                            LocalExchange{}, pairs, p);
  });
}

PackingReport relax_particles(const PackingConfig& config, const PeriodicBox& box,
                              KernelType kernel, double support_radius, double spacing,
                              ParticleArrays& particles, const std::function<bool()>& cancelled) {
  LocalExchange one_process;
  return relax_particles(config, box, kernel, support_radius, spacing, particles, one_process,
                         cancelled);
}

PackingReport relax_particles(const PackingConfig& config, const PeriodicBox& box,
                              KernelType kernel, double support_radius, double spacing,
                              ParticleArrays& particles, Exchange& exchange,
                              const std::function<bool()>& cancelled) {
  PackingReport report;
  ParticleArrays& p = particles;
  fill_packing_arrays(p, spacing);
  if (config.perturbation > 0.0) perturb_positions(config, box, spacing, p);
  std::size_t owned = p.size();
  with_kernel(kernel, box.dimension, support_radius, [&](const auto& k) {
    constexpr int Dim = std::decay_t<decltype(k)>::dimension;
    VerletNeighbourSearch search(box, support_radius, kPackingSkin * support_radius);
    std::array<std::vector<double>, 3> still;  // zero velocities of owned and halo particles
    InteractionList pairs;
    // As the solver's rebuild: migrate (distributed), locality order, halo, lists in id order.
    const auto rebuild = [&] {
      if (exchange.distributed()) {
        p.truncate(owned);
        exchange.migrate(p, {});
      }
      p.reorder(search.locality_order(view_positions(p)));
      owned = p.size();
      exchange.build_halo(p);
      search.build(view_positions(p), order_by_key(p.id), owned);
      for (int d = 0; d < Dim; ++d) still[d].assign(p.size(), 0.0);
    };
    const auto residual_now = [&] {
      return background_force(k, box, search.list(), spacing, view_of(still, Dim), owned, exchange,
                              pairs, p);
    };
    rebuild();
    double residual = residual_now();
    report.initial_residual = residual;
    const double dt = kStepOverSpacing * spacing;
    while (residual > config.tolerance && report.iterations < config.max_iterations) {
      if (exchange.any(cancelled && cancelled()))
        throw SetupCancelled("packing cancelled after " + std::to_string(report.iterations) +
                             " iterations");
      for (int d = 0; d < Dim; ++d) {
        double* v = p.velocity[d].data();
        double* x = p.position[d].data();
        const double* a = p.acceleration[d].data();
        const double length = box.length[d];
        const auto n = static_cast<std::ptrdiff_t>(owned);
#pragma omp parallel for schedule(static)
        for (std::ptrdiff_t si = 0; si < n; ++si) {
          const auto i = static_cast<std::size_t>(si);
          v[i] = (v[i] + dt * a[i]) * (1.0 - kDampingPerStep);
          x[i] = wrap_periodic(x[i] + dt * v[i], length);
        }
      }
      if (exchange.any(search.needs_rebuild(view_positions(p), owned))) {
        rebuild();
      } else if (exchange.distributed()) {
        std::vector<std::vector<double>*> positions;
        for (int d = 0; d < Dim; ++d) positions.push_back(&p.position[d]);
        exchange.refresh(positions);
      }
      residual = residual_now();
      ++report.iterations;
    }
    report.final_residual = residual;
    report.converged = residual <= config.tolerance;
  });
  // This process' particles in id order, so that a packed state does not depend on how often
  // the search reordered it.
  p.truncate(owned);
  p.reorder(order_by_key(p.id));
  // Only the positions are kept: the packing's fictitious fields do not leak into a run.
  for (int d = 0; d < p.dimension; ++d) {
    p.velocity[d].assign(p.size(), 0.0);
    p.acceleration[d].assign(p.size(), 0.0);
  }
  for (std::vector<double>* field : {&p.mass, &p.volume, &p.density, &p.pressure})
    field->assign(p.size(), 0.0);
  return report;
}

std::filesystem::path default_packing_cache_dir() {
  if (const char* xdg = std::getenv("XDG_CACHE_HOME"); xdg && *xdg)
    return std::filesystem::path(xdg) / "sphles" / "packing";
  if (const char* home = std::getenv("HOME"); home && *home)
    return std::filesystem::path(home) / ".cache" / "sphles" / "packing";
  return std::filesystem::temp_directory_path() / "sphles-packing";
}

std::uint64_t PackingCacheFile::checksum(int axis, std::uint64_t first,
                                         std::span<const double> values) const {
  std::uint64_t sum = 0;
  for (std::size_t k = 0; k < values.size(); ++k) {
    std::uint64_t bits = 0;
    std::memcpy(&bits, &values[k], sizeof bits);
    const std::uint64_t place = static_cast<std::uint64_t>(axis) * count + first + k;
    sum += mix64(bits ^ mix64(place));
  }
  return sum;
}

std::optional<PackingCacheBlock> read_packing_cache_block(const PackingCacheFile& f,
                                                          std::uint64_t first,
                                                          std::uint64_t count) {
  std::error_code ec;
  const auto size = std::filesystem::file_size(f.path, ec);
  if (ec || size != f.file_size() || first + count > f.count) return std::nullopt;
  std::ifstream in(f.path, std::ios::binary);
  std::string header(f.header.size(), '\0');
  if (!in.read(header.data(), static_cast<std::streamsize>(header.size())) || header != f.header)
    return std::nullopt;
  PackingCacheBlock block;
  ParticleArrays& p = block.particles;
  p.dimension = f.dimension;
  p.resize(count);
  for (std::size_t k = 0; k < p.size(); ++k) p.id[k] = first + k;
  for (int d = 0; d < f.dimension; ++d) {
    in.seekg(static_cast<std::streamoff>(f.offset(d, first)));
    if (!in.read(reinterpret_cast<char*>(p.position[d].data()),
                 static_cast<std::streamsize>(count * sizeof(double))))
      return std::nullopt;
    block.checksum_part += f.checksum(d, first, p.position[d]);
  }
  in.seekg(static_cast<std::streamoff>(f.checksum_offset()));
  if (!in.read(reinterpret_cast<char*>(&block.stored), sizeof block.stored)) return std::nullopt;
  return block;
}

double packing_list_radius(const PeriodicBox& box, double support_radius) {
  return VerletNeighbourSearch(box, support_radius, kPackingSkin * support_radius).list_radius();
}

PackingCacheFile packing_cache_file(const Scene& scene, const SetupOptions& options) {
  PackingCacheFile f;
  f.dimension = scene.dimension();
  f.count = scene.num_particles();
  if (!scene.packing.enabled || !scene.packing.cache) return f;
  const std::string key = cache_key(scene);
  f.key_hash = fnv1a(key.data(), key.size());
  const std::filesystem::path dir =
      options.packing_cache_dir.empty() ? default_packing_cache_dir() : options.packing_cache_dir;
  std::ostringstream name;
  name << "pack_" << scene.dimension() << "d_n" << scene.particles_per_side << "_"
       << kernel_name(scene.kernel) << "_dk" << scene.kernel_diameter_over_spacing << "_"
       << std::hex << f.key_hash << ".bin";
  f.path = dir / name.str();
  const std::uint64_t key_size = key.size();
  f.header.assign(kCacheMagic, sizeof kCacheMagic);
  f.header.append(reinterpret_cast<const char*>(&key_size), sizeof key_size);
  f.header += key;
  f.header.append(reinterpret_cast<const char*>(&f.count), sizeof f.count);
  return f;
}

ParticleArrays packed_positions(const Scene& scene, PackingReport* report,
                                const SetupOptions& options) {
  PeriodicBox box;
  box.dimension = scene.dimension();
  for (int d = 0; d < box.dimension; ++d) box.length[d] = scene.box_length();
  PackingReport local;
  PackingReport& r = report ? *report : local;
  r = PackingReport{};
  if (!scene.packing.enabled) return make_lattice(box, scene.particles_per_side);

  const PackingCacheFile file = packing_cache_file(scene, options);
  r.cache_file = file.path.string();
  if (!file.path.empty()) {
    if (auto cached = read_cache(file)) {
      r.from_cache = true;
      r.converged = true;
      return std::move(*cached);
    }
  }
  ParticleArrays p = make_lattice(box, scene.particles_per_side);
  r = relax_particles(scene.packing, box, scene.kernel, 0.5 * scene.kernel_diameter(),
                      scene.particle_spacing(), p, options.cancelled);
  r.cache_file = file.path.string();
  if (!file.path.empty()) write_cache(file, p);
  return p;
}

}  // namespace sphles::sim
