// imuemud's fault log (issue 18 ground truth, docs/faults.md): every fault's
// start and end as the running engine reports them, appended to the file of
// --fault-log or the scene's [daemon] fault_log, one JSON line each
// (io/fault_log.hpp), on the service io thread. The file is opened once at
// start (a path that cannot be opened fails the start, naming it); a write
// that fails later is logged once and the events after it are dropped (the
// emission goes on: the log is a record, not the product).
#pragma once

#include <fstream>
#include <optional>
#include <string>
#include <vector>

#include "core/fault/fault.hpp"

namespace imuemu::service {

class FaultLogWriter {
 public:
  explicit FaultLogWriter(std::string path) : path_(std::move(path)) {}

  const std::string& path() const { return path_; }  // empty: no fault log

  // Opens (appends to) the fault log; throws naming the path.
  void open();

  // One line per event and a flush; nothing without a log (the caller still
  // takes the events from the engine: its queue is bounded).
  void write(const std::vector<fault::FaultEvent>& events);

 private:
  std::string path_;
  std::optional<std::ofstream> out_;
  bool failed_ = false;
};

}  // namespace imuemu::service
