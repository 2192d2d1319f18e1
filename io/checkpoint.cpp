// SPDX-License-Identifier: GPL-3.0-or-later
#include "io/checkpoint.hpp"

#include <hdf5.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <tuple>

#include "io/checkpoint_collective.hpp"
#include "io/collective_file.hpp"
#include "io/hdf5_file.hpp"
#include "sim/scene.hpp"

namespace sphles::io {

namespace {

using detail::agree;
using detail::attempt;
using detail::Handle;
using detail::write_scalar_attribute;
using detail::write_string_attribute;

const char* kAxis[] = {"x", "y", "z"};

/// At most this many entries per chunk of a particle dataset.
constexpr hsize_t kChunkEntries = hsize_t{1} << 16;

/// Entries per chunk for a dataset of `size` entries: the fewest chunks of at most kChunkEntries,
/// of equal length (HDF5 allocates the last chunk whole, so 70 000 entries in chunks of 65 536
/// would take 131 072 entries of space; in two chunks of 35 000 they take 70 000).
hsize_t chunk_entries(hsize_t size) {
  if (size == 0) return 0;
  const hsize_t chunks = (size + kChunkEntries - 1) / kChunkEntries;
  return (size + chunks - 1) / chunks;
}

// --- writing ---------------------------------------------------------------------------

/// Where this process' particles go in the file's datasets: entries [first, first + count) of
/// `total`, written with the data transfer properties `transfer` (collective for MPI-IO).
struct Placement {
  hsize_t first = 0;
  hsize_t total = 0;
  hid_t transfer = H5P_DEFAULT;
  bool eddy_viscosity = false;  // whether the run has ν_t (a process may hold no particles)
};

template <class T>
void write_dataset(hid_t group, const std::string& name, hid_t type, const std::vector<T>& data,
                   const std::string& units, const CheckpointWriteOptions& options,
                   const std::string& label, const Placement& block) {
  const auto failed = [&] {
    return CheckpointError(label + ": cannot write dataset 'particles/" + name + "'");
  };
  const hsize_t size = block.total;
  const hsize_t count = data.size();
  const Handle space(H5Screate_simple(1, &size, nullptr), H5Sclose);
  const Handle properties(H5Pcreate(H5P_DATASET_CREATE), H5Pclose);
  if (!space.valid() || !properties.valid()) throw failed();
  if (size > 0) {
    const hsize_t chunk = chunk_entries(size);
    if (H5Pset_chunk(properties.get(), 1, &chunk) < 0 || H5Pset_fletcher32(properties.get()) < 0)
      throw failed();
    if (options.gzip_level > 0 &&
        (H5Pset_shuffle(properties.get()) < 0 ||
         H5Pset_deflate(properties.get(), static_cast<unsigned>(options.gzip_level)) < 0))
      throw failed();
  }
  const Handle dataset(H5Dcreate2(group, name.c_str(), type, space.get(), H5P_DEFAULT,
                                  properties.get(), H5P_DEFAULT),
                       H5Dclose);
  if (!dataset.valid()) throw failed();
  if (size > 0) {
    // This process' entries; a process with none still takes part in a collective write.
    const hsize_t one = 1;
    const Handle memory(H5Screate_simple(1, count > 0 ? &count : &one, nullptr), H5Sclose);
    const herr_t selected =
        count > 0 ? H5Sselect_hyperslab(space.get(), H5S_SELECT_SET, &block.first, nullptr, &count,
                                        nullptr)
                  : std::min(H5Sselect_none(space.get()), H5Sselect_none(memory.get()));
    if (!memory.valid() || selected < 0 ||
        H5Dwrite(dataset.get(), type, memory.get(), space.get(), block.transfer, data.data()) < 0)
      throw failed();
  }
  write_string_attribute(dataset.get(), "units", units, label);
}

/// The whole checkpoint under `root`: its attributes, then the particle datasets with this
/// process' particles (`state`) at `block`. Every process of a collective write makes the same
/// calls with the same attribute values.
void write_contents(hid_t root, const sim::SolverState& state, const CheckpointMetadata& metadata,
                    const CheckpointWriteOptions& options, const std::string& label,
                    const Placement& block) {
  const sim::ParticleArrays& p = state.particles;
  const int dim = p.dimension;
  write_string_attribute(root, "schema", kCheckpointSchema, label);
  write_scalar_attribute(root, "schema_version", H5T_NATIVE_INT, kCheckpointSchemaVersion, label);
  write_string_attribute(root, "code_version", metadata.code_version, label);
  write_scalar_attribute(root, "dimension", H5T_NATIVE_INT, dim, label);
  write_scalar_attribute(root, "num_particles", H5T_NATIVE_UINT64,
                         static_cast<std::uint64_t>(block.total), label);
  write_scalar_attribute(root, "time", H5T_NATIVE_DOUBLE, state.time, label);
  write_scalar_attribute(root, "step", H5T_NATIVE_UINT64, state.step, label);
  write_scalar_attribute(root, "neighbour_builds", H5T_NATIVE_UINT64, state.neighbour_builds,
                         label);
  write_string_attribute(root, "scene", metadata.scene_json, label);
  write_string_attribute(root, "packing", metadata.packing, label);
  write_string_attribute(root, "units",
                         "SI: position m, velocity m/s, acceleration m/s^2, mass kg (kg/m in "
                         "2D), volume m^n, density kg/m^n, pressure Pa, eddy_viscosity m^2/s",
                         label);
  const Handle group(H5Gcreate2(root, "particles", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
                     H5Gclose);
  if (!group.valid()) throw CheckpointError(label + ": cannot create group 'particles'");
  const hid_t g = group.get();
  const bool three = dim == 3;
  for (int d = 0; d < dim; ++d) {
    const std::string axis = kAxis[d];
    write_dataset(g, "position_" + axis, H5T_NATIVE_DOUBLE, p.position[d], "m", options, label,
                  block);
    write_dataset(g, "velocity_" + axis, H5T_NATIVE_DOUBLE, p.velocity[d], "m/s", options, label,
                  block);
    write_dataset(g, "acceleration_" + axis, H5T_NATIVE_DOUBLE, p.acceleration[d], "m/s^2", options,
                  label, block);
    write_dataset(g, "list_reference_" + axis, H5T_NATIVE_DOUBLE, state.list_reference_positions[d],
                  "m", options, label, block);
  }
  write_dataset(g, "mass", H5T_NATIVE_DOUBLE, p.mass, three ? "kg" : "kg/m", options, label, block);
  write_dataset(g, "volume", H5T_NATIVE_DOUBLE, p.volume, three ? "m^3" : "m^2", options, label,
                block);
  write_dataset(g, "density", H5T_NATIVE_DOUBLE, p.density, three ? "kg/m^3" : "kg/m^2", options,
                label, block);
  write_dataset(g, "pressure", H5T_NATIVE_DOUBLE, p.pressure, "Pa", options, label, block);
  write_dataset(g, "id", H5T_NATIVE_UINT64, p.id, "1", options, label, block);
  if (block.eddy_viscosity)
    write_dataset(g, "eddy_viscosity", H5T_NATIVE_DOUBLE, p.eddy_viscosity, "m^2/s", options, label,
                  block);
}

void check_gzip_level(const CheckpointWriteOptions& options) {
  if (options.gzip_level < 0 || options.gzip_level > 9)
    throw CheckpointError("checkpoint: gzip level must be in [0, 9]");
}

// --- reading ---------------------------------------------------------------------------

std::string read_string_attribute(hid_t object, const char* name, const std::string& file) {
  if (H5Aexists(object, name) <= 0)
    throw CheckpointError("checkpoint '" + file + "': missing attribute '" + name + "'");
  const Handle attribute(H5Aopen(object, name, H5P_DEFAULT), H5Aclose);
  const Handle type(H5Aget_type(attribute.get()), H5Tclose);
  if (H5Tget_class(type.get()) != H5T_STRING || H5Tis_variable_str(type.get()) > 0)
    throw CheckpointError("checkpoint '" + file + "': attribute '" + name + "' is not a string");
  const std::size_t size = H5Tget_size(type.get());
  std::string value(size, '\0');
  if (H5Aread(attribute.get(), type.get(), value.data()) < 0)
    throw CheckpointError("checkpoint '" + file + "': cannot read attribute '" + name + "'");
  value.resize(std::strlen(value.c_str()));
  return value;
}

template <class T>
T read_scalar_attribute(hid_t object, const char* name, hid_t type, const std::string& file) {
  if (H5Aexists(object, name) <= 0)
    throw CheckpointError("checkpoint '" + file + "': missing attribute '" + name + "'");
  const Handle attribute(H5Aopen(object, name, H5P_DEFAULT), H5Aclose);
  T value{};
  if (H5Aread(attribute.get(), type, &value) < 0)
    throw CheckpointError("checkpoint '" + file + "': cannot read attribute '" + name + "'");
  return value;
}

/// Entries [first, first + count) of a dataset that must hold `expected` entries, read with the
/// data transfer properties `transfer` (collective for MPI-IO).
struct Range {
  hsize_t first = 0;
  hsize_t count = 0;
  hid_t transfer = H5P_DEFAULT;
};

template <class T>
std::vector<T> read_dataset(hid_t group, const std::string& name, hid_t type, std::size_t expected,
                            const Range& range, const std::string& file) {
  if (H5Lexists(group, name.c_str(), H5P_DEFAULT) <= 0)
    throw CheckpointError("checkpoint '" + file + "': missing dataset 'particles/" + name + "'");
  const Handle dataset(H5Dopen2(group, name.c_str(), H5P_DEFAULT), H5Dclose);
  const Handle space(H5Dget_space(dataset.get()), H5Sclose);
  if (H5Sget_simple_extent_ndims(space.get()) != 1)
    throw CheckpointError("checkpoint '" + file + "': dataset 'particles/" + name +
                          "' is not one-dimensional");
  hsize_t size = 0;
  H5Sget_simple_extent_dims(space.get(), &size, nullptr);
  if (size != expected)
    throw CheckpointError("checkpoint '" + file + "': dataset 'particles/" + name + "' has " +
                          std::to_string(size) + " entries, expected " + std::to_string(expected) +
                          " (particle count mismatch)");
  std::vector<T> data(range.count);
  if (expected == 0) return data;
  // A process with no entries still takes part in a collective read.
  const hsize_t one = 1;
  const Handle memory(H5Screate_simple(1, range.count > 0 ? &range.count : &one, nullptr),
                      H5Sclose);
  const herr_t selected = range.count > 0
                              ? H5Sselect_hyperslab(space.get(), H5S_SELECT_SET, &range.first,
                                                    nullptr, &range.count, nullptr)
                              : std::min(H5Sselect_none(space.get()), H5Sselect_none(memory.get()));
  if (!memory.valid() || selected < 0 ||
      H5Dread(dataset.get(), type, memory.get(), space.get(), range.transfer, data.data()) < 0)
    throw CheckpointError("checkpoint '" + file + "': dataset 'particles/" + name +
                          "' cannot be read (checksum mismatch or truncated file)");
  return data;
}

// --- content validation ----------------------------------------------------------------

/// Shortest text that reads back as the same double (1e+300, -1, 6.283185307179586).
std::string number(double value) {
  char text[32];
  const auto result = std::to_chars(text, text + sizeof text, value);
  return std::string(text, result.ptr);
}

// `first`: the file index of values[0] (a range of the dataset), for the messages.
void require_finite(const std::vector<double>& values, const std::string& name, std::uint64_t first,
                    const std::string& file) {
  for (std::size_t i = 0; i < values.size(); ++i)
    if (!std::isfinite(values[i]))
      throw CheckpointError("checkpoint '" + file + "': non-finite value in 'particles/" + name +
                            "' at index " + std::to_string(first + i));
}

void require_positive(const std::vector<double>& values, const std::string& name,
                      std::uint64_t first, const std::string& file) {
  for (std::size_t i = 0; i < values.size(); ++i)
    if (!(values[i] > 0.0))
      throw CheckpointError("checkpoint '" + file + "': dataset 'particles/" + name +
                            "' has a non-positive value " + number(values[i]) + " at index " +
                            std::to_string(first + i));
}

/// Positions are wrapped into [0, L) after every drift (sim::wrap_periodic).
void require_inside_box(const std::vector<double>& values, const std::string& name, double length,
                        std::uint64_t first, const std::string& file) {
  for (std::size_t i = 0; i < values.size(); ++i)
    if (!(values[i] >= 0.0 && values[i] < length))
      throw CheckpointError("checkpoint '" + file + "': dataset 'particles/" + name + "' has " +
                            number(values[i]) + " at index " + std::to_string(first + i) +
                            ", outside the periodic box [0, " + number(length) + ") m");
}

/// Ids below the particle count, for a range of the dataset (the permutation is checked over
/// all ranges together: par::id_block).
void require_ids_below(const std::vector<std::uint64_t>& ids, std::uint64_t count,
                       std::uint64_t first, const std::string& file) {
  for (std::size_t i = 0; i < ids.size(); ++i)
    if (ids[i] >= count)
      throw CheckpointError("checkpoint '" + file + "': dataset 'particles/id' has " +
                            std::to_string(ids[i]) + " at index " + std::to_string(first + i) +
                            ", outside 0.." + std::to_string(count - 1) +
                            " (ids are a permutation of 0..N-1)");
}

/// Particle ids are a permutation of 0..N-1 (sim::make_lattice numbers them; the solver only
/// reorders). One pass; a second one only to name the first copy of a duplicate.
void require_permutation(const std::vector<std::uint64_t>& ids, const std::string& file) {
  const std::size_t n = ids.size();
  std::vector<char> seen(n, 0);
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint64_t id = ids[i];
    if (id >= n)
      throw CheckpointError("checkpoint '" + file + "': dataset 'particles/id' has " +
                            std::to_string(id) + " at index " + std::to_string(i) +
                            ", outside 0.." + std::to_string(n - 1) +
                            " (ids are a permutation of 0..N-1)");
    if (seen[id]) {
      const auto first =
          static_cast<std::size_t>(std::find(ids.begin(), ids.end(), id) - ids.begin());
      throw CheckpointError("checkpoint '" + file + "': dataset 'particles/id' repeats " +
                            std::to_string(id) + " at index " + std::to_string(i) +
                            " (first at index " + std::to_string(first) +
                            "; ids are a permutation of 0..N-1)");
    }
    seen[id] = 1;
  }
}

/// The stored run configuration: a JSON object.
nlohmann::json parse_scene_attribute(const std::string& text, const std::string& file) {
  nlohmann::json scene;
  try {
    scene = nlohmann::json::parse(text);
  } catch (const nlohmann::json::parse_error& e) {
    throw CheckpointError("checkpoint '" + file + "': attribute 'scene' is not JSON (byte " +
                          std::to_string(e.byte) + " of " + std::to_string(text.size()) +
                          "): " + e.what());
  }
  if (!scene.is_object())
    throw CheckpointError("checkpoint '" + file +
                          "': attribute 'scene' is JSON but not an object (" +
                          std::string(scene.type_name()) + ")");
  return scene;
}

/// What the stored scene says about the particle set: box, dimension, particle count.
struct SceneGeometry {
  std::optional<sim::Scene> scene;  // set when the scene names a case this sphles knows
  std::string unknown;              // otherwise why not
};

bool is_known_preset(const nlohmann::json& value) {
  if (!value.is_string()) return false;
  const auto presets = sim::preset_names();
  return std::find(presets.begin(), presets.end(), value.get<std::string>()) != presets.end();
}

/// The geometry keys of the scene (case or preset, particles_per_side, box_length) resolved by
/// sim::parse_scene, which owns their defaults and limits. A scene that names no case this
/// sphles knows (not one sphles wrote) determines nothing; one that names a known case must
/// determine the box, or the file is rejected.
SceneGeometry scene_geometry(const nlohmann::json& scene, const std::string& file) {
  SceneGeometry g;
  const auto case_it = scene.find("case");
  const auto preset_it = scene.find("preset");
  if (case_it != scene.end()) {
    bool known = false;
    if (case_it->is_string()) {
      try {
        sim::parse_scene({{"case", *case_it}});
        known = true;
      } catch (const sim::SceneError&) {
      }
    }
    if (!known) {
      g.unknown = "the scene's 'case' " + case_it->dump() + " is not a known case";
      return g;
    }
  } else if (preset_it == scene.end()) {
    g.unknown = "the scene names no case";
    return g;
  } else if (!is_known_preset(*preset_it)) {
    g.unknown = "the scene's 'preset' " + preset_it->dump() + " is not a known preset";
    return g;
  }
  nlohmann::json geometry = nlohmann::json::object();
  for (const char* key : {"case", "particles_per_side", "box_length"})
    if (const auto it = scene.find(key); it != scene.end()) geometry[key] = *it;
  // A preset supplies the defaults the explicit keys override; one this sphles no longer has
  // must not hide an explicit case.
  if (preset_it != scene.end() && is_known_preset(*preset_it)) geometry["preset"] = *preset_it;
  try {
    g.scene = sim::parse_scene(geometry);
  } catch (const sim::SceneError& e) {
    throw CheckpointError("checkpoint '" + file +
                          "': attribute 'scene' does not determine the periodic box: " + e.what());
  }
  return g;
}

/// The attributes of an open checkpoint, validated (structure and the time counters; the
/// scene's box and particle count against dimension and num_particles).
struct Header {
  Checkpoint checkpoint;  // metadata, time, step, builds; no particles
  int dimension = 3;
  std::uint64_t count = 0;
  SceneGeometry geometry;
};

Header read_header(hid_t root, const std::string& file) {
  Header h;
  Checkpoint& c = h.checkpoint;
  const std::string schema = read_string_attribute(root, "schema", file);
  if (schema != kCheckpointSchema)
    throw CheckpointError("checkpoint '" + file + "': wrong schema '" + schema + "' (expected '" +
                          kCheckpointSchema + "')");
  const int version = read_scalar_attribute<int>(root, "schema_version", H5T_NATIVE_INT, file);
  if (version != kCheckpointSchemaVersion)
    throw CheckpointError("checkpoint '" + file + "': schema version " + std::to_string(version) +
                          " is not supported (this sphles reads version " +
                          std::to_string(kCheckpointSchemaVersion) + ")");
  const int dim = read_scalar_attribute<int>(root, "dimension", H5T_NATIVE_INT, file);
  if (dim != 2 && dim != 3)
    throw CheckpointError("checkpoint '" + file + "': dimension " + std::to_string(dim) +
                          " (expected 2 or 3)");
  h.dimension = dim;
  const auto count =
      read_scalar_attribute<std::uint64_t>(root, "num_particles", H5T_NATIVE_UINT64, file);
  h.count = count;
  c.state.particles.dimension = dim;
  c.state.time = read_scalar_attribute<double>(root, "time", H5T_NATIVE_DOUBLE, file);
  c.state.step = read_scalar_attribute<std::uint64_t>(root, "step", H5T_NATIVE_UINT64, file);
  c.state.neighbour_builds =
      read_scalar_attribute<std::uint64_t>(root, "neighbour_builds", H5T_NATIVE_UINT64, file);
  if (!std::isfinite(c.state.time))
    throw CheckpointError("checkpoint '" + file + "': non-finite time");
  if (c.state.time < 0.0)
    throw CheckpointError("checkpoint '" + file + "': attribute 'time' is " + number(c.state.time) +
                          " (must be >= 0)");
  if (c.state.step > 0 && !(c.state.time > 0.0))
    throw CheckpointError("checkpoint '" + file + "': attribute 'step' is " +
                          std::to_string(c.state.step) +
                          " but 'time' is 0 (every step advances the time)");
  // The Verlet list is built once when the solver starts and at most once per step.
  if (c.state.neighbour_builds < 1 || c.state.neighbour_builds - 1 > c.state.step)
    throw CheckpointError("checkpoint '" + file + "': attribute 'neighbour_builds' is " +
                          std::to_string(c.state.neighbour_builds) +
                          ", expected 1 to step + 1 = " + std::to_string(c.state.step + 1) +
                          " (one build at the start, at most one per step)");
  c.metadata.scene_json = read_string_attribute(root, "scene", file);
  c.metadata.code_version = read_string_attribute(root, "code_version", file);
  c.metadata.packing = read_string_attribute(root, "packing", file);
  h.geometry = scene_geometry(parse_scene_attribute(c.metadata.scene_json, file), file);
  if (h.geometry.scene) {
    const sim::Scene& s = *h.geometry.scene;
    if (s.dimension() != dim)
      throw CheckpointError("checkpoint '" + file + "': attribute 'dimension' is " +
                            std::to_string(dim) + " but the scene's case '" +
                            std::string(sim::case_name(s.case_type)) + "' is " +
                            std::to_string(s.dimension()) + "D");
    if (s.num_particles() != count)
      throw CheckpointError(
          "checkpoint '" + file + "': attribute 'num_particles' is " + std::to_string(count) +
          " but the scene has " + std::to_string(s.num_particles()) + " (particles_per_side " +
          std::to_string(s.particles_per_side) + " in " + std::to_string(dim) + "D)");
  }
  if (H5Lexists(root, "particles", H5P_DEFAULT) <= 0)
    throw CheckpointError("checkpoint '" + file + "': missing group 'particles'");
  return h;
}

/// Particles [range.first, range.first + range.count) of the file into h.checkpoint's state,
/// every value checked (finite; mass, volume, density positive; positions in the scene's box;
/// ids below the count). The ids' permutation is the caller's to check.
void read_particles(hid_t root, Header& h, const Range& range, const std::string& file) {
  const Handle group(H5Gopen2(root, "particles", H5P_DEFAULT), H5Gclose);
  sim::SolverState& state = h.checkpoint.state;
  sim::ParticleArrays& p = state.particles;
  const auto n = static_cast<std::size_t>(h.count);
  const std::uint64_t first = range.first;
  // Every dataset is read even after a failure, the first failure thrown at the end: in a
  // collective read, a process that left early would leave the others waiting in the next one.
  std::optional<std::string> failure;
  const auto check = [&](auto&& step) {
    if (auto what = attempt(step); what && !failure) failure = std::move(what);
  };
  const auto read = [&](const std::string& name, std::vector<double>& into) {
    check([&] {
      into = read_dataset<double>(group.get(), name, H5T_NATIVE_DOUBLE, n, range, file);
      require_finite(into, name, first, file);
    });
  };
  for (int d = 0; d < h.dimension; ++d) {
    const std::string axis = kAxis[d];
    read("position_" + axis, p.position[d]);
    read("velocity_" + axis, p.velocity[d]);
    read("acceleration_" + axis, p.acceleration[d]);
    read("list_reference_" + axis, state.list_reference_positions[d]);
    if (h.geometry.scene) {
      const double length = h.geometry.scene->box_length();
      check([&] {
        require_inside_box(p.position[d], "position_" + axis, length, first, file);
        require_inside_box(state.list_reference_positions[d], "list_reference_" + axis, length,
                           first, file);
      });
    }
  }
  for (auto [name, target, positive] :
       {std::tuple{"mass", &p.mass, true}, std::tuple{"volume", &p.volume, true},
        std::tuple{"density", &p.density, true}, std::tuple{"pressure", &p.pressure, false}}) {
    read(name, *target);
    if (positive) check([&] { require_positive(*target, name, first, file); });
  }
  check([&] {
    p.id = read_dataset<std::uint64_t>(group.get(), "id", H5T_NATIVE_UINT64, n, range, file);
    require_ids_below(p.id, h.count, first, file);
  });
  if (H5Lexists(group.get(), "eddy_viscosity", H5P_DEFAULT) > 0)
    read("eddy_viscosity", p.eddy_viscosity);
  if (failure) throw CheckpointError(*failure);
}

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

std::uint64_t checkpoint_size_bound(int dimension, std::uint64_t particles, bool eddy_viscosity,
                                    std::size_t metadata_bytes) {
  // Per particle: position, velocity, acceleration and list reference per axis, mass, volume,
  // density, pressure, id (8 bytes each), ν_t when the run has it.
  const std::uint64_t datasets =
      4 * static_cast<std::uint64_t>(dimension) + 5 + (eddy_viscosity ? 1 : 0);
  // Chunks are allocated whole, the last one too (chunk_entries keeps that waste below one entry
  // per chunk); compressed chunks are no larger than that.
  const std::uint64_t chunk = chunk_entries(particles);
  const std::uint64_t chunks = chunk == 0 ? 0 : (particles + chunk - 1) / chunk;
  // A chunk's checksum (4 B) and index entry (< 64 B), a dataset's header and attributes (< 4 kB);
  // gzip can grow incompressible data by < 0.1 %: 1 % and 1 MiB of margin.
  const std::uint64_t raw =
      datasets * (8 * chunk * chunks + 64 * chunks + 4096) + 2 * metadata_bytes;
  return raw + raw / 100 + (std::uint64_t{1} << 20);
}

CheckpointShape write_checkpoint_collective(MPI_Comm comm, const std::filesystem::path& path,
                                            const sim::SolverState& part, std::uint64_t first,
                                            std::uint64_t total, const CheckpointMetadata& metadata,
                                            const CheckpointWriteOptions& options) {
  check_gzip_level(options);
  const std::string label = "checkpoint '" + path.string() + "'";
  int rank = 0;
  MPI_Comm_rank(comm, &rank);
  const auto fail = [&](const std::optional<std::string>& failure) {
    detail::fail_agreed(comm, path, failure);
  };

  // The parts must tile [0, total).
  const unsigned long long count = part.particles.size();
  unsigned long long held = 0;
  MPI_Allreduce(&count, &held, 1, MPI_UNSIGNED_LONG_LONG, MPI_SUM, comm);
  fail(agree(comm, held == total && first + count <= total
                       ? std::nullopt
                       : std::optional<std::string>(
                             label + ": the processes hold " + std::to_string(held) +
                             " particles for a checkpoint of " + std::to_string(total) + " (rank " +
                             std::to_string(rank) + " holds [" + std::to_string(first) + ", " +
                             std::to_string(first + count) + "))")));

  // Whether the run has ν_t: a process may hold no particles.
  const int mine = part.particles.eddy_viscosity.empty() ? 0 : 1;
  int eddy_viscosity = 0;
  MPI_Allreduce(&mine, &eddy_viscosity, 1, MPI_INT, MPI_MAX, comm);
  fail(agree(comm, part.particles.eddy_viscosity.size() == (eddy_viscosity ? count : 0)
                       ? std::nullopt
                       : std::optional<std::string>(label + ": rank " + std::to_string(rank) +
                                                    " has no eddy viscosity for its particles")));

  const std::uint64_t bound = checkpoint_size_bound(
      part.particles.dimension, total, eddy_viscosity != 0,
      metadata.scene_json.size() + metadata.code_version.size() + metadata.packing.size());
  detail::write_collectively(comm, path, label, bound, [&](hid_t file, hid_t transfer) {
    write_contents(
        file, part, metadata, options, label,
        {static_cast<hsize_t>(first), static_cast<hsize_t>(total), transfer, eddy_viscosity != 0});
  });
  return {part.particles.dimension, total, part.time, eddy_viscosity != 0};
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

Block equal_block(std::uint64_t total, int rank, int ranks) {
  const auto r = static_cast<std::uint64_t>(rank);
  const auto p = static_cast<std::uint64_t>(ranks);
  const std::uint64_t base = total / p, longer = total % p;
  const std::uint64_t first = r * base + std::min(r, longer);
  return {first, base + (r < longer ? 1 : 0)};
}

int equal_block_rank(std::uint64_t id, std::uint64_t total, int ranks) {
  const auto p = static_cast<std::uint64_t>(ranks);
  const std::uint64_t base = total / p, longer = total % p;
  const std::uint64_t split = longer * (base + 1);  // ids below it lie in the longer blocks
  return static_cast<int>(id < split ? id / (base + 1) : longer + (id - split) / base);
}

Checkpoint read_checkpoint_collective(MPI_Comm comm, const std::filesystem::path& path,
                                      std::uint64_t& first) {
  const std::string file = path.string();
  int rank = 0, size = 1;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &size);
  const auto fail = [](const std::optional<std::string>& failure) {
    if (failure) throw CheckpointError(*failure);
  };
  const std::lock_guard lock(hdf5_library_mutex());
  detail::silence_hdf5();
  // Every process sees the file before any opens it (the open is collective).
  fail(agree(comm, attempt([&] {
               if (!std::filesystem::exists(path))
                 throw CheckpointError("checkpoint '" + file + "': file does not exist");
               if (H5Fis_hdf5(file.c_str()) <= 0)
                 throw CheckpointError("checkpoint '" + file +
                                       "': not a readable HDF5 file (truncated or corrupted)");
             })));
  const detail::PlainCommunicator plain(comm);  // (collective_file.hpp: why)
  const Handle access(H5Pcreate(H5P_FILE_ACCESS), H5Pclose);
  const Handle transfer(H5Pcreate(H5P_DATASET_XFER), H5Pclose);
  const bool properties = access.valid() && transfer.valid() &&
                          H5Pset_fapl_mpio(access.get(), plain.comm, MPI_INFO_NULL) >= 0 &&
                          H5Pset_dxpl_mpio(transfer.get(), H5FD_MPIO_COLLECTIVE) >= 0;
  fail(agree(comm, properties ? std::nullopt
                              : std::optional<std::string>(
                                    "checkpoint '" + file +
                                    "': cannot set up the MPI-IO file access properties")));
  const Handle h5(H5Fopen(file.c_str(), H5F_ACC_RDONLY, access.get()), H5Fclose);
  fail(agree(comm, h5.valid() ? std::nullopt
                              : std::optional<std::string>(
                                    "checkpoint '" + file +
                                    "': not a readable HDF5 file (truncated or corrupted)")));
  Header h;
  fail(agree(comm, attempt([&] { h = read_header(h5.get(), file); })));
  const Block block = equal_block(h.count, rank, size);
  first = block.first;
  fail(agree(comm, attempt([&] {
               read_particles(h5.get(), h,
                              {static_cast<hsize_t>(block.first), static_cast<hsize_t>(block.count),
                               transfer.get()},
                              file);
             })));
  return std::move(h.checkpoint);
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

std::filesystem::path newest_valid_checkpoint(const std::filesystem::path& directory,
                                              std::vector<std::string>* rejected,
                                              CheckpointCheck check) {
  const auto files = list_checkpoints(directory);
  for (const auto& file : files) {
    try {
      if (check == CheckpointCheck::Header)
        read_checkpoint_header(file);
      else
        read_checkpoint(file);
      return file;
    } catch (const CheckpointError& e) {
      if (rejected) rejected->push_back(e.what());
    }
  }
  throw CheckpointError("checkpoint: no valid checkpoint in '" + directory.string() + "' (" +
                        std::to_string(files.size()) + " candidates)");
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
