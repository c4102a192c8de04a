// `imuemu fault inject|list|clear` (issue 18): run-time fault injection into a
// running imuemud over its control socket (daemon/service/control_socket.hpp, the
// commands fault-inject, fault-list and fault-clear; docs/daemon.md). The
// socket's permissions (0660, its group) decide who may inject.
//
//   imuemu fault inject (--scene S | --socket P) --imu NAME --type T
//                       [--after-s X] [--duration-s D] [--param key=value ...]
//   imuemu fault list   (--scene S | --socket P) [--imu NAME]
//   imuemu fault clear  (--scene S | --socket P) --imu NAME (--id N | --all)
//
// Prints the daemon's reply (JSON); exit 0 when it accepted, kCannotProcess
// with the daemon's error message on stderr when it refused or cannot be
// reached, kUsageError for a bad command line.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace CLI {
class App;
}

namespace imuemu::cli {

struct FaultArgs {
  std::string action;       // inject | list | clear
  std::string socket_path;  // empty: default_control_socket_path(scene)
  std::string scene = "default";
  std::string imu;
  std::string type;
  std::optional<double> after_s, duration_s;
  std::vector<std::string> params;  // key=value, datasheet units in the key (gyro_bias_deg_h=100)
  std::optional<std::uint64_t> id;
  bool all = false;
  double timeout_s = 2.0;
  bool compact = false;
};

// The control command and its arguments for `args` (fault-inject {...}, ...).
// Throws std::invalid_argument for a malformed --param or a missing option.
// A value is sent as a JSON number when it parses as one entirely, true/false
// as a boolean, anything else as a string.
std::pair<std::string, nlohmann::json> fault_request(const FaultArgs& args);

int run_fault(const FaultArgs& args);

void add_fault_command(CLI::App& app, int& exit_code);

}  // namespace imuemu::cli
