// SPDX-License-Identifier: GPL-3.0-or-later
// OSMesa context creation and the two symbols that route VTK's GL loading to OSMesa.
//
// Debian's VTK 9.1 loads GL entry points through the system GLEW, which asks glXGetProcAddressARB.
// Defining that symbol here (exported from the executable, see render/CMakeLists.txt) makes GLEW
// resolve every entry point through OSMesaGetProcAddress, so no X display is needed. GLEW's
// glewInit still returns GLEW_ERROR_NO_GLX_DISPLAY (4) after loading all core entry points,
// because its GLX extension query finds no display; VTK then logs an error and retries on every
// Render. glewInit is interposed: the real one runs (found with dlsym(RTLD_NEXT)), and 4 is
// mapped to GLEW_OK (0).
#include "render/osmesa_context.hpp"

#include <GL/osmesa.h>
#include <dlfcn.h>

#include <stdexcept>
#include <string>

namespace {

using GlProc = void (*)();
constexpr unsigned int kGlewOk = 0;
constexpr unsigned int kGlewErrorNoGlxDisplay = 4;

}  // namespace

extern "C" {

// NOLINTNEXTLINE(readability-identifier-naming): the GLX name GLEW looks up.
__attribute__((visibility("default"))) GlProc glXGetProcAddressARB(const unsigned char* name) {
  return OSMesaGetProcAddress(reinterpret_cast<const char*>(name));
}

__attribute__((visibility("default"))) unsigned int glewInit() {
  using GlewInit = unsigned int (*)();
  static const auto real_glew_init = reinterpret_cast<GlewInit>(dlsym(RTLD_NEXT, "glewInit"));
  if (real_glew_init == nullptr) return kGlewErrorNoGlxDisplay;
  const unsigned int result = real_glew_init();
  return result == kGlewErrorNoGlxDisplay ? kGlewOk : result;
}

}  // extern "C"

namespace sphles::render::detail {

OsmesaContext::OsmesaContext(int width, int height)
    : width_(width),
      height_(height),
      buffer_(static_cast<std::size_t>(width) * static_cast<std::size_t>(height) * 4) {
  if (width <= 0 || height <= 0) throw std::invalid_argument("OsmesaContext: empty size");
  const int attributes[] = {OSMESA_FORMAT,
                            OSMESA_RGBA,
                            OSMESA_DEPTH_BITS,
                            24,
                            OSMESA_STENCIL_BITS,
                            8,
                            OSMESA_ACCUM_BITS,
                            0,
                            OSMESA_PROFILE,
                            OSMESA_CORE_PROFILE,
                            OSMESA_CONTEXT_MAJOR_VERSION,
                            3,
                            OSMESA_CONTEXT_MINOR_VERSION,
                            2,
                            0};
  context_ = OSMesaCreateContextAttribs(attributes, nullptr);
  if (context_ == nullptr) {
    throw std::runtime_error("OSMesaCreateContextAttribs failed (core profile 3.2)");
  }
  make_current();
}

OsmesaContext::~OsmesaContext() {
  if (context_ != nullptr) OSMesaDestroyContext(static_cast<OSMesaContext>(context_));
}

void OsmesaContext::make_current() {
  if (!OSMesaMakeCurrent(static_cast<OSMesaContext>(context_), buffer_.data(), GL_UNSIGNED_BYTE,
                         width_, height_)) {
    throw std::runtime_error("OSMesaMakeCurrent failed for " + std::to_string(width_) + "x" +
                             std::to_string(height_));
  }
}

}  // namespace sphles::render::detail
