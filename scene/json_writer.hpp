// SPDX-License-Identifier: GPL-3.0-or-later
// Writing a configuration object to JSON with the calls that read it (scene/json_reader.hpp):
// a section's keys are listed once, in a function template over the reader or this writer, so
// that a document read and written back has the same keys.
#pragma once

#include <array>
#include <cstddef>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "sim/name_table.hpp"

namespace sphles::scene {

/// Writes keys into one JSON object (created on first use); the counterpart of ObjectReader.
class ObjectWriter {
 public:
  static constexpr bool kReads = false;

  explicit ObjectWriter(nlohmann::json& object) : object_(object) {
    if (!object_.is_object()) object_ = nlohmann::json::object();
  }

  ObjectWriter object(const std::string& key) { return ObjectWriter(object_[key]); }

  void number(const std::string& key, double value) { object_[key] = value; }
  template <class Int>
  void integer(const std::string& key, Int value) {
    object_[key] = value;
  }
  void boolean(const std::string& key, bool value) { object_[key] = value; }
  void string(const std::string& key, const std::string& value) { object_[key] = value; }
  template <class Enum, std::size_t N>
  void choice(const std::string& key, const sim::NameTable<Enum, N>& table, Enum value) {
    object_[key] = std::string(table.name(value));
  }
  void vector(const std::string& key, const std::array<double, 3>& value, std::size_t size) {
    object_[key] = std::vector<double>(value.begin(), value.begin() + size);
  }
  void strings(const std::string& key, const std::vector<std::string>& value) {
    object_[key] = value;
  }
  template <class Enum, std::size_t N>
  void names(const std::string& key, const sim::NameTable<Enum, N>& table,
             const std::set<Enum>& value) {
    nlohmann::json list = nlohmann::json::array();
    for (const Enum e : value) list.push_back(std::string(table.name(e)));
    object_[key] = std::move(list);
  }
  void optional_number(const std::string& key, const std::optional<double>& value) {
    object_[key] = value ? nlohmann::json(*value) : nlohmann::json(nullptr);
  }

  /// Nothing to check when writing (the reader rejects keys no call read).
  void finish() const {}

 private:
  nlohmann::json& object_;
};

}  // namespace sphles::scene
