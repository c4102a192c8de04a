// The one narrow interface every byte-stream transport plug-in implements
// (pty, UART, ...). Encoders produce frames; a transport only moves bytes.
// CAN has its own frame type (drivers/can_transport.hpp) and GPIO sync pulses
// are not frames (drivers/gpio_sync.hpp); both report the same counters.
#pragma once

#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <span>
#include <stdexcept>
#include <string>

namespace imuemu::drivers {

// A transport could not be opened or its options are wrong. The message
// names the device (port, interface, chip/line) and what was expected.
class TransportError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Every frame offered to a transport ends in exactly one bucket, or is
// still queued:
//   frames == frames_sent + dropped_queue_full + dropped_link_down + write_errors + queued
// (exact whenever the writer is idle; a snapshot taken while it works may be
// one frame behind).
struct TransportCounters {
  std::uint64_t frames = 0;              // frames offered to write_frame
  std::uint64_t bytes = 0;               // their bytes
  std::uint64_t frames_sent = 0;         // handed to the kernel completely
  std::uint64_t bytes_sent = 0;
  std::uint64_t dropped_queue_full = 0;  // refused: the bounded queue was full (reader or link slower than the schedule)
  std::uint64_t dropped_link_down = 0;   // refused or discarded while the link was down (device removed,
                                         // interface down or bus-off, no process reading the pty)
  std::uint64_t write_errors = 0;        // invalid frame (empty, too large, bad CAN id/length) or refused by the kernel
  std::uint64_t queued = 0;              // accepted, not yet handed to the kernel
  std::uint64_t dropped_at_stop = 0;     // still queued when the transport stopped and its bounded drain ended
  std::uint64_t link_down_events = 0;    // up -> down transitions
  std::uint64_t link_restored = 0;       // down -> up transitions
  std::uint64_t retries = 0;             // back-off retries of a frame the kernel had no room for (CAN ENOBUFS)
  std::uint64_t input_bytes_discarded = 0;  // bytes the peer sent us (commands to the emulated device), read and dropped
                                            // because no device protocol takes input on this transport
  std::uint64_t input_bytes = 0;            // bytes the peer sent us, all of them (handed to the input handler or discarded)
  std::uint64_t replies_sent = 0;           // replies (InputHandler's) handed to the kernel whole
  std::uint64_t replies_dropped = 0;        // replies refused (reply queue full) or discarded (link lost)
};

// Where an InputHandler's replies go: the transport queues them and writes
// them between two frames, never inside one. Called on the transport's io
// thread only (inside InputHandler::on_input).
class ReplySink {
 public:
  virtual ~ReplySink() = default;
  // Queues one whole reply; false (counted replies_dropped) when the bounded
  // reply queue has no room for it.
  virtual bool reply(std::span<const std::uint8_t> bytes) = 0;
  // Once every reply queued so far is handed to the kernel (and, on a UART,
  // has left the line: tcdrain), the line changes to `baud` (a device that
  // changes its rate after acknowledging the command). A pty records it.
  virtual void change_baud_after_replies(std::uint32_t baud) = 0;
};

// What a device protocol does with the bytes its driver writes (commands).
// on_input runs on the transport's io thread (its writer thread), never on
// the emission thread; it may allocate and lock.
class InputHandler {
 public:
  virtual ~InputHandler() = default;
  virtual void on_input(std::span<const std::uint8_t> bytes, ReplySink& replies) = 0;
};

// What `now` counted since `base` (a transport reused by a new emission
// engine across a reload: its counters start there). `queued` is a gauge,
// taken as is.
inline TransportCounters counters_since(const TransportCounters& now, const TransportCounters& base) noexcept {
  TransportCounters d = now;
  d.frames -= base.frames;
  d.bytes -= base.bytes;
  d.frames_sent -= base.frames_sent;
  d.bytes_sent -= base.bytes_sent;
  d.dropped_queue_full -= base.dropped_queue_full;
  d.dropped_link_down -= base.dropped_link_down;
  d.write_errors -= base.write_errors;
  d.dropped_at_stop -= base.dropped_at_stop;
  d.link_down_events -= base.link_down_events;
  d.link_restored -= base.link_restored;
  d.retries -= base.retries;
  d.input_bytes_discarded -= base.input_bytes_discarded;
  d.input_bytes -= base.input_bytes;
  d.replies_sent -= base.replies_sent;
  d.replies_dropped -= base.replies_dropped;
  return d;
}

class Transport {
 public:
  virtual ~Transport() = default;
  // Queues one encoded frame; never blocks the emission thread. Returns false
  // when the frame was not accepted (counted in one of the dropped/error
  // counters). Called from one thread at a time (the emission thread).
  virtual bool write_frame(std::span<const std::byte> frame) = 0;
  virtual std::string describe() const = 0;
  // A snapshot: a transport's writer thread updates the counters concurrently.
  virtual TransportCounters counters() const = 0;
  // False while frames are being dropped because the device or reader is gone.
  virtual bool link_up() const { return true; }
  // Waits until every accepted frame has been handed to the kernel (or
  // dropped); false on timeout. For an orderly shutdown, not the emission path.
  virtual bool flush(std::chrono::milliseconds timeout) {
    (void)timeout;
    return true;
  }
  // End of use: a bounded drain (at most drain_timeout), then what is still
  // queued is discarded and counted (TransportCounters::dropped_at_stop);
  // counters() stays readable. No write_frame afterwards.
  virtual void stop(std::chrono::milliseconds drain_timeout) { flush(drain_timeout); }
  // Hands what the peer writes to `handler` from now on (nullptr: read and
  // discard again). The handler must stay valid until it is replaced; this
  // call returns only when the io thread is no longer inside the previous
  // one. False: this transport has no input (null, CAN frames elsewhere).
  // Not the emission thread.
  virtual bool set_input_handler(InputHandler* handler) {
    (void)handler;
    return false;
  }
  // The line rate the transport runs at now (a UART after a baud change; a
  // pty the rate its peer was last told); 0: not a serial line.
  virtual std::uint32_t baud() const { return 0; }
};

// Discards frames, counting them as sent: for timing benchmarks and dry runs.
// Counted with relaxed atomics: write_frame runs on the emission thread while
// counters() is read by the status socket.
class NullTransport final : public Transport {
 public:
  bool write_frame(std::span<const std::byte> frame) override {
    frames_.fetch_add(1, std::memory_order_relaxed);
    bytes_.fetch_add(frame.size(), std::memory_order_relaxed);
    return true;
  }
  std::string describe() const override { return "null"; }
  TransportCounters counters() const override {
    TransportCounters c;
    c.frames = c.frames_sent = frames_.load(std::memory_order_relaxed);
    c.bytes = c.bytes_sent = bytes_.load(std::memory_order_relaxed);
    return c;
  }

 private:
  std::atomic<std::uint64_t> frames_{0}, bytes_{0};
};

}  // namespace imuemu::drivers
