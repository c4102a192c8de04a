#include "daemon/service/service_notify.hpp"

#include <systemd/sd-daemon.h>
#include <time.h>

#include <atomic>
#include <cstdlib>
#include <stdexcept>
#include <cstring>
#include <string>

#include "log/log.hpp"

namespace imuemu::service {
namespace {

TimeNs monotonic_now_ns() {
  timespec ts{};
  ::clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<TimeNs>(ts.tv_sec) * kNsPerSecond + ts.tv_nsec;
}

NotifyOutcome send(const std::string& state) {
  // sd_notify returns 0 when NOTIFY_SOCKET is unset, > 0 when sent, -errno
  // on failure (sd_notify(3)). The environment is kept (unset_environment=0):
  // a SIGHUP reload notifies again.
  const int r = ::sd_notify(0, state.c_str());
  if (r > 0) return NotifyOutcome::sent;
  if (r == 0) return NotifyOutcome::not_under_systemd;
  static std::atomic<bool> warned{false};
  if (!warned.exchange(true)) {
    const char* socket = std::getenv("NOTIFY_SOCKET");
    log_warning(std::string("sd_notify to NOTIFY_SOCKET=") + (socket ? socket : "") + " failed: " +
                std::strerror(-r) + " (further failures not logged)");
  }
  return NotifyOutcome::failed;
}

}  // namespace

std::string status_assignment(std::string_view status_text) {
  std::string out = "STATUS=";
  for (const char c : status_text) out.push_back(c == '\n' || c == '\r' ? ' ' : c);
  return out;
}

NotifyOutcome notify_ready(std::string_view status_text) {
  return send("READY=1\n" + status_assignment(status_text));
}
NotifyOutcome notify_status(std::string_view status_text) { return send(status_assignment(status_text)); }
NotifyOutcome notify_stopping() { return send("STOPPING=1"); }
NotifyOutcome notify_reloading() { return send("RELOADING=1"); }
NotifyOutcome notify_watchdog() { return send("WATCHDOG=1"); }

std::optional<std::chrono::microseconds> watchdog_interval() {
  std::uint64_t usec = 0;
  const int r = ::sd_watchdog_enabled(0, &usec);
  if (r > 0 && usec > 0) return std::chrono::microseconds(static_cast<std::int64_t>(usec));
  if (r < 0) {
    log_warning(std::string("WATCHDOG_USEC/WATCHDOG_PID are malformed (") + std::strerror(-r) +
                "): running without the watchdog");
  }
  return std::nullopt;
}

void EmissionHeartbeat::beat() noexcept { beat(monotonic_now_ns()); }

bool EmissionHeartbeat::alive_within(TimeNs max_age_ns, TimeNs now_ns) const noexcept {
  const TimeNs last = last_beat_ns_.load(std::memory_order_relaxed);
  return last != kNever && now_ns - last <= max_age_ns;
}

bool EmissionHeartbeat::alive_within(TimeNs max_age_ns) const noexcept {
  return alive_within(max_age_ns, monotonic_now_ns());
}

std::optional<TimeNs> EmissionHeartbeat::last_beat_ns() const noexcept {
  const TimeNs last = last_beat_ns_.load(std::memory_order_relaxed);
  if (last == kNever) return std::nullopt;
  return last;
}

WatchdogPetter::WatchdogPetter(boost::asio::io_context& io, std::chrono::microseconds watchdog_interval,
                               HealthPredicate healthy)
    // Half the interval, as sd_watchdog_enabled(3) recommends: one late or
    // withheld pet is not yet a restart.
    : timer_(io), pet_period_(watchdog_interval / 2), healthy_(std::move(healthy)) {
  if (watchdog_interval.count() <= 1) throw std::invalid_argument("watchdog interval must be longer than 1 us");
  if (!healthy_) throw std::invalid_argument("WatchdogPetter needs a health predicate");
}

WatchdogPetter::~WatchdogPetter() { stop(); }

void WatchdogPetter::start() {
  if (running_) return;
  running_ = true;
  schedule();
}

void WatchdogPetter::stop() {
  running_ = false;
  timer_.cancel();
}

void WatchdogPetter::schedule() {
  timer_.expires_after(pet_period_);
  timer_.async_wait([this](const boost::system::error_code& ec) {
    if (ec || !running_) return;  // cancelled: `this` may be going away, touch nothing else
    check_and_pet();
    schedule();
  });
}

void WatchdogPetter::check_and_pet() {
  bool healthy = false;
  try {
    healthy = healthy_();
  } catch (const std::exception& e) {
    log_err(std::string("watchdog health check threw: ") + e.what());
  }
  if (healthy) {
    notify_watchdog();
    pets_sent_.fetch_add(1);
    if (!was_healthy_) log_info("emission progressing again: watchdog pets resumed");
  } else {
    pets_withheld_.fetch_add(1);
    if (was_healthy_) {
      log_err("emission thread made no progress recently: withholding the watchdog pet "
              "(systemd restarts the service after WatchdogSec)");
    }
  }
  was_healthy_ = healthy;
}

}  // namespace imuemu::service
