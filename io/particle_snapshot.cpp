#include "io/particle_snapshot.hpp"

#include <hdf5.h>
#include <unistd.h>

#include <fstream>
#include <mutex>
#include <sstream>
#include <stdexcept>

#include "io/checkpoint.hpp"

namespace sphles::io {

namespace {

struct Closer {
  hid_t id;
  herr_t (*close)(hid_t);
  ~Closer() {
    if (id >= 0) close(id);
  }
};

void string_attribute(hid_t object, const char* name, const std::string& value) {
  const hid_t type = H5Tcopy(H5T_C_S1);
  H5Tset_size(type, std::max<std::size_t>(value.size(), 1));
  const hid_t space = H5Screate(H5S_SCALAR);
  const hid_t attribute = H5Acreate2(object, name, type, space, H5P_DEFAULT, H5P_DEFAULT);
  const std::string padded = value.empty() ? std::string(1, '\0') : value;
  const herr_t status = H5Awrite(attribute, type, padded.data());
  H5Aclose(attribute);
  H5Sclose(space);
  H5Tclose(type);
  if (status < 0) throw CheckpointError(std::string("snapshot: cannot write attribute ") + name);
}

template <class T>
void scalar_attribute(hid_t object, const char* name, hid_t type, T value) {
  const hid_t space = H5Screate(H5S_SCALAR);
  const hid_t attribute = H5Acreate2(object, name, type, space, H5P_DEFAULT, H5P_DEFAULT);
  const herr_t status = H5Awrite(attribute, type, &value);
  H5Aclose(attribute);
  H5Sclose(space);
  if (status < 0) throw CheckpointError(std::string("snapshot: cannot write attribute ") + name);
}

void dataset(hid_t file, const std::string& name, const std::vector<double>& data, hsize_t rows,
             hsize_t columns, const std::string& units) {
  const hsize_t dims[2] = {rows, columns};
  const hid_t space = H5Screate_simple(columns == 1 ? 1 : 2, dims, nullptr);
  const hid_t set = H5Dcreate2(file, name.c_str(), H5T_NATIVE_DOUBLE, space, H5P_DEFAULT,
                               H5P_DEFAULT, H5P_DEFAULT);
  herr_t status = set < 0 ? -1 : 0;
  if (status == 0 && rows > 0)
    status = H5Dwrite(set, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, data.data());
  if (status == 0) string_attribute(set, "units", units);
  if (set >= 0) H5Dclose(set);
  H5Sclose(space);
  if (status < 0) throw CheckpointError("snapshot: cannot write dataset '" + name + "'");
}

}  // namespace

void write_particle_snapshot(const std::filesystem::path& path, const sim::ParticleArrays& p,
                             double time, std::uint64_t step,
                             const std::vector<ParticleField>& extra,
                             const std::string& scene_json) {
  const std::lock_guard lock(hdf5_library_mutex());
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  const std::size_t n = p.size();
  const std::filesystem::path temporary =
      path.string() + ".tmp." + std::to_string(static_cast<long>(::getpid()));
  try {
    {
      Closer file{H5Fcreate(temporary.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT), H5Fclose};
      if (file.id < 0)
        throw CheckpointError("snapshot: cannot create '" + temporary.string() + "'");
      scalar_attribute(file.id, "time", H5T_NATIVE_DOUBLE, time);
      scalar_attribute(file.id, "step", H5T_NATIVE_UINT64, step);
      scalar_attribute(file.id, "dimension", H5T_NATIVE_INT, p.dimension);
      string_attribute(file.id, "scene", scene_json);
      std::vector<double> xyz(3 * n, 0.0), uvw(3 * n, 0.0);
      for (std::size_t i = 0; i < n; ++i)
        for (int d = 0; d < p.dimension; ++d) {
          xyz[3 * i + static_cast<std::size_t>(d)] = p.position[d][i];
          uvw[3 * i + static_cast<std::size_t>(d)] = p.velocity[d][i];
        }
      dataset(file.id, "position", xyz, n, 3, "m");
      dataset(file.id, "velocity", uvw, n, 3, "m/s");
      dataset(file.id, "mass", p.mass, n, 1, p.dimension == 3 ? "kg" : "kg/m");
      dataset(file.id, "density", p.density, n, 1, p.dimension == 3 ? "kg/m^3" : "kg/m^2");
      dataset(file.id, "pressure", p.pressure, n, 1, "Pa");
      for (const ParticleField& f : extra) {
        if (f.values.size() != n)
          throw CheckpointError("snapshot: field '" + f.name + "' has " +
                                std::to_string(f.values.size()) + " values for " +
                                std::to_string(n) + " particles");
        dataset(file.id, f.name, f.values, n, 1, f.units);
      }
      H5Fflush(file.id, H5F_SCOPE_GLOBAL);
    }
    std::filesystem::rename(temporary, path);
  } catch (...) {
    std::error_code ec;
    std::filesystem::remove(temporary, ec);
    throw;
  }
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
    const auto item = [&](const std::string& dims, const std::string& dataset) {
      return "<DataItem Dimensions=\"" + dims +
             "\" NumberType=\"Float\" Precision=\"8\" Format=\"HDF\">" + e.file + ":/" + dataset +
             "</DataItem>";
    };
    x << "      <Grid Name=\"" << e.file << "\" GridType=\"Uniform\">\n"
      << "        <Time Value=\"" << e.time << "\"/>\n"
      << "        <Topology TopologyType=\"Polyvertex\" NumberOfElements=\"" << n
      << "\" NodesPerElement=\"1\"/>\n"
      << "        <Geometry GeometryType=\"XYZ\">" << item(n + " 3", "position") << "</Geometry>\n"
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
  const std::filesystem::path temporary = path.string() + ".tmp";
  {
    std::ofstream out(temporary, std::ios::trunc);
    out << x.str();
    out.flush();
    if (!out) throw CheckpointError("snapshot: cannot write '" + temporary.string() + "'");
  }
  std::filesystem::rename(temporary, path);
}

}  // namespace sphles::io
