// SPDX-License-Identifier: GPL-3.0-or-later
#include "io/particle_snapshot_format.hpp"

#include <hdf5.h>

#include <numeric>
#include <string>
#include <vector>

#include "io/checkpoint_error.hpp"
#include "io/hdf5_file.hpp"

namespace sphles::io::particle_snapshot_format {

using detail::Handle;
using detail::write_scalar_attribute;
using detail::write_string_attribute;

Rows rows_of(const sim::ParticleArrays& p, const std::vector<std::size_t>& row_of,
             std::uint64_t first, std::uint64_t total, const std::vector<ParticleField>& extra) {
  const std::size_t n = row_of.size();
  Rows rows;
  rows.dimension = p.dimension;
  rows.first = first;
  rows.total = total;
  const auto reordered = [&](const std::vector<double>& values) {
    std::vector<double> out(n);
    for (std::size_t k = 0; k < n; ++k) out[k] = values[row_of[k]];
    return out;
  };
  rows.id.resize(n);
  std::iota(rows.id.begin(), rows.id.end(), first);
  rows.position.assign(3 * n, 0.0);
  rows.velocity.assign(3 * n, 0.0);
  for (std::size_t k = 0; k < n; ++k)
    for (int d = 0; d < p.dimension; ++d) {
      rows.position[3 * k + static_cast<std::size_t>(d)] = p.position[d][row_of[k]];
      rows.velocity[3 * k + static_cast<std::size_t>(d)] = p.velocity[d][row_of[k]];
    }
  rows.mass = reordered(p.mass);
  rows.density = reordered(p.density);
  rows.pressure = reordered(p.pressure);
  for (const ParticleField& f : extra) rows.extra.push_back({f.name, f.units, reordered(f.values)});
  return rows;
}

namespace {

/// The dataset `name` of rows.total x `columns` entries (one column: a 1D dataset), this
/// process' rows written; a process with none still takes part in a collective write.
template <class T>
void dataset(hid_t file, const std::string& name, hid_t type, const std::vector<T>& data,
             hsize_t columns, const std::string& units, const std::string& label,
             const Rows& rows) {
  const int rank = columns == 1 ? 1 : 2;
  const hsize_t dims[2] = {rows.total, columns};
  const Handle space(H5Screate_simple(rank, dims, nullptr), H5Sclose);
  // Every entry is written, so no fill value: through MPI-IO, HDF5 would write fill values
  // when it allocates the dataset, and those writes are not ordered before the other
  // processes' writes of their rows (a process' rows could be overwritten by fill values).
  const Handle properties(H5Pcreate(H5P_DATASET_CREATE), H5Pclose);
  const bool created = space.valid() && properties.valid() &&
                       H5Pset_fill_time(properties.get(), H5D_FILL_TIME_NEVER) >= 0;
  const Handle set(created ? H5Dcreate2(file, name.c_str(), type, space.get(), H5P_DEFAULT,
                                        properties.get(), H5P_DEFAULT)
                           : -1,
                   H5Dclose);
  const auto failed = [&] {
    return CheckpointError(label + ": cannot write dataset '" + name + "'");
  };
  if (!set.valid()) throw failed();
  if (rows.total > 0) {
    const hsize_t start[2] = {rows.first, 0};
    const hsize_t count[2] = {rows.count(), columns};
    const hsize_t one[2] = {1, columns};
    const Handle memory(H5Screate_simple(rank, rows.count() > 0 ? count : one, nullptr), H5Sclose);
    const herr_t selected =
        rows.count() > 0
            ? H5Sselect_hyperslab(space.get(), H5S_SELECT_SET, start, nullptr, count, nullptr)
            : std::min(H5Sselect_none(space.get()), H5Sselect_none(memory.get()));
    if (!memory.valid() || selected < 0 ||
        H5Dwrite(set.get(), type, memory.get(), space.get(), rows.transfer, data.data()) < 0)
      throw failed();
  }
  write_string_attribute(set.get(), "units", units, label);
}

}  // namespace

void write_contents(hid_t root, const Rows& rows, double time, std::uint64_t step,
                    const SnapshotMetadata& metadata, const std::string& label) {
  const bool three = rows.dimension == 3;
  write_string_attribute(root, "schema", kParticleSnapshotSchema, label);
  write_scalar_attribute(root, "schema_version", H5T_NATIVE_INT, kParticleSnapshotSchemaVersion,
                         label);
  write_string_attribute(root, "code_version", metadata.code_version, label);
  write_scalar_attribute(root, "time", H5T_NATIVE_DOUBLE, time, label);
  write_string_attribute(root, "time_units", "s", label);
  write_scalar_attribute(root, "step", H5T_NATIVE_UINT64, step, label);
  write_scalar_attribute(root, "dimension", H5T_NATIVE_INT, rows.dimension, label);
  write_scalar_attribute(root, "num_particles", H5T_NATIVE_UINT64,
                         static_cast<std::uint64_t>(rows.total), label);
  write_string_attribute(root, "scene", metadata.scene_json, label);
  dataset(root, "id", H5T_NATIVE_UINT64, rows.id, 1, "1", label, rows);
  dataset(root, "position", H5T_NATIVE_DOUBLE, rows.position, 3, "m", label, rows);
  dataset(root, "velocity", H5T_NATIVE_DOUBLE, rows.velocity, 3, "m/s", label, rows);
  dataset(root, "mass", H5T_NATIVE_DOUBLE, rows.mass, 1, three ? "kg" : "kg/m", label, rows);
  dataset(root, "density", H5T_NATIVE_DOUBLE, rows.density, 1, three ? "kg/m^3" : "kg/m^2", label,
          rows);
  dataset(root, "pressure", H5T_NATIVE_DOUBLE, rows.pressure, 1, "Pa", label, rows);
  for (const ParticleField& f : rows.extra)
    dataset(root, f.name, H5T_NATIVE_DOUBLE, f.values, 1, f.units, label, rows);
}

void check_fields(const std::vector<ParticleField>& extra, std::size_t n,
                  const std::string& label) {
  for (const ParticleField& f : extra)
    if (f.values.size() != n)
      throw CheckpointError(label + ": field '" + f.name + "' has " +
                            std::to_string(f.values.size()) + " values for " + std::to_string(n) +
                            " particles");
}

}  // namespace sphles::io::particle_snapshot_format
