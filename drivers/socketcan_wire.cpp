#include "drivers/socketcan_wire.hpp"

#include <linux/can.h>
#include <linux/can/raw.h>
#include <net/if_arp.h>
#include <net/if.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>

#include "drivers/queued_writer.hpp"
#include "drivers/transport.hpp"

namespace imuemu::drivers {

static_assert(kCanMtu == CAN_MTU && kCanFdMtu == CANFD_MTU, "linux/can.h frame sizes");

namespace {

std::string hex_id(std::uint32_t id) {
  char text[16];
  std::snprintf(text, sizeof text, "0x%X", id);
  return text;
}

// An ordinary socket to ask the kernel about interfaces (SIOCGIF* ioctls
// work on any socket family and need no CAN support).
class IoctlSocket {
 public:
  IoctlSocket() : fd_(::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0)) {}
  ~IoctlSocket() {
    if (fd_ >= 0) ::close(fd_);
  }
  IoctlSocket(const IoctlSocket&) = delete;
  IoctlSocket& operator=(const IoctlSocket&) = delete;
  int fd() const noexcept { return fd_; }

 private:
  int fd_;
};

}  // namespace

bool valid_can_fd_length(unsigned length) noexcept {
  return length <= 8 || length == 12 || length == 16 || length == 20 || length == 24 || length == 32 ||
         length == 48 || length == 64;
}

std::size_t to_socketcan(const CanFrame& frame, bool fd_enabled, bool bitrate_switch,
                         std::array<std::byte, kCanFdMtu>& wire, std::string& error) {
  const std::uint32_t id_limit = frame.extended ? CAN_EFF_MASK : CAN_SFF_MASK;
  if (frame.id > id_limit) {
    error = "CAN id " + hex_id(frame.id) + " does not fit " + (frame.extended ? "29" : "11") + " bits";
    return 0;
  }
  const canid_t can_id = frame.id | (frame.extended ? CAN_EFF_FLAG : 0U);
  if (!frame.fd) {
    if (frame.len > CAN_MAX_DLEN) {
      error = "classic CAN frame " + hex_id(frame.id) + " with " + std::to_string(frame.len) + " data bytes (at most 8)";
      return 0;
    }
    can_frame out{};
    out.can_id = can_id;
    out.len = frame.len;
    std::memcpy(out.data, frame.data.data(), frame.len);
    std::memcpy(wire.data(), &out, sizeof out);
    return sizeof out;
  }
  if (!fd_enabled) {
    error = "CAN FD frame " + hex_id(frame.id) + " on a transport opened for classic CAN (enable fd_frames)";
    return 0;
  }
  if (!valid_can_fd_length(frame.len)) {
    error = "CAN FD frame " + hex_id(frame.id) + " with " + std::to_string(frame.len) +
            " data bytes (expected 0-8, 12, 16, 20, 24, 32, 48 or 64)";
    return 0;
  }
  canfd_frame out{};
  out.can_id = can_id;
  out.len = frame.len;
  out.flags = static_cast<__u8>(CANFD_FDF | (bitrate_switch ? CANFD_BRS : 0));
  std::memcpy(out.data, frame.data.data(), frame.len);
  std::memcpy(wire.data(), &out, sizeof out);
  return sizeof out;
}

std::optional<CanFrame> from_socketcan(std::span<const std::byte> wire, std::string& what) {
  if (wire.size() != CAN_MTU && wire.size() != CANFD_MTU) {
    what = "a " + std::to_string(wire.size()) + "-byte read (neither struct can_frame nor canfd_frame)";
    return std::nullopt;
  }
  canfd_frame in{};  // can_frame is a prefix of canfd_frame with the same field offsets
  std::memcpy(&in, wire.data(), wire.size());
  if (in.can_id & CAN_ERR_FLAG) {
    what = "an error frame";
    return std::nullopt;
  }
  if (in.can_id & CAN_RTR_FLAG) {
    what = "a remote-request frame";
    return std::nullopt;
  }
  CanFrame frame;
  frame.extended = (in.can_id & CAN_EFF_FLAG) != 0;
  frame.id = in.can_id & (frame.extended ? CAN_EFF_MASK : CAN_SFF_MASK);
  frame.fd = wire.size() == CANFD_MTU;
  const unsigned limit = frame.fd ? CANFD_MAX_DLEN : CAN_MAX_DLEN;
  frame.len = static_cast<std::uint8_t>(in.len > limit ? limit : in.len);
  std::memcpy(frame.data.data(), in.data, frame.len);
  return frame;
}

CanInterfaceState inspect_can_interface(const std::string& name, bool need_fd) {
  const std::string where = "CAN interface '" + name + "'";
  if (name.empty() || name.size() >= IFNAMSIZ) {
    throw TransportError(where + ": an interface name has 1 to " + std::to_string(IFNAMSIZ - 1) + " characters");
  }
  IoctlSocket helper;
  if (helper.fd() < 0) throw TransportError(where + ": socket for interface queries: " + errno_message(errno));
  ifreq request{};
  std::memcpy(request.ifr_name, name.c_str(), name.size() + 1);
  if (::ioctl(helper.fd(), SIOCGIFINDEX, &request) != 0) {
    if (errno == ENODEV) {
      throw TransportError(where + ": no such network interface (a virtual bus: ip link add dev " + name +
                           " type vcan && ip link set up " + name + ")");
    }
    throw TransportError(where + ": cannot look it up: " + errno_message(errno));
  }
  CanInterfaceState state;
  state.index = static_cast<unsigned>(request.ifr_ifindex);
  if (::ioctl(helper.fd(), SIOCGIFHWADDR, &request) != 0) {
    throw TransportError(where + ": cannot read its link type: " + errno_message(errno));
  }
  if (request.ifr_hwaddr.sa_family != ARPHRD_CAN) {
    throw TransportError("network interface '" + name + "' is not a CAN interface (link type " +
                         std::to_string(request.ifr_hwaddr.sa_family) + ", expected " + std::to_string(ARPHRD_CAN) +
                         " = ARPHRD_CAN)");
  }
  if (::ioctl(helper.fd(), SIOCGIFMTU, &request) != 0) {
    throw TransportError(where + ": cannot read its MTU: " + errno_message(errno));
  }
  state.mtu = request.ifr_mtu;
  if (need_fd && state.mtu < static_cast<int>(CANFD_MTU)) {
    throw TransportError(where + " has MTU " + std::to_string(state.mtu) +
                         ": it does not carry CAN FD frames (expected 72: ip link set " + name +
                         " mtu 72 for vcan, or a controller configured with fd on)");
  }
  if (::ioctl(helper.fd(), SIOCGIFFLAGS, &request) != 0) {
    throw TransportError(where + ": cannot read its flags: " + errno_message(errno));
  }
  state.up = (request.ifr_flags & IFF_UP) != 0;
  state.running = (request.ifr_flags & IFF_RUNNING) != 0;
  return state;
}

int open_can_raw_socket(const std::string& name, unsigned index, bool fd_frames) {
  const std::string where = "CAN interface '" + name + "'";
  const int fd = ::socket(PF_CAN, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, CAN_RAW);
  if (fd < 0) {
    const int error = errno;
    if (error == EAFNOSUPPORT || error == EPROTONOSUPPORT) {
      throw TransportError(where + ": this kernel has no SocketCAN raw sockets (CONFIG_CAN and CONFIG_CAN_RAW; "
                           "modprobe can_raw): " + errno_message(error));
    }
    throw TransportError(where + ": cannot create a CAN_RAW socket: " + errno_message(error));
  }
  const auto fail = [&](const std::string& what) {
    const int error = errno;
    ::close(fd);
    throw TransportError(where + ": " + what + ": " + errno_message(error));
  };
  if (fd_frames) {
    const int on = 1;
    if (::setsockopt(fd, SOL_CAN_RAW, CAN_RAW_FD_FRAMES, &on, sizeof on) != 0) fail("cannot enable CAN FD frames");
  }
  sockaddr_can address{};
  address.can_family = AF_CAN;
  address.can_ifindex = static_cast<int>(index);
  if (::bind(fd, reinterpret_cast<const sockaddr*>(&address), sizeof address) != 0) fail("cannot bind a CAN_RAW socket");
  return fd;
}

}  // namespace imuemu::drivers
