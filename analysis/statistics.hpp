// SPDX-License-Identifier: GPL-3.0-or-later
// Chapter-4 statistics (SPEC §5): bivariate histogram of (τ*, ω²*) and the polar histogram of
// the angle between the major principal direction t_I and the velocity.
#pragma once

#include <cstdint>
#include <limits>
#include <span>
#include <vector>

#include "analysis/histograms.hpp"
#include "analysis/subfilter_stress.hpp"

namespace sphles::analysis {

/// Histogram of (x_i / max x, y_i / max y) for all i (a zero maximum maps every value to 0).
Histogram2D normalised_bivariate_histogram(std::span<const double> x, std::span<const double> y,
                                           int bins_x, int bins_y);
/// The same with the maxima given (those of a larger set, the particles of every rank: par/);
/// total = x.size().
Histogram2D bivariate_histogram(std::span<const double> x, std::span<const double> y, double max_x,
                                double max_y, int bins_x, int bins_y);

/// The largest value, 0 for none (or none positive).
double max_value(std::span<const double> values);

/// Over the particles of `stress` (the first stress.norm.size() of `particles`), with τ* taken
/// against `max_norm` (max_value(stress.norm) when NaN).
AngleHistogram principal_direction_alignment(
    const SubfilterStressField& stress, const sim::ParticleArrays& particles, int bins,
    double threshold, double max_norm = std::numeric_limits<double>::quiet_NaN());

}  // namespace sphles::analysis
