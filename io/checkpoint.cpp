// SPDX-License-Identifier: GPL-3.0-or-later
#include "io/checkpoint.hpp"

#include <hdf5.h>

#include <algorithm>
#include <cstdio>
#include <functional>
#include <mutex>
#include <sstream>

#include "io/checkpoint_format.hpp"
#include "io/hdf5_file.hpp"
#include "sim/scene.hpp"

namespace sphles::io {

namespace {

using checkpoint_format::check_gzip_level;
using checkpoint_format::Header;
using checkpoint_format::number;
using checkpoint_format::read_header;
using checkpoint_format::read_particles;
using checkpoint_format::require_permutation;
using checkpoint_format::SceneGeometry;
using checkpoint_format::write_contents;
using detail::Handle;

/// Opens `path` for reading with `access` (H5P_DEFAULT: one process), after checking that it
/// exists and is HDF5. Call with hdf5_library_mutex() held.
hid_t open_for_reading(const std::filesystem::path& path, hid_t access) {
  const std::string file = path.string();
  if (!std::filesystem::exists(path))
    throw CheckpointError("checkpoint '" + file + "': file does not exist");
  detail::silence_hdf5();
  if (H5Fis_hdf5(file.c_str()) <= 0)
    throw CheckpointError("checkpoint '" + file +
                          "': not a readable HDF5 file (truncated or corrupted)");
  const hid_t h5 = H5Fopen(file.c_str(), H5F_ACC_RDONLY, access);
  if (h5 < 0)
    throw CheckpointError("checkpoint '" + file +
                          "': not a readable HDF5 file (truncated or corrupted)");
  return h5;
}

Checkpoint read_and_validate(const std::filesystem::path& path, SceneGeometry* geometry_out) {
  const std::string file = path.string();
  const std::lock_guard lock(hdf5_library_mutex());
  const Handle h5(open_for_reading(path, H5P_DEFAULT), H5Fclose);
  Header h = read_header(h5.get(), file);
  read_particles(h5.get(), h, {0, static_cast<hsize_t>(h.count), H5P_DEFAULT}, file);
  require_permutation(h.checkpoint.state.particles.id, file);
  if (geometry_out) *geometry_out = h.geometry;
  return std::move(h.checkpoint);
}

}  // namespace

DistributedCheckpoints::~DistributedCheckpoints() = default;

std::string checkpoint_file_name(std::uint64_t step) {
  char name[64];
  std::snprintf(name, sizeof name, "ckpt_%010llu.h5", static_cast<unsigned long long>(step));
  return name;
}

void write_checkpoint(const std::filesystem::path& path, const sim::SolverState& state,
                      const CheckpointMetadata& metadata, const CheckpointWriteOptions& options) {
  check_gzip_level(options);
  const std::string label = "checkpoint '" + path.string() + "'";
  detail::FileImage image;
  {
    const std::lock_guard lock(hdf5_library_mutex());
    detail::MemoryFile h5(path, label);
    write_contents(h5.get(), state, metadata, options, label,
                   {0, static_cast<hsize_t>(state.particles.size()), H5P_DEFAULT,
                    !state.particles.eddy_viscosity.empty()});
    image = h5.finish();
  }
  // The disk write needs no HDF5 call, so it runs outside the library lock.
  detail::write_file_atomically(path, image, label);
}

std::filesystem::path checkpoint_xdmf_path(const std::filesystem::path& checkpoint) {
  std::filesystem::path side = checkpoint;
  return side.replace_extension(".xdmf2");
}

CheckpointShape CheckpointShape::of(const sim::SolverState& state) {
  return {state.particles.dimension, static_cast<std::uint64_t>(state.particles.size()), state.time,
          !state.particles.eddy_viscosity.empty()};
}

void write_checkpoint_xdmf(const std::filesystem::path& checkpoint, const sim::SolverState& state) {
  write_checkpoint_xdmf(checkpoint, CheckpointShape::of(state));
}

void write_checkpoint_xdmf(const std::filesystem::path& checkpoint, const CheckpointShape& shape) {
  const std::string n = std::to_string(shape.particles);
  const std::string file = checkpoint.filename().string();
  const auto item = [&](const std::string& dataset, const char* type = "Float") {
    return "<DataItem Dimensions=\"" + n + "\" NumberType=\"" + type +
           "\" Precision=\"8\" Format=\"HDF\">" + file + ":/particles/" + dataset + "</DataItem>";
  };
  // Positions from their components (X_Y_Z, or X_Y with z = 0 in 2D); vectors joined from
  // them by XDMF 2 function items (ParaView's Xdmf3 reader evaluates neither, its XDMF 2 reader
  // both). A 2D vector gets z = 0 * x, so that ParaView sees 3-vectors in both cases.
  const auto vector = [&](const std::string& prefix) {
    std::string components = item(prefix + "_x") + item(prefix + "_y");
    const char* function = shape.dimension == 3 ? "JOIN($0, $1, $2)" : "JOIN($0, $1, 0 * $0)";
    if (shape.dimension == 3) components += item(prefix + "_z");
    return "<DataItem ItemType=\"Function\" Function=\"" + std::string(function) +
           "\" Dimensions=\"" + n + " 3\">" + components + "</DataItem>";
  };
  std::ostringstream x;
  x.precision(17);
  x << "<?xml version=\"1.0\" ?>\n"
    << "<Xdmf Version=\"2.0\">\n  <Domain>\n"
    << "    <Grid Name=\"" << file << "\" GridType=\"Uniform\">\n"
    << "      <Time Value=\"" << shape.time << "\"/>\n"
    << "      <Topology TopologyType=\"Polyvertex\" NumberOfElements=\"" << n
    << "\" NodesPerElement=\"1\">" << item("id", "UInt") << "</Topology>\n"
    << "      <Geometry GeometryType=\"" << (shape.dimension == 3 ? "X_Y_Z" : "X_Y") << "\">"
    << item("position_x") << item("position_y") << (shape.dimension == 3 ? item("position_z") : "")
    << "</Geometry>\n";
  for (const char* v : {"velocity", "acceleration"})
    x << "      <Attribute Name=\"" << v << "\" AttributeType=\"Vector\" Center=\"Node\">"
      << vector(v) << "</Attribute>\n";
  x << "      <Attribute Name=\"id\" AttributeType=\"Scalar\" Center=\"Node\">"
    << item("id", "UInt") << "</Attribute>\n";
  std::vector<std::string> scalars{"mass", "volume", "density", "pressure"};
  if (shape.eddy_viscosity) scalars.push_back("eddy_viscosity");
  for (const std::string& s : scalars)
    x << "      <Attribute Name=\"" << s << "\" AttributeType=\"Scalar\" Center=\"Node\">"
      << item(s) << "</Attribute>\n";
  x << "    </Grid>\n  </Domain>\n</Xdmf>\n";
  const std::filesystem::path side = checkpoint_xdmf_path(checkpoint);
  detail::write_file_atomically(side, x.str(), "checkpoint side file '" + side.string() + "'");
}

Checkpoint read_checkpoint(const std::filesystem::path& path) {
  return read_and_validate(path, nullptr);
}

CheckpointHeader read_checkpoint_header(const std::filesystem::path& path) {
  const std::string file = path.string();
  const std::lock_guard lock(hdf5_library_mutex());
  const Handle h5(open_for_reading(path, H5P_DEFAULT), H5Fclose);
  Header h = read_header(h5.get(), file);
  const Handle group(H5Gopen2(h5.get(), "particles", H5P_DEFAULT), H5Gclose);
  if (!group.valid()) throw CheckpointError("checkpoint '" + file + "': cannot open 'particles'");
  const sim::SolverState& s = h.checkpoint.state;
  return {h.checkpoint.metadata,
          {h.dimension, h.count, s.time, H5Lexists(group.get(), "eddy_viscosity", H5P_DEFAULT) > 0},
          s.step,
          s.neighbour_builds};
}

std::vector<std::filesystem::path> list_checkpoints(const std::filesystem::path& directory) {
  std::vector<std::filesystem::path> files;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(directory, ec)) {
    const std::string name = entry.path().filename().string();
    if (entry.is_regular_file() && name.starts_with("ckpt_") && name.ends_with(".h5"))
      files.push_back(entry.path());
  }
  // Zero-padded step numbers: lexicographic order is step order.
  std::sort(files.begin(), files.end(), std::greater<>());
  return files;
}

CheckpointHeader header_of(const Checkpoint& c) {
  return {c.metadata, CheckpointShape::of(c.state), c.state.step, c.state.neighbour_builds};
}

namespace {

/// What `take` returns for the newest checkpoint of `directory` it does not reject with a
/// CheckpointError; the rejections, newest first, into `rejected`.
template <class Take>
auto newest_taken(const std::filesystem::path& directory, std::vector<std::string>* rejected,
                  Take take) {
  const auto files = list_checkpoints(directory);
  for (const auto& file : files) {
    try {
      return take(file);
    } catch (const CheckpointError& e) {
      if (rejected) rejected->push_back(e.what());
    }
  }
  throw CheckpointError("checkpoint: no valid checkpoint in '" + directory.string() + "' (" +
                        std::to_string(files.size()) + " candidates)");
}

}  // namespace

std::filesystem::path newest_valid_checkpoint(const std::filesystem::path& directory,
                                              std::vector<std::string>* rejected,
                                              CheckpointCheck check,
                                              const CheckpointAccept& accept) {
  return newest_taken(directory, rejected, [&](const std::filesystem::path& file) {
    const CheckpointHeader header = check == CheckpointCheck::Header
                                        ? read_checkpoint_header(file)
                                        : header_of(read_checkpoint(file));
    if (accept) accept(file, header);
    return file;
  });
}

std::pair<std::filesystem::path, Checkpoint> read_newest_valid_checkpoint(
    const std::filesystem::path& directory, std::vector<std::string>* rejected,
    const CheckpointAccept& accept) {
  return newest_taken(directory, rejected, [&](const std::filesystem::path& file) {
    std::pair<std::filesystem::path, Checkpoint> read{file, read_checkpoint(file)};
    if (accept) accept(file, header_of(read.second));
    return read;
  });
}

std::string describe_checkpoint(const std::filesystem::path& path) {
  SceneGeometry geometry;
  const Checkpoint c = read_and_validate(path, &geometry);
  const sim::ParticleArrays& p = c.state.particles;
  std::ostringstream out;
  out.precision(17);
  out << "file:             " << path.string() << " (" << std::filesystem::file_size(path)
      << " bytes)\n"
      << "schema:           " << kCheckpointSchema << " version " << kCheckpointSchemaVersion
      << "\n"
      << "code version:     " << c.metadata.code_version << "\n"
      << "dimension:        " << p.dimension << "\n"
      << "particles:        " << p.size() << "\n"
      << "time:             " << c.state.time << " s\n"
      << "step:             " << c.state.step << "\n"
      << "neighbour builds: " << c.state.neighbour_builds << "\n"
      << "packing:          " << c.metadata.packing << "\n"
      << "periodic box:     ";
  if (geometry.scene)
    out << "L = " << number(geometry.scene->box_length()) << " m (case "
        << sim::case_name(geometry.scene->case_type) << ", " << geometry.scene->particles_per_side
        << "^" << p.dimension << " particles); positions checked against it\n";
  else
    out << "not determined (" << geometry.unknown << "); positions checked for finiteness only\n";
  out << "datasets:         particles/{position,velocity,acceleration,list_reference}_{"
      << (p.dimension == 3 ? "x,y,z" : "x,y") << "}, mass, volume, density, pressure, id"
      << (p.eddy_viscosity.empty() ? "" : ", eddy_viscosity") << " (" << p.size()
      << " entries each)\n";
  double kinetic = 0.0, mass = 0.0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    double v2 = 0.0;
    for (int d = 0; d < p.dimension; ++d) v2 += p.velocity[d][i] * p.velocity[d][i];
    kinetic += 0.5 * p.mass[i] * v2;
    mass += p.mass[i];
  }
  out << "e_v:              " << (mass > 0.0 ? kinetic / mass : 0.0) << " m^2/s^2\n"
      << "scene:            " << c.metadata.scene_json << "\n";
  return out.str();
}

}  // namespace sphles::io
