#include "drivers/queued_writer.hpp"

#include <poll.h>
#include <pthread.h>
#include <sched.h>
#include <sys/eventfd.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstdio>
#include <cstring>

#include "log/log.hpp"

namespace imuemu::drivers {
namespace {

constexpr std::size_t kLengthBytes = sizeof(std::uint32_t);  // each queued frame's length prefix
constexpr std::size_t kMinQueueBytes = 64;
constexpr std::size_t kStreamBatchBytes = 4096;
// A retry_later episode this long is worth a log line (CAN: a bus nobody
// acknowledges, or a controller in bus-off that keeps its queue stopped).
constexpr std::chrono::seconds kRetryEpisodeLog{1};
constexpr std::chrono::seconds kRejectLogInterval{1};

std::size_t checked_queue_bytes(const QueuedWriterOptions& options) {
  if (options.queue_bytes < kMinQueueBytes || options.queue_bytes > std::size_t{1} << 30) {
    throw TransportError(options.name + ": queue size " + std::to_string(options.queue_bytes) +
                         " bytes is out of range (expected 64 bytes .. 1 GiB)");
  }
  if (options.restore_initial.count() <= 0 || options.restore_max < options.restore_initial ||
      options.retry_initial.count() <= 0 || options.retry_max < options.retry_initial) {
    throw TransportError(options.name + ": back-off times must be positive with initial <= max");
  }
  return options.queue_bytes;
}

std::string seconds_text(std::chrono::nanoseconds d) {
  char text[32];
  std::snprintf(text, sizeof text, "%.3g s", static_cast<double>(d.count()) * 1e-9);
  return text;
}

// set_writer_threads_realtime_priority: what every writer thread applies.
std::atomic<int> g_writer_realtime_priority{0};

// On the writer thread: applies a changed process-wide priority (a refusal
// leaves the thread as it was; the emission thread's own request reports
// whether SCHED_FIFO is granted at all).
void apply_writer_priority(int& applied) noexcept {
  const int wanted = g_writer_realtime_priority.load(std::memory_order_relaxed);
  if (wanted == applied) return;
  sched_param sp{};
  sp.sched_priority = wanted;
  (void)pthread_setschedparam(pthread_self(), wanted > 0 ? SCHED_FIFO : SCHED_OTHER, &sp);
  applied = wanted;
}

}  // namespace

void set_writer_threads_realtime_priority(int priority) noexcept {
  g_writer_realtime_priority.store(priority, std::memory_order_relaxed);
}

std::string errno_message(int error) {
  char buffer[256];
  // GNU strerror_r returns the message (maybe not in `buffer`).
  return strerror_r(error, buffer, sizeof buffer);
}

void emit_log(const std::function<void(std::string_view)>& sink, std::string_view line) {
  if (sink) {
    sink(line);
    return;
  }
  // No sink: the project's log line (sd-daemon priority prefix, one write(2),
  // bounded), so a daemon's journal keeps the level of these lines too.
  service::log_warning("imuemu: " + std::string(line));
}

void run_thread_body(const std::function<void()>& body, const std::function<void(const char*)>& failed) noexcept {
  try {
    body();
  } catch (const std::exception& e) {
    failed(e.what());
  } catch (...) {
    failed("unknown exception");
  }
}

QueuedWriter::QueuedWriter(std::unique_ptr<WriterDevice> device, QueuedWriterOptions options)
    : device_(std::move(device)),
      options_(std::move(options)),
      max_frame_bytes_(checked_queue_bytes(options_) - kLengthBytes),
      queue_(options_.queue_bytes),
      scratch_(options_.queue_bytes),
      restore_backoff_(options_.restore_initial, options_.restore_max),
      retry_backoff_(options_.retry_initial, options_.retry_max) {
  batch_.reserve(kStreamBatchBytes + max_frame_bytes_);  // the last frame may cross the batch limit
  frame_ends_.reserve(options_.queue_bytes / (kLengthBytes + 1) + 1);
  wake_fd_ = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  if (wake_fd_ < 0) throw TransportError(options_.name + ": eventfd: " + errno_message(errno));
  link_up_.store(device_->initially_up(), std::memory_order_release);
  baud_.store(options_.baud, std::memory_order_relaxed);
  device_->set_input_tap(this);
  thread_ = std::thread([this] { run(); });
}

QueuedWriter::~QueuedWriter() {
  stop();
  ::close(wake_fd_);
}

void QueuedWriter::stop(std::chrono::milliseconds drain_timeout) {
  if (!thread_.joinable()) return;
  // Drain: the writer runs on; a link that is down drops its queue itself.
  const auto until = std::chrono::steady_clock::now() + drain_timeout;
  while (finished_.load(std::memory_order_acquire) < accepted_.load(std::memory_order_acquire) &&
         link_up_.load(std::memory_order_acquire) && std::chrono::steady_clock::now() < until) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  stop_.store(true, std::memory_order_release);
  signal_wake();
  thread_.join();
  drop_replies();  // replies still waiting: counted replies_dropped
  // The writer is gone: what it did not finish (queued, or in its batch) is
  // discarded here, and counted, instead of vanishing from the counters.
  const std::uint64_t accepted = accepted_.load(std::memory_order_acquire);
  const std::uint64_t finished = finished_.load(std::memory_order_acquire);
  if (accepted > finished) {
    const std::uint64_t left = accepted - finished;
    dropped_at_stop_.fetch_add(left, std::memory_order_relaxed);
    finished_.store(accepted, std::memory_order_release);
    log(std::to_string(left) + " queued frame(s) not written: the device did not take them within the " +
        std::to_string(drain_timeout.count()) + " ms stop drain (dropped_at_stop)");
  }
}

void QueuedWriter::signal_wake() const noexcept {
  const std::uint64_t one = 1;
  // Cannot block (EFD_NONBLOCK) and cannot fail short of a counter overflow
  // after 2^64 wake-ups; a failed write would only delay the writer.
  [[maybe_unused]] const auto written = ::write(wake_fd_, &one, sizeof one);
}

void QueuedWriter::log(std::string_view line) const {
  emit_log(options_.log, std::string(options_.name) + ": " + std::string(line));
}

bool QueuedWriter::offer(std::span<const std::byte> frame) {
  frames_.fetch_add(1, std::memory_order_relaxed);
  bytes_.fetch_add(frame.size(), std::memory_order_relaxed);
  if (frame.empty() || frame.size() > max_frame_bytes_) {
    write_errors_.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  if (!link_up_.load(std::memory_order_acquire)) {
    dropped_link_down_.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  const std::size_t record_bytes = kLengthBytes + frame.size();
  // Only this thread pushes, so the free space can only grow until the push.
  if (queue_.write_available() < record_bytes) {
    dropped_queue_full_.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  const auto length = static_cast<std::uint32_t>(frame.size());
  std::memcpy(scratch_.data(), &length, kLengthBytes);
  std::memcpy(scratch_.data() + kLengthBytes, frame.data(), frame.size());
  accepted_.fetch_add(1, std::memory_order_relaxed);
  // One push publishes the whole record at once (a single release store of
  // the write index), so the writer never pops half a frame.
  queue_.push(scratch_.data(), record_bytes);
  // Store-buffering handshake with the writer's idle wait (see run()): either
  // we see it sleeping and wake it, or it sees this frame before sleeping.
  std::atomic_thread_fence(std::memory_order_seq_cst);
  if (sleeping_.load(std::memory_order_relaxed)) signal_wake();
  return true;
}

void QueuedWriter::count_invalid_frame() {
  frames_.fetch_add(1, std::memory_order_relaxed);
  write_errors_.fetch_add(1, std::memory_order_relaxed);
}

TransportCounters QueuedWriter::counters() const {
  TransportCounters c;
  // Outcomes first, offers last: a frame in flight then shows as queued
  // rather than making the sum exceed `frames`.
  const std::uint64_t finished = finished_.load(std::memory_order_relaxed);
  c.frames_sent = frames_sent_.load(std::memory_order_relaxed);
  c.bytes_sent = bytes_sent_.load(std::memory_order_relaxed);
  c.dropped_queue_full = dropped_queue_full_.load(std::memory_order_relaxed);
  c.dropped_link_down = dropped_link_down_.load(std::memory_order_relaxed);
  c.write_errors = write_errors_.load(std::memory_order_relaxed);
  c.link_down_events = link_down_events_.load(std::memory_order_relaxed);
  c.link_restored = link_restored_.load(std::memory_order_relaxed);
  c.retries = retries_.load(std::memory_order_relaxed);
  c.input_bytes_discarded = input_discarded_.load(std::memory_order_relaxed);
  c.input_bytes = input_bytes_.load(std::memory_order_relaxed);
  c.replies_sent = replies_sent_.load(std::memory_order_relaxed);
  c.replies_dropped = replies_dropped_.load(std::memory_order_relaxed);
  c.dropped_at_stop = dropped_at_stop_.load(std::memory_order_relaxed);
  const std::uint64_t accepted = accepted_.load(std::memory_order_relaxed);
  c.queued = accepted > finished ? accepted - finished : 0;
  c.frames = frames_.load(std::memory_order_relaxed);
  c.bytes = bytes_.load(std::memory_order_relaxed);
  return c;
}

bool QueuedWriter::flush(std::chrono::milliseconds timeout) const {
  const std::uint64_t target = accepted_.load(std::memory_order_relaxed);
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (finished_.load(std::memory_order_relaxed) < target) {
    if (std::chrono::steady_clock::now() >= deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return true;
}

short QueuedWriter::wait(short device_events, std::chrono::nanoseconds timeout) {
  pollfd fds[2] = {{wake_fd_, POLLIN, 0}, {device_->poll_fd(), device_events, 0}};
  const nfds_t count = device_events != 0 && fds[1].fd >= 0 ? 2 : 1;
  timespec limit{};
  if (timeout.count() >= 0) {
    limit.tv_sec = static_cast<time_t>(timeout.count() / 1'000'000'000);
    limit.tv_nsec = static_cast<long>(timeout.count() % 1'000'000'000);
  }
  const int ready = ::ppoll(fds, count, timeout.count() >= 0 ? &limit : nullptr, nullptr);
  if (ready <= 0) return 0;  // timeout or EINTR: the caller loops
  if (fds[0].revents & POLLIN) {
    std::uint64_t value = 0;
    [[maybe_unused]] const auto got = ::read(wake_fd_, &value, sizeof value);
  }
  return count == 2 ? fds[1].revents : 0;
}

bool QueuedWriter::take_batch() {
  batch_.clear();
  frame_ends_.clear();
  batch_pos_ = 0;
  next_frame_ = 0;
  // A byte stream gets up to kStreamBatchBytes per write (at least one
  // frame); a datagram device one frame. Small batches keep the queue the
  // bound on what waits: queue_bytes + one batch + the kernel's buffer.
  const std::size_t limit = device_->datagrams() ? 1 : kStreamBatchBytes;
  while (batch_.size() < limit && queue_.read_available() >= kLengthBytes) {
    std::array<std::byte, kLengthBytes> prefix;
    queue_.pop(prefix.data(), kLengthBytes);
    std::uint32_t length = 0;
    std::memcpy(&length, prefix.data(), kLengthBytes);
    // The producer publishes a record whole, so its payload is there too.
    const std::size_t start = batch_.size();
    batch_.resize(start + length);
    queue_.pop(batch_.data() + start, length);
    frame_ends_.push_back(batch_.size());
  }
  return !frame_ends_.empty();
}

void QueuedWriter::advance(std::size_t bytes) {
  batch_pos_ += bytes;
  while (next_frame_ < frame_ends_.size() && frame_ends_[next_frame_] <= batch_pos_) {
    const std::size_t start = next_frame_ == 0 ? 0 : frame_ends_[next_frame_ - 1];
    frames_sent_.fetch_add(1, std::memory_order_relaxed);
    bytes_sent_.fetch_add(frame_ends_[next_frame_] - start, std::memory_order_relaxed);
    finished_.fetch_add(1, std::memory_order_relaxed);
    ++next_frame_;
  }
}

void QueuedWriter::skip_current_frame() {
  batch_pos_ = frame_ends_[next_frame_];
  ++next_frame_;
  write_errors_.fetch_add(1, std::memory_order_relaxed);
  finished_.fetch_add(1, std::memory_order_relaxed);
}

void QueuedWriter::drop_batch_and_queue() {
  do {
    const std::uint64_t unfinished = frame_ends_.size() - next_frame_;
    dropped_link_down_.fetch_add(unfinished, std::memory_order_relaxed);
    finished_.fetch_add(unfinished, std::memory_order_relaxed);
    next_frame_ = frame_ends_.size();
  } while (take_batch());
}

void QueuedWriter::set_input_handler(InputHandler* handler) {
  const std::lock_guard<std::mutex> lock(handler_mutex_);
  handler_ = handler;
}

void QueuedWriter::input(std::span<const std::byte> bytes) {
  input_bytes_.fetch_add(bytes.size(), std::memory_order_relaxed);
  const std::lock_guard<std::mutex> lock(handler_mutex_);
  if (handler_ == nullptr) {
    input_discarded_.fetch_add(bytes.size(), std::memory_order_relaxed);
    return;
  }
  handler_->on_input(std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size()),
                     *this);
}

bool QueuedWriter::reply(std::span<const std::uint8_t> bytes) {
  if (bytes.empty()) return true;
  if (replies_.size() - replies_pos_ + bytes.size() > options_.reply_queue_bytes) {
    replies_dropped_.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  const auto* b = reinterpret_cast<const std::byte*>(bytes.data());
  replies_.insert(replies_.end(), b, b + bytes.size());
  reply_ends_.push_back(replies_.size());
  if (baud_after_replies_ && !baud_change_at_) baud_change_at_ = replies_.size();
  return true;
}

void QueuedWriter::change_baud_after_replies(std::uint32_t baud) {
  baud_after_replies_ = baud;
  baud_change_at_.reset();  // set by the reply queued next (the ACK)
}

bool QueuedWriter::at_frame_boundary() const noexcept {
  if (next_frame_ >= frame_ends_.size()) return true;
  return batch_pos_ == (next_frame_ == 0 ? 0 : frame_ends_[next_frame_ - 1]);
}

void QueuedWriter::drop_replies() {
  replies_dropped_.fetch_add(reply_ends_.size() - next_reply_, std::memory_order_relaxed);
  replies_.clear();
  reply_ends_.clear();
  replies_pos_ = 0;
  next_reply_ = 0;
  baud_after_replies_.reset();  // the command's ACK never left: the device keeps its rate
  baud_change_at_.reset();
}

void QueuedWriter::write_replies() {
  // A datagram device (CAN) takes one reply frame per write; a byte stream
  // takes what is queued.
  std::size_t end = device_->datagrams() ? reply_ends_[next_reply_] : replies_.size();
  // Nothing after the ACK of a rate change leaves at the old rate.
  if (baud_change_at_ && *baud_change_at_ > replies_pos_) end = std::min(end, *baud_change_at_);
  const DeviceWrite result =
      device_->write(std::span<const std::byte>(replies_).subspan(replies_pos_, end - replies_pos_));
  switch (result.outcome) {
    case DeviceWrite::Outcome::written:
      replies_pos_ += result.bytes;
      while (next_reply_ < reply_ends_.size() && reply_ends_[next_reply_] <= replies_pos_) {
        replies_sent_.fetch_add(1, std::memory_order_relaxed);
        ++next_reply_;
      }
      if (baud_after_replies_ && replies_pos_ == baud_change_at_.value_or(replies_.size())) {
        const std::uint32_t baud = *baud_after_replies_;
        baud_after_replies_.reset();
        baud_change_at_.reset();
        std::string why;
        if (device_->set_baud(baud, why)) {
          baud_.store(baud, std::memory_order_relaxed);
          log("line rate now " + std::to_string(baud) + " baud (the device was told so by its driver)");
        } else {
          log("line rate " + std::to_string(baud) + " baud refused by the port: " + why);
        }
      }
      if (replies_pos_ == replies_.size()) {
        replies_.clear();
        reply_ends_.clear();
        replies_pos_ = 0;
        next_reply_ = 0;
      }
      break;
    case DeviceWrite::Outcome::would_block:
      handle_events(wait(POLLIN | POLLOUT, std::chrono::nanoseconds(-1)));
      break;
    case DeviceWrite::Outcome::retry_later:
      back_off_before_retry();
      break;
    case DeviceWrite::Outcome::frame_rejected:
      drop_replies();
      break;
    case DeviceWrite::Outcome::link_lost:
      go_down(result.reason);
      break;
  }
}

void QueuedWriter::go_down(const std::string& reason) {
  link_down_events_.fetch_add(1, std::memory_order_relaxed);
  link_up_.store(false, std::memory_order_release);  // refuse new frames at once; the log line follows
  drop_batch_and_queue();
  drop_replies();
  device_->on_link_lost();
  restore_backoff_.reset();
  last_restore_failure_.clear();
  retrying_ = false;
  log(options_.link_lost_verb + " (" + reason + "); dropping frames until it is back, checking every " +
      seconds_text(options_.restore_initial) + " doubling up to " + seconds_text(options_.restore_max));
}

void QueuedWriter::handle_events(short revents) {
  if ((revents & ~POLLOUT) == 0) return;
  std::uint64_t discarded = 0;
  const std::optional<std::string> lost = device_->service(revents, &discarded);
  if (discarded != 0) input_discarded_.fetch_add(discarded, std::memory_order_relaxed);
  if (lost) go_down(*lost);
}

void QueuedWriter::wait_while_down() {
  const auto deadline = std::chrono::steady_clock::now() + restore_backoff_.current();
  for (;;) {
    const auto left = deadline - std::chrono::steady_clock::now();
    if (left.count() <= 0 || stop_.load(std::memory_order_acquire)) break;
    wait(0, std::chrono::duration_cast<std::chrono::nanoseconds>(left));
  }
  if (stop_.load(std::memory_order_acquire)) return;
  std::string why;
  if (device_->try_restore(why)) {
    drop_batch_and_queue();  // frames that slipped in while the link went down
    restore_backoff_.reset();
    last_restore_failure_.clear();
    // Counted and logged before frames are accepted again, so whoever sees
    // link_up() also sees the transition reported.
    link_restored_.fetch_add(1, std::memory_order_relaxed);
    log(options_.link_restored_verb);
    link_up_.store(true, std::memory_order_release);
    return;
  }
  if (why != last_restore_failure_) {
    log("still down: " + why);
    last_restore_failure_ = why;
  }
  restore_backoff_.grow();
}

void QueuedWriter::back_off_before_retry() {
  retries_.fetch_add(1, std::memory_order_relaxed);
  const auto now = std::chrono::steady_clock::now();
  if (!retrying_) {
    retrying_ = true;
    retry_episode_logged_ = false;
    retrying_since_ = now;
  } else if (!retry_episode_logged_ && now - retrying_since_ >= kRetryEpisodeLog) {
    retry_episode_logged_ = true;
    log("the kernel has had no room for frames for " + seconds_text(now - retrying_since_) +
        " (transmit queue full: bus-off, no node acknowledging, or a bus slower than the schedule); "
        "retrying every <= " + seconds_text(options_.retry_max) + ", dropping what overflows the queue");
  }
  // Waits the whole back-off (not a busy loop), still serving device events
  // (CAN error frames) and stop requests meanwhile.
  const auto deadline = now + retry_backoff_.current();
  retry_backoff_.grow();
  for (;;) {
    const auto left = deadline - std::chrono::steady_clock::now();
    if (left.count() <= 0 || stop_.load(std::memory_order_acquire)) return;
    const short revents = wait(POLLIN, std::chrono::duration_cast<std::chrono::nanoseconds>(left));
    handle_events(revents);
    if (!link_up_.load(std::memory_order_relaxed)) return;
  }
}

// No exception leaves the writer thread (std::terminate would abort the
// daemon): the link is marked down, so every later frame is refused and
// counted (dropped_link_down), and the reason is logged once.
void QueuedWriter::run() noexcept {
  run_thread_body([this] { write_loop(); }, [this](const char* what) { writer_failed(what); });
}

void QueuedWriter::writer_failed(const char* what) noexcept {
  link_up_.store(false, std::memory_order_release);
  try {
    log(std::string("writer thread stopped by an error (frames are dropped from now on): ") + what);
  } catch (...) {
  }
}

void QueuedWriter::write_loop() {
  pthread_setname_np(pthread_self(), "imuemu-tx");
  int applied_priority = 0;
  while (!stop_.load(std::memory_order_acquire)) {
    apply_writer_priority(applied_priority);
    if (!link_up_.load(std::memory_order_relaxed)) {
      wait_while_down();
      continue;
    }
    // Replies to the driver's commands go out between two frames, never
    // inside one (a MIP parser would lose both packets).
    if (!replies_.empty() && at_frame_boundary()) {
      write_replies();
      continue;
    }
    if (next_frame_ == frame_ends_.size() && !take_batch()) {
      // Idle. Announce the sleep, then look once more: offer() pushes, then
      // checks sleeping_; with a full fence on both sides one of us sees the
      // other (no lost wake-up, no eventfd write per frame while busy).
      sleeping_.store(true, std::memory_order_relaxed);
      std::atomic_thread_fence(std::memory_order_seq_cst);
      if (queue_.read_available() > 0 || stop_.load(std::memory_order_acquire)) {
        sleeping_.store(false, std::memory_order_relaxed);
        continue;
      }
      const short revents = wait(POLLIN, std::chrono::nanoseconds(-1));
      sleeping_.store(false, std::memory_order_relaxed);
      handle_events(revents);
      continue;
    }
    // A byte stream gets everything pending in one write; a datagram device
    // one frame per write.
    // With replies waiting, only up to the end of the current frame.
    const std::size_t end =
        device_->datagrams() || !replies_.empty() ? frame_ends_[next_frame_] : batch_.size();
    const DeviceWrite result = device_->write(std::span<const std::byte>(batch_).subspan(batch_pos_, end - batch_pos_));
    switch (result.outcome) {
      case DeviceWrite::Outcome::written:
        advance(result.bytes);
        if (retrying_) {
          retrying_ = false;
          retry_backoff_.reset();
        }
        break;
      case DeviceWrite::Outcome::would_block:
        handle_events(wait(POLLIN | POLLOUT, std::chrono::nanoseconds(-1)));
        break;
      case DeviceWrite::Outcome::retry_later:
        back_off_before_retry();
        break;
      case DeviceWrite::Outcome::frame_rejected: {
        skip_current_frame();
        ++rejects_since_log_;
        const auto now = std::chrono::steady_clock::now();
        if (now - last_reject_log_ >= kRejectLogInterval) {
          log("frame refused by the kernel (" + result.reason + "); " + std::to_string(rejects_since_log_) +
              " refused since the last report");
          last_reject_log_ = now;
          rejects_since_log_ = 0;
        }
        break;
      }
      case DeviceWrite::Outcome::link_lost:
        go_down(result.reason);
        break;
    }
  }
}

}  // namespace imuemu::drivers
