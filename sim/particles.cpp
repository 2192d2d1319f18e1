// SPDX-License-Identifier: GPL-3.0-or-later
#include "sim/particles.hpp"

#include <numeric>
#include <stdexcept>

namespace sphles::sim {

void ParticleArrays::resize(std::size_t n) {
  for (int d = 0; d < 3; ++d) {
    const std::size_t m = d < dimension ? n : 0;
    position[d].assign(m, 0.0);
    velocity[d].assign(m, 0.0);
    acceleration[d].assign(m, 0.0);
  }
  mass.assign(n, 0.0);
  volume.assign(n, 0.0);
  density.assign(n, 0.0);
  pressure.assign(n, 0.0);
  eddy_viscosity.clear();
  id.resize(n);
  std::iota(id.begin(), id.end(), std::uint64_t{0});
}

void ParticleArrays::truncate(std::size_t n) {
  if (n > size()) throw std::invalid_argument("particles: cannot truncate to more than size()");
  for (std::vector<double>* f : double_fields()) f->resize(n);
  id.resize(n);
}

namespace {
template <class T>
void permute(std::vector<T>& values, std::span<const std::uint32_t> order,
             std::vector<T>& scratch) {
  if (values.empty()) return;
  scratch.resize(values.size());
  const auto n = static_cast<std::ptrdiff_t>(order.size());
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t k = 0; k < n; ++k)
    scratch[static_cast<std::size_t>(k)] = values[order[static_cast<std::size_t>(k)]];
  values.swap(scratch);
}
}  // namespace

void ParticleArrays::reorder(std::span<const std::uint32_t> order) {
  if (order.size() != size()) throw std::invalid_argument("reorder: permutation size mismatch");
  std::vector<double> scratch;
  for (std::vector<double>* field : double_fields()) permute(*field, order, scratch);
  std::vector<std::uint64_t> id_scratch;
  permute(id, order, id_scratch);
}

std::vector<std::vector<double>*> ParticleArrays::double_fields() {
  std::vector<std::vector<double>*> fields;
  for (int d = 0; d < dimension; ++d) fields.push_back(&position[d]);
  for (int d = 0; d < dimension; ++d) fields.push_back(&velocity[d]);
  for (int d = 0; d < dimension; ++d) fields.push_back(&acceleration[d]);
  for (std::vector<double>* f : {&mass, &volume, &density, &pressure}) fields.push_back(f);
  if (!eddy_viscosity.empty()) fields.push_back(&eddy_viscosity);
  return fields;
}

std::vector<const std::vector<double>*> ParticleArrays::double_fields() const {
  std::vector<const std::vector<double>*> fields;
  for (std::vector<double>* f : const_cast<ParticleArrays*>(this)->double_fields())
    fields.push_back(f);
  return fields;
}

}  // namespace sphles::sim
