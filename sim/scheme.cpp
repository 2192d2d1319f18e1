// SPDX-License-Identifier: GPL-3.0-or-later
#include "sim/scheme.hpp"

#include <string>

namespace sphles::sim {

namespace {

template <class... Schemes>
constexpr auto registered_names(SchemeList<Schemes...>) {
  return std::array<std::pair<SchemeType, std::string_view>, sizeof...(Schemes)>{
      {{Schemes::type, Schemes::name}...}};
}

constexpr auto kSchemeNames = registered_names(SchemeRegistry{});

constexpr std::array<std::pair<AleCorrection, std::string_view>, 2> kAleCorrectionNames{{
    {AleCorrection::Conservative, "conservative"},
    {AleCorrection::Full, "full"},
}};

}  // namespace

std::string_view scheme_name(SchemeType type) {
  for (const auto& [t, name] : kSchemeNames)
    if (t == type) return name;
  return "unknown";
}

SchemeType scheme_from_name(std::string_view name) {
  std::string valid;
  for (const auto& [t, n] : kSchemeNames) {
    if (n == name) return t;
    valid += (valid.empty() ? "" : ", ") + std::string(n);
  }
  throw std::invalid_argument("unknown scheme '" + std::string(name) + "' (valid: " + valid + ")");
}

bool scheme_uses_transport_velocity(SchemeType type) {
  bool uses = false;
  visit_scheme(type, [&](auto scheme) { uses = decltype(scheme)::transport_velocity; });
  return uses;
}

std::string_view ale_correction_name(AleCorrection ale) {
  for (const auto& [a, name] : kAleCorrectionNames)
    if (a == ale) return name;
  return "unknown";
}

AleCorrection ale_correction_from_name(std::string_view name) {
  for (const auto& [a, n] : kAleCorrectionNames)
    if (n == name) return a;
  throw std::invalid_argument("must be one of conservative, full, got '" + std::string(name) + "'");
}

}  // namespace sphles::sim
