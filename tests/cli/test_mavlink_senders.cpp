// A live MAVLink source takes one vehicle (issue 26 N4): several senders of
// HIL_STATE_QUATERNION on one port (two simulated vehicles, a stray ground
// station, a second bridge) were merged into one pose stream. Now the source
// takes the configured (sysid, compid), or the first one seen, and counts and
// logs the others (io/pose_admission.hpp, docs/pose-wire-format.md §4.5).
//
// Truth: the packets each test builds (their sender and their pose); what the
// smoother makes of the admitted poses is judged against the motion sent
// (a hovering vehicle feels gravity only, a vehicle yawing at a constant rate
// turns at that rate), through core's batch pipeline, the same smoother the
// emission engine runs.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <mutex>
#include <numbers>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "core/pipeline.hpp"
#include "core/so3.hpp"
#include "daemon/cli/status_command.hpp"
#include "daemon/scene/scene_config.hpp"
#include "daemon/scene/scene_runner.hpp"
#include "io/mavlink_pose.hpp"
#include "io/pose_admission.hpp"
#include "io/pose_source.hpp"
#include "tests/support/udp_sender.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace imuemu::io {}
namespace unity_cli_test_mavlink_senders {
namespace imuemu { using namespace ::imuemu; }
namespace imuemu::io { using namespace ::imuemu::io; }

namespace imuemu::io {
namespace {

using Bytes = std::vector<std::uint8_t>;
using namespace std::chrono_literals;

constexpr std::uint64_t kPeriodUs = 20'000;  // each vehicle at 50 Hz
constexpr std::int32_t kLat1kmDegE7 = 90'039;  // 1 km of latitude at 41.5 deg: 1e3 m / M, M = 6.3634e6 m (WGS84 meridian radius)

// A level vehicle at (41.5 N, 2.25 E, 100 m), heading `yaw_rad`, at rest.
mavlink::HilStateQuaternion hover(std::uint64_t time_usec, double yaw_rad, std::int32_t north_degE7 = 0) {
  mavlink::HilStateQuaternion m;
  m.time_usec = time_usec;
  m.attitude_quaternion = {static_cast<float>(std::cos(yaw_rad / 2)), 0.0f, 0.0f,
                           static_cast<float>(std::sin(yaw_rad / 2))};
  m.lat_degE7 = 415'000'000 + north_degE7;
  m.lon_degE7 = 22'500'000;
  m.alt_mm = 100'000;
  return m;
}

Bytes packet(const mavlink::HilStateQuaternion& m, std::uint8_t sequence, std::uint8_t sysid, std::uint8_t compid = 1) {
  return mavlink::encode_hil_state_quaternion(m, {sequence, sysid, compid});
}

struct Admitted {
  std::vector<SourcedPose> poses;
  PoseSourceCounters counters;
  std::vector<std::string> log;
};

// The datagrams through one source's admission, in order, as the UDP source
// hands them over (receive time = the packet's index in ms).
Admitted admit_all(const std::vector<Bytes>& datagrams, PoseSourceOptions options = {}) {
  Admitted a;
  options.physics = Physics::ecef;
  options.log = [&a](std::string_view line) { a.log.emplace_back(line); };
  PoseAdmission admission(options);
  TimeNs receive_ns = 1'000'000'000;
  for (const Bytes& d : datagrams) {
    SourcedPose out;
    receive_ns += 1'000'000;
    if (admission.receive_mavlink_datagram(d, receive_ns, "127.0.0.1:14550", out)) {
      a.poses.push_back(out);
      while (admission.take_released(out)) a.poses.push_back(out);
    }
  }
  a.counters = admission.counters();
  return a;
}

// The smoother over the admitted poses (core's batch pipeline: the emission
// engine's smoother) at 200 Hz, one knot interval of window.
BatchResult smoothed(const std::vector<SourcedPose>& admitted) {
  std::vector<Pose> knots;
  for (const SourcedPose& p : admitted) knots.push_back(p.pose);
  PipelineOptions o;
  o.scene.physics = Physics::ecef;
  o.rate_hz = 200;
  o.kernel.delta = 4;
  return run_batch(knots, o);
}

double max_norm(const std::vector<ImuSample>& imu, Vec3 ImuSample::*field) {
  double m = 0;
  for (const ImuSample& s : imu) m = std::max(m, (s.*field).norm());
  return m;
}

// Two vehicles (sysid 1 and 2) hovering 1 km apart, their packets
// interleaved, their clocks 10 ms apart. Before: both were admitted, the
// stream jumped 1 km every 10 ms and the smoother made specific forces of
// ~1e7 m/s^2 of it. Now: vehicle 1 (the first seen) only, vehicle 2 counted.
TEST(MavlinkSenders, TwoVehiclesOneKilometreApartOnlyTheFirstReachesTheSmoother) {
  constexpr std::size_t kPackets = 250;  // 5 s each
  std::vector<Bytes> datagrams;
  for (std::size_t k = 0; k < kPackets; ++k) {
    const auto seq = static_cast<std::uint8_t>(k);
    datagrams.push_back(packet(hover(1'000'000 + kPeriodUs * k, 0.0), seq, 1));
    datagrams.push_back(packet(hover(1'010'000 + kPeriodUs * k, 0.0, kLat1kmDegE7), seq, 2));
  }
  const Admitted a = admit_all(datagrams);
  ASSERT_GE(a.poses.size(), 2u);
  EXPECT_EQ(a.poses.size(), kPackets) << "accepted " << a.counters.accepted << " of " << a.counters.received;
  const Vec3 vehicle1 = a.poses.front().pose.position_m;
  std::size_t not_vehicle1 = 0, off_time = 0;
  for (std::size_t k = 0; k < a.poses.size(); ++k) {
    off_time += a.poses[k].pose.t_ns != static_cast<TimeNs>(1'000'000'000 + 20'000'000 * k);
    not_vehicle1 += a.poses[k].pose.position_m != vehicle1;
  }
  EXPECT_EQ(not_vehicle1, 0u) << "poses of vehicle 2 reached the smoother";
  EXPECT_EQ(off_time, 0u);
  // At rest: the accelerometer reads gravity (9.80 m/s^2 at 41.5 N), nothing of a 1-km jump.
  const BatchResult b = smoothed(a.poses);
  const double f_max = max_norm(b.imu, &ImuSample::accel_m_s2);
  EXPECT_LT(f_max, 9.81) << "specific force " << f_max << " m/s^2";
  EXPECT_GT(f_max, 9.79);
  EXPECT_EQ(a.counters.other_sender, kPackets);
  EXPECT_EQ(a.counters.rejected(), kPackets);
  EXPECT_EQ(a.counters.received, a.counters.accepted + a.counters.rejected() + a.counters.held + a.counters.ignored);
  EXPECT_EQ(a.counters.lost(), 0u);  // vehicle 2's numbers never enter vehicle 1's loss statistics
}

// Vehicle 1 yaws at 0.2 rad/s; once a second a stray packet of sysid 7 (a
// ground station's test message) says heading + 90 deg at the same place.
// Before: each stray was admitted between two poses of vehicle 1 and the
// gyro spiked (tens of rad/s). Now: the strays are counted, the gyro is the
// vehicle's 0.2 rad/s (plus Earth rate).
TEST(MavlinkSenders, AStrayPacketASecondFromAnotherSystemMakesNoGyroSpike) {
  constexpr double kYawRate = 0.2;
  constexpr std::size_t kPackets = 500;  // 10 s
  std::vector<Bytes> datagrams;
  std::size_t strays = 0;
  for (std::size_t k = 0; k < kPackets; ++k) {
    const double t_s = static_cast<double>(k) * 0.02;
    datagrams.push_back(packet(hover(1'000'000 + kPeriodUs * k, kYawRate * t_s), static_cast<std::uint8_t>(k), 1));
    if (k % 50 == 25) {
      datagrams.push_back(packet(hover(1'010'000 + kPeriodUs * k, kYawRate * t_s + std::numbers::pi / 2),
                                 static_cast<std::uint8_t>(strays), 7, 190));
      ++strays;
    }
  }
  const Admitted a = admit_all(datagrams);
  ASSERT_GE(a.poses.size(), 2u);
  const BatchResult b = smoothed(a.poses);
  const double w_max = max_norm(b.imu, &ImuSample::gyro_rad_s);
  EXPECT_LT(w_max, kYawRate + 1e-3) << "gyro spike: " << w_max << " rad/s";
  EXPECT_GT(w_max, kYawRate - 1e-3);
  EXPECT_EQ(a.poses.size(), kPackets);
  EXPECT_EQ(a.counters.other_sender, strays);
  // Logged, naming the sender; at most one line a second per sender.
  std::size_t lines = 0;
  for (const std::string& l : a.log) lines += l.find("sysid 7 compid 190") != std::string::npos;
  EXPECT_GE(lines, 1u);
  EXPECT_LE(lines, strays);
}

// Two senders at the same place, headings 175 deg apart (beyond the
// smoother's 3-rad chart), clocks interleaved. Before: no two consecutive
// poses were consistent, so the stream was never acquired and nothing at all
// was emitted. Now: the first sender's poses, all of them, with its attitude.
TEST(MavlinkSenders, TwoSendersWithDifferentAttitudesTheFirstIsEmitted) {
  constexpr std::size_t kPackets = 100;
  const double kOther = 175.0 * std::numbers::pi / 180.0;
  std::vector<Bytes> datagrams;
  for (std::size_t k = 0; k < kPackets; ++k) {
    const auto seq = static_cast<std::uint8_t>(k);
    datagrams.push_back(packet(hover(1'000'000 + kPeriodUs * k, 0.3), seq, 1, 1));
    datagrams.push_back(packet(hover(1'010'000 + kPeriodUs * k, 0.3 + kOther), seq, 1, 2));  // another component
  }
  const Admitted a = admit_all(datagrams);
  ASSERT_EQ(a.poses.size(), kPackets) << "accepted " << a.counters.accepted << ", chart_span "
                                      << a.counters.chart_span << ", time_jump " << a.counters.time_jump;
  for (const SourcedPose& p : a.poses) EXPECT_LT(so3::angle(a.poses.front().pose.attitude.transpose() * p.pose.attitude), 1e-12);
  EXPECT_EQ(a.poses.front().pose.t_ns, 1'000'000'000);
  EXPECT_EQ(a.counters.other_sender, kPackets);
  EXPECT_EQ(a.counters.chart_span + a.counters.attitude_step + a.counters.time_jump, 0u);
  bool taken = false, other = false;
  for (const std::string& l : a.log) {
    taken = taken || l.find("takes sysid 1 compid 1") != std::string::npos;
    other = other || l.find("sysid 1 compid 2") != std::string::npos;
  }
  EXPECT_TRUE(taken) << "no line names the sender taken";
  EXPECT_TRUE(other) << "no line names the other sender";
}


// A configured sender is taken even when another one speaks first; the
// component may be left free (the first component of that system is taken).
TEST(MavlinkSenders, AConfiguredSystemIsTakenWhateverSpeaksFirst) {
  std::vector<Bytes> datagrams;
  for (std::size_t k = 0; k < 50; ++k) {
    const auto seq = static_cast<std::uint8_t>(k);
    datagrams.push_back(packet(hover(1'000'000 + kPeriodUs * k, 0.0), seq, 1));
    datagrams.push_back(packet(hover(5'000'000 + kPeriodUs * k, 1.0, kLat1kmDegE7), seq, 2, 7));
    datagrams.push_back(packet(hover(9'000'000 + kPeriodUs * k, 2.0), seq, 2, 8));
  }
  PoseSourceOptions options;
  options.mavlink_system_id = 2;
  const Admitted a = admit_all(datagrams, options);
  ASSERT_EQ(a.poses.size(), 50u);
  EXPECT_EQ(a.poses.front().pose.t_ns, 5'000'000'000);  // sysid 2 compid 7: the first of system 2
  EXPECT_EQ(a.counters.other_sender, 100u);
  options.mavlink_component_id = 8;
  const Admitted b = admit_all(datagrams, options);
  ASSERT_EQ(b.poses.size(), 50u);
  EXPECT_EQ(b.poses.front().pose.t_ns, 9'000'000'000);
  EXPECT_EQ(b.counters.other_sender, 100u);
  // Other messages (HEARTBEAT) of any sender are ignored, as before.
  const Bytes heartbeat = {0xFD, 0x09, 0x00, 0x00, 0x00, 0x05, 0x01, 0x00, 0x00, 0x00, 0x00, 0x00,
                           0x00, 0x00, 0x02, 0x03, 0x51, 0x04, 0x03, 0x00, 0x00};
  const Admitted c = admit_all({heartbeat}, options);
  EXPECT_EQ(c.counters.ignored, 1u);
  EXPECT_EQ(c.counters.other_sender, 0u);
}

// A corrupted packet does not choose the sender (its header cannot be
// trusted), and a packet of the taken sender with impossible values still
// belongs to it: refused for its values, not counted as another sender's.
TEST(MavlinkSenders, OnlyAnIntactPacketChoosesTheSender) {
  Bytes corrupted = packet(hover(1'000'000, 0.0), 0, 9);
  corrupted[20] ^= 0x01;
  mavlink::HilStateQuaternion bad = hover(1'000'000, 0.0);
  bad.attitude_quaternion = {0.5f, 0, 0, 0};
  std::vector<Bytes> datagrams = {corrupted, packet(bad, 0, 3)};
  for (std::size_t k = 1; k < 20; ++k) {
    datagrams.push_back(packet(hover(1'000'000 + kPeriodUs * k, 0.0), static_cast<std::uint8_t>(k), 3));
    datagrams.push_back(packet(hover(1'000'000 + kPeriodUs * k, 0.0), static_cast<std::uint8_t>(k), 9));
  }
  const Admitted a = admit_all(datagrams);
  EXPECT_EQ(a.poses.size(), 19u);
  EXPECT_EQ(a.counters.datagram_errors[static_cast<std::size_t>(DatagramError::bad_checksum)], 1u);
  EXPECT_EQ(a.counters.datagram_errors[static_cast<std::size_t>(DatagramError::bad_value)], 1u);
  EXPECT_EQ(a.counters.other_sender, 19u);
  EXPECT_EQ(a.counters.received, a.counters.accepted + a.counters.rejected() + a.counters.held + a.counters.ignored);
}

// The real UDP source, two senders on two sockets: vehicle 2's datagrams are
// counted and logged once a second, vehicle 1's all arrive.
TEST(MavlinkSenders, LoopbackSourceTakesOneVehicleAndLogsTheOther) {
  std::vector<std::string> log;
  std::mutex log_mutex;
  PoseSourceOptions options;
  options.physics = Physics::ecef;
  options.log = [&](std::string_view line) {
    std::lock_guard lock(log_mutex);
    log.emplace_back(line);
  };
  auto source = make_mavlink_udp_pose_source({"127.0.0.1", 0}, options);
  source->start();
  const test::LoopbackUdpSender one(source->local_port()), two(source->local_port());
  for (std::uint8_t k = 0; k < 20; ++k) {
    ASSERT_TRUE(one.send(packet(hover(1'000'000 + kPeriodUs * k, 0.0), k, 1)));
    ASSERT_TRUE(two.send(packet(hover(1'010'000 + kPeriodUs * k, 0.0, kLat1kmDegE7), k, 2)));
    // Paced, so that the receive buffer never overflows on a loaded host.
    std::this_thread::sleep_for(1ms);
  }
  const auto deadline = std::chrono::steady_clock::now() + 10s;
  while (source->counters().received < 40 && std::chrono::steady_clock::now() < deadline) std::this_thread::sleep_for(1ms);
  source->stop();
  const PoseSourceCounters c = source->counters();
  EXPECT_EQ(c.received, 40u);
  EXPECT_EQ(c.accepted, 20u);
  EXPECT_EQ(c.other_sender, 20u);
  std::vector<SourcedPose> poses;
  source->queue().drain(poses);
  ASSERT_EQ(poses.size(), 20u);
  for (const SourcedPose& p : poses) EXPECT_EQ(p.pose.position_m, poses.front().pose.position_m);
  std::size_t lines = 0;
  for (const std::string& l : log)
    if (l.find("sysid 2 compid 1") != std::string::npos) {
      ++lines;
      if (l.find("dropped HIL_STATE_QUATERNION") != std::string::npos) {
        EXPECT_NE(l.find("127.0.0.1:"), std::string::npos) << l;  // and where it came from
      }
    }
  EXPECT_GE(lines, 1u);
  EXPECT_LE(lines, 2u);  // rate limited: 20 datagrams in ~40 ms, the rest reported as suppressed at stop
}


// The scene keys: [trajectory] mavlink_system_id / mavlink_component_id,
// 1..255 (0 is MAVLink's broadcast address), mavlink: sources only; refused
// with file:line and the key otherwise.
TEST(MavlinkSenders, SceneKeysChooseTheVehicleAndAreCheckedWhereTheyAreWritten) {
  const auto scene = [](const std::string& source, const std::string& keys) {
    return "[scene]\nname = \"t\"\nphysics = \"ecef\"\n[trajectory]\nsource = \"" + source + "\"\n" + keys +
           "[[imu]]\nname = \"a\"\nrate_hz = 100\nprotocol = \"native\"\n[imu.transport]\ntype = \"pty\"\n"
           "link = \"/tmp/imuemu-t/a\"\n";
  };
  const scene::SceneConfig both = scene::parse_scene_text(
      scene("mavlink:127.0.0.1:14560", "mavlink_system_id = 2\nmavlink_component_id = 191\n"), "s.toml", "/tmp");
  EXPECT_EQ(both.trajectory.mavlink_system_id, std::optional<std::uint8_t>(2));
  EXPECT_EQ(both.trajectory.mavlink_component_id, std::optional<std::uint8_t>(191));
  // What the daemon's source is built with.
  const PoseSourceOptions so = scene::pose_source_options(both, scene::RunnerOptions{});
  EXPECT_EQ(so.mavlink_system_id, std::optional<std::uint8_t>(2));
  EXPECT_EQ(so.mavlink_component_id, std::optional<std::uint8_t>(191));
  const scene::SceneConfig none = scene::parse_scene_text(scene("mavlink:127.0.0.1:14560", ""), "s.toml", "/tmp");
  EXPECT_FALSE(none.trajectory.mavlink_system_id || none.trajectory.mavlink_component_id);
  struct Bad {
    std::string source, keys, key, says;
  };
  for (const Bad& b : {Bad{"mavlink:127.0.0.1:14560", "mavlink_system_id = 0\n", "trajectory.mavlink_system_id", "1..255"},
                       Bad{"mavlink:127.0.0.1:14560", "mavlink_component_id = 256\n", "trajectory.mavlink_component_id",
                           "1..255"},
                       Bad{"mavlink:127.0.0.1:14560", "mavlink_system_id = 1.5\n", "trajectory.mavlink_system_id",
                           "expected an integer"},
                       Bad{"udp:127.0.0.1:5005", "mavlink_system_id = 1\n", "trajectory.mavlink_system_id",
                           "mavlink: sources only"}}) {
    try {
      scene::parse_scene_text(scene(b.source, b.keys), "s.toml", "/tmp");
      ADD_FAILURE() << b.keys << " accepted";
    } catch (const scene::SceneError& e) {
      EXPECT_EQ(e.key(), b.key) << e.what();
      EXPECT_EQ(e.line(), 6u) << e.what();
      EXPECT_NE(std::string(e.what()).find(b.says), std::string::npos) << e.what();
    }
  }
}

// `imuemu status --summary` names the other senders' packets of a MAVLink
// source (the daemon's JSON key other_sender, engine.pose_source).
TEST(MavlinkSenders, StatusSummaryNamesTheOtherSendersPackets) {
  const nlohmann::json source = {{"name", "mavlink udp 0.0.0.0:14560"}, {"received", 900}, {"accepted", 450},
                                 {"rejected", 450}, {"other_sender", 450}};
  const nlohmann::json status{{"scene", "hitl"}, {"pid", 9}, {"uptime_s", 2.0}, {"samples_emitted", 800},
                              {"emitter_progressing", true}, {"engine", {{"pose_source", source}}}};
  std::ostringstream out;
  cli::print_status_summary(status, out);
  EXPECT_NE(out.str().find("other MAVLink senders: 450 packets dropped"), std::string::npos) << out.str();
}

}  // namespace
}  // namespace imuemu::io
}  // namespace unity_cli_test_mavlink_senders
