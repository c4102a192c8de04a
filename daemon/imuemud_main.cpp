// imuemud: FIRST, PLACEHOLDER version (written with the service plumbing,
// issue 6) so the systemd unit and the user-mode-Linux systemd test run a real
// binary. It does the service side for real — scene file, sd_notify
// READY/STATUS/STOPPING/RELOADING, the watchdog petted only while the
// emission thread progresses, the control socket, SIGTERM/SIGINT/SIGHUP,
// SCHED_FIFO and mlockall as the scene asks — but its emission thread only
// ticks at the first device's rate and counts: no poses, no encoders, no
// transports. The emission engine (daemon/emission.*) replaces
// PlaceholderEmitter; everything around it stays.
//
//   imuemud --scene /etc/imuemu/NAME.toml [--control-socket PATH] [--log-level L]
//
// Test hook: with IMUEMU_TEST_HOOKS=1 in the environment the control socket
// also offers "stall-emitter" (the emission thread stops making progress
// while staying alive), which tests/hil/uml_systemd_run.sh uses to prove the
// watchdog restarts a stalled daemon. Never set in the shipped unit.
#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <optional>
#include <string>
#include <thread>

#include <CLI/CLI.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/steady_timer.hpp>
#include <nlohmann/json.hpp>

#include "daemon/control_socket.hpp"
#include "daemon/log.hpp"
#include "daemon/scene_config.hpp"
#include "daemon/service_notify.hpp"
#include "daemon/service_signals.hpp"

namespace {

namespace svc = imuemu::service;
using imuemu::TimeNs;
using imuemu::kNsPerSecond;

// Exit codes for systemd: 0 clean stop; anything else is a failure that
// Restart=on-failure acts on (a scene that does not parse fails every time
// and ends in the unit's start limit, visibly).
constexpr int kExitOk = 0;
constexpr int kExitStartFailed = 1;
constexpr int kExitUsage = 2;
constexpr int kExitBadScene = 3;

TimeNs monotonic_now_ns() {
  timespec ts{};
  ::clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<TimeNs>(ts.tv_sec) * kNsPerSecond + ts.tv_nsec;
}

// Stands in for the emission engine: one thread ticking on an absolute
// CLOCK_MONOTONIC grid, one heartbeat per tick.
class PlaceholderEmitter {
 public:
  PlaceholderEmitter(std::int64_t rate_hz, int realtime_priority, svc::EmissionHeartbeat& heartbeat)
      : period_ns_(kNsPerSecond / std::max<std::int64_t>(rate_hz, 1)), priority_(realtime_priority), heartbeat_(heartbeat) {}
  ~PlaceholderEmitter() { stop(); }

  // Throws std::runtime_error when the real-time priority cannot be had.
  void start() {
    running_ = true;
    std::atomic<int> started{0};  // 1 ok, -errno on failure
    thread_ = std::thread([this, &started] {
      if (priority_ > 0) {
        sched_param param{};
        param.sched_priority = priority_;
        const int r = ::pthread_setschedparam(::pthread_self(), SCHED_FIFO, &param);
        if (r != 0) {
          started = -r;
          return;
        }
      }
      started = 1;
      run();
    });
    while (started == 0) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    if (started < 0) {
      thread_.join();
      running_ = false;
      throw std::runtime_error("SCHED_FIFO priority " + std::to_string(priority_) +
                               " for the emission thread: " + std::strerror(-started.load()) +
                               " (needs CAP_SYS_NICE or LimitRTPRIO)");
    }
  }
  void stop() {
    running_ = false;
    if (thread_.joinable()) thread_.join();
  }
  void stall() { stalled_ = true; }  // test hook
  std::uint64_t ticks() const { return ticks_.load(); }
  void reset_counters() { ticks_ = 0; }
  bool stalled() const { return stalled_; }

 private:
  void run() {
    TimeNs next_ns = monotonic_now_ns();
    while (running_) {
      next_ns += period_ns_;
      const timespec until{static_cast<time_t>(next_ns / kNsPerSecond), static_cast<long>(next_ns % kNsPerSecond)};
      ::clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &until, nullptr);
      if (stalled_) continue;  // alive but no progress: what a blocked device write looks like
      ticks_.fetch_add(1, std::memory_order_relaxed);
      heartbeat_.beat();
      const TimeNs now_ns = monotonic_now_ns();
      if (now_ns - next_ns > kNsPerSecond) next_ns = now_ns;  // suspended or starved: resume the grid from now
    }
  }

  TimeNs period_ns_;
  int priority_;
  svc::EmissionHeartbeat& heartbeat_;
  std::thread thread_;
  std::atomic<bool> running_{false};
  std::atomic<bool> stalled_{false};
  std::atomic<std::uint64_t> ticks_{0};
};

struct Running {
  imuemu::scene::SceneConfig scene;
  std::unique_ptr<PlaceholderEmitter> emitter;
};

std::int64_t first_rate_hz(const imuemu::scene::SceneConfig& scene) {
  return scene.imus.empty() ? 100 : scene.imus.front().rate_hz;
}

std::string ready_text(const imuemu::scene::SceneConfig& scene) {
  return "scene " + scene.name + ": " + std::to_string(scene.imus.size()) + " IMU(s), placeholder emitter at " +
         std::to_string(first_rate_hz(scene)) + " Hz";
}

void apply_memory_lock(const imuemu::scene::SceneConfig& scene) {
  if (!scene.daemon.lock_memory) return;
  if (::mlockall(MCL_CURRENT | MCL_FUTURE) == 0) {
    svc::log_info("memory locked (mlockall)");
    return;
  }
  const std::string what = std::string("mlockall: ") + std::strerror(errno) + " (needs CAP_IPC_LOCK or LimitMEMLOCK)";
  if (scene.daemon.require_realtime) throw std::runtime_error(what);
  svc::log_warning(what + "; continuing without (require_realtime = false)");
}

std::unique_ptr<PlaceholderEmitter> start_emitter(const imuemu::scene::SceneConfig& scene, svc::EmissionHeartbeat& heartbeat) {
  auto emitter = std::make_unique<PlaceholderEmitter>(first_rate_hz(scene), scene.daemon.realtime_priority, heartbeat);
  try {
    emitter->start();
  } catch (const std::exception& e) {
    if (scene.daemon.require_realtime) throw;
    svc::log_warning(std::string(e.what()) + "; running with normal scheduling (require_realtime = false)");
    emitter = std::make_unique<PlaceholderEmitter>(first_rate_hz(scene), 0, heartbeat);
    emitter->start();
  }
  return emitter;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"imuemud: the imuemu IMU emulator service (PLACEHOLDER emitter; see daemon/imuemud_main.cpp)"};
  std::string scene_path, socket_override, log_level = "info";
  app.add_option("--scene", scene_path, "Scene file (docs/scene-format.md)")->required();
  app.add_option("--control-socket", socket_override, "Control socket path (default: the scene's [daemon] control_socket)");
  app.add_option("--log-level", log_level, "err, warning, notice, info, debug")->capture_default_str()
      ->check(CLI::IsMember({"err", "warning", "notice", "info", "debug"}));
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? kExitOk : kExitUsage;
  }
  const std::map<std::string, svc::LogLevel> levels{{"err", svc::LogLevel::err}, {"warning", svc::LogLevel::warning},
      {"notice", svc::LogLevel::notice}, {"info", svc::LogLevel::info}, {"debug", svc::LogLevel::debug}};
  svc::set_log_threshold(levels.at(log_level));

  Running running;
  try {
    running.scene = imuemu::scene::parse_scene_file(scene_path);
  } catch (const std::exception& e) {
    svc::log_err(e.what());
    return kExitBadScene;
  }
  const bool test_hooks = [] {
    const char* v = std::getenv("IMUEMU_TEST_HOOKS");
    return v != nullptr && std::string(v) == "1";
  }();

  boost::asio::io_context io;
  svc::EmissionHeartbeat heartbeat;
  const TimeNs started_ns = monotonic_now_ns();
  try {
    apply_memory_lock(running.scene);
    const std::string socket_path = !socket_override.empty() ? socket_override
                                    : !running.scene.daemon.control_socket.empty()
                                        ? running.scene.daemon.control_socket
                                        : svc::default_control_socket_path(running.scene.name);
    svc::ControlServer control(io, {socket_path, running.scene.daemon.control_group, std::chrono::seconds(2)});

    std::optional<svc::WatchdogPetter> petter;
    const std::optional<std::chrono::microseconds> watchdog = running.scene.daemon.watchdog ? svc::watchdog_interval() : std::nullopt;
    if (watchdog) {
      // Healthy = a sample went out within half the watchdog interval: a
      // stall is noticed at the next pet and costs at most WatchdogSec.
      const TimeNs max_age_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(*watchdog / 2).count();
      petter.emplace(io, *watchdog, [&heartbeat, max_age_ns] { return heartbeat.alive_within(max_age_ns); });
    }

    control.add_command("status", "scene, counters, watchdog", [&] {
      nlohmann::json status{
          {"scene", running.scene.name},
          {"scene_file", running.scene.file},
          {"pid", ::getpid()},
          {"uptime_s", static_cast<double>(monotonic_now_ns() - started_ns) / 1e9},
          {"placeholder_emitter", true},
          {"samples_emitted", running.emitter ? running.emitter->ticks() : 0},
          {"emitter_rate_hz", first_rate_hz(running.scene)},
          {"emitter_progressing", heartbeat.alive_within(kNsPerSecond)},
          {"imus", running.scene.imus.size()},
      };
      if (petter) {
        status["watchdog"] = {{"interval_s", static_cast<double>(watchdog->count()) / 1e6},
                              {"pets_sent", petter->pets_sent()},
                              {"pets_withheld", petter->pets_withheld()}};
      } else {
        status["watchdog"] = nullptr;
      }
      return status;
    });
    control.add_command("stats-reset", "zero the counters", [&] {
      if (running.emitter) running.emitter->reset_counters();
      return nlohmann::json{{"reset", true}};
    });
    if (test_hooks) {
      control.add_command("stall-emitter", "TEST HOOK: the emission thread stops progressing (watchdog test)", [&] {
        svc::log_warning("test hook: emitter stalled on request");
        if (running.emitter) running.emitter->stall();
        return nlohmann::json{{"stalled", true}};
      });
    }

    boost::asio::steady_timer status_timer(io);
    const auto status_period = std::chrono::nanoseconds(
        static_cast<std::int64_t>(std::llround(std::max(running.scene.daemon.status_interval_s, 0.1) * 1e9)));
    std::function<void()> schedule_status = [&] {
      status_timer.expires_after(status_period);
      status_timer.async_wait([&](const boost::system::error_code& ec) {
        if (ec) return;
        const std::string line = "scene " + running.scene.name + ": " +
                                 std::to_string(running.emitter ? running.emitter->ticks() : 0) + " samples" +
                                 (heartbeat.alive_within(kNsPerSecond) ? "" : ", EMITTER STALLED");
        svc::notify_status(line);
        svc::log_debug(line);
        schedule_status();
      });
    };

    svc::ServiceSignals signals(
        io,
        [&](int) {
          svc::notify_stopping();
          if (petter) petter->stop();
          status_timer.cancel();
          if (running.emitter) running.emitter->stop();
          control.close();
          io.stop();
        },
        [&] {
          svc::notify_reloading();
          try {
            imuemu::scene::SceneConfig next = imuemu::scene::parse_scene_file(scene_path);
            running.emitter.reset();  // joins
            running.scene = std::move(next);
            running.emitter = start_emitter(running.scene, heartbeat);
            svc::log_info("reloaded: " + ready_text(running.scene));
          } catch (const std::exception& e) {
            svc::log_err(std::string("reload failed, keeping the running scene: ") + e.what());
            if (!running.emitter) running.emitter = start_emitter(running.scene, heartbeat);
          }
          svc::notify_ready(ready_text(running.scene));
        });

    running.emitter = start_emitter(running.scene, heartbeat);
    if (petter) petter->start();
    schedule_status();
    svc::notify_ready(ready_text(running.scene));
    svc::log_info("ready: " + ready_text(running.scene) + "; control socket " + control.path() +
                  (watchdog ? "; watchdog " + std::to_string(watchdog->count() / 1000) + " ms" : "; no watchdog") +
                  (test_hooks ? "; TEST HOOKS ENABLED" : ""));
    io.run();
    running.emitter.reset();
  } catch (const std::exception& e) {
    svc::log_err(e.what());
    return kExitStartFailed;
  }
  svc::log_info("stopped");
  return kExitOk;
}
