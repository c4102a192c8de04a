// Sensor-model parameters as datasheets write them (unit in the key name),
// converted to SI once, and presets made of those keys (docs/sensor-models.md).
// Pure: no I/O; the TOML reading lives in daemon/scene/error_model_config.cpp.
#pragma once

#include <string>
#include <vector>

#include "core/sensor/sensor_model.hpp"

namespace imuemu::sensor {

enum class Triad { gyro, accel };

// One datasheet key: which term it sets, its unit, and how many values it
// takes (1: all axes; 3: x, y, z; 9 for g-sensitivity: row-major 3x3; the
// g-sensitivity also takes 1 or 3 values for the diagonal).
struct KeyInfo {
  Triad triad;
  std::string key;
  std::string term;   // the term it sets: two keys of one term in one table are ambiguous
  std::string unit;   // as written in docs and --help
  double to_si = 1.0;
};
const std::vector<KeyInfo>& datasheet_keys();

// Temperature and run keys of the [error_model] table itself (not per triad).
struct TopKeyInfo {
  std::string key, unit;
};
const std::vector<TopKeyInfo>& temperature_keys();

// Sets the term of `key` in spec. Throws std::invalid_argument saying what is
// wrong: an unknown key (with the keys of that triad), a key without a unit
// (naming the keys with units), a wrong number of values.
void apply_key(SensorModelSpec& spec, Triad triad, const std::string& key, const std::vector<double>& values);
void apply_temperature_key(SensorModelSpec& spec, const std::string& key, double value);
// The term a key sets (for the ambiguity check), or "" if unknown.
std::string term_of(Triad triad, const std::string& key);

struct PresetEntry {
  Triad triad;
  std::string key;
  std::vector<double> values;
};
struct Preset {
  std::string name;         // adis16470
  std::string description;  // grade and device
  std::string source;       // the datasheet it comes from
  std::vector<PresetEntry> entries;
};
const std::vector<Preset>& presets();
const Preset* find_preset(const std::string& name);
// The preset's spec (seed 0). Throws std::invalid_argument for an unknown name.
SensorModelSpec preset_spec(const std::string& name);

}  // namespace imuemu::sensor
