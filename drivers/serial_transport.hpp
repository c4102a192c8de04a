// UART transport through libserialport: a real serial port (USB adapter,
// on-board UART) at up to 4 Mbaud where the port and its driver allow.
//
// Writes never block the emission thread (bounded queue + writer thread using
// sp_nonblocking_write; drivers/queued_writer.hpp). When the device goes away
// (USB adapter unplugged: EIO/ENXIO, or a hang-up) the port is closed, the
// loss is logged, frames are dropped and counted (dropped_link_down) while
// the schedule continues, and the port is reopened and reconfigured with
// exponential back-off (reconnect_initial doubling up to reconnect_max).
//
// libserialport 0.1.1 cannot open pseudo-terminals; use PtyTransport for
// software-in-the-loop.
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

#include "drivers/transport.hpp"

namespace imuemu::drivers {

class QueuedWriter;

enum class Parity { none, odd, even, mark, space };
enum class FlowControl { none, rts_cts, xon_xoff };

struct SerialSettings {
  int baud = 115200;  // any rate the port accepts (libserialport uses termios2 for non-standard rates)
  int data_bits = 8;  // 5..8
  Parity parity = Parity::none;
  int stop_bits = 1;  // 1 or 2
  FlowControl flow_control = FlowControl::none;
};

// Throws TransportError naming the setting when one is out of range.
void validate(const SerialSettings& settings);
// "921600 8N1, flow none"
std::string to_string(const SerialSettings& settings);
// Names as on the command line: none|odd|even|mark|space, none|rtscts|xonxoff.
// Throw TransportError listing the accepted names.
Parity parse_parity(std::string_view name);
FlowControl parse_flow_control(std::string_view name);

struct SerialTransportOptions {
  std::string port;  // e.g. /dev/ttyUSB0, /dev/ttyAMA0, /dev/serial/by-id/...
  SerialSettings settings;
  // Queue capacity; 0: 100 ms of line time at the configured rate (at least
  // 1 KiB), so a link slower than the schedule drops frames instead of
  // delivering seconds-old samples.
  std::size_t queue_bytes = 0;
  std::chrono::milliseconds reconnect_initial{100};
  std::chrono::milliseconds reconnect_max{2000};
  // Receives each log line (device lost/reopened); empty: stderr.
  std::function<void(std::string_view)> log;
};

class SerialTransport final : public Transport {
 public:
  // Opens and configures the port; throws TransportError naming the port and
  // what failed (missing, not a serial port, a pty, busy, a rate the driver
  // refuses).
  explicit SerialTransport(SerialTransportOptions options);
  ~SerialTransport() override;

  bool write_frame(std::span<const std::byte> frame) override;
  std::string describe() const override;  // "serial /dev/ttyUSB0 921600 8N1, flow none"
  TransportCounters counters() const override;
  bool link_up() const override;
  bool flush(std::chrono::milliseconds timeout) override;
  void stop(std::chrono::milliseconds drain_timeout) override;
  // What the device on the other end writes goes to `handler`; a baud change
  // it asks for (ReplySink::change_baud_after_replies) reconfigures the port
  // once the reply has left the line.
  bool set_input_handler(InputHandler* handler) override;
  std::uint32_t baud() const override;

 private:
  std::string description_;
  std::unique_ptr<QueuedWriter> writer_;
};

// A serial port as libserialport reports it (empty/nullopt where it has no
// answer, e.g. USB fields of an on-board UART).
struct SerialPortInfo {
  std::string name;         // /dev/ttyUSB0
  std::string description;  // libserialport's human-readable description
  std::string transport;    // native | usb | bluetooth
  std::optional<std::uint16_t> usb_vid, usb_pid;
  std::string usb_serial_number, usb_manufacturer, usb_product;
  std::string bluetooth_address;
};

// The serial ports libserialport finds (never ptys). Throws TransportError if
// it cannot enumerate them.
std::vector<SerialPortInfo> list_serial_ports();

}  // namespace imuemu::drivers
