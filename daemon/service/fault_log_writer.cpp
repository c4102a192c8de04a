#include "daemon/service/fault_log_writer.hpp"

#include <fcntl.h>
#include <poll.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <sstream>
#include <stdexcept>
#include <utility>

#include "io/fault_log.hpp"
#include "log/log.hpp"

namespace imuemu::service {

namespace {

using Clock = std::chrono::steady_clock;
using namespace std::chrono_literals;

// A log that cannot be opened (a FIFO without reader, a reader gone, an I/O
// error) is tried again this often.
constexpr auto kRetryOpen = 1s;
// A full pipe is polled this long at a time, so a stop or a reopen is seen.
constexpr int kPollMs = 100;
// At most one line about dropped events this often (the rest are counted).
constexpr auto kDropLogInterval = 1s;

std::string reason_of(int error) { return std::strerror(error); }

}  // namespace

nlohmann::json to_json(const FaultLogCounters& c) {
  return {{"path", c.path.empty() ? nlohmann::json(nullptr) : nlohmann::json(c.path)},
          {"open", c.open},
          {"lines_written", c.lines_written},
          {"dropped_events", c.dropped_events},
          {"queued", c.queued},
          {"opens", c.opens},
          {"last_error", c.last_error.empty() ? nlohmann::json(nullptr) : nlohmann::json(c.last_error)}};
}

FaultLogWriter::FaultLogWriter(std::string path, WriteFn write_fn, std::size_t capacity_lines)
    : write_fn_(write_fn != nullptr ? write_fn : &::write), capacity_lines_(capacity_lines), path_(std::move(path)) {
  counters_.path = path_;
}

FaultLogWriter::~FaultLogWriter() { close(0ms); }

std::string FaultLogWriter::path() const {
  const std::lock_guard lock(mutex_);
  return reopen_requested_ ? pending_path_ : path_;
}

void FaultLogWriter::open() {
  std::unique_lock lock(mutex_);
  if (!path_.empty() && !try_open_locked(lock, true)) {
    log_warning("fault log " + path_ + ": " + counters_.last_error +
                "; the events wait (at most " + std::to_string(capacity_lines_) +
                ") and the open is tried again every second");
  }
  if (!thread_.joinable()) thread_ = std::thread([this] { run(); });
}

bool FaultLogWriter::try_open_locked(std::unique_lock<std::mutex>& lock, bool at_start) {
  const std::string path = path_;
  lock.unlock();
  // O_NONBLOCK: opening a FIFO without reader fails with ENXIO instead of
  // waiting for one, and writes to a pipe never wait (the thread polls).
  const int fd = ::open(path.c_str(), O_WRONLY | O_APPEND | O_CREAT | O_NONBLOCK | O_CLOEXEC | O_NOCTTY, 0644);
  const int error = errno;
  struct stat st {};
  const bool regular = fd >= 0 && ::fstat(fd, &st) == 0 && S_ISREG(st.st_mode);
  lock.lock();
  if (fd >= 0 && (path != path_ || reopen_requested_)) {  // reopened meanwhile: the new path is tried next
    ::close(fd);
    return false;
  }
  if (fd < 0) {
    counters_.open = false;
    counters_.last_error = error == ENXIO ? "a FIFO with no reader (" + reason_of(error) + ")"
                                          : "cannot open it for writing: " + reason_of(error);
    next_open_ = Clock::now() + kRetryOpen;
    if (at_start && error != ENXIO) throw std::runtime_error("fault log " + path + ": " + counters_.last_error);
    return false;
  }
  fd_ = fd;
  regular_ = regular;
  counters_.open = true;
  ++counters_.opens;
  return true;
}

void FaultLogWriter::close_fd() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
  counters_.open = false;
}

void FaultLogWriter::drop(std::uint64_t lines, const std::string& reason) {
  if (lines == 0) return;
  counters_.dropped_events += lines;
  counters_.last_error = reason;
  dropped_not_logged_ += lines;
  const auto now = Clock::now();
  if (now - last_drop_log_ < kDropLogInterval) return;
  last_drop_log_ = now;
  // log() is one write(2) to stderr; said under the lock, which the io
  // thread only takes to queue a line.
  log_warning("fault log " + path_ + ": " + std::to_string(dropped_not_logged_) + " event(s) not written (" + reason +
              "); " + std::to_string(counters_.dropped_events) + " dropped so far");
  dropped_not_logged_ = 0;
}

void FaultLogWriter::write(const std::vector<fault::FaultEvent>& events) {
  if (events.empty()) return;
  {
    const std::lock_guard lock(mutex_);
    if ((reopen_requested_ ? pending_path_ : path_).empty()) return;
  }
  for (const fault::FaultEvent& e : events) {
    std::ostringstream line;
    fault_log::write_fault_event_json_line(line, e);
    std::string text = line.str();
    if (!text.empty() && text.back() == '\n') text.pop_back();
    write_line(std::move(text));
  }
}

void FaultLogWriter::write_line(std::string line) {
  line.push_back('\n');
  {
    const std::lock_guard lock(mutex_);
    if ((reopen_requested_ ? pending_path_ : path_).empty()) return;
    if (queue_.size() >= capacity_lines_ || stop_) {
      drop(1, "the queue of " + std::to_string(capacity_lines_) + " lines is full: the log is not open or its reader is slow");
      return;
    }
    queue_.push_back(std::move(line));
  }
  wake_.notify_all();
}

void FaultLogWriter::reopen(std::string path) {
  {
    const std::lock_guard lock(mutex_);
    pending_path_ = std::move(path);
    reopen_requested_ = true;
  }
  wake_.notify_all();
}

void FaultLogWriter::close(std::chrono::milliseconds drain_limit) {
  {
    const std::lock_guard lock(mutex_);
    stop_ = true;
    drain_until_ = Clock::now() + drain_limit;
  }
  wake_.notify_all();
  if (thread_.joinable()) thread_.join();
  const std::lock_guard lock(mutex_);
  drop(queue_.size(), "left unwritten at exit");
  queue_.clear();
  close_fd();
}

bool FaultLogWriter::wait_idle(std::chrono::milliseconds limit) {
  std::unique_lock lock(mutex_);
  return wake_.wait_for(lock, limit, [this] { return queue_.empty() && !busy_; });
}

FaultLogCounters FaultLogWriter::counters() const {
  const std::lock_guard lock(mutex_);
  FaultLogCounters c = counters_;
  c.queued = queue_.size() + (busy_ ? 1 : 0);
  return c;
}

bool FaultLogWriter::write_whole(const std::string& line) {
  // A regular file is cut back to here if the line does not fit whole.
  const off_t start = regular_ ? ::lseek(fd_, 0, SEEK_END) : -1;
  std::size_t done = 0;
  while (done < line.size()) {
    const ssize_t n = write_fn_(fd_, line.data() + done, line.size() - done);
    if (n > 0) {
      done += static_cast<std::size_t>(n);
      continue;
    }
    const int error = n < 0 ? errno : EIO;
    if (error == EINTR) continue;
    if (error == EAGAIN || error == EWOULDBLOCK) {
      // A full pipe: wait for room, a bounded time at a time; give up on the
      // line (whole, if none of it went out) when stopping past the drain
      // limit or reopening.
      {
        std::unique_lock lock(mutex_);
        const bool give_up = (stop_ && Clock::now() >= drain_until_) || reopen_requested_;
        if (give_up) {
          drop(1, done == 0 ? "the reader is not reading" : "the reader is not reading (a line cut short in the pipe)");
          return false;
        }
      }
      pollfd p{fd_, POLLOUT, 0};
      (void)::poll(&p, 1, kPollMs);
      continue;
    }
    std::unique_lock lock(mutex_);
    if (error == ENOSPC || error == EDQUOT || error == EFBIG) {
      // Only whole lines: what went out of this one is taken back; the file
      // stays open and the next line is tried (the recording resumes when
      // there is room again).
      // ftruncate's result is checked: glibc declares it warn_unused_result,
      // which a (void) cast does not silence (the Debian package's
      // _FORTIFY_SOURCE build made that an error).
      const bool taken_back = start < 0 || ::ftruncate(fd_, start) == 0;
      drop(1, "a line of " + std::to_string(line.size()) + " bytes does not fit: " + reason_of(error) +
                  (taken_back ? "" : "; its written part could not be taken back"));
      return false;
    }
    // The reader went away (EPIPE: SIGPIPE is ignored) or the file failed:
    // closed, and opened again later (a FIFO's next reader, a remounted disk).
    const bool taken_back = start < 0 || done == 0 || ::ftruncate(fd_, start) == 0;
    close_fd();
    next_open_ = Clock::now() + kRetryOpen;
    drop(1, (error == EPIPE ? "the reader went away: " : "writing failed: ") + reason_of(error) +
                (taken_back ? "" : "; a partial line stays in the file") + "; the log is opened again every second");
    return false;
  }
  return true;
}

void FaultLogWriter::run() {
  std::unique_lock lock(mutex_);
  for (;;) {
    if (reopen_requested_) {
      reopen_requested_ = false;
      close_fd();
      path_ = pending_path_;
      counters_.path = path_;
      counters_.last_error.clear();
      next_open_ = {};
      if (path_.empty()) {
        drop(queue_.size(), "the fault log was removed from the configuration");
        queue_.clear();
      }
    }
    if (fd_ < 0 && !path_.empty() && Clock::now() >= next_open_) (void)try_open_locked(lock, false);
    if (stop_ && (queue_.empty() || Clock::now() >= drain_until_ || fd_ < 0)) break;
    if (fd_ >= 0 && !queue_.empty() && !reopen_requested_) {
      std::string line = std::move(queue_.front());
      queue_.pop_front();
      busy_ = true;
      lock.unlock();
      const bool written = write_whole(line);
      lock.lock();
      busy_ = false;
      if (written) ++counters_.lines_written;
      continue;
    }
    wake_.notify_all();  // wait_idle()
    const auto wait = fd_ < 0 && !path_.empty() ? std::chrono::duration_cast<std::chrono::milliseconds>(kRetryOpen) : 1000ms;
    wake_.wait_for(lock, wait, [this] {
      return stop_ || reopen_requested_ || (fd_ >= 0 && !queue_.empty()) || (fd_ < 0 && !path_.empty() && Clock::now() >= next_open_);
    });
  }
  busy_ = false;
  wake_.notify_all();
}

}  // namespace imuemu::service
