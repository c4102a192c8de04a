#include "drivers/protocols/responder_status.hpp"

#include <utility>

namespace imuemu::drivers {

CommandCounters ResponderStatus::counters() const {
  CommandCounters c;
  c.received = received.load(std::memory_order_relaxed);
  c.answered = answered.load(std::memory_order_relaxed);
  c.nacked = nacked.load(std::memory_order_relaxed);
  c.not_command_bytes = not_command_bytes.load(std::memory_order_relaxed);
  c.replies_dropped = replies_dropped.load(std::memory_order_relaxed);
  const std::lock_guard<std::mutex> lock(mutex_);
  c.mode = mode_;
  c.format = format_;
  c.baud = baud_;
  return c;
}

void ResponderStatus::set_mode_and_format(std::string mode, std::string format) {
  const std::lock_guard<std::mutex> lock(mutex_);
  mode_ = std::move(mode);
  format_ = std::move(format);
}

void ResponderStatus::set_format(std::string format) {
  const std::lock_guard<std::mutex> lock(mutex_);
  format_ = std::move(format);
}

void ResponderStatus::set_baud(std::uint32_t baud) {
  const std::lock_guard<std::mutex> lock(mutex_);
  baud_ = baud;
}

void ResponderStatus::set_log(std::function<void(std::string_view)> log) {
  const std::lock_guard<std::mutex> lock(mutex_);
  log_ = std::move(log);
}

void ResponderStatus::log(const std::string& line) const {
  const std::lock_guard<std::mutex> lock(mutex_);
  if (log_) log_(log_prefix_ + line);
}

}  // namespace imuemu::drivers
