// Network endpoints for the byte-stream protocols (issue 27: "a UDP and a
// TCP endpoint besides pty and UART"), as ground stations and simulators
// reach a MAVLink component:
//  - UDP: every frame is one datagram to a remote address (QGroundControl
//    listens on 14550 and answers to the address a datagram came from), sent
//    from a local port the peer's commands come back to. Connectionless: the
//    link is always up; a datagram nobody receives is lost on the network,
//    not counted as dropped here.
//  - TCP server: listens on an address and port and streams to one client
//    at a time (as PX4's simulator link, where the simulator listens on 4560
//    and PX4 connects). Until a client connects, and after it leaves, the
//    link is down: frames are dropped and counted (dropped_link_down), as on
//    a pty nobody reads; the next client starts with fresh samples. A second
//    client waits in the listen backlog until the first one leaves.
// Both hand what the peer sends to the device's input handler (commands), on
// the transport's writer thread, like the pty and the UART (transport.hpp).
// Frames go through the same bounded queue and writer thread
// (drivers/queued_writer.hpp): the emission thread never blocks.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>

#include "drivers/transport.hpp"

namespace imuemu::drivers {

class QueuedWriter;

struct NetTransportOptions {
  enum class Kind { udp, tcp_server };
  Kind kind = Kind::udp;
  // udp: where datagrams go (IPv4 address or host name, port 1..65535).
  // tcp_server: the address to listen on ("0.0.0.0": every interface) and
  // port (0: one the kernel picks; describe() names it).
  std::string host = "127.0.0.1";
  std::uint16_t port = 14550;
  // udp: the local port datagrams leave from and commands arrive at (0: one
  // the kernel picks; describe() names it).
  std::uint16_t bind_port = 0;
  std::size_t queue_bytes = 32 * 1024;
  // tcp_server: how often the writer looks for a new client while none is connected.
  std::chrono::milliseconds accept_interval{20};
  std::function<void(std::string_view)> log;  // connect/leave lines; empty: stderr
};

// Parses "udp:HOST:PORT[,bind=PORT]" or "tcp-listen:[HOST:]PORT" (the --device
// forms of `imuemu emit`); std::invalid_argument naming what was expected.
NetTransportOptions parse_net_device(const std::string& device);
bool is_net_device(const std::string& device);

class NetTransport final : public Transport {
 public:
  // Throws TransportError naming the address (cannot resolve, bind, listen).
  explicit NetTransport(NetTransportOptions options);
  ~NetTransport() override;

  bool write_frame(std::span<const std::byte> frame) override;
  std::string describe() const override;  // "udp 0.0.0.0:40123 -> 127.0.0.1:14550", "tcp server 0.0.0.0:4560"
  TransportCounters counters() const override;
  bool link_up() const override;
  bool flush(std::chrono::milliseconds timeout) override;
  void stop(std::chrono::milliseconds drain_timeout) override;
  bool set_input_handler(InputHandler* handler) override;

  // The local port actually bound (udp: the source port; tcp: the listening port).
  std::uint16_t local_port() const noexcept { return local_port_; }

 private:
  std::string description_;
  std::uint16_t local_port_ = 0;
  std::unique_ptr<QueuedWriter> writer_;
};

}  // namespace imuemu::drivers
