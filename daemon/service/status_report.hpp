// What imuemud says about its health, and how often: the one-line summary
// (the STATUS= line `systemctl status` shows, and the log line: at info once
// a minute, at debug at every status interval), the rate-limited warning
// about poses the method refused, and the control socket's "status" reply
// (docs/daemon.md; `imuemu status --summary` explains its fields). Nothing
// here decides anything about the scene: daemon/service/scene_lifecycle.hpp
// gathers the numbers and calls these on the io thread.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/types.hpp"
#include "daemon/engine/emission.hpp"
#include "daemon/service/fault_log_writer.hpp"

namespace imuemu::service {

// "scene NAME: imu0 N samples[ (counters)]...; lateness p99 X us, max Y us
// [; input ...][; ... poses refused by the method][; EMITTER STALLED]":
// counters that are zero are left out. alive: the emission thread made
// progress recently.
std::string summary_line(const std::string& scene_name, const emission::EngineStats& stats, bool alive);

// The daemon's state as the control socket's "status" command reports it.
struct DaemonStatus {
  std::string scene_name, scene_file;
  std::size_t imus = 0;
  long pid = 0;
  TimeNs uptime_ns = 0;
  bool waiting_for_device = false;
  std::string fault_log_path;  // empty: no fault log
  std::optional<FaultLogCounters> fault_log_output;  // the fault log's writer (issue 26 N2/N3/N13)
  std::uint64_t log_lines_lost = 0;  // log lines stderr refused (EPIPE: its reader went away)
  struct Build {
    bool start = true;  // false: a reload's re-read
    TimeNs elapsed_ns = 0;
  };
  std::optional<Build> building;              // a scene build under way
  std::optional<emission::EngineStats> engine;  // the running engine's, if any
  bool emitter_progressing = false;
  struct Watchdog {
    std::chrono::microseconds interval{0};
    std::uint64_t pets_sent = 0, pets_withheld = 0;
  };
  std::optional<Watchdog> watchdog;  // systemd asked for one
};

// {"scene", "scene_file", "pid", "uptime_s", "imus", "waiting_for_device",
//  "fault_log", "fault_log_output", "log_lines_lost", "building", "samples_emitted", "emitter_progressing",
//  "engine", "watchdog"}; what is absent is null (samples_emitted 0).
nlohmann::json status_json(const DaemonStatus& status);

// The periodic reports of a running scene, at the status timer's ticks.
class StatusReport {
 public:
  using Clock = std::chrono::steady_clock;

  // The status timer starts: the first summary log line is due a minute on.
  void start(Clock::time_point now) { last_summary_ = now; }

  // Poses the method refused (counted by the engine, which never logs): a
  // warning with the newest reason, at most one per 10 s, so a stream whose
  // every pose is refused says why within a second and then stays quiet but
  // counted. A count lower than the last one is a new engine (restart, reload).
  void log_new_refusals(const emission::EngineStats& stats, Clock::time_point now);

  // A device that falls behind (underruns: the producer had nothing when the
  // tick was due; deadline misses: the emission thread woke more than a
  // period late) says so while it does (issue 26: only the exit summary did):
  // a warning naming the device and what it missed since the last one, at
  // most one per 10 s; quiet while nothing new is missed. Counts lower than
  // the last seen are a new engine.
  void log_falling_behind(const emission::EngineStats& stats, Clock::time_point now);

  // Once per status_period: STATUS=summary_line, logged at info once a
  // minute, at debug otherwise.
  void publish(const std::string& scene_name, const emission::EngineStats& stats, bool alive, Clock::time_point now,
               std::chrono::nanoseconds status_period);

 private:
  Clock::time_point last_status_{}, last_summary_{}, last_refusal_log_{};
  std::uint64_t refusals_logged_ = 0;  // of the running engine's poses_refused
  struct Behind {
    std::uint64_t underruns = 0, deadline_misses = 0;
  };
  std::vector<Behind> behind_logged_;  // per device, as of the last warning
  Clock::time_point last_behind_log_{};
  bool behind_logged_once_ = false;
};

}  // namespace imuemu::service
