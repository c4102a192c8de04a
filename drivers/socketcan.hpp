// SocketCAN (Linux CAN_RAW sockets, Documentation/networking/can.rst):
// CanTransport sends the frames a CAN encoder produces (classic CAN and
// CAN FD, 11/29-bit ids); CanReader receives them with kernel timestamps for
// `imuemu listen`.
//
// CanTransport's send() never blocks the emission thread: frames go into a
// bounded queue a writer thread drains (drivers/queued_writer.hpp).
//  - ENOBUFS (the interface's transmit queue is full): the frame stays at the
//    head of the queue and is retried after a back-off (retry_initial
//    doubling up to retry_max; counted in `retries`, logged after 1 s of it);
//    what overflows the queue meanwhile is dropped and counted.
//  - Interface down (ENETDOWN, also reported asynchronously by the socket),
//    removed (ENODEV) or bus-off (a controller error frame): the link is down
//    (counted, logged); frames are dropped and counted (dropped_link_down)
//    rather than queued stale; the interface is checked and the socket
//    reopened with back-off (restore_initial doubling up to restore_max)
//    until it is up and running again.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/types.hpp"
#include "drivers/protocol.hpp"
#include "drivers/transport.hpp"

namespace imuemu::drivers {

class QueuedWriter;

struct CanTransportOptions {
  std::string interface;          // e.g. can0, vcan0
  bool fd_frames = false;         // allow CAN FD frames (CAN_RAW_FD_FRAMES; the interface needs MTU 72)
  bool fd_bitrate_switch = true;  // CANFD_BRS on FD frames (data phase at the second bit rate)
  std::size_t queue_frames = 256;
  std::chrono::nanoseconds retry_initial{std::chrono::microseconds(200)};  // ENOBUFS back-off
  std::chrono::nanoseconds retry_max{std::chrono::milliseconds(20)};
  std::chrono::milliseconds restore_initial{100};  // interface down / bus-off back-off
  std::chrono::milliseconds restore_max{2000};
  // Receives each log line; empty: stderr.
  std::function<void(std::string_view)> log;
  // The requests the device answers (CanCommandResponder::receive_filters):
  // the socket receives exactly these data frames (none when empty), plus
  // the bus-off / restarted error frames.
  std::vector<CanReceiveFilter> receive_filters;
};

class CanTransport {
 public:
  // Throws TransportError naming the interface: no such interface, not a CAN
  // interface, no CAN FD MTU while fd_frames, no SocketCAN in the kernel. An
  // interface that exists but is down is not an error: the link starts down.
  explicit CanTransport(CanTransportOptions options);
  ~CanTransport();
  CanTransport(const CanTransport&) = delete;
  CanTransport& operator=(const CanTransport&) = delete;

  // Queues one frame; never blocks. False (and counted) when the frame is
  // invalid (write_errors), the link is down or the queue is full.
  bool send(const CanFrame& frame);
  std::string describe() const;  // "socketcan vcan0 (CAN FD)"
  TransportCounters counters() const;
  bool link_up() const;
  bool flush(std::chrono::milliseconds timeout);
  void stop(std::chrono::milliseconds drain_timeout);  // Transport::stop
  // Hands each received frame (those the receive filters let through) to
  // `responder` on the writer (io) thread from now on; its replies are
  // queued and written between the device's own frames. nullptr: received
  // frames are read and discarded again. Returns once the io thread is no
  // longer inside the previous responder. Not the emission thread.
  void set_command_responder(CanCommandResponder* responder);

 private:
  class FrameInput;
  CanTransportOptions options_;
  std::string description_;
  std::unique_ptr<QueuedWriter> writer_;
  std::unique_ptr<FrameInput> input_;
};

struct ReceivedCanFrame {
  CanFrame frame;
  // When the kernel received the frame (SO_TIMESTAMPNS: CLOCK_REALTIME, ns
  // since the Unix epoch); 0 if the kernel gave none.
  TimeNs kernel_receive_realtime_ns = 0;
};

struct CanReaderCounters {
  std::uint64_t frames = 0;           // frames returned by receive()
  std::uint64_t ignored_frames = 0;   // remote-request frames (no CanFrame form)
  std::uint64_t kernel_drops = 0;     // frames the socket's receive queue dropped (SO_RXQ_OVFL)
  std::uint64_t interface_down = 0;   // times the interface went down (the socket receives again once it is up)
};

class CanReader {
 public:
  // `fd_frames`: also receive CAN FD frames. Throws TransportError naming the
  // interface (as CanTransport).
  explicit CanReader(const std::string& interface, bool fd_frames = true);
  ~CanReader();
  CanReader(const CanReader&) = delete;
  CanReader& operator=(const CanReader&) = delete;

  // The next frame, or nullopt after `timeout` without one. The interface
  // going down is counted (interface_down), not an error; throws
  // TransportError if it is removed.
  std::optional<ReceivedCanFrame> receive(std::chrono::milliseconds timeout);
  const CanReaderCounters& counters() const noexcept { return counters_; }
  std::string describe() const;

 private:
  std::string interface_;
  int socket_ = -1;
  CanReaderCounters counters_;
};

}  // namespace imuemu::drivers
