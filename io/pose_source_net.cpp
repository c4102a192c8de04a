// UDP datagram and TCP line pose sources on Boost.Asio, each with its own
// io_context run by the source's thread.
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/address.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/ip/udp.hpp>
#include <boost/asio/steady_timer.hpp>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <linux/sockios.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <time.h>

#include <algorithm>
#include <optional>
#include <stdexcept>
#include <utility>
#include <vector>

#include "core/time_arith.hpp"
#include "io/pose_admission.hpp"
#include "io/pose_source.hpp"

namespace imuemu::io {
namespace {

namespace asio = boost::asio;
using boost::system::error_code;

asio::ip::address parse_address(const NetEndpoint& endpoint, std::string_view what) {
  error_code ec;
  const asio::ip::address address = asio::ip::make_address(endpoint.address, ec);
  if (ec) {
    throw std::runtime_error(std::string(what) + " pose source: '" + endpoint.address +
                             "' is not an IPv4 or IPv6 address: " + ec.message());
  }
  return address;
}

// "udp 127.0.0.1:5005", with the port actually bound.
std::string endpoint_name(std::string_view protocol, const std::string& address, std::uint16_t port) {
  return std::string(protocol) + " " + address + ":" + std::to_string(port);
}

[[noreturn]] void bind_failed(const std::string& name, const error_code& ec) {
  throw std::runtime_error(name + ": cannot bind: " + ec.message());
}

// ---------------------------------------------------------------- UDP

class UdpPoseSource final : public PoseSource {
 public:
  UdpPoseSource(const NetEndpoint& endpoint, PoseSourceOptions options, bool mavlink)
      : PoseSource(std::move(options)), socket_(io_), buffer_(kMaxDatagramBytes), mavlink_(mavlink) {
    const asio::ip::udp::endpoint local(parse_address(endpoint, "udp"), endpoint.port);
    error_code ec;
    socket_.open(local.protocol(), ec);
    if (!ec && endpoint.receive_buffer_bytes > 0)
      socket_.set_option(asio::socket_base::receive_buffer_size(endpoint.receive_buffer_bytes), ec);
    if (!ec) socket_.bind(local, ec);
    if (ec) bind_failed(endpoint_name("udp", endpoint.address, endpoint.port), ec);
    port_ = socket_.local_endpoint().port();
    if (name_.empty()) set_name(endpoint_name(mavlink ? "mavlink udp" : "udp", endpoint.address, port_));
    // The first SIOCGSTAMPNS turns on the kernel's receive time stamps for
    // this socket (it answers ENOENT: nothing received yet); see arrival_ns.
    timespec unused{};
    (void)::ioctl(socket_.native_handle(), SIOCGSTAMPNS, &unused);
  }
  ~UdpPoseSource() override { stop(); }
  std::uint16_t local_port() const noexcept override { return port_; }

 private:
  // Larger than any UDP payload: an oversized datagram is seen whole and
  // refused for its length instead of being truncated into a valid size.
  static constexpr std::size_t kMaxDatagramBytes = 65536;

  void run() override {
    receive_next();
    io_.run();
  }
  void wake() override { io_.stop(); }

  void receive_next() {
    socket_.async_receive_from(asio::buffer(buffer_), sender_, [this](const error_code& ec, std::size_t size) {
      if (ec == asio::error::operation_aborted) return;
      if (ec) {
        // ICMP errors and the like are transient; a datagram stream goes on.
        admission_->log("receive_error", "receive failed: " + ec.message());
      } else {
        handle(size, arrival_ns(monotonic_now_ns()));
      }
      receive_next();
    });
  }

  // When the datagram just read reached the socket (the kernel's receive
  // time stamp, SIOCGSTAMPNS, CLOCK_REALTIME, taken back to CLOCK_MONOTONIC),
  // not when this thread woke to read it: a pose's receive_ns anchors the
  // live clock (the first pose's) and starts its latency (issue 17: a first
  // pose read 2-4 ms after it arrived, this thread waking late, made every
  // sample of the run that much later). Without a stamp, or with one older
  // than 1 s or in the future (a clock step), the read time. Never before the
  // previous pose's, never after the read.
  TimeNs arrival_ns(TimeNs read_ns) {
    TimeNs arrival = read_ns;
    timespec stamp{};
    timespec real{};
    if (::ioctl(socket_.native_handle(), SIOCGSTAMPNS, &stamp) == 0 && ::clock_gettime(CLOCK_REALTIME, &real) == 0) {
      // Through the saturating helpers: a stamp is the kernel's, but a
      // garbage one must give a refused age, never a wrapped one.
      const TimeNs age_ns =
          saturating_add_ns(saturating_mul_ns(saturating_sub_ns(real.tv_sec, stamp.tv_sec), kNsPerSecond),
                            saturating_sub_ns(real.tv_nsec, stamp.tv_nsec));
      if (age_ns >= 0 && age_ns < kNsPerSecond) arrival = saturating_sub_ns(monotonic_now_ns(), age_ns);
    }
    arrival = std::clamp(arrival, std::min(last_arrival_ns_, read_ns), read_ns);
    last_arrival_ns_ = arrival;
    return arrival;
  }

  void handle(std::size_t size, TimeNs receive_ns) {
    // One published snapshot per datagram, after its pose is queued: a
    // reader that sees it received sees it classified and its pose queued
    // (overflow_dropped included).
    const PoseAdmission::Unit unit(*admission_);
    SourcedPose pose;
    if (sender_ != named_sender_) {  // the sender's name only for log lines: no allocation per datagram
      named_sender_ = sender_;
      sender_name_ = sender_.address().to_string() + ":" + std::to_string(sender_.port());
    }
    const std::span<const std::uint8_t> bytes(buffer_.data(), size);
    if (!(mavlink_ ? admission_->receive_mavlink_datagram(bytes, receive_ns, sender_name_, pose)
                   : admission_->receive_datagram(bytes, receive_ns, sender_name_, pose)))
      return;
    do {  // an acquisition releases the held poses too
      // A burst beyond the queue: the freshest poses matter most.
      if (queue_.push_or_drop_oldest(pose)) admission_->overflow_dropped();
    } while (admission_->take_released(pose));
  }

  asio::io_context io_;
  asio::ip::udp::socket socket_;
  asio::ip::udp::endpoint sender_;
  asio::ip::udp::endpoint named_sender_;
  std::string sender_name_;
  std::vector<std::uint8_t> buffer_;
  std::uint16_t port_ = 0;
  TimeNs last_arrival_ns_ = 0;  // arrival_ns's previous answer
  bool mavlink_;  // MAVLink 2 HIL_STATE_QUATERNION datagrams instead of pose datagrams
};

// ---------------------------------------------------------------- TCP

class TcpPoseSource final : public PoseSource {
 public:
  TcpPoseSource(const NetEndpoint& endpoint, PoseSourceOptions options)
      : PoseSource(std::move(options)),
        acceptor_(io_),
        retry_timer_(io_),
        accept_retry_timer_(io_),
        idle_timer_(io_),
        read_buffer_(kReadBytes),
        idle_timeout_ns_(endpoint.tcp_idle_timeout_ns),
        takeover_idle_ns_(endpoint.tcp_takeover_idle_ns),
        keepalive_(endpoint.tcp_keepalive) {
    if (idle_timeout_ns_ < 0 || takeover_idle_ns_ < 0)
      throw std::invalid_argument("tcp pose source: tcp_idle_timeout_ns and tcp_takeover_idle_ns must be >= 0");
    const asio::ip::tcp::endpoint local(parse_address(endpoint, "tcp"), endpoint.port);
    error_code ec;
    acceptor_.open(local.protocol(), ec);
    if (!ec) acceptor_.set_option(asio::socket_base::reuse_address(true), ec);
    if (!ec) acceptor_.bind(local, ec);
    if (!ec) acceptor_.listen(asio::socket_base::max_listen_connections, ec);
    if (ec) bind_failed(endpoint_name("tcp", endpoint.address, endpoint.port), ec);
    port_ = acceptor_.local_endpoint().port();
    if (name_.empty()) set_name(endpoint_name("tcp", endpoint.address, port_));
  }
  ~TcpPoseSource() override { stop(); }
  std::uint16_t local_port() const noexcept override { return port_; }

 private:
  static constexpr std::size_t kReadBytes = 16384;
  // While the queue is full the source polls it at this period (the
  // consumer drains at its own pace; Asio has no wake-up from the queue).
  static constexpr auto kBackpressureRetry = std::chrono::milliseconds(1);
  // Keepalive probing (NetEndpoint::tcp_keepalive): first probe after 2 s of
  // silence, then every 1 s; 3 unanswered probes reset the connection.
  static constexpr int kKeepaliveIdleS = 2, kKeepaliveIntervalS = 1, kKeepaliveProbes = 3;

  void run() override {
    accept_next();
    io_.run();
  }
  void wake() override { io_.stop(); }

  static std::string peer_name(const asio::ip::tcp::socket& socket) {
    error_code ignored;
    const auto peer = socket.remote_endpoint(ignored);
    return peer.address().to_string() + ":" + std::to_string(peer.port());
  }

  // How long the connected client has been silent while the source waited
  // for its bytes; 0 while the source is not reading (backpressure stall).
  TimeNs client_idle_ns(TimeNs now_ns) const { return reading_ ? now_ns - waiting_since_ns_ : 0; }

  void set_keepalive(asio::ip::tcp::socket& socket) {
    error_code ec;
    socket.set_option(asio::socket_base::keep_alive(true), ec);
    const int fd = socket.native_handle();
    const int values[] = {kKeepaliveIdleS, kKeepaliveIntervalS, kKeepaliveProbes};
    const int names[] = {TCP_KEEPIDLE, TCP_KEEPINTVL, TCP_KEEPCNT};
    bool ok = !ec;
    for (std::size_t i = 0; i < 3 && ok; ++i) ok = ::setsockopt(fd, IPPROTO_TCP, names[i], &values[i], sizeof(int)) == 0;
    if (!ok) admission_->log("keepalive", "cannot enable TCP keepalive on " + client_name_ + " (the idle timeout still applies)");
  }

  // Ends the current client's stream (its unterminated last line counted).
  // key: the rate-limited log's key ("connection" for an ordinary end).
  void drop_client(std::string_view key, const std::string& why) {
    stream_->finish();
    admission_->log(key, "client disconnected: " + client_name_ + why);
    error_code ignored;
    client_->close(ignored);  // a pending read completes with operation_aborted
    client_.reset();
    stream_.reset();
    pending_.reset();  // only set while stalled, and a stalled client is never dropped for idleness
    stalled_ = false;
    reading_ = false;
    idle_timer_.cancel();
  }

  void accept_next() {
    acceptor_.async_accept([this](const error_code& ec, asio::ip::tcp::socket socket) {
      if (ec == asio::error::operation_aborted) return;
      if (ec) {
        // E.g. out of file descriptors: try again a little later rather
        // than spin on an error that repeats at once.
        admission_->log("accept_error", "accept failed: " + ec.message());
        accept_retry_timer_.expires_after(std::chrono::milliseconds(100));
        accept_retry_timer_.async_wait([this](const error_code& timer_ec) {
          if (timer_ec != asio::error::operation_aborted) accept_next();
        });
        return;
      }
      const TimeNs now_ns = monotonic_now_ns();
      if (client_ && client_idle_ns(now_ns) >= takeover_idle_ns_) {
        // The connected client is silent: most likely the sender's previous
        // connection, gone half-open; the new one takes the slot.
        admission_->connection_replaced();
        drop_client("connection_replaced", " (idle for " + std::to_string(client_idle_ns(now_ns) / 1'000'000) +
                    " ms, replaced by a new client " + peer_name(socket) + ")");
      }
      if (client_) {
        // One client at a time: a second stream would interleave with the
        // first's poses. Closing tells the client at once.
        admission_->connection_refused();
        admission_->log("connection_refused", "refused client " + peer_name(socket) + ": another client is connected");
        error_code ignored;
        socket.close(ignored);
      } else {
        admission_->connection();
        ++connection_number_;
        // The admission's log lines start with the source's name; messages
        // add the connection and its line numbers.
        client_name_ = "connection " + std::to_string(connection_number_) + " (" + peer_name(socket) + ")";
        admission_->log("connection", "client connected: " + client_name_);
        client_.emplace(std::move(socket));
        if (keepalive_) set_keepalive(*client_);
        stream_.emplace(*admission_, client_name_);
        read_next();
        arm_idle_timer(idle_timeout_ns_);
      }
      accept_next();
    });
  }

  // Checks the idle timeout after `after_ns`; re-arms for the rest of it.
  void arm_idle_timer(TimeNs after_ns) {
    if (idle_timeout_ns_ == 0) return;
    idle_timer_.expires_after(std::chrono::nanoseconds(after_ns));
    idle_timer_.async_wait([this](const error_code& ec) {
      if (ec == asio::error::operation_aborted || !client_) return;
      const TimeNs idle_ns = client_idle_ns(monotonic_now_ns());
      if (idle_ns >= idle_timeout_ns_) {
        admission_->connection_idle_closed();
        drop_client("idle_timeout", " (nothing received for " + std::to_string(idle_ns / 1'000'000) + " ms: idle timeout " +
                    std::to_string(idle_timeout_ns_ / 1'000'000) + " ms)");
        return;
      }
      arm_idle_timer(idle_timeout_ns_ - idle_ns);
    });
  }

  void read_next() {
    reading_ = true;
    waiting_since_ns_ = monotonic_now_ns();
    client_->async_read_some(asio::buffer(read_buffer_), [this](const error_code& ec, std::size_t size) {
      if (ec == asio::error::operation_aborted) return;
      reading_ = false;
      if (ec) {
        drop_client("connection", ec == asio::error::eof ? std::string() : " (" + ec.message() + ")");
        return;
      }
      stream_->append(read_buffer_.data(), size, monotonic_now_ns());
      process();
    });
  }

  // Queues the buffered lines' poses; reads on only when all are queued.
  void process() {
    for (;;) {
      if (pending_) {
        if (!queue_.try_push(*pending_)) {
          if (!stalled_) {
            stalled_ = true;
            admission_->backpressure_event();
          }
          retry_timer_.expires_after(kBackpressureRetry);
          retry_timer_.async_wait([this](const error_code& ec) {
            if (ec != asio::error::operation_aborted && client_) process();
          });
          return;
        }
        pending_.reset();
        stalled_ = false;
      }
      SourcedPose pose;
      if (!stream_->next(pose)) break;
      pending_ = pose;
    }
    read_next();
  }

  asio::io_context io_;
  asio::ip::tcp::acceptor acceptor_;
  asio::steady_timer retry_timer_;
  asio::steady_timer accept_retry_timer_;
  asio::steady_timer idle_timer_;
  std::optional<asio::ip::tcp::socket> client_;
  std::optional<PoseLineStream> stream_;
  std::optional<SourcedPose> pending_;
  bool stalled_ = false;
  bool reading_ = false;         // a read of the client is pending (the source waits for its bytes)
  TimeNs waiting_since_ns_ = 0;  // when that read was issued
  std::vector<char> read_buffer_;
  std::uint64_t connection_number_ = 0;
  std::string client_name_;
  std::uint16_t port_ = 0;
  TimeNs idle_timeout_ns_;
  TimeNs takeover_idle_ns_;
  bool keepalive_;
};

}  // namespace

std::unique_ptr<PoseSource> make_udp_pose_source(const NetEndpoint& endpoint, PoseSourceOptions options) {
  return std::make_unique<UdpPoseSource>(endpoint, std::move(options), false);
}

std::unique_ptr<PoseSource> make_mavlink_udp_pose_source(const NetEndpoint& endpoint, PoseSourceOptions options) {
  return std::make_unique<UdpPoseSource>(endpoint, std::move(options), true);
}

std::unique_ptr<PoseSource> make_tcp_pose_source(const NetEndpoint& endpoint, PoseSourceOptions options) {
  return std::make_unique<TcpPoseSource>(endpoint, std::move(options));
}

}  // namespace imuemu::io
