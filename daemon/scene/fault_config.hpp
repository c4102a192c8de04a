// Fault injection in a scene file (issue 18, docs/faults.md): the
// `[[imu.fault]]` tables and `[imu.random_faults]` of one [[imu]], parsed
// into core/fault specs (SI units), and their one-line descriptions for
// check-config, generate and imuemud.
//
//   [[imu.fault]]
//   type = "bias_step"          # fault::kind_names()
//   after_s = 10                # since the device's first sample; or at_s = trajectory time (exactly one)
//   duration_s = 5              # optional; absent or 0: until cleared or the end of the run
//   sensor = "gyro"             # gyro | accel | both (sensor faults; default: the sensor the parameters name, else both)
//   axes = "xz"                 # a subset of xyz (default xyz)
//   bias_deg_s = 0.5            # parameters in datasheet units, the unit in the key
//   flag_status = true          # the device reports the fault in its status fields
//   seed = 3                    # random terms; default the error model's seed
//
//   [imu.random_faults]
//   per_hour = 6                # mean faults per hour (Poisson), 0..1800
//   types = ["stuck", "bias_step", "drop"]
//   duration_s = 10             # each
//   seed = 42                   # default the error model's seed
//   bias_deg_s = 2              # optional parameters, sensor, axes, flag_status as above
//
// Strict like the rest of the scene: an unknown key, a parameter of another
// type, both or neither of at_s / after_s, a wrong unit or a value the fault
// refuses is a SceneError naming file:line:column, the dotted key
// (imu[0].fault[1].bias_deg_s) and what is expected.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <toml++/toml.h>

#include "core/fault/fault.hpp"
#include "core/fault/timeline.hpp"

namespace imuemu::scene {

struct DeviceFaults {
  std::vector<fault::FaultSpec> faults;
  fault::RandomFaults random;
};

// The fault keys of one [[imu]] table (`imu_table`, at `imu_path` such as
// "imu[0]" in messages): its "fault" array and "random_faults" table, for
// the device `device` at `rate_hz`; `default_seed`: the error model's seed.
// Throws SceneError.
DeviceFaults parse_device_faults(const toml::table& imu_table, const std::string& file, const std::string& imu_path,
                                 const std::string& device, std::int64_t rate_hz, std::uint64_t default_seed);

// One fault table on its own (the control socket's `imuemu fault inject`
// can build a TOML table of the same keys): `path` in messages.
fault::FaultSpec parse_fault_table(const toml::table& table, const std::string& file, const std::string& path,
                                   const std::string& device, std::int64_t rate_hz, std::uint64_t default_seed);

// One line per fault and one for the random faults ("fault 1: bias_step gyro
// xyz at 10 s since start for 5 s: gyro 0.5 deg/s; seed 0, source scene").
// The ids are those the timeline gives the scene's faults (1, 2, ... in
// file order).
std::vector<std::string> fault_lines(const std::vector<fault::FaultSpec>& faults, const fault::RandomFaults& random);

// The scene keys of each parameter (docs and messages).
std::vector<std::string> fault_parameter_keys();

}  // namespace imuemu::scene
