#include "sim/packing.hpp"

#include <unistd.h>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <random>
#include <sstream>

#include "sim/neighbour_search.hpp"
#include "sim/physics.hpp"
#include "sim/reduction.hpp"

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

/// Evaluates a = -(2 p_b/ρ) Σ_j ∇W_ij V_j into p.acceleration and returns the residual
/// max_i |Σ_j ∇W_ij V_j| Δl.
template <class KernelT>
double background_force(const KernelT& kernel, const PeriodicBox& box,
                        const VerletNeighbourSearch& search, double spacing, ParticleArrays& p) {
  constexpr int Dim = KernelT::dimension;
  const FluidParameters fluid = background_fluid();
  InteractionList pairs;
  density_pass<Dim>(kernel, box, search.list(), fluid, p, &pairs);
  force_pass<Dim>(kernel, box, pairs, fluid, view_velocity(p), p);
  // a_i = -2 p_b Σ_j ∇W_ij V_j / ρ_i with 2 p_b = 1, hence |Σ ∇W V| = |a_i| ρ_i.
  return spacing * std::sqrt(parallel_max(p.size(), [&](std::size_t i) {
           double a2 = 0.0;
           for (int d = 0; d < Dim; ++d) a2 += p.acceleration[d][i] * p.acceleration[d][i];
           return a2 * p.density[i] * p.density[i];
         }));
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

constexpr char kCacheMagic[8] = {'S', 'P', 'H', 'P', 'A', 'C', 'K', '1'};

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

std::optional<ParticleArrays> read_cache(const std::filesystem::path& file, const std::string& key,
                                         int dim, std::size_t count) {
  std::ifstream in(file, std::ios::binary);
  if (!in) return std::nullopt;
  char magic[8];
  std::uint64_t key_size = 0, stored_count = 0;
  if (!in.read(magic, 8) || std::memcmp(magic, kCacheMagic, 8) != 0) return std::nullopt;
  if (!in.read(reinterpret_cast<char*>(&key_size), sizeof key_size) || key_size > 4096)
    return std::nullopt;
  std::string stored_key(key_size, '\0');
  if (!in.read(stored_key.data(), static_cast<std::streamsize>(key_size)) || stored_key != key)
    return std::nullopt;
  if (!in.read(reinterpret_cast<char*>(&stored_count), sizeof stored_count) ||
      stored_count != count)
    return std::nullopt;
  ParticleArrays p;
  p.dimension = dim;
  p.resize(count);
  std::uint64_t hash = fnv1a(stored_key.data(), stored_key.size());
  for (int d = 0; d < dim; ++d) {
    const auto bytes = static_cast<std::streamsize>(count * sizeof(double));
    if (!in.read(reinterpret_cast<char*>(p.position[d].data()), bytes)) return std::nullopt;
    hash = fnv1a(p.position[d].data(), count * sizeof(double), hash);
  }
  std::uint64_t stored_hash = 0;
  if (!in.read(reinterpret_cast<char*>(&stored_hash), sizeof stored_hash) || stored_hash != hash)
    return std::nullopt;
  return p;
}

void write_cache(const std::filesystem::path& file, const std::string& key,
                 const ParticleArrays& p) {
  std::error_code ec;
  std::filesystem::create_directories(file.parent_path(), ec);
  const std::filesystem::path temporary =
      file.string() + ".tmp." + std::to_string(static_cast<long>(::getpid()));
  {
    std::ofstream out(temporary, std::ios::binary | std::ios::trunc);
    if (!out) return;  // the cache is an optimisation: an unwritable directory is not an error
    const std::uint64_t key_size = key.size(), count = p.size();
    out.write(kCacheMagic, 8);
    out.write(reinterpret_cast<const char*>(&key_size), sizeof key_size);
    out.write(key.data(), static_cast<std::streamsize>(key.size()));
    out.write(reinterpret_cast<const char*>(&count), sizeof count);
    std::uint64_t hash = fnv1a(key.data(), key.size());
    for (int d = 0; d < p.dimension; ++d) {
      out.write(reinterpret_cast<const char*>(p.position[d].data()),
                static_cast<std::streamsize>(count * sizeof(double)));
      hash = fnv1a(p.position[d].data(), count * sizeof(double), hash);
    }
    out.write(reinterpret_cast<const char*>(&hash), sizeof hash);
    out.flush();
    if (!out) {
      std::filesystem::remove(temporary, ec);
      return;
    }
  }
  std::filesystem::rename(temporary, file, ec);
  if (ec) std::filesystem::remove(temporary, ec);
}

}  // namespace

ParticleArrays make_lattice(const PeriodicBox& box, int per_side) {
  ParticleArrays p;
  p.dimension = box.dimension;
  std::size_t n = 1;
  for (int d = 0; d < box.dimension; ++d) n *= static_cast<std::size_t>(per_side);
  p.resize(n);
  for (std::size_t k = 0; k < n; ++k) {
    std::size_t rest = k;
    for (int d = 0; d < box.dimension; ++d) {
      const std::size_t index = rest % static_cast<std::size_t>(per_side);
      rest /= static_cast<std::size_t>(per_side);
      const double spacing = box.length[d] / per_side;
      p.position[d][k] = (static_cast<double>(index) + 0.5) * spacing;
    }
  }
  return p;
}

double packing_residual(const PeriodicBox& box, KernelType kernel, double support_radius,
                        double spacing, const ParticleArrays& particles) {
  ParticleArrays p = particles;
  fill_packing_arrays(p, spacing);
  return with_kernel(kernel, box.dimension, support_radius, [&](const auto& k) {
    VerletNeighbourSearch search(box, support_radius, 0.0);
    search.build(view_positions(p));
    return background_force(k, box, search, spacing, p);
  });
}

PackingReport relax_particles(const PackingConfig& config, const PeriodicBox& box,
                              KernelType kernel, double support_radius, double spacing,
                              ParticleArrays& particles, const std::function<bool()>& cancelled) {
  PackingReport report;
  ParticleArrays& p = particles;
  fill_packing_arrays(p, spacing);
  if (config.perturbation > 0.0) {
    std::mt19937_64 rng(config.seed);
    std::uniform_real_distribution<double> uniform(-1.0, 1.0);
    for (std::size_t i = 0; i < p.size(); ++i)
      for (int d = 0; d < p.dimension; ++d)
        p.position[d][i] = wrap_periodic(
            p.position[d][i] + config.perturbation * spacing * uniform(rng), box.length[d]);
  }
  with_kernel(kernel, box.dimension, support_radius, [&](const auto& k) {
    constexpr int Dim = std::decay_t<decltype(k)>::dimension;
    VerletNeighbourSearch search(box, support_radius, kPackingSkin * support_radius);
    const auto rebuild = [&] {
      p.reorder(search.locality_order(view_positions(p)));
      search.build(view_positions(p));
    };
    rebuild();
    double residual = background_force(k, box, search, spacing, p);
    report.initial_residual = residual;
    const double dt = kStepOverSpacing * spacing;
    const std::size_t n = p.size();
    while (residual > config.tolerance && report.iterations < config.max_iterations) {
      if (cancelled && cancelled())
        throw SetupCancelled("packing cancelled after " + std::to_string(report.iterations) +
                             " iterations");
      for (int d = 0; d < Dim; ++d) {
        double* v = p.velocity[d].data();
        double* x = p.position[d].data();
        const double* a = p.acceleration[d].data();
        const double length = box.length[d];
#pragma omp parallel for schedule(static)
        for (std::size_t i = 0; i < n; ++i) {
          v[i] = (v[i] + dt * a[i]) * (1.0 - kDampingPerStep);
          x[i] = wrap_periodic(x[i] + dt * v[i], length);
        }
      }
      if (search.needs_rebuild(view_positions(p))) rebuild();
      residual = background_force(k, box, search, spacing, p);
      ++report.iterations;
    }
    report.final_residual = residual;
    report.converged = residual <= config.tolerance;
  });
  // Restore the lattice order of identities so that a packed state does not depend on how often
  // the search reordered it.
  std::vector<std::uint32_t> order(p.size());
  for (std::size_t k = 0; k < p.size(); ++k) order[p.id[k]] = static_cast<std::uint32_t>(k);
  p.reorder(order);
  for (int d = 0; d < p.dimension; ++d) {
    p.velocity[d].assign(p.size(), 0.0);
    p.acceleration[d].assign(p.size(), 0.0);
  }
  return report;
}

std::filesystem::path default_packing_cache_dir() {
  if (const char* xdg = std::getenv("XDG_CACHE_HOME"); xdg && *xdg)
    return std::filesystem::path(xdg) / "sphles" / "packing";
  if (const char* home = std::getenv("HOME"); home && *home)
    return std::filesystem::path(home) / ".cache" / "sphles" / "packing";
  return std::filesystem::temp_directory_path() / "sphles-packing";
}

ParticleArrays packed_positions(const Scene& scene, PackingReport* report,
                                const SetupOptions& options) {
  PeriodicBox box;
  box.dimension = scene.dimension();
  for (int d = 0; d < box.dimension; ++d) box.length[d] = scene.box_length();
  ParticleArrays p = make_lattice(box, scene.particles_per_side);
  PackingReport local;
  PackingReport& r = report ? *report : local;
  r = PackingReport{};
  if (!scene.packing.enabled) return p;

  const std::string key = cache_key(scene);
  std::filesystem::path file;
  if (scene.packing.cache) {
    const std::filesystem::path dir =
        options.packing_cache_dir.empty() ? default_packing_cache_dir() : options.packing_cache_dir;
    std::ostringstream name;
    name << "pack_" << scene.dimension() << "d_n" << scene.particles_per_side << "_"
         << kernel_name(scene.kernel) << "_dk" << scene.kernel_diameter_over_spacing << "_"
         << std::hex << fnv1a(key.data(), key.size()) << ".bin";
    file = dir / name.str();
    r.cache_file = file.string();
    if (auto cached = read_cache(file, key, box.dimension, p.size())) {
      r.from_cache = true;
      r.converged = true;
      return std::move(*cached);
    }
  }
  r = relax_particles(scene.packing, box, scene.kernel, 0.5 * scene.kernel_diameter(),
                      scene.particle_spacing(), p, options.cancelled);
  r.cache_file = file.string();
  if (!file.empty()) write_cache(file, key, p);
  return p;
}

}  // namespace sphles::sim
