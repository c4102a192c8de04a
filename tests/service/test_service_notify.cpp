// daemon/service_notify, log/log, daemon/service_signals: the sd_notify
// messages as a service manager receives them (a fake NOTIFY_SOCKET bound
// here, the protocol of sd_notify(3)), the watchdog petted only while the
// emitter beats, journald priority prefixes (sd-daemon(3)), rate limiting;
// daemon/service/status_report: the STATUS= line (docs/daemon.md
// "Lifecycle"), how often it is sent and logged, the refusal warnings and the
// "status" reply, at given instants (no host timing).
#include <gtest/gtest.h>

#include <poll.h>
#include <stdlib.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <boost/asio/executor_work_guard.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/post.hpp>

#include "log/log.hpp"
#include "drivers/queued_writer.hpp"
#include "io/pose_admission.hpp"
#include "tests/support/io_thread.hpp"
#include "daemon/service/service_notify.hpp"
#include "daemon/service/service_signals.hpp"
#include "daemon/service/status_report.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_service_test_service_notify {
namespace imuemu { using namespace ::imuemu; }

namespace svc = imuemu::service;
using imuemu::test::IoThread;
using namespace std::chrono_literals;

namespace {

// The service manager's end: a datagram socket at a temp path, NOTIFY_SOCKET
// pointing at it while the fixture lives.
class FakeNotifySocket {
 public:
  FakeNotifySocket() {
    char dir_template[] = "/tmp/imuemu_notify_XXXXXX";
    dir_ = ::mkdtemp(dir_template);
    path_ = dir_ + "/notify";
    fd_ = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    sockaddr_un address{};
    address.sun_family = AF_UNIX;
    std::strncpy(address.sun_path, path_.c_str(), sizeof address.sun_path - 1);
    if (::bind(fd_, reinterpret_cast<sockaddr*>(&address), sizeof address) != 0) throw std::runtime_error("bind");
    ::setenv("NOTIFY_SOCKET", path_.c_str(), 1);
  }
  ~FakeNotifySocket() {
    ::unsetenv("NOTIFY_SOCKET");
    ::close(fd_);
    std::filesystem::remove_all(dir_);
  }
  // Next datagram within `timeout`, or nullopt.
  std::optional<std::string> receive(std::chrono::milliseconds timeout) {
    pollfd p{fd_, POLLIN, 0};
    if (::poll(&p, 1, static_cast<int>(timeout.count())) != 1) return std::nullopt;
    char buffer[4096];
    const ssize_t n = ::recv(fd_, buffer, sizeof buffer, 0);
    if (n < 0) return std::nullopt;
    return std::string(buffer, static_cast<std::size_t>(n));
  }
  // Every datagram arriving within `window`.
  std::vector<std::string> collect(std::chrono::milliseconds window) {
    std::vector<std::string> got;
    const auto end = std::chrono::steady_clock::now() + window;
    while (true) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(end - std::chrono::steady_clock::now());
      if (left.count() <= 0) break;
      if (auto m = receive(left)) got.push_back(*m);
    }
    return got;
  }

 private:
  std::string dir_, path_;
  int fd_ = -1;
};


// Stderr captured through a pipe while alive.
class StderrCapture {
 public:
  StderrCapture() {
    if (::pipe(pipe_) != 0) throw std::runtime_error("pipe");
    saved_ = ::dup(STDERR_FILENO);
    ::dup2(pipe_[1], STDERR_FILENO);
  }
  std::string finish() {
    ::dup2(saved_, STDERR_FILENO);
    ::close(saved_);
    ::close(pipe_[1]);
    std::string out;
    char buffer[4096];
    ssize_t n;
    while ((n = ::read(pipe_[0], buffer, sizeof buffer)) > 0) out.append(buffer, static_cast<std::size_t>(n));
    ::close(pipe_[0]);
    return out;
  }

 private:
  int pipe_[2]{};
  int saved_ = -1;
};

}  // namespace

TEST(ServiceNotify, NoOpWithoutNotifySocket) {
  ::unsetenv("NOTIFY_SOCKET");
  EXPECT_EQ(svc::notify_ready("running"), svc::NotifyOutcome::not_under_systemd);
  EXPECT_EQ(svc::notify_watchdog(), svc::NotifyOutcome::not_under_systemd);
  EXPECT_EQ(svc::notify_stopping(), svc::NotifyOutcome::not_under_systemd);
}

TEST(ServiceNotify, ExactMessagesOnTheNotifySocket) {
  FakeNotifySocket manager;
  EXPECT_EQ(svc::notify_ready("scene car-urban: 2 IMUs at 400 Hz"), svc::NotifyOutcome::sent);
  EXPECT_EQ(manager.receive(1s), "READY=1\nSTATUS=scene car-urban: 2 IMUs at 400 Hz");
  svc::notify_status("line one\nline two");
  EXPECT_EQ(manager.receive(1s), "STATUS=line one line two");  // a newline would end the assignment
  svc::notify_reloading();
  EXPECT_EQ(manager.receive(1s), "RELOADING=1");
  svc::notify_stopping();
  EXPECT_EQ(manager.receive(1s), "STOPPING=1");
  svc::notify_watchdog();
  EXPECT_EQ(manager.receive(1s), "WATCHDOG=1");
  EXPECT_EQ(manager.receive(50ms), std::nullopt);
}

TEST(ServiceNotify, FailureIsReportedNotThrown) {
  ::setenv("NOTIFY_SOCKET", "/nonexistent-imuemu-dir/notify", 1);
  EXPECT_EQ(svc::notify_watchdog(), svc::NotifyOutcome::failed);
  ::unsetenv("NOTIFY_SOCKET");
}

TEST(ServiceNotify, WatchdogIntervalFromEnvironment) {
  ::unsetenv("WATCHDOG_USEC");
  ::unsetenv("WATCHDOG_PID");
  EXPECT_EQ(svc::watchdog_interval(), std::nullopt);
  ::setenv("WATCHDOG_USEC", "2500000", 1);
  EXPECT_EQ(svc::watchdog_interval(), std::chrono::microseconds(2'500'000));
  ::setenv("WATCHDOG_PID", std::to_string(::getpid()).c_str(), 1);
  EXPECT_EQ(svc::watchdog_interval(), std::chrono::microseconds(2'500'000));
  // Meant for another process (a child that inherited the environment).
  ::setenv("WATCHDOG_PID", std::to_string(::getpid() + 1).c_str(), 1);
  EXPECT_EQ(svc::watchdog_interval(), std::nullopt);
  ::unsetenv("WATCHDOG_USEC");
  ::unsetenv("WATCHDOG_PID");
}

TEST(EmissionHeartbeat, AliveOnlyWithinTheAge) {
  svc::EmissionHeartbeat heartbeat;
  EXPECT_FALSE(heartbeat.alive_within(1'000'000'000, 5));  // never beaten
  EXPECT_EQ(heartbeat.last_beat_ns(), std::nullopt);
  heartbeat.beat(100);
  EXPECT_TRUE(heartbeat.alive_within(50, 150));
  EXPECT_FALSE(heartbeat.alive_within(50, 151));
  EXPECT_EQ(heartbeat.last_beat_ns(), 100);
}

TEST(WatchdogPetter, PetsOnlyWhileTheEmitterBeats) {
  FakeNotifySocket manager;
  svc::EmissionHeartbeat heartbeat;
  std::atomic<bool> emitter_running{true};
  std::thread emitter([&] {
    while (emitter_running) {
      heartbeat.beat();
      std::this_thread::sleep_for(2ms);
    }
  });
  constexpr auto kInterval = 120ms;  // WatchdogSec; pets every 60 ms
  constexpr std::int64_t kMaxAge_ns = 60'000'000;
  IoThread io;
  std::optional<svc::WatchdogPetter> petter;
  io.run([&] {
    petter.emplace(io.io, std::chrono::duration_cast<std::chrono::microseconds>(kInterval),
                   [&] { return heartbeat.alive_within(kMaxAge_ns); });
    petter->start();
  });
  EXPECT_EQ(petter->pet_period(), 60ms);

  // Healthy: about 600 / 60 = 10 pets, nothing else.
  const auto healthy = manager.collect(600ms);
  EXPECT_GE(healthy.size(), 6u);
  EXPECT_LE(healthy.size(), 11u);
  for (const auto& m : healthy) EXPECT_EQ(m, "WATCHDOG=1");

  // Stall the emitter: after the beats age out (60 ms) and a pet that may be
  // in flight, not one more pet.
  emitter_running = false;
  emitter.join();
  manager.collect(150ms);
  const std::uint64_t withheld_before = petter->pets_withheld();
  EXPECT_TRUE(manager.collect(500ms).empty());
  EXPECT_GE(petter->pets_withheld(), withheld_before + 6);

  // Progress again: pets resume.
  emitter_running = true;
  std::thread emitter2([&] {
    while (emitter_running) {
      heartbeat.beat();
      std::this_thread::sleep_for(2ms);
    }
  });
  EXPECT_EQ(manager.receive(500ms), "WATCHDOG=1");
  emitter_running = false;
  emitter2.join();
  io.run([&] { petter.reset(); });
}

TEST(WatchdogPetter, RejectsNonsense) {
  boost::asio::io_context io;
  EXPECT_THROW(svc::WatchdogPetter(io, std::chrono::microseconds(1), [] { return true; }), std::invalid_argument);
  EXPECT_THROW(svc::WatchdogPetter(io, std::chrono::microseconds(1000), nullptr), std::invalid_argument);
}

TEST(ServiceLog, SyslogPriorityPrefixes) {
  // RFC 5424 severities: err 3, warning 4, notice 5, info 6, debug 7.
  EXPECT_EQ(svc::format_log_line(svc::LogLevel::err, "device lost"), "<3>device lost\n");
  EXPECT_EQ(svc::format_log_line(svc::LogLevel::warning, "w"), "<4>w\n");
  EXPECT_EQ(svc::format_log_line(svc::LogLevel::notice, "n"), "<5>n\n");
  EXPECT_EQ(svc::format_log_line(svc::LogLevel::info, "i"), "<6>i\n");
  EXPECT_EQ(svc::format_log_line(svc::LogLevel::debug, "d"), "<7>d\n");
  EXPECT_EQ(svc::format_log_line(svc::LogLevel::info, "a\nb\r"), "<6>a b \n");
}

TEST(ServiceLog, WritesToStderrAboveThreshold) {
  const svc::LogLevel saved = svc::log_threshold();
  svc::set_log_threshold(svc::LogLevel::info);
  StderrCapture capture;
  svc::log_err("e1");
  svc::log_debug("dropped");
  svc::log_info("i1");
  svc::set_log_threshold(svc::LogLevel::debug);
  svc::log_debug("d1");
  const std::string out = capture.finish();
  svc::set_log_threshold(saved);
  EXPECT_EQ(out, "<3>e1\n<6>i1\n<7>d1\n");
}

// Issue 13: two stderr fallbacks (a transport's log with no sink, a pose
// source's with no sink) wrote bare lines, without the sd-daemon <N> prefix
// every other daemon line has: journald filed them without a level. Both are
// now the project's log lines (warning), newlines flattened.
TEST(ServiceLog, TransportAndPoseSourceFallbacksCarryThePriorityPrefix) {
  const svc::LogLevel saved = svc::log_threshold();
  svc::set_log_threshold(svc::LogLevel::info);
  StderrCapture capture;
  imuemu::drivers::emit_log({}, "pty /tmp/x: reader gone");
  imuemu::io::RateLimitedLog pose_log({}, 1'000'000'000);
  pose_log.log("bad_crc", "udp 127.0.0.1:5005: dropped datagram (bad_crc):\nfrom 127.0.0.1", 0);
  const std::string out = capture.finish();
  svc::set_log_threshold(saved);
  EXPECT_EQ(out, "<4>imuemu: pty /tmp/x: reader gone\n"
                 "<4>udp 127.0.0.1:5005: dropped datagram (bad_crc): from 127.0.0.1\n");
}

TEST(RateLimiter, BurstThenSuppressedCountReported) {
  svc::RateLimiter limiter(1'000'000'000, 3);  // 3 lines per second
  int emitted = 0;
  for (int i = 0; i < 10; ++i) emitted += limiter.check(i * 10'000'000).emit ? 1 : 0;
  EXPECT_EQ(emitted, 3);
  const auto next_window = limiter.check(1'000'000'000);
  EXPECT_TRUE(next_window.emit);
  EXPECT_EQ(next_window.suppressed_before, 7u);
  EXPECT_EQ(limiter.check(1'000'000'001).suppressed_before, 0u);

  StderrCapture capture;
  svc::RateLimiter once(1'000'000'000, 1);
  once.log(svc::LogLevel::warning, "bad datagram", 0);
  once.log(svc::LogLevel::warning, "bad datagram", 1);
  once.log(svc::LogLevel::warning, "bad datagram", 2);
  once.log(svc::LogLevel::warning, "bad datagram", 1'000'000'000);
  EXPECT_EQ(capture.finish(), "<4>bad datagram\n<4>bad datagram (2 similar messages suppressed)\n");
}

TEST(ServiceSignals, TermStopsOnceHupReloads) {
  IoThread io;
  std::atomic<int> stops{0}, reloads{0}, stop_signal{0};
  std::optional<svc::ServiceSignals> signals;
  io.run([&] {
    signals.emplace(io.io, [&](int s) { stop_signal = s; ++stops; }, [&] { ++reloads; });
  });
  StderrCapture quiet;  // the handlers log
  ::kill(::getpid(), SIGHUP);
  ::kill(::getpid(), SIGHUP);
  for (int i = 0; i < 200 && reloads < 2; ++i) std::this_thread::sleep_for(5ms);
  ::kill(::getpid(), SIGTERM);
  for (int i = 0; i < 200 && stops < 1; ++i) std::this_thread::sleep_for(5ms);
  ::kill(::getpid(), SIGTERM);  // while stopping: ignored
  ::kill(::getpid(), SIGHUP);   // while stopping: ignored
  std::this_thread::sleep_for(100ms);
  const std::string log = quiet.finish();
  io.run([&] { signals.reset(); });
  EXPECT_EQ(reloads.load(), 2);
  EXPECT_EQ(stops.load(), 1);
  EXPECT_EQ(stop_signal.load(), SIGTERM);
  EXPECT_NE(log.find("<6>SIGTERM: stopping"), std::string::npos) << log;
}

namespace {

// Two devices as docs/daemon.md's STATUS= line names them: imu0 with nothing
// to report beyond its samples, imu1 with every counter the line can carry.
imuemu::emission::EngineStats busy_engine() {
  imuemu::emission::EngineStats s;
  s.devices.resize(2);
  s.devices[0].name = "imu0";
  s.devices[0].emitted = 1000;
  auto& d = s.devices[1];
  d.name = "imu1";
  d.emitted = 400;
  d.extrapolated = 3;
  d.blending = 2;
  d.producer_late = 4;
  d.deadline_misses = 5;
  d.write_errors = 6;
  d.dropped_link_down = 9;
  d.transport.dropped_link_down = 9;
  d.faults.active = 2;
  d.faults.silenced = 7;
  s.lateness.p99_ns = 12'999;    // microseconds, truncated
  s.lateness.max_ns = 345'000;
  s.pose_source.emplace();
  s.pose_source->accepted = 50;
  s.pose_source->lost = 2;
  s.pose_source->rejected = 1;
  s.poses_refused = 8;
  s.emitted = 1400;
  return s;
}

}  // namespace

TEST(StatusReport, SummaryLineNamesEveryNonZeroCounter) {
  EXPECT_EQ(svc::summary_line("bench", busy_engine(), false),
            "scene bench: imu0 1000 samples; imu1 400 samples (3 extrapolated, 2 blending), 4 underruns, 5 late, "
            "6 not written, 9 dropped (no reader/link down), 2 faults acting, 7 silenced by faults; "
            "lateness p99 12 us, max 345 us; input 50 poses, 2 lost, 1 rejected; 8 poses refused by the method; "
            "EMITTER STALLED");
  imuemu::emission::EngineStats quiet;
  quiet.devices.resize(1);
  quiet.devices[0].name = "imu0";
  quiet.devices[0].emitted = 7;
  quiet.devices[0].faults.active = 1;
  quiet.pose_source.emplace();  // live input, nothing arrived yet
  EXPECT_EQ(svc::summary_line("car", quiet, true),
            "scene car: imu0 7 samples, 1 fault acting; lateness p99 0 us, max 0 us; input 0 poses "
            "(waiting for the first pose)");
}

TEST(StatusReport, StatusLineOncePerIntervalLoggedAtInfoOnceAMinute) {
  using Clock = svc::StatusReport::Clock;
  const Clock::time_point t0 = Clock::time_point{} + std::chrono::hours(1);
  imuemu::emission::EngineStats s;
  s.devices.resize(1);
  s.devices[0].name = "imu0";
  FakeNotifySocket manager;
  const svc::LogLevel saved = svc::log_threshold();
  svc::set_log_threshold(svc::LogLevel::debug);
  StderrCapture capture;
  svc::StatusReport report;
  report.start(t0);
  const auto publish = [&](std::uint64_t emitted, Clock::duration at) {
    s.devices[0].emitted = emitted;
    report.publish("bench", s, true, t0 + at, 1s);
  };
  publish(1, 0s);        // the first tick: sent, logged at debug (the minute has not passed)
  publish(2, 500ms);     // within the interval: nothing
  publish(3, 1s);        // sent, debug
  publish(4, 60s);       // sent, info: a minute since the start
  publish(5, 61s);       // sent, debug: a minute since the last info line
  publish(6, 120s);      // sent, info
  const std::string log = capture.finish();
  svc::set_log_threshold(saved);
  const std::string line = "scene bench: imu0 N samples; lateness p99 0 us, max 0 us";
  const auto with = [&](const char* n) { return std::string(line).replace(line.find('N'), 1, n); };
  EXPECT_EQ(manager.collect(200ms), (std::vector<std::string>{"STATUS=" + with("1"), "STATUS=" + with("3"),
                                                              "STATUS=" + with("4"), "STATUS=" + with("5"),
                                                              "STATUS=" + with("6")}));
  EXPECT_EQ(log, "<7>" + with("1") + "\n<7>" + with("3") + "\n<6>" + with("4") + "\n<7>" + with("5") + "\n<6>" +
                     with("6") + "\n");
}

TEST(StatusReport, RefusalsWarnedAtMostEveryTenSecondsAndAgainForANewEngine) {
  using Clock = svc::StatusReport::Clock;
  const Clock::time_point t0 = Clock::time_point{} + std::chrono::hours(1);
  imuemu::emission::EngineStats s;
  const svc::LogLevel saved = svc::log_threshold();
  svc::set_log_threshold(svc::LogLevel::info);
  StderrCapture capture;
  svc::StatusReport report;
  report.start(t0);
  report.log_new_refusals(s, t0);  // none: nothing
  s.poses_refused = 3;
  s.last_pose_refusal = "time went back";
  report.log_new_refusals(s, t0 + 1s);  // the first ones: at once
  s.poses_refused = 5;
  report.log_new_refusals(s, t0 + 10s);  // 9 s later: counted, quiet
  report.log_new_refusals(s, t0 + 11s);  // 10 s later: the 2 new ones
  report.log_new_refusals(s, t0 + 30s);  // nothing new: quiet
  s.poses_refused = 1;                   // a new engine (reload, loop restart): at once
  s.last_pose_refusal.clear();
  report.log_new_refusals(s, t0 + 31s);
  const std::string log = capture.finish();
  svc::set_log_threshold(saved);
  EXPECT_EQ(log,
            "<4>3 poses refused by the method (3 in all); the newest: time went back\n"
            "<4>2 poses refused by the method (5 in all); the newest: time went back\n"
            "<4>1 poses refused by the method (1 in all); the newest: no reason recorded\n");
}

// Issue 26: a device that falls behind says so while it does (only the
// exit summary did): a warning at most every 10 s with what it missed since
// the last one; quiet while nothing new is missed; again for a new engine.
TEST(StatusReport, ADeviceFallingBehindIsWarnedWhileItDoesAtMostEveryTenSeconds) {
  using Clock = svc::StatusReport::Clock;
  const Clock::time_point t0 = Clock::time_point{} + std::chrono::hours(1);
  imuemu::emission::EngineStats s;
  s.devices.resize(2);
  s.devices[0].name = "imu0";
  s.devices[1].name = "imu1";
  const svc::LogLevel saved = svc::log_threshold();
  svc::set_log_threshold(svc::LogLevel::info);
  StderrCapture capture;
  svc::StatusReport report;
  report.start(t0);
  report.log_falling_behind(s, t0);  // on time: nothing
  s.devices[1].producer_late = 4;
  s.devices[1].deadline_misses = 1;
  report.log_falling_behind(s, t0 + 1s);  // at once
  s.devices[1].producer_late = 9;
  report.log_falling_behind(s, t0 + 5s);   // within 10 s: counted, quiet
  report.log_falling_behind(s, t0 + 11s);  // the 5 new ones
  report.log_falling_behind(s, t0 + 30s);  // caught up: quiet
  s.devices[1].producer_late = 2;          // a new engine
  s.devices[1].deadline_misses = 0;
  report.log_falling_behind(s, t0 + 41s);
  const std::string log = capture.finish();
  svc::set_log_threshold(saved);
  EXPECT_EQ(log,
            "<4>imu1 is falling behind: 4 underruns (no sample ready when due) and 1 deadline misses (woken more than a "
            "period late) since the last report (4 and 1 in all)\n"
            "<4>imu1 is falling behind: 5 underruns (no sample ready when due) and 0 deadline misses (woken more than a "
            "period late) since the last report (9 and 1 in all)\n"
            "<4>imu1 is falling behind: 2 underruns (no sample ready when due) and 0 deadline misses (woken more than a "
            "period late) since the last report (2 and 0 in all)\n");
}

TEST(StatusReport, StatusReplyNullsWhatIsAbsent) {
  svc::DaemonStatus idle;
  idle.scene_name = "bench";
  idle.scene_file = "/etc/imuemu/bench.toml";
  idle.imus = 2;
  idle.pid = 42;
  idle.uptime_ns = 2'500'000'000;
  idle.waiting_for_device = true;
  idle.building = svc::DaemonStatus::Build{false, 250'000'000};
  idle.watchdog = svc::DaemonStatus::Watchdog{std::chrono::microseconds(3'000'000), 7, 1};
  EXPECT_EQ(svc::status_json(idle), nlohmann::json::parse(R"({
      "scene": "bench", "scene_file": "/etc/imuemu/bench.toml", "pid": 42, "uptime_s": 2.5, "imus": 2,
      "waiting_for_device": true, "fault_log": null, "fault_log_output": null, "log_lines_lost": 0,
      "building": {"what": "reload", "elapsed_s": 0.25},
      "samples_emitted": 0, "emitter_progressing": false, "engine": null,
      "watchdog": {"interval_s": 3.0, "pets_sent": 7, "pets_withheld": 1}})"));

  svc::DaemonStatus running;
  running.scene_name = "bench";
  running.fault_log_path = "/var/log/imuemu/faults.jsonl";
  running.engine = busy_engine();
  running.emitter_progressing = true;
  const nlohmann::json status = svc::status_json(running);
  EXPECT_EQ(status["fault_log"], "/var/log/imuemu/faults.jsonl");
  EXPECT_EQ(status["building"], nullptr);
  EXPECT_EQ(status["watchdog"], nullptr);
  EXPECT_EQ(status["samples_emitted"], 1400u);  // the engine's total
  EXPECT_EQ(status["emitter_progressing"], true);
  EXPECT_EQ(status["engine"]["poses_refused"], 8u);
  EXPECT_EQ(status["engine"]["devices"][1]["name"], "imu1");
}
}  // namespace unity_service_test_service_notify
