// SPDX-License-Identifier: GPL-3.0-or-later
#include "sim/kernels.hpp"

#include <string>

namespace sphles::sim {

namespace {

template <class... Shapes>
std::string_view name_of(KernelType type, KernelShapeList<Shapes...>) {
  std::string_view found;
  ((Shapes::type == type ? (found = Shapes::name, true) : false) || ...);
  return found;
}

template <class... Shapes>
bool type_of(std::string_view name, KernelType& type, KernelShapeList<Shapes...>) {
  return ((Shapes::name == name ? (type = Shapes::type, true) : false) || ...);
}

template <class... Shapes>
std::string all_names(KernelShapeList<Shapes...>) {
  std::string valid;
  ((valid += (valid.empty() ? "" : ", ") + std::string(Shapes::name)), ...);
  return valid;
}

}  // namespace

std::string_view kernel_name(KernelType type) {
  const std::string_view name = name_of(type, KernelRegistry{});
  if (name.empty()) throw std::invalid_argument("unknown kernel type");
  return name;
}

KernelType kernel_from_name(std::string_view name) {
  KernelType type{};
  if (type_of(name, type, KernelRegistry{})) return type;
  throw std::invalid_argument("unknown kernel '" + std::string(name) +
                              "' (valid: " + all_names(KernelRegistry{}) + ")");
}

}  // namespace sphles::sim
