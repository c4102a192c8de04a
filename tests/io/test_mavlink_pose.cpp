// MAVLink 2 HIL_STATE_QUATERNION (#115) as a live pose input (io/mavlink_pose.hpp,
// docs/pose-wire-format.md §4) and the pose datagram v2 with rates (§2.5):
//  - CRC_EXTRA recomputed here from the common.xml field list with a bitwise
//    X.25 written in this file (not the parser's Boost.CRC), compared with
//    the constant;
//  - golden bytes from tests/support/protocol_reference.py (an independent
//    Python encoder written from the MAVLink guide);
//  - malformed, truncated, wrong-CRC, MAVLink 1 and non-unit datagrams counted
//    and refused through the admission, without changing what is accepted;
//  - a real loopback UDP source;
//  - the rates converted to the ecef scene against a numerical derivative of
//    Eq. 1.1.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <numbers>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "core/attitude.hpp"
#include "core/earth.hpp"
#include "core/so3.hpp"
#include "io/mavlink_pose.hpp"
#include "io/pose_admission.hpp"
#include "io/pose_source.hpp"
#include "io/pose_wire.hpp"
#include "io/scene_poses.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace imuemu::io {}
namespace unity_io_test_mavlink_pose {
namespace imuemu { using namespace ::imuemu; }
namespace imuemu::io { using namespace ::imuemu::io; }

namespace imuemu::io {
namespace {

using Bytes = std::vector<std::uint8_t>;
using namespace std::chrono_literals;

Bytes hex(const std::string& text) {
  Bytes out;
  std::istringstream in(text);
  std::string byte;
  while (in >> byte) out.push_back(static_cast<std::uint8_t>(std::stoul(byte, nullptr, 16)));
  return out;
}

// Bitwise CRC-16/MCRF4XX from its Rocksoft parameters (poly 0x1021 reflected
// = 0x8408, init 0xFFFF, no final xor), independent of Boost.CRC.
std::uint16_t x25(const std::string& text, std::uint16_t crc) {
  for (unsigned char b : text) {
    crc ^= b;
    for (int i = 0; i < 8; ++i) crc = (crc & 1) ? static_cast<std::uint16_t>((crc >> 1) ^ 0x8408) : crc >> 1;
  }
  return crc;
}

struct XmlField {
  std::string type, name;
  int array_length;  // 0: not an array
};

int type_bytes(const std::string& type) {
  if (type == "uint64_t" || type == "int64_t" || type == "double") return 8;
  if (type == "uint32_t" || type == "int32_t" || type == "float") return 4;
  if (type == "uint16_t" || type == "int16_t") return 2;
  return 1;
}

// MAVLink guide "CRC_EXTRA Calculation" over the fields in wire order (guide
// "Field Reordering": stable sort by base type size, largest first).
std::uint8_t crc_extra(const std::string& message, std::vector<XmlField> fields) {
  std::stable_sort(fields.begin(), fields.end(),
                   [](const XmlField& a, const XmlField& b) { return type_bytes(a.type) > type_bytes(b.type); });
  std::uint16_t crc = x25(message + " ", 0xFFFF);
  for (const XmlField& f : fields) {
    crc = x25(f.type + " ", crc);
    crc = x25(f.name + " ", crc);
    if (f.array_length > 0) crc = x25(std::string(1, static_cast<char>(f.array_length)), crc);
  }
  return static_cast<std::uint8_t>((crc & 0xFF) ^ (crc >> 8));
}

// common.xml HIL_STATE_QUATERNION, in XML order.
const std::vector<XmlField> kHilStateQuaternionXml = {
    {"uint64_t", "time_usec", 0}, {"float", "attitude_quaternion", 4}, {"float", "rollspeed", 0},
    {"float", "pitchspeed", 0},   {"float", "yawspeed", 0},             {"int32_t", "lat", 0},
    {"int32_t", "lon", 0},        {"int32_t", "alt", 0},                {"int16_t", "vx", 0},
    {"int16_t", "vy", 0},         {"int16_t", "vz", 0},                 {"uint16_t", "ind_airspeed", 0},
    {"uint16_t", "true_airspeed", 0}, {"int16_t", "xacc", 0},          {"int16_t", "yacc", 0},
    {"int16_t", "zacc", 0}};

// protocol_reference.py: "HIL_STATE_QUATERNION seq 9 sys 1 comp 1".
const Bytes kGoldenHilState = hex(
    "FD 40 00 00 09 01 01 73 00 00 40 22 20 18 24 0A 06 00 EA 46 77 3F 00 00 00 00 00 00 00 00 EE 83 84 3E "
    "0A D7 23 3C 0A D7 A3 BC 00 00 00 3F C0 65 BC 18 A0 52 57 01 B4 D6 01 00 E8 03 06 FF 32 00 FC 03 06 04 "
    "0A 00 EC FF 18 FC A5 55");

// protocol_reference.py: "pose datagram v2".
const Bytes kGoldenPoseV2 = hex(
    "49 4D 55 50 02 02 01 03 07 00 00 00 00 00 00 00 00 F9 02 95 00 00 00 00 00 00 00 00 00 00 24 40 00 00 00 "
    "00 00 00 0C C0 00 00 00 00 00 00 D0 3F 00 00 00 00 00 00 F0 3F 00 00 00 00 00 00 00 00 00 00 00 00 00 00 "
    "00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 F8 3F 00 00 00 00 00 00 E0 BF 00 00 00 00 00 00 D0 3F 9A "
    "99 99 99 99 99 B9 3F 00 00 00 00 00 00 00 00 9A 99 99 99 99 99 C9 BF 00 00 00 00 00 00 00 00 00 00 00 00 "
    "00 00 00 00 00 00 00 00 00 00 00 00 67 93 52 A0");

mavlink::HilStateQuaternion golden_message() {
  mavlink::HilStateQuaternion m;
  m.time_usec = 1700000000123456;
  const double half = 15.0 * std::numbers::pi / 180.0;
  m.attitude_quaternion = {static_cast<float>(std::cos(half)), 0.0f, 0.0f, static_cast<float>(std::sin(half))};
  m.rollspeed_rad_s = 0.01f;
  m.pitchspeed_rad_s = -0.02f;
  m.yawspeed_rad_s = 0.5f;
  m.lat_degE7 = 415000000;
  m.lon_degE7 = 22500000;
  m.alt_mm = 120500;
  m.vx_cm_s = 1000;
  m.vy_cm_s = -250;
  m.vz_cm_s = 50;
  m.ind_airspeed_cm_s = 1020;
  m.true_airspeed_cm_s = 1030;
  m.xacc_mG = 10;
  m.yacc_mG = -20;
  m.zacc_mG = -1000;
  return m;
}

TEST(MavlinkHilState, CrcExtraFromTheCommonXmlFieldList) {
  EXPECT_EQ(x25("123456789", 0xFFFF), 0x6F91);  // CRC-16/MCRF4XX check value
  EXPECT_EQ(mavlink::crc16_mcrf4xx(std::span(reinterpret_cast<const std::uint8_t*>("123456789"), 9)), 0x6F91);
  EXPECT_EQ(crc_extra("HIL_STATE_QUATERNION", kHilStateQuaternionXml), mavlink::kHilStateQuaternionCrcExtra);
  EXPECT_EQ(mavlink::kHilStateQuaternionCrcExtra, 4);
  // The same derivation gives the CRC_EXTRA of messages drivers/ already sends.
  EXPECT_EQ(crc_extra("HEARTBEAT", {{"uint8_t", "type", 0}, {"uint8_t", "autopilot", 0}, {"uint8_t", "base_mode", 0},
                                    {"uint32_t", "custom_mode", 0}, {"uint8_t", "system_status", 0},
                                    {"uint8_t", "mavlink_version", 0}}),
            50);
  int payload = 0;
  for (const XmlField& f : kHilStateQuaternionXml) payload += type_bytes(f.type) * std::max(1, f.array_length);
  EXPECT_EQ(payload, static_cast<int>(mavlink::kHilStateQuaternionPayloadBytes));
}

TEST(MavlinkHilState, GoldenBytesEncodeAndDecode) {
  EXPECT_EQ(mavlink::encode_hil_state_quaternion(golden_message(), {9, 1, 1}), kGoldenHilState);

  mavlink::HilStateQuaternion m;
  mavlink::PacketInfo info;
  DatagramDecodeError error;
  ASSERT_EQ(mavlink::decode_datagram(kGoldenHilState, m, info, error), mavlink::Outcome::hil_state) << error.message;
  EXPECT_EQ(info.sequence, 9);
  EXPECT_EQ(info.system_id, 1);
  EXPECT_EQ(info.component_id, 1);
  const mavlink::HilStateQuaternion g = golden_message();
  EXPECT_EQ(m.time_usec, g.time_usec);
  EXPECT_EQ(m.attitude_quaternion, g.attitude_quaternion);
  EXPECT_EQ(m.lat_degE7, 415000000);
  EXPECT_EQ(m.alt_mm, 120500);
  EXPECT_EQ(m.vy_cm_s, -250);
  EXPECT_EQ(m.true_airspeed_cm_s, 1030);
  EXPECT_EQ(m.zacc_mG, -1000);

  // Units: 1e-7 deg, mm, cm/s, us; q_b^l; body rates in rad/s.
  TrajectoryRecord r;
  ASSERT_TRUE(mavlink::to_record(m, r, error)) << error.message;
  EXPECT_EQ(r.t_ns, 1700000000123456000);
  EXPECT_EQ(r.position_kind, PositionKind::geodetic);
  EXPECT_NEAR(r.position.x(), 41.5, 1e-12);
  EXPECT_NEAR(r.position.y(), 2.25, 1e-12);
  EXPECT_NEAR(r.position.z(), 120.5, 1e-12);
  EXPECT_EQ(r.attitude_kind, AttitudeKind::quaternion);
  const Mat3 R = attitude::rotation_from_quaternion(r.attitude[0], r.attitude[1], r.attitude[2], r.attitude[3]);
  EXPECT_NEAR(attitude::hpr_from_rotation(R).heading_rad, 30.0 * std::numbers::pi / 180.0, 1e-7);  // heading 30 deg
  ASSERT_TRUE(r.rates.velocity_m_s && r.rates.angular_rate_rad_s);
  EXPECT_NEAR((*r.rates.velocity_m_s - Vec3(10.0, -2.5, 0.5)).norm(), 0.0, 1e-12);
  EXPECT_NEAR((*r.rates.angular_rate_rad_s - Vec3(0.01, -0.02, 0.5)).norm(), 0.0, 1e-7);
  EXPECT_FALSE(r.rates.acceleration_m_s2);  // xacc..zacc: frame differs per bridge, not used
}

TEST(MavlinkHilState, TruncatedPayloadIsZeroExtended) {
  // [G] empty-byte truncation: zero trailing fields are not sent.
  mavlink::HilStateQuaternion m = golden_message();
  m.xacc_mG = m.yacc_mG = m.zacc_mG = 0;
  m.true_airspeed_cm_s = 0;
  const Bytes packet = mavlink::encode_hil_state_quaternion(m, {0, 1, 1});
  EXPECT_EQ(packet[1], 56);  // up to ind_airspeed (offset 54, 2 bytes)
  EXPECT_EQ(packet.size(), 10u + 56u + 2u);
  mavlink::HilStateQuaternion back;
  mavlink::PacketInfo info;
  DatagramDecodeError error;
  ASSERT_EQ(mavlink::decode_datagram(packet, back, info, error), mavlink::Outcome::hil_state);
  EXPECT_EQ(back.ind_airspeed_cm_s, 1020);
  EXPECT_EQ(back.zacc_mG, 0);
}

struct Refusal {
  std::string what;
  Bytes bytes;
  DatagramError reason;
};

std::vector<Refusal> refusals(std::uint8_t sequence = 10) {
  std::vector<Refusal> out;
  const Bytes& g = kGoldenHilState;
  out.push_back({"empty", {}, DatagramError::too_short});
  out.push_back({"truncated header", Bytes(g.begin(), g.begin() + 6), DatagramError::too_short});
  out.push_back({"truncated payload", Bytes(g.begin(), g.end() - 3), DatagramError::bad_length});
  Bytes crc = g;
  crc.back() ^= 0x01;
  out.push_back({"wrong CRC", crc, DatagramError::bad_checksum});
  Bytes flipped = g;
  flipped[30] ^= 0x40;
  out.push_back({"flipped payload bit", flipped, DatagramError::bad_checksum});
  Bytes v1 = g;
  v1[0] = 0xFE;
  out.push_back({"MAVLink 1 STX", v1, DatagramError::unsupported_version});
  Bytes magic = g;
  magic[0] = 0x55;
  out.push_back({"not a MAVLink STX", magic, DatagramError::bad_magic});
  Bytes incompat = g;
  incompat[2] = 0x02;
  out.push_back({"unknown incompat flag", incompat, DatagramError::unsupported_version});
  Bytes twice = g;
  twice.insert(twice.end(), g.begin(), g.end());
  out.push_back({"two HIL_STATE_QUATERNION", twice, DatagramError::bad_length});
  mavlink::HilStateQuaternion m = golden_message();
  m.attitude_quaternion = {0.5f, 0.0f, 0.0f, 0.0f};
  out.push_back({"non-unit quaternion", mavlink::encode_hil_state_quaternion(m, {sequence, 1, 1}), DatagramError::bad_value});
  m = golden_message();
  m.rollspeed_rad_s = std::numeric_limits<float>::quiet_NaN();
  out.push_back({"NaN body rate", mavlink::encode_hil_state_quaternion(m, {sequence, 1, 1}), DatagramError::bad_value});
  m = golden_message();
  m.lat_degE7 = 900000001;
  out.push_back({"latitude beyond 90", mavlink::encode_hil_state_quaternion(m, {sequence, 1, 1}), DatagramError::bad_value});
  return out;
}

mavlink::HilStateQuaternion level_at(std::uint64_t time_usec, std::int32_t north_offset_degE7) {
  mavlink::HilStateQuaternion m;
  m.time_usec = time_usec;
  m.attitude_quaternion = {1.0f, 0.0f, 0.0f, 0.0f};
  m.lat_degE7 = 415000000 + north_offset_degE7;
  m.lon_degE7 = 22500000;
  m.alt_mm = 100000;
  m.vx_cm_s = 100;
  return m;
}

TEST(MavlinkHilState, MalformedDatagramsAreCountedAndRefusedWithoutDisturbingTheStream) {
  for (const Refusal& r : refusals()) {
    mavlink::HilStateQuaternion m;
    mavlink::PacketInfo info;
    DatagramDecodeError error;
    const mavlink::Outcome outcome = mavlink::decode_datagram(r.bytes, m, info, error);
    TrajectoryRecord record;
    const bool refused = outcome == mavlink::Outcome::refused ||
                         (outcome == mavlink::Outcome::hil_state && !mavlink::to_record(m, record, error));
    EXPECT_TRUE(refused) << r.what;
    EXPECT_EQ(error.reason, r.reason) << r.what << ": " << error.message;
    EXPECT_FALSE(error.message.empty()) << r.what;
  }

  // The same good stream with and without every bad datagram interleaved
  // (and a HEARTBEAT-only datagram, ignored): the accepted poses are equal.
  auto run = [](bool with_bad) {
    PoseSourceOptions options;
    options.physics = Physics::ecef;
    options.log = [](std::string_view) {};
    PoseAdmission admission(options);
    std::vector<SourcedPose> poses;
    for (std::uint8_t k = 0; k < 20; ++k) {
      const Bytes good = mavlink::encode_hil_state_quaternion(level_at(1'000'000 + 4000u * k, k), {k, 1, 1});
      SourcedPose out;
      if (admission.receive_mavlink_datagram(good, k, "test", out)) {
        poses.push_back(out);
        while (admission.take_released(out)) poses.push_back(out);
      }
      if (with_bad && k % 2 == 1) {
        for (const Refusal& r : refusals(k)) EXPECT_FALSE(admission.receive_mavlink_datagram(r.bytes, k, "test", out));
        // A HEARTBEAT (#0) packet alone: another message, not checked, ignored.
        const Bytes heartbeat = hex("FD 09 00 00 00 01 01 00 00 00 00 00 00 00 02 03 51 04 03 00 00");
        EXPECT_FALSE(admission.receive_mavlink_datagram(heartbeat, k, "test", out));
      }
    }
    return std::make_pair(poses, admission.counters());
  };
  const auto [clean, clean_counters] = run(false);
  const auto [noisy, noisy_counters] = run(true);
  ASSERT_EQ(clean.size(), 20u);
  ASSERT_EQ(noisy.size(), clean.size());
  for (std::size_t i = 0; i < clean.size(); ++i) {
    EXPECT_EQ(noisy[i].pose.t_ns, clean[i].pose.t_ns);
    EXPECT_EQ(noisy[i].pose.position_m, clean[i].pose.position_m);
    EXPECT_EQ(noisy[i].pose.attitude, clean[i].pose.attitude);
    EXPECT_EQ(*noisy[i].rates.velocity_m_s, *clean[i].rates.velocity_m_s);
  }
  const std::uint64_t bad_per_round = refusals().size();
  EXPECT_EQ(noisy_counters.received, 20u + 10u * (bad_per_round + 1));
  EXPECT_EQ(noisy_counters.accepted, 20u);
  EXPECT_EQ(noisy_counters.ignored, 10u);  // the heartbeats
  EXPECT_EQ(noisy_counters.rejected(), 10u * bad_per_round);
  const PoseSourceCounters noisy_c = noisy_counters;  // a structured binding cannot be captured (C++20, clang 14)
  auto count = [&](DatagramError e) { return noisy_c.datagram_errors[static_cast<std::size_t>(e)]; };
  EXPECT_EQ(count(DatagramError::bad_checksum), 20u);
  EXPECT_EQ(count(DatagramError::bad_value), 30u);
  EXPECT_EQ(count(DatagramError::too_short), 20u);
  EXPECT_EQ(count(DatagramError::bad_length), 20u);
  EXPECT_EQ(count(DatagramError::unsupported_version), 20u);
  EXPECT_EQ(count(DatagramError::bad_magic), 10u);
  // Sequence numbers 0..19 of (1, 1) all arrived; the refused intact ones
  // (sent with the number of the good one before them) are repeats, not gaps.
  EXPECT_EQ(noisy_counters.lost(), 0u);
  EXPECT_EQ(clean_counters.lost(), 0u);
}

TEST(MavlinkHilState, EightBitSequenceLossIsCounted) {
  PoseSourceOptions options;
  options.physics = Physics::ecef;
  options.log = [](std::string_view) {};
  PoseAdmission admission(options);
  // 300 packets (the 8-bit counter wraps), every 7th never sent.
  std::uint64_t sent = 0;
  for (std::uint32_t k = 0; k < 300; ++k) {
    if (k % 7 == 3) continue;
    const Bytes d = mavlink::encode_hil_state_quaternion(level_at(1'000'000 + 4000ull * k, static_cast<std::int32_t>(k)),
                                                         {static_cast<std::uint8_t>(k), 1, 1});
    SourcedPose out;
    admission.receive_mavlink_datagram(d, k, "test", out);
    ++sent;
  }
  EXPECT_EQ(admission.counters().received, sent);
  EXPECT_EQ(admission.counters().lost(), 300u - sent);
}

TEST(MavlinkHilState, RatesInTheEcefSceneMatchTheDerivativeOfTheGeodeticPath) {
  // Flying north-east and up at (10, -2.5, 0.5) m/s NED: the ECEF velocity
  // the converter gives equals the central difference of Eq. 1.1 along the
  // path (independent truth: only ecef_from_geodetic).
  mavlink::HilStateQuaternion m = golden_message();
  TrajectoryRecord r;
  DatagramDecodeError error;
  ASSERT_TRUE(mavlink::to_record(m, r, error));
  ScenePoseConverter converter(Physics::ecef);
  converter.convert(r);
  const PoseRates rates = converter.convert_rates(r);
  ASSERT_TRUE(rates.velocity_m_s);
  const double lat = 41.5 * std::numbers::pi / 180, lon = 2.25 * std::numbers::pi / 180, h = 120.5;
  const double dt = 1e-3;
  // NED velocity -> geodetic rates with the WGS84 radii.
  const double a = 6378137.0, f = 1 / 298.257223563, e2 = f * (2 - f);
  const double w = std::sqrt(1 - e2 * std::sin(lat) * std::sin(lat));
  const double rn = a / w, rm = a * (1 - e2) / (w * w * w);
  auto at = [&](double s) {
    return earth::ecef_from_geodetic({lat + s * 10.0 / (rm + h), lon + s * -2.5 / ((rn + h) * std::cos(lat)),
                                      h - s * 0.5});
  };
  const Vec3 v_fd = (at(dt) - at(-dt)) / (2 * dt);
  EXPECT_LT((*rates.velocity_m_s - v_fd).norm(), 1e-6) << rates.velocity_m_s->transpose() << " vs " << v_fd.transpose();
  // The body rate relative to ECEF adds the transport rate (|v|/R ~ 1.6e-6 rad/s).
  const Vec3 delta = *rates.angular_rate_rad_s - *r.rates.angular_rate_rad_s;
  EXPECT_GT(delta.norm(), 1e-6);
  EXPECT_LT(delta.norm(), 3e-6);
}

TEST(PoseDatagramV2, GoldenBytesAndBackwardCompatibility) {
  TrajectoryRecord r;
  r.t_ns = 2'500'000'000;
  r.position_kind = PositionKind::local_ned;
  r.position = Vec3(10.0, -3.5, 0.25);
  r.attitude_kind = AttitudeKind::quaternion;
  r.attitude = Eigen::Vector4d(1, 0, 0, 0);
  r.rates.velocity_m_s = Vec3(1.5, -0.5, 0.25);
  r.rates.angular_rate_rad_s = Vec3(0.1, 0.0, -0.2);
  const auto v2 = encode_pose_datagram_v2(PoseDatagram{7, r});
  EXPECT_EQ(Bytes(v2.begin(), v2.end()), kGoldenPoseV2);

  PoseDatagram back;
  DatagramDecodeError error;
  ASSERT_TRUE(decode_pose_datagram(kGoldenPoseV2, back, error)) << error.message;
  EXPECT_EQ(back.sequence, 7u);
  EXPECT_EQ(*back.record.rates.velocity_m_s, Vec3(1.5, -0.5, 0.25));
  EXPECT_EQ(*back.record.rates.angular_rate_rad_s, Vec3(0.1, 0.0, -0.2));
  EXPECT_FALSE(back.record.rates.acceleration_m_s2);

  // v1 still reads as before, without rates.
  const auto v1 = encode_pose_datagram(PoseDatagram{7, r});
  ASSERT_TRUE(decode_pose_datagram(v1, back, error));
  EXPECT_FALSE(back.record.rates.any());

  auto reseal = [](Bytes& d) {
    const std::uint32_t crc = crc32c(std::span(d.data(), kDatagramV2CrcOffset));
    for (std::size_t i = 0; i < 4; ++i) d[kDatagramV2CrcOffset + i] = static_cast<std::uint8_t>(crc >> (8 * i));
  };
  Bytes bad = kGoldenPoseV2;
  bad[kDatagramRatesMaskOffset] = 0x08;  // unknown bit
  reseal(bad);
  EXPECT_FALSE(decode_pose_datagram(bad, back, error));
  EXPECT_EQ(error.reason, DatagramError::reserved_not_zero);
  bad = kGoldenPoseV2;
  bad[kDatagramAccelerationOffset + 7] = 0x3F;  // acceleration bytes with its bit clear
  reseal(bad);
  EXPECT_FALSE(decode_pose_datagram(bad, back, error));
  EXPECT_EQ(error.reason, DatagramError::reserved_not_zero);
  bad = kGoldenPoseV2;
  bad[kDatagramVelocityOffset + 6] = 0xF0;  // velocity x = +inf
  bad[kDatagramVelocityOffset + 7] = 0x7F;
  for (std::size_t i = 0; i < 6; ++i) bad[kDatagramVelocityOffset + i] = 0;
  reseal(bad);
  EXPECT_FALSE(decode_pose_datagram(bad, back, error));
  EXPECT_EQ(error.reason, DatagramError::bad_value);
  EXPECT_NE(error.message.find("velocity_m_s"), std::string::npos) << error.message;
  bad = Bytes(kGoldenPoseV2.begin(), kGoldenPoseV2.begin() + kPoseDatagramV1Size);  // v2 byte with v1 length
  EXPECT_FALSE(decode_pose_datagram(bad, back, error));
  EXPECT_EQ(error.reason, DatagramError::bad_length);
}

TEST(MavlinkUdpPoseSource, LoopbackDeliversPosesWithRatesAndCountsCorruption) {
  PoseSourceOptions options;
  options.physics = Physics::ecef;
  options.log = [](std::string_view) {};
  auto source = make_mavlink_udp_pose_source({"127.0.0.1", 0}, options);
  EXPECT_EQ(source->name(), "mavlink udp 127.0.0.1:" + std::to_string(source->local_port()));
  source->start();
  const int fd = ::socket(AF_INET, SOCK_DGRAM, 0);
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_port = htons(source->local_port());
  to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  auto send = [&](const Bytes& d) {
    ASSERT_EQ(::sendto(fd, d.data(), d.size(), 0, reinterpret_cast<const sockaddr*>(&to), sizeof to),
              static_cast<ssize_t>(d.size()));
  };
  for (std::uint8_t k = 0; k < 10; ++k) {
    Bytes d = mavlink::encode_hil_state_quaternion(level_at(2'000'000 + 4000u * k, k), {k, 1, 1});
    if (k == 5) d[20] ^= 0x01;  // corrupted in transit: refused, counted, and lost
    send(d);
  }
  ::close(fd);
  const auto deadline = std::chrono::steady_clock::now() + 5s;
  while (source->counters().received < 10 && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(1ms);
  const PoseSourceCounters c = source->counters();
  EXPECT_EQ(c.received, 10u);
  EXPECT_EQ(c.accepted, 9u);
  EXPECT_EQ(c.datagram_errors[static_cast<std::size_t>(DatagramError::bad_checksum)], 1u);
  EXPECT_EQ(c.lost(), 1u);
  std::vector<SourcedPose> poses;
  source->queue().drain(poses);
  ASSERT_EQ(poses.size(), 9u);
  EXPECT_EQ(poses.front().pose.t_ns, 2'000'000'000);
  for (const SourcedPose& p : poses) {
    ASSERT_TRUE(p.rates.velocity_m_s && p.rates.angular_rate_rad_s);
    EXPECT_NEAR(p.rates.velocity_m_s->norm(), 1.0, 1e-9);  // vx 100 cm/s, rotated to ECEF
    EXPECT_GT(p.receive_ns, 0);
  }
}

}  // namespace
}  // namespace imuemu::io
}  // namespace unity_io_test_mavlink_pose
