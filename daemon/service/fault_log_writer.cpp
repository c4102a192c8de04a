#include "daemon/service/fault_log_writer.hpp"

#include <stdexcept>

#include "io/fault_log.hpp"
#include "log/log.hpp"

namespace imuemu::service {

void FaultLogWriter::open() {
  if (path_.empty()) return;
  out_.emplace(path_, std::ios::app);
  if (!*out_) throw std::runtime_error("fault log " + path_ + ": cannot open it for writing");
}

void FaultLogWriter::write(const std::vector<fault::FaultEvent>& events) {
  if (events.empty() || !out_) return;
  for (const fault::FaultEvent& e : events) fault_log::write_fault_event_json_line(*out_, e);
  out_->flush();
  if (!*out_ && !failed_) {
    failed_ = true;
    log_err("fault log " + path_ + ": writing failed; fault events are no longer recorded");
  }
}

}  // namespace imuemu::service
