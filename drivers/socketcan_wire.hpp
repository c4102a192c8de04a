// Internal to drivers/: CanFrame <-> the kernel's struct can_frame /
// struct canfd_frame (linux/can.h, Documentation/networking/can.rst §4.1.5),
// and the interface checks shared by CanTransport and CanReader.
#pragma once

#include <array>
#include <cstddef>
#include <optional>
#include <span>
#include <string>

#include "drivers/protocol.hpp"

namespace imuemu::drivers {

constexpr std::size_t kCanMtu = 16;    // sizeof(struct can_frame)
constexpr std::size_t kCanFdMtu = 72;  // sizeof(struct canfd_frame)

// The payload lengths a CAN FD frame can have (DLC 0..15 -> 0-8, 12, 16, 20,
// 24, 32, 48, 64; ISO 11898-1:2015 table 5).
bool valid_can_fd_length(unsigned length) noexcept;

// Fills `wire` with the kernel structure for `frame` and returns its size
// (kCanMtu or kCanFdMtu); returns 0 with `error` set when the frame is
// invalid (id beyond 11/29 bits, classic length > 8, FD length not a DLC
// length, an FD frame while fd_enabled is false).
std::size_t to_socketcan(const CanFrame& frame, bool fd_enabled, bool bitrate_switch,
                         std::array<std::byte, kCanFdMtu>& wire, std::string& error);

// The reverse for a received structure (kCanMtu or kCanFdMtu bytes); nullopt
// with `what` set for remote-request and error frames (no CanFrame form) or a
// size that is neither.
std::optional<CanFrame> from_socketcan(std::span<const std::byte> wire, std::string& what);

struct CanInterfaceState {
  unsigned index = 0;
  int mtu = 0;
  bool up = false;       // IFF_UP (administratively up)
  bool running = false;  // IFF_RUNNING (carrier: not bus-off)
};

// Looks the interface up without a CAN socket (so it works, and names the
// problem, on kernels without SocketCAN). Throws TransportError naming the
// interface when the name is invalid, it does not exist, it is not a CAN
// interface, or `need_fd` and its MTU cannot carry CAN FD frames.
CanInterfaceState inspect_can_interface(const std::string& name, bool need_fd);

// A non-blocking CAN_RAW socket bound to the interface. `fd_frames` enables
// CAN_RAW_FD_FRAMES. Throws TransportError (e.g. no SocketCAN in the kernel).
int open_can_raw_socket(const std::string& name, unsigned index, bool fd_frames);

}  // namespace imuemu::drivers
