#include "sim/kernels.hpp"

#include <array>
#include <utility>

namespace sphles::sim {

namespace {
constexpr std::array<std::pair<KernelType, std::string_view>, 4> kKernelNames{{
    {KernelType::WendlandC2, "wendland_c2"},
    {KernelType::WendlandC4, "wendland_c4"},
    {KernelType::WendlandC6, "wendland_c6"},
    {KernelType::QuinticSpline, "quintic_spline"},
}};
}  // namespace

std::string_view kernel_name(KernelType type) {
  for (const auto& [t, name] : kKernelNames)
    if (t == type) return name;
  throw std::invalid_argument("unknown kernel type");
}

KernelType kernel_from_name(std::string_view name) {
  for (const auto& [t, n] : kKernelNames)
    if (n == name) return t;
  std::string valid;
  for (const auto& [t, n] : kKernelNames) valid += (valid.empty() ? "" : ", ") + std::string(n);
  throw std::invalid_argument("unknown kernel '" + std::string(name) + "' (valid: " + valid + ")");
}

}  // namespace sphles::sim
