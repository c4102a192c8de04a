// Test support: a UDP socket sending datagrams to 127.0.0.1:port (a live
// pose source under test), as a simulator or a second vehicle would.
#pragma once

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cstdint>
#include <span>

namespace imuemu::test {

class LoopbackUdpSender {
 public:
  explicit LoopbackUdpSender(std::uint16_t port) : fd_(::socket(AF_INET, SOCK_DGRAM, 0)) {
    to_.sin_family = AF_INET;
    to_.sin_port = htons(port);
    to_.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  }
  ~LoopbackUdpSender() {
    if (fd_ >= 0) ::close(fd_);
  }
  LoopbackUdpSender(const LoopbackUdpSender&) = delete;
  LoopbackUdpSender& operator=(const LoopbackUdpSender&) = delete;

  // True when the whole datagram was handed to the kernel.
  bool send(std::span<const std::uint8_t> bytes) const {
    return fd_ >= 0 && ::sendto(fd_, bytes.data(), bytes.size(), 0, reinterpret_cast<const sockaddr*>(&to_),
                                sizeof to_) == static_cast<ssize_t>(bytes.size());
  }

 private:
  int fd_;
  sockaddr_in to_{};
};

}  // namespace imuemu::test
