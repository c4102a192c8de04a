// What every device that answers its driver keeps for status and logs: the
// command counters (bumped by the io thread, read by the control thread
// without a lock), the mode/format/baud text behind one mutex, and the log
// sink with the device's prefix. Never touched by the emission thread: the
// encoders read their settings from their own lock-free mailbox.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <mutex>
#include <string>
#include <string_view>

#include "drivers/protocol.hpp"

namespace imuemu::drivers {

class ResponderStatus {
 public:
  // `log_prefix` starts every log line ("vectornav: ").
  explicit ResponderStatus(std::string log_prefix) : log_prefix_(std::move(log_prefix)) {}

  // The counters as CommandCounters defines them (drivers/protocol.hpp).
  std::atomic<std::uint64_t> received{0}, answered{0}, nacked{0}, not_command_bytes{0}, replies_dropped{0};

  // The counters and the settings text, for CommandResponder::command_counters().
  CommandCounters counters() const;
  void set_mode_and_format(std::string mode, std::string format);
  void set_format(std::string format);
  void set_baud(std::uint32_t baud);

  void set_log(std::function<void(std::string_view)> log);
  void log(const std::string& line) const;

 private:
  const std::string log_prefix_;
  mutable std::mutex mutex_;  // the strings, the baud and the log sink
  std::string mode_, format_;
  std::uint32_t baud_ = 0;
  std::function<void(std::string_view)> log_;
};

}  // namespace imuemu::drivers
