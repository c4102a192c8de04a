// imuemud: the imuemu IMU emulator service (issue 6, docs/daemon.md).
//
//   imuemud [--scene FILE] [--control-socket PATH] [--pty-link-dir DIR]
//           [--seconds S] [--stats-json PATH] [--log-level L]
//   imuemud --check-config FILE [--json]
//
// Reads a scene (docs/scene-format.md; without --scene the built-in
// config/default.toml), opens its devices (fail fast naming the device, or
// wait with back-off when [daemon] device_missing = "wait"), builds one
// emission engine (daemon/engine/emission.hpp: a producer thread smoothing the poses,
// one absolute-deadline emission thread for all devices), and only then tells
// systemd READY=1. The scene is built on a worker thread (it can take
// seconds); everything else runs on one Boost.Asio io_context, never blocked
// by a build: the control socket (`imuemu status`), signals, STATUS= lines,
// the watchdog (petted while the emission thread makes progress, or while a
// scene is being built) and the periodic log summary. SIGTERM/SIGINT stop at
// a packet boundary, flush and close the devices and exit 0, at once also
// during a build (the build is abandoned). SIGHUP reads and checks the new
// scene (its trajectory included) while the running one goes on; only then
// is the running scene stopped and the new one started (devices reopened, a
// new time base); a scene that does not load is logged and the running one
// kept untouched, and one that loads but does not start is replaced by the
// previous scene again. An exception on an engine thread stops the scene
// with exit 5 (never std::terminate).
//
// Test hook: with IMUEMU_TEST_HOOKS=1 in the environment the control socket
// also offers "stall-emitter" (the emission thread stops making progress
// while staying alive), which tests/hil/systemd_run.sh uses to prove the
// watchdog restarts a stalled daemon, and "fault-producer" (the producer
// thread throws: tests/test_imuemud.cpp proves it ends in exit 5, not an
// abort). Never set in the shipped unit.
#include <sys/mman.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <map>
#include <memory>
#include <optional>
#include <sstream>
#include <set>
#include <string>
#include <thread>

#include <CLI/CLI.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/steady_timer.hpp>
#include <nlohmann/json.hpp>

#include "daemon/service/control_socket.hpp"
#include "daemon/scene/default_scene.hpp"
#include "daemon/engine/emission.hpp"
#include "daemon/service/fault_control.hpp"
#include "io/fault_log.hpp"
#include "log/log.hpp"
#include "daemon/scene/scene_check.hpp"
#include "daemon/scene/scene_config.hpp"
#include "daemon/scene/scene_runner.hpp"
#include "daemon/service/service_notify.hpp"
#include "daemon/service/service_signals.hpp"
#include "io/pose_source.hpp"

namespace {

namespace svc = imuemu::service;
namespace sc = imuemu::scene;
using imuemu::kNsPerSecond;
using imuemu::TimeNs;
using imuemu::emission::monotonic_now_ns;

// Exit codes for systemd: 0 clean stop (or the trajectory ended); anything
// else is a failure that Restart=on-failure acts on (a scene that does not
// parse fails every time and ends in the unit's start limit, visibly).
constexpr int kExitOk = 0;
constexpr int kExitStartFailed = 1;
constexpr int kExitUsage = 2;
constexpr int kExitBadScene = 3;
constexpr int kExitLinkRefused = 4;
constexpr int kExitEmissionFailed = 5;  // an engine thread failed while running (issue 13 C1)
// SIGTERM during a scene build: how long the worker may take to finish (it
// may be opening devices, which is quick) before the process exits without it.
constexpr auto kBuildJoinLimit = std::chrono::milliseconds(500);

// The emission thread must have looped within this long to count as alive
// when no watchdog interval is known (status only).
constexpr TimeNs kAliveWithinNs = kNsPerSecond;
constexpr auto kSummaryLogPeriod = std::chrono::seconds(60);
constexpr auto kRefusalLogPeriod = std::chrono::seconds(10);

TimeNs seconds_ns(double s) { return static_cast<TimeNs>(std::llround(s * 1e9)); }

std::string us_text(TimeNs ns) { return std::to_string(ns / 1000) + " us"; }

// The one-line health summary: STATUS= and the periodic log line.
std::string summary_line(const sc::SceneConfig& scene, const imuemu::emission::EngineStats& s, bool alive) {
  std::ostringstream out;
  out << "scene " << scene.name << ":";
  bool first = true;
  for (const auto& d : s.devices) {
    out << (first ? " " : "; ") << d.name << " " << d.emitted << " samples";
    if (d.extrapolated > 0 || d.blending > 0) out << " (" << d.extrapolated << " extrapolated, " << d.blending << " blending)";
    if (d.producer_late > 0) out << ", " << d.producer_late << " underruns";
    if (d.deadline_misses > 0) out << ", " << d.deadline_misses << " late";
    if (d.write_errors > 0) out << ", " << d.write_errors << " not written";
    if (d.transport.dropped_link_down > 0) out << " (" << d.transport.dropped_link_down << " while no reader/link down)";
    if (d.faults.active > 0) out << ", " << d.faults.active << " fault" << (d.faults.active == 1 ? "" : "s") << " acting";
    if (d.faults.silenced > 0) out << ", " << d.faults.silenced << " silenced by faults";
    first = false;
  }
  out << "; lateness p99 " << us_text(s.lateness.p99_ns) << ", max " << us_text(s.lateness.max_ns);
  if (s.pose_source) {
    out << "; input " << s.pose_source->accepted << " poses";
    if (s.pose_source->lost > 0) out << ", " << s.pose_source->lost << " lost";
    if (s.pose_source->rejected > 0) out << ", " << s.pose_source->rejected << " rejected";
    if (s.pose_source->accepted == 0) out << " (waiting for the first pose)";
  }
  if (s.poses_refused > 0) out << "; " << s.poses_refused << " poses refused by the method";
  if (!alive) out << "; EMITTER STALLED";
  return out.str();
}

// One scene build on the worker thread (issue 13 H3/H4). Building can take
// seconds (a long sample trajectory, a 200 MB file) or never end (a scene
// whose derived sizes are absurd): on the service io thread it blocked
// SIGTERM, the control socket and the watchdog. The io thread only launches
// a job and takes its result (posted back to it); nothing else is shared.
//   start:    sc::build_engine (opens the devices; not started)
//   validate: re-read the scene file, check it and compute its trajectory,
//             for a reload: the running scene is stopped only if this works.
struct BuildJob {
  enum class Kind { start, validate };
  Kind kind = Kind::start;
  sc::SceneConfig scene;        // start: the scene to build; validate: the re-read one
  std::string scene_path;       // validate: empty for the built-in scene
  sc::RunnerOptions runner;     // start (a copy: the worker shares nothing)
  TimeNs next_retry_ns = 0;     // start: back-off after this attempt (device_missing = "wait")
  sc::ReusableTransports reuse;  // start: transports kept open from the previous engine (ptys across a reload)
  sc::BuiltEngine built;        // start: the result
  std::exception_ptr error;     // what the build threw
  TimeNs started_ns = 0;
  std::atomic<bool> done{false};  // the worker has posted its result and ends
};

void run_build_job(BuildJob& job) {
  if (job.kind == BuildJob::Kind::start) {
    job.built = sc::build_engine(job.scene, job.runner, &job.reuse);
    return;
  }
  sc::SceneConfig next = job.scene_path.empty() ? sc::default_scene() : sc::parse_scene_file(job.scene_path);
  const sc::SceneCheck check = sc::check_scene(next);
  if (check.refused) throw std::runtime_error("link budget over 100 %:\n" + sc::to_text(check));
  const bool live = sc::is_live(next.trajectory.kind);
  if (!live) {
    // The trajectory's content (a file that became malformed) is what most
    // often fails a reload: found here, while the old scene still runs.
    const std::size_t poses = sc::scene_trajectory(next).size();
    if (poses < 2)
      throw std::runtime_error(next.file + ": the trajectory has " + std::to_string(poses) +
                               " poses; at least two are needed");
  }
  job.scene = std::move(next);
}

class Daemon {
 public:
  Daemon(boost::asio::io_context& io, std::string scene_path, sc::SceneConfig scene, sc::RunnerOptions runner,
         std::optional<double> run_seconds, bool test_hooks, std::string fault_log_path)
      : io_(io),
        fault_log_path_(std::move(fault_log_path)),
        scene_path_(std::move(scene_path)),
        scene_(std::move(scene)),
        runner_(std::move(runner)),
        run_seconds_(run_seconds),
        test_hooks_(test_hooks),
        retry_timer_(io),
        status_timer_(io),
        stop_timer_(io) {}

  const sc::SceneConfig& scene() const { return scene_; }
  int exit_code() const { return exit_code_; }
  std::optional<imuemu::emission::EngineStats> final_stats() const { return final_stats_; }

  void attach(svc::ControlServer& control, svc::WatchdogPetter* petter, std::optional<std::chrono::microseconds> watchdog) {
    petter_ = petter;
    watchdog_ = watchdog;
    control.add_command("status", "scene, devices, counters, lateness, watchdog", [this] { return status_json(); });
    // Issue 18: run-time faults. The arguments are checked here (nothing
    // reaches the engine otherwise); the engine's producer thread takes the
    // request through its mailbox (a few ms at most, bounded).
    control.add_command_with_args(
        "fault-inject", "{\"imu\", \"type\", \"after_s\", \"duration_s\", \"params\": {...}}: start a fault (docs/faults.md)",
        [this](const nlohmann::json& args) {
          const svc::FaultInjectRequest r = svc::parse_fault_inject(args);
          imuemu::emission::EmissionEngine& engine = running_engine();
          const auto injected = engine.inject_fault(r.imu, r.spec, r.after_ns);
          svc::log_notice("fault injected on " + r.imu + ": id " + std::to_string(injected.id) + ", " +
                          imuemu::fault::describe(r.spec) + ", from sample " + std::to_string(injected.first_sample));
          return nlohmann::json{{"imu", r.imu},
                                {"id", injected.id},
                                {"type", std::string(imuemu::fault::kind_name(r.spec.kind))},
                                {"first_sample", injected.first_sample},
                                {"start_since_start_ns", injected.start_since_start_ns},
                                {"duration_ns", r.spec.duration_ns}};
        });
    control.add_command_with_args("fault-list", "{} or {\"imu\"}: the scheduled and active faults",
                                  [this](const nlohmann::json& args) {
                                    const std::string imu = svc::parse_fault_list(args);
                                    nlohmann::json faults = nlohmann::json::array();
                                    for (const auto& f : running_engine().list_faults(imu))
                                      faults.push_back(svc::fault_info_json(f));
                                    return nlohmann::json{{"faults", std::move(faults)}};
                                  });
    control.add_command_with_args("fault-clear", "{\"imu\", \"id\"} or {\"imu\", \"all\": true}: end faults",
                                  [this](const nlohmann::json& args) {
                                    const svc::FaultClearRequest r = svc::parse_fault_clear(args);
                                    const std::vector<std::uint64_t> cleared = running_engine().clear_faults(r.imu, r.id);
                                    std::string ids;
                                    for (const std::uint64_t id : cleared) ids += (ids.empty() ? "" : ", ") + std::to_string(id);
                                    svc::log_notice("faults cleared on " + r.imu + ": " + ids);
                                    write_fault_events();  // the end events at once
                                    return nlohmann::json{{"imu", r.imu}, {"cleared", cleared}};
                                  });
    if (test_hooks_) {
      control.add_command("stall-emitter", "TEST HOOK: the emission thread stops progressing (watchdog test)", [this] {
        svc::log_warning("test hook: emitter stalled on request");
        if (built_.engine) built_.engine->set_emission_stall_for_test(true);
        return nlohmann::json{{"stalled", true}};
      });
      control.add_command("fault-producer", "TEST HOOK: the producer thread throws (no exception may abort imuemud)", [this] {
        svc::log_warning("test hook: producer fault on request");
        if (built_.engine) built_.engine->inject_producer_fault_for_test();
        return nlohmann::json{{"fault", built_.engine != nullptr}};
      });
    }
  }

  // Healthy: the emission thread looped within max_age_ns, or it is still
  // waiting for a device, or a scene is being built on the worker (the io
  // thread that asks is alive; systemd's TimeoutStartSec bounds a first
  // build, and during a reload the running scene's own health counts).
  bool healthy(TimeNs max_age_ns) const {
    if (!built_.engine) return waiting_for_device_ || job_ != nullptr;
    return built_.engine->healthy(monotonic_now_ns(), max_age_ns);
  }

  // Builds the scene on the worker; opens the devices and starts emission
  // when it is built; READY=1 once running.
  // A reload being read meanwhile ends in a start itself (of the new scene,
  // or of this one again when nothing is running).
  // reuse: transports of the previous engine the scene's devices take
  // again (a reload, a loop restart): a pty stays open, its reader is not
  // hung up.
  void start(sc::ReusableTransports reuse = {}) {
    if (job_) return;
    launch_start(seconds_ns(scene_.daemon.device_retry_initial_s), std::move(reuse));
  }

  void stop(int exit_code) {
    if (stopping_) return;
    stopping_ = true;
    exit_code_ = exit_code;
    svc::notify_stopping();
    retry_timer_.cancel();
    status_timer_.cancel();
    stop_timer_.cancel();
    if (petter_) petter_->stop();
    if (job_)
      svc::log_notice(std::string("stopping while a scene is being ") +
                      (job_->kind == BuildJob::Kind::start ? "built" : "re-read") + " (" +
                      seconds_text(monotonic_now_ns() - job_->started_ns) + " so far): the build is abandoned");
    stop_engine();
    if (on_stopped_) on_stopped_();
  }
  void on_stopped(std::function<void()> f) { on_stopped_ = std::move(f); }

  // SIGHUP. The new scene is read, checked and its trajectory computed on
  // the worker while the running one goes on; only if that succeeds is the
  // running scene stopped and the new one started. If the new one then fails
  // to start, the previous scene is started again.
  void reload() {
    if (stopping_) return;
    if (job_) {
      pending_reload_ = true;
      svc::log_notice("SIGHUP during a scene build: the reload follows when the build ends");
      return;
    }
    svc::notify_reloading();
    auto job = std::make_shared<BuildJob>();
    job->kind = BuildJob::Kind::validate;
    job->scene_path = scene_path_;
    launch(std::move(job));
  }

  // After io.run() returned: waits (bounded) for a worker still building.
  // False if it did not end in time: the caller must not destroy what the
  // worker may still post to (it exits the process instead).
  bool join_builder(std::chrono::milliseconds limit) {
    if (!builder_.joinable()) return true;
    const auto until = std::chrono::steady_clock::now() + limit;
    while (!(builder_job_ && builder_job_->done.load(std::memory_order_acquire))) {
      if (std::chrono::steady_clock::now() >= until) return false;
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    builder_.join();
    builder_job_.reset();
    job_.reset();  // an unused result closes its devices here (removes pty links)
    return true;
  }

 private:
  static std::string seconds_text(TimeNs ns) {
    std::ostringstream out;
    out.precision(3);
    out << std::fixed << static_cast<double>(ns) / 1e9 << " s";
    return out.str();
  }

  std::string ready_text() const {
    std::string text = "scene " + scene_.name + ": ";
    for (std::size_t i = 0; i < built_.outputs.size(); ++i) text += (i ? "; " : "") + built_.outputs[i];
    return text;
  }

  void launch_start(TimeNs next_retry_ns, sc::ReusableTransports reuse = {}) {
    if (stopping_) return;
    auto job = std::make_shared<BuildJob>();
    job->kind = BuildJob::Kind::start;
    job->scene = scene_;
    job->runner = runner_;
    job->reuse = std::move(reuse);
    job->next_retry_ns = next_retry_ns;
    launch(std::move(job));
  }

  void launch(std::shared_ptr<BuildJob> job) {
    // The previous worker posted its result before ending: the join is brief.
    if (builder_.joinable()) builder_.join();
    job->started_ns = monotonic_now_ns();
    job_ = job;
    builder_job_ = job;
    builder_ = std::thread([this, job] {
      try {
        run_build_job(*job);
      } catch (...) {  // nothing leaves the worker: the io thread reports it
        job->error = std::current_exception();
      }
      try {
        boost::asio::post(io_, [this, job] { on_job_done(job); });
      } catch (...) {  // no memory for the handler: the build is lost, the daemon stops
        job->error = std::current_exception();
      }
      job->done.store(true, std::memory_order_release);
    });
  }

  void on_job_done(const std::shared_ptr<BuildJob>& job) {
    if (job != job_) return;
    job_.reset();
    if (stopping_) return;  // the result (if any) is destroyed with the job: devices closed
    if (job->kind == BuildJob::Kind::validate) on_validated(*job);
    else on_built(*job);
    if (pending_reload_ && !job_ && !stopping_) {
      pending_reload_ = false;
      reload();
    }
  }

  void on_validated(BuildJob& job) {
    if (job.error) {
      try {
        std::rethrow_exception(job.error);
      } catch (const std::exception& e) {
        svc::log_err(std::string("reload failed, keeping the running scene: ") + e.what());
      } catch (...) {
        svc::log_err("reload failed (unknown error), keeping the running scene");
      }
      if (built_.engine) svc::notify_ready(ready_text());
      else if (!waiting_for_device_) start();  // nothing was running (the trajectory had ended): start it again
      return;
    }
    svc::log_notice("reload: " + job.scene.name + " read and checked (" +
                    seconds_text(monotonic_now_ns() - job.started_ns) +
                    "): restarting emission with it (ptys with the same link kept open, other devices reopened, "
                    "new time base)");
    previous_scene_ = scene_;
    sc::ReusableTransports kept;
    stop_engine(&kept);
    retry_timer_.cancel();
    waiting_for_device_ = false;
    scene_ = std::move(job.scene);
    // Only what the new scene opens again stays open (the rest is closed
    // before its devices are opened: a changed pty may reuse the link).
    std::set<std::string> wanted;
    for (const sc::ImuConfig& imu : scene_.imus) wanted.insert(sc::reuse_key(imu, runner_));
    for (auto it = kept.begin(); it != kept.end();) it = wanted.count(it->first) != 0 ? std::next(it) : kept.erase(it);
    start(std::move(kept));
  }

  void on_built(BuildJob& job) {
    // Transports the build did not take are closed now, before a retry or
    // the previous scene opens its devices again.
    job.reuse.clear();
    if (job.error) {
      try {
        std::rethrow_exception(job.error);
      } catch (const sc::DeviceOpenError& e) {
        on_device_missing(e, job.next_retry_ns);
      } catch (const std::exception& e) {
        start_failed(e.what());
      } catch (...) {
        start_failed("unknown error while building the scene");
      }
      return;
    }
    built_ = std::move(job.built);
    try {
      built_.engine->start();
    } catch (const std::exception& e) {
      built_ = {};
      start_failed(e.what());
      return;
    }
    previous_scene_.reset();
    running();
  }

  void on_device_missing(const sc::DeviceOpenError& e, TimeNs next_retry_ns) {
    if (scene_.daemon.device_missing == sc::DeviceMissingPolicy::wait) {
      waiting_for_device_ = true;
      const std::string what = std::string(e.what()) + "; retrying in " +
                               std::to_string(static_cast<double>(next_retry_ns) / 1e9).substr(0, 5) + " s";
      svc::notify_status("waiting for a device: " + what);
      svc::log_warning(what);
      retry_timer_.expires_after(std::chrono::nanoseconds(next_retry_ns));
      retry_timer_.async_wait([this, next_retry_ns](const boost::system::error_code& ec) {
        if (ec) return;
        launch_start(std::min(2 * next_retry_ns, seconds_ns(scene_.daemon.device_retry_max_s)));
      });
      return;
    }
    start_failed(std::string(e.what()) + " ([daemon] device_missing = \"fail\")");
  }

  void start_failed(const std::string& what) {
    if (previous_scene_) {
      svc::log_err("reload: the new scene " + scene_.name + " did not start: " + what +
                   "; starting the previous scene " + previous_scene_->name + " again");
      scene_ = std::move(*previous_scene_);
      previous_scene_.reset();
      start();
      return;
    }
    svc::log_err(what);
    stop(kExitStartFailed);
  }

  void running() {
    waiting_for_device_ = false;
    const imuemu::emission::EngineStats s = built_.engine->stats();
    if (!s.realtime_note.empty()) svc::log_warning(s.realtime_note + " (running without it; require_realtime = false)");
    if (s.realtime_priority) svc::log_info("emission thread SCHED_FIFO priority " + std::to_string(scene_.daemon.realtime_priority));
    if (s.memory_locked) svc::log_info("memory locked (mlockall)");
    svc::notify_ready(ready_text());
    svc::log_info("ready: " + ready_text() +
                  (watchdog_ ? "; watchdog " + std::to_string(watchdog_->count() / 1000) + " ms" : "; no watchdog") +
                  (test_hooks_ ? "; TEST HOOKS ENABLED" : ""));
    if (!started_once_) {
      started_once_ = true;
      if (run_seconds_) {
        stop_timer_.expires_after(std::chrono::nanoseconds(seconds_ns(*run_seconds_)));
        stop_timer_.async_wait([this](const boost::system::error_code& ec) {
          if (!ec) {
            svc::log_info("--seconds reached");
            stop(kExitOk);
          }
        });
      }
    }
  }

  imuemu::emission::EmissionEngine& running_engine() {
    if (!built_.engine) throw std::runtime_error(job_ ? "the scene is being built; try again" : "no scene is running");
    return *built_.engine;
  }

  // Ground truth (issue 18): the engine's fault events to the fault log,
  // one JSON line each (io/fault_log.hpp), on the io thread. Without a
  // log they are still taken (the engine's queue is bounded) and counted.
  void write_fault_events() {
    if (!built_.engine) return;
    const std::vector<imuemu::fault::FaultEvent> events = built_.engine->take_fault_events();
    if (events.empty() || !fault_log_) return;
    for (const imuemu::fault::FaultEvent& e : events) imuemu::fault_log::write_fault_event_json_line(*fault_log_, e);
    fault_log_->flush();
    if (!*fault_log_ && !fault_log_failed_) {
      fault_log_failed_ = true;
      svc::log_err("fault log " + fault_log_path_ + ": writing failed; fault events are no longer recorded");
    }
  }

 public:
  // Opens (appends to) the fault log; throws naming the path.
  void open_fault_log() {
    if (fault_log_path_.empty()) return;
    fault_log_.emplace(fault_log_path_, std::ios::app);
    if (!*fault_log_) throw std::runtime_error("fault log " + fault_log_path_ + ": cannot open it for writing");
  }

 private:
  // keep: the byte-stream transports with a reuse_key() stay open and go
  // there (the scene's devices are the engine's, in order); the rest close.
  void stop_engine(sc::ReusableTransports* keep = nullptr) {
    if (!built_.engine) return;
    if (keep != nullptr) built_.engine->stop_keeping_transports();
    else built_.engine->stop();
    write_fault_events();  // the last ones, the ends of the faults still active included
    final_stats_ = built_.engine->stats();
    svc::log_info("emission stopped: " + summary_line(scene_, *final_stats_, true));
    if (keep != nullptr) {
      std::vector<std::unique_ptr<imuemu::drivers::Transport>> transports = built_.engine->take_transports();
      for (std::size_t i = 0; i < transports.size() && i < scene_.imus.size(); ++i) {
        const std::string key = sc::reuse_key(scene_.imus[i], runner_);
        if (!key.empty() && transports[i]) (*keep)[key] = std::move(transports[i]);
      }
    }
    built_ = {};
  }

 public:
  // The status timer and the watchdog run from the start, through the
  // builds (they are what must not go quiet while a scene is built).
  void start_service_timers() {
    if (petter_) petter_->start();
    last_summary_ = std::chrono::steady_clock::now();
    schedule_status();
  }

 private:
  void schedule_status() {
    const auto period = std::chrono::nanoseconds(seconds_ns(std::max(scene_.daemon.status_interval_s, 0.1)));
    status_timer_.expires_after(std::min<std::chrono::nanoseconds>(period, std::chrono::milliseconds(500)));
    status_timer_.async_wait([this, period](const boost::system::error_code& ec) {
      if (ec || stopping_) return;
      on_status_tick(period);
      if (!stopping_) schedule_status();
    });
  }

  void on_status_tick(std::chrono::nanoseconds status_period) {
    if (!built_.engine) return;
    write_fault_events();
    const imuemu::emission::EngineStats s = built_.engine->stats();
    if (!s.fault.empty() || s.thread_faults > 0) {
      // An exception reached the top of an engine thread (caught there, both
      // threads stopped): the scene cannot go on; a failure exit lets
      // Restart=on-failure bring it back.
      svc::log_err("emission failed: " + (s.fault.empty() ? std::string("a thread failed") : s.fault) +
                   "; stopping the scene");
      stop(kExitEmissionFailed);
      return;
    }
    if (s.finished) {
      if (scene_.trajectory.loop) {
        svc::log_notice("the looped trajectory ended: restarting the run (ptys kept open, other devices reopened, "
                        "new time base)");
        sc::ReusableTransports kept;
        stop_engine(&kept);
        start(std::move(kept));
      } else {
        svc::log_notice(s.time_limit_ends > 0
                            ? "the stream reached the end of int64 nanosecond time (no later tick is representable): stopping"
                            : "the trajectory ended: stopping");
        stop(kExitOk);
      }
      return;
    }
    const auto now = std::chrono::steady_clock::now();
    log_new_refusals(s, now);
    const bool alive = built_.engine->healthy(monotonic_now_ns(), kAliveWithinNs);
    if (now - last_status_ >= status_period) {
      last_status_ = now;
      const std::string line = summary_line(scene_, s, alive);
      svc::notify_status(line);
      if (now - last_summary_ >= kSummaryLogPeriod) {
        last_summary_ = now;
        svc::log_info(line);
      } else {
        svc::log_debug(line);
      }
    }
  }

  // Poses the method refused (counted by the engine, which never logs): a
  // warning with the newest reason, at most one per kRefusalLogPeriod, so a
  // stream whose every pose is refused says why within a second and then
  // stays quiet but counted.
  void log_new_refusals(const imuemu::emission::EngineStats& s, std::chrono::steady_clock::time_point now) {
    if (s.poses_refused < refusals_logged_) refusals_logged_ = 0;  // a new engine (restart, reload)
    if (s.poses_refused <= refusals_logged_) return;
    if (refusals_logged_ > 0 && now - last_refusal_log_ < kRefusalLogPeriod) return;
    svc::log_warning(std::to_string(s.poses_refused - refusals_logged_) + " poses refused by the method (" +
                     std::to_string(s.poses_refused) + " in all); the newest: " +
                     (s.last_pose_refusal.empty() ? std::string("no reason recorded") : s.last_pose_refusal));
    refusals_logged_ = s.poses_refused;
    last_refusal_log_ = now;
  }

  nlohmann::json status_json() const {
    nlohmann::json status{
        {"scene", scene_.name},
        {"scene_file", scene_.file},
        {"pid", ::getpid()},
        {"uptime_s", static_cast<double>(monotonic_now_ns() - started_ns_) / 1e9},
        {"imus", scene_.imus.size()},
        {"waiting_for_device", waiting_for_device_},
        {"fault_log", fault_log_path_.empty() ? nlohmann::json(nullptr) : nlohmann::json(fault_log_path_)},
    };
    if (job_) {
      status["building"] = {{"what", job_->kind == BuildJob::Kind::start ? "start" : "reload"},
                            {"elapsed_s", static_cast<double>(monotonic_now_ns() - job_->started_ns) / 1e9}};
    } else {
      status["building"] = nullptr;
    }
    if (built_.engine) {
      const imuemu::emission::EngineStats s = built_.engine->stats();
      status["samples_emitted"] = s.emitted;
      status["emitter_progressing"] = built_.engine->healthy(monotonic_now_ns(), kAliveWithinNs);
      status["engine"] = imuemu::emission::to_json(s);
    } else {
      status["samples_emitted"] = 0;
      status["emitter_progressing"] = false;
      status["engine"] = nullptr;
    }
    if (petter_ && watchdog_) {
      status["watchdog"] = {{"interval_s", static_cast<double>(watchdog_->count()) / 1e6},
                            {"pets_sent", petter_->pets_sent()},
                            {"pets_withheld", petter_->pets_withheld()}};
    } else {
      status["watchdog"] = nullptr;
    }
    return status;
  }

  boost::asio::io_context& io_;
  std::string fault_log_path_;  // empty: no fault log
  std::optional<std::ofstream> fault_log_;
  bool fault_log_failed_ = false;
  std::string scene_path_;  // empty: the built-in scene
  sc::SceneConfig scene_;
  sc::RunnerOptions runner_;
  std::optional<double> run_seconds_;
  bool test_hooks_;
  boost::asio::steady_timer retry_timer_, status_timer_, stop_timer_;
  sc::BuiltEngine built_;
  std::thread builder_;
  std::shared_ptr<BuildJob> job_;          // the build under way (io thread's view); null: none
  std::shared_ptr<BuildJob> builder_job_;  // the job of builder_ (for join_builder)
  bool pending_reload_ = false;
  std::optional<sc::SceneConfig> previous_scene_;  // during a reload: started again if the new scene fails
  svc::WatchdogPetter* petter_ = nullptr;
  std::optional<std::chrono::microseconds> watchdog_;
  bool waiting_for_device_ = false;
  bool started_once_ = false;
  bool stopping_ = false;
  int exit_code_ = kExitOk;
  std::function<void()> on_stopped_;
  std::optional<imuemu::emission::EngineStats> final_stats_;
  std::chrono::steady_clock::time_point last_status_{}, last_summary_{}, last_refusal_log_{};
  std::uint64_t refusals_logged_ = 0;  // of the running engine's poses_refused
  TimeNs started_ns_ = monotonic_now_ns();
};

void write_stats(const std::string& path, const Daemon& daemon) {
  if (path.empty()) return;
  std::ofstream out(path);
  out << (daemon.final_stats() ? imuemu::emission::to_json(*daemon.final_stats()).dump(2) : std::string("null")) << "\n";
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
    std::cerr << "imuemud: " << scene.file << ": refused: a link is loaded beyond 100 % (see above)\n";
    return kExitLinkRefused;
  }
  return kExitOk;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"imuemud: the imuemu IMU emulator service (docs/daemon.md)"};
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
      svc::log_err(scene.file + ": refused: a link is loaded beyond 100 %:\n" + sc::to_text(check));
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
  Daemon daemon(io, scene_path, scene, runner, run_seconds, test_hooks,
                fault_log_path.empty() ? scene.daemon.fault_log : fault_log_path);
  try {
    const std::string socket_path = !socket_override.empty() ? socket_override
                                    : !scene.daemon.control_socket.empty()
                                        ? scene.daemon.control_socket
                                        : svc::default_control_socket_path(scene.name);
    sc::check_start_paths(scene, runner, socket_path);  // aliases, directories, lengths (scene_check.hpp)
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
      petter.emplace(io, *watchdog, [&daemon, max_age_ns] { return daemon.healthy(max_age_ns); });
    }
    daemon.open_fault_log();
    daemon.attach(control, petter ? &*petter : nullptr, watchdog);
    svc::ServiceSignals signals(io, [&](int) { daemon.stop(kExitOk); }, [&] { daemon.reload(); });
    daemon.on_stopped([&] {
      control.close();
      io.stop();
    });
    daemon.start();
    daemon.start_service_timers();
    // A handler that throws ends io.run() with the exception; the service
    // goes on (io_context can be run again), the failure is counted and
    // logged, at most one line a second. No exception leaves the io thread.
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
    if (!daemon.join_builder(kBuildJoinLimit)) {
      // The worker is still inside a scene build (nothing there can be
      // interrupted): exit without it, promptly, as SIGTERM asks. It has
      // opened no device yet (that is the quick last step), the control
      // socket is closed; std::_Exit skips the destructors that would wait
      // for or race with it.
      write_stats(stats_json, daemon);
      svc::log_notice("stopped during a scene build (the build did not end within 0.5 s; abandoned)");
      std::_Exit(daemon.exit_code());
    }
  } catch (const std::exception& e) {
    svc::log_err(e.what());
    if (!daemon.join_builder(kBuildJoinLimit)) std::_Exit(kExitStartFailed);
    return kExitStartFailed;
  }
  write_stats(stats_json, daemon);
  svc::log_info(daemon.exit_code() == kExitOk ? "stopped" : "stopped after a failure");
  return daemon.exit_code();
}
