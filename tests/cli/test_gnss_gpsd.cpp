// Issue 28, acceptance 1 (GNSS errors off): Debian's gpsd, started by this
// test on the ptys of two `imuemu emit` GNSS receivers (one NMEA 0183 at the
// default 1 Hz, one u-blox UBX at 5 Hz), reports TPV fixes whose time,
// latitude, longitude, ellipsoidal altitude, speed and track equal the
// trajectory within each format's resolution. The trajectory is analytic:
// latitude, longitude and height linear in time, so its position and NED
// velocity at any instant are written here from the WGS84 ellipsoid's radii
// of curvature (NIMA TR8350.2), independent of imuemu's geodesy. Each TPV's
// time must also be an epoch of the receiver's rate on the GPS second (the
// default time base puts trajectory time 0 at GPS week 2400, TOW 0).
//
// gpsd runs in the foreground, read-only (-b: it sends no probe or
// configuration to the receivers), on its own port and control socket.
// Wall time: the 8-s trajectory plus start-up, whatever the host's speed
// (nothing here is timed; the counts asked for are a fraction of the epochs).
#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <tuple>
#include <utility>
#include <vector>

#include "tests/support/spawn.hpp"

namespace fs = std::filesystem;
using namespace std::chrono_literals;

namespace {

constexpr const char* kGpsd = "/usr/sbin/gpsd";

// The trajectory: linear in latitude, longitude and ellipsoidal height.
constexpr double kLat0Deg = 47.3977, kLon0Deg = 8.5456, kH0M = 500.0;
constexpr double kLatRateDegS = 9e-5, kLonRateDegS = 6.6e-5, kClimbMS = 1.0;
constexpr double kDurationS = 8.0;
constexpr double kPi = 3.14159265358979323846;
// WGS84 (NIMA TR8350.2): semi-major axis and flattening.
constexpr double kA = 6378137.0, kF = 1.0 / 298.257223563;

struct Truth {
  double lat_deg, lon_deg, h_m, speed_m_s, track_deg;
};

Truth truth_at(double t_s) {
  Truth x;
  x.lat_deg = kLat0Deg + kLatRateDegS * t_s;
  x.lon_deg = kLon0Deg + kLonRateDegS * t_s;
  x.h_m = kH0M + kClimbMS * t_s;
  const double e2 = kF * (2.0 - kF);
  const double s = std::sin(x.lat_deg * kPi / 180.0);
  const double w = std::sqrt(1.0 - e2 * s * s);
  const double meridian_m = kA * (1.0 - e2) / (w * w * w);  // M
  const double normal_m = kA / w;                           // N
  // d(north)/dt = (M + h) dlat/dt, d(east)/dt = (N + h) cos(lat) dlon/dt.
  const double v_n = (meridian_m + x.h_m) * kLatRateDegS * kPi / 180.0;
  const double v_e = (normal_m + x.h_m) * std::cos(x.lat_deg * kPi / 180.0) * kLonRateDegS * kPi / 180.0;
  x.speed_m_s = std::hypot(v_n, v_e);
  x.track_deg = std::atan2(v_e, v_n) * 180.0 / kPi;
  if (x.track_deg < 0.0) x.track_deg += 360.0;
  return x;
}

void write_trajectory(const fs::path& path) {
  std::ofstream f(path);
  f << "time_s,lat_deg,lon_deg,h_m,heading_deg,pitch_deg,roll_deg\n";
  char line[160];
  for (int i = 0; i <= static_cast<int>(kDurationS * 10); ++i) {
    const double t = i / 10.0;
    std::snprintf(line, sizeof line, "%.1f,%.12f,%.12f,%.9f,30,0,0\n", t, kLat0Deg + kLatRateDegS * t,
                  kLon0Deg + kLonRateDegS * t, kH0M + kClimbMS * t);
    f << line;
  }
}

// "2026-01-03T23:59:43.200Z" -> POSIX ms (days from civil: H. Hinnant).
long long posix_ms_of(const std::string& iso) {
  int y = 0, mo = 0, d = 0, h = 0, mi = 0;
  double sec = 0.0;
  if (std::sscanf(iso.c_str(), "%d-%d-%dT%d:%d:%lfZ", &y, &mo, &d, &h, &mi, &sec) != 6) return -1;
  y -= mo <= 2;
  const long long era = (y >= 0 ? y : y - 399) / 400;
  const long long yoe = y - era * 400;
  const long long doy = (153 * (mo + (mo > 2 ? -3 : 9)) + 2) / 5 + d - 1;
  const long long doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
  const long long days = era * 146097 + doe - 719468;
  return ((days * 24 + h) * 60 + mi) * 60'000LL + std::llround(sec * 1000.0);
}

// Trajectory time (ms) of a UTC instant: GPS = UTC + 18 s (IERS, since
// 2017-01-01) on the GPS epoch 1980-01-06 (POSIX 315964800 s); trajectory
// time 0 = GPS week 2400, TOW 0.
long long trajectory_ms_of(long long posix_ms) {
  return posix_ms + 18'000 - 315'964'800'000LL - 2400LL * 604'800'000LL;
}

int free_tcp_port() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = 0;
  socklen_t len = sizeof a;
  if (::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0 ||
      ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) != 0) {
    ::close(fd);
    return -1;
  }
  ::close(fd);
  return ntohs(a.sin_port);
}

int connect_with_retry(int port, std::chrono::milliseconds limit) {
  const auto until = std::chrono::steady_clock::now() + limit;
  while (std::chrono::steady_clock::now() < until) {
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    a.sin_port = htons(static_cast<std::uint16_t>(port));
    if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0) return fd;
    ::close(fd);
    std::this_thread::sleep_for(20ms);
  }
  return -1;
}

bool exited(pid_t pid, int& status) { return ::waitpid(pid, &status, WNOHANG) == pid; }

struct Tolerance {
  double latlon_deg, alt_m, speed_m_s, track_deg;
};

std::string file_text(const fs::path& p) {
  std::ifstream f(p);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

}  // namespace

TEST(GnssGpsd, GpsdReportsTheTrajectoryFromImuemusNmeaAndUbx) {
  if (!fs::exists(kGpsd))
    GTEST_SKIP() << kGpsd << " is absent: install Debian's gpsd (scripts/setup.sh test installs gpsd gpsd-clients)";
  const fs::path dir = fs::temp_directory_path() / ("imuemu_gnss_gpsd_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  write_trajectory(dir / "traj.csv");
  const std::string nmea_link = (dir / "nmea").string(), ubx_link = (dir / "ubx").string();

  const pid_t nmea = imuemu::test::spawn_logged(
      IMUEMU_CLI_PATH, {"emit", "--trajectory", (dir / "traj.csv").string(), "--protocol", "nmea", "--device",
                        "pty:" + nmea_link},
      (dir / "nmea.log").string());
  const pid_t ubx = imuemu::test::spawn_logged(
      IMUEMU_CLI_PATH, {"emit", "--trajectory", (dir / "traj.csv").string(), "--protocol", "ubx", "--rate", "5",
                        "--device", "pty:" + ubx_link},
      (dir / "ubx.log").string());
  ASSERT_GT(nmea, 0);
  ASSERT_GT(ubx, 0);
  // A bound, not a timing: the links appear within milliseconds on an idle
  // host; a loaded CI host (or a sanitizer build) may take seconds.
  for (int i = 0; i < 3000 && !(fs::exists(nmea_link) && fs::exists(ubx_link)); ++i) std::this_thread::sleep_for(10ms);
  ASSERT_TRUE(fs::exists(nmea_link) && fs::exists(ubx_link)) << file_text(dir / "nmea.log") << file_text(dir / "ubx.log");

  const int port = free_tcp_port();
  ASSERT_GT(port, 0);
  const pid_t gpsd = imuemu::test::spawn_logged(
      kGpsd, {"-N", "-n", "-b", "-S", std::to_string(port), "-F", (dir / "gpsd.sock").string(), nmea_link, ubx_link},
      (dir / "gpsd.log").string());
  ASSERT_GT(gpsd, 0);
  const int fd = connect_with_retry(port, 10s);
  ASSERT_GE(fd, 0) << "gpsd did not listen on port " << port << ": " << file_text(dir / "gpsd.log");
  const std::string watch = "?WATCH={\"enable\":true,\"json\":true}\n";
  ASSERT_EQ(::write(fd, watch.data(), watch.size()), static_cast<ssize_t>(watch.size()));

  // Read gpsd's reports until both receivers have finished their trajectory
  // (emit exits at its end), then a little more for the last epoch.
  std::string received;
  int nmea_status = 0, ubx_status = 0;
  bool nmea_done = false, ubx_done = false;
  auto after_both = std::chrono::steady_clock::time_point::max();
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(static_cast<int>(kDurationS) + 30);
  while (std::chrono::steady_clock::now() < std::min(after_both, give_up)) {
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, 100) > 0) {
      char buffer[8192];
      const ssize_t n = ::read(fd, buffer, sizeof buffer);
      if (n <= 0) break;
      received.append(buffer, static_cast<std::size_t>(n));
    }
    nmea_done = nmea_done || exited(nmea, nmea_status);
    ubx_done = ubx_done || exited(ubx, ubx_status);
    if (nmea_done && ubx_done && after_both == std::chrono::steady_clock::time_point::max())
      after_both = std::chrono::steady_clock::now() + 300ms;
  }
  ::close(fd);
  ::kill(gpsd, SIGTERM);
  int gpsd_status = 0;
  ::waitpid(gpsd, &gpsd_status, 0);
  if (!nmea_done) ::kill(nmea, SIGTERM), ::waitpid(nmea, &nmea_status, 0);
  if (!ubx_done) ::kill(ubx, SIGTERM), ::waitpid(ubx, &ubx_status, 0);
  std::ofstream(dir / "gpsd.json") << received;  // kept for a failure's diagnosis
  EXPECT_TRUE(WIFEXITED(nmea_status) && WEXITSTATUS(nmea_status) == 0) << file_text(dir / "nmea.log");
  EXPECT_TRUE(WIFEXITED(ubx_status) && WEXITSTATUS(ubx_status) == 0) << file_text(dir / "ubx.log");

  // Resolution of each format (half a step of the wire field, plus half a
  // step of gpsd's JSON print: lat/lon 9 decimals, altHAE 4, speed 3, track 4):
  //   NMEA: ddmm.mmmmmm (1e-6 arc minute), altitude 0.01 m (GGA, geoid
  //     separation 0.00), speed 0.001 knot (RMC), course 0.01 deg;
  //   UBX NAV-PVT: 1e-7 deg, 1 mm, 1 mm/s; gpsd takes the track from
  //     velN/velE (1 mm/s each: atan of 1 mm/s over the 11 m/s ground speed,
  //     5e-3 deg) and the speed from gSpeed.
  const std::map<std::string, Tolerance> tolerance = {
      {nmea_link, {0.5e-6 / 60.0 + 0.5e-9, 0.005 + 0.5e-4, 0.0005 * 1852.0 / 3600.0 + 0.5e-3, 0.005 + 0.5e-4}},
      {ubx_link, {0.5e-7 + 0.5e-9, 0.0005 + 0.5e-4, 0.0005 + 0.5e-3, 5e-3 + 0.5e-4}},
  };
  const std::map<std::string, long long> epoch_ms = {{nmea_link, 1000}, {ubx_link, 200}};
  std::map<std::string, int> fixes;                 // TPVs checked (gpsd reports UBX twice an epoch)
  std::map<std::string, std::set<long long>> epochs;  // distinct epochs among them
  std::map<std::string, std::string> first_tpv;
  std::istringstream lines(received);
  std::string line;
  while (std::getline(lines, line)) {
    const nlohmann::json j = nlohmann::json::parse(line, nullptr, false);
    if (j.is_discarded() || j.value("class", "") != "TPV" || j.value("mode", 0) != 3) continue;
    const std::string device = j.value("device", "");
    if (!tolerance.count(device)) continue;
    if (!j.contains("time") || !j.contains("lat") || !j.contains("lon") || !j.contains("altHAE") ||
        !j.contains("speed") || !j.contains("track"))
      continue;  // a report before the receiver's first whole epoch
    SCOPED_TRACE(line);
    const long long t_ms = trajectory_ms_of(posix_ms_of(j["time"].get<std::string>()));
    // The fix's time is an epoch of the receiver's rate, on the GPS second.
    EXPECT_EQ(t_ms % epoch_ms.at(device), 0) << "epoch not on the receiver's grid";
    EXPECT_GE(t_ms, 0);
    EXPECT_LE(t_ms, static_cast<long long>(kDurationS * 1000));
    const Truth x = truth_at(static_cast<double>(t_ms) * 1e-3);
    const Tolerance& tol = tolerance.at(device);
    EXPECT_NEAR(j["lat"].get<double>(), x.lat_deg, tol.latlon_deg);
    EXPECT_NEAR(j["lon"].get<double>(), x.lon_deg, tol.latlon_deg);
    EXPECT_NEAR(j["altHAE"].get<double>(), x.h_m, tol.alt_m);
    EXPECT_NEAR(j["speed"].get<double>(), x.speed_m_s, tol.speed_m_s);
    EXPECT_NEAR(j["track"].get<double>(), x.track_deg, tol.track_deg);
    if (fixes[device]++ == 0) first_tpv[device] = line;
    epochs[device].insert(t_ms);
  }
  // gpsd needs a sentence or two to lock on, and the epochs sent before it
  // opened the ptys are lost (emit starts on its own): of the 9 NMEA and 41
  // UBX epochs, 7 and 33 reached it on an idle host; a third is asked for.
  EXPECT_GE(epochs[nmea_link].size(), 3u) << received.substr(0, 4000) << file_text(dir / "gpsd.log");
  EXPECT_GE(epochs[ubx_link].size(), 13u) << received.substr(0, 4000) << file_text(dir / "gpsd.log");
  std::printf("gpsd TPV fixes: %d from NMEA (%zu epochs), %d from UBX (%zu epochs); first NMEA: %s\nfirst UBX: %s\n",
              fixes[nmea_link], epochs[nmea_link].size(), fixes[ubx_link], epochs[ubx_link].size(),
              first_tpv[nmea_link].c_str(), first_tpv[ubx_link].c_str());
  if (!HasFailure()) fs::remove_all(dir);
}

// What a GNSS receiver refuses on `imuemu emit`'s command line before
// opening anything: a rate beyond the 1..10 Hz navigation rates, and a flat
// scene (no geodetic position to report). Exit code 2 (usage) with the reason.
TEST(GnssGpsd, EmitRefusesAFastRateAndAFlatScene) {
  const auto run = [](const std::string& args) {
    const std::string cmd = std::string(IMUEMU_CLI_PATH) + " " + args + " 2>&1";
    std::string out;
    FILE* p = ::popen(cmd.c_str(), "r");
    char buf[4096];
    std::size_t n = 0;
    while (p && (n = std::fread(buf, 1, sizeof buf, p)) > 0) out.append(buf, n);
    const int status = p ? ::pclose(p) : -1;
    return std::make_pair(WIFEXITED(status) ? WEXITSTATUS(status) : -1, out);
  };
  const std::string link = (fs::temp_directory_path() / ("imuemu_gnss_refuse_" + std::to_string(::getpid()))).string();
  auto [code, out] = run("emit --sample static --protocol ubx --rate 20 --device pty:" + link);
  EXPECT_EQ(code, 2) << out;
  EXPECT_NE(out.find("navigates at 1..10 Hz"), std::string::npos) << out;
  std::tie(code, out) = run("emit --sample static --scene flat --protocol nmea --device pty:" + link);
  EXPECT_EQ(code, 2) << out;
  EXPECT_NE(out.find("needs --scene ecef"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(link));
}
