#include "log/log.hpp"

#include <systemd/sd-daemon.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>

namespace imuemu::service {
namespace {

std::atomic<int> g_threshold{static_cast<int>(LogLevel::info)};
std::atomic<std::uint64_t> g_lines_lost{0};

// The prefixes are sd-daemon(3)'s macros, not literals of our own, so the
// format is exactly what journald parses.
const char* prefix_of(LogLevel level) {
  switch (level) {
    case LogLevel::err: return SD_ERR;
    case LogLevel::warning: return SD_WARNING;
    case LogLevel::notice: return SD_NOTICE;
    case LogLevel::info: return SD_INFO;
    case LogLevel::debug: return SD_DEBUG;
  }
  return SD_ERR;
}

}  // namespace

std::string format_log_line(LogLevel level, std::string_view text) {
  std::string line = prefix_of(level);
  // Messages echo user input (a scene's names, a source's lines): a 100 KB
  // name must not become a 100 KB journal line.
  const bool cut = text.size() > kMaxLogTextBytes;
  const std::string_view shown = cut ? text.substr(0, kMaxLogTextBytes) : text;
  line.reserve(line.size() + shown.size() + 48);
  for (const char c : shown) line.push_back(c == '\n' || c == '\r' ? ' ' : c);
  if (cut) line += "... (" + std::to_string(text.size() - kMaxLogTextBytes) + " more bytes not shown)";
  line.push_back('\n');
  return line;
}

void set_log_threshold(LogLevel least_severe_logged) { g_threshold.store(static_cast<int>(least_severe_logged)); }
LogLevel log_threshold() { return static_cast<LogLevel>(g_threshold.load()); }
std::uint64_t log_lines_lost() { return g_lines_lost.load(std::memory_order_relaxed); }

void log(LogLevel level, std::string_view text) {
  if (static_cast<int>(level) > g_threshold.load()) return;
  const std::string line = format_log_line(level, text);
  // One write(2) per line (stderr is unbuffered, but iostreams may split it);
  // a short write to a pipe is finished, EINTR retried; other errors are
  // dropped and counted: there is nowhere left to report them but the status.
  std::size_t written = 0;
  while (written < line.size()) {
    const ssize_t n = ::write(STDERR_FILENO, line.data() + written, line.size() - written);
    if (n < 0) {
      if (errno == EINTR) continue;
      g_lines_lost.fetch_add(1, std::memory_order_relaxed);
      return;
    }
    written += static_cast<std::size_t>(n);
  }
}

RateLimiter::RateLimiter(TimeNs interval_ns, std::uint32_t burst) : interval_ns_(interval_ns), burst_(burst) {}

RateLimiter::Decision RateLimiter::check(TimeNs now_ns) {
  const std::lock_guard lock(mutex_);
  if (!window_started_ || now_ns - window_start_ns_ >= interval_ns_) {
    window_started_ = true;
    window_start_ns_ = now_ns;
    emitted_in_window_ = 0;
  }
  if (emitted_in_window_ >= burst_) {
    ++suppressed_;
    return {};
  }
  ++emitted_in_window_;
  Decision decision{true, suppressed_};
  suppressed_ = 0;
  return decision;
}

void RateLimiter::log(LogLevel level, std::string_view text, TimeNs now_ns) {
  const Decision decision = check(now_ns);
  if (!decision.emit) return;
  if (decision.suppressed_before == 0) {
    service::log(level, text);
  } else {
    service::log(level, std::string(text) + " (" + std::to_string(decision.suppressed_before) +
                            " similar messages suppressed)");
  }
}

}  // namespace imuemu::service
