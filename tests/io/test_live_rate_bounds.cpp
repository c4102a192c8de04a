// Physically impossible live inputs are refused at the door (issue 26 N10):
// the rates a pose datagram v2 or a MAVLink HIL_STATE_QUATERNION carries were
// only checked for finiteness, so a body rate of 5.9e38 rad/s (MAVLink
// rollspeed = FLT_MAX on all three axes) or 1e300 rad/s, or a velocity of
// 1e300 m/s, became the end slopes of the causal method's cubics and reached
// the wire. The bounds (io/pose_wire.hpp kMaxLive*) and their physical
// reasons are in docs/pose-wire-format.md §2.5; a refusal is counted under
// datagram_errors[bad_value] with a message naming the field and the bound.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "io/mavlink_pose.hpp"
#include "io/pose_admission.hpp"
#include "io/pose_wire.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace imuemu::io {}
namespace unity_io_test_live_rate_bounds {
namespace imuemu { using namespace ::imuemu; }
namespace imuemu::io { using namespace ::imuemu::io; }

namespace imuemu::io {
namespace {

using Bytes = std::vector<std::uint8_t>;

TrajectoryRecord at_rest(TimeNs t_ns) {
  TrajectoryRecord r;
  r.t_ns = t_ns;
  r.position_kind = PositionKind::local_ned;
  r.position = Vec3(10.0, -3.5, 0.25);
  r.attitude_kind = AttitudeKind::quaternion;
  r.attitude = Eigen::Vector4d(1, 0, 0, 0);
  return r;
}

struct Case {
  const char* what;
  PoseRates rates;
  bool accepted;
  const char* field;  // named in the refusal
};

std::vector<Case> cases() {
  const double f = std::numeric_limits<float>::max();
  std::vector<Case> c;
  PoseRates r;
  r.angular_rate_rad_s = Vec3(f, f, f);  // |w| = 5.9e38 rad/s
  c.push_back({"body rate FLT_MAX on three axes", r, false, "angular_rate_rad_s"});
  r = {};
  r.angular_rate_rad_s = Vec3(1e300, 0, 0);
  c.push_back({"body rate 1e300 rad/s", r, false, "angular_rate_rad_s"});
  r = {};
  r.angular_rate_rad_s = Vec3(0, 0, 1.0001e4);
  c.push_back({"body rate just beyond 1e4 rad/s", r, false, "angular_rate_rad_s"});
  r = {};
  r.angular_rate_rad_s = Vec3(0, 0, 2000.0);  // a spin-stabilised shell (~300 rev/s): possible
  c.push_back({"body rate 2000 rad/s", r, true, ""});
  r = {};
  r.velocity_m_s = Vec3(1e300, 0, 0);
  c.push_back({"velocity 1e300 m/s", r, false, "velocity_m_s"});
  r = {};
  r.velocity_m_s = Vec3(0, 7.1e4, 7.1e4);  // |v| = 1.004e5 m/s
  c.push_back({"velocity just beyond 1e5 m/s", r, false, "velocity_m_s"});
  r = {};
  r.velocity_m_s = Vec3(7800.0, 0, 0);  // low Earth orbit
  c.push_back({"velocity 7.8 km/s", r, true, ""});
  r = {};
  r.acceleration_m_s2 = Vec3(0, -1e300, 0);
  c.push_back({"acceleration 1e300 m/s^2", r, false, "acceleration_m_s2"});
  r = {};
  r.acceleration_m_s2 = Vec3(0, 0, 2e6);
  c.push_back({"acceleration 2e6 m/s^2 (2e5 g)", r, false, "acceleration_m_s2"});
  r = {};
  r.acceleration_m_s2 = Vec3(0, 0, 3e5);  // a gun launch (3e4 g)
  c.push_back({"acceleration 3e5 m/s^2", r, true, ""});
  return c;
}

TEST(LiveRateBounds, PoseDatagramV2RatesBeyondPhysicalBoundsAreRefusedAsBadValues) {
  for (const Case& c : cases()) {
    TrajectoryRecord r = at_rest(1'000'000'000);
    r.rates = c.rates;
    const auto bytes = encode_pose_datagram_v2(PoseDatagram{5, r});
    PoseDatagram out;
    DatagramDecodeError error;
    const bool decoded = decode_pose_datagram(bytes, out, error);
    EXPECT_EQ(decoded, c.accepted) << c.what;
    if (c.accepted) continue;
    EXPECT_EQ(error.reason, DatagramError::bad_value) << c.what;
    EXPECT_TRUE(error.intact) << c.what << ": an intact datagram still counts for the loss statistics";
    EXPECT_NE(error.message.find(c.field), std::string::npos) << c.what << ": " << error.message;
    EXPECT_NE(error.message.find("beyond"), std::string::npos) << c.what << ": " << error.message;
  }
}

TEST(LiveRateBounds, ThroughTheAdmissionEachRefusalIsCountedAndTheStreamGoesOn) {
  PoseSourceOptions options;
  options.physics = Physics::flat;
  std::vector<std::string> log;
  options.log = [&](std::string_view line) { log.emplace_back(line); };
  PoseAdmission admission(options);
  std::uint64_t sequence = 0, refused = 0, accepted = 0;
  TimeNs t_ns = 1'000'000'000;
  for (const Case& c : cases()) {
    for (int good = 0; good < 2; ++good) {  // a plain pose before each case: the stream is acquired and stays so
      SourcedPose out;
      accepted += admission.receive_datagram(encode_pose_datagram_v2(PoseDatagram{sequence++, at_rest(t_ns)}), t_ns,
                                             "test", out);
      while (admission.take_released(out)) ++accepted;
      t_ns += 10'000'000;
    }
    TrajectoryRecord r = at_rest(t_ns);
    r.rates = c.rates;
    SourcedPose out;
    const bool ok = admission.receive_datagram(encode_pose_datagram_v2(PoseDatagram{sequence++, r}), t_ns, "test", out);
    EXPECT_EQ(ok, c.accepted) << c.what;
    if (ok) {
      ++accepted;
      ASSERT_TRUE(out.rates.any());
    } else {
      ++refused;
    }
    t_ns += 10'000'000;
  }
  const PoseSourceCounters k = admission.counters();
  EXPECT_EQ(k.datagram_errors[static_cast<std::size_t>(DatagramError::bad_value)], refused);
  EXPECT_EQ(k.accepted, accepted);
  EXPECT_EQ(k.received, k.accepted + k.rejected() + k.held);
  EXPECT_EQ(k.lost(), 0u);
  bool named = false;
  for (const std::string& l : log) named = named || l.find("angular_rate_rad_s") != std::string::npos;
  EXPECT_TRUE(named);
}

TEST(LiveRateBounds, MavlinkBodyRatesBeyondPhysicalBoundsAreRefused) {
  mavlink::HilStateQuaternion m;
  m.time_usec = 1'000'000;
  m.attitude_quaternion = {1.0f, 0.0f, 0.0f, 0.0f};
  m.lat_degE7 = 415'000'000;
  m.lon_degE7 = 22'500'000;
  TrajectoryRecord r;
  DatagramDecodeError error;
  const float f = std::numeric_limits<float>::max();
  for (const auto& [roll, pitch, yaw] : {std::array<float, 3>{f, 0, 0}, std::array<float, 3>{f, f, f},
                                          std::array<float, 3>{0, -1e5f, 0}, std::array<float, 3>{0, 0, -1.0001e4f}}) {
    m.rollspeed_rad_s = roll;
    m.pitchspeed_rad_s = pitch;
    m.yawspeed_rad_s = yaw;
    // Through the wire: encoded, checksummed, decoded, then refused for its value.
    const Bytes packet = mavlink::encode_hil_state_quaternion(m, {1, 1, 1});
    mavlink::HilStateQuaternion back;
    mavlink::PacketInfo info;
    ASSERT_EQ(mavlink::decode_datagram(packet, back, info, error), mavlink::Outcome::hil_state);
    EXPECT_FALSE(mavlink::to_record(back, r, error)) << roll << " " << pitch << " " << yaw;
    EXPECT_EQ(error.reason, DatagramError::bad_value);
    EXPECT_TRUE(error.intact);
    EXPECT_NE(error.message.find("beyond"), std::string::npos) << error.message;
  }
  m.rollspeed_rad_s = 35.0f;  // 2000 deg/s: a gyro's full scale
  m.pitchspeed_rad_s = -9000.0f;
  m.yawspeed_rad_s = 0.0f;
  EXPECT_TRUE(mavlink::to_record(m, r, error)) << error.message;
}

}  // namespace
}  // namespace imuemu::io
}  // namespace unity_io_test_live_rate_bounds
