// imuemud's side of the systemd service manager protocol (sd_notify(3),
// sd_watchdog_enabled(3); unit imuemud@.service is Type=notify with
// WatchdogSec=). Every call is a no-op returning not_under_systemd when
// NOTIFY_SOCKET is unset (run from a shell, from a test).
//
// The watchdog is petted only while the emission thread is making progress:
// a stalled emitter (blocked device write, deadlock, a lost real-time
// thread) stops the pets, systemd kills the service after WatchdogSec and
// Restart=on-failure brings it back. Petting from a timer alone would hide
// exactly the failure the watchdog is for.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <string_view>

#include <boost/asio/io_context.hpp>
#include <boost/asio/steady_timer.hpp>

#include "core/types.hpp"

namespace imuemu::service {

enum class NotifyOutcome {
  sent,
  not_under_systemd,  // NOTIFY_SOCKET unset
  failed,             // the socket is set but sending failed (logged once as a warning)
};

// READY=1 with STATUS=status_text: the scene is running and its devices are open.
NotifyOutcome notify_ready(std::string_view status_text);
// STATUS=...: the one-line status `systemctl status` shows.
NotifyOutcome notify_status(std::string_view status_text);
// STOPPING=1: shutdown began (SIGTERM).
NotifyOutcome notify_stopping();
// RELOADING=1: SIGHUP, the scene is being restarted in-process; follow with
// notify_ready() when it runs again.
NotifyOutcome notify_reloading();
// WATCHDOG=1.
NotifyOutcome notify_watchdog();

// The text sent as STATUS= (newlines would end the assignment: they become
// spaces). Exposed for tests.
std::string status_assignment(std::string_view status_text);

// WATCHDOG_USEC for this process (sd_watchdog_enabled: also checks
// WATCHDOG_PID), or nullopt when systemd did not ask for a watchdog.
std::optional<std::chrono::microseconds> watchdog_interval();

// Progress mark of the emission thread: it calls beat() after every sample
// (one relaxed atomic store); the watchdog's health predicate asks
// alive_within(). Time is CLOCK_MONOTONIC ns.
class EmissionHeartbeat {
 public:
  void beat(TimeNs now_ns) noexcept { last_beat_ns_.store(now_ns, std::memory_order_relaxed); }
  void beat() noexcept;  // with the current CLOCK_MONOTONIC time
  // Never beaten counts as not alive.
  bool alive_within(TimeNs max_age_ns, TimeNs now_ns) const noexcept;
  bool alive_within(TimeNs max_age_ns) const noexcept;
  std::optional<TimeNs> last_beat_ns() const noexcept;

 private:
  static constexpr TimeNs kNever = INT64_MIN;
  std::atomic<TimeNs> last_beat_ns_{kNever};
};

// Pets the watchdog every half interval from a steady_timer on `io` (the
// daemon's service io_context: control socket, signals), but only when
// `healthy()` returns true at that moment. Stops on stop() or destruction;
// both must run on the io_context's thread or after it stopped.
class WatchdogPetter {
 public:
  using HealthPredicate = std::function<bool()>;

  WatchdogPetter(boost::asio::io_context& io, std::chrono::microseconds watchdog_interval, HealthPredicate healthy);
  ~WatchdogPetter();
  WatchdogPetter(const WatchdogPetter&) = delete;
  WatchdogPetter& operator=(const WatchdogPetter&) = delete;

  void start();  // first check after half an interval
  void stop();

  std::chrono::microseconds pet_period() const { return pet_period_; }
  std::uint64_t pets_sent() const { return pets_sent_.load(); }
  std::uint64_t pets_withheld() const { return pets_withheld_.load(); }  // unhealthy checks

 private:
  void schedule();
  void check_and_pet();

  boost::asio::steady_timer timer_;
  std::chrono::microseconds pet_period_;
  HealthPredicate healthy_;
  bool running_ = false;
  bool was_healthy_ = true;
  std::atomic<std::uint64_t> pets_sent_{0};
  std::atomic<std::uint64_t> pets_withheld_{0};
};

}  // namespace imuemu::service
