// SPDX-License-Identifier: GPL-3.0-or-later
#include "io/checkpoint_format.hpp"

#include <hdf5.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstring>
#include <functional>
#include <nlohmann/json.hpp>
#include <optional>
#include <tuple>

#include "io/collective_file.hpp"
#include "io/hdf5_file.hpp"
#include "scene/document.hpp"
#include "scene/presets.hpp"
#include "sim/scene.hpp"

namespace sphles::io::checkpoint_format {

namespace {

using detail::agree;
using detail::attempt;
using detail::Handle;
using detail::write_scalar_attribute;
using detail::write_string_attribute;

const char* kAxis[] = {"x", "y", "z"};

/// At most this many entries per chunk of a particle dataset.
constexpr hsize_t kChunkEntries = hsize_t{1} << 16;

}  // namespace

hsize_t chunk_entries(hsize_t size) {
  if (size == 0) return 0;
  const hsize_t chunks = (size + kChunkEntries - 1) / kChunkEntries;
  return (size + chunks - 1) / chunks;
}

// --- writing ---------------------------------------------------------------------------

namespace {

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

}  // namespace

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

namespace {

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

}  // namespace

// --- content validation ----------------------------------------------------------------

std::string number(double value) {
  char text[32];
  const auto result = std::to_chars(text, text + sizeof text, value);
  return std::string(text, result.ptr);
}

namespace {

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

}  // namespace

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

namespace {

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

bool is_known_preset(const nlohmann::json& value) {
  if (!value.is_string()) return false;
  const auto presets = scene::preset_names();
  return std::find(presets.begin(), presets.end(), value.get<std::string>()) != presets.end();
}

/// The geometry keys of the scene (case or preset, particles_per_side, box_length) resolved by
/// scene::parse_scene, which owns their defaults and limits. A scene that names no case this
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
        scene::parse_scene({{"case", *case_it}});
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
    g.scene = scene::parse_scene(geometry);
  } catch (const sim::SceneError& e) {
    throw CheckpointError("checkpoint '" + file +
                          "': attribute 'scene' does not determine the periodic box: " + e.what());
  }
  return g;
}

}  // namespace

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
  // Steps are reported as JSON numbers (run.json, the API, the time series), which clients read
  // as doubles: exact up to 2^53. A scene's step is at least 2^-40 of time.end (sim/scene.hpp),
  // so no run of an accepted scene comes near it.
  constexpr std::uint64_t kMaxStep = std::uint64_t{1} << 53;
  if (c.state.step > kMaxStep)
    throw CheckpointError(
        "checkpoint '" + file + "': attribute 'step' is " + std::to_string(c.state.step) +
        ", above 2^53 = " + std::to_string(kMaxStep) + " (the largest step count read exactly)");
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

}  // namespace sphles::io::checkpoint_format
