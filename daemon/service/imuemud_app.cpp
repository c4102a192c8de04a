// imuemud: the imuemu IMU emulator service (issue 6, docs/daemon.md).
//
//   imuemud [--scene FILE] [--control-socket PATH] [--pty-link-dir DIR]
//           [--seconds S] [--stats-json PATH] [--log-level L]
//   imuemud --check-config FILE [--json]
//
// This file: the options, --check-config (parse and check a scene, print its
// figures, open nothing) and run_imuemud() (main() is in imuemud_main.cpp, so
// this file compiles in the service room's batch). It reads and checks the scene
// (docs/scene-format.md; without --scene the built-in config/default.toml),
// then sets up one Boost.Asio io_context that runs everything but the engine
// and the scene builds: the control socket (daemon/service/control_socket.hpp,
// its commands in control_commands.hpp), the signals (service_signals.hpp),
// the watchdog (service_notify.hpp: petted while the emission thread makes
// progress, or while a scene is being built) and the scene's life cycle
// (scene_lifecycle.hpp: start, retries, reload on SIGHUP, status ticks, stop).
// SIGTERM/SIGINT stop at a packet boundary, flush and close the devices and
// exit 0, at once also during a build (the build is abandoned). An exception
// on an engine thread stops the scene with exit 5 (never std::terminate);
// the exit codes are in daemon/service/imuemud.hpp.
//
// Test hook: with IMUEMU_TEST_HOOKS=1 in the environment the control socket
// also offers "stall-emitter" and "fault-producer" (control_commands.hpp).
// Never set in the shipped unit.
#include <csignal>
#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <optional>
#include <string>

#include <CLI/CLI.hpp>
#include <boost/asio/io_context.hpp>
#include <nlohmann/json.hpp>

#include "daemon/engine/emission.hpp"
#include "daemon/scene/default_scene.hpp"
#include "daemon/scene/scene_check.hpp"
#include "daemon/scene/scene_config.hpp"
#include "daemon/scene/scene_runner.hpp"
#include "daemon/service/control_commands.hpp"
#include "daemon/service/control_socket.hpp"
#include "daemon/service/imuemud.hpp"
#include "daemon/service/scene_lifecycle.hpp"
#include "daemon/service/service_notify.hpp"
#include "daemon/service/service_signals.hpp"
#include "io/pose_source.hpp"
#include "log/log.hpp"

namespace {

namespace svc = imuemu::service;
namespace sc = imuemu::scene;
using imuemu::TimeNs;
using svc::kExitBadScene;
using svc::kExitLinkRefused;
using svc::kExitOk;
using svc::kExitStartFailed;
using svc::kExitUsage;

// SIGTERM during a scene build: how long the worker may take to finish (it
// may be opening devices, which is quick) before the process exits without it.
constexpr auto kBuildJoinLimit = std::chrono::milliseconds(500);
// At exit, the fault events still waiting get this long to be written (a
// reader that stopped reading must not hold up SIGTERM; the rest are counted).
constexpr auto kFaultLogDrainLimit = std::chrono::milliseconds(500);

// A handler that throws ends io.run() with the exception; the service
// goes on (io_context can be run again), the failure is counted and
// logged, at most one line a second. No exception leaves the io thread.
void run_until_stopped(boost::asio::io_context& io) {
  std::uint64_t handler_failures = 0;
  auto last_failure_log = std::chrono::steady_clock::time_point{};
  for (;;) {
    try {
      io.run();
      break;
    } catch (const std::exception& e) {
      ++handler_failures;
      const auto now = std::chrono::steady_clock::now();
      if (now - last_failure_log >= std::chrono::seconds(1)) {
        last_failure_log = now;
        svc::log_err(std::string("service handler failed (") + std::to_string(handler_failures) +
                     " so far), going on: " + e.what());
      }
    }
  }
}

// False (logged with the reason) when the file could not be written: the
// exit is then a failure (issue 26 N17), the run's numbers are gone.
bool write_stats(const std::string& path, const svc::SceneLifecycle& lifecycle) {
  if (path.empty()) return true;
  errno = 0;
  std::ofstream out(path);
  if (out)
    out << (lifecycle.final_stats() ? imuemu::emission::to_json(*lifecycle.final_stats()).dump(2) : std::string("null"))
        << "\n";
  if (out) out.flush();
  if (!out) {
    const int error = errno;
    svc::log_err("--stats-json " + path + ": cannot write the statistics" +
                 (error != 0 ? std::string(": ") + std::strerror(error) : std::string()));
    return false;
  }
  return true;
}

// --check-config: parse, compute the figures, print them. Nothing is opened.
int check_config(const std::string& path, bool json, const sc::RunnerOptions& runner) {
  sc::SceneConfig scene;
  try {
    scene = path == "-" ? sc::default_scene() : sc::parse_scene_file(path);
    sc::check_startable(scene, runner);  // what a start would refuse (scene_check.hpp)
  } catch (const std::exception& e) {
    std::cerr << e.what() << "\n";
    return kExitBadScene;
  }
  const sc::SceneCheck check = sc::check_scene(scene);
  std::cout << (json ? sc::to_json(check) : sc::to_text(check));
  if (check.refused) {
    std::cerr << "imuemud: " << scene.file << ": " << sc::refusal_text(check) << "\n";
    return kExitLinkRefused;
  }
  return kExitOk;
}

}  // namespace

int imuemu::service::run_imuemud(int argc, char** argv, const char* version_text) {
  CLI::App app{"imuemud: the imuemu IMU emulator service (man imuemud; docs/daemon.md, under /usr/share/doc/imuemu when installed)"};
  app.set_version_flag("--version", std::string("imuemud ") + version_text);
  std::string scene_path, check_path, socket_override, pty_link_dir, stats_json, log_level = "info";
  std::optional<double> run_seconds;
  bool json = false;
  app.add_option("--scene", scene_path, "Scene file (docs/scene-format.md); default: the built-in config/default.toml");
  app.add_option("--check-config", check_path,
                 "Validate this scene file ('-': the built-in one) without opening devices, print the derived figures "
                 "(look-ahead, link budget, CPU estimate) and exit");
  app.add_flag("--json", json, "--check-config: print JSON");
  app.add_option("--control-socket", socket_override, "Control socket path (default: the scene's [daemon] control_socket)");
  app.add_option("--pty-link-dir", pty_link_dir, "Publish every pty link in this directory instead of the scene's paths");
  app.add_option("--seconds", run_seconds, "Stop cleanly after this many seconds of emission (tests, demos)")
      ->check(CLI::PositiveNumber);
  std::string late_ticks;
  app.add_option("--late-ticks", late_ticks, "Override the scene's [daemon] late_ticks: drop or send")
      ->check(CLI::IsMember({"drop", "send"}));
  app.add_option("--stats-json", stats_json, "At exit, write the emission statistics (JSON) here");
  std::string fault_log_path;
  app.add_option("--fault-log", fault_log_path,
                 "Append every fault's start and end (JSON lines, docs/faults.md) here; overrides the scene's [daemon] fault_log");
  app.add_option("--log-level", log_level, "err, warning, notice, info, debug")->capture_default_str()
      ->check(CLI::IsMember({"err", "warning", "notice", "info", "debug"}));
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? kExitOk : kExitUsage;
  }
  // A reader of the fault log or of stderr that goes away must not kill the
  // daemon (issue 26 N1): a write gets EPIPE instead, which is counted.
  std::signal(SIGPIPE, SIG_IGN);
  if (!check_path.empty()) {
    sc::RunnerOptions check_runner;
    check_runner.pty_link_dir = pty_link_dir;
    return check_config(check_path, json, check_runner);
  }

  const std::map<std::string, svc::LogLevel> levels{{"err", svc::LogLevel::err}, {"warning", svc::LogLevel::warning},
      {"notice", svc::LogLevel::notice}, {"info", svc::LogLevel::info}, {"debug", svc::LogLevel::debug}};
  svc::set_log_threshold(levels.at(log_level));

  sc::SceneConfig scene;
  try {
    scene = scene_path.empty() ? sc::default_scene() : sc::parse_scene_file(scene_path);
    const sc::SceneCheck check = sc::check_scene(scene);
    for (const std::string& w : check.warnings) svc::log_warning(w);
    if (check.refused) {
      svc::log_err(scene.file + ": " + sc::refusal_text(check) + ":\n" + sc::to_text(check));
      return kExitLinkRefused;
    }
  } catch (const std::exception& e) {
    svc::log_err(e.what());
    return kExitBadScene;
  }
  if (scene_path.empty()) svc::log_info("no --scene: running the built-in scene (config/default.toml)");
  const bool test_hooks = [] {
    const char* v = std::getenv("IMUEMU_TEST_HOOKS");
    return v != nullptr && std::string(v) == "1";
  }();

  boost::asio::io_context io;
  sc::RunnerOptions runner;
  runner.pty_link_dir = pty_link_dir;
  if (!late_ticks.empty()) runner.drop_late_ticks = late_ticks == "drop";
  runner.log = [](std::string_view line) { svc::log_notice(line); };
  const std::string fault_log = fault_log_path.empty() ? scene.daemon.fault_log : fault_log_path;
  svc::SceneLifecycle lifecycle(io, scene_path, scene, runner, run_seconds, test_hooks, fault_log,
                                !fault_log_path.empty());
  try {
    const std::string socket_path = !socket_override.empty() ? socket_override
                                    : !scene.daemon.control_socket.empty()
                                        ? scene.daemon.control_socket
                                        : svc::default_control_socket_path(scene.name);
    // Aliases, directories, lengths, the outputs' collisions (scene_check.hpp):
    // nothing is opened or created before.
    sc::check_start_paths(scene, runner, socket_path, sc::OutputPaths{fault_log, stats_json});
    {
      // /run/imuemu comes from the unit's RuntimeDirectory=; the built-in
      // scene's /tmp/imuemu and test directories are made here.
      std::error_code ec;
      std::filesystem::create_directories(std::filesystem::path(socket_path).parent_path(), ec);
    }
    svc::ControlServer control(io, {socket_path, scene.daemon.control_group, std::chrono::seconds(2)});

    std::optional<svc::WatchdogPetter> petter;
    const std::optional<std::chrono::microseconds> watchdog = scene.daemon.watchdog ? svc::watchdog_interval() : std::nullopt;
    if (watchdog) {
      // Healthy = the emission thread looped within half the watchdog
      // interval: a stall is noticed at the next pet and costs at most WatchdogSec.
      const TimeNs max_age_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(*watchdog / 2).count();
      petter.emplace(io, *watchdog, [&lifecycle, max_age_ns] { return lifecycle.healthy(max_age_ns); });
    }
    lifecycle.open_fault_log();
    lifecycle.attach_watchdog(petter ? &*petter : nullptr, watchdog);
    svc::add_control_commands(control, lifecycle, test_hooks);
    svc::ServiceSignals signals(io, [&](int) { lifecycle.stop(kExitOk); }, [&] { lifecycle.reload(); });
    lifecycle.on_stopped([&] {
      control.close();
      io.stop();
    });
    lifecycle.start();
    lifecycle.start_service_timers();
    run_until_stopped(io);
    lifecycle.close_fault_log(kFaultLogDrainLimit);
    if (!lifecycle.join_builder(kBuildJoinLimit)) {
      // The worker is still inside a scene build (nothing there can be
      // interrupted): exit without it, promptly, as SIGTERM asks. It has
      // opened no device yet (that is the quick last step), the control
      // socket is closed; std::_Exit skips the destructors that would wait
      // for or race with it.
      const bool stats_written = write_stats(stats_json, lifecycle);
      svc::log_notice("stopped during a scene build (the build did not end within 0.5 s; abandoned)");
      std::_Exit(!stats_written && lifecycle.exit_code() == kExitOk ? kExitStartFailed : lifecycle.exit_code());
    }
  } catch (const std::exception& e) {
    svc::log_err(e.what());
    if (!lifecycle.join_builder(kBuildJoinLimit)) std::_Exit(kExitStartFailed);
    return kExitStartFailed;
  }
  const bool stats_written = write_stats(stats_json, lifecycle);
  svc::log_info(lifecycle.exit_code() == kExitOk ? "stopped" : "stopped after a failure");
  return !stats_written && lifecycle.exit_code() == kExitOk ? kExitStartFailed : lifecycle.exit_code();
}
