// Issue 29: the emulated VectorNav VN-100 / VN-300 answers its drivers and
// streams what they configure. Every command, reply and packet layout below
// is written by hand from the VectorNav user manuals ("Serial ASCII": $VN,
// comma-separated parameters, "*" + two hex digits of the XOR of the bytes
// between $ and *, or four hex digits of CRC-16/CCITT, "XX" to skip it;
// $VNERR,XX in hex; "Binary Output Protocol": 0xFA, group byte, one
// little-endian 16-bit field mask per group, the fields in bit order,
// CRC-16/CCITT (poly 0x1021, init 0) over everything after the sync byte,
// most significant byte first), not from imuemu's headers: the checksum, CRC,
// field-size table and decoder here are the test's own.
//
// The start-up sequences replayed, read from the clients' sources:
//  - ArduPilot: lashVN/ardupilot 04e3123343469b5162388d45a59c43edd7ae3abf
//    (the VectorNav author's branch of ArduPilot PR #27459, "Add validation
//    to initialization configuration commands"),
//    libraries/AP_ExternalAHRS/AP_ExternalAHRS_VectorNav.cpp initialize():
//    run_command() sends nmea_printf("$%s") of VNASY,0; VNWRG,06,0,1;
//    VNWRG,06,0,2; VNRRG,01; then for a "VN-1..." model VNWRG,75,3,<800 /
//    rate>,01,0721 and VNWRG,76,3,16,11,0001,0106, for others
//    VNWRG,75,3,<imu_rate / rate>,01,0721, VNWRG,76,3,<imu_rate / 50>,31,0001,0106,0613
//    and VNWRG,77,3,<imu_rate / 5>,49,0003,26B8,0018 (imu_rate 400 for a
//    VN-300); VNASY,1. Each is resent every 500 ms until a reply whose first
//    term matches the command's name and whose 8-bit checksum is right
//    arrives (a VNERR reply is retried); the model is the reply's third term
//    when it starts "VN-". healthy(): IMU packet (0x01 / 0x0721, 82 bytes)
//    younger than 40 ms, attitude / EKF packet younger than 500 ms and, for
//    an INS, the GNSS packet younger than 1000 ms; pre_arm_check(): GNSS1
//    fix >= 3 and, for a VN-3xx, GNSS2 fix >= 3. ArduPilot/ardupilot master
//    at 00e10957e3f350c10839f4d587459d9450c71417 sends the same sequence
//    with message_to_send "$VNASY,0": "$$VNASY,0*..", whose checksum covers
//    the second $ and whose first term can never match its own reply (see
//    docs/vectornav-device.md); it is not replayed.
//  - PX4-Autopilot 004d420324d12d4b2aeb42827c189fc4005dafee,
//    src/drivers/ins/vectornav/VectorNav.cpp init() and configure(), through
//    its libvnc (src/drivers/ins/vectornav/libvnc, commit d44a0fd0): the
//    sensor's error detection mode is the 8-bit checksum (VnSensor_initialize);
//    commands "$VNRRG,01" (verify connectivity), "$VNWRG,05,921600" (then
//    the host changes rate), model, hardware revision, serial number and
//    firmware reads (registers 1-4), "$VNWRG,06,0" (ASCII off), VPE basic
//    control read / write / read (register 35), and binary outputs 1-3 on
//    serial port 2 (ASYNCMODE_PORT2): "$VNWRG,75,2,1,6,1,C" (time startup;
//    uncompensated accel and gyro), "$VNWRG,76,2,8,36,1,130,84,613" and
//    "$VNWRG,77,2,80,A,1,26B9" (libvnc's "%u,%u,%u,%X" + ",%X" per group).
//  - The ROS 2 driver dawonn/vectornav, branch ros2 at
//    2a2789eaf8fb3ec99e5effc0df9c731d7933d74c (vectornav/src/vectornav.cc
//    connect() and configure_sensor(), config/vectornav.yaml, through the
//    vnproglib 1.2.0.0 it carries: cpp/src/sensors.cpp, packet.cpp): the
//    model register read at the requested 115200 baud (then at each of
//    vnproglib's nine rates until one answers; none: "Unable to connect"),
//    twice more, then registers 1, 4, 2, 3, 0; writes of registers 6, 7,
//    32, 30 and 75-77 with the 8-bit checksum, each taken by the first
//    $VNRRG / $VNWRG / $VNERR line that arrives; the model again and, on a
//    VN-200 / VN-300, the GNSS registers 55, 57 (and 93 on a VN-300) inside
//    a try block that only logs a refusal. (Register 8 is not read by this
//    revision.)
#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "drivers/protocols/stream_protocols.hpp"
#include "drivers/protocols/vectornav.hpp"
#include "drivers/protocols/vectornav_device.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_device_test_vectornav_device {
namespace imuemu { using namespace ::imuemu; }

namespace {

using namespace imuemu;
using Bytes = std::vector<std::uint8_t>;

// ------------------------------------------------ the manual, independently

// CRC-16/CCITT, poly 0x1021, initial 0, bit by bit (no table, no reflection).
std::uint16_t spec_crc(const std::uint8_t* p, std::size_t n) {
  std::uint16_t crc = 0;
  for (std::size_t i = 0; i < n; ++i) {
    for (int bit = 7; bit >= 0; --bit) {
      const bool in = ((p[i] >> bit) & 1) != 0;
      const bool top = (crc & 0x8000) != 0;
      crc = static_cast<std::uint16_t>(crc << 1);
      if (in != top) crc ^= 0x1021;
    }
  }
  return crc;
}
std::uint16_t spec_crc(const std::string& s) { return spec_crc(reinterpret_cast<const std::uint8_t*>(s.data()), s.size()); }
std::uint8_t spec_xor(const std::string& s) {
  std::uint8_t x = 0;
  for (const char c : s) x ^= static_cast<std::uint8_t>(c);
  return x;
}
// "$" body "*" XX CR LF, as nmea_printf / libvnc's 8-bit mode frame it.
std::string framed(const std::string& body) {
  char sum[8];
  std::snprintf(sum, sizeof sum, "*%02X\r\n", spec_xor(body));
  return "$" + body + sum;
}
std::string framed_crc(const std::string& body) {
  char sum[8];
  std::snprintf(sum, sizeof sum, "*%04X\r\n", spec_crc(body));
  return "$" + body + sum;
}

// [Manual] field sizes: group -> bit -> bytes.
const std::map<int, std::map<int, std::size_t>> kSpecSizes = {
    {0, {{0, 8}, {1, 8}, {2, 8}, {3, 12}, {4, 16}, {5, 12}, {6, 24}, {7, 12}, {8, 12}, {9, 24}, {10, 20}, {11, 28},
         {12, 2}, {13, 4}, {14, 8}}},
    {1, {{0, 8}, {1, 8}, {2, 8}, {3, 2}, {4, 8}, {5, 8}, {6, 8}, {7, 4}, {8, 4}, {9, 1}}},
    {2, {{0, 2}, {1, 12}, {2, 12}, {3, 12}, {4, 4}, {5, 4}, {6, 16}, {7, 12}, {8, 12}, {9, 12}, {10, 12}, {11, 2}}},
    {3, {{0, 8}, {1, 8}, {2, 2}, {3, 1}, {4, 1}, {5, 24}, {6, 24}, {7, 12}, {8, 12}, {9, 12}, {10, 4}, {11, 4}, {12, 2}, {13, 28}}},
    {4, {{0, 2}, {1, 12}, {2, 16}, {3, 36}, {4, 12}, {5, 12}, {6, 12}, {7, 12}, {8, 12}}},
    {5, {{0, 2}, {1, 24}, {2, 24}, {3, 12}, {4, 12}, {5, 12}, {6, 12}, {7, 12}, {8, 12}, {9, 4}, {10, 4}}},
    {6, {{0, 8}, {1, 8}, {2, 2}, {3, 1}, {4, 1}, {5, 24}, {6, 24}, {7, 12}, {8, 12}, {9, 12}, {10, 4}, {11, 4}, {12, 2}, {13, 28}}},
};

struct SpecPacket {
  std::uint8_t groups = 0;
  std::map<int, std::uint16_t> masks;
  std::map<std::pair<int, int>, std::size_t> offsets;  // (group, bit) -> offset in `bytes`
  Bytes bytes;                                          // the whole packet, sync to CRC
  std::uint64_t counter = 0;                            // the sample it came with
};

template <class T>
T le(const std::uint8_t* p) {
  T v;
  std::memcpy(&v, p, sizeof v);  // the test host is little-endian, as the wire
  return v;
}

// Packets and ASCII lines in a stream; counts bytes outside both (and bad CRCs).
struct Split {
  std::vector<SpecPacket> packets;
  std::vector<std::string> lines;
  std::size_t bad = 0;
};
Split spec_split(const Bytes& s, std::uint64_t counter = 0) {
  Split out;
  std::size_t i = 0;
  while (i < s.size()) {
    if (s[i] == '$') {
      std::size_t e = i;
      while (e < s.size() && s[e] != '\n') ++e;
      if (e == s.size()) break;
      out.lines.emplace_back(s.begin() + static_cast<std::ptrdiff_t>(i), s.begin() + static_cast<std::ptrdiff_t>(e + 1));
      i = e + 1;
      continue;
    }
    if (s[i] != 0xFA || i + 2 > s.size()) {
      ++out.bad, ++i;
      continue;
    }
    SpecPacket p;
    p.groups = s[i + 1];
    std::size_t at = i + 2;
    bool ok = true;
    for (int g = 0; g < 7 && ok; ++g) {
      if ((p.groups & (1 << g)) == 0) continue;
      if (at + 2 > s.size()) ok = false;
      else p.masks[g] = le<std::uint16_t>(&s[at]), at += 2;
    }
    std::size_t off = at - i;
    for (const auto& [g, mask] : p.masks) {
      for (int b = 0; b < 16 && ok; ++b) {
        if ((mask & (1 << b)) == 0) continue;
        const auto it = kSpecSizes.at(g).find(b);
        if (it == kSpecSizes.at(g).end()) ok = false;
        else p.offsets[{g, b}] = off, off += it->second;
      }
    }
    const std::size_t total = off + 2;
    if (!ok || i + total > s.size() || spec_crc(&s[i + 1], total - 1) != 0) {
      ++out.bad, ++i;
      continue;
    }
    p.bytes.assign(s.begin() + static_cast<std::ptrdiff_t>(i), s.begin() + static_cast<std::ptrdiff_t>(i + total));
    p.counter = counter;
    out.packets.push_back(std::move(p));
    i += total;
  }
  return out;
}
const std::uint8_t* field(const SpecPacket& p, int group, int bit) {
  const auto it = p.offsets.find({group, bit});
  return it == p.offsets.end() ? nullptr : p.bytes.data() + it->second;
}
Eigen::Vector3d f3(const std::uint8_t* p) { return {le<float>(p), le<float>(p + 4), le<float>(p + 8)}; }
Eigen::Vector3d d3(const std::uint8_t* p) { return {le<double>(p), le<double>(p + 8), le<double>(p + 16)}; }

// ------------------------------------------------ the analytic trajectory

// Level, turning at a constant yaw rate at a fixed place (47 N, 8 E, 500 m):
// R_s^n(t) = Rz(w t); the gyro reads (0, 0, w), the accelerometer the
// specific force (0, 0, -g).
constexpr double kYawRate = 0.5;  // rad/s
constexpr double kG = 9.80665;
constexpr double kPi = 3.14159265358979323846;
constexpr double kLatDeg = 47.0, kLonDeg = 8.0, kHeight = 500.0;

drivers::ImuFrameInput sample_at(std::uint64_t k, std::int64_t rate_hz) {
  drivers::ImuFrameInput s;
  s.sample_counter = k;
  s.period_ns = 1'000'000'000 / rate_hz;
  s.t_ns = static_cast<TimeNs>(k) * s.period_ns;
  const double t = static_cast<double>(s.t_ns) * 1e-9;
  const double dt = static_cast<double>(s.period_ns) * 1e-9;
  s.gyro_rad_s = Vec3(0.0, 0.0, kYawRate);
  s.accel_m_s2 = Vec3(0.0, 0.0, -kG);
  s.delta_theta_rad = Vec3(0.0, 0.0, kYawRate * dt);
  s.delta_velocity_m_s = Vec3(0.0, 0.0, -kG * dt);
  s.has_navigation = true;
  s.latitude_rad = kLatDeg * kPi / 180.0;
  s.longitude_rad = kLonDeg * kPi / 180.0;
  s.height_m = kHeight;
  s.sensor_to_ned = Eigen::AngleAxisd(kYawRate * t, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return s;
}
double yaw_deg_at(std::uint64_t k, std::int64_t rate_hz) {
  double y = std::fmod(kYawRate * static_cast<double>(k) / static_cast<double>(rate_hz), 2 * kPi) * 180.0 / kPi;
  return y > 180.0 ? y - 360.0 : y;
}

// ------------------------------------------------ the device under test

struct Sink final : drivers::ReplySink {
  std::vector<Bytes> replies;
  std::optional<std::uint32_t> baud_after;
  bool reply(std::span<const std::uint8_t> b) override {
    replies.emplace_back(b.begin(), b.end());
    return true;
  }
  void change_baud_after_replies(std::uint32_t baud) override { baud_after = baud; }
};

drivers::StreamEncoderOptions options(drivers::VectorNavModel model, std::int64_t rate_hz) {
  drivers::StreamEncoderOptions o;
  o.nominal_sample_rate_hz = static_cast<double>(rate_hz);
  o.vectornav.model = model;
  return o;
}

// One command (bytes as the client writes them), its one reply as text.
std::string ask(drivers::CommandResponder& d, const std::string& command, Sink* sink_out = nullptr) {
  Sink sink;
  d.on_input(std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(command.data()), command.size()), sink);
  if (sink_out != nullptr) *sink_out = sink;
  EXPECT_EQ(sink.replies.size(), 1u) << command;
  return sink.replies.empty() ? std::string() : std::string(sink.replies.front().begin(), sink.replies.front().end());
}

// Runs samples [first, first + n) through the encoder: the packets and lines
// each sample sent, and no byte outside them.
Split run(drivers::vectornav::Encoder& e, std::uint64_t first, std::uint64_t n, std::int64_t rate_hz) {
  Split all;
  for (std::uint64_t k = first; k < first + n; ++k) {
    Bytes out;
    e.encode(sample_at(k, rate_hz), out);
    Split s = spec_split(out, k);
    EXPECT_EQ(s.bad, 0u) << "sample " << k;
    for (auto& p : s.packets) all.packets.push_back(std::move(p));
    for (auto& l : s.lines) all.lines.push_back(std::move(l));
  }
  return all;
}

// ArduPilot's reply acceptance (lashVN/ardupilot 04e3123, decode() and
// decode_latest_term()), re-stated: the sentence from $ to *: term 0 must
// be a prefix-match of the command (or VNERR: an error, retried), term 1
// is compared on its first character with the command after "VNXXX,"
// (strncmp with length `term_offset != 0`), a term 2 starting "VN-" is the
// model; the two hex digits after * must equal the XOR of the bytes between
// $ and *.
struct ApVerdict {
  bool accepted = false;
  bool error = false;
  std::string model;
};
ApVerdict ardupilot_decode(const std::string& reply, const std::string& message_to_send) {
  ApVerdict v;
  if (reply.empty() || reply[0] != '$') return v;
  const std::size_t star = reply.find('*');
  if (star == std::string::npos || star + 3 > reply.size()) return v;
  const std::string body = reply.substr(1, star - 1);
  std::vector<std::string> terms;
  std::size_t start = 0;
  for (std::size_t c = 0; c <= body.size(); ++c)
    if (c == body.size() || body[c] == ',') terms.push_back(body.substr(start, c - start)), start = c + 1;
  bool valid = true;
  if (terms[0] == "VNERR") v.error = true;
  else if (message_to_send.compare(0, terms[0].size(), terms[0]) != 0) valid = false;
  if (terms.size() > 1 && !v.error && message_to_send.size() > 6 && !terms[1].empty() && terms[1][0] != message_to_send[6])
    valid = false;
  if (terms.size() > 2 && terms[2].rfind("VN-", 0) == 0) v.model = terms[2];
  const unsigned sum = static_cast<unsigned>(std::stoul(reply.substr(star + 1, 2), nullptr, 16));
  v.accepted = valid && sum == spec_xor(body) && !v.error;
  return v;
}

// --------------------------------------------------------------- framing

TEST(VectorNavDevice, ChecksumAndCrcMatchTheWorkedExamplesInTheDriversSources) {
  // CRC-16/CCITT with init 0 is CRC-16/XMODEM: check value over "123456789".
  EXPECT_EQ(spec_crc("123456789"), 0x31C3);
  EXPECT_EQ(drivers::vectornav::crc16(std::span<const std::uint8_t>(
                reinterpret_cast<const std::uint8_t*>("123456789"), 9)),
            0x31C3);
  // ArduPilot's comments give commands with their checksums (lashVN/ardupilot
  // 04e3123, ArduPilot 338dbba). "$VNWRG,75,3,16,01,0721*D415" and
  // "$VNWRG,76,3,80,4E,0002,0010,20B8,0018*63" check out; the others there
  // (76 ...*B36B, ...*097A, 75,3,8,34,...*0C, 75,3,80,14,...*66) do not
  // match their own text by either algorithm: comments edited without
  // their checksums, not worked examples.
  EXPECT_EQ(spec_crc("VNWRG,75,3,16,01,0721"), 0xD415);
  EXPECT_EQ(spec_xor("VNWRG,76,3,80,4E,0002,0010,20B8,0018"), 0x63);
  EXPECT_EQ(drivers::vectornav::checksum8("VNWRG,76,3,80,4E,0002,0010,20B8,0018"), 0x63);
}

TEST(VectorNavDevice, ReadsAnswerInEitherChecksumModeAndXXSkipsTheCheck) {
  drivers::vectornav::Encoder e(options(drivers::VectorNavModel::vn100, 800));
  drivers::CommandResponder& d = *e.command_responder();
  EXPECT_EQ(ask(d, framed("VNRRG,01")), framed("VNRRG,01,VN-100T-CR"));
  EXPECT_EQ(ask(d, framed_crc("VNRRG,01")), framed("VNRRG,01,VN-100T-CR")) << "replies use register 30's mode";
  EXPECT_EQ(ask(d, "$VNRRG,1*XX\r\n"), framed("VNRRG,01,VN-100T-CR"));
  EXPECT_EQ(ask(d, "$VNRRG,04*XXXX\r\n"), framed("VNRRG,04,2.1.0.0"));
  EXPECT_EQ(ask(d, framed("VNRRG,02")), framed("VNRRG,02,2"));
  EXPECT_EQ(ask(d, framed("VNRRG,03")), framed("VNRRG,03,100012345"));
  EXPECT_EQ(ask(d, framed("VNRRG,00")), framed("VNRRG,00,"));
  EXPECT_EQ(ask(d, framed("VNWRG,00,bench unit 7")), framed("VNWRG,00,bench unit 7"));
  EXPECT_EQ(ask(d, framed("VNRRG,00")), framed("VNRRG,00,bench unit 7"));
  EXPECT_EQ(ask(d, framed("VNRRG,05")), framed("VNRRG,05,115200"));
  EXPECT_EQ(ask(d, framed("VNRRG,06")), framed("VNRRG,06,14"));
  EXPECT_EQ(ask(d, framed("VNRRG,06,?")), framed("VNRRG,06,14,1"));
  EXPECT_EQ(ask(d, framed("VNRRG,07")), framed("VNRRG,07,40"));
  EXPECT_EQ(ask(d, framed("VNRRG,30")), framed("VNRRG,30,0,0,0,0,1,0,1"));
  EXPECT_EQ(ask(d, framed("VNRRG,32")), framed("VNRRG,32,3,0,0,0,0,0,0,100000000,0"));
  EXPECT_EQ(ask(d, framed("VNRRG,75")), framed("VNRRG,75,0,0,00"));
  // Register 30 to CRC-16: the reply to that write and every one after it.
  EXPECT_EQ(ask(d, framed("VNWRG,30,0,0,0,0,2,0,1")), framed_crc("VNWRG,30,0,0,0,0,2,0,1"));
  EXPECT_EQ(ask(d, framed("VNRRG,01")), framed_crc("VNRRG,01,VN-100T-CR"));
}

TEST(VectorNavDevice, ErrorsCarryTheManualsCodesAndChangeNothing) {
  drivers::vectornav::Encoder e(options(drivers::VectorNavModel::vn100, 800));
  drivers::CommandResponder& d = *e.command_responder();
  EXPECT_EQ(ask(d, "$VNRRG,01*00\r\n"), framed("VNERR,03"));            // invalid checksum
  EXPECT_EQ(ask(d, framed("VNXYZ,1")), framed("VNERR,04"));             // invalid command
  EXPECT_EQ(ask(d, framed("VNRRG")), framed("VNERR,05"));               // not enough parameters
  EXPECT_EQ(ask(d, framed("VNASY,1,2")), framed("VNERR,06"));           // too many parameters
  EXPECT_EQ(ask(d, framed("VNWRG,07,33")), framed("VNERR,07"));         // 33 Hz is not a rate
  EXPECT_EQ(ask(d, framed("VNRRG,250")), framed("VNERR,08"));           // no such register
  EXPECT_EQ(ask(d, framed("VNWRG,01,VN-999")), framed("VNERR,09"));     // read only
  EXPECT_EQ(ask(d, framed("VNWRG,75,1,16,08,0001")), framed("VNERR,07")) << "no GNSS group on a VN-100";
  EXPECT_EQ(ask(d, framed("VNWRG,75,1,16,01,8000")), framed("VNERR,07")) << "no extension fields";
  // 800 Hz of a 82-byte packet is 656 kbit/s: more than 115200 baud carries.
  EXPECT_EQ(ask(d, framed("VNWRG,75,1,1,01,0721")), framed("VNERR,0C"));
  EXPECT_EQ(ask(d, framed("VNRRG,07")), framed("VNRRG,07,40"));
  EXPECT_EQ(ask(d, framed("VNRRG,75")), framed("VNRRG,75,0,0,00"));
  const drivers::CommandCounters c = d.command_counters();
  EXPECT_EQ(c.received, 12u);
  EXPECT_EQ(c.nacked, 10u);
  EXPECT_EQ(c.answered, 2u);
}

TEST(VectorNavDevice, CommandsSplitAcrossReadsAndGarbageAroundThemAreFound) {
  drivers::vectornav::Encoder e(options(drivers::VectorNavModel::vn100, 800));
  drivers::CommandResponder& d = *e.command_responder();
  const std::string cmd = framed("VNRRG,01");
  const std::string stream = "\x01\xFAgarbage$VN" + std::string("\r\n") + cmd + cmd;
  Sink sink;
  for (const char c : stream) {
    const auto b = static_cast<std::uint8_t>(c);
    d.on_input(std::span<const std::uint8_t>(&b, 1), sink);
  }
  ASSERT_EQ(sink.replies.size(), 2u);
  for (const Bytes& r : sink.replies) EXPECT_EQ(std::string(r.begin(), r.end()), framed("VNRRG,01,VN-100T-CR"));
  EXPECT_GT(d.command_counters().not_command_bytes, 9u);
}

TEST(VectorNavDevice, BaudChangesAfterItsReply) {
  drivers::vectornav::Encoder e(options(drivers::VectorNavModel::vn100, 800));
  drivers::CommandResponder& d = *e.command_responder();
  Sink sink;
  EXPECT_EQ(ask(d, framed("VNWRG,05,921600"), &sink), framed("VNWRG,05,921600"));
  EXPECT_EQ(sink.baud_after, 921600u);
  EXPECT_EQ(d.command_counters().baud, 921600u);
  EXPECT_EQ(ask(d, framed("VNWRG,05,460800,2"), &sink), framed("VNWRG,05,460800,2"));
  EXPECT_FALSE(sink.baud_after) << "the other port's rate: this line stays";
  EXPECT_EQ(ask(d, framed("VNWRG,05,12345")), framed("VNERR,07"));
  // Reset: back to the saved (power-up) rate, after the reply.
  EXPECT_EQ(ask(d, framed("VNRST"), &sink), framed("VNRST"));
  EXPECT_EQ(sink.baud_after, 115200u);
}

// ------------------------------------------------------------ binary output

TEST(VectorNavDevice, AHandBuiltPacketMatchesTheEncodersBytesCrcIncluded) {
  // Output 1: common group, TimeStartup | AngularRate | Accel (0x0121), on
  // port 1, every 8th IMU sample. Laid out by hand from the manual.
  drivers::vectornav::Encoder e(options(drivers::VectorNavModel::vn100, 800));
  drivers::CommandResponder& d = *e.command_responder();
  EXPECT_EQ(ask(d, framed("VNWRG,06,0")), framed("VNWRG,06,0"));
  EXPECT_EQ(ask(d, framed("VNWRG,75,1,8,1,121")), framed("VNWRG,75,1,8,01,0121"));
  Bytes out;
  e.encode(sample_at(16, 800), out);
  Bytes want{0xFA, 0x01, 0x21, 0x01};
  auto put = [&](const void* p, std::size_t n) {
    const auto* b = static_cast<const std::uint8_t*>(p);
    want.insert(want.end(), b, b + n);
  };
  const std::uint64_t time_startup = 16 * 1'250'000ULL;  // 16 samples of 1.25 ms after power-up
  put(&time_startup, 8);
  for (const float v : {0.0f, 0.0f, static_cast<float>(kYawRate)}) put(&v, 4);
  for (const float v : {0.0f, 0.0f, static_cast<float>(-kG)}) put(&v, 4);
  const std::uint16_t crc = spec_crc(want.data() + 1, want.size() - 1);
  want.push_back(static_cast<std::uint8_t>(crc >> 8));
  want.push_back(static_cast<std::uint8_t>(crc & 0xFF));
  EXPECT_EQ(out, want);
  EXPECT_EQ(spec_crc(out.data() + 1, out.size() - 1), 0) << "the CRC appended gives 0";
}

TEST(VectorNavDevice, EveryFieldOfEveryGroupFitsTheLinkBudgetBound) {
  drivers::vectornav::Encoder e(options(drivers::VectorNavModel::vn300, 400));
  drivers::CommandResponder& d = *e.command_responder();
  const std::string all = "1,400,7F,7FFF,03FF,0FFF,3FFF,01FF,07FF,3FFF";  // 1 Hz: within 115200 baud
  for (const char* reg : {"75", "76", "77"})
    EXPECT_EQ(ask(d, framed(std::string("VNWRG,") + reg + "," + all)), framed(std::string("VNWRG,") + reg + "," + all));
  ask(d, framed("VNWRG,06,14"));
  Bytes out;
  e.encode(sample_at(0, 400), out);
  const Split s = spec_split(out);
  ASSERT_EQ(s.packets.size(), 3u);
  ASSERT_EQ(s.lines.size(), 1u);
  std::size_t fields = 0;
  for (const auto& [g, sizes] : kSpecSizes)
    for (const auto& [bit, n] : sizes) fields += n;
  EXPECT_EQ(s.packets[0].bytes.size(), 1 + 1 + 7 * 2 + fields + 2);
  EXPECT_LE(out.size(), e.max_bytes_per_sample());
  EXPECT_GE(out.size(), 3 * s.packets[0].bytes.size());
}

TEST(VectorNavDevice, RateDivisorCountsOnTheImuRateWhateverTheSceneRate) {
  for (const std::int64_t rate : {800, 400}) {
    drivers::vectornav::Encoder e(options(drivers::VectorNavModel::vn100, rate));
    drivers::CommandResponder& d = *e.command_responder();
    ask(d, framed("VNWRG,06,0"));
    ask(d, framed("VNWRG,75,1,4,01,0001"));  // 800 / 4 = 200 Hz
    const Split s = run(e, 0, static_cast<std::uint64_t>(rate), rate);
    EXPECT_EQ(s.packets.size(), 200u) << rate << " Hz scene";
    EXPECT_TRUE(s.lines.empty());
    for (std::size_t i = 1; i < s.packets.size(); ++i)
      EXPECT_EQ(s.packets[i].counter - s.packets[i - 1].counter, static_cast<std::uint64_t>(rate / 200));
  }
}

TEST(VectorNavDevice, AsyncAsciiFollowsRegisters6And7AndVnasyPausesEverything) {
  drivers::vectornav::Encoder e(options(drivers::VectorNavModel::vn100, 800));
  drivers::CommandResponder& d = *e.command_responder();
  // Power-up: VNYMR at 40 Hz.
  Split s = run(e, 0, 800, 800);
  ASSERT_EQ(s.lines.size(), 40u);
  EXPECT_EQ(s.lines[0].rfind("$VNYMR,", 0), 0u);
  const std::string& l = s.lines[20];
  const std::size_t star = l.find('*');
  EXPECT_EQ(std::stoul(l.substr(star + 1, 2), nullptr, 16), static_cast<unsigned long>(spec_xor(l.substr(1, star - 1))));
  // 12 fields: yaw, pitch, roll, mag x3, accel x3, gyro x3.
  EXPECT_EQ(std::count(l.begin(), l.end(), ','), 12);
  float yaw = 0, pitch = 0, roll = 0;
  ASSERT_EQ(std::sscanf(l.c_str(), "$VNYMR,%f,%f,%f", &yaw, &pitch, &roll), 3);
  EXPECT_NEAR(yaw, yaw_deg_at(400, 800), 1e-3);  // line 20 of 40 per second: sample 400
  EXPECT_NEAR(pitch, 0.0, 1e-3);
  ask(d, framed("VNWRG,06,1"));
  ask(d, framed("VNWRG,07,10"));
  ask(d, framed("VNWRG,75,3,16,01,0001"));
  s = run(e, 800, 800, 800);
  EXPECT_EQ(s.lines.size(), 10u);
  EXPECT_EQ(s.lines[0].rfind("$VNYPR,", 0), 0u);
  EXPECT_EQ(s.packets.size(), 50u);
  EXPECT_EQ(ask(d, framed("VNASY,0")), framed("VNASY,0"));
  s = run(e, 1600, 800, 800);
  EXPECT_TRUE(s.lines.empty());
  EXPECT_TRUE(s.packets.empty());
  EXPECT_EQ(ask(d, framed("VNASY,1")), framed("VNASY,1"));
  s = run(e, 2400, 800, 800);
  EXPECT_EQ(s.lines.size(), 10u);
  EXPECT_EQ(s.packets.size(), 50u);
}

TEST(VectorNavDevice, ConfiguredTrafficIsEachOutputsBytesTimesItsRateAndFollowsRegisterWrites) {
  drivers::vectornav::Encoder e(options(drivers::VectorNavModel::vn100, 800));
  drivers::CommandResponder& d = *e.command_responder();
  // One second of the scene on the wire.
  auto wire_bytes = [&](std::uint64_t first) {
    Bytes out;
    for (std::uint64_t k = first; k < first + 800; ++k) e.encode(sample_at(k, 800), out);
    return static_cast<double>(out.size());
  };
  // Power-up: $VNYMR at 40 Hz, of fixed-width fields [U]: "$VNYMR," (7),
  // yaw / pitch / roll %+08.3f (3 x 8), magnetic %+07.4f (3 x 7),
  // acceleration %+07.3f (3 x 7), angular rate %+09.6f (3 x 9), 11 commas,
  // "*XX\r\n" (5).
  const double ymr = 7 + 3 * 8 + 3 * 7 + 3 * 7 + 3 * 9 + 11 + 5;
  EXPECT_DOUBLE_EQ(e.configured_bytes_per_second(800.0), ymr * 40);
  EXPECT_EQ(wire_bytes(0), ymr * 40);
  // Binary output 1 at 800 / 8 = 100 Hz, Common group TimeStartup (8),
  // Ypr (12), AngularRate (12): sync, group byte, one field mask (2), the
  // fields, CRC (2).
  ask(d, framed("VNWRG,75,1,8,01,0029"));
  const double binary = 1 + 1 + 2 + (8 + 12 + 12) + 2;
  EXPECT_DOUBLE_EQ(e.configured_bytes_per_second(800.0), ymr * 40 + binary * 100);
  EXPECT_EQ(wire_bytes(800), ymr * 40 + binary * 100);
  // A 50 Hz scene sends the 100 Hz packet on every sample.
  EXPECT_DOUBLE_EQ(e.configured_bytes_per_second(50.0), ymr * 40 + binary * 50);
  ask(d, framed("VNWRG,06,0"));  // the ASCII output off
  EXPECT_DOUBLE_EQ(e.configured_bytes_per_second(800.0), binary * 100);
  ask(d, framed("VNASY,0"));  // everything paused
  EXPECT_DOUBLE_EQ(e.configured_bytes_per_second(800.0), 0.0);
}

TEST(VectorNavDevice, ARestartBringsBackTheSavedSettings) {
  drivers::vectornav::Encoder e(options(drivers::VectorNavModel::vn100, 800));
  drivers::CommandResponder& d = *e.command_responder();
  ask(d, framed("VNWRG,06,0"));
  ask(d, framed("VNWRG,75,1,16,01,0001"));
  EXPECT_EQ(ask(d, framed("VNWNV")), framed("VNWNV"));
  ask(d, framed("VNWRG,75,1,8,01,0001"));
  ask(d, framed("VNASY,0"));
  Bytes nothing;
  e.restart(0, nothing);
  const Split s = run(e, 0, 800, 800);
  EXPECT_EQ(s.packets.size(), 50u) << "saved: divisor 16, async on";
  EXPECT_TRUE(s.lines.empty());
  EXPECT_EQ(ask(d, framed("VNRRG,75")), framed("VNRRG,75,1,16,01,0001"));
  EXPECT_EQ(ask(d, framed("VNRFS")), framed("VNRFS"));
  EXPECT_EQ(ask(d, framed("VNRRG,75")), framed("VNRRG,75,0,0,00"));
  EXPECT_EQ(ask(d, framed("VNRRG,06")), framed("VNRRG,06,14"));
}

// Scene key saved_registers: a unit configured in flash ($VNWRG ... $VNWNV)
// streams that at power-up, with or without a driver; $VNRST keeps it,
// $VNRFS restores the factory's. A write the device refuses is refused as
// a scene (the device's own error code).
TEST(VectorNavDevice, SavedRegistersStreamFromPowerUpAndOnlyTheFactoryResetDropsThem) {
  drivers::StreamEncoderOptions o = options(drivers::VectorNavModel::vn100, 800);
  o.vectornav.saved_registers = "6,0;75,1,16,01,0001;0,BENCH UNIT";
  {
    drivers::vectornav::Encoder e(o);
    Split s = run(e, 0, 800, 800);
    EXPECT_EQ(s.packets.size(), 50u) << "binary output 1 at 800 / 16 Hz from power-up";
    EXPECT_TRUE(s.lines.empty()) << "register 6 saved as 0: no VNYMR";
    drivers::CommandResponder& d = *e.command_responder();
    EXPECT_EQ(ask(d, framed("VNRRG,00")), framed("VNRRG,00,BENCH UNIT"));
    ask(d, framed("VNWRG,75,1,8,01,0001"));
    EXPECT_EQ(ask(d, framed("VNRST")), framed("VNRST"));
    EXPECT_EQ(ask(d, framed("VNRRG,75")), framed("VNRRG,75,1,16,01,0001")) << "a reset comes back to the saved settings";
    EXPECT_EQ(ask(d, framed("VNRFS")), framed("VNRFS"));
    EXPECT_EQ(ask(d, framed("VNRRG,75")), framed("VNRRG,75,0,0,00"));
    EXPECT_EQ(ask(d, framed("VNRRG,06")), framed("VNRRG,06,14"));
    s = run(e, 800, 800, 800);
    EXPECT_TRUE(s.packets.empty());
    EXPECT_EQ(s.lines.size(), 40u) << "the factory's VNYMR at 40 Hz";
  }
  // Its receive wire not connected (answers_commands = false): the saved
  // settings stream all the same, and nothing answers.
  o.vectornav.answers_commands = false;
  drivers::vectornav::Encoder quiet(o);
  EXPECT_EQ(quiet.command_responder(), nullptr);
  EXPECT_EQ(run(quiet, 0, 800, 800).packets.size(), 50u);
  // Refused as the device refuses the write: divisor 0 on a port, a group
  // the VN-100 lacks (GNSS, bit 3), a read-only register.
  for (const auto& [saved, code] : std::vector<std::pair<std::string, std::string>>{
           {"75,1,0,01,0001", "$VNERR,07"}, {"75,1,4,08,0001", "$VNERR,07"}, {"1,VN-100", "$VNERR,09"}}) {
    o.vectornav.saved_registers = saved;
    const std::optional<std::string> problem = drivers::vectornav::saved_registers_problem(o.vectornav);
    ASSERT_TRUE(problem.has_value()) << saved;
    EXPECT_NE(problem->find("'" + saved + "'"), std::string::npos) << *problem;
    EXPECT_NE(problem->find(code), std::string::npos) << *problem;
    EXPECT_THROW(drivers::make_stream_encoder("vectornav", o), std::invalid_argument);
  }
}

// [U] register 32, Synchronization Control: SyncInMode, SyncInEdge,
// SyncInSkipFactor, reserved, SyncOutMode (0 none, 1 ItStart, 2 ImuReady,
// 3 Ins, 6 GpsPps), SyncOutPolarity (0 negative, 1 positive),
// SyncOutSkipFactor, SyncOutPulseWidth (ns), reserved. The SyncOut pin is
// the scene's GPIO sync line: the device decides each sample's pulse.
TEST(VectorNavDevice, Register32SyncOutDecidesTheSyncLinesPulses) {
  drivers::vectornav::Encoder e(options(drivers::VectorNavModel::vn100, 800));
  drivers::CommandResponder& d = *e.command_responder();
  auto pulses_over = [&](std::uint64_t first, std::uint64_t n) {
    std::vector<std::uint64_t> at;
    for (std::uint64_t k = first; k < first + n; ++k) {
      Bytes out;
      e.encode(sample_at(k, 800), out);
      const std::optional<drivers::DeviceSyncPulse> p = e.device_sync_pulse();
      if (!p) return std::vector<std::uint64_t>{~std::uint64_t{0}};  // the scene's pulse applies
      if (p->pulse) at.push_back(k);
    }
    return at;
  };
  // Factory: SyncOutMode none, the scene's [imu.sync] applies.
  EXPECT_EQ(ask(d, framed("VNRRG,32")), framed("VNRRG,32,3,0,0,0,0,0,0,100000000,0"));
  EXPECT_EQ(pulses_over(0, 8), std::vector<std::uint64_t>{~std::uint64_t{0}});
  // ImuReady, every 4th IMU sample (skip 3), positive, 500 us.
  EXPECT_EQ(ask(d, framed("VNWRG,32,3,0,0,0,2,1,3,500000,0")), framed("VNWRG,32,3,0,0,0,2,1,3,500000,0"));
  EXPECT_EQ(pulses_over(8, 16), std::vector<std::uint64_t>({8, 12, 16, 20}));
  const std::optional<drivers::DeviceSyncPulse> p = e.device_sync_pulse();
  ASSERT_TRUE(p.has_value());
  EXPECT_EQ(p->width_ns, 500'000);
  EXPECT_FALSE(p->active_low);
  // Ins: the 400 Hz attitude solution, every one (skip 0), negative.
  ask(d, framed("VNWRG,32,3,0,0,0,3,0,0,1000000,0"));
  EXPECT_EQ(pulses_over(24, 8), std::vector<std::uint64_t>({24, 26, 28, 30}));
  EXPECT_TRUE(e.device_sync_pulse()->active_low);
  // $VNASY,0 pauses the async outputs, not the IMU's sync events.
  ask(d, framed("VNASY,0"));
  EXPECT_EQ(pulses_over(32, 4), std::vector<std::uint64_t>({32, 34}));
  // Refused, nothing changed: GpsPps on a VN-100 (no GNSS), mode 4, polarity 2.
  for (const char* bad : {"VNWRG,32,3,0,0,0,6,1,0,1000,0", "VNWRG,32,3,0,0,0,4,1,0,1000,0", "VNWRG,32,3,0,0,0,2,2,0,1000,0"})
    EXPECT_EQ(ask(d, framed(bad)), framed("VNERR,07")) << bad;
  EXPECT_EQ(ask(d, framed("VNRRG,32")), framed("VNRRG,32,3,0,0,0,3,0,0,1000000,0"));
  // Saved as a scene key: pulses from power-up.
  drivers::StreamEncoderOptions o = options(drivers::VectorNavModel::vn100, 800);
  o.vectornav.saved_registers = "32,3,0,0,0,1,1,7,200000,0";  // ItStart, every 8th
  drivers::vectornav::Encoder saved(o);
  std::vector<std::uint64_t> at;
  for (std::uint64_t k = 0; k < 24; ++k) {
    Bytes out;
    saved.encode(sample_at(k, 800), out);
    if (saved.device_sync_pulse() && saved.device_sync_pulse()->pulse) at.push_back(k);
  }
  EXPECT_EQ(at, std::vector<std::uint64_t>({0, 8, 16}));
}

TEST(VectorNavDevice, RegisterReadsOfAttitudeAndBomPollsCarryTheLatestSample) {
  drivers::vectornav::Encoder e(options(drivers::VectorNavModel::vn100, 800));
  drivers::CommandResponder& d = *e.command_responder();
  ask(d, framed("VNWRG,75,0,16,01,0009"));  // TimeStartup, YawPitchRoll; not streamed (async mode 0)
  (void)run(e, 0, 801, 800);  // the last sample: 800 (t = 1 s)
  const std::string ypr = ask(d, framed("VNRRG,08"));
  float yaw = 0, pitch = 0, roll = 0;
  ASSERT_EQ(std::sscanf(ypr.c_str(), "$VNRRG,08,%f,%f,%f", &yaw, &pitch, &roll), 3) << ypr;
  EXPECT_NEAR(yaw, yaw_deg_at(800, 800), 1e-3);
  Sink sink;
  d.on_input(std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(framed("VNBOM,1").data()),
                                           framed("VNBOM,1").size()),
             sink);
  ASSERT_EQ(sink.replies.size(), 1u);
  const Split s = spec_split(sink.replies.front());
  ASSERT_EQ(s.packets.size(), 1u);
  EXPECT_EQ(le<std::uint64_t>(field(s.packets[0], 0, 0)), 1'000'000'000ULL);
  EXPECT_NEAR(f3(field(s.packets[0], 0, 3)).x(), yaw_deg_at(800, 800), 1e-4);
}

// --------------------------------------------------------------- ArduPilot

struct ApRun {
  std::string model;
  Split stream;
};
// Replays ArduPilot's initialize() for a device of `model` at EAHRS_RATE
// `rate` (50 Hz default) with the scene at the model's IMU rate.
ApRun ardupilot_start_up(drivers::VectorNavModel model, std::int64_t imu_rate, unsigned rate) {
  drivers::vectornav::Encoder e(options(model, imu_rate));
  drivers::CommandResponder& d = *e.command_responder();
  ApRun r;
  auto run_command = [&](const std::string& message) {
    const ApVerdict v = ardupilot_decode(ask(d, framed(message)), message);
    EXPECT_TRUE(v.accepted) << message << " would be resent forever";
    if (!v.model.empty()) r.model = v.model;
  };
  run_command("VNASY,0");
  run_command("VNWRG,06,0,1");
  run_command("VNWRG,06,0,2");
  run_command("VNRRG,01");
  if (r.model.rfind("VN-1", 0) == 0) {
    run_command("VNWRG,75,3," + std::to_string(800 / rate) + ",01,0721");
    run_command("VNWRG,76,3,16,11,0001,0106");
  } else {
    const unsigned ins_rate = r.model.rfind("VN-300", 0) == 0 ? 400 : 800;
    run_command("VNWRG,75,3," + std::to_string(ins_rate / rate) + ",01,0721");
    run_command("VNWRG,76,3," + std::to_string(ins_rate / 50) + ",31,0001,0106,0613");
    run_command("VNWRG,77,3," + std::to_string(ins_rate / 5) + ",49,0003,26B8,0018");
  }
  run_command("VNASY,1");
  // Two seconds of streaming.
  r.stream = run(e, 0, static_cast<std::uint64_t>(2 * imu_rate), imu_rate);
  return r;
}

// ArduPilot's header match: sync, then the packet's header bytes; and its lengths.
bool header_is(const SpecPacket& p, std::initializer_list<std::uint8_t> h, std::size_t length) {
  return p.bytes.size() == length && std::equal(h.begin(), h.end(), p.bytes.begin() + 1);
}

TEST(VectorNavDevice, ArduPilotVn100StartUpGetsEveryReplyThenItsPacketsKeepItHealthy) {
  const ApRun r = ardupilot_start_up(drivers::VectorNavModel::vn100, 800, 50);
  EXPECT_EQ(r.model, "VN-100T-CR");
  EXPECT_TRUE(r.stream.lines.empty()) << "ASCII output off on both ports";
  std::vector<double> imu_ms, ekf_ms;
  for (const SpecPacket& p : r.stream.packets) {
    const double ms = static_cast<double>(p.counter) * 1.25;
    if (header_is(p, {0x01, 0x21, 0x07}, 82)) {
      imu_ms.push_back(ms);
      // VN_IMU_packet: timeStartup, gyro, accel, uncompAccel, uncompAngRate, mag, temp, pressure.
      const std::uint8_t* b = p.bytes.data() + 4;
      EXPECT_EQ(le<std::uint64_t>(b), p.counter * 1'250'000ULL);
      EXPECT_NEAR(f3(b + 8).z(), kYawRate, 1e-6);
      EXPECT_NEAR(f3(b + 20).z(), -kG, 1e-5);
      EXPECT_NEAR(f3(b + 32).z(), -kG, 1e-5);
      EXPECT_NEAR(f3(b + 44).z(), kYawRate, 1e-6);
      EXPECT_NEAR(le<float>(b + 72), 95.461, 0.01) << "ISA pressure at 500 m, kPa";
    } else if (header_is(p, {0x11, 0x01, 0x00, 0x06, 0x01}, 56)) {
      ekf_ms.push_back(ms);
      // VN_AHRS_ekf_packet: timeStartup, ypr, quaternion (x, y, z, w), yprU.
      const std::uint8_t* b = p.bytes.data() + 6;
      EXPECT_NEAR(le<float>(b + 8), yaw_deg_at(p.counter, 800), 1e-3);
      const double half = std::remainder(kYawRate * static_cast<double>(p.counter) / 800.0, 2 * kPi) / 2.0;
      const double sgn = std::cos(half) < 0 ? -1.0 : 1.0;
      EXPECT_NEAR(le<float>(b + 28), sgn * std::sin(half), 1e-6);
      EXPECT_NEAR(le<float>(b + 32), sgn * std::cos(half), 1e-6);
    } else {
      ADD_FAILURE() << "a packet ArduPilot does not expect";
    }
  }
  ASSERT_FALSE(imu_ms.empty());
  ASSERT_FALSE(ekf_ms.empty());
  EXPECT_EQ(imu_ms.front(), 0.0);
  // healthy(): every gap below 40 ms (IMU) and 500 ms (EKF) - here 20 ms each.
  for (std::size_t i = 1; i < imu_ms.size(); ++i) EXPECT_LT(imu_ms[i] - imu_ms[i - 1], 40.0);
  for (std::size_t i = 1; i < ekf_ms.size(); ++i) EXPECT_LT(ekf_ms[i] - ekf_ms[i - 1], 500.0);
  EXPECT_EQ(imu_ms.size(), 100u);
  EXPECT_EQ(ekf_ms.size(), 100u);
}

TEST(VectorNavDevice, ArduPilotVn300StartUpStreamsImuInsAndGnssPacketsWithBothFixes) {
  const ApRun r = ardupilot_start_up(drivers::VectorNavModel::vn300, 400, 50);
  EXPECT_EQ(r.model, "VN-300T-CR");
  std::size_t imu = 0, ins = 0, gnss = 0;
  for (const SpecPacket& p : r.stream.packets) {
    if (header_is(p, {0x01, 0x21, 0x07}, 82)) {
      ++imu;
    } else if (header_is(p, {0x31, 0x01, 0x00, 0x06, 0x01, 0x13, 0x06}, 104)) {
      ++ins;
      // VN_INS_ekf_packet after the header: timeStartup, ypr, quaternion,
      // yprU, insStatus, posLla, velNed, posU, velU.
      const std::uint8_t* b = p.bytes.data() + 8;
      EXPECT_EQ(le<std::uint16_t>(b + 48) & 0x3, 2) << "INS mode tracking";
      const Eigen::Vector3d lla = d3(b + 50);
      EXPECT_NEAR(lla.x(), kLatDeg, 1e-9);
      EXPECT_NEAR(lla.y(), kLonDeg, 1e-9);
      EXPECT_NEAR(lla.z(), kHeight, 1e-6);
    } else if (header_is(p, {0x49, 0x03, 0x00, 0xB8, 0x26, 0x18, 0x00}, 110)) {
      ++gnss;
      // VN_INS_gnss_packet: timeStartup, timeGps, numSats1, fix1, ..., numSats2, fix2.
      const std::uint8_t* b = p.bytes.data() + 8;
      const std::uint64_t gps_ns = le<std::uint64_t>(b + 8);
      // Default receiver time base: GPS week 2400, TOW 0 at trajectory time 0.
      EXPECT_EQ(gps_ns, 2400ULL * 604800ULL * 1'000'000'000ULL + p.counter * 2'500'000ULL);
      EXPECT_EQ(b[17], 3) << "GPS1 fix";
      EXPECT_EQ(b[p.bytes.size() - 8 - 2 - 1], 3) << "GPS2 fix";
    } else {
      ADD_FAILURE() << "a packet ArduPilot does not expect";
    }
  }
  EXPECT_EQ(imu, 100u);   // 400 / 8 = 50 Hz for 2 s
  EXPECT_EQ(ins, 100u);   // 400 / 8
  EXPECT_EQ(gnss, 10u);   // 400 / 80 = 5 Hz
}

// --------------------------------------------------------------------- PX4

TEST(VectorNavDevice, Px4StartUpThroughLibvncGetsEveryReplyAndDecodesItsThreeOutputs) {
  drivers::StreamEncoderOptions o = options(drivers::VectorNavModel::vn300, 400);
  o.vectornav.port = 2;  // PX4 configures ASYNCMODE_PORT2: the device's port 2 is the autopilot's
  drivers::vectornav::Encoder e(o);
  drivers::CommandResponder& d = *e.command_responder();
  // Every reply: the command's name and register, an 8-bit checksum libvnc checks.
  auto expect_reply = [&](const std::string& command, const std::string& reply, Sink* sink = nullptr) {
    EXPECT_EQ(ask(d, framed(command), sink), framed(reply)) << command;
  };
  expect_reply("VNRRG,01", "VNRRG,01,VN-300T-CR");  // verifySensorConnectivity
  Sink sink;
  expect_reply("VNWRG,05,921600", "VNWRG,05,921600", &sink);
  EXPECT_EQ(sink.baud_after, 921600u) << "after the reply, as libvnc changes its own rate";
  expect_reply("VNRRG,01", "VNRRG,01,VN-300T-CR");
  expect_reply("VNRRG,02", "VNRRG,02,2");
  expect_reply("VNRRG,03", "VNRRG,03,100012345");
  expect_reply("VNRRG,04", "VNRRG,04,2.1.0.0");
  expect_reply("VNWRG,06,0", "VNWRG,06,0");
  expect_reply("VNRRG,35", "VNRRG,35,1,1,1,1");
  expect_reply("VNWRG,35,1,1,1,1", "VNWRG,35,1,1,1,1");
  expect_reply("VNRRG,35", "VNRRG,35,1,1,1,1");
  expect_reply("VNWRG,75,2,1,6,1,C", "VNWRG,75,2,1,06,0001,000C");
  expect_reply("VNWRG,76,2,8,36,1,130,84,613", "VNWRG,76,2,8,36,0001,0130,0084,0613");
  expect_reply("VNWRG,77,2,80,A,1,26B9", "VNWRG,77,2,80,0A,0001,26B9");

  const Split s = run(e, 0, 400, 400);
  EXPECT_TRUE(s.lines.empty());
  std::size_t n1 = 0, n2 = 0, n3 = 0;
  for (const SpecPacket& p : s.packets) {
    const double t = static_cast<double>(p.counter) / 400.0;
    ASSERT_NE(field(p, 1, 0), nullptr) << "every output carries TimeStartup";
    EXPECT_EQ(le<std::uint64_t>(field(p, 1, 0)), p.counter * 2'500'000ULL);
    if (p.groups == 0x06) {
      ++n1;
      EXPECT_NEAR(f3(field(p, 2, 2)).z(), -kG, 1e-5);         // UncompAccel
      EXPECT_NEAR(f3(field(p, 2, 3)).z(), kYawRate, 1e-6);    // UncompGyro
    } else if (p.groups == 0x36) {
      ++n2;
      const std::uint8_t* q = field(p, 4, 2);  // quaternion x, y, z, w
      const double half = std::remainder(kYawRate * t, 2 * kPi) / 2.0;
      const double sgn = std::cos(half) < 0 ? -1.0 : 1.0;
      EXPECT_NEAR(le<float>(q + 8), sgn * std::sin(half), 1e-6);
      EXPECT_NEAR(le<float>(q + 12), sgn * std::cos(half), 1e-6);
      EXPECT_NEAR(f3(field(p, 4, 7)).norm(), 0.0, 1e-3) << "LinearAccelNed: at rest in translation";
      EXPECT_EQ(le<std::uint16_t>(field(p, 5, 0)) & 0x3, 2);
      EXPECT_NEAR(d3(field(p, 5, 1)).x(), kLatDeg, 1e-9);
      EXPECT_NEAR(le<float>(field(p, 2, 5)), 95.461, 0.01);  // pressure kPa
    } else if (p.groups == 0x0A) {
      ++n3;
      EXPECT_EQ(field(p, 3, 4)[0], 3) << "3D fix";
      EXPECT_EQ(field(p, 3, 3)[0], 12) << "satellites";
      EXPECT_NEAR(d3(field(p, 3, 5)).y(), kLonDeg, 1e-9);
      const std::uint8_t* utc = field(p, 3, 0);  // year - 2000, month, day, hour, min, s, ms
      EXPECT_EQ(utc[0], 26);
      EXPECT_EQ(utc[1], 1);
    } else {
      ADD_FAILURE() << "unexpected group byte " << int(p.groups);
    }
  }
  EXPECT_EQ(n1, 400u);  // divisor 1 of 400 Hz
  EXPECT_EQ(n2, 50u);   // 400 / 8
  EXPECT_EQ(n3, 5u);    // 400 / 80
}

// ------------------------------------------------------ ROS 2 (dawonn/vectornav)

// vnproglib 1.2's handling of a reply (dawonn/vectornav ros2 2a2789e,
// vnproglib-1.2.0.0/cpp/src/packet.cpp isValid / isError / isResponse,
// sensors.cpp possiblePacketFoundHandler / transactionWithWait), re-stated:
// an ASCII line is valid when the two hex digits after '*' equal the XOR of
// the bytes between '$' and '*' (four digits: the CRC; "XX": unchecked);
// "$VNERR" ends the transaction with a sensor_error; a line whose
// characters 3..5 are RRG or WRG is the response to whichever command is
// waiting (its register is not compared); the parse takes the comma-
// separated terms from character 7 (the register number, then the values).
struct Ros2VnReply {
  bool valid = false;
  bool error = false;
  bool response = false;
  std::vector<std::string> terms;
};
Ros2VnReply ros2_vnproglib_take(const std::string& line) {
  Ros2VnReply r;
  if (line.size() < 8 || line[0] != '$' || line.compare(line.size() - 2, 2, "\r\n") != 0) return r;
  const std::string packet = line.substr(0, line.size() - 2);
  const std::size_t n = packet.size();
  if (packet[n - 3] != '*') return r;  // the device answers in the 8-bit checksum mode register 30 sets
  const std::string body = packet.substr(1, n - 4);
  r.valid = std::stoul(packet.substr(n - 2), nullptr, 16) == spec_xor(body);
  r.error = packet.compare(3, 3, "ERR") == 0;
  r.response = packet.compare(3, 3, "RRG") == 0 || packet.compare(3, 3, "WRG") == 0;
  std::size_t start = 7;
  for (std::size_t c = 7; c <= n - 3; ++c)
    if (packet[c] == ',' || packet[c] == '*') r.terms.push_back(packet.substr(start, c - start)), start = c + 1;
  return r;
}

struct Ros2VnRun {
  std::vector<std::pair<std::string, std::string>> exchanges;  // (command body, reply line)
  bool configured = false;  // configure_sensor() returned true
  std::string failed_at;    // the command whose sensor_error escaped connect()
  std::string model, firmware, user_tag;
  std::uint32_t hardware = 0, serial = 0;
};

// dawonn/vectornav ros2 2a2789eaf8fb3ec99e5effc0df9c731d7933d74c,
// vectornav/src/vectornav.cc connect() and configure_sensor() with
// config/vectornav.yaml's parameters (baud 115200, AsyncDataOutputType 0,
// AsyncDataOutputFrequency 20, syncInMode 3, serialChecksum 1, errorMode 1,
// BO1 asyncMode 3, rateDivisor 40, commonField 0x7FFF, and the source's
// defaults for the BO1 gpsField (GPSGROUP_FIX | GPSGROUP_POSU = 0x0210) and
// insField (INSGROUP_POSECEF | INSGROUP_VELBODY = 0x000C); BO2 and BO3
// off), each command as vnproglib's Packet::gen* / writeBinaryOutput
// formats it ("$VNRRG,01", "$VNWRG,06,%u", "$VNWRG,07,%u", "$VNWRG,32,%u,
// %u,%u,0,%u,%u,%u,%u,0", "$VNWRG,30,%u,...", "$VNWRG,%u,%u,%u,%X" + ",%X"
// per non-zero group) with the 8-bit checksum (VnSensor's default error
// detection mode) and CR LF.
Ros2VnRun ros2_vectornav_start_up(drivers::vectornav::Encoder& e) {
  drivers::CommandResponder& d = *e.command_responder();
  Ros2VnRun run;
  // One vnproglib transaction: sent, answered by one line, taken or thrown.
  auto transaction = [&](const std::string& body) -> std::optional<Ros2VnReply> {
    const std::string reply = ask(d, framed(body));
    run.exchanges.emplace_back(body, reply);
    const Ros2VnReply r = ros2_vnproglib_take(reply);
    EXPECT_TRUE(r.valid) << body << " -> " << reply;
    EXPECT_TRUE(r.error || r.response) << body << ": vnproglib would wait 1 s, resending every 50 ms, then time out";
    if (r.error) return std::nullopt;  // sensor_error
    return r;
  };
  auto value = [](const std::optional<Ros2VnReply>& r) {
    return r && r->terms.size() > 1 ? r->terms[1] : std::string();
  };
  // connect(): VnSensor::connect(port, 115200) (the requested rate first,
  // then supportedBaudrates() 9600 ... 921600 until verifySensorConnectivity()
  // reads register 1); the loop's read, the read after the loop, the read
  // after the (skipped: same rate) changeBaudRate.
  for (int i = 0; i < 3; ++i)
    if (!transaction("VNRRG,01")) return run;
  run.model = value(transaction("VNRRG,01"));      // readModelNumber
  run.firmware = value(transaction("VNRRG,04"));   // readFirmwareVersion
  run.hardware = static_cast<std::uint32_t>(std::atoi(value(transaction("VNRRG,02")).c_str()));  // ATOU32
  run.serial = static_cast<std::uint32_t>(std::atoi(value(transaction("VNRRG,03")).c_str()));
  run.user_tag = value(transaction("VNRRG,00"));
  // configure_sensor(): a sensor_error here escapes connect() and the node's constructor.
  for (const char* body : {"VNWRG,06,0", "VNWRG,07,20", "VNWRG,32,3,0,0,0,0,0,0,100000000,0", "VNWRG,30,0,0,0,0,1,0,1",
                           "VNWRG,75,3,40,29,7FFF,210,C", "VNWRG,76,0,0,0", "VNWRG,77,0,0,0"}) {
    if (!transaction(body)) {
      run.failed_at = body;
      return run;
    }
  }
  // determineDeviceFamily() reads the model again; not a VN-100: the GNSS
  // reads (55, 57, then for a VN-300 93) in a try block whose sensor_error
  // only logs "GPS initialization error".
  const std::string family = value(transaction("VNRRG,01"));
  if (family.rfind("VN-100", 0) != 0 && transaction("VNRRG,55") && transaction("VNRRG,57") &&
      family.rfind("VN-300", 0) == 0)
    transaction("VNRRG,93");
  run.configured = true;
  return run;
}

TEST(VectorNavDevice, Ros2DriverStartUpOnAVn300GetsEveryReplyAndItsBinaryOutputDecodes) {
  drivers::vectornav::Encoder e(options(drivers::VectorNavModel::vn300, 400));
  const Ros2VnRun r = ros2_vectornav_start_up(e);
  EXPECT_TRUE(r.configured) << r.failed_at;
  EXPECT_EQ(r.model, "VN-300T-CR");
  EXPECT_EQ(r.firmware, "2.1.0.0");
  EXPECT_EQ(r.hardware, 2u);
  EXPECT_EQ(r.serial, 100012345u);
  EXPECT_EQ(r.user_tag, "");
  // The exact replies (the device's formatting of what was written).
  const std::map<std::string, std::string> want{
      {"VNWRG,06,0", "VNWRG,06,0"},
      {"VNWRG,07,20", "VNWRG,07,20"},
      {"VNWRG,32,3,0,0,0,0,0,0,100000000,0", "VNWRG,32,3,0,0,0,0,0,0,100000000,0"},
      {"VNWRG,30,0,0,0,0,1,0,1", "VNWRG,30,0,0,0,0,1,0,1"},
      {"VNWRG,75,3,40,29,7FFF,210,C", "VNWRG,75,3,40,29,7FFF,0210,000C"},
      {"VNWRG,76,0,0,0", "VNWRG,76,0,0,00"},
      {"VNWRG,77,0,0,0", "VNWRG,77,0,0,00"},
      {"VNRRG,55", "VNERR,08"},  // no GNSS configuration register emulated: caught, logged
  };
  for (const auto& [command, reply] : r.exchanges) {
    const auto w = want.find(command);
    if (w != want.end()) {
      EXPECT_EQ(reply, framed(w->second)) << command;
    }
  }
  ASSERT_EQ(r.exchanges.size(), 17u);  // 8 reads, 7 writes, the family read, register 55
  EXPECT_EQ(r.exchanges.back().first, "VNRRG,55");

  // Binary output 1 on both ports, every 40th IMU sample (10 Hz of 400):
  // common 0x7FFF, GNSS1 Fix | PosU, INS PosEcef | VelBody; no ASCII.
  const Split s = run(e, 0, 400, 400);
  EXPECT_TRUE(s.lines.empty());
  ASSERT_EQ(s.packets.size(), 10u);
  for (std::size_t i = 0; i < s.packets.size(); ++i) EXPECT_EQ(s.packets[i].counter, 40u * i);
  const SpecPacket& p = s.packets[0];
  EXPECT_EQ(p.groups, 0x29);
  EXPECT_EQ(p.masks.at(0), 0x7FFF);
  EXPECT_EQ(p.masks.at(3), 0x0210);
  EXPECT_EQ(p.masks.at(5), 0x000C);
  // 1 sync + 1 groups + 3 masks + 198 common + 13 GNSS + 36 INS + 2 CRC.
  EXPECT_EQ(p.bytes.size(), 2u + 6u + 198u + 13u + 36u + 2u);
  EXPECT_EQ(le<std::uint64_t>(field(p, 0, 0)), 0u);                      // TimeStartup
  EXPECT_NEAR(f3(field(p, 0, 3)).x(), yaw_deg_at(0, 400), 1e-4);        // Ypr
  EXPECT_NEAR(le<float>(field(p, 0, 4) + 12), 1.0, 1e-6);                // Quaternion w at yaw 0
  EXPECT_NEAR(f3(field(p, 0, 5)).z(), kYawRate, 1e-6);                   // AngularRate
  EXPECT_NEAR(d3(field(p, 0, 6)).x(), kLatDeg, 1e-9);                    // Position LLA
  EXPECT_NEAR(d3(field(p, 0, 6)).z(), kHeight, 1e-6);
  EXPECT_NEAR(f3(field(p, 0, 8)).z(), -kG, 1e-5);                        // Accel
  EXPECT_NEAR(f3(field(p, 0, 9) + 12).z(), kYawRate, 1e-6);              // Imu: uncompensated gyro
  EXPECT_EQ(le<std::uint16_t>(field(p, 0, 12)) & 0x3, 2);                // InsStatus: tracking
  EXPECT_EQ(field(p, 3, 4)[0], 3);                                       // GNSS1 Fix: 3D
  // INS PosEcef from the manual's WGS-84 (a = 6378137 m, e^2 = 6.69437999014e-3).
  const double lat = kLatDeg * kPi / 180.0, lon = kLonDeg * kPi / 180.0, e2 = 6.69437999014e-3;
  const double n = 6378137.0 / std::sqrt(1.0 - e2 * std::sin(lat) * std::sin(lat));
  const Eigen::Vector3d ecef((n + kHeight) * std::cos(lat) * std::cos(lon), (n + kHeight) * std::cos(lat) * std::sin(lon),
                             (n * (1.0 - e2) + kHeight) * std::sin(lat));
  EXPECT_LT((d3(field(p, 5, 2)) - ecef).norm(), 0.01);
  EXPECT_LT(f3(field(p, 5, 3)).norm(), 1e-3) << "VelBody: at rest in translation";
}

TEST(VectorNavDevice, Ros2DriverDefaultsAskAVn100ForGnssAndInsGroupsWhichItRefuses) {
  // The node's default BO1 carries the GNSS and INS groups, which a VN-100
  // does not have: $VNERR,07 to that write, a sensor_error configure_sensor()
  // does not catch, so the node stops in its constructor. A VN-100 needs
  // BO1.gpsField and BO1.insField set to 0 in the parameters.
  drivers::vectornav::Encoder e(options(drivers::VectorNavModel::vn100, 800));
  const Ros2VnRun r = ros2_vectornav_start_up(e);
  EXPECT_FALSE(r.configured);
  EXPECT_EQ(r.model, "VN-100T-CR");
  EXPECT_EQ(r.failed_at, "VNWRG,75,3,40,29,7FFF,210,C");
  ASSERT_FALSE(r.exchanges.empty());
  EXPECT_EQ(r.exchanges.back().second, framed("VNERR,07"));
  // With those two fields 0, the rest of the sequence is answered.
  drivers::CommandResponder& d = *e.command_responder();
  EXPECT_EQ(ask(d, framed("VNWRG,75,3,40,1,7FFF")), framed("VNWRG,75,3,40,01,7FFF"));
  EXPECT_EQ(ask(d, framed("VNWRG,76,0,0,0")), framed("VNWRG,76,0,0,00"));
  EXPECT_EQ(ask(d, framed("VNWRG,77,0,0,0")), framed("VNWRG,77,0,0,00"));
  const Split s = run(e, 0, 800, 800);
  ASSERT_EQ(s.packets.size(), 20u);  // 800 / 40
  EXPECT_NEAR(f3(field(s.packets[1], 0, 5)).z(), kYawRate, 1e-6);
}

TEST(VectorNavDevice, PortOneOutputsStayOffTheOtherPort) {
  drivers::StreamEncoderOptions o = options(drivers::VectorNavModel::vn100, 800);
  o.vectornav.port = 2;
  drivers::vectornav::Encoder e(o);
  drivers::CommandResponder& d = *e.command_responder();
  ask(d, framed("VNWRG,06,0"));
  ask(d, framed("VNWRG,75,1,16,01,0001"));
  EXPECT_TRUE(run(e, 0, 100, 800).packets.empty());
  ask(d, framed("VNWRG,75,2,16,01,0001"));
  EXPECT_FALSE(run(e, 0, 100, 800).packets.empty());
}

TEST(VectorNavDevice, NonFiniteValuesGoOutClampedAndFlagged) {
  drivers::vectornav::Encoder e(options(drivers::VectorNavModel::vn100, 800));
  drivers::CommandResponder& d = *e.command_responder();
  ask(d, framed("VNWRG,06,14"));
  ask(d, framed("VNWRG,75,1,8,04,0A06"));  // IMU group: UncompMag, UncompAccel, Accel, SensSat
  drivers::ImuFrameInput s = sample_at(0, 800);
  s.accel_m_s2 = Vec3(std::nan(""), 1e300, -std::numeric_limits<double>::infinity());
  Bytes out;
  e.encode(s, out);
  const Split sp = spec_split(out);
  ASSERT_EQ(sp.packets.size(), 1u);
  ASSERT_EQ(sp.lines.size(), 1u);
  const Eigen::Vector3d a = f3(field(sp.packets[0], 2, 2));
  EXPECT_EQ(a.x(), 0.0);
  EXPECT_EQ(a.y(), static_cast<double>(std::numeric_limits<float>::max()));
  EXPECT_EQ(a.z(), -static_cast<double>(std::numeric_limits<float>::max()));
  EXPECT_NE(le<std::uint16_t>(field(sp.packets[0], 2, 11)), 0) << "SensSat flags the saturated axes";
  EXPECT_EQ(sp.lines[0].find("nan"), std::string::npos);
  EXPECT_EQ(sp.lines[0].find("inf"), std::string::npos);
}

TEST(VectorNavDevice, TheDecoderTakesWhatTheEncoderSendsAndCountsCorruption) {
  drivers::vectornav::Encoder e(options(drivers::VectorNavModel::vn100, 800));
  drivers::CommandResponder& d = *e.command_responder();
  ask(d, framed("VNWRG,75,1,8,01,0921"));  // TimeStartup, AngularRate, Accel, DeltaThetaVel
  Bytes stream;
  for (std::uint64_t k = 0; k < 80; ++k) e.encode(sample_at(k, 800), stream);
  stream[40] ^= 0x01;  // inside the first packet
  drivers::vectornav::Decoder dec;
  std::vector<drivers::DecodedSample> got;
  for (std::size_t i = 0; i < stream.size(); i += 7)
    dec.feed(std::span<const std::uint8_t>(stream.data() + i, std::min<std::size_t>(7, stream.size() - i)),
             [&](const drivers::DecodedSample& s) { got.push_back(s); });
  EXPECT_EQ(got.size(), 9u);  // 10 packets, one corrupt
  EXPECT_GE(dec.counters().checksum_errors, 1u);
  EXPECT_EQ(dec.counters().frames, 9u + 4u);  // and 4 VNYMR lines (40 Hz over 0.1 s, from sample 0)
  for (const drivers::DecodedSample& s : got) EXPECT_NEAR(s.gyro_rad_s.z(), kYawRate, 1e-6);
}

}  // namespace
}  // namespace unity_device_test_vectornav_device
