// Log lines for imuemud on stderr, each prefixed with its syslog priority
// ("<3>" error, "<4>" warning, "<5>" notice, "<6>" info, "<7>" debug: the
// SD_ERR... macros of sd-daemon(3)). Under systemd, stderr goes to journald,
// which strips the prefix and keeps the level (`journalctl -p warning` works);
// on a terminal the prefix stays visible, which is harmless.
//
// One line is one write(2) call, so lines from several threads never
// interleave. The emission thread must not log per sample: it counts, and the
// daemon logs a periodic summary (and uses RateLimiter for repeated events).
#pragma once

#include <cstddef>
#include <cstdint>
#include <mutex>
#include <string>
#include <string_view>

#include "core/types.hpp"

namespace imuemu::service {

// Values are the syslog priorities (RFC 5424 §6.2.1), as journald reads them.
enum class LogLevel : int { err = 3, warning = 4, notice = 5, info = 6, debug = 7 };

// Longest text of one log line; the rest is cut and counted ("... (N more
// bytes not shown)").
inline constexpr std::size_t kMaxLogTextBytes = 4096;

// "<P>text\n" with the SD_* prefix of `level`; newlines inside `text` become
// spaces (journald would otherwise make the rest a line without a priority);
// text beyond kMaxLogTextBytes is cut.
std::string format_log_line(LogLevel level, std::string_view text);

// Lines less severe than this are dropped (default info: debug is dropped).
void set_log_threshold(LogLevel least_severe_logged);
LogLevel log_threshold();

// Writes one line to stderr (fd 2) unless below the threshold. A line stderr
// refuses (EPIPE: its reader went away; imuemud ignores SIGPIPE) is counted.
void log(LogLevel level, std::string_view text);
// Lines (or their rest) stderr refused since the start (issue 26 N1).
std::uint64_t log_lines_lost();
inline void log_err(std::string_view text) { log(LogLevel::err, text); }
inline void log_warning(std::string_view text) { log(LogLevel::warning, text); }
inline void log_notice(std::string_view text) { log(LogLevel::notice, text); }
inline void log_info(std::string_view text) { log(LogLevel::info, text); }
inline void log_debug(std::string_view text) { log(LogLevel::debug, text); }

// Rate limit for a message that can repeat quickly (a device that keeps
// failing, a malformed datagram per packet): at most `burst` lines per
// `interval_ns`; what is held back is counted and reported with the first line
// allowed afterwards ("... (37 similar messages suppressed)"). The caller
// passes the time (CLOCK_MONOTONIC ns), so tests drive it. Thread-safe.
class RateLimiter {
 public:
  RateLimiter(TimeNs interval_ns, std::uint32_t burst);

  struct Decision {
    bool emit = false;
    std::uint64_t suppressed_before = 0;  // held back since the last emitted line
  };
  Decision check(TimeNs now_ns);

  // check() + log(): appends the suppressed count when there is one.
  void log(LogLevel level, std::string_view text, TimeNs now_ns);

 private:
  std::mutex mutex_;
  TimeNs interval_ns_;
  std::uint32_t burst_;
  TimeNs window_start_ns_ = 0;
  bool window_started_ = false;
  std::uint32_t emitted_in_window_ = 0;
  std::uint64_t suppressed_ = 0;
};

}  // namespace imuemu::service
