#include "daemon/cli/fault_command.hpp"

#include <charconv>
#include <cmath>
#include <iostream>
#include <memory>
#include <stdexcept>

#include <CLI/CLI.hpp>

#include "daemon/cli/cli_options.hpp"
#include "daemon/cli/commands.hpp"
#include "daemon/service/imuemud.hpp"
#include "daemon/cli/status_command.hpp"

namespace imuemu::cli {

namespace {

nlohmann::json param_value(const std::string& text) {
  if (text == "true") return true;
  if (text == "false") return false;
  // A whole number stays integral (ids, divisors, sample counts).
  std::int64_t integer = 0;
  if (const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), integer);
      ec == std::errc() && end == text.data() + text.size())
    return integer;
  double number = 0.0;
  if (const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), number);
      ec == std::errc() && end == text.data() + text.size() && std::isfinite(number))
    return number;
  return text;
}

}  // namespace

std::pair<std::string, nlohmann::json> fault_request(const FaultArgs& args) {
  nlohmann::json request = nlohmann::json::object();
  if (!args.imu.empty()) request["imu"] = args.imu;
  if (args.action == "inject") {
    if (args.imu.empty()) throw std::invalid_argument("fault inject: --imu is required");
    if (args.type.empty()) throw std::invalid_argument("fault inject: --type is required");
    request["type"] = args.type;
    if (args.after_s) request["after_s"] = *args.after_s;
    if (args.duration_s) request["duration_s"] = *args.duration_s;
    nlohmann::json params = nlohmann::json::object();
    for (const std::string& p : args.params) {
      const std::size_t eq = p.find('=');
      if (eq == std::string::npos || eq == 0 || eq + 1 == p.size())
        throw std::invalid_argument("fault inject: --param '" + p + "' is not key=value");
      const std::string key = p.substr(0, eq);
      if (params.contains(key)) throw std::invalid_argument("fault inject: --param " + key + " given twice");
      params[key] = param_value(p.substr(eq + 1));
    }
    request["params"] = std::move(params);
    return {"fault-inject", request};
  }
  if (args.action == "list") return {"fault-list", request};
  if (args.action == "clear") {
    if (args.imu.empty()) throw std::invalid_argument("fault clear: --imu is required");
    if (args.id.has_value() == args.all) throw std::invalid_argument("fault clear: give either --id N or --all");
    if (args.id) request["id"] = *args.id;
    else request["all"] = true;
    return {"fault-clear", request};
  }
  throw std::invalid_argument("fault: unknown action '" + args.action + "' (inject, list, clear)");
}

int run_fault(const FaultArgs& args) {
  std::pair<std::string, nlohmann::json> request;
  try {
    request = fault_request(args);
  } catch (const std::invalid_argument& e) {
    std::cerr << "imuemu " << e.what() << '\n';
    return kUsageError;
  }
  const std::string path = args.socket_path.empty() ? service::find_control_socket(args.scene) : args.socket_path;
  const auto timeout = std::chrono::milliseconds(static_cast<std::int64_t>(std::llround(args.timeout_s * 1000.0)));
  try {
    const nlohmann::json reply = query_control_socket(path, request.first, request.second, timeout);
    // A refusal is said once, on stderr (issue 26: it was also printed as
    // JSON on stdout); stdout carries only an accepted request's reply.
    if (!(reply.is_object() && reply.contains("error"))) std::cout << reply.dump(args.compact ? -1 : 2) << '\n';
    if (reply.is_object() && reply.contains("error")) {
      const nlohmann::json& error = reply["error"];
      std::cerr << "imuemu fault " << args.action << ": the daemon at " << path
                << " refused: " << (error.is_string() ? error.get<std::string>() : error.dump()) << '\n';
      return kCannotProcess;
    }
    return kOk;
  } catch (const std::exception& e) {
    std::cerr << "imuemu fault " << args.action << ": " << e.what()
              << (args.socket_path.empty() ? " (looked at " + service::control_socket_places_text(args.scene) + ")" : "")
              << '\n';
    return kCannotProcess;
  }
}

void add_fault_command(CLI::App& app, int& exit_code) {
  auto* fault = app.add_subcommand("fault", "Inject, list or clear faults in a running imuemud (control socket; docs/faults.md)");
  fault->require_subcommand(1);
  const auto common = [&exit_code](CLI::App* cmd, const std::shared_ptr<FaultArgs>& args) {
    auto* socket_option = cmd->add_option("--socket", args->socket_path, "Control socket path (default /run/imuemu/SCENE.sock, else /tmp/imuemu/SCENE.sock: the first that exists)");
    cmd->add_option("--scene", args->scene, "Scene name, for the default socket path")->capture_default_str()->excludes(socket_option);
    cmd->add_option("--timeout-s", args->timeout_s, "Give up when no reply comes within this")
        ->capture_default_str()->check(seconds_in(0.0, kMaxIntervalS, true));
    cmd->add_flag("--compact", args->compact, "One-line JSON");
    cmd->callback([args, &exit_code] { exit_code = run_fault(*args); });
  };
  {
    auto args = std::make_shared<FaultArgs>();
    args->action = "inject";
    auto* cmd = fault->add_subcommand("inject", "Start a fault on a device; prints its id");
    common(cmd, args);
    cmd->add_option("--imu", args->imu, "The [[imu]] name")->required();
    cmd->add_option("--type", args->type, "Fault type (docs/faults.md: dead, stuck, bias_step, drop, bad_checksum, ...)")->required();
    cmd->add_option("--after-s", args->after_s, "Start this long after the next sample the daemon computes (default 0)")
        ->check(seconds_in(0.0, kMaxIntervalS));
    cmd->add_option("--duration-s", args->duration_s, "Last this long (default: until cleared)")
        ->check(seconds_in(0.0, kMaxDurationS));
    cmd->add_option("--param", args->params, "key=value, the scene's [[imu.fault]] keys, datasheet units in the key (bias_deg_h=100); repeatable");
  }
  {
    auto args = std::make_shared<FaultArgs>();
    args->action = "list";
    auto* cmd = fault->add_subcommand("list", "List the active and scheduled faults (all devices, or one)");
    common(cmd, args);
    cmd->add_option("--imu", args->imu, "Only this [[imu]]");
  }
  {
    auto args = std::make_shared<FaultArgs>();
    args->action = "clear";
    auto* cmd = fault->add_subcommand("clear", "End a fault (by id) or all faults of a device");
    common(cmd, args);
    cmd->add_option("--imu", args->imu, "The [[imu]] name")->required();
    // Checked as text before the conversion: CLI11 would wrap "-5" into
    // 18446744073709551611 (issue 26 N17).
    auto* id = cmd->add_option("--id", args->id, "The fault's id (from inject or list)")
                   ->check([](const std::string& text) -> std::string {
                     const bool digits = !text.empty() && text.size() <= 19 &&
                                         text.find_first_not_of("0123456789") == std::string::npos;
                     if (!digits || text.find_first_not_of('0') == std::string::npos)
                       return "expected a fault id (an integer >= 1, from inject or list), got '" + text + "'";
                     return {};
                   });
    cmd->add_flag("--all", args->all, "Every fault of the device")->excludes(id);
  }
}

}  // namespace imuemu::cli
