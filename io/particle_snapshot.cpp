#include "io/particle_snapshot.hpp"

#include <hdf5.h>

#include <algorithm>
#include <cstring>
#include <mutex>
#include <numeric>
#include <sstream>
#include <stdexcept>

#include "io/checkpoint.hpp"
#include "io/hdf5_file.hpp"

namespace sphles::io {

namespace {

using detail::Handle;
using detail::write_scalar_attribute;
using detail::write_string_attribute;

template <class T>
void dataset(hid_t file, const std::string& name, hid_t type, const std::vector<T>& data,
             hsize_t rows, hsize_t columns, const std::string& units, const std::string& label) {
  const hsize_t dims[2] = {rows, columns};
  const Handle space(H5Screate_simple(columns == 1 ? 1 : 2, dims, nullptr), H5Sclose);
  const Handle set(space.valid() ? H5Dcreate2(file, name.c_str(), type, space.get(), H5P_DEFAULT,
                                              H5P_DEFAULT, H5P_DEFAULT)
                                 : -1,
                   H5Dclose);
  if (!set.valid() ||
      (rows > 0 && H5Dwrite(set.get(), type, H5S_ALL, H5S_ALL, H5P_DEFAULT, data.data()) < 0))
    throw CheckpointError(label + ": cannot write dataset '" + name + "'");
  write_string_attribute(set.get(), "units", units, label);
}

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

}  // namespace

void write_particle_snapshot(const std::filesystem::path& path, const sim::ParticleArrays& p,
                             double time, std::uint64_t step,
                             const std::vector<ParticleField>& extra,
                             const SnapshotMetadata& metadata) {
  const std::string label = "snapshot '" + path.string() + "'";
  const std::size_t n = p.size();
  for (const ParticleField& f : extra)
    if (f.values.size() != n)
      throw CheckpointError(label + ": field '" + f.name + "' has " +
                            std::to_string(f.values.size()) + " values for " + std::to_string(n) +
                            " particles");
  const std::vector<std::size_t> row_of = id_order(p, label);
  const auto reordered = [&](const std::vector<double>& values) {
    std::vector<double> out(n);
    for (std::size_t k = 0; k < n; ++k) out[k] = values[row_of[k]];
    return out;
  };
  std::vector<double> xyz(3 * n, 0.0), uvw(3 * n, 0.0);
  std::vector<std::uint64_t> ids(n);
  std::iota(ids.begin(), ids.end(), std::uint64_t{0});
  for (std::size_t k = 0; k < n; ++k)
    for (int d = 0; d < p.dimension; ++d) {
      xyz[3 * k + static_cast<std::size_t>(d)] = p.position[d][row_of[k]];
      uvw[3 * k + static_cast<std::size_t>(d)] = p.velocity[d][row_of[k]];
    }
  const bool three = p.dimension == 3;
  detail::FileImage image;
  {
    const std::lock_guard lock(hdf5_library_mutex());
    detail::MemoryFile file(path, label);
    const hid_t root = file.get();
    write_string_attribute(root, "schema", kParticleSnapshotSchema, label);
    write_scalar_attribute(root, "schema_version", H5T_NATIVE_INT, kParticleSnapshotSchemaVersion,
                           label);
    write_string_attribute(root, "code_version", metadata.code_version, label);
    write_scalar_attribute(root, "time", H5T_NATIVE_DOUBLE, time, label);
    write_string_attribute(root, "time_units", "s", label);
    write_scalar_attribute(root, "step", H5T_NATIVE_UINT64, step, label);
    write_scalar_attribute(root, "dimension", H5T_NATIVE_INT, p.dimension, label);
    write_scalar_attribute(root, "num_particles", H5T_NATIVE_UINT64, static_cast<std::uint64_t>(n),
                           label);
    write_string_attribute(root, "scene", metadata.scene_json, label);
    dataset(root, "id", H5T_NATIVE_UINT64, ids, n, 1, "1", label);
    dataset(root, "position", H5T_NATIVE_DOUBLE, xyz, n, 3, "m", label);
    dataset(root, "velocity", H5T_NATIVE_DOUBLE, uvw, n, 3, "m/s", label);
    dataset(root, "mass", H5T_NATIVE_DOUBLE, reordered(p.mass), n, 1, three ? "kg" : "kg/m", label);
    dataset(root, "density", H5T_NATIVE_DOUBLE, reordered(p.density), n, 1,
            three ? "kg/m^3" : "kg/m^2", label);
    dataset(root, "pressure", H5T_NATIVE_DOUBLE, reordered(p.pressure), n, 1, "Pa", label);
    for (const ParticleField& f : extra)
      dataset(root, f.name, H5T_NATIVE_DOUBLE, reordered(f.values), n, 1, f.units, label);
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

std::string hdf5_schema(const std::filesystem::path& path) {
  const std::string label = "file '" + path.string() + "'";
  const std::lock_guard lock(hdf5_library_mutex());
  detail::silence_hdf5();
  if (!std::filesystem::is_regular_file(path)) throw CheckpointError(label + ": no such file");
  if (H5Fis_hdf5(path.c_str()) <= 0) throw CheckpointError(label + ": not an HDF5 file");
  const Handle file(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
  if (!file.valid()) throw CheckpointError(label + ": HDF5 cannot open it");
  return attribute_text(file.get(), "schema");
}

std::string describe_particle_snapshot(const std::filesystem::path& path) {
  const std::string label = "snapshot '" + path.string() + "'";
  const std::lock_guard lock(hdf5_library_mutex());
  detail::silence_hdf5();
  if (H5Fis_hdf5(path.c_str()) <= 0) throw CheckpointError(label + ": not an HDF5 file");
  const Handle file(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
  if (!file.valid()) throw CheckpointError(label + ": HDF5 cannot open it");
  const hid_t root = file.get();
  if (attribute_text(root, "schema") != kParticleSnapshotSchema)
    throw CheckpointError(label + ": attribute 'schema' is not '" +
                          std::string(kParticleSnapshotSchema) + "'");
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
