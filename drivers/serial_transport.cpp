#include "drivers/serial_transport.hpp"

#include <fcntl.h>
#include <poll.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <termios.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstdio>

#include "drivers/queued_writer.hpp"
#include "drivers/serial_port.hpp"

namespace imuemu::drivers {
namespace {

sp_parity to_sp(Parity parity) {
  switch (parity) {
    case Parity::none: return SP_PARITY_NONE;
    case Parity::odd: return SP_PARITY_ODD;
    case Parity::even: return SP_PARITY_EVEN;
    case Parity::mark: return SP_PARITY_MARK;
    case Parity::space: return SP_PARITY_SPACE;
  }
  return SP_PARITY_NONE;
}

sp_flowcontrol to_sp(FlowControl flow) {
  switch (flow) {
    case FlowControl::none: return SP_FLOWCONTROL_NONE;
    case FlowControl::rts_cts: return SP_FLOWCONTROL_RTSCTS;
    case FlowControl::xon_xoff: return SP_FLOWCONTROL_XONXOFF;
  }
  return SP_FLOWCONTROL_NONE;
}

const char* flow_name(FlowControl flow) {
  switch (flow) {
    case FlowControl::none: return "none";
    case FlowControl::rts_cts: return "rtscts";
    case FlowControl::xon_xoff: return "xonxoff";
  }
  return "?";
}

char parity_letter(Parity parity) {
  switch (parity) {
    case Parity::none: return 'N';
    case Parity::odd: return 'O';
    case Parity::even: return 'E';
    case Parity::mark: return 'M';
    case Parity::space: return 'S';
  }
  return '?';
}

// libserialport keeps these strings in the port structure (not ours to free).
std::string copy_or_empty(const char* text) { return text ? std::string(text) : std::string(); }

// Bytes the line carries in 100 ms: start bit, data bits, parity, stop bits per byte.
std::size_t line_time_queue_bytes(const SerialSettings& s) {
  const int bits_per_byte = 1 + s.data_bits + (s.parity == Parity::none ? 0 : 1) + s.stop_bits;
  const auto bytes = static_cast<std::size_t>(s.baud / bits_per_byte / 10);
  return std::max<std::size_t>(bytes, 1024);
}

// The device side of a SerialTransport, as the queued writer sees it.
class SerialDevice final : public WriterDevice {
 public:
  SerialDevice(SerialPortHandle port, std::string path, SerialSettings settings)
      : port_(std::move(port)), fd_(serial_port_fd(port_.get())), path_(std::move(path)), settings_(settings) {}

  bool datagrams() const override { return false; }
  int poll_fd() const override { return fd_; }

  DeviceWrite write(std::span<const std::byte> bytes) override {
    // libserialport returns byte counts through its enum return type:
    // converted to int at once, never held as an out-of-range sp_return.
    const int result = static_cast<int>(sp_nonblocking_write(port_.get(), bytes.data(), bytes.size()));
    if (result > 0) return {DeviceWrite::Outcome::written, static_cast<std::size_t>(result), {}};
    if (result == 0) return {DeviceWrite::Outcome::would_block, 0, {}};
    if (result == SP_ERR_FAIL && (sp_last_error_code() == EAGAIN || sp_last_error_code() == EINTR)) {
      return {DeviceWrite::Outcome::would_block, 0, {}};
    }
    // EIO/ENXIO/ENODEV after a USB adapter is unplugged; anything else on a
    // serial write also means the port needs reopening.
    return {DeviceWrite::Outcome::link_lost, 0, "write failed: " + serial_error_text(static_cast<sp_return>(result))};
  }

  std::optional<std::string> service(short revents, std::uint64_t* discarded_bytes) override {
    if (revents & POLLIN) {
      std::array<std::byte, 4096> sink;
      for (;;) {
        const int result = static_cast<int>(sp_nonblocking_read(port_.get(), sink.data(), sink.size()));
        if (result == 0) break;
        if (result < 0) return "read failed: " + serial_error_text(static_cast<sp_return>(result));
        deliver_input(std::span<const std::byte>(sink.data(), static_cast<std::size_t>(result)), discarded_bytes);
      }
    }
    if (revents & (POLLHUP | POLLERR | POLLNVAL)) return std::string("the device hung up (unplugged?)");
    return std::nullopt;
  }

  void on_link_lost() override {
    port_.reset();
    fd_ = -1;
  }

  bool set_baud(std::uint32_t baud, std::string& why) override {
    // The reply (the ACK) leaves the line at the old rate first, as the
    // device sends it (tcdrain: until the UART's shift register is empty).
    if (fd_ >= 0) ::tcdrain(fd_);
    if (port_) {
      const sp_return r = sp_set_baudrate(port_.get(), static_cast<int>(baud));
      if (r != SP_OK) {
        why = serial_error_text(r);
        return false;
      }
    }
    settings_.baud = static_cast<int>(baud);  // a reopen after a device loss keeps it
    return true;
  }

  bool try_restore(std::string& why) override {
    try {
      port_ = open_serial_port(path_, settings_, SP_MODE_READ_WRITE);
      fd_ = serial_port_fd(port_.get());
      return true;
    } catch (const TransportError& e) {
      why = e.what();
      return false;
    }
  }

  bool initially_up() const override { return true; }

 private:
  SerialPortHandle port_;
  int fd_;
  std::string path_;
  SerialSettings settings_;
};

}  // namespace

void validate(const SerialSettings& s) {
  if (s.baud <= 0) throw TransportError("serial: baud rate " + std::to_string(s.baud) + " must be positive");
  if (s.data_bits < 5 || s.data_bits > 8) {
    throw TransportError("serial: " + std::to_string(s.data_bits) + " data bits; expected 5, 6, 7 or 8");
  }
  if (s.stop_bits != 1 && s.stop_bits != 2) {
    throw TransportError("serial: " + std::to_string(s.stop_bits) + " stop bits; expected 1 or 2");
  }
}

std::string to_string(const SerialSettings& s) {
  return std::to_string(s.baud) + " " + std::to_string(s.data_bits) + parity_letter(s.parity) +
         std::to_string(s.stop_bits) + ", flow " + flow_name(s.flow_control);
}

Parity parse_parity(std::string_view name) {
  if (name == "none") return Parity::none;
  if (name == "odd") return Parity::odd;
  if (name == "even") return Parity::even;
  if (name == "mark") return Parity::mark;
  if (name == "space") return Parity::space;
  throw TransportError("serial: parity '" + std::string(name) + "'; expected none, odd, even, mark or space");
}

FlowControl parse_flow_control(std::string_view name) {
  if (name == "none") return FlowControl::none;
  if (name == "rtscts") return FlowControl::rts_cts;
  if (name == "xonxoff") return FlowControl::xon_xoff;
  throw TransportError("serial: flow control '" + std::string(name) + "'; expected none, rtscts or xonxoff");
}

std::string serial_error_text(sp_return result) {
  switch (result) {
    case SP_ERR_FAIL: {
      char* message = sp_last_error_message();
      std::string text = message ? message : "unknown system error";
      sp_free_error_message(message);
      return text;
    }
    case SP_ERR_ARG: return "invalid argument";
    case SP_ERR_MEM: return "out of memory";
    case SP_ERR_SUPP: return "not supported by this port or driver";
    case SP_OK: return "ok";
  }
  return "libserialport error " + std::to_string(static_cast<int>(result));
}

bool is_pty_slave(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0 || !S_ISCHR(st.st_mode)) return false;
  // Documentation/admin-guide/devices.txt: 136-143 char = Unix98 PTY slaves.
  const unsigned major_number = major(st.st_rdev);
  return major_number >= 136 && major_number <= 143;
}

int serial_port_fd(sp_port* port) {
  int fd = -1;
  if (sp_get_port_handle(port, &fd) != SP_OK) return -1;
  return fd;
}

SerialPortHandle open_serial_port(const std::string& path, const SerialSettings& settings, sp_mode mode,
                                  std::string* applied) {
  validate(settings);
  const std::string where = "serial port " + path;
  sp_port* raw = nullptr;
  if (sp_get_port_by_name(path.c_str(), &raw) != SP_OK) {
    struct stat st {};
    if (::stat(path.c_str(), &st) != 0) throw TransportError(where + ": not found (" + errno_message(errno) + ")");
    if (is_pty_slave(path)) {
      throw TransportError(where + " is a pseudo-terminal, which libserialport 0.1.1 cannot open; "
                           "use the pty transport (or read it with the termios reader)");
    }
    throw TransportError(where + ": libserialport does not recognise it as a serial port");
  }
  const sp_return opened = sp_open(raw, mode);
  if (opened != SP_OK) {
    const int error = opened == SP_ERR_FAIL ? sp_last_error_code() : 0;
    std::string why = serial_error_text(opened);
    sp_free_port(raw);
    if (error == EACCES) why += " (is the user in the port's group, usually dialout?)";
    if (error == EBUSY) why += " (another process has it open exclusively)";
    throw TransportError(where + ": cannot open: " + why);
  }
  SerialPortHandle port(raw);
  const auto check = [&](sp_return result, const std::string& what) {
    if (result != SP_OK) throw TransportError(where + ": cannot set " + what + ": " + serial_error_text(result));
  };
  check(sp_set_baudrate(port.get(), settings.baud),
        std::to_string(settings.baud) + " baud (does the port and its driver support this rate?)");
  check(sp_set_bits(port.get(), settings.data_bits), std::to_string(settings.data_bits) + " data bits");
  check(sp_set_parity(port.get(), to_sp(settings.parity)), std::string("parity ") + parity_letter(settings.parity));
  check(sp_set_stopbits(port.get(), settings.stop_bits), std::to_string(settings.stop_bits) + " stop bits");
  check(sp_set_flowcontrol(port.get(), to_sp(settings.flow_control)),
        std::string("flow control ") + flow_name(settings.flow_control));
  const int fd = serial_port_fd(port.get());
  if (fd < 0 || ::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) | O_NONBLOCK) != 0) {
    throw TransportError(where + ": cannot make the descriptor non-blocking");
  }
  if (applied) {
    // A driver may round a rate it cannot divide down to exactly.
    sp_port_config* config = nullptr;
    int actual = 0;
    if (sp_new_config(&config) == SP_OK) {
      if (sp_get_config(port.get(), config) == SP_OK && sp_get_config_baudrate(config, &actual) == SP_OK &&
          actual != settings.baud) {
        *applied = "the driver reports " + std::to_string(actual) + " baud (asked for " + std::to_string(settings.baud) + ")";
      }
      sp_free_config(config);
    }
  }
  return port;
}

SerialTransport::SerialTransport(SerialTransportOptions options) {
  std::string applied;
  SerialPortHandle port = open_serial_port(options.port, options.settings, SP_MODE_READ_WRITE, &applied);
  description_ = "serial " + options.port + " " + to_string(options.settings);
  if (!applied.empty()) emit_log(options.log, description_ + ": " + applied);
  QueuedWriterOptions writer;
  writer.name = description_;
  writer.queue_bytes = options.queue_bytes != 0 ? options.queue_bytes : line_time_queue_bytes(options.settings);
  writer.restore_initial = options.reconnect_initial;
  writer.restore_max = options.reconnect_max;
  writer.link_lost_verb = "device lost";
  writer.link_restored_verb = "device reopened";
  writer.log = std::move(options.log);
  writer.baud = static_cast<std::uint32_t>(options.settings.baud);
  writer_ = std::make_unique<QueuedWriter>(
      std::make_unique<SerialDevice>(std::move(port), options.port, options.settings), std::move(writer));
}

SerialTransport::~SerialTransport() = default;

bool SerialTransport::write_frame(std::span<const std::byte> frame) { return writer_->offer(frame); }
bool SerialTransport::set_input_handler(InputHandler* handler) {
  writer_->set_input_handler(handler);
  return true;
}
std::uint32_t SerialTransport::baud() const { return writer_->baud(); }
std::string SerialTransport::describe() const { return description_; }
TransportCounters SerialTransport::counters() const { return writer_->counters(); }
bool SerialTransport::link_up() const { return writer_->link_up(); }
bool SerialTransport::flush(std::chrono::milliseconds timeout) { return writer_->flush(timeout); }
void SerialTransport::stop(std::chrono::milliseconds drain_timeout) { writer_->stop(drain_timeout); }

std::vector<SerialPortInfo> list_serial_ports() {
  sp_port** ports = nullptr;
  const sp_return listed = sp_list_ports(&ports);
  if (listed != SP_OK) throw TransportError("listing serial ports: " + serial_error_text(listed));
  std::vector<SerialPortInfo> result;
  for (sp_port** p = ports; *p != nullptr; ++p) {
    SerialPortInfo info;
    info.name = copy_or_empty(sp_get_port_name(*p));
    info.description = copy_or_empty(sp_get_port_description(*p));
    switch (sp_get_port_transport(*p)) {
      case SP_TRANSPORT_NATIVE: info.transport = "native"; break;
      case SP_TRANSPORT_USB: info.transport = "usb"; break;
      case SP_TRANSPORT_BLUETOOTH: info.transport = "bluetooth"; break;
    }
    int vid = 0, pid = 0;
    if (sp_get_port_usb_vid_pid(*p, &vid, &pid) == SP_OK) {
      info.usb_vid = static_cast<std::uint16_t>(vid);
      info.usb_pid = static_cast<std::uint16_t>(pid);
    }
    info.usb_serial_number = copy_or_empty(sp_get_port_usb_serial(*p));
    info.usb_manufacturer = copy_or_empty(sp_get_port_usb_manufacturer(*p));
    info.usb_product = copy_or_empty(sp_get_port_usb_product(*p));
    info.bluetooth_address = copy_or_empty(sp_get_port_bluetooth_address(*p));
    result.push_back(std::move(info));
  }
  sp_free_port_list(ports);
  return result;
}

}  // namespace imuemu::drivers
