// The life of imuemud's scene, on the service io thread: start it (built on
// the worker, daemon/service/scene_builder.hpp; devices opened, then the
// emission engine started and READY=1), retry a missing device with doubling
// back-off ([daemon] device_missing = "wait"), reload it on SIGHUP (the new
// scene is read and checked while the running one goes on; only then is the
// running one stopped and the new one started, ptys with the same link kept
// open; a scene that does not load is logged and the running one kept, one
// that loads but does not start is replaced by the previous scene again),
// restart a looped trajectory at its end, and stop (SIGTERM, --seconds, the
// trajectory's end, an engine thread that failed: exit 5). The status timer
// ticks here too: it notices an engine that failed or finished, writes the
// fault events (daemon/service/fault_log_writer.hpp) and has
// daemon/service/status_report.hpp publish the summary. Nothing here waits on
// a build: SIGTERM, the control socket and the watchdog are served during one.
#pragma once

#include <chrono>
#include <functional>
#include <memory>
#include <optional>
#include <string>

#include <boost/asio/io_context.hpp>
#include <boost/asio/steady_timer.hpp>
#include <nlohmann/json.hpp>

#include "core/types.hpp"
#include "daemon/engine/emission.hpp"
#include "daemon/scene/scene_config.hpp"
#include "daemon/scene/scene_runner.hpp"
#include "daemon/service/fault_log_writer.hpp"
#include "daemon/service/scene_builder.hpp"
#include "daemon/service/service_notify.hpp"
#include "daemon/service/status_report.hpp"

namespace imuemu::service {

class SceneLifecycle {
 public:
  // scene_path: empty for the built-in scene. run_seconds: --seconds (the
  // first start's emission time). test_hooks: only named in the ready line
  // (the hooks are control commands, daemon/service/control_commands.hpp).
  // fault_log_path: empty for none. fault_log_fixed: it came from
  // --fault-log (a reload keeps it; else the new scene's [daemon] fault_log).
  SceneLifecycle(boost::asio::io_context& io, std::string scene_path, scene::SceneConfig scene,
                 scene::RunnerOptions runner, std::optional<double> run_seconds, bool test_hooks,
                 std::string fault_log_path, bool fault_log_fixed = false);

  int exit_code() const { return exit_code_; }
  // The engine's statistics when it last stopped (--stats-json).
  std::optional<emission::EngineStats> final_stats() const { return final_stats_; }

  // The watchdog petter (null: none) and its interval, for the status and
  // the ready line; set before start().
  void attach_watchdog(WatchdogPetter* petter, std::optional<std::chrono::microseconds> watchdog) {
    petter_ = petter;
    watchdog_ = watchdog;
  }
  // Opens (appends to) the fault log; throws naming the path and the reason
  // (a FIFO without reader is not an error: retried, fault_log_writer.hpp).
  void open_fault_log() { fault_log_.open(); }
  // At exit: the events still waiting get up to drain_limit to be written.
  void close_fault_log(std::chrono::milliseconds drain_limit) { fault_log_.close(drain_limit); }
  // on_stopped: called once stop() has stopped everything (main closes the
  // control socket and stops the io_context).
  void on_stopped(std::function<void()> f) { on_stopped_ = std::move(f); }

  // Builds the scene on the worker; opens the devices and starts emission
  // when it is built; READY=1 once running.
  // A reload being read meanwhile ends in a start itself (of the new scene,
  // or of this one again when nothing is running).
  // reuse: transports of the previous engine the scene's devices take
  // again (a reload, a loop restart): a pty stays open, its reader is not
  // hung up.
  void start(scene::ReusableTransports reuse = {});

  // The status timer and the watchdog run from the start, through the
  // builds (they are what must not go quiet while a scene is built).
  void start_service_timers();

  // SIGTERM/SIGINT, --seconds, the end: STOPPING=1, the engine stopped at a
  // packet boundary (devices flushed and closed), a build under way abandoned.
  void stop(int exit_code);

  // SIGHUP. The new scene is read, checked and its trajectory computed on
  // the worker while the running one goes on; only if that succeeds is the
  // running scene stopped and the new one started. If the new one then fails
  // to start, the previous scene is started again.
  void reload();

  // After io.run() returned: waits (bounded) for a worker still building.
  // False if it did not end in time: the caller must not destroy what the
  // worker may still post to (it exits the process instead).
  bool join_builder(std::chrono::milliseconds limit);

  // Healthy: the emission thread looped within max_age_ns, or it is still
  // waiting for a device, or a scene is being built on the worker (the io
  // thread that asks is alive; systemd's TimeoutStartSec bounds a first
  // build, and during a reload the running scene's own health counts).
  bool healthy(TimeNs max_age_ns) const;

  // For the control commands (daemon/service/control_commands.hpp), on the
  // io thread:
  nlohmann::json status_json() const;  // the "status" reply (status_report.hpp)
  // The running engine; throws std::runtime_error when none runs (a scene
  // being built, the trajectory ended).
  emission::EmissionEngine& running_engine();
  emission::EmissionEngine* engine() { return built_.engine.get(); }  // null: none
  // Ground truth (issue 18): the engine's fault events to the fault log.
  // Without a log they are still taken (the engine's queue is bounded).
  void write_fault_events();

 private:
  void launch_start(TimeNs next_retry_ns, scene::ReusableTransports reuse = {});
  void launch(std::shared_ptr<SceneBuildJob> job);
  void on_job_done(const std::shared_ptr<SceneBuildJob>& job);
  void on_validated(SceneBuildJob& job);
  void on_built(SceneBuildJob& job);
  void on_device_missing(const scene::DeviceOpenError& e, TimeNs next_retry_ns);
  void start_failed(const std::string& what);
  void running();
  std::string ready_text() const;
  // keep: the byte-stream transports with a reuse_key() stay open and go
  // there (the scene's devices are the engine's, in order); the rest close.
  void stop_engine(scene::ReusableTransports* keep = nullptr);
  void schedule_status();
  void on_status_tick(std::chrono::nanoseconds status_period);

  FaultLogWriter fault_log_;
  bool fault_log_fixed_ = false;
  std::string scene_path_;  // empty: the built-in scene
  scene::SceneConfig scene_;
  scene::RunnerOptions runner_;
  std::optional<double> run_seconds_;
  bool test_hooks_;
  boost::asio::steady_timer retry_timer_, status_timer_, stop_timer_;
  scene::BuiltEngine built_;
  SceneBuilder builder_;
  std::shared_ptr<SceneBuildJob> job_;  // the build under way (io thread's view); null: none
  bool pending_reload_ = false;
  std::optional<scene::SceneConfig> previous_scene_;  // during a reload: started again if the new scene fails
  WatchdogPetter* petter_ = nullptr;
  std::optional<std::chrono::microseconds> watchdog_;
  bool waiting_for_device_ = false;
  bool started_once_ = false;
  bool stopping_ = false;
  int exit_code_ = 0;
  std::function<void()> on_stopped_;
  std::optional<emission::EngineStats> final_stats_;
  StatusReport report_;
  TimeNs started_ns_ = emission::monotonic_now_ns();
};

}  // namespace imuemu::service
