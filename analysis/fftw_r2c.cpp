// SPDX-License-Identifier: GPL-3.0-or-later
#include "analysis/fftw_r2c.hpp"

namespace sphles::analysis {

std::unique_lock<std::mutex> fftw_planner_lock() {
  static std::mutex mutex;
  return std::unique_lock<std::mutex>(mutex);
}

}  // namespace sphles::analysis
