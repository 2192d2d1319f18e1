// SPDX-License-Identifier: GPL-3.0-or-later
#include "sim/scheme.hpp"

#include <string>
#include <vector>

namespace sphles::sim {

std::string_view scheme_name(SchemeType type) {
  return kSchemeNames.name(type);
}

bool scheme_uses_transport_velocity(SchemeType type) {
  bool uses = false;
  visit_scheme(type, [&](auto scheme) { uses = decltype(scheme)::transport_velocity; });
  return uses;
}

bool scheme_takes(SchemeType type, std::string_view key) {
  bool takes = false;
  visit_scheme(type, [&](auto scheme) {
    for (const std::string_view k : decltype(scheme)::parameters) takes = takes || k == key;
  });
  return takes;
}

std::string schemes_taking(std::string_view key) {
  std::vector<std::string_view> names;
  for (const auto& [type, name] : kSchemeNames.entries)
    if (scheme_takes(type, key)) names.push_back(name);
  std::string text;
  for (std::size_t k = 0; k < names.size(); ++k)
    text += (k == 0 ? "" : k + 1 == names.size() ? " and " : ", ") + std::string(names[k]);
  return text;
}

std::string_view ale_correction_name(AleCorrection ale) {
  return kAleCorrectionNames.name(ale);
}

}  // namespace sphles::sim
