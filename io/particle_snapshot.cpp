// SPDX-License-Identifier: GPL-3.0-or-later
#include "io/particle_snapshot.hpp"

#include <hdf5.h>

#include <algorithm>
#include <cstring>
#include <mutex>
#include <numeric>
#include <optional>
#include <sstream>
#include <stdexcept>

#include "io/checkpoint.hpp"
#include "io/hdf5_file.hpp"
#include "io/particle_snapshot_format.hpp"

namespace sphles::io {

namespace {

using detail::Handle;
using particle_snapshot_format::check_fields;
using particle_snapshot_format::Rows;
using particle_snapshot_format::rows_of;
using particle_snapshot_format::write_contents;

/// row_of[k] = the array index of the particle with id k. Throws unless the ids are a
/// permutation of 0..N-1.
std::vector<std::size_t> id_order(const sim::ParticleArrays& p, const std::string& label) {
  const std::size_t n = p.size();
  if (p.id.size() != n)
    throw CheckpointError(label + ": " + std::to_string(p.id.size()) + " ids for " +
                          std::to_string(n) + " particles");
  std::vector<std::size_t> row_of(n, n);
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint64_t id = p.id[i];
    if (id >= n || row_of[id] != n)
      throw CheckpointError(label + ": particle ids are not a permutation of 0.." +
                            std::to_string(n - 1) + " (id " + std::to_string(id) + " at index " +
                            std::to_string(i) + ")");
    row_of[id] = i;
  }
  return row_of;
}

std::string attribute_text(hid_t object, const char* name) {
  if (H5Aexists(object, name) <= 0) return {};
  const Handle attribute(H5Aopen(object, name, H5P_DEFAULT), H5Aclose);
  const Handle type(H5Aget_type(attribute.get()), H5Tclose);
  if (!type.valid()) return {};
  if (H5Tget_class(type.get()) == H5T_STRING && H5Tis_variable_str(type.get()) <= 0) {
    std::string value(H5Tget_size(type.get()), '\0');
    if (H5Aread(attribute.get(), type.get(), value.data()) < 0) return {};
    value.resize(std::strlen(value.c_str()));
    return value;
  }
  if (H5Tget_class(type.get()) == H5T_FLOAT) {
    double v = 0.0;
    if (H5Aread(attribute.get(), H5T_NATIVE_DOUBLE, &v) < 0) return {};
    std::ostringstream s;
    s.precision(17);
    s << v;
    return s.str();
  }
  if (H5Tget_class(type.get()) == H5T_INTEGER) {
    long long v = 0;
    if (H5Aread(attribute.get(), H5T_NATIVE_LLONG, &v) < 0) return {};
    return std::to_string(v);
  }
  return {};
}

std::vector<double> read_doubles(hid_t file, const char* name, std::size_t expected,
                                 const std::string& label) {
  const Handle set(H5Lexists(file, name, H5P_DEFAULT) > 0 ? H5Dopen2(file, name, H5P_DEFAULT) : -1,
                   H5Dclose);
  if (!set.valid()) throw CheckpointError(label + ": missing dataset '" + name + "'");
  const Handle space(H5Dget_space(set.get()), H5Sclose);
  if (H5Sget_simple_extent_npoints(space.get()) != static_cast<hssize_t>(expected))
    throw CheckpointError(label + ": dataset '" + name + "' has the wrong size");
  std::vector<double> values(expected);
  if (expected > 0 &&
      H5Dread(set.get(), H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, values.data()) < 0)
    throw CheckpointError(label + ": cannot read dataset '" + name + "'");
  return values;
}

/// `path` opened for reading (call with the HDF5 library lock held); throws naming it when it is
/// missing or not an HDF5 file HDF5 can open.
Handle open_for_reading(const std::filesystem::path& path, const std::string& label) {
  detail::silence_hdf5();
  if (!std::filesystem::is_regular_file(path)) throw CheckpointError(label + ": no such file");
  if (H5Fis_hdf5(path.c_str()) <= 0) throw CheckpointError(label + ": not an HDF5 file");
  const hid_t file = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  if (file < 0) throw CheckpointError(label + ": HDF5 cannot open it");
  return Handle(file, H5Fclose);
}

void require_snapshot_schema(hid_t root, const std::string& label) {
  if (attribute_text(root, "schema") != kParticleSnapshotSchema)
    throw CheckpointError(label + ": attribute 'schema' is not '" +
                          std::string(kParticleSnapshotSchema) + "'");
}

}  // namespace

void write_particle_snapshot(const std::filesystem::path& path, const sim::ParticleArrays& p,
                             double time, std::uint64_t step,
                             const std::vector<ParticleField>& extra,
                             const SnapshotMetadata& metadata) {
  const std::string label = "snapshot '" + path.string() + "'";
  check_fields(extra, p.size(), label);
  const Rows rows = rows_of(p, id_order(p, label), 0, p.size(), extra);
  detail::FileImage image;
  {
    const std::lock_guard lock(hdf5_library_mutex());
    detail::MemoryFile file(path, label);
    write_contents(file.get(), rows, time, step, metadata, label);
    image = file.finish();
  }
  detail::write_file_atomically(path, image, label);
}

void write_xdmf_series(const std::filesystem::path& path,
                       const std::vector<SnapshotEntry>& entries) {
  std::ostringstream x;
  x.precision(17);
  x << "<?xml version=\"1.0\" ?>\n"
    << "<Xdmf Version=\"3.0\">\n"
    << "  <Domain>\n"
    << "    <Grid Name=\"particles\" GridType=\"Collection\" CollectionType=\"Temporal\">\n";
  for (const SnapshotEntry& e : entries) {
    const std::string n = std::to_string(e.count);
    const auto item = [&](const std::string& dims, const std::string& dataset,
                          const char* type = "Float") {
      return "<DataItem Dimensions=\"" + dims + "\" NumberType=\"" + type +
             "\" Precision=\"8\" Format=\"HDF\">" + e.file + ":/" + dataset + "</DataItem>";
    };
    x << "      <Grid Name=\"" << e.file << "\" GridType=\"Uniform\">\n"
      << "        <Time Value=\"" << e.time << "\"/>\n"
      << "        <Topology TopologyType=\"Polyvertex\" NumberOfElements=\"" << n
      << "\" NodesPerElement=\"1\">" << item(n, "id", "UInt") << "</Topology>\n"
      << "        <Geometry GeometryType=\"XYZ\">" << item(n + " 3", "position") << "</Geometry>\n"
      << "        <Attribute Name=\"id\" AttributeType=\"Scalar\" Center=\"Node\">"
      << item(n, "id", "UInt") << "</Attribute>\n"
      << "        <Attribute Name=\"velocity\" AttributeType=\"Vector\" Center=\"Node\">"
      << item(n + " 3", "velocity") << "</Attribute>\n";
    std::vector<std::string> scalars{"mass", "density", "pressure"};
    scalars.insert(scalars.end(), e.scalars.begin(), e.scalars.end());
    for (const std::string& s : scalars)
      x << "        <Attribute Name=\"" << s << "\" AttributeType=\"Scalar\" Center=\"Node\">"
        << item(n, s) << "</Attribute>\n";
    x << "      </Grid>\n";
  }
  x << "    </Grid>\n  </Domain>\n</Xdmf>\n";
  detail::write_file_atomically(path, x.str(), "snapshot series '" + path.string() + "'");
}

ParticleSnapshotContents read_particle_snapshot(const std::filesystem::path& path) {
  const std::string label = "snapshot '" + path.string() + "'";
  const std::lock_guard lock(hdf5_library_mutex());
  const Handle file = open_for_reading(path, label);
  const hid_t root = file.get();
  require_snapshot_schema(root, label);
  ParticleSnapshotContents contents;
  H5O_info_t object{};
  if (H5Oget_info(root, &object) < 0) throw CheckpointError(label + ": cannot list attributes");
  for (hsize_t k = 0; k < object.num_attrs; ++k) {
    char name[256] = {};
    if (H5Aget_name_by_idx(root, ".", H5_INDEX_NAME, H5_ITER_INC, k, name, sizeof name,
                           H5P_DEFAULT) < 0)
      throw CheckpointError(label + ": cannot read an attribute's name");
    contents.attributes[name] = attribute_text(root, name);
  }
  H5G_info_t info{};
  if (H5Gget_info(root, &info) < 0) throw CheckpointError(label + ": cannot list datasets");
  for (hsize_t k = 0; k < info.nlinks; ++k) {
    char name[256] = {};
    if (H5Lget_name_by_idx(root, ".", H5_INDEX_NAME, H5_ITER_INC, k, name, sizeof name,
                           H5P_DEFAULT) < 0)
      throw CheckpointError(label + ": cannot read a dataset's name");
    const Handle set(H5Dopen2(root, name, H5P_DEFAULT), H5Dclose);
    const Handle space(set.valid() ? H5Dget_space(set.get()) : -1, H5Sclose);
    const hssize_t points = space.valid() ? H5Sget_simple_extent_npoints(space.get()) : -1;
    if (points < 0) throw CheckpointError(label + ": cannot open dataset '" + name + "'");
    ParticleSnapshotContents::Dataset& d = contents.datasets[name];
    d.values = read_doubles(root, name, static_cast<std::size_t>(points), label);
    d.units = attribute_text(set.get(), "units");
  }
  return contents;
}

std::string hdf5_schema(const std::filesystem::path& path) {
  const std::string label = "file '" + path.string() + "'";
  const std::lock_guard lock(hdf5_library_mutex());
  return attribute_text(open_for_reading(path, label).get(), "schema");
}

std::string describe_particle_snapshot(const std::filesystem::path& path) {
  const std::string label = "snapshot '" + path.string() + "'";
  const std::lock_guard lock(hdf5_library_mutex());
  const Handle file = open_for_reading(path, label);
  const hid_t root = file.get();
  require_snapshot_schema(root, label);
  std::ostringstream out;
  out << "file:             " << path.string() << " (" << std::filesystem::file_size(path)
      << " bytes)\n";
  for (const char* name :
       {"schema", "schema_version", "code_version", "dimension", "num_particles", "time", "step"})
    out << std::string(name) + ":" << std::string(17 - std::strlen(name), ' ')
        << attribute_text(root, name) << (std::string(name) == "time" ? " s" : "") << "\n";
  const std::string count_text = attribute_text(root, "num_particles");
  const std::size_t n = count_text.empty() ? 0 : std::stoull(count_text);
  out << "datasets:\n";
  H5G_info_t info{};
  H5Gget_info(root, &info);
  for (hsize_t k = 0; k < info.nlinks; ++k) {
    char name[256] = {};
    if (H5Lget_name_by_idx(root, ".", H5_INDEX_NAME, H5_ITER_INC, k, name, sizeof name,
                           H5P_DEFAULT) < 0)
      continue;
    const Handle set(H5Dopen2(root, name, H5P_DEFAULT), H5Dclose);
    if (!set.valid()) continue;
    const Handle space(H5Dget_space(set.get()), H5Sclose);
    hsize_t dims[2] = {0, 1};
    const int rank = H5Sget_simple_extent_dims(space.get(), dims, nullptr);
    out << "  " << name << std::string(std::max<std::size_t>(1, 18 - std::strlen(name)), ' ')
        << dims[0] << (rank == 2 ? " x " + std::to_string(dims[1]) : std::string()) << "  ["
        << attribute_text(set.get(), "units") << "]\n";
  }
  // Row k must hold id k (schema version 2).
  const std::vector<double> ids = read_doubles(root, "id", n, label);
  std::size_t misplaced = 0;
  for (std::size_t k = 0; k < n; ++k) misplaced += ids[k] != static_cast<double>(k);
  out << "id order:         "
      << (misplaced == 0 ? "row k holds id k"
                         : "NOT in id order (" + std::to_string(misplaced) + " rows)")
      << "\n";
  const std::vector<double> mass = read_doubles(root, "mass", n, label);
  const std::vector<double> velocity = read_doubles(root, "velocity", 3 * n, label);
  double kinetic = 0.0, total = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const double v2 = velocity[3 * i] * velocity[3 * i] +
                      velocity[3 * i + 1] * velocity[3 * i + 1] +
                      velocity[3 * i + 2] * velocity[3 * i + 2];
    kinetic += 0.5 * mass[i] * v2;
    total += mass[i];
  }
  out.precision(17);
  out << "e_v:              " << (total > 0.0 ? kinetic / total : 0.0) << " m^2/s^2\n"
      << "scene:            " << attribute_text(root, "scene") << "\n";
  return out.str();
}

}  // namespace sphles::io
