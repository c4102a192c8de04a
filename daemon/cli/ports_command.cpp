#include "daemon/cli/ports_command.hpp"

#include <algorithm>
#include <array>
#include <cstdio>
#include <iostream>
#include <string>
#include <vector>

#include "daemon/cli/commands.hpp"
#include "drivers/serial_transport.hpp"

namespace imuemu::cli {

int ports() {
  std::vector<drivers::SerialPortInfo> found;
  try {
    found = drivers::list_serial_ports();
  } catch (const drivers::TransportError& e) {
    std::cerr << "imuemu: " << e.what() << "\n";
    return kInternalError;
  }
  if (found.empty()) {
    std::cout << "no serial ports found (libserialport lists the UARTs the kernel reports; "
                 "pseudo-terminals, such as a pty transport's, are never listed)\n";
    return kOk;
  }
  const auto hex4 = [](std::uint16_t value) {
    std::array<char, 8> text{};
    std::snprintf(text.data(), text.size(), "%04x", value);
    return std::string(text.data());
  };
  const auto dash_if_empty = [](const std::string& text) { return text.empty() ? std::string("-") : text; };
  std::vector<std::array<std::string, 7>> rows;
  rows.push_back({"PORT", "TRANSPORT", "VID:PID", "SERIAL", "MANUFACTURER", "PRODUCT", "DESCRIPTION"});
  for (const auto& port : found) {
    const std::string vid_pid = port.usb_vid && port.usb_pid ? hex4(*port.usb_vid) + ":" + hex4(*port.usb_pid) : "-";
    rows.push_back({port.name, dash_if_empty(port.transport), vid_pid, dash_if_empty(port.usb_serial_number),
                    dash_if_empty(port.usb_manufacturer), dash_if_empty(port.usb_product),
                    dash_if_empty(port.description)});
  }
  std::array<std::size_t, 7> width{};
  for (const auto& row : rows) {
    for (std::size_t i = 0; i < row.size(); ++i) width[i] = std::max(width[i], row[i].size());
  }
  for (const auto& row : rows) {
    std::string line;
    for (std::size_t i = 0; i < row.size(); ++i) {
      line += row[i];
      if (i + 1 < row.size()) line += std::string(width[i] - row[i].size() + 2, ' ');
    }
    std::cout << line << "\n";
  }
  return kOk;
}

}  // namespace imuemu::cli
