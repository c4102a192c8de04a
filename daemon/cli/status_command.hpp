// `imuemu status [--scene NAME | --socket PATH] [--command CMD] [--timeout-s S]`:
// asks a running imuemud over its control socket (daemon/service/control_socket.hpp)
// and prints the JSON reply, pretty. Errors name the socket path and say what
// to do: no such socket (daemon not running / other scene), permission denied
// (join the socket's group), nothing listening (stale socket), no reply
// within the timeout (daemon hung).
#pragma once

#include <chrono>
#include <iosfwd>
#include <stdexcept>
#include <string>

#include <nlohmann/json.hpp>

namespace CLI {
class App;
}

namespace imuemu::cli {

class ControlClientError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Sends `command` and returns the daemon's JSON reply; throws
// ControlClientError (message names `socket_path`).
nlohmann::json query_control_socket(const std::string& socket_path, const std::string& command,
                                    std::chrono::milliseconds timeout);
// A command with arguments: sends `command {args}` (one line, compact JSON).
nlohmann::json query_control_socket(const std::string& socket_path, const std::string& command,
                                    const nlohmann::json& args, std::chrono::milliseconds timeout);

struct StatusArgs {
  std::string socket_path;  // empty: default_control_socket_path(scene)
  std::string scene = "default";
  std::string command = "status";
  double timeout_s = 2.0;
  bool compact = false;  // one line instead of pretty JSON
  bool summary = false;  // a few explained lines for a person instead of JSON
};

// The status reply of imuemud (daemon/service/status_report.hpp status_json) as a few
// lines, each counter named with what it means. Missing fields print as 0.
void print_status_summary(const nlohmann::json& status, std::ostream& out);

// Prints the reply to stdout, errors to stderr. Exit code (daemon/cli/commands.hpp):
// 0 with a reply, kCannotProcess when the daemon cannot be reached or the
// reply is {"error": ...}, kUsageError for bad options.
int run_status(const StatusArgs& args);

void add_status_command(CLI::App& app, int& exit_code);

}  // namespace imuemu::cli
