// imuemud's fault commands on the control socket (issue 18; protocol in
// docs/daemon.md): the arguments of fault-inject / fault-list / fault-clear
// checked and turned into what the emission engine takes, and its answers
// into JSON. Every parse throws std::invalid_argument naming the key before
// anything is sent to the engine, so refused arguments change nothing.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/fault/fault.hpp"
#include "daemon/engine/emission.hpp"

namespace imuemu::service {

// fault-inject {"imu": NAME, "type": KIND, "after_s": X, "duration_s": D,
//               "params": {key: value, ...}}
// after_s (default 0): the fault starts that long after the next sample the
// daemon computes; duration_s (default 0): until cleared. params: the keys of
// a scene's [[imu.fault]] entry beyond type/start/duration (docs/faults.md).
struct FaultInjectRequest {
  std::string imu;
  fault::FaultSpec spec;  // clock and start are set by the engine
  TimeNs after_ns = 0;
};
FaultInjectRequest parse_fault_inject(const nlohmann::json& args);

// fault-clear {"imu": NAME, "id": N} or {"imu": NAME, "all": true}
struct FaultClearRequest {
  std::string imu;
  std::optional<std::uint64_t> id;  // nullopt: all
};
FaultClearRequest parse_fault_clear(const nlohmann::json& args);

// fault-list {} or {"imu": NAME}; returns the name ("" for all).
std::string parse_fault_list(const nlohmann::json& args);

nlohmann::json fault_info_json(const emission::FaultInfo& info);

}  // namespace imuemu::service
