// `imuemu ports`: the serial ports libserialport finds, with what it reports
// about each (for choosing a UART transport's port).
#pragma once

namespace imuemu::cli {

// Prints one line per port (name, transport, USB VID:PID, serial number,
// manufacturer, product, description) to stdout. Returns a process exit code.
int ports();

}  // namespace imuemu::cli
