// The fault log (issue 18 ground truth): one JSON object per line for every
// fault's start (its first affected sample) and end (its last affected
// sample), so a test harness can score a navigation computer's detection.
// Used by `imuemu generate` (beside the output file) and by imuemud.
//
//   {"device":"imu0","phase":"start","fault_id":1,"type":"bias_step",
//    "source":"scene","sample_counter":400,"t_ns":1000000000,
//    "sensor":"gyro","axes":"xyz","clock":"since_start","start_ns":1000000000,
//    "duration_ns":500000000,"flag_status":false,"seed":7,
//    "parameters":{"gyro_bias_rad_s":0.0174533}}
//
// "parameters" holds the fields of the fault's kind in SI units (the
// FaultSpec names); "sensor"/"axes" only for sensor faults. Field list:
// docs/faults.md.
#pragma once

#include <ostream>
#include <string>

#include <nlohmann/json.hpp>

#include "core/fault/fault.hpp"

namespace imuemu::fault_log {

// The event as a JSON object (the line without its newline).
nlohmann::json fault_event_json(const fault::FaultEvent& event);

// One line: the object and '\n'. Returns the stream (check it for errors).
std::ostream& write_fault_event_json_line(std::ostream& out, const fault::FaultEvent& event);

// The kind's parameters of a spec in SI units, as in "parameters" above.
nlohmann::json fault_parameters_json(const fault::FaultSpec& spec);

}  // namespace imuemu::fault_log
