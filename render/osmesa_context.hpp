// SPDX-License-Identifier: GPL-3.0-or-later
// An OSMesa (software GL) context that VTK renders into, plus the GL loader workaround.
#pragma once

#include <vector>

namespace sphles::render::detail {

/// Core-profile OSMesa context (GL >= 3.2) current on a client RGBA buffer of width x height.
/// Not copyable; one per Renderer.
class OsmesaContext {
 public:
  OsmesaContext(int width, int height);
  ~OsmesaContext();
  OsmesaContext(const OsmesaContext&) = delete;
  OsmesaContext& operator=(const OsmesaContext&) = delete;

  /// Makes the context current on the calling thread. Throws std::runtime_error on failure.
  void make_current();

 private:
  void* context_ = nullptr;  // OSMesaContext
  int width_, height_;
  std::vector<unsigned char> buffer_;  // RGBA, the default framebuffer
};

}  // namespace sphles::render::detail
