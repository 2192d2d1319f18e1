// SPDX-License-Identifier: GPL-3.0-or-later
// What a renderer reports of its last frame, shared by the slice and particle renderers and the
// VTK window beneath them.
#pragma once

namespace sphles::render {

/// Wall time of the stages of the last frame [ms].
struct FrameTimings {
  double prepare_ms = 0.0;    // colour mapping on the CPU and scene update
  double render_ms = 0.0;     // vtkRenderWindow::Render
  double read_back_ms = 0.0;  // vtkWindowToImageFilter::Update
  double encode_ms = 0.0;     // vtkPNGWriter to memory
};

}  // namespace sphles::render
