// Vorticity by second-order central differences on the periodic grid (SPEC §5).
#pragma once

#include <vector>

#include "analysis/grid.hpp"

namespace sphles::analysis {

/// ω = ∇ × u. 3D: components 0, 1, 2 = ω_x, ω_y, ω_z. 2D: component 2 holds ω_z, components 0
/// and 1 are empty.
VectorField vorticity(const VectorField& velocity);

/// |ω|² at every node.
std::vector<double> squared_magnitude(const VectorField& field);

/// Arithmetic mean of the values (⟨ω²⟩ for the dissipation ε_v = ν ⟨ω²⟩ of (4.6)).
double mean_value(const std::vector<double>& values);

}  // namespace sphles::analysis
