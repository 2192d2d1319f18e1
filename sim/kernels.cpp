// SPDX-License-Identifier: GPL-3.0-or-later
#include "sim/kernels.hpp"

namespace sphles::sim {

std::string_view kernel_name(KernelType type) {
  return kKernelNames.name(type);
}

}  // namespace sphles::sim
