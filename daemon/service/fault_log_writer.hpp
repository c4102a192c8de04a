// imuemud's fault log (issue 18 ground truth, docs/faults.md): every fault's
// start and end as the running engine reports them, appended to the file of
// --fault-log or the scene's [daemon] fault_log, one JSON line each
// (io/fault_log.hpp).
//
// The log is a record, not the product, and its reader is not trusted
// (issue 26 N1-N3, N13, N14): the io thread that serves status, signals and
// the watchdog only formats the lines and puts them in a bounded queue; a
// thread of its own writes them to a descriptor opened O_NONBLOCK, so
//  - a FIFO with no reader does not block the start: the log counts as not
//    open and the open is retried every second (the lines wait in the queue);
//  - a reader that stops reading fills the queue, never blocks a thread that
//    serves anything: what does not fit is dropped whole and counted;
//  - a reader that goes away (EPIPE; imuemud ignores SIGPIPE) closes the log;
//    it is opened again as above;
//  - a full disk (ENOSPC, EDQUOT, EFBIG) drops the line whole: a regular file
//    is cut back to the end of the last whole line, and the next line is tried
//    again, so the recording resumes when space returns;
//  - reopen() (SIGHUP) closes the log and opens its path again, or a new one:
//    a rotation (rename, then a new file at the path) or a changed
//    [daemon] fault_log.
// Every line dropped is counted (dropped_events in the status JSON's
// "fault_log_output") and logged with its reason, at most one line a second.
#pragma once

#include <sys/types.h>

#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/fault/fault.hpp"

namespace imuemu::service {

struct FaultLogCounters {
  std::string path;                 // empty: no fault log
  bool open = false;                // a descriptor is open (false: a FIFO without reader, an error; retried)
  std::uint64_t lines_written = 0;  // whole lines written
  std::uint64_t dropped_events = 0; // events not written: queue full, disk full, reader gone, left at exit
  std::uint64_t queued = 0;         // lines waiting now (a gauge)
  std::uint64_t opens = 0;          // successful opens (the first, retries and reopens)
  std::string last_error;           // the newest failure with its reason (empty: none)
};

nlohmann::json to_json(const FaultLogCounters& c);

class FaultLogWriter {
 public:
  // The write(2) of the writer thread; a seam for tests (a disk that fills
  // up and frees again).
  using WriteFn = ssize_t (*)(int fd, const void* data, std::size_t size);

  // capacity_lines: lines that may wait for the writer thread (beyond: dropped).
  explicit FaultLogWriter(std::string path, WriteFn write_fn = nullptr, std::size_t capacity_lines = 4096);
  ~FaultLogWriter();
  FaultLogWriter(const FaultLogWriter&) = delete;
  FaultLogWriter& operator=(const FaultLogWriter&) = delete;

  std::string path() const;  // empty: no fault log

  // Opens (appends to, creating it 0644) the fault log and starts the writer
  // thread. Throws naming the path and the reason (strerror) when it cannot
  // be opened, except a FIFO without a reader (ENXIO), which is retried.
  void open();

  // Queues one line per event; never blocks on the log. Nothing without a log
  // (the caller still takes the events from the engine: its queue is bounded).
  void write(const std::vector<fault::FaultEvent>& events);
  // One line (without its newline) as write() queues it; for tests.
  void write_line(std::string line);

  // Closes the log and opens `path` (the same: a rotation; empty: no log
  // from now on) on the writer thread; lines waiting go to the new file.
  void reopen(std::string path);

  // Waits up to `drain_limit` for the waiting lines to be written, then stops
  // the writer thread and closes the log; lines left are counted as dropped.
  void close(std::chrono::milliseconds drain_limit);

  // Waits (bounded) until no line waits; for tests. True if it got there.
  bool wait_idle(std::chrono::milliseconds limit);

  FaultLogCounters counters() const;

 private:
  void run();
  bool try_open_locked(std::unique_lock<std::mutex>& lock, bool at_start);
  void close_fd();
  void drop(std::uint64_t lines, const std::string& reason);
  // Writes `line` whole (true) or drops it (false); the lock is not held.
  bool write_whole(const std::string& line);

  WriteFn write_fn_;
  std::size_t capacity_lines_;
  mutable std::mutex mutex_;
  std::condition_variable wake_;
  std::deque<std::string> queue_;
  std::string path_, pending_path_;
  bool reopen_requested_ = false;
  bool stop_ = false;
  std::chrono::steady_clock::time_point drain_until_{};
  std::chrono::steady_clock::time_point next_open_{};
  bool busy_ = false;  // the writer thread holds a line it took from the queue
  int fd_ = -1;        // the writer thread's (and open()'s before it starts)
  bool regular_ = false;
  FaultLogCounters counters_;
  std::chrono::steady_clock::time_point last_drop_log_{};
  std::uint64_t dropped_not_logged_ = 0;
  std::thread thread_;
};

}  // namespace imuemu::service
