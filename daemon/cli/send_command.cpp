// `imuemu send` (daemon/cli/send_command.hpp). The bytes are the receiver's
// own encoders' (io/pose_wire.hpp for datagrams; the trajectory file's
// column names and io::detail::format_double / format_decimal_seconds for lines, so
// a line parses back to the file's record bit for bit), paced on absolute
// CLOCK_MONOTONIC deadlines through the replay's own time mapping
// (core/time_mapping.hpp), so `--speed` means what it means for `imuemu
// stream --source file:`.
#include "daemon/cli/send_command.hpp"

#include <CLI/CLI.hpp>

#include <netdb.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <iostream>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/time_arith.hpp"
#include "core/time_mapping.hpp"
#include "daemon/cli/cli_options.hpp"
#include "daemon/cli/commands.hpp"
#include "io/decimal_time.hpp"
#include "io/pose_source.hpp"
#include "io/pose_wire.hpp"
#include "io/sample_trajectory.hpp"
#include "io/trajectory_csv.hpp"

namespace imuemu::cli {

namespace send_impl {

// A failure of the network side (resolve, connect, send): exit kOutputError.
class NetworkError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct Destination {
  bool udp = true;
  std::string host;
  std::string port;
};

// "udp:HOST:PORT" / "tcp:HOST:PORT"; HOST may be a name, an IPv4 literal or
// a bracketed IPv6 literal ("[::1]").
Destination parse_destination(const std::string& spec) {
  Destination d;
  std::string rest;
  if (spec.rfind("udp:", 0) == 0) d.udp = true;
  else if (spec.rfind("tcp:", 0) == 0) d.udp = false;
  else throw UsageError("--to '" + spec + "': expected udp:HOST:PORT or tcp:HOST:PORT");
  rest = spec.substr(4);
  const auto colon = rest.rfind(':');
  if (colon == std::string::npos || colon == 0) throw UsageError("--to '" + spec + "': expected " + spec.substr(0, 3) + ":HOST:PORT");
  d.host = rest.substr(0, colon);
  if (d.host.size() >= 2 && d.host.front() == '[' && d.host.back() == ']') d.host = d.host.substr(1, d.host.size() - 2);
  d.port = rest.substr(colon + 1);
  const io::Int64Parse p = io::try_parse_int64(d.port);
  if (p.status != io::NumberStatus::ok || p.value < 1 || p.value > 65535)
    throw UsageError("--to '" + spec + "': port '" + d.port + "' is not 1..65535");
  return d;
}

std::string errno_text(int e) { return std::strerror(e); }

class Socket {
 public:
  Socket() = default;
  explicit Socket(int fd) : fd_(fd) {}
  Socket(const Socket&) = delete;
  Socket& operator=(const Socket&) = delete;
  Socket(Socket&& o) noexcept : fd_(o.fd_) { o.fd_ = -1; }
  Socket& operator=(Socket&& o) noexcept {
    if (this != &o) {
      reset();
      fd_ = o.fd_;
      o.fd_ = -1;
    }
    return *this;
  }
  ~Socket() { reset(); }
  void reset() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }
  int fd() const { return fd_; }

 private:
  int fd_ = -1;
};

TimeNs now_ns() { return io::monotonic_now_ns(); }

void sleep_until_ns(TimeNs deadline_ns) {
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(deadline_ns / kNsPerSecond);
  ts.tv_nsec = static_cast<long>(deadline_ns % kNsPerSecond);
  while (::clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

// Resolves and connects. UDP: connect() only fixes the peer (nothing is sent),
// so a receiver that is not there yet is no error. TCP: retries refused or
// unreachable connections every 100 ms until timeout_ns has passed.
Socket open_connected(const Destination& d, TimeNs timeout_ns, const std::string& spec) {
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = d.udp ? SOCK_DGRAM : SOCK_STREAM;
  addrinfo* found = nullptr;
  const int rc = ::getaddrinfo(d.host.c_str(), d.port.c_str(), &hints, &found);
  if (rc != 0) throw NetworkError("--to " + spec + ": cannot resolve '" + d.host + "': " + ::gai_strerror(rc));
  struct Free {
    addrinfo* p;
    ~Free() { ::freeaddrinfo(p); }
  } free_found{found};
  const TimeNs deadline = saturating_add_ns(now_ns(), timeout_ns);
  int last_errno = 0;
  for (;;) {
    for (addrinfo* a = found; a != nullptr; a = a->ai_next) {
      Socket s(::socket(a->ai_family, a->ai_socktype | SOCK_CLOEXEC, a->ai_protocol));
      if (s.fd() < 0) {
        last_errno = errno;
        continue;
      }
      if (::connect(s.fd(), a->ai_addr, a->ai_addrlen) == 0) return s;
      last_errno = errno;
    }
    if (d.udp || now_ns() >= deadline) break;
    sleep_until_ns(std::min(deadline, saturating_add_ns(now_ns(), kNsPerSecond / 10)));
  }
  throw NetworkError("--to " + spec + ": cannot connect" +
                     (d.udp ? std::string() : " within --connect-timeout-s") + ": " + errno_text(last_errno));
}

// The record as one pose line, in the file's columns (io/trajectory_csv.hpp
// rules) and with round-trip numbers, so the receiver's record equals the
// file's.
std::string header_line(io::PositionKind p, io::AttitudeKind a) {
  std::string line = "time_s";
  for (int i = 0; i < 3; ++i) (line += ',') += io::position_column_rule(p, i).name;
  for (int i = 0; i < io::attitude_component_count(a); ++i) (line += ',') += io::attitude_column_rule(a, i).name;
  return line + '\n';
}

std::string record_line(const io::TrajectoryRecord& r, TimeNs t_ns) {
  std::string line = io::format_decimal_seconds(t_ns);
  for (int i = 0; i < 3; ++i) (line += ',') += io::detail::format_double(r.position[i]);
  for (int i = 0; i < io::attitude_component_count(r.attitude_kind); ++i) (line += ',') += io::detail::format_double(r.attitude[i]);
  return line + '\n';
}

void send_all_tcp(int fd, const std::string& bytes, const std::string& spec) {
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::send(fd, bytes.data() + done, bytes.size() - done, MSG_NOSIGNAL);
    if (n < 0) {
      if (errno == EINTR) continue;
      throw NetworkError("--to " + spec + ": the receiver closed the connection (" + errno_text(errno) + ")");
    }
    done += static_cast<std::size_t>(n);
  }
}

}  // namespace send_impl

int send(const SendArgs& a) {
  using namespace send_impl;
  const char* const who = "imuemu send: ";
  if ((a.in_path.empty() ? 0 : 1) + (a.sample_kind.empty() ? 0 : 1) != 1) {
    std::cerr << who << "give exactly one of --in, --sample\n";
    return kUsageError;
  }
  Destination dest;
  live::SpeedFactor speed;
  const bool paced = a.speed != "max";
  TimeNs connect_timeout_ns = 0;
  try {
    dest = parse_destination(a.to);
    if (paced) speed = live::parse_speed_factor(a.speed);
    connect_timeout_ns = option_ns("--connect-timeout-s", a.connect_timeout_s);
  } catch (const std::exception& e) {
    std::cerr << who << e.what() << "\n";
    return kUsageError;
  }
  if (!dest.udp && a.datagram_version != 1) {
    std::cerr << who << "--datagram-version applies to udp only (tcp sends pose lines)\n";
    return kUsageError;
  }

  // The whole input is read and checked before anything is sent: a bad line
  // (named by file, line and column) sends nothing.
  io::Trajectory trajectory;
  try {
    trajectory = a.in_path.empty()
                     ? io::parse_trajectory_csv(io::sample_trajectory_csv(a.sample_kind, a.sample_duration_s, a.sample_period_s),
                                                "sample " + a.sample_kind)
                     : io::read_trajectory_csv(a.in_path);
  } catch (const io::CsvFormatError& e) {
    std::cerr << who << e.what() << "\n";
    return kBadInput;
  } catch (const std::exception& e) {
    std::cerr << who << e.what() << "\n";
    return kUsageError;
  }
  const std::vector<io::TrajectoryRecord>& records = trajectory.records;
  // --loop: pass k is sent with times + k * (span + last interval), so the
  // receiver sees one increasing timeline (a closed path such as the circle
  // or the static sample continues smoothly; an open one jumps back in
  // position, which the receiver's admission rules judge).
  TimeNs loop_shift_ns = 0;
  if (a.loop) {
    if (records.size() < 2) {
      std::cerr << who << "--loop needs at least two poses\n";
      return kUsageError;
    }
    loop_shift_ns = saturating_add_ns(saturating_sub_ns(records.back().t_ns, records.front().t_ns),
                                      saturating_sub_ns(records.back().t_ns, records[records.size() - 2].t_ns));
  }

  std::uint64_t sent = 0;
  std::uint64_t refused_by_peer = 0;  // udp: ICMP port unreachable reported on a later send
  const TimeNs started_ns = now_ns();
  try {
    Socket sock = open_connected(dest, connect_timeout_ns, a.to);
    if (!dest.udp) send_all_tcp(sock.fd(), "# imuemu-pose-lines v1\n" + header_line(trajectory.position_kind, trajectory.attitude_kind), a.to);
    const TimeNs t0 = records.front().t_ns;
    const live::TimeMapping mapping = live::TimeMapping::start_now(t0, now_ns(), speed);
    std::uint64_t sequence = 0;
    for (std::int64_t pass = 0;; ++pass) {
      const TimeNs shift = saturating_mul_ns(loop_shift_ns, pass);
      for (const io::TrajectoryRecord& r : records) {
        const TimeNs t = saturating_add_ns(r.t_ns, shift);
        if (t == kMaxTimeNs) throw std::overflow_error("--loop: the pose times left the int64 ns range");
        if (paced) sleep_until_ns(mapping.monotonic_at(t));
        if (dest.udp) {
          io::PoseDatagram d;
          d.sequence = sequence++;
          d.record = r;
          d.record.t_ns = t;
          d.record.line = 0;
          ssize_t n = 0;
          if (a.datagram_version == 2) {
            const auto bytes = io::encode_pose_datagram_v2(d);
            n = ::send(sock.fd(), bytes.data(), bytes.size(), 0);
          } else {
            const auto bytes = io::encode_pose_datagram(d);
            n = ::send(sock.fd(), bytes.data(), bytes.size(), 0);
          }
          if (n < 0) {
            // Nobody listening yet (ICMP port unreachable, reported on the
            // next send of a connected socket) is normal for a sender started
            // first: counted and said once, not fatal.
            if (errno == ECONNREFUSED) {
              if (refused_by_peer++ == 0 && !a.quiet)
                std::cerr << who << a.to << ": nothing listens there yet (port unreachable); still sending\n";
            } else {
              throw NetworkError("--to " + a.to + ": send: " + errno_text(errno));
            }
          } else {
            ++sent;
          }
        } else {
          send_all_tcp(sock.fd(), record_line(r, t), a.to);
          ++sent;
        }
      }
      if (!a.loop) break;
    }
    if (!dest.udp) ::shutdown(sock.fd(), SHUT_WR);
  } catch (const NetworkError& e) {
    std::cerr << who << e.what() << " (" << sent << " poses sent)\n";
    return kOutputError;
  } catch (const std::exception& e) {
    std::cerr << who << e.what() << "\n";
    return kInternalError;
  }
  if (!a.quiet)
    std::cerr << who << sent << " poses sent to " << a.to << " in "
              << static_cast<double>(now_ns() - started_ns) / 1e9 << " s"
              << (paced ? " (speed " + live::to_string(speed) + ")" : std::string(" (unpaced)"))
              << (refused_by_peer > 0 ? ", " + std::to_string(refused_by_peer) + " refused (port unreachable)" : std::string())
              << "\n";
  return kOk;
}

void add_send_command(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<SendArgs>();
  SendArgs& a = *args;
  auto* c = app.add_subcommand(
      "send",
      "Send a trajectory to a live pose source in real time: UDP pose datagrams or TCP pose lines "
      "(imuemud's udp:/tcp: [trajectory] source, imuemu stream --source; docs/pose-wire-format.md). "
      "The whole input is checked first: a bad line sends nothing (exit 3); a failed connection "
      "or send exits 5");
  auto* in = c->add_option("--in", a.in_path, "Trajectory CSV (docs/trajectory-format.md), as imuemu generate reads it");
  auto* sample = c->add_option("--sample", a.sample_kind, "Built-in trajectory instead: flight, circle or static")
                     ->check(CLI::IsMember({"flight", "circle", "static"}));
  in->excludes(sample);
  c->add_option("--duration-s", a.sample_duration_s, "--sample: trajectory duration")->capture_default_str()
      ->check(seconds_in(0.0, kMaxDurationS, true));
  c->add_option("--sample-period-s", a.sample_period_s, "--sample: pose period")->capture_default_str()
      ->check(seconds_in(0.0, kMaxIntervalS, true));
  c->add_option("--to", a.to, "udp:HOST:PORT (pose datagrams) or tcp:HOST:PORT (pose lines)")->required();
  c->add_option("--datagram-version", a.datagram_version,
                "udp: pose datagram version 1 (84 bytes) or 2 (156 bytes, no rates sent)")
      ->capture_default_str()->check(CLI::IsMember({1, 2}));
  c->add_option("--speed", a.speed,
                "Trajectory seconds per wall second (\"2.5\", \"1/3\"), or max: as fast as the link takes them")
      ->capture_default_str();
  c->add_flag("--loop", a.loop,
              "Send the trajectory again and again (until killed), each pass's times shifted by its span plus "
              "its last interval, sequence numbers continuing");
  c->add_option("--connect-timeout-s", a.connect_timeout_s, "tcp: keep trying to connect this long")
      ->capture_default_str()->check(seconds_in(0.0, 86400.0));
  c->add_flag("--quiet", a.quiet, "No summary on stderr");
  c->callback([args, &exit_code] { exit_code = send(*args); });
}

}  // namespace imuemu::cli
