#include "io/particle_snapshot.hpp"

#include <hdf5.h>

#include <algorithm>
#include <mutex>
#include <sstream>
#include <stdexcept>

#include "io/checkpoint.hpp"
#include "io/hdf5_file.hpp"

namespace sphles::io {

namespace {

using detail::Handle;
using detail::write_scalar_attribute;
using detail::write_string_attribute;

void dataset(hid_t file, const std::string& name, const std::vector<double>& data, hsize_t rows,
             hsize_t columns, const std::string& units, const std::string& label) {
  const hsize_t dims[2] = {rows, columns};
  const Handle space(H5Screate_simple(columns == 1 ? 1 : 2, dims, nullptr), H5Sclose);
  const Handle set(space.valid() ? H5Dcreate2(file, name.c_str(), H5T_NATIVE_DOUBLE, space.get(),
                                              H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT)
                                 : -1,
                   H5Dclose);
  if (!set.valid() || (rows > 0 && H5Dwrite(set.get(), H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL,
                                            H5P_DEFAULT, data.data()) < 0))
    throw CheckpointError(label + ": cannot write dataset '" + name + "'");
  write_string_attribute(set.get(), "units", units, label);
}

}  // namespace

void write_particle_snapshot(const std::filesystem::path& path, const sim::ParticleArrays& p,
                             double time, std::uint64_t step,
                             const std::vector<ParticleField>& extra,
                             const std::string& scene_json) {
  const std::string label = "snapshot '" + path.string() + "'";
  const std::size_t n = p.size();
  for (const ParticleField& f : extra)
    if (f.values.size() != n)
      throw CheckpointError(label + ": field '" + f.name + "' has " +
                            std::to_string(f.values.size()) + " values for " + std::to_string(n) +
                            " particles");
  std::vector<double> xyz(3 * n, 0.0), uvw(3 * n, 0.0);
  for (std::size_t i = 0; i < n; ++i)
    for (int d = 0; d < p.dimension; ++d) {
      xyz[3 * i + static_cast<std::size_t>(d)] = p.position[d][i];
      uvw[3 * i + static_cast<std::size_t>(d)] = p.velocity[d][i];
    }
  detail::FileImage image;
  {
    const std::lock_guard lock(hdf5_library_mutex());
    detail::MemoryFile file(path, label);
    const hid_t root = file.get();
    write_scalar_attribute(root, "time", H5T_NATIVE_DOUBLE, time, label);
    write_scalar_attribute(root, "step", H5T_NATIVE_UINT64, step, label);
    write_scalar_attribute(root, "dimension", H5T_NATIVE_INT, p.dimension, label);
    write_string_attribute(root, "scene", scene_json, label);
    dataset(root, "position", xyz, n, 3, "m", label);
    dataset(root, "velocity", uvw, n, 3, "m/s", label);
    dataset(root, "mass", p.mass, n, 1, p.dimension == 3 ? "kg" : "kg/m", label);
    dataset(root, "density", p.density, n, 1, p.dimension == 3 ? "kg/m^3" : "kg/m^2", label);
    dataset(root, "pressure", p.pressure, n, 1, "Pa", label);
    for (const ParticleField& f : extra) dataset(root, f.name, f.values, n, 1, f.units, label);
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
  detail::write_file_atomically(path, x.str(), "snapshot series '" + path.string() + "'");
}

}  // namespace sphles::io
