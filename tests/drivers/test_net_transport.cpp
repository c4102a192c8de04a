// The UDP and TCP-server endpoints (drivers/net_transport.hpp, issue 27)
// against plain sockets of this test: every frame arrives whole and in
// order (UDP: one datagram each), what the peer sends reaches the device's
// input handler and its replies come back, a TCP link is down until a client
// connects and after it leaves (frames counted, not queued), and the next
// client gets fresh frames.
#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <cstring>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "drivers/net_transport.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_drivers_test_net_transport {
namespace imuemu { using namespace ::imuemu; }

namespace drv = imuemu::drivers;
using namespace std::chrono_literals;

namespace {

std::vector<std::byte> net_frame(int i, std::size_t size = 40) {
  std::vector<std::byte> f(size);
  for (std::size_t k = 0; k < size; ++k) f[k] = static_cast<std::byte>((i * 7 + static_cast<int>(k)) & 0xFF);
  return f;
}

template <class Predicate>
bool net_wait(Predicate ready, std::chrono::milliseconds timeout = 5s) {
  const auto end = std::chrono::steady_clock::now() + timeout;
  while (!ready()) {
    if (std::chrono::steady_clock::now() > end) return false;
    std::this_thread::sleep_for(2ms);
  }
  return true;
}

sockaddr_in loopback(std::uint16_t port) {
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(port);
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  return a;
}

std::uint16_t port_of_socket(int fd) {
  sockaddr_in a{};
  socklen_t len = sizeof a;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
  return ntohs(a.sin_port);
}

// Records what the peer sent; answers each input with "ok:" + its bytes.
class EchoHandler final : public drv::InputHandler {
 public:
  void on_input(std::span<const std::uint8_t> bytes, drv::ReplySink& replies) override {
    std::lock_guard<std::mutex> lock(mutex_);
    received_.insert(received_.end(), bytes.begin(), bytes.end());
    std::vector<std::uint8_t> reply{'o', 'k', ':'};
    reply.insert(reply.end(), bytes.begin(), bytes.end());
    replies.reply(reply);
  }
  std::string received() {
    std::lock_guard<std::mutex> lock(mutex_);
    return std::string(received_.begin(), received_.end());
  }

 private:
  std::mutex mutex_;
  std::vector<std::uint8_t> received_;
};

// Reads whatever arrives on `fd` for `wait`, appended to `out`.
void net_read_for(int fd, std::vector<std::byte>& out, std::chrono::milliseconds wait) {
  const auto end = std::chrono::steady_clock::now() + wait;
  std::array<std::byte, 65536> buffer;
  while (std::chrono::steady_clock::now() < end) {
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, 10) <= 0) continue;
    const ssize_t n = ::recv(fd, buffer.data(), buffer.size(), 0);
    if (n <= 0) return;
    out.insert(out.end(), buffer.begin(), buffer.begin() + n);
  }
}

TEST(NetTransport, UdpSendsEachFrameAsOneDatagramAndTheReplyGoesBackToThePeer) {
  const int peer = ::socket(AF_INET, SOCK_DGRAM, 0);
  const sockaddr_in peer_address = loopback(0);
  ASSERT_EQ(::bind(peer, reinterpret_cast<const sockaddr*>(&peer_address), sizeof peer_address), 0);
  const std::uint16_t peer_port = port_of_socket(peer);

  drv::NetTransport t(drv::parse_net_device("udp:127.0.0.1:" + std::to_string(peer_port)));
  EXPECT_TRUE(t.link_up());
  EXPECT_NE(t.local_port(), 0);
  EXPECT_EQ(t.describe(), "udp 0.0.0.0:" + std::to_string(t.local_port()) + " -> 127.0.0.1:" + std::to_string(peer_port));
  EchoHandler handler;
  ASSERT_TRUE(t.set_input_handler(&handler));
  for (int i = 0; i < 50; ++i) ASSERT_TRUE(t.write_frame(net_frame(i, 20 + static_cast<std::size_t>(i))));
  ASSERT_TRUE(t.flush(2s));
  for (int i = 0; i < 50; ++i) {
    std::array<std::byte, 2048> d;
    pollfd p{peer, POLLIN, 0};
    ASSERT_EQ(::poll(&p, 1, 2000), 1) << "datagram " << i;
    const ssize_t n = ::recv(peer, d.data(), d.size(), 0);
    const auto want = net_frame(i, 20 + static_cast<std::size_t>(i));
    ASSERT_EQ(static_cast<std::size_t>(n), want.size()) << "one frame per datagram, " << i;
    EXPECT_EQ(std::memcmp(d.data(), want.data(), want.size()), 0);
  }
  // The peer's command reaches the handler; the reply comes back as a datagram.
  const sockaddr_in device = loopback(t.local_port());
  ASSERT_EQ(::sendto(peer, "ping", 4, 0, reinterpret_cast<const sockaddr*>(&device), sizeof device), 4);
  ASSERT_TRUE(net_wait([&] { return handler.received() == "ping"; }));
  std::vector<std::byte> reply;
  net_read_for(peer, reply, 300ms);
  EXPECT_EQ(std::string(reinterpret_cast<const char*>(reply.data()), reply.size()), "ok:ping");
  t.stop(1s);
  const drv::TransportCounters c = t.counters();
  EXPECT_EQ(c.frames, 50u);
  EXPECT_EQ(c.frames_sent, 50u);
  EXPECT_EQ(c.input_bytes, 4u);
  EXPECT_EQ(c.replies_sent, 1u);
  ::close(peer);
}

TEST(NetTransport, TcpServerIsDownWithoutAClientStreamsToOneAndStartsFreshForTheNext) {
  drv::NetTransport t(drv::parse_net_device("tcp-listen:127.0.0.1:0"));
  const std::uint16_t port = t.local_port();
  ASSERT_NE(port, 0);
  EXPECT_FALSE(t.link_up());
  EXPECT_FALSE(t.write_frame(net_frame(0))) << "no client: refused, not queued";
  EchoHandler handler;
  ASSERT_TRUE(t.set_input_handler(&handler));

  for (int client_number = 0; client_number < 2; ++client_number) {
    const int client = ::socket(AF_INET, SOCK_STREAM, 0);
    const sockaddr_in server = loopback(port);
    ASSERT_EQ(::connect(client, reinterpret_cast<const sockaddr*>(&server), sizeof server), 0);
    ASSERT_TRUE(net_wait([&] { return t.link_up(); })) << "client " << client_number;
    std::vector<std::byte> want;
    for (int i = 0; i < 100; ++i) {
      const auto f = net_frame(1000 * client_number + i);
      ASSERT_TRUE(t.write_frame(f));
      want.insert(want.end(), f.begin(), f.end());
    }
    ASSERT_TRUE(t.flush(2s));
    std::vector<std::byte> got;
    net_read_for(client, got, 300ms);
    EXPECT_EQ(got, want) << "client " << client_number << ": exactly its frames, in order, nothing older";
    ASSERT_EQ(::send(client, "cmd", 3, 0), 3);
    std::vector<std::byte> reply;
    net_read_for(client, reply, 300ms);
    EXPECT_EQ(std::string(reinterpret_cast<const char*>(reply.data()), reply.size()), "ok:cmd");
    ::close(client);
    ASSERT_TRUE(net_wait([&] { return !t.link_up(); })) << "the client left: link down";
    EXPECT_FALSE(t.write_frame(net_frame(5)));
  }
  EXPECT_EQ(handler.received(), "cmdcmd");
  t.stop(1s);
  const drv::TransportCounters c = t.counters();
  EXPECT_EQ(c.frames_sent, 200u);
  EXPECT_EQ(c.dropped_link_down, 3u);
  EXPECT_EQ(c.link_restored, 2u);
}

TEST(NetTransport, DeviceStringsParseOrSayWhatWasExpected) {
  const drv::NetTransportOptions u = drv::parse_net_device("udp:10.0.0.5:14550,bind=14555");
  EXPECT_EQ(u.kind, drv::NetTransportOptions::Kind::udp);
  EXPECT_EQ(u.host, "10.0.0.5");
  EXPECT_EQ(u.port, 14550);
  EXPECT_EQ(u.bind_port, 14555);
  const drv::NetTransportOptions s = drv::parse_net_device("tcp-listen:4560");
  EXPECT_EQ(s.kind, drv::NetTransportOptions::Kind::tcp_server);
  EXPECT_EQ(s.host, "0.0.0.0");
  EXPECT_EQ(s.port, 4560);
  for (const char* bad : {"udp:14550", "udp:host:0", "udp:host:70000", "udp:host:1,bound=3", "tcp-listen:", "tcp-listen:x:y"}) {
    try {
      drv::parse_net_device(bad);
      ADD_FAILURE() << bad << " accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(bad), std::string::npos) << e.what();
    }
  }
  EXPECT_THROW(drv::NetTransport(drv::parse_net_device("udp:no-such-host.invalid:14550")), drv::TransportError);
}

}  // namespace
}  // namespace unity_drivers_test_net_transport
