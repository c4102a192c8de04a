// The sensor error model of one device, from TOML: `[imu.error_model]` in a
// scene file (daemon/scene/scene_config.cpp hands the table here) or a file of its
// own for `imuemu generate --sensor FILE.toml` / `imuemu stream --sensor`
// (docs/sensor-models.md):
//
//   preset = "adis16470"        # or "ideal" (default); the keys below override it term by term
//   seed = 42                   # noise seed (integer >= 0)
//   [gyro]                      # datasheet keys with the unit in the name (core/sensor/datasheet.hpp)
//   arw_deg_rt_h = 0.2
//   [accel]
//   bias_instability_ug = 20
//   [temperature]
//   start_c = 10
//   end_c = 40
//   warmup_tau_s = 600
//
// Strict: an unknown key, a key without a unit, two keys setting one term in
// one table (ambiguous), a wrong type or a spec the model refuses is a
// scene::SceneError naming file:line:column and the dotted key.
#pragma once

#include <cstdint>
#include <string>

#include <toml++/toml.h>

#include "core/sensor/sensor_model.hpp"
#include "core/setting_error.hpp"
#include "core/trajectory.hpp"
#include "daemon/scene/scene_config.hpp"

namespace imuemu::scene {

// `table`: the error-model table; `key_path`: its dotted path in messages
// ("imu[0].error_model", or "" for a file of its own).
ErrorModelConfig parse_error_model_table(const toml::table& table, const std::string& file, const std::string& key_path);

// A setting the core refused (core/setting_error.hpp) as a SceneError at the
// entry of `table` (a [signal_chain] or [signal_chain.vibration] table at
// `key_path`) its key names, scene units mapped (angular_rad_s is written
// angular_deg_s, ...): the core's message (plus `suffix`) at that entry's
// file:line:column and dotted key, so the parser, check-config and the core
// say the same thing.
[[noreturn]] void throw_at_setting(const toml::table& table, const std::string& file, const std::string& key_path,
                                   const SettingError& error, const std::string& suffix = "");

// A whole TOML file as an error-model table. Throws SceneError.
ErrorModelConfig parse_error_model_file(const std::string& path);

// `--sensor`: a preset name ("ideal", "adis16470", ...) or a TOML file;
// `seed` (if >= 0) replaces the file's. Throws SceneError or
// std::invalid_argument (unknown preset).
ErrorModelConfig error_model_from_option(const std::string& preset_or_file, std::int64_t seed);

// One line per term with its discrete sigma at the device's rate, for
// check-config and generate ("gyro white noise: N = ... -> sigma = ...").
std::vector<std::string> error_model_lines(const ErrorModelConfig& model, double rate_hz);

// The batch form of the stage (generate): sample k of the output grid
// t_k = t0 + floor(k 1e9 / rate) (core/pipeline.hpp) is measured as sample k,
// exactly as imuemud's producer measures tick k, so both give the same bits.
// Returns the number of samples with a saturated axis. Nothing happens for
// an ideal model.
std::uint64_t apply_error_model(const ErrorModelConfig& model, const std::string& device, std::int64_t rate_hz,
                                TimeNs t0_ns, std::vector<ImuSample>& samples);

// The grid index of t_ns on t0 + floor(k 1e9 / rate): ceil((t - t0) rate / 1e9).
std::uint64_t grid_index(TimeNs t0_ns, TimeNs t_ns, std::int64_t rate_hz);

}  // namespace imuemu::scene
