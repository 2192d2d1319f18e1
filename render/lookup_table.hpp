// SPDX-License-Identifier: GPL-3.0-or-later
// The VTK lookup table matching sphles::render's CPU colour mapping (used by the scalar bar).
#pragma once

#include <vtkLookupTable.h>
#include <vtkSmartPointer.h>

#include <array>

namespace sphles::render {

/// A 256-entry viridis vtkLookupTable over range; SetScaleToLog10 for log_scale. Its GetIndex
/// agrees with colour_index for values inside the range.
vtkSmartPointer<vtkLookupTable> make_lookup_table(const std::array<double, 2>& range,
                                                  bool log_scale);

}  // namespace sphles::render
