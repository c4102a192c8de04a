// The machinery behind every queued transport (pty, UART, SocketCAN): a
// bounded lock-free queue filled by the emission thread and drained by one
// writer thread per transport, which owns the device, waits on it, backs off
// and reconnects. Internal to drivers/ (the transports' public headers hide
// it); tests drive it with fake devices.
//
// Why a writer thread rather than flushing from the emission thread:
//  - the emission thread's cost per frame is a bounds check and one memcpy
//    into a lock-free single-producer/single-consumer ring
//    (boost::lockfree::spsc_queue), plus an eventfd write only when the
//    writer sleeps: no lock it could wait on, no system call that can block,
//    whatever the device does;
//  - back-off sleeps (CAN ENOBUFS, reconnecting a removed UART, probing a
//    pty for a reader) happen on the writer thread while the schedule goes on;
//  - the queue drains as soon as the device can take bytes, not once per
//    sample period.
//
// Frames are queued whole and dropped whole at the queue's entrance (newest
// first: the frame being offered is refused), so a byte stream never carries
// a partial frame because of an overflow. Only a device loss can cut a
// frame, and that frame is counted as dropped.
//
// Link state: while the link is down (device removed, interface down or
// bus-off, nobody reading the pty) write_frame refuses frames at once
// (dropped_link_down) instead of letting the queue fill with stale samples;
// the writer probes/reopens the device with exponential back-off and logs
// each transition once.
#pragma once

#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include <boost/lockfree/spsc_queue.hpp>

#include "drivers/transport.hpp"

namespace imuemu::drivers {

// What one write attempt did.
struct DeviceWrite {
  enum class Outcome {
    written,         // `bytes` accepted (a datagram device accepts a whole frame or nothing)
    would_block,     // nothing accepted; wait for POLLOUT on poll_fd()
    retry_later,     // nothing accepted and polling would not help (CAN ENOBUFS): back off, retry the frame
    frame_rejected,  // the kernel refused this frame (EINVAL, EMSGSIZE): drop it, count a write error
    link_lost,       // the device is gone or down: drop queued frames, reconnect with back-off
  };
  Outcome outcome = Outcome::written;
  std::size_t bytes = 0;
  std::string reason;  // for rejected / lost: what the kernel said
};

// Where a device's input goes (QueuedWriter: to the transport's
// InputHandler). The writer thread only.
class InputTap {
 public:
  virtual ~InputTap() = default;
  virtual void input(std::span<const std::byte> bytes) = 0;
};

// The device side of a queued transport. All calls come from the writer
// thread, except the constructor/destructor.
class WriterDevice {
 public:
  virtual ~WriterDevice() = default;
  // Set once by the QueuedWriter that owns the device, before its thread starts.
  void set_input_tap(InputTap* tap) noexcept { tap_ = tap; }
  // Changes the line rate (a UART, after the replies before it left the
  // line); a pty only records it. False with `why` when the port refused.
  virtual bool set_baud(std::uint32_t baud, std::string& why) {
    (void)baud;
    (void)why;
    return true;
  }
  // True: each write() is one whole frame (CAN); false: a byte stream that
  // may accept part of what it is given.
  virtual bool datagrams() const = 0;
  // File descriptor to poll (POLLOUT when would_block; POLLIN for input and
  // error frames; POLLHUP/POLLERR); -1 while closed.
  virtual int poll_fd() const = 0;
  virtual DeviceWrite write(std::span<const std::byte> bytes) = 0;
  // Handles poll events other than POLLOUT: reads and discards input
  // (adding to *discarded_bytes), reads error frames. Returns the reason when
  // the events mean the link is lost (hang-up, error, bus-off).
  virtual std::optional<std::string> service(short revents, std::uint64_t* discarded_bytes) = 0;
  // The link was lost: close the device or flush its stale bytes.
  virtual void on_link_lost() = 0;
  // Probes (pty: is a reader there?) or reopens (UART, CAN) the device.
  // True when the link is usable again; otherwise `why` says what is wrong.
  virtual bool try_restore(std::string& why) = 0;
  // Link state at start.
  virtual bool initially_up() const = 0;

 protected:
  // What service() read from the peer: to the tap (the transport's input
  // handler), or counted in *discarded_bytes without one.
  void deliver_input(std::span<const std::byte> bytes, std::uint64_t* discarded_bytes) {
    if (tap_ != nullptr) tap_->input(bytes);
    else *discarded_bytes += bytes.size();
  }

 private:
  InputTap* tap_ = nullptr;
};

struct QueuedWriterOptions {
  std::string name;                   // prefix of log lines, e.g. "pty /dev/pts/3"
  // Queue capacity (each frame also takes 4 bytes of length). What waits for
  // the device is at most this, plus the batch being written (4 KiB for a
  // byte stream, one frame for datagrams), plus the kernel's own buffer.
  std::size_t queue_bytes = 32 * 1024;
  // Waiting for a lost link to come back: first wait, doubled after each
  // failed attempt up to the maximum.
  std::chrono::nanoseconds restore_initial{std::chrono::milliseconds(100)};
  std::chrono::nanoseconds restore_max{std::chrono::seconds(2)};
  // Retrying a frame the kernel had no room for (retry_later).
  std::chrono::nanoseconds retry_initial{std::chrono::microseconds(200)};
  std::chrono::nanoseconds retry_max{std::chrono::milliseconds(20)};
  // What the log lines call the link going away / coming back.
  std::string link_lost_verb = "link lost";
  std::string link_restored_verb = "link restored";
  // Receives each log line (without '\n'); empty: written to stderr.
  std::function<void(std::string_view)> log;
  // stop() without an argument (and the destructor) first lets the writer
  // hand what is queued to the device for at most this long.
  std::chrono::milliseconds stop_drain{200};
  // The line rate at start (a UART's; a pty's nominal one), for baud().
  std::uint32_t baud = 0;
  // Replies (InputHandler's) waiting to be written between frames, at most.
  std::size_t reply_queue_bytes = 8 * 1024;
};

// Exponential back-off: current() starts at `initial`, grow() doubles it up
// to `max`, reset() starts over.
class Backoff {
 public:
  Backoff(std::chrono::nanoseconds initial, std::chrono::nanoseconds max) : initial_(initial), max_(max), current_(initial) {}
  std::chrono::nanoseconds current() const noexcept { return current_; }
  void grow() noexcept { current_ = current_ >= max_ / 2 ? max_ : current_ * 2; }
  void reset() noexcept { current_ = initial_; }

 private:
  std::chrono::nanoseconds initial_, max_, current_;
};

class QueuedWriter final : private InputTap, private ReplySink {
 public:
  // Starts the writer thread. Throws TransportError on bad options.
  QueuedWriter(std::unique_ptr<WriterDevice> device, QueuedWriterOptions options);
  ~QueuedWriter();  // stop()
  QueuedWriter(const QueuedWriter&) = delete;
  QueuedWriter& operator=(const QueuedWriter&) = delete;

  // Emission thread (single producer). Never blocks.
  bool offer(std::span<const std::byte> frame);
  // Counts a frame the caller found invalid before offering it.
  void count_invalid_frame();

  TransportCounters counters() const;
  bool link_up() const noexcept { return link_up_.load(std::memory_order_acquire); }
  bool flush(std::chrono::milliseconds timeout) const;
  std::size_t max_frame_bytes() const noexcept { return max_frame_bytes_; }
  // Bounded drain, then the thread stops: the writer goes on handing queued
  // frames to the device until none is left, the link is down or
  // drain_timeout has passed; what is still queued then is discarded and
  // counted (TransportCounters::dropped_at_stop, logged once), so every
  // accepted frame ends in exactly one counter. offer() must no longer be
  // called. Idempotent (a second call does nothing).
  void stop(std::chrono::milliseconds drain_timeout);
  void stop() { stop(options_.stop_drain); }
  // Transport::set_input_handler: what the device reads goes to `handler`
  // (on the writer thread); returns once the writer is not inside the old one.
  void set_input_handler(InputHandler* handler);
  std::uint32_t baud() const noexcept { return baud_.load(std::memory_order_relaxed); }

 private:
  // InputTap: the device read `bytes` from the peer (writer thread).
  void input(std::span<const std::byte> bytes) override;
  // ReplySink (writer thread, inside the handler).
  bool reply(std::span<const std::uint8_t> bytes) override;
  void change_baud_after_replies(std::uint32_t baud) override;
  // Replies are written only where a frame ends (or none is under way).
  bool at_frame_boundary() const noexcept;
  void write_replies();
  void drop_replies();
  void run() noexcept;
  void write_loop();
  void writer_failed(const char* what) noexcept;
  void log(std::string_view line) const;
  void signal_wake() const noexcept;
  bool take_batch();                   // moves queued frames into batch_; false if none
  void advance(std::size_t bytes);     // bytes of batch_ the device accepted
  void skip_current_frame();           // the device rejected it
  void drop_batch_and_queue();         // link down: every unfinished frame counts as dropped
  void go_down(const std::string& reason);
  void handle_events(short revents);   // device events other than POLLOUT
  void wait_while_down();
  void back_off_before_retry();
  // Waits for device events (and the wake-up eventfd) up to `timeout`
  // (negative: no limit). Returns the device's revents (0 on timeout/wake).
  short wait(short device_events, std::chrono::nanoseconds timeout);

  std::unique_ptr<WriterDevice> device_;
  QueuedWriterOptions options_;
  std::size_t max_frame_bytes_ = 0;

  // Producer side (emission thread only).
  boost::lockfree::spsc_queue<std::byte> queue_;
  std::vector<std::byte> scratch_;  // length prefix + frame, pushed in one call so the writer sees it whole

  // Writer side (writer thread only).
  std::vector<std::byte> batch_;         // frame payloads back to back
  std::vector<std::size_t> frame_ends_;  // end offset of each frame in batch_
  std::size_t batch_pos_ = 0;            // bytes of batch_ handed to the device
  std::size_t next_frame_ = 0;           // first frame of batch_ not completely handed over
  Backoff restore_backoff_;
  Backoff retry_backoff_;
  std::string last_restore_failure_;
  std::chrono::steady_clock::time_point retrying_since_{};  // first retry_later of the current episode
  bool retrying_ = false, retry_episode_logged_ = false;
  std::chrono::steady_clock::time_point last_reject_log_{};
  std::uint64_t rejects_since_log_ = 0;

  int wake_fd_ = -1;  // eventfd: data queued while the writer slept, or stop
  std::atomic<bool> sleeping_{false};
  std::atomic<bool> stop_{false};
  std::atomic<bool> link_up_{false};
  std::thread thread_;

  // Counters (relaxed atomics: both threads add to them). accepted_ counts
  // frames that entered the queue, finished_ those the writer is done with
  // (sent, dropped after acceptance, rejected by the kernel).
  std::atomic<std::uint64_t> frames_{0}, bytes_{0}, accepted_{0}, finished_{0};
  std::atomic<std::uint64_t> frames_sent_{0}, bytes_sent_{0};
  std::atomic<std::uint64_t> dropped_queue_full_{0}, dropped_link_down_{0}, write_errors_{0};
  std::atomic<std::uint64_t> link_down_events_{0}, link_restored_{0}, retries_{0}, input_discarded_{0};
  std::atomic<std::uint64_t> dropped_at_stop_{0};

  // Input and replies. The handler is swapped under the mutex (control
  // thread) and called under it (writer thread); the emission thread never
  // touches either.
  std::mutex handler_mutex_;
  InputHandler* handler_ = nullptr;
  std::vector<std::byte> replies_;         // writer thread: whole replies back to back
  std::vector<std::size_t> reply_ends_;    // end offset of each reply in replies_
  std::size_t replies_pos_ = 0;            // bytes of replies_ handed to the device
  std::size_t next_reply_ = 0;             // first reply not completely handed over
  // A line-rate change the device asked for (change_baud_after_replies),
  // and the offset in replies_ where it happens: the end of the reply queued
  // next (the ACK the device is building when it asks), so that a reply
  // queued later (the next command's, arriving while the ACK is still being
  // written) leaves at the new rate, as on the real part. Unset offset: no
  // reply followed; the change waits for the queue to drain.
  std::optional<std::uint32_t> baud_after_replies_;
  std::optional<std::size_t> baud_change_at_;
  std::atomic<std::uint64_t> input_bytes_{0}, replies_sent_{0}, replies_dropped_{0};
  std::atomic<std::uint32_t> baud_{0};
};

// Issue 17 (latency): the SCHED_FIFO priority of every queued writer's
// thread (1..99; 0: normal scheduling), process-wide. Each writer applies a
// change at its next wake-up (its next frame). The emission engine sets it
// from [daemon] realtime_priority, so the bytes of a sample leave for the
// kernel as promptly as the emission thread queued them.
void set_writer_threads_realtime_priority(int priority) noexcept;

// strerror for messages (thread-safe).
std::string errno_message(int error);

// Writes a log line through `sink`, or to stderr (the project's log line,
// log/log.hpp, warning) when it is empty.
void emit_log(const std::function<void(std::string_view)>& sink, std::string_view line);

// A thread's body: an exception that would leave it (std::terminate) goes to
// `failed` with its message instead. `failed` must not throw.
void run_thread_body(const std::function<void()>& body, const std::function<void(const char*)>& failed) noexcept;

}  // namespace imuemu::drivers
