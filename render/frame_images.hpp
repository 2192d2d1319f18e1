// SPDX-License-Identifier: GPL-3.0-or-later
// The images one analysis frame yields under a render configuration: one per slice field, all
// fields side by side, and the 3D view when due. Pure: depends on its inputs only.
#pragma once

#include <string>
#include <vector>

#include "analysis/products.hpp"
#include "render/config.hpp"

namespace sphles::render {

struct FrameImage {
  std::string field;  // "omega2", "tau_sfs", "nu_t", "combined" or "view3d"
  std::vector<unsigned char> png;
  double milliseconds = 0.0;  // wall time to render and encode
};

/// Whether `frame` holds what the 3D view draws: the particles' view points of its field, or
/// its field on the analysis grid (an iso-surface).
bool has_view3d_input(const analysis::AnalysisFrame& frame, const View3dConfig& view);

/// Renders the slices of `frame` that `config` asks for (in the order omega2, tau_sfs, nu_t,
/// combined) and, with `include_view3d`, the 3D view (particles or iso-surface). A requested slice
/// missing from the frame is skipped (the analysis had it switched off at that time).
std::vector<FrameImage> render_frame_images(const analysis::AnalysisFrame& frame,
                                            const RenderConfig& config,
                                            const std::string& case_name, bool include_view3d);

}  // namespace sphles::render
