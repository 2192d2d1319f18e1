// SPDX-License-Identifier: GPL-3.0-or-later
// Numbers in messages: the shortest form a reader recognises (std::ostream's default, 6
// significant digits), the same in every error and log line that quotes a value.
#pragma once

#include <sstream>
#include <string>

namespace sphles::sim {

inline std::string format_number(double value) {
  std::ostringstream s;
  s << value;
  return s.str();
}

}  // namespace sphles::sim
