// SPDX-License-Identifier: GPL-3.0-or-later
#include "sim/health.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <vector>

#include "sim/pair_loop.hpp"
#include "sim/reduction.hpp"

namespace sphles::sim {

std::string_view classification_name(Classification c) {
  return kClassificationNames.name(c);
}

Classification worst(Classification a, Classification b) {
  return static_cast<int>(a) >= static_cast<int>(b) ? a : b;
}

DensityDeviation density_deviation(const ParticleArrays& p, double reference_density) {
  DensityDeviation result;
  const std::size_t n = p.size();
  if (n == 0) return result;
  auto deviation = [&](std::size_t i) {
    const double d = std::abs(p.density[i] / reference_density - 1.0);
    return std::isfinite(d) ? d : 0.0;
  };
  const double sum_squares = deterministic_sum(n, [&](std::size_t i) {
    const double d = deviation(i);
    return d * d;
  });
  result.rms = std::sqrt(sum_squares / static_cast<double>(n));
  // Sequential arg-max: the first index of the maximum, independent of the thread count.
  for (std::size_t i = 0; i < n; ++i) {
    const double d = deviation(i);
    if (d > result.max) {
      result.max = d;
      result.max_index = i;
    }
  }
  return result;
}

namespace {

constexpr double kNoNeighbour = std::numeric_limits<double>::infinity();

/// The squared distances to the nearest and the second-nearest neighbour of every particle in
/// its Verlet list, as an evaluator of the pair loop reducing by a running top-2 minimum.
template <int Dim>
struct NearestTwo {
  static constexpr int outputs = 2;
  static constexpr bool coincident_pairs = true;  // a coincident pair is the closest there is
  static constexpr double identity = kNoNeighbour;
  struct Own {};

  static void accumulate(double (&acc)[outputs], const double (&c)[outputs]) {
    const double d2 = c[0];  // c = {r², r²}
    if (d2 < acc[0]) {
      acc[1] = acc[0];
      acc[0] = d2;
    } else if (d2 < acc[1]) {
      acc[1] = d2;
    }
  }
  Own own(std::size_t) const { return {}; }
  void pair(const Own&, const Pair<Dim>& q, double (&out)[outputs]) const {
    out[0] = q.r2;
    out[1] = q.r2;
  }
  void finish(std::size_t i, const Own&, const double (&sum)[outputs]) const {
    nearest2[i] = sum[0];
    second2[i] = sum[1];
  }

  double* nearest2;
  double* second2;
};

}  // namespace

PairingStatistics pairing_statistics(const ParticleArrays& p, const NeighbourList& list,
                                     const PeriodicBox& box, double spacing,
                                     const HealthThresholds& thresholds) {
  PairingStatistics result;
  const std::size_t n = std::min(p.size(), list.num_particles());
  std::vector<double> nearest2(n), second2(n);  // every entry written by NearestTwo::finish
  // Every entry of the list counts (an infinite "support"), as in a plain scan of the list.
  const double everywhere = std::numeric_limits<double>::infinity();
  if (p.dimension == 2)
    pair_pass<2>(NearestTwo<2>{nearest2.data(), second2.data()}, PeriodicGeometry<2>(box, p), list,
                 everywhere, 0, n);
  else
    pair_pass<3>(NearestTwo<3>{nearest2.data(), second2.data()}, PeriodicGeometry<3>(box, p), list,
                 everywhere, 0, n);
  const double distance2 = thresholds.pairing_distance * thresholds.pairing_distance;
  const double ratio2 = thresholds.pairing_ratio * thresholds.pairing_ratio;
  const double spacing2 = spacing * spacing;
  double min2 = kNoNeighbour;
  for (std::size_t i = 0; i < n; ++i) {
    min2 = std::min(min2, nearest2[i]);
    if (nearest2[i] < distance2 * spacing2 && nearest2[i] < ratio2 * second2[i])
      ++result.paired_count;
  }
  result.min_distance = std::sqrt(min2 / spacing2);
  result.paired_fraction =
      n > 0 ? static_cast<double>(result.paired_count) / static_cast<double>(n) : 0.0;
  return result;
}

std::optional<NonFiniteValue> find_non_finite(const ParticleArrays& p) {
  const int dim = p.dimension;
  auto check = [](const std::vector<double>& values, std::size_t i) {
    return i < values.size() && !std::isfinite(values[i]);
  };
  for (std::size_t i = 0; i < p.size(); ++i) {
    auto found = [&](const std::string& field, double value) {
      return NonFiniteValue{i, i < p.id.size() ? p.id[i] : i, field, value};
    };
    const std::array<std::pair<const char*, const std::array<std::vector<double>, 3>*>, 3> vectors{
        {{"position", &p.position}, {"velocity", &p.velocity}, {"acceleration", &p.acceleration}}};
    for (const auto& [name, field] : vectors)
      for (int d = 0; d < dim; ++d)
        if (check((*field)[d], i))
          return found(std::string(name) + "[" + std::to_string(d) + "]", (*field)[d][i]);
    const std::array<std::pair<const char*, const std::vector<double>*>, 5> scalars{
        {{"mass", &p.mass},
         {"volume", &p.volume},
         {"density", &p.density},
         {"pressure", &p.pressure},
         {"eddy_viscosity", &p.eddy_viscosity}}};
    for (const auto& [name, field] : scalars)
      if (check(*field, i)) return found(name, (*field)[i]);
  }
  return std::nullopt;
}

double mean_kinetic_energy(const ParticleArrays& p) {
  const std::size_t n = p.size();
  const double mass = deterministic_sum(n, [&](std::size_t i) { return p.mass[i]; });
  const double twice = deterministic_sum(n, [&](std::size_t i) {
    double v2 = 0.0;
    for (int d = 0; d < p.dimension; ++d) v2 += p.velocity[d][i] * p.velocity[d][i];
    return p.mass[i] * v2;
  });
  return 0.5 * twice / mass;  // (5.3)
}

double runaway_reference_energy(double initial_energy, double sound_speed,
                                const BlowUpThresholds& thresholds) {
  const double acoustic_speed = thresholds.reference_mach * sound_speed;
  return std::max(
      {initial_energy, thresholds.reference_energy, 0.5 * acoustic_speed * acoustic_speed});
}

bool is_energy_runaway(double kinetic_energy, double reference_energy,
                       const BlowUpThresholds& thresholds) {
  return !std::isfinite(kinetic_energy) ||
         kinetic_energy > thresholds.energy_factor * reference_energy;
}

std::size_t fastest_particle(const ParticleArrays& p) {
  std::size_t best = 0;
  double best_v2 = -1.0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    double v2 = 0.0;
    for (int d = 0; d < p.dimension; ++d) v2 += p.velocity[d][i] * p.velocity[d][i];
    if (!std::isfinite(v2)) return i;
    if (v2 > best_v2) {
      best_v2 = v2;
      best = i;
    }
  }
  return best;
}

HealthReport assess_health(const ParticleArrays& p, const NeighbourList& list,
                           const PeriodicBox& box, double spacing, double reference_density,
                           double reference_energy, const HealthThresholds& thresholds) {
  HealthReport report;
  report.non_finite = find_non_finite(p);
  report.kinetic_energy = mean_kinetic_energy(p);
  report.energy_runaway =
      is_energy_runaway(report.kinetic_energy, reference_energy, thresholds.blow_up);
  report.density = density_deviation(p, reference_density);
  report.pairing = pairing_statistics(p, list, box, spacing, thresholds);
  std::ostringstream reason;
  if (report.non_finite) {
    report.classification = Classification::BlownUp;
    reason << "non-finite " << report.non_finite->field << " at particle id "
           << report.non_finite->id;
  } else if (report.energy_runaway) {
    report.classification = Classification::BlownUp;
    reason << "kinetic energy " << report.kinetic_energy << " > "
           << thresholds.blow_up.energy_factor << " x reference " << reference_energy;
  } else if (report.pairing.paired_fraction > thresholds.paired_fraction) {
    report.classification = Classification::Paired;
    reason << report.pairing.paired_fraction * 100.0 << " % of particles paired (nearest "
           << "neighbour < " << thresholds.pairing_distance << " dl and < "
           << thresholds.pairing_ratio << " x second nearest; limit "
           << thresholds.paired_fraction * 100.0 << " %)";
  } else if (report.density.rms > thresholds.noisy_rms_density_deviation) {
    report.classification = Classification::Noisy;
    reason << "rms density deviation " << report.density.rms << " > "
           << thresholds.noisy_rms_density_deviation;
  } else if (report.density.max > thresholds.noisy_max_density_deviation) {
    report.classification = Classification::Noisy;
    reason << "max density deviation " << report.density.max << " > "
           << thresholds.noisy_max_density_deviation;
  }
  report.reason = reason.str();
  return report;
}

}  // namespace sphles::sim
