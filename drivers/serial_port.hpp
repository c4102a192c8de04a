// Internal to drivers/: opening and configuring a port through libserialport,
// shared by SerialTransport and ByteStreamReader.
#pragma once

#include <libserialport.h>

#include <memory>
#include <string>

#include "drivers/serial_transport.hpp"

namespace imuemu::drivers {

struct SerialPortCloser {
  void operator()(sp_port* port) const noexcept {
    sp_close(port);
    sp_free_port(port);
  }
};
using SerialPortHandle = std::unique_ptr<sp_port, SerialPortCloser>;

// Opens `path` with libserialport in `mode`, applies `settings` one by one
// (so an error names the setting the port refused) and makes the descriptor
// non-blocking. `applied` receives a note when the driver rounded the baud
// rate. Throws TransportError naming the port.
SerialPortHandle open_serial_port(const std::string& path, const SerialSettings& settings, sp_mode mode,
                                  std::string* applied = nullptr);

// The port's file descriptor (sp_get_port_handle).
int serial_port_fd(sp_port* port);

// True when `path` (after symlinks) is a pty slave (Unix98 pty majors 136-143).
bool is_pty_slave(const std::string& path);

// libserialport's message for a failed call.
std::string serial_error_text(sp_return result);

}  // namespace imuemu::drivers
