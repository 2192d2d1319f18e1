// SPDX-License-Identifier: GPL-3.0-or-later
#include "spectral/reference_checkpoint.hpp"

#include <hdf5.h>

#include <cmath>
#include <cstdio>
#include <mutex>

#include "io/checkpoint.hpp"
#include "io/hdf5_file.hpp"

namespace sphles::spectral {

namespace {

using io::CheckpointError;
using io::detail::Handle;

std::string label_of(const std::filesystem::path& path) {
  return "reference checkpoint '" + path.string() + "'";
}

template <class T>
T read_scalar(hid_t file, const char* name, hid_t type, const std::string& label) {
  if (H5Aexists(file, name) <= 0)
    throw CheckpointError(label + ": has no attribute '" + name + "'");
  Handle attribute(H5Aopen(file, name, H5P_DEFAULT), H5Aclose);
  T value{};
  if (!attribute.valid() || H5Aread(attribute.get(), type, &value) < 0)
    throw CheckpointError(label + ": cannot read attribute '" + name + "'");
  return value;
}

std::string read_string(hid_t file, const char* name, const std::string& label) {
  if (H5Aexists(file, name) <= 0)
    throw CheckpointError(label + ": has no attribute '" + name + "'");
  Handle attribute(H5Aopen(file, name, H5P_DEFAULT), H5Aclose);
  Handle type(H5Aget_type(attribute.get()), H5Tclose);
  if (!type.valid() || H5Tget_class(type.get()) != H5T_STRING || H5Tis_variable_str(type.get()))
    throw CheckpointError(label + ": attribute '" + name + "' is not a fixed-length string");
  std::string value(H5Tget_size(type.get()), '\0');
  if (H5Aread(attribute.get(), type.get(), value.data()) < 0)
    throw CheckpointError(label + ": cannot read attribute '" + name + "'");
  value.resize(value.find('\0') == std::string::npos ? value.size() : value.find('\0'));
  return value;
}

}  // namespace

std::string reference_checkpoint_name(std::uint64_t step) {
  char name[32];
  std::snprintf(name, sizeof name, "ref_%010llu.h5", static_cast<unsigned long long>(step));
  return name;
}

void write_reference_checkpoint(const std::filesystem::path& path, const ReferenceState& state) {
  const std::string label = label_of(path);
  io::detail::FileImage image;
  {
    std::lock_guard<std::mutex> lock(io::hdf5_library_mutex());
    io::detail::silence_hdf5();
    io::detail::MemoryFile file(path, label);
    const hid_t f = file.get();
    io::detail::write_string_attribute(f, "schema", kReferenceCheckpointSchema, label);
    io::detail::write_scalar_attribute(f, "time", H5T_NATIVE_DOUBLE, state.time, label);
    io::detail::write_scalar_attribute(f, "step", H5T_NATIVE_UINT64, state.step, label);
    io::detail::write_scalar_attribute(f, "dimension", H5T_NATIVE_INT, state.dimension, label);
    io::detail::write_scalar_attribute(f, "points_per_side", H5T_NATIVE_INT, state.points_per_side,
                                       label);
    io::detail::write_string_attribute(f, "scene", state.scene, label);
    for (int c = 0; c < state.dimension; ++c) {
      const std::string name = "modes_" + std::to_string(c);
      const hsize_t dims[2] = {state.modes[c].size(), 2};
      Handle space(H5Screate_simple(2, dims, nullptr), H5Sclose);
      Handle dataset(H5Dcreate2(f, name.c_str(), H5T_IEEE_F64LE, space.get(), H5P_DEFAULT,
                                H5P_DEFAULT, H5P_DEFAULT),
                     H5Dclose);
      if (!dataset.valid() || H5Dwrite(dataset.get(), H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL,
                                       H5P_DEFAULT, state.modes[c].data()) < 0)
        throw CheckpointError(label + ": cannot write dataset '" + name + "'");
    }
    image = file.finish();
  }
  io::detail::write_file_atomically(path, image, label);
}

ReferenceState read_reference_checkpoint(const std::filesystem::path& path) {
  const std::string label = label_of(path);
  std::lock_guard<std::mutex> lock(io::hdf5_library_mutex());
  io::detail::silence_hdf5();
  if (!std::filesystem::is_regular_file(path)) throw CheckpointError(label + ": no such file");
  Handle file(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
  if (!file.valid()) throw CheckpointError(label + ": not an HDF5 file, or damaged");
  const hid_t f = file.get();
  const std::string schema = read_string(f, "schema", label);
  if (schema != kReferenceCheckpointSchema)
    throw CheckpointError(label + ": schema is '" + schema + "', not '" +
                          kReferenceCheckpointSchema + "'");
  ReferenceState s;
  s.time = read_scalar<double>(f, "time", H5T_NATIVE_DOUBLE, label);
  s.step = read_scalar<std::uint64_t>(f, "step", H5T_NATIVE_UINT64, label);
  s.dimension = read_scalar<int>(f, "dimension", H5T_NATIVE_INT, label);
  s.points_per_side = read_scalar<int>(f, "points_per_side", H5T_NATIVE_INT, label);
  s.scene = read_string(f, "scene", label);
  if (!std::isfinite(s.time) || s.time < 0.0)
    throw CheckpointError(label + ": time is not a finite non-negative number");
  if (s.dimension != 2 && s.dimension != 3)
    throw CheckpointError(label + ": dimension " + std::to_string(s.dimension) + " is not 2 or 3");
  if (s.points_per_side < 4 || s.points_per_side % 2 != 0 || s.points_per_side > 4096)
    throw CheckpointError(label + ": points_per_side " + std::to_string(s.points_per_side) +
                          " is not an even number in [4, 4096]");
  const std::size_t n = static_cast<std::size_t>(s.points_per_side);
  const std::size_t expected = (n / 2 + 1) * (s.dimension == 3 ? n * n : n);
  for (int c = 0; c < s.dimension; ++c) {
    const std::string name = "modes_" + std::to_string(c);
    if (H5Lexists(f, name.c_str(), H5P_DEFAULT) <= 0)
      throw CheckpointError(label + ": has no dataset '" + name + "'");
    Handle dataset(H5Dopen2(f, name.c_str(), H5P_DEFAULT), H5Dclose);
    Handle space(H5Dget_space(dataset.get()), H5Sclose);
    hsize_t dims[2] = {0, 0};
    if (!space.valid() || H5Sget_simple_extent_ndims(space.get()) != 2 ||
        H5Sget_simple_extent_dims(space.get(), dims, nullptr) < 0 || dims[0] != expected ||
        dims[1] != 2)
      throw CheckpointError(label + ": dataset '" + name + "' is not of shape (" +
                            std::to_string(expected) + ", 2)");
    s.modes[c].resize(expected);
    if (H5Dread(dataset.get(), H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT,
                s.modes[c].data()) < 0)
      throw CheckpointError(label + ": cannot read dataset '" + name + "'");
    for (const Complex& z : s.modes[c])
      if (!std::isfinite(z.real()) || !std::isfinite(z.imag()))
        throw CheckpointError(label + ": dataset '" + name + "' holds a non-finite value");
  }
  return s;
}

}  // namespace sphles::spectral
