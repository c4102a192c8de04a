// UDP and TCP-server endpoints: see net_transport.hpp.
#include "drivers/net_transport.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <charconv>
#include <stdexcept>

#include "drivers/queued_writer.hpp"

namespace imuemu::drivers {
namespace {

std::string endpoint_text(const sockaddr_in& a) {
  std::array<char, INET_ADDRSTRLEN> text{};
  ::inet_ntop(AF_INET, &a.sin_addr, text.data(), text.size());
  return std::string(text.data()) + ":" + std::to_string(ntohs(a.sin_port));
}

sockaddr_in resolve_ipv4(const std::string& host, std::uint16_t port, const std::string& where) {
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(port);
  if (::inet_pton(AF_INET, host.c_str(), &a.sin_addr) == 1) return a;
  addrinfo hints{};
  hints.ai_family = AF_INET;
  addrinfo* found = nullptr;
  const int rc = ::getaddrinfo(host.c_str(), nullptr, &hints, &found);
  if (rc != 0 || found == nullptr) throw TransportError(where + ": cannot resolve '" + host + "': " + ::gai_strerror(rc));
  a.sin_addr = reinterpret_cast<const sockaddr_in*>(found->ai_addr)->sin_addr;
  ::freeaddrinfo(found);
  return a;
}

std::uint16_t bound_port(int fd) {
  sockaddr_in a{};
  socklen_t len = sizeof a;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
  return ntohs(a.sin_port);
}

// Reads what the peer sent (commands) until the socket is empty; true when
// the peer closed the stream (TCP recv 0).
template <class Deliver>
bool drain_input(int fd, Deliver&& deliver) {
  std::array<std::byte, 4096> buffer;
  for (;;) {
    const ssize_t n = ::recv(fd, buffer.data(), buffer.size(), MSG_DONTWAIT);
    if (n > 0) {
      deliver(std::span<const std::byte>(buffer.data(), static_cast<std::size_t>(n)));
      continue;
    }
    return n == 0;
  }
}

class UdpDevice final : public WriterDevice {
 public:
  UdpDevice(int fd, sockaddr_in remote) : fd_(fd), remote_(remote) {}
  ~UdpDevice() override { ::close(fd_); }
  bool datagrams() const override { return true; }
  int poll_fd() const override { return fd_; }
  DeviceWrite write(std::span<const std::byte> bytes) override {
    const ssize_t n = ::sendto(fd_, bytes.data(), bytes.size(), MSG_DONTWAIT | MSG_NOSIGNAL,
                               reinterpret_cast<const sockaddr*>(&remote_), sizeof remote_);
    if (n >= 0) return {DeviceWrite::Outcome::written, static_cast<std::size_t>(n), {}};
    if (errno == EAGAIN || errno == EINTR) return {DeviceWrite::Outcome::would_block, 0, {}};
    if (errno == ENOBUFS) return {DeviceWrite::Outcome::retry_later, 0, {}};
    // ECONNREFUSED / EHOSTUNREACH: an ICMP error for an earlier datagram;
    // the datagram protocol goes on (the peer may start listening later).
    return {DeviceWrite::Outcome::frame_rejected, 0, "sendto " + endpoint_text(remote_) + ": " + errno_message(errno)};
  }
  std::optional<std::string> service(short revents, std::uint64_t* discarded_bytes) override {
    if (revents & POLLIN)
      drain_input(fd_, [&](std::span<const std::byte> b) { deliver_input(b, discarded_bytes); });
    if (revents & POLLERR) {  // a pending ICMP error: read and forget it
      int error = 0;
      socklen_t len = sizeof error;
      ::getsockopt(fd_, SOL_SOCKET, SO_ERROR, &error, &len);
    }
    return std::nullopt;
  }
  void on_link_lost() override {}
  bool try_restore(std::string&) override { return true; }
  bool initially_up() const override { return true; }

 private:
  int fd_;
  sockaddr_in remote_;
};

class TcpServerDevice final : public WriterDevice {
 public:
  TcpServerDevice(int listen_fd, std::string name) : listen_fd_(listen_fd), name_(std::move(name)) {}
  ~TcpServerDevice() override {
    close_client();
    ::close(listen_fd_);
  }
  bool datagrams() const override { return false; }
  int poll_fd() const override { return client_fd_; }
  DeviceWrite write(std::span<const std::byte> bytes) override {
    if (client_fd_ < 0) return {DeviceWrite::Outcome::link_lost, 0, "no client"};
    const ssize_t n = ::send(client_fd_, bytes.data(), bytes.size(), MSG_DONTWAIT | MSG_NOSIGNAL);
    if (n >= 0) return {DeviceWrite::Outcome::written, static_cast<std::size_t>(n), {}};
    if (errno == EAGAIN || errno == EINTR) return {DeviceWrite::Outcome::would_block, 0, {}};
    return {DeviceWrite::Outcome::link_lost, 0, "client " + client_name_ + ": " + errno_message(errno)};
  }
  std::optional<std::string> service(short revents, std::uint64_t* discarded_bytes) override {
    if (client_fd_ < 0) return "no client";
    if (revents & POLLIN) {
      const bool closed =
          drain_input(client_fd_, [&](std::span<const std::byte> b) { deliver_input(b, discarded_bytes); });
      if (closed) return "client " + client_name_ + " closed the connection";
    }
    if (revents & (POLLHUP | POLLERR | POLLNVAL)) return "client " + client_name_ + " hung up";
    return std::nullopt;
  }
  void on_link_lost() override { close_client(); }
  bool try_restore(std::string& why) override {
    sockaddr_in peer{};
    socklen_t len = sizeof peer;
    const int fd = ::accept4(listen_fd_, reinterpret_cast<sockaddr*>(&peer), &len, SOCK_NONBLOCK | SOCK_CLOEXEC);
    if (fd < 0) {
      why = "no client has connected to " + name_;
      return false;
    }
    const int one = 1;
    // Small frames at a fixed rate: each should leave when written, not wait
    // for Nagle's coalescing.
    ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    client_fd_ = fd;
    client_name_ = endpoint_text(peer);
    return true;
  }
  bool initially_up() const override { return false; }

 private:
  void close_client() {
    if (client_fd_ >= 0) ::close(client_fd_);
    client_fd_ = -1;
  }
  int listen_fd_;
  int client_fd_ = -1;
  std::string name_, client_name_;
};

std::uint16_t port_of(std::string_view text, const std::string& device, bool zero_ok) {
  unsigned v = 0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (ec != std::errc() || end != text.data() + text.size() || v > 65535 || (v == 0 && !zero_ok))
    throw std::invalid_argument("--device '" + device + "': '" + std::string(text) + "' is not a port (1..65535)");
  return static_cast<std::uint16_t>(v);
}

}  // namespace

bool is_net_device(const std::string& device) {
  return device.rfind("udp:", 0) == 0 || device.rfind("tcp-listen:", 0) == 0;
}

NetTransportOptions parse_net_device(const std::string& device) {
  NetTransportOptions o;
  if (device.rfind("udp:", 0) == 0) {
    o.kind = NetTransportOptions::Kind::udp;
    std::string rest = device.substr(4);
    if (const auto comma = rest.find(','); comma != std::string::npos) {
      const std::string option = rest.substr(comma + 1);
      if (option.rfind("bind=", 0) != 0)
        throw std::invalid_argument("--device '" + device + "': expected udp:HOST:PORT[,bind=PORT]");
      o.bind_port = port_of(std::string_view(option).substr(5), device, true);
      rest.resize(comma);
    }
    const auto colon = rest.rfind(':');
    if (colon == std::string::npos || colon == 0)
      throw std::invalid_argument("--device '" + device + "': expected udp:HOST:PORT[,bind=PORT]");
    o.host = rest.substr(0, colon);
    o.port = port_of(std::string_view(rest).substr(colon + 1), device, false);
    return o;
  }
  if (device.rfind("tcp-listen:", 0) == 0) {
    o.kind = NetTransportOptions::Kind::tcp_server;
    const std::string rest = device.substr(11);
    const auto colon = rest.rfind(':');
    o.host = colon == std::string::npos ? "0.0.0.0" : rest.substr(0, colon);
    o.port = port_of(colon == std::string::npos ? std::string_view(rest) : std::string_view(rest).substr(colon + 1),
                     device, true);  // 0: a port the kernel picks (describe() names it)
    return o;
  }
  throw std::invalid_argument("--device '" + device + "': expected udp:HOST:PORT[,bind=PORT] or tcp-listen:[HOST:]PORT");
}

NetTransport::NetTransport(NetTransportOptions options) {
  const bool udp = options.kind == NetTransportOptions::Kind::udp;
  const std::string where = (udp ? "udp " : "tcp server ") + options.host + ":" + std::to_string(options.port);
  const sockaddr_in address = resolve_ipv4(options.host, options.port, where);
  const int fd = ::socket(AF_INET, (udp ? SOCK_DGRAM : SOCK_STREAM) | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  if (fd < 0) throw TransportError(where + ": socket: " + errno_message(errno));
  std::unique_ptr<WriterDevice> device;
  try {
    if (udp) {
      sockaddr_in local{};
      local.sin_family = AF_INET;
      local.sin_addr.s_addr = htonl(INADDR_ANY);
      local.sin_port = htons(options.bind_port);
      if (::bind(fd, reinterpret_cast<const sockaddr*>(&local), sizeof local) != 0)
        throw TransportError(where + ": bind to local port " + std::to_string(options.bind_port) + ": " +
                             errno_message(errno));
      local_port_ = bound_port(fd);
      description_ = "udp 0.0.0.0:" + std::to_string(local_port_) + " -> " + endpoint_text(address);
      device = std::make_unique<UdpDevice>(fd, address);
    } else {
      const int one = 1;
      ::setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
      if (::bind(fd, reinterpret_cast<const sockaddr*>(&address), sizeof address) != 0)
        throw TransportError(where + ": bind: " + errno_message(errno));
      if (::listen(fd, 4) != 0) throw TransportError(where + ": listen: " + errno_message(errno));
      local_port_ = bound_port(fd);
      description_ = "tcp server " + options.host + ":" + std::to_string(local_port_);
      device = std::make_unique<TcpServerDevice>(fd, description_);
    }
  } catch (...) {
    ::close(fd);
    throw;
  }
  QueuedWriterOptions writer;
  writer.name = description_;
  writer.queue_bytes = options.queue_bytes;
  writer.restore_initial = options.accept_interval;
  writer.restore_max = options.accept_interval;
  writer.link_lost_verb = "client gone";
  writer.link_restored_verb = "client connected";
  writer.log = std::move(options.log);
  writer_ = std::make_unique<QueuedWriter>(std::move(device), std::move(writer));
}

NetTransport::~NetTransport() { writer_.reset(); }

bool NetTransport::write_frame(std::span<const std::byte> frame) { return writer_->offer(frame); }
std::string NetTransport::describe() const { return description_; }
TransportCounters NetTransport::counters() const { return writer_->counters(); }
bool NetTransport::link_up() const { return writer_->link_up(); }
bool NetTransport::flush(std::chrono::milliseconds timeout) { return writer_->flush(timeout); }
void NetTransport::stop(std::chrono::milliseconds drain_timeout) { writer_->stop(drain_timeout); }
bool NetTransport::set_input_handler(InputHandler* handler) {
  writer_->set_input_handler(handler);
  return true;
}

}  // namespace imuemu::drivers
