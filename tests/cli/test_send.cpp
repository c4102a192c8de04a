// `imuemu send` (daemon/cli/send_command.hpp), through the real binary:
//  - on the wire: UDP datagrams v1 and v2 decoded here by a decoder written
//    from docs/pose-wire-format.md §2 (own CRC-32C loop, own little-endian
//    reads), TCP pose lines parsed back; both against the file's records,
//    bit for bit, in order, with consecutive sequence numbers;
//  - pacing: the wall time of a paced run is at least span / speed (a lower
//    bound only: a loaded host can only make it later);
//  - refusals: a bad file line (file, line, column named, nothing sent, exit
//    3), a TCP port nobody listens on (exit 5 after --connect-timeout-s),
//    usage errors (exit 2); a UDP port nobody listens on is said, not fatal;
//  - end to end: imuemud on config/live-udp.toml (its UDP port and pty link
//    moved to free ones, margin_s 0.5 instead of 0.05 so a loaded host does
//    not make poses late), `imuemu send` of a 50 Hz flight, `imuemu listen`
//    on the pty; every sample the daemon flagged exact (status 0) equals
//    `imuemu generate` on the same file with the scene's method (ecef,
//    delta = window_s * rate = 20, gap split at 1 s) bit for bit in gyro and
//    accel: the native protocol carries binary64, and the live path and the
//    batch path are one computation (core/stream.hpp);
//  - TCP end to end: `imuemu stream --source tcp:` fed by `imuemu send`, its
//    exact samples equal to generate's the same way.
#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "io/trajectory_csv.hpp"
#include "tests/support/spawn.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_cli_test_send {
namespace imuemu { using namespace ::imuemu; }

namespace fs = std::filesystem;
using namespace std::chrono_literals;

namespace {

struct SendRun {
  int exit_code = -1;
  std::string output;  // stdout + stderr
};

SendRun run_imuemu(const std::string& args) {
  const std::string cmd = std::string(IMUEMU_CLI_PATH) + " " + args + " 2>&1";
  SendRun r;
  FILE* p = ::popen(cmd.c_str(), "r");
  if (!p) return r;
  char buf[4096];
  std::size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) r.output.append(buf, n);
  const int status = ::pclose(p);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

// CRC-32C from its definition (docs/pose-wire-format.md §2.3): reflected
// polynomial 0x82F63B78, init and final xor 0xFFFFFFFF.
std::uint32_t spec_crc32c(const std::uint8_t* p, std::size_t n) {
  std::uint32_t crc = 0xFFFFFFFFu;
  for (std::size_t i = 0; i < n; ++i) {
    crc ^= p[i];
    for (int k = 0; k < 8; ++k) crc = (crc & 1u) ? (crc >> 1) ^ 0x82F63B78u : crc >> 1;
  }
  return crc ^ 0xFFFFFFFFu;
}

std::uint64_t le_u64(const std::uint8_t* p) {
  std::uint64_t v = 0;
  for (int i = 7; i >= 0; --i) v = (v << 8) | p[i];
  return v;
}
std::uint32_t le_u32(const std::uint8_t* p) {
  return static_cast<std::uint32_t>(p[0]) | (static_cast<std::uint32_t>(p[1]) << 8) |
         (static_cast<std::uint32_t>(p[2]) << 16) | (static_cast<std::uint32_t>(p[3]) << 24);
}
double le_f64(const std::uint8_t* p) {
  const std::uint64_t bits = le_u64(p);
  double d;
  std::memcpy(&d, &bits, sizeof d);
  return d;
}

struct Udp {
  int fd = -1;
  int port = 0;
  Udp() {
    fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    int big = 1 << 20;
    ::setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &big, sizeof big);
    socklen_t len = sizeof a;
    if (::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0 &&
        ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) == 0)
      port = ntohs(a.sin_port);
  }
  ~Udp() { ::close(fd); }
  // Every datagram queued now (the sender has exited: all of it is here).
  std::vector<std::vector<std::uint8_t>> drain() const {
    std::vector<std::vector<std::uint8_t>> out;
    std::array<std::uint8_t, 2048> buf{};
    for (;;) {
      const ssize_t n = ::recv(fd, buf.data(), buf.size(), MSG_DONTWAIT);
      if (n < 0) break;
      out.emplace_back(buf.begin(), buf.begin() + n);
    }
    return out;
  }
};

// A free port of the given type on 127.0.0.1 (bound to 0, read, released).
int free_port(int type) {
  const int fd = ::socket(AF_INET, type | SOCK_CLOEXEC, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t len = sizeof a;
  int port = -1;
  if (::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0 &&
      ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) == 0)
    port = ntohs(a.sin_port);
  ::close(fd);
  return port;
}

class Send : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("imuemu_send_" + std::to_string(::getpid()) + "_" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  // A flight at `period` for `seconds`, written by `imuemu sample-trajectory`.
  std::string flight(double seconds, double period) {
    const std::string f = path("flight.csv");
    const SendRun r = run_imuemu("sample-trajectory --kind flight --out " + f + " --duration-s " + std::to_string(seconds) +
                                 " --period-s " + std::to_string(period));
    EXPECT_EQ(r.exit_code, 0) << r.output;
    return f;
  }
  fs::path dir_;
};

// Datagrams of both versions against the file's records, from the spec's bytes.
TEST_F(Send, UdpDatagramsCarryTheFileRecordsBitForBit) {
  const std::string f = flight(2.0, 0.05);
  const imuemu::io::Trajectory want = imuemu::io::read_trajectory_csv(f);
  ASSERT_EQ(want.records.size(), 41u);
  for (int version : {1, 2}) {
    SCOPED_TRACE("datagram version " + std::to_string(version));
    Udp rx;
    ASSERT_GT(rx.port, 0);
    const SendRun r = run_imuemu("send --in " + f + " --to udp:127.0.0.1:" + std::to_string(rx.port) +
                                 " --speed max --datagram-version " + std::to_string(version));
    ASSERT_EQ(r.exit_code, 0) << r.output;
    EXPECT_NE(r.output.find("41 poses sent"), std::string::npos) << r.output;
    const auto got = rx.drain();
    ASSERT_EQ(got.size(), want.records.size());
    const std::size_t size = version == 1 ? 84 : 156;
    for (std::size_t i = 0; i < got.size(); ++i) {
      const auto& d = got[i];
      const auto& w = want.records[i];
      ASSERT_EQ(d.size(), size) << i;
      EXPECT_EQ(std::memcmp(d.data(), "IMUP", 4), 0);
      EXPECT_EQ(d[4], version);
      EXPECT_EQ(d[5], 0);  // geodetic
      EXPECT_EQ(d[6], 0);  // heading-pitch-roll
      EXPECT_EQ(d[7], 0);  // reserved (v1) / rates mask: none (v2)
      EXPECT_EQ(le_u32(d.data() + size - 4), spec_crc32c(d.data(), size - 4)) << i;
      EXPECT_EQ(le_u64(d.data() + 8), static_cast<std::uint64_t>(i));  // sequence from 0, +1 each
      EXPECT_EQ(static_cast<std::int64_t>(le_u64(d.data() + 16)), w.t_ns) << i;
      for (int k = 0; k < 3; ++k) EXPECT_EQ(le_f64(d.data() + 24 + 8 * k), w.position[k]) << i << " position " << k;
      for (int k = 0; k < 3; ++k) EXPECT_EQ(le_f64(d.data() + 48 + 8 * k), w.attitude[k]) << i << " attitude " << k;
      EXPECT_EQ(le_f64(d.data() + 72), 0.0);
      for (std::size_t k = 80; k < size - 4 && version == 2; ++k) EXPECT_EQ(d[k], 0) << "absent rates are zero";
    }
  }
}

// Paced: 0.6 s of trajectory at --speed 2 cannot take less than 0.3 s of
// wall time. --loop sends pass after pass with times shifted by the span plus
// the last interval (checked on what arrived before the sender was stopped).
TEST_F(Send, PacedAndLooped) {
  const std::string f = flight(0.6, 0.05);
  Udp rx;
  const auto start = std::chrono::steady_clock::now();
  const SendRun r = run_imuemu("send --in " + f + " --to udp:127.0.0.1:" + std::to_string(rx.port) + " --speed 2 --quiet");
  const double wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(r.output, "");  // --quiet
  EXPECT_EQ(rx.drain().size(), 13u);
  EXPECT_GE(wall_s, 0.3);

  // --loop at --speed 100: 13 poses per 0.65 s of trajectory, 6.5 ms of wall time per pass.
  const std::string log = path("loop.log");
  const pid_t pid = imuemu::test::spawn_logged(
      IMUEMU_CLI_PATH, {"send", "--in", f, "--to", "udp:127.0.0.1:" + std::to_string(rx.port), "--speed", "100", "--loop"}, log);
  ASSERT_GT(pid, 0);
  std::vector<std::vector<std::uint8_t>> got;
  for (int i = 0; i < 2000 && got.size() < 40; ++i) {
    for (auto& d : rx.drain()) got.push_back(std::move(d));
    std::this_thread::sleep_for(5ms);
  }
  ::kill(pid, SIGTERM);
  int status = 0;
  ::waitpid(pid, &status, 0);
  ASSERT_GE(got.size(), 40u);
  const imuemu::io::Trajectory want = imuemu::io::read_trajectory_csv(f);
  const std::int64_t shift = 650'000'000;  // span 0.6 s + last interval 0.05 s
  for (std::size_t i = 0; i < 40; ++i) {
    EXPECT_EQ(le_u64(got[i].data() + 8), i);
    EXPECT_EQ(static_cast<std::int64_t>(le_u64(got[i].data() + 16)),
              want.records[i % 13].t_ns + shift * static_cast<std::int64_t>(i / 13)) << i;
    EXPECT_EQ(le_f64(got[i].data() + 24), want.records[i % 13].position[0]) << i;
  }
}

// TCP: the version line, the header, then one line per record that parses back
// (with the trajectory reader) to the file's record exactly.
TEST_F(Send, TcpLinesParseBackToTheFileRecords) {
  const std::string f = flight(2.0, 0.05);
  const int lfd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t len = sizeof a;
  ASSERT_EQ(::bind(lfd, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
  ASSERT_EQ(::listen(lfd, 1), 0);
  ASSERT_EQ(::getsockname(lfd, reinterpret_cast<sockaddr*>(&a), &len), 0);
  const int port = ntohs(a.sin_port);
  SendRun r;
  std::thread sender([&] { r = run_imuemu("send --in " + f + " --to tcp:127.0.0.1:" + std::to_string(port) + " --speed max"); });
  const int cfd = ::accept(lfd, nullptr, nullptr);
  std::string text;
  char buf[4096];
  for (ssize_t n; cfd >= 0 && (n = ::read(cfd, buf, sizeof buf)) > 0;) text.append(buf, static_cast<std::size_t>(n));
  sender.join();
  ::close(cfd);
  ::close(lfd);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(text.rfind("# imuemu-pose-lines v1\ntime_s,lat_deg,lon_deg,h_m,heading_deg,pitch_deg,roll_deg\n", 0), 0u) << text;
  ASSERT_EQ(text.back(), '\n');
  const imuemu::io::Trajectory got = imuemu::io::parse_trajectory_csv(text, "tcp");
  const imuemu::io::Trajectory want = imuemu::io::read_trajectory_csv(f);
  ASSERT_EQ(got.records.size(), want.records.size());
  for (std::size_t i = 0; i < got.records.size(); ++i) {
    EXPECT_EQ(got.records[i].t_ns, want.records[i].t_ns) << i;
    EXPECT_EQ(got.records[i].position, want.records[i].position) << i;
    EXPECT_EQ(got.records[i].attitude, want.records[i].attitude) << i;
  }
}

TEST_F(Send, Refusals) {
  // A bad line: the message names the file, the line and the column; nothing is sent.
  std::ofstream(path("bad.csv")) << "time_s,lat_deg,lon_deg,h_m,heading_deg,pitch_deg,roll_deg\n"
                                    "0.0,41.0,2.0,100.0,90.0,2.0,0.0\n"
                                    "0.1,41.0,2.0,100.0,90.0,91.0,0.0\n";
  Udp rx;
  SendRun r = run_imuemu("send --in " + path("bad.csv") + " --to udp:127.0.0.1:" + std::to_string(rx.port));
  EXPECT_EQ(r.exit_code, 3) << r.output;
  EXPECT_NE(r.output.find(path("bad.csv") + ":3: column 'pitch_deg' (6)"), std::string::npos) << r.output;
  EXPECT_TRUE(rx.drain().empty());
  r = run_imuemu("send --in " + path("missing.csv") + " --to udp:127.0.0.1:" + std::to_string(rx.port));
  EXPECT_EQ(r.exit_code, 3) << r.output;
  EXPECT_NE(r.output.find("missing.csv"), std::string::npos) << r.output;

  // A TCP port nobody listens on: refused until --connect-timeout-s, exit 5 naming it.
  const int port = free_port(SOCK_STREAM);
  r = run_imuemu("send --sample static --duration-s 1 --to tcp:127.0.0.1:" + std::to_string(port) + " --connect-timeout-s 0.3");
  EXPECT_EQ(r.exit_code, 5) << r.output;
  EXPECT_NE(r.output.find("tcp:127.0.0.1:" + std::to_string(port) + ": cannot connect within --connect-timeout-s: Connection refused"),
            std::string::npos) << r.output;

  // A UDP port nobody listens on is no error (the receiver may start later):
  // the datagrams the kernel refused (ICMP port unreachable, reported on the
  // next send) are counted and said, the exit is 0.
  const int udp_port = free_port(SOCK_DGRAM);
  r = run_imuemu("send --sample static --duration-s 1 --sample-period-s 0.1 --speed 10 --to udp:127.0.0.1:" + std::to_string(udp_port));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("nothing listens there yet (port unreachable); still sending"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("refused (port unreachable)"), std::string::npos) << r.output;

  // Usage: a destination that is neither udp: nor tcp:, no input, two inputs, v2 over tcp.
  for (const std::string& args : {std::string("send --sample static --to serial:/dev/ttyS0"),
                                  std::string("send --to udp:127.0.0.1:9"),
                                  std::string("send --in x.csv --sample static --to udp:127.0.0.1:9"),
                                  std::string("send --sample static --to udp:127.0.0.1:0"),
                                  std::string("send --sample static --to udp:127.0.0.1:9 --speed 0"),
                                  std::string("send --sample static --to tcp:127.0.0.1:9 --datagram-version 2")}) {
    r = run_imuemu(args);
    EXPECT_EQ(r.exit_code, 2) << args << "\n" << r.output;
  }
}

// End to end: imuemu send -> imuemud (config/live-udp.toml) -> pty -> imuemu listen,
// against imuemu generate on the same poses.
TEST_F(Send, DrivesTheLiveUdpSceneLikeGenerate) {
  const std::string f = flight(3.0, 0.02);  // the scene's knot_interval_s
  std::ifstream in(std::string(IMUEMU_SOURCE_DIR) + "/config/live-udp.toml");
  std::stringstream scene_text;
  scene_text << in.rdbuf();
  std::string scene = scene_text.str();
  const int port = free_port(SOCK_DGRAM);
  for (const auto& [from, to] : {std::pair<std::string, std::string>{"udp:0.0.0.0:5005", "udp:127.0.0.1:" + std::to_string(port)},
                                 {"margin_s = 0.05", "margin_s = 0.5"}}) {
    const auto at = scene.find(from);
    ASSERT_NE(at, std::string::npos) << from << " not in config/live-udp.toml";
    scene.replace(at, from.size(), to);
  }
  std::ofstream(path("live.toml")) << scene;
  const std::string link = path("ttyIMU0");
  const pid_t daemon = imuemu::test::spawn_logged(
      IMUEMUD_PATH, {"--scene", path("live.toml"), "--pty-link-dir", dir_.string(), "--control-socket", path("c.sock"), "--late-ticks", "send"},
      path("daemon.log"));
  ASSERT_GT(daemon, 0);
  struct Stop {
    pid_t pid;
    ~Stop() {
      ::kill(pid, SIGTERM);
      int status = 0;
      ::waitpid(pid, &status, 0);
    }
  } stop_daemon{daemon};
  for (int i = 0; i < 3000 && !fs::is_symlink(link); ++i) std::this_thread::sleep_for(10ms);
  ASSERT_TRUE(fs::is_symlink(link)) << std::ifstream(path("daemon.log")).rdbuf();
  // listen stops after the samples of the 3 s of poses (1200 at 400 Hz; the
  // emitter extrapolates past the last pose, so they come), or after 20 s.
  const pid_t listen = imuemu::test::spawn_logged(
      IMUEMU_CLI_PATH, {"listen", "--protocol", "native", "--device", link, "--out", path("capture.csv"), "--count", "1200",
                        "--duration-s", "20", "--quiet"},
      path("listen.log"));
  ASSERT_GT(listen, 0);
  const SendRun sent = run_imuemu("send --in " + f + " --to udp:127.0.0.1:" + std::to_string(port));
  EXPECT_EQ(sent.exit_code, 0) << sent.output;
  int status = 0;
  ASSERT_EQ(::waitpid(listen, &status, 0), listen);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << std::ifstream(path("listen.log")).rdbuf();

  const SendRun gen = run_imuemu("generate --in " + f + " --out " + path("reference.csv") +
                                 " --rate 400 --scene ecef --delta 20 --gap-policy split --max-gap-s 1 --quiet");
  ASSERT_EQ(gen.exit_code, 0) << gen.output;
  std::map<std::int64_t, std::array<double, 6>> reference;
  {
    std::ifstream ref(path("reference.csv"));
    std::string line;
    while (std::getline(ref, line)) {
      if (line.empty() || line[0] == '#' || line.rfind("time", 0) == 0) continue;
      std::stringstream ss(line);
      std::string field;
      std::getline(ss, field, ',');
      const std::int64_t t = std::stoll(field);
      std::array<double, 6> v{};
      for (double& x : v) {
        std::getline(ss, field, ',');
        x = std::stod(field);
      }
      reference[t] = v;
    }
  }
  ASSERT_GT(reference.size(), 1000u);
  std::ifstream cap(path("capture.csv"));
  std::string line;
  std::getline(cap, line);  // header
  std::size_t rows = 0, exact = 0, compared = 0;
  while (std::getline(cap, line)) {
    ++rows;
    std::vector<std::string> f6;
    std::stringstream ss(line);
    for (std::string field; std::getline(ss, field, ',');) f6.push_back(field);
    ASSERT_EQ(f6.size(), 15u) << line;
    if (std::stoul(f6[14]) != 0) continue;  // extrapolated or blending: not the smoother's own sample
    ++exact;
    const std::int64_t t = std::stoll(f6[1]);
    const auto it = reference.find(t);
    ASSERT_NE(it, reference.end()) << "sample time " << t << " is not on generate's 400 Hz grid";
    ++compared;
    for (int k = 0; k < 6; ++k) EXPECT_EQ(std::stod(f6[2 + k]), it->second[k]) << "t_ns " << t << " column " << k;
  }
  std::cout << "live-udp via imuemu send: " << rows << " samples captured, " << exact << " exact, " << compared
            << " equal to generate's compared\n";
  EXPECT_EQ(rows, 1200u);
  // Most of the 3 s are exact samples: with 0.5 s of margin a pose is late
  // only if the sender stalls for half a second.
  EXPECT_GE(compared, 800u) << exact << " exact samples of " << rows;
}

}  // namespace

namespace {

// IMU CSV rows keyed by time: "time_ns,gx,gy,gz,ax,ay,az[,status]" (generate's
// and stream's layout); with a status column only rows whose status is `keep`.
std::map<std::int64_t, std::array<double, 6>> read_imu_rows(const std::string& path, const std::string& keep = "") {
  std::map<std::int64_t, std::array<double, 6>> rows;
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#' || line.rfind("time", 0) == 0) continue;
    std::vector<std::string> f;
    std::stringstream ss(line);
    for (std::string field; std::getline(ss, field, ',');) f.push_back(field);
    if (f.size() < 7 || (f.size() == 8 && !keep.empty() && f[7] != keep)) continue;
    std::array<double, 6> v{};
    for (std::size_t k = 0; k < 6; ++k) v[k] = std::stod(f[k + 1]);
    rows[std::stoll(f[0])] = v;
  }
  return rows;
}

// TCP end to end: `imuemu stream --source tcp:` fed by `imuemu send --to tcp:`
// (started first: it retries the connection until the stream listens); every
// sample stream marks exact equals generate's on the same file with the same
// method (Delta 8 = one 0.02 s knot interval at 400 Hz, gap split at 1 s).
TEST_F(Send, TcpDrivesImuemuStreamLikeGenerate) {
  const std::string f = flight(2.0, 0.02);
  const int port = free_port(SOCK_STREAM);
  const pid_t sender = imuemu::test::spawn_logged(
      IMUEMU_CLI_PATH, {"send", "--in", f, "--to", "tcp:127.0.0.1:" + std::to_string(port), "--connect-timeout-s", "20"},
      path("send.log"));
  ASSERT_GT(sender, 0);
  const SendRun streamed = run_imuemu("stream --source tcp:127.0.0.1:" + std::to_string(port) +
                                      " --knot-interval-s 0.02 --delta 8 --margin-s 0.5 --max-gap-s 1 --duration-s 1.5 --out " +
                                      path("stream.csv"));
  int status = 0;
  ASSERT_EQ(::waitpid(sender, &status, 0), sender);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << std::ifstream(path("send.log")).rdbuf();
  ASSERT_EQ(streamed.exit_code, 0) << streamed.output;
  const SendRun gen = run_imuemu("generate --in " + f + " --out " + path("reference.csv") +
                                 " --rate 400 --scene ecef --delta 8 --gap-policy split --max-gap-s 1 --quiet");
  ASSERT_EQ(gen.exit_code, 0) << gen.output;
  const auto reference = read_imu_rows(path("reference.csv"));
  const auto exact = read_imu_rows(path("stream.csv"), "exact");
  std::cout << "tcp via imuemu send: " << exact.size() << " exact samples from imuemu stream compared\n";
  EXPECT_GE(exact.size(), 400u);  // of the 601 in 1.5 s
  for (const auto& [t, v] : exact) {
    const auto it = reference.find(t);
    ASSERT_NE(it, reference.end()) << "sample time " << t << " is not on generate's 400 Hz grid";
    for (std::size_t k = 0; k < 6; ++k) EXPECT_EQ(v[k], it->second[k]) << "t_ns " << t << " column " << k;
  }
}

}  // namespace
}  // namespace unity_cli_test_send
