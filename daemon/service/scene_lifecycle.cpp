#include "daemon/service/scene_lifecycle.hpp"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <iterator>
#include <set>
#include <sstream>
#include <stdexcept>
#include <utility>
#include <vector>

#include "daemon/scene/scene_check.hpp"
#include "daemon/service/imuemud.hpp"
#include "io/pose_source.hpp"
#include "log/log.hpp"

namespace imuemu::service {

namespace {

// The emission thread must have looped within this long to count as alive
// when no watchdog interval is known (status only).
constexpr TimeNs kAliveWithinNs = kNsPerSecond;

TimeNs seconds_ns(double s) { return static_cast<TimeNs>(std::llround(s * 1e9)); }

std::string seconds_text(TimeNs ns) {
  std::ostringstream out;
  out.precision(3);
  out << std::fixed << static_cast<double>(ns) / 1e9 << " s";
  return out.str();
}

}  // namespace

SceneLifecycle::SceneLifecycle(boost::asio::io_context& io, std::string scene_path, scene::SceneConfig scene,
                               scene::RunnerOptions runner, std::optional<double> run_seconds, bool test_hooks,
                               std::string fault_log_path, bool fault_log_fixed)
    : fault_log_(std::move(fault_log_path)),
      fault_log_fixed_(fault_log_fixed),
      scene_path_(std::move(scene_path)),
      scene_(std::move(scene)),
      runner_(std::move(runner)),
      run_seconds_(run_seconds),
      test_hooks_(test_hooks),
      retry_timer_(io),
      status_timer_(io),
      stop_timer_(io),
      builder_(io, [this](const std::shared_ptr<SceneBuildJob>& job) { on_job_done(job); }),
      exit_code_(kExitOk) {}

bool SceneLifecycle::healthy(TimeNs max_age_ns) const {
  if (!built_.engine) return waiting_for_device_ || job_ != nullptr;
  return built_.engine->healthy(emission::monotonic_now_ns(), max_age_ns);
}

void SceneLifecycle::start(scene::ReusableTransports reuse) {
  if (job_) return;
  launch_start(seconds_ns(scene_.daemon.device_retry_initial_s), std::move(reuse));
}

void SceneLifecycle::stop(int exit_code) {
  if (stopping_) return;
  stopping_ = true;
  exit_code_ = exit_code;
  notify_stopping();
  retry_timer_.cancel();
  status_timer_.cancel();
  stop_timer_.cancel();
  if (petter_) petter_->stop();
  if (job_)
    log_notice(std::string("stopping while a scene is being ") +
               (job_->kind == SceneBuildJob::Kind::start ? "built" : "re-read") + " (" +
               seconds_text(emission::monotonic_now_ns() - job_->started_ns) + " so far): the build is abandoned");
  stop_engine();
  if (on_stopped_) on_stopped_();
}

void SceneLifecycle::reload() {
  if (stopping_) return;
  if (job_) {
    pending_reload_ = true;
    log_notice("SIGHUP during a scene build: the reload follows when the build ends");
    return;
  }
  notify_reloading();
  // A log rotation (rename, then SIGHUP): the fault log is opened again at
  // its path, a new file (issue 26 N14); a changed [daemon] fault_log is
  // taken when the new scene has been read (on_validated).
  if (const std::string log_path = fault_log_.path(); !log_path.empty()) fault_log_.reopen(log_path);
  auto job = std::make_shared<SceneBuildJob>();
  job->kind = SceneBuildJob::Kind::validate;
  job->scene_path = scene_path_;
  launch(std::move(job));
}

bool SceneLifecycle::join_builder(std::chrono::milliseconds limit) {
  if (!builder_.join(limit)) return false;
  job_.reset();  // an unused result closes its devices here (removes pty links)
  return true;
}

std::string SceneLifecycle::ready_text() const {
  std::string text = "scene " + scene_.name + ": ";
  for (std::size_t i = 0; i < built_.outputs.size(); ++i) text += (i ? "; " : "") + built_.outputs[i];
  return text;
}

void SceneLifecycle::launch_start(TimeNs next_retry_ns, scene::ReusableTransports reuse) {
  if (stopping_) return;
  auto job = std::make_shared<SceneBuildJob>();
  job->kind = SceneBuildJob::Kind::start;
  job->scene = scene_;
  job->runner = runner_;
  job->reuse = std::move(reuse);
  job->next_retry_ns = next_retry_ns;
  launch(std::move(job));
}

void SceneLifecycle::launch(std::shared_ptr<SceneBuildJob> job) {
  job_ = job;
  builder_.launch(std::move(job));
}

void SceneLifecycle::on_job_done(const std::shared_ptr<SceneBuildJob>& job) {
  if (job != job_) return;
  job_.reset();
  if (stopping_) return;  // the result (if any) is destroyed with the job: devices closed
  if (job->kind == SceneBuildJob::Kind::validate) on_validated(*job);
  else on_built(*job);
  if (pending_reload_ && !job_ && !stopping_) {
    pending_reload_ = false;
    reload();
  }
}

void SceneLifecycle::on_validated(SceneBuildJob& job) {
  if (job.error) {
    try {
      std::rethrow_exception(job.error);
    } catch (const std::exception& e) {
      log_err(std::string("reload failed, keeping the running scene: ") + e.what());
    } catch (...) {
      log_err("reload failed (unknown error), keeping the running scene");
    }
    if (built_.engine) notify_ready(ready_text());
    else if (!waiting_for_device_) start();  // nothing was running (the trajectory had ended): start it again
    return;
  }
  log_notice("reload: " + job.scene.name + " read and checked (" +
             seconds_text(emission::monotonic_now_ns() - job.started_ns) +
             "): restarting emission with it (ptys with the same link kept open, other devices reopened, "
             "new time base)");
  previous_scene_ = scene_;
  scene::ReusableTransports kept;
  stop_engine(&kept);  // its last fault events go to the log they belong to
  if (!fault_log_fixed_ && job.scene.daemon.fault_log != fault_log_.path()) {
    try {  // the outputs' collisions, as at the start (issue 26 N15)
      scene::check_start_paths(job.scene, runner_, "", scene::OutputPaths{job.scene.daemon.fault_log, ""});
    } catch (const std::exception& e) {
      log_err(std::string("reload: the new fault log is refused, keeping ") + fault_log_.path() + ": " + e.what());
      job.scene.daemon.fault_log = fault_log_.path();
    }
  }
  if (!fault_log_fixed_ && job.scene.daemon.fault_log != fault_log_.path()) {
    log_notice("reload: the fault log is now " +
               (job.scene.daemon.fault_log.empty() ? std::string("none") : job.scene.daemon.fault_log) + " (was " +
               (fault_log_.path().empty() ? std::string("none") : fault_log_.path()) + ")");
    fault_log_.reopen(job.scene.daemon.fault_log);
  }
  retry_timer_.cancel();
  waiting_for_device_ = false;
  scene_ = std::move(job.scene);
  // Only what the new scene opens again stays open (the rest is closed
  // before its devices are opened: a changed pty may reuse the link).
  std::set<std::string> wanted;
  for (const scene::ImuConfig& imu : scene_.imus) wanted.insert(scene::reuse_key(imu, runner_));
  for (auto it = kept.begin(); it != kept.end();) it = wanted.count(it->first) != 0 ? std::next(it) : kept.erase(it);
  start(std::move(kept));
}

void SceneLifecycle::on_built(SceneBuildJob& job) {
  // Transports the build did not take are closed now, before a retry or
  // the previous scene opens its devices again.
  job.reuse.clear();
  if (job.error) {
    try {
      std::rethrow_exception(job.error);
    } catch (const scene::DeviceOpenError& e) {
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

void SceneLifecycle::on_device_missing(const scene::DeviceOpenError& e, TimeNs next_retry_ns) {
  if (scene_.daemon.device_missing == scene::DeviceMissingPolicy::wait) {
    waiting_for_device_ = true;
    const std::string what = std::string(e.what()) + "; retrying in " +
                             std::to_string(static_cast<double>(next_retry_ns) / 1e9).substr(0, 5) + " s";
    notify_status("waiting for a device: " + what);
    log_warning(what);
    retry_timer_.expires_after(std::chrono::nanoseconds(next_retry_ns));
    retry_timer_.async_wait([this, next_retry_ns](const boost::system::error_code& ec) {
      if (ec) return;
      launch_start(std::min(2 * next_retry_ns, seconds_ns(scene_.daemon.device_retry_max_s)));
    });
    return;
  }
  start_failed(std::string(e.what()) + " ([daemon] device_missing = \"fail\")");
}

void SceneLifecycle::start_failed(const std::string& what) {
  if (previous_scene_) {
    log_err("reload: the new scene " + scene_.name + " did not start: " + what + "; starting the previous scene " +
            previous_scene_->name + " again");
    scene_ = std::move(*previous_scene_);
    previous_scene_.reset();
    start();
    return;
  }
  log_err(what);
  stop(kExitStartFailed);
}

void SceneLifecycle::running() {
  waiting_for_device_ = false;
  const emission::EngineStats s = built_.engine->stats();
  if (!s.realtime_note.empty()) log_warning(s.realtime_note + " (running without it; require_realtime = false)");
  if (s.realtime_priority) log_info("emission thread SCHED_FIFO priority " + std::to_string(scene_.daemon.realtime_priority));
  if (s.memory_locked) log_info("memory locked (mlockall)");
  notify_ready(ready_text());
  log_info("ready: " + ready_text() +
           (watchdog_ ? "; watchdog " + std::to_string(watchdog_->count() / 1000) + " ms" : "; no watchdog") +
           (test_hooks_ ? "; TEST HOOKS ENABLED" : ""));
  if (!started_once_) {
    started_once_ = true;
    if (run_seconds_) {
      stop_timer_.expires_after(std::chrono::nanoseconds(seconds_ns(*run_seconds_)));
      stop_timer_.async_wait([this](const boost::system::error_code& ec) {
        if (!ec) {
          log_info("--seconds reached");
          stop(kExitOk);
        }
      });
    }
  }
}

emission::EmissionEngine& SceneLifecycle::running_engine() {
  if (!built_.engine) throw std::runtime_error(job_ ? "the scene is being built; try again" : "no scene is running");
  return *built_.engine;
}

void SceneLifecycle::write_fault_events() {
  if (!built_.engine) return;
  fault_log_.write(built_.engine->take_fault_events());
}

void SceneLifecycle::stop_engine(scene::ReusableTransports* keep) {
  if (!built_.engine) return;
  if (keep != nullptr) built_.engine->stop_keeping_transports();
  else built_.engine->stop();
  write_fault_events();  // the last ones, the ends of the faults still active included
  final_stats_ = built_.engine->stats();
  log_info("emission stopped: " + summary_line(scene_.name, *final_stats_, true));
  if (keep != nullptr) {
    std::vector<std::unique_ptr<drivers::Transport>> transports = built_.engine->take_transports();
    for (std::size_t i = 0; i < transports.size() && i < scene_.imus.size(); ++i) {
      const std::string key = scene::reuse_key(scene_.imus[i], runner_);
      if (!key.empty() && transports[i]) (*keep)[key] = std::move(transports[i]);
    }
  }
  built_ = {};
}

void SceneLifecycle::start_service_timers() {
  if (petter_) petter_->start();
  report_.start(std::chrono::steady_clock::now());
  schedule_status();
}

void SceneLifecycle::schedule_status() {
  const auto period = std::chrono::nanoseconds(seconds_ns(std::max(scene_.daemon.status_interval_s, 0.1)));
  status_timer_.expires_after(std::min<std::chrono::nanoseconds>(period, std::chrono::milliseconds(500)));
  status_timer_.async_wait([this, period](const boost::system::error_code& ec) {
    if (ec || stopping_) return;
    on_status_tick(period);
    if (!stopping_) schedule_status();
  });
}

void SceneLifecycle::on_status_tick(std::chrono::nanoseconds status_period) {
  if (!built_.engine) return;
  write_fault_events();
  const emission::EngineStats s = built_.engine->stats();
  if (!s.fault.empty() || s.thread_faults > 0) {
    // An exception reached the top of an engine thread (caught there, both
    // threads stopped): the scene cannot go on; a failure exit lets
    // Restart=on-failure bring it back.
    log_err("emission failed: " + (s.fault.empty() ? std::string("a thread failed") : s.fault) +
            "; stopping the scene");
    stop(kExitEmissionFailed);
    return;
  }
  if (s.finished) {
    if (scene_.trajectory.loop) {
      log_notice("the looped trajectory ended: restarting the run (ptys kept open, other devices reopened, "
                 "new time base)");
      scene::ReusableTransports kept;
      stop_engine(&kept);
      start(std::move(kept));
    } else {
      log_notice(s.time_limit_ends > 0
                     ? "the stream reached the end of int64 nanosecond time (no later tick is representable): stopping"
                     : "the trajectory ended: stopping");
      stop(kExitOk);
    }
    return;
  }
  const auto now = std::chrono::steady_clock::now();
  report_.log_new_refusals(s, now);
  report_.log_falling_behind(s, now);
  const bool alive = built_.engine->healthy(emission::monotonic_now_ns(), kAliveWithinNs);
  report_.publish(scene_.name, s, alive, now, status_period);
}

nlohmann::json SceneLifecycle::status_json() const {
  DaemonStatus status;
  status.scene_name = scene_.name;
  status.scene_file = scene_.file;
  status.pid = ::getpid();
  status.uptime_ns = emission::monotonic_now_ns() - started_ns_;
  status.imus = scene_.imus.size();
  status.waiting_for_device = waiting_for_device_;
  status.fault_log_path = fault_log_.path();
  status.fault_log_output = fault_log_.counters();
  status.log_lines_lost = log_lines_lost();
  if (job_)
    status.building = DaemonStatus::Build{job_->kind == SceneBuildJob::Kind::start,
                                          emission::monotonic_now_ns() - job_->started_ns};
  if (built_.engine) {
    status.engine = built_.engine->stats();
    status.emitter_progressing = built_.engine->healthy(emission::monotonic_now_ns(), kAliveWithinNs);
  }
  if (petter_ && watchdog_)
    status.watchdog = DaemonStatus::Watchdog{*watchdog_, petter_->pets_sent(), petter_->pets_withheld()};
  return service::status_json(status);
}

}  // namespace imuemu::service
