// SPDX-License-Identifier: GPL-3.0-or-later
#include "sim/scheme.hpp"

#include <string>

namespace sphles::sim {

std::string_view scheme_name(SchemeType type) {
  return kSchemeNames.name(type);
}

bool scheme_uses_transport_velocity(SchemeType type) {
  bool uses = false;
  visit_scheme(type, [&](auto scheme) { uses = decltype(scheme)::transport_velocity; });
  return uses;
}

std::string_view ale_correction_name(AleCorrection ale) {
  return kAleCorrectionNames.name(ale);
}

}  // namespace sphles::sim
