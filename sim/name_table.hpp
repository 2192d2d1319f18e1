// SPDX-License-Identifier: GPL-3.0-or-later
// The one mapping between an enum and the names a scene, a file or the API spells it with. Every
// enum with names has one NameTable; its name, its lookup, the list a schema publishes and the
// error for a name it does not know all come from it.
#pragma once

#include <array>
#include <cstddef>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace sphles::sim {

template <class Enum, std::size_t N>
struct NameTable {
  std::array<std::pair<Enum, std::string_view>, N> entries;

  /// The name of `value`; every value of the enum has one (a missing entry is a programming
  /// error and throws std::logic_error).
  constexpr std::string_view name(Enum value) const {
    for (const auto& [v, name] : entries)
      if (v == value) return name;
    throw std::logic_error("NameTable: a value without a name");
  }

  /// The value named `name`, nullopt if none is.
  constexpr std::optional<Enum> find(std::string_view name) const {
    for (const auto& [v, n] : entries)
      if (n == name) return v;
    return std::nullopt;
  }

  /// Every name, in the table's order (the order a schema lists them in).
  std::vector<std::string> names() const {
    std::vector<std::string> out;
    out.reserve(N);
    for (const auto& entry : entries) out.emplace_back(entry.second);
    return out;
  }

  /// "a, b, c": the names for a message.
  std::string list() const {
    std::string out;
    for (const auto& entry : entries) out += (out.empty() ? "" : ", ") + std::string(entry.second);
    return out;
  }
};

/// A table from a compile-time registry of types that each declare `type` and `name` (the
/// kernel, scheme and sub-filter registries), in the registry's order.
template <class Enum, template <class...> class List, class... Members>
constexpr NameTable<Enum, sizeof...(Members)> registry_names(List<Members...>) {
  return {{{{Members::type, Members::name}...}}};
}

}  // namespace sphles::sim
