// Virtual serial port for software-in-the-loop: imuemu opens a pseudo-terminal
// pair itself (openpty, raw termios) and publishes the slave under a stable
// symlink (e.g. /run/imuemu/ttyIMU0) that the driver under test opens like a
// UART. No hardware and no socat needed.
//
// Writes never block the emission thread: frames go into a bounded queue that
// a writer thread drains into the master (drivers/queued_writer.hpp).
// Where bytes go, by reader state:
//  - a reader has the slave open and reads: frames arrive whole and in order;
//  - a reader has it open but stalls: the kernel's pty buffer fills (about
//    16-18 KB on Linux 6.1), then imuemu's queue (queue_bytes), then new
//    frames are refused whole and counted (dropped_queue_full); once the
//    reader resumes it sees whole frames with a gap, never a cut frame;
//  - nobody has the slave open (before the first reader, after it closed):
//    the link is "down" like a UART with no cable: frames are dropped and
//    counted (dropped_link_down), nothing accumulates, and the bytes a
//    departed reader left unread are flushed, so the next reader starts with
//    fresh samples instead of seconds-old ones. The writer checks for a
//    reader every reader_probe_interval (the first frames after a reader
//    opens the slave can be lost within that interval).
// Bytes the reader writes (commands to the emulated device) are read on the
// writer thread and handed to the device's input handler
// (set_input_handler), whose replies go out between frames; without one they
// are discarded (input_bytes_discarded), so the reader never blocks.
#pragma once

#include <chrono>
#include <cstddef>
#include <functional>
#include <memory>
#include <string>
#include <string_view>

#include "drivers/transport.hpp"

namespace imuemu::drivers {

class QueuedWriter;

struct PtyTransportOptions {
  // Symlink to the slave, e.g. /run/imuemu/ttyIMU0. Its directory is created;
  // a symlink already there is replaced unless another live imuemu holds it
  // (a lock file "<link>.lock" next to it says so); anything that is not a
  // symlink is never replaced. Removed on close. Empty: no symlink.
  std::string link_path;
  std::size_t queue_bytes = 32 * 1024;
  std::chrono::milliseconds reader_probe_interval{20};
  // Permission bits for the slave, e.g. 0660 or 0666 so that another user
  // (the driver under test) may open it; 0 keeps openpty's (owner rw, group tty w).
  unsigned slave_mode = 0;
  // Receives each log line (reader connected/gone); empty: stderr.
  std::function<void(std::string_view)> log;
};

class PtyTransport final : public Transport {
 public:
  // Throws TransportError naming the link path or the failing call.
  explicit PtyTransport(PtyTransportOptions options);
  ~PtyTransport() override;  // stops the writer, closes the pty, removes the symlink

  bool write_frame(std::span<const std::byte> frame) override;
  std::string describe() const override;  // "pty /dev/pts/3 (/run/imuemu/ttyIMU0)"
  TransportCounters counters() const override;
  bool link_up() const override;  // a process has the slave open
  bool flush(std::chrono::milliseconds timeout) override;
  void stop(std::chrono::milliseconds drain_timeout) override;
  bool set_input_handler(InputHandler* handler) override;
  std::uint32_t baud() const override;

  const std::string& slave_path() const noexcept { return slave_path_; }
  const std::string& link_path() const noexcept { return link_path_; }

 private:
  class PublishedLink;
  std::string slave_path_;
  std::string link_path_;
  std::unique_ptr<PublishedLink> link_;
  std::unique_ptr<QueuedWriter> writer_;
};

}  // namespace imuemu::drivers
