// Issue 29: the emulated Xsens MTi answers its drivers and streams what they
// configure. Every frame, reply and MTData2 layout below is written by hand
// from the "MT Low Level Communication Protocol Documentation" ([L]: a
// message is FA, bus id FF, MID, LEN (FF: two more bytes of extended length,
// big-endian), data, and a checksum making the sum of every byte after FA
// zero modulo 256; MTData2 is a list of (data id u16, size u8, data), big-
// endian, data id bits 1..0 the precision (float32, fp12.20, fp16.32,
// float64), bits 3..2 the frame (ENU, NED, NWU)), not from imuemu's headers:
// the checksum, framer, size table and MTData2 decoder here are the test's own.
//
// The start-up sequences replayed, read from the clients' sources:
//  - ArduPilot/ardupilot 1056c40f8f57ad5fbb5620a7c293318f2b8471ab,
//    libraries/AP_ExternalAHRS/AP_ExternalAHRS_Xsens.cpp (and the .h of
//    3913ba6599922b1cd2ea4733bcdf2a8ae8585410 for the ids):
//    update_state_machine() sends GotoConfig (FA FF 30 00 D1) and waits for
//    GotoConfigAck (0x31); SetOutputConfig (0xC0) of PACKET_COUNTER 0x1020,
//    SAMPLE_TIME_FINE 0x1060, UTC_TIME 0x1010, TEMPERATURE 0x0810,
//    QUATERNION 0x2010, ACCELERATION 0x4020, RATE_OF_TURN 0x8020,
//    MAGNETIC_FIELD 0xC020, STATUS_WORD 0xE020, BAROMETRIC_PRESSURE 0x3010,
//    LAT_LON 0x5042, ALTITUDE_ELLIPSOID 0x5022, VELOCITY_XYZ 0xD012 and
//    GNSSPVTDATA 0x7010, each at EAHRS_RATE (default 50 Hz), and waits for
//    OutputConfig (0xC1); SetAlignmentRotation RotLocal (0x01, q = 0,
//    0x3F3504F4, 0x3F3504F4, 0: ENU to NED) and RotSensor (0x00, q = 0, 1,
//    0, 0 with the sensor facing up), each waiting for 0xED; GotoMeasurement,
//    waiting for 0x11 (any MTData2 also puts it in RUNNING; an Error 0x42
//    puts it in ERROR). Its UART framer reads the one-byte length only; its
//    parse_mtdata2() takes each item only at its documented size.
//  - xsenssupport/Xsens_MTi_ROS_Driver_and_Ntrip_Client
//    e2f611d69b679c47962a10194ebb759cacc95000, the driver's xspublic:
//    xscontroller/devicecommunicator.cpp gotoConfig() (GotoConfig, waits for
//    0x31), getDeviceId() (ReqDID: a 4-byte id, or 8 bytes read as one
//    64-bit id when either half is not a legacy id (bit 31 set); then
//    ReqProductCode, cut at the first space, and ReqHardwareVersion, a
//    u16), serialcommunicator.cpp (ReqFWRev: major, minor, revision, build,
//    svn), xsdevice_def.cpp setOutputConfiguration() (SetOutputConfiguration,
//    the reply's pairs become the device's configuration), gotoMeasurement()
//    (GotoMeasurement, waits for 0x11); src/xdainterface.cpp connectDevice()
//    stops with "No MTi device found" when the scan gets no device id.
//  - The same repository's ROS 2 node (branch ros2 at
//    2022373604d9c4aab4a38743832dbc2e60114078, src/xsens_mti_ros2_driver):
//    connectDevice() and prepare() through its xspublic, message by message
//    (see Ros2NodeStartUp... below), ReqEmts included.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <map>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "drivers/protocols/stream_protocols.hpp"
#include "drivers/protocols/xsens.hpp"
#include "drivers/protocols/xsens_device.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_device_test_xsens_device {
namespace imuemu { using namespace ::imuemu; }

namespace {

using namespace imuemu;
using Bytes = std::vector<std::uint8_t>;

constexpr double kPi = 3.14159265358979323846;
constexpr double kG = 9.80665;
constexpr double kYawRate = 0.5;  // rad/s about NED down

// ------------------------------------------------ the document, independently

std::uint8_t spec_checksum(const Bytes& after_preamble) {
  unsigned s = 0;
  for (const std::uint8_t b : after_preamble) s += b;
  return static_cast<std::uint8_t>((256 - s % 256) % 256);
}

// A host message as [L 2.2] builds it.
Bytes spec_message(std::uint8_t mid, const Bytes& data = {}) {
  Bytes body{0xFF, mid};
  if (data.size() < 255) {
    body.push_back(static_cast<std::uint8_t>(data.size()));
  } else {
    body.push_back(0xFF);
    body.push_back(static_cast<std::uint8_t>(data.size() / 256));
    body.push_back(static_cast<std::uint8_t>(data.size() % 256));
  }
  body.insert(body.end(), data.begin(), data.end());
  Bytes m{0xFA};
  m.insert(m.end(), body.begin(), body.end());
  m.push_back(spec_checksum(body));
  return m;
}

struct SpecMessage {
  std::uint8_t mid = 0;
  Bytes data;
};
// Splits a byte stream into whole messages; `bad` counts bytes that were not
// part of a valid message.
struct Split {
  std::vector<SpecMessage> messages;
  std::size_t bad = 0;
};
Split spec_split(const Bytes& s) {
  Split out;
  std::size_t i = 0;
  while (i < s.size()) {
    if (s[i] != 0xFA || i + 4 > s.size() || s[i + 1] != 0xFF) {
      ++out.bad, ++i;
      continue;
    }
    std::size_t len = s[i + 3], head = 4;
    if (len == 0xFF) {
      if (i + 6 > s.size()) break;
      len = s[i + 4] * 256u + s[i + 5];
      head = 6;
    }
    if (i + head + len + 1 > s.size()) {
      out.bad += s.size() - i;
      break;
    }
    unsigned sum = 0;
    for (std::size_t k = i + 1; k < i + head + len + 1; ++k) sum += s[k];
    if (sum % 256 != 0) {
      ++out.bad, ++i;
      continue;
    }
    out.messages.push_back({s[i + 2], Bytes(s.begin() + static_cast<std::ptrdiff_t>(i + head),
                                            s.begin() + static_cast<std::ptrdiff_t>(i + head + len))});
    i += head + len + 1;
  }
  return out;
}

std::uint32_t be32(const std::uint8_t* p) {
  return (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) | p[3];
}
std::uint16_t be16(const std::uint8_t* p) { return static_cast<std::uint16_t>((p[0] << 8) | p[1]); }
float bef(const std::uint8_t* p) {
  const std::uint32_t u = be32(p);
  float f;
  std::memcpy(&f, &u, 4);
  return f;
}
double bed(const std::uint8_t* p) {
  const std::uint64_t u = (std::uint64_t{be32(p)} << 32) | be32(p + 4);
  double d;
  std::memcpy(&d, &u, 8);
  return d;
}
Bytes be_float(float f) {
  std::uint32_t u;
  std::memcpy(&u, &f, 4);
  return {static_cast<std::uint8_t>(u >> 24), static_cast<std::uint8_t>(u >> 16), static_cast<std::uint8_t>(u >> 8),
          static_cast<std::uint8_t>(u)};
}
// [L] precision of a real value: float32, fp12.20 (int32 / 2^20), fp16.32
// (u32 fraction then i16 integer), float64.
double spec_real(const std::uint8_t* p, unsigned precision) {
  switch (precision) {
    case 0: return bef(p);
    case 1: return static_cast<std::int32_t>(be32(p)) / 1048576.0;
    case 2: return static_cast<std::int16_t>(be16(p + 4)) + be32(p) / 4294967296.0;
    default: return bed(p);
  }
}
std::size_t spec_precision_bytes(unsigned precision) { return precision < 2 ? 4 : precision == 2 ? 6 : 8; }

// [L] the identifiers' value counts (real-valued) or fixed sizes.
std::size_t spec_size(std::uint16_t id) {
  const std::map<std::uint16_t, std::size_t> reals{{0x0810, 1}, {0x2010, 4}, {0x2020, 9}, {0x2030, 3}, {0x4010, 3},
                                                   {0x4020, 3}, {0x4030, 3}, {0x5020, 1}, {0x5040, 2}, {0x8020, 3},
                                                   {0x8030, 4}, {0xC020, 3}, {0xD010, 3}};
  const std::map<std::uint16_t, std::size_t> fixed{{0x1010, 12}, {0x1020, 2}, {0x1060, 4},
                                                   {0x3010, 4},  {0x7010, 94}, {0xE020, 4}};
  const auto base = static_cast<std::uint16_t>(id & 0xFFF0);
  if (const auto r = reals.find(base); r != reals.end()) return r->second * spec_precision_bytes(id & 3);
  if (const auto f = fixed.find(base); f != fixed.end()) return (id & 0xF) == 0 ? f->second : 0;
  return 0;
}

// An MTData2's items by identifier; the sizes checked against [L]'s.
struct SpecItems {
  std::map<std::uint16_t, Bytes> by_id;
  std::vector<std::uint16_t> order;
  bool tiled = true;
  const Bytes& at(std::uint16_t id) const {
    static const Bytes none;
    const auto f = by_id.find(id);
    return f == by_id.end() ? none : f->second;
  }
  std::vector<double> reals(std::uint16_t id) const {
    const Bytes& b = at(id);
    std::vector<double> v;
    const std::size_t w = spec_precision_bytes(id & 3);
    for (std::size_t i = 0; i + w <= b.size(); i += w) v.push_back(spec_real(b.data() + i, id & 3));
    return v;
  }
};
SpecItems spec_items(const Bytes& data) {
  SpecItems out;
  std::size_t i = 0;
  while (i < data.size()) {
    if (i + 3 > data.size()) return out.tiled = false, out;
    const std::uint16_t id = be16(&data[i]);
    const std::size_t n = data[i + 2];
    if (i + 3 + n > data.size() || n != spec_size(id)) return out.tiled = false, out;
    out.by_id[id] = Bytes(data.begin() + static_cast<std::ptrdiff_t>(i + 3),
                          data.begin() + static_cast<std::ptrdiff_t>(i + 3 + n));
    out.order.push_back(id);
    i += 3 + n;
  }
  return out;
}

Bytes config_data(const std::vector<std::pair<std::uint16_t, std::uint16_t>>& items) {
  Bytes d;
  for (const auto& [id, rate] : items)
    for (const std::uint16_t v : {id, rate}) d.push_back(static_cast<std::uint8_t>(v >> 8)), d.push_back(static_cast<std::uint8_t>(v));
  return d;
}

// ------------------------------------------------ the device under test

struct Sink final : drivers::ReplySink {
  Bytes bytes;
  std::optional<std::uint32_t> baud_after;
  bool reply(std::span<const std::uint8_t> b) override {
    bytes.insert(bytes.end(), b.begin(), b.end());
    return true;
  }
  void change_baud_after_replies(std::uint32_t baud) override { baud_after = baud; }
};

drivers::StreamEncoderOptions options(drivers::XsensModel model, double rate_hz = 400.0) {
  drivers::StreamEncoderOptions o;
  o.nominal_sample_rate_hz = rate_hz;
  o.xsens.model = model;
  return o;
}

// A level body turning at kYawRate about down, over Barcelona at 500 m.
drivers::ImuFrameInput sample_at(std::uint64_t k, double rate_hz = 400.0) {
  drivers::ImuFrameInput s;
  s.sample_counter = k;
  s.period_ns = static_cast<TimeNs>(std::llround(1e9 / rate_hz));
  s.t_ns = static_cast<TimeNs>(k) * s.period_ns;
  const double t = static_cast<double>(s.t_ns) * 1e-9;
  s.gyro_rad_s = Vec3(0, 0, kYawRate);
  s.accel_m_s2 = Vec3(0, 0, -kG);
  s.delta_theta_rad = s.gyro_rad_s / rate_hz;
  s.delta_velocity_m_s = s.accel_m_s2 / rate_hz;
  const double yaw = kYawRate * t;
  s.sensor_to_ned = (Mat3() << std::cos(yaw), -std::sin(yaw), 0, std::sin(yaw), std::cos(yaw), 0, 0, 0, 1).finished();
  s.has_navigation = true;
  s.latitude_rad = 41.4 * kPi / 180;
  s.longitude_rad = 2.17 * kPi / 180;
  s.height_m = 500.0;
  s.velocity_ned_m_s = Vec3(1.0, 2.0, -0.5);
  return s;
}

// The replies to one host message, split.
std::vector<SpecMessage> ask(drivers::CommandResponder& d, const Bytes& message, Sink* sink_out = nullptr) {
  Sink sink;
  d.on_input(message, sink);
  if (sink_out != nullptr) *sink_out = sink;
  const Split s = spec_split(sink.bytes);
  EXPECT_EQ(s.bad, 0u);
  return s.messages;
}

// Samples [first, first + n): the messages they sent, every byte in one.
std::vector<SpecMessage> run(drivers::xsens::Encoder& e, std::uint64_t first, std::uint64_t n, double rate_hz = 400.0) {
  std::vector<SpecMessage> all;
  for (std::uint64_t k = first; k < first + n; ++k) {
    Bytes out;
    e.encode(sample_at(k, rate_hz), out);
    const Split s = spec_split(out);
    EXPECT_EQ(s.bad, 0u) << "sample " << k;
    all.insert(all.end(), s.messages.begin(), s.messages.end());
  }
  return all;
}

// ------------------------------------------------ framing and golden bytes

TEST(XsensDevice, FramesMatchTheDocumentsExamplesChecksumIncluded) {
  // [L] "GotoConfig: FA FF 30 00 D1", "GotoMeasurement: FA FF 10 00 F1", "ReqDID: FA FF 00 00 01".
  EXPECT_EQ(drivers::xsens::message(0x30), (Bytes{0xFA, 0xFF, 0x30, 0x00, 0xD1}));
  EXPECT_EQ(drivers::xsens::message(0x10), (Bytes{0xFA, 0xFF, 0x10, 0x00, 0xF1}));
  EXPECT_EQ(drivers::xsens::message(0x00), (Bytes{0xFA, 0xFF, 0x00, 0x00, 0x01}));
  EXPECT_EQ(spec_message(0x30), (Bytes{0xFA, 0xFF, 0x30, 0x00, 0xD1}));
  // Extended length: 300 bytes of data -> FF 01 2C.
  const Bytes big(300, 0xA5);
  const Bytes m = drivers::xsens::message(0x36, big);
  ASSERT_EQ(m.size(), 300u + 7u);
  EXPECT_EQ(m[3], 0xFF);
  EXPECT_EQ(m[4], 0x01);
  EXPECT_EQ(m[5], 0x2C);
  EXPECT_EQ(m, spec_message(0x36, big));
  // The device answers: GotoConfigAck FA FF 31 00 D0, GotoMeasurementAck FA FF 11 00 F0.
  drivers::xsens::Encoder e(options(drivers::XsensModel::mti630));
  Sink sink;
  e.command_responder()->on_input(Bytes{0xFA, 0xFF, 0x30, 0x00, 0xD1}, sink);
  EXPECT_EQ(sink.bytes, (Bytes{0xFA, 0xFF, 0x31, 0x00, 0xD0}));
  sink.bytes.clear();
  e.command_responder()->on_input(Bytes{0xFA, 0xFF, 0x10, 0x00, 0xF1}, sink);
  EXPECT_EQ(sink.bytes, (Bytes{0xFA, 0xFF, 0x11, 0x00, 0xF0}));
}

TEST(XsensDevice, AHandBuiltMtData2MatchesTheEncodersBytes) {
  drivers::xsens::Encoder e(options(drivers::XsensModel::mti630));
  drivers::CommandResponder& d = *e.command_responder();
  ask(d, spec_message(0x30));
  ask(d, spec_message(0xC0, config_data({{0x1020, 0xFFFF}, {0x1060, 0xFFFF}, {0x4020, 400}})));
  ask(d, spec_message(0x10));
  drivers::ImuFrameInput s = sample_at(3);
  s.sensor_to_ned = Mat3::Identity();
  Bytes out;
  e.encode(s, out);
  // PacketCounter 0; SampleTimeFine 3 samples of 2.5 ms = 75 ticks of 100 us;
  // Acceleration (0, 0, +g) in the sensor frame (z up) as float32.
  Bytes expected{0xFA, 0xFF, 0x36, 0x1B, 0x10, 0x20, 0x02, 0x00, 0x00, 0x10, 0x60, 0x04, 0x00, 0x00,
                 0x00, 0x4B, 0x40, 0x20, 0x0C, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00};
  const Bytes g = be_float(static_cast<float>(kG));
  EXPECT_EQ(g, (Bytes{0x41, 0x1C, 0xE8, 0x0A}));
  expected.insert(expected.end(), g.begin(), g.end());
  expected.push_back(0x04);  // 256 - (sum of FF .. 0A) mod 256, by hand
  EXPECT_EQ(out, expected);
  EXPECT_EQ(spec_checksum(Bytes(expected.begin() + 1, expected.end() - 1)), 0x04);
}

TEST(XsensDevice, MessagesSplitAcrossReadsAndGarbageAroundThemAreFound) {
  drivers::xsens::Encoder e(options(drivers::XsensModel::mti630));
  drivers::CommandResponder& d = *e.command_responder();
  Bytes stream{0x00, 0xFA, 0x13, 0xFA, 0xFF, 0x30, 0x00, 0x00};  // garbage, a bad checksum
  const Bytes a = spec_message(0x30), b = spec_message(0x00);
  stream.insert(stream.end(), a.begin(), a.end());
  stream.insert(stream.end(), b.begin(), b.end());
  Sink sink;
  for (const std::uint8_t byte : stream) d.on_input(Bytes{byte}, sink);
  const Split s = spec_split(sink.bytes);
  ASSERT_EQ(s.messages.size(), 2u);
  EXPECT_EQ(s.messages[0].mid, 0x31);
  EXPECT_EQ(s.messages[1].mid, 0x01);
  EXPECT_EQ(d.command_counters().received, 2u);
  EXPECT_GT(d.command_counters().not_command_bytes, 0u);
}

// ------------------------------------------------ commands

TEST(XsensDevice, IdentityRequestsAnswerTheModelsPresets) {
  struct Case {
    drivers::XsensModel model;
    Bytes did;
    std::string product;
    Bytes fw_head;
  };
  const std::vector<Case> cases{
      {drivers::XsensModel::mti630, {0x00, 0x00, 0x00, 0x00, 0x80, 0x00, 0x1A, 0x2D}, "MTi-630-8A1G6", {1, 12, 0}},
      {drivers::XsensModel::mti680g, {0x00, 0x00, 0x00, 0x00, 0x80, 0x00, 0x1A, 0x2E}, "MTi-680G-8A1G6", {1, 12, 0}},
      {drivers::XsensModel::mti3, {0x03, 0x80, 0x1A, 0x2B}, "MTi-3-8A7G6", {1, 10, 2}},
      {drivers::XsensModel::mti_g710, {0x07, 0x70, 0x1A, 0x2F}, "MTi-G-710-2A8G4", {1, 9, 2}},
  };
  for (const Case& c : cases) {
    drivers::xsens::Encoder e(options(c.model));
    drivers::CommandResponder& d = *e.command_responder();
    auto r = ask(d, spec_message(0x00));
    ASSERT_EQ(r.size(), 1u);
    EXPECT_EQ(r[0].mid, 0x01);
    EXPECT_EQ(r[0].data, c.did);
    r = ask(d, spec_message(0x1C));
    ASSERT_EQ(r.size(), 1u);
    EXPECT_EQ(r[0].mid, 0x1D);
    std::string padded = c.product;
    padded.resize(20, ' ');
    EXPECT_EQ(std::string(r[0].data.begin(), r[0].data.end()), padded) << "[L] 20 characters, space-padded";
    r = ask(d, spec_message(0x12));
    ASSERT_EQ(r.size(), 1u);
    EXPECT_EQ(r[0].mid, 0x13);
    ASSERT_EQ(r[0].data.size(), 11u) << "major, minor, revision, build u32, svn u32";
    EXPECT_EQ(Bytes(r[0].data.begin(), r[0].data.begin() + 3), c.fw_head);
    r = ask(d, spec_message(0x1E));
    ASSERT_EQ(r.size(), 1u);
    EXPECT_EQ(r[0].mid, 0x1F);
    EXPECT_EQ(r[0].data.size(), 2u);
  }
}

TEST(XsensDevice, ConfiguredIdentityIsReportedAndBadIdentitiesAreRefusedUpFront) {
  drivers::StreamEncoderOptions o = options(drivers::XsensModel::mti3);
  o.xsens.device_id = 0x03805555;
  o.xsens.product_code = "MTi-3-8A7G6-X";
  o.xsens.firmware_version = "1.8.4";
  o.xsens.firmware_build = 7;
  o.xsens.firmware_svn = 99;
  const auto e = drivers::make_stream_encoder("xsens", o);
  drivers::CommandResponder& d = *e->command_responder();
  EXPECT_EQ(ask(d, spec_message(0x00)).at(0).data, (Bytes{0x03, 0x80, 0x55, 0x55}));
  const Bytes pc = ask(d, spec_message(0x1C)).at(0).data;
  EXPECT_EQ(std::string(pc.begin(), pc.begin() + 13), "MTi-3-8A7G6-X");
  EXPECT_EQ(ask(d, spec_message(0x12)).at(0).data, (Bytes{1, 8, 4, 0, 0, 0, 7, 0, 0, 0, 99}));
  for (const auto& bad : std::vector<std::pair<std::string, std::string>>{
           {"product_code", "MTi 3"}, {"product_code", "MTi-3-8A7G6-0123456789"}, {"firmware_version", "1.8"},
           {"firmware_version", "1.8.400"}}) {
    drivers::StreamEncoderOptions b = options(drivers::XsensModel::mti3);
    (bad.first == "product_code" ? b.xsens.product_code : b.xsens.firmware_version) = bad.second;
    EXPECT_THROW((void)drivers::make_stream_encoder("xsens", b), std::invalid_argument) << bad.second;
  }
  drivers::StreamEncoderOptions b = options(drivers::XsensModel::mti3);
  b.xsens.baud = 12345;
  EXPECT_THROW((void)drivers::make_stream_encoder("xsens", b), std::invalid_argument);
}

TEST(XsensDevice, ConfigOnlyCommandsInMeasurementAndUnknownMessagesAreRefusedAndChangeNothing) {
  drivers::xsens::Encoder e(options(drivers::XsensModel::mti630));
  drivers::CommandResponder& d = *e.command_responder();
  const Bytes before = run(e, 0, 4).at(0).data;
  // Measurement state: SetOutputConfiguration -> Error 0x04 ([L] "invalid message").
  auto r = ask(d, spec_message(0xC0, config_data({{0x2030, 100}})));
  ASSERT_EQ(r.size(), 1u);
  EXPECT_EQ(r[0].mid, 0x42);
  EXPECT_EQ(r[0].data, (Bytes{0x04}));
  EXPECT_EQ(d.command_counters().nacked, 1u);
  // An unknown message (0x7E ReqErrorReport is not answered) -> 0x04.
  ask(d, spec_message(0x30));
  r = ask(d, spec_message(0x7E));
  ASSERT_EQ(r.size(), 1u);
  EXPECT_EQ(r[0].mid, 0x42);
  EXPECT_EQ(r[0].data, (Bytes{0x04}));
  // A bad baud code -> 0x20; a bad alignment parameter / not unit quaternion -> 0x21;
  // an output identifier with an undefined frame -> 0x21.
  r = ask(d, spec_message(0x18, {0x55}));
  EXPECT_EQ(r.at(0).data, (Bytes{0x20}));
  Bytes align{0x02};
  for (const float f : {1.0f, 0.0f, 0.0f, 0.0f}) {
    const Bytes b = be_float(f);
    align.insert(align.end(), b.begin(), b.end());
  }
  r = ask(d, spec_message(0xEC, align));
  EXPECT_EQ(r.at(0).data, (Bytes{0x21}));
  align[0] = 0x00;
  align[1] = 0x40;  // w = 2
  r = ask(d, spec_message(0xEC, align));
  EXPECT_EQ(r.at(0).data, (Bytes{0x21}));
  r = ask(d, spec_message(0xC0, config_data({{0x4020, 100}, {0x402C, 100}})));
  EXPECT_EQ(r.at(0).data, (Bytes{0x21}));
  // Nothing changed: the default configuration streams as before.
  r = ask(d, spec_message(0xC0));
  ASSERT_EQ(r.size(), 1u);
  EXPECT_EQ(r[0].mid, 0xC1);
  EXPECT_EQ(r[0].data, config_data({{0x1020, 0xFFFF}, {0x1060, 0xFFFF}, {0x2010, 100}, {0x4020, 100}, {0x8020, 100},
                                    {0xC020, 100}, {0xE020, 100}}));
  r = ask(d, spec_message(0x18));
  EXPECT_EQ(r.at(0).data, (Bytes{0x02})) << "115200";
  ask(d, spec_message(0x10));
  const std::vector<SpecMessage> after = run(e, 4, 4);
  ASSERT_EQ(after.size(), 1u);
  EXPECT_EQ(spec_items(after[0].data).order, spec_items(before).order);
}

TEST(XsensDevice, OutputConfigurationAppliesDivisorRatesAndTheModelsOutputs) {
  drivers::xsens::Encoder e(options(drivers::XsensModel::mti630));
  drivers::CommandResponder& d = *e.command_responder();
  ask(d, spec_message(0x30));
  // 150 Hz -> 100 (400 / 4; 133.3 is no integer rate), 400 stays, 0xFFFF stays,
  // PacketCounter's rate -> 0xFFFF, LatLon dropped (an MTi-630 has no GNSS).
  auto r = ask(d, spec_message(0xC0, config_data({{0x1020, 10}, {0x2030, 150}, {0x8020, 400}, {0x4020, 0xFFFF}, {0x5042, 100}})));
  ASSERT_EQ(r.size(), 1u);
  EXPECT_EQ(r[0].mid, 0xC1);
  EXPECT_EQ(r[0].data, config_data({{0x1020, 0xFFFF}, {0x2030, 100}, {0x8020, 400}, {0x4020, 0xFFFF}}));
  // Config state streams nothing.
  EXPECT_TRUE(run(e, 0, 8).empty());
  ask(d, spec_message(0x10));
  // Measurement: a packet per 400 Hz sample; Euler angles in every 4th.
  const std::vector<SpecMessage> m = run(e, 8, 40);
  ASSERT_EQ(m.size(), 40u);
  int euler = 0;
  for (std::size_t i = 0; i < m.size(); ++i) {
    const SpecItems items = spec_items(m[i].data);
    ASSERT_TRUE(items.tiled);
    EXPECT_EQ(be16(items.at(0x1020).data()), i) << "PacketCounter counts packets";
    euler += items.by_id.count(0x2030) != 0 ? 1 : 0;
  }
  EXPECT_EQ(euler, 10);
}

TEST(XsensDevice, ConfiguredTrafficCountsThePacketsOfTheOutputConfiguration) {
  drivers::xsens::Encoder e(options(drivers::XsensModel::mti630));
  drivers::CommandResponder& d = *e.command_responder();
  // One second of the 400 Hz scene on the wire.
  auto wire_bytes = [&](std::uint64_t first) {
    Bytes out;
    for (std::uint64_t k = first; k < first + 400; ++k) e.encode(sample_at(k), out);
    return static_cast<double>(out.size());
  };
  // Power-up (docs/xsens-device.md): PacketCounter (2) and SampleTimeFine
  // (4) in every packet, Quaternion (16), Acceleration, RateOfTurn,
  // MagneticField (12 each) and StatusWord (4) at 100 Hz: 7 x (id 2 + size
  // 1) + 62 bytes of data, and preamble, bus id, MID, length, checksum.
  const double factory_packet = 7 * 3 + (2 + 4 + 16 + 12 + 12 + 12 + 4) + 5;
  EXPECT_DOUBLE_EQ(e.configured_bytes_per_second(400.0), factory_packet * 100);
  EXPECT_EQ(wire_bytes(0), factory_packet * 100);
  // Acceleration at 100 Hz and RateOfTurn at 40 Hz with PacketCounter: a
  // packet on every 4th sample and every 10th, both on every 20th (20 Hz):
  // 80 with Acceleration alone, 20 with RateOfTurn alone, 20 with both.
  ask(d, spec_message(0x30));
  ask(d, spec_message(0xC0, config_data({{0x1020, 0xFFFF}, {0x4020, 100}, {0x8020, 40}})));
  EXPECT_DOUBLE_EQ(e.configured_bytes_per_second(400.0), 0.0);  // config state: nothing
  ask(d, spec_message(0x10));
  const double one = 2 * 3 + 2 + 12 + 5, both = 3 * 3 + 2 + 12 + 12 + 5;
  EXPECT_DOUBLE_EQ(e.configured_bytes_per_second(400.0), 80 * one + 20 * one + 20 * both);
  EXPECT_EQ(wire_bytes(400), 80 * one + 20 * one + 20 * both);
}

TEST(XsensDevice, FramesAndPrecisionsFollowTheIdentifiersFormatBits) {
  drivers::xsens::Encoder e(options(drivers::XsensModel::mti680g));
  drivers::CommandResponder& d = *e.command_responder();
  ask(d, spec_message(0x30));
  ask(d, spec_message(0xC0, config_data({{0x2010, 400}, {0x2014, 400}, {0x2033, 400}, {0x2037, 400}, {0x2027, 400},
                                         {0x8021, 400}, {0x4022, 400}, {0x5043, 400}, {0x5022, 400}, {0xD013, 400},
                                         {0xD017, 400}, {0x4033, 400}, {0x3010, 400}})));
  ask(d, spec_message(0x10));
  const std::uint64_t k = 800;  // 2 s: yaw 1 rad (NED)
  const std::vector<SpecMessage> m = run(e, k, 1);
  ASSERT_EQ(m.size(), 1u);
  const SpecItems it = spec_items(m[0].data);
  ASSERT_TRUE(it.tiled);
  const double psi = kYawRate * 2.0;
  // ENU quaternion of the sensor (x forward, z up): yaw about up of pi/2 - psi.
  const std::vector<double> q_enu = it.reals(0x2010);
  EXPECT_NEAR(q_enu[0], std::cos((kPi / 2 - psi) / 2), 1e-6);
  EXPECT_NEAR(q_enu[3], std::sin((kPi / 2 - psi) / 2), 1e-6);
  // NED (bits 0x4): the same sensor axes to NED: x forward, y left, z up =
  // FRD rotated by pi about x. Check through the Euler angles in float64:
  // roll 180, pitch 0, yaw psi.
  const std::vector<double> eul_ned = it.reals(0x2037);
  EXPECT_NEAR(std::fabs(eul_ned[0]), 180.0, 1e-9);
  EXPECT_NEAR(eul_ned[1], 0.0, 1e-9);
  EXPECT_NEAR(eul_ned[2], psi * 180 / kPi, 1e-9);
  const std::vector<double> eul_enu = it.reals(0x2033);
  EXPECT_NEAR(eul_enu[0], 0.0, 1e-9);
  EXPECT_NEAR(eul_enu[2], 90.0 - psi * 180 / kPi, 1e-9);
  // The NED quaternion's rotation of x (forward) has north cos psi, east sin psi.
  const std::vector<double> q_ned = it.reals(0x2014);
  const double w = q_ned[0], x = q_ned[1], y = q_ned[2], z = q_ned[3];
  EXPECT_NEAR(1 - 2 * (y * y + z * z), std::cos(psi), 1e-6);
  EXPECT_NEAR(2 * (x * y + w * z), std::sin(psi), 1e-6);
  // Rotation matrix (NED, float64), column by column: first column = x_S in NED.
  const std::vector<double> r = it.reals(0x2027);
  ASSERT_EQ(r.size(), 9u);
  EXPECT_NEAR(r[0], std::cos(psi), 1e-12);
  EXPECT_NEAR(r[1], std::sin(psi), 1e-12);
  EXPECT_NEAR(r[8], -1.0, 1e-12) << "z_S (up) is -down";
  // Rate of turn in fp12.20: z up = -yaw rate about down.
  const std::vector<double> gyr = it.reals(0x8021);
  EXPECT_NEAR(gyr[2], -kYawRate, 1.0 / 1048576);
  // Acceleration fp16.32: +g on z.
  EXPECT_NEAR(it.reals(0x4022)[2], kG, 1e-9);
  // Position float64 / fp16.32, velocity ENU / NED.
  EXPECT_NEAR(it.reals(0x5043)[0], 41.4, 1e-12);
  EXPECT_NEAR(it.reals(0x5043)[1], 2.17, 1e-12);
  EXPECT_NEAR(it.reals(0x5022)[0], 500.0, 1e-9);
  const std::vector<double> v_enu = it.reals(0xD013), v_ned = it.reals(0xD017);
  EXPECT_NEAR(v_enu[0], 2.0, 1e-12);
  EXPECT_NEAR(v_enu[1], 1.0, 1e-12);
  EXPECT_NEAR(v_enu[2], 0.5, 1e-12);
  EXPECT_NEAR(v_ned[0], 1.0, 1e-12);
  EXPECT_NEAR(v_ned[2], -0.5, 1e-12);
  // Free acceleration (gravity removed) of a body at rest in its turn: ~0
  // (the normal gravity at 41.4 deg, 500 m differs from g0 by a few mm/s^2).
  for (const double a : it.reals(0x4033)) EXPECT_NEAR(a, 0.0, 0.02);
  // ISA pressure at 500 m.
  EXPECT_NEAR(static_cast<double>(be32(it.at(0x3010).data())), 95461.0, 10.0);
}

TEST(XsensDevice, SaturatedAndNonFiniteValuesGoOutClampedAndFlagged) {
  drivers::xsens::Encoder e(options(drivers::XsensModel::mti630));
  drivers::CommandResponder& d = *e.command_responder();
  ask(d, spec_message(0x30));
  ask(d, spec_message(0xC0, config_data({{0x4021, 400}, {0x8020, 400}, {0x4022, 400}, {0xE020, 400}})));
  ask(d, spec_message(0x10));
  drivers::ImuFrameInput s = sample_at(0);
  s.accel_m_s2 = Vec3(5000.0, -1e6, std::numeric_limits<double>::quiet_NaN());
  s.gyro_rad_s = Vec3(std::numeric_limits<double>::infinity(), 1.0, 2.0);
  Bytes out;
  e.encode(s, out);
  const Split sp = spec_split(out);
  ASSERT_EQ(sp.messages.size(), 1u);
  const SpecItems it = spec_items(sp.messages[0].data);
  ASSERT_TRUE(it.tiled);
  const std::vector<double> acc1220 = it.reals(0x4021);
  EXPECT_NEAR(acc1220[0], 2048.0, 1e-5) << "fp12.20 saturates at 2^11";
  EXPECT_NEAR(acc1220[1], 2048.0, 1e-5) << "y_S = -y_B = +1e6 saturates";
  EXPECT_EQ(acc1220[2], 0.0) << "NaN goes out as 0";
  const std::vector<double> gyr = it.reals(0x8020);
  EXPECT_EQ(gyr[0], static_cast<double>(std::numeric_limits<float>::max()));
  EXPECT_TRUE(std::isfinite(gyr[0]));
  EXPECT_NEAR(gyr[1], -1.0, 1e-7);
  const std::vector<double> acc1632 = it.reals(0x4022);
  EXPECT_NEAR(acc1632[0], 5000.0, 1e-9) << "fp16.32 holds 5000";
  EXPECT_NEAR(acc1632[1], 32768.0, 1e-6) << "fp16.32 saturates at 2^15";
  const std::uint32_t status = be32(it.at(0xE020).data());
  EXPECT_NE(status & (1u << 19), 0u) << "clipping indication";
  EXPECT_EQ(status & (7u << 8), 7u << 8) << "accelerometer x, y, z clipped";
  EXPECT_NE(status & (1u << 11), 0u) << "gyroscope x clipped";
  EXPECT_NE(status & 0x3u, 0u) << "self test and filter valid";
}

TEST(XsensDevice, EveryPrecisionRoundTripsOverItsRange) {
  drivers::xsens::Encoder e(options(drivers::XsensModel::mti630));
  drivers::CommandResponder& d = *e.command_responder();
  ask(d, spec_message(0x30));
  ask(d, spec_message(0xC0, config_data({{0x4020, 400}, {0x4021, 400}, {0x4022, 400}, {0x4023, 400}, {0xE020, 400}})));
  ask(d, spec_message(0x10));
  std::uint64_t k = 0;
  // Values across each format's range (fp12.20: +-2048, fp16.32: +-32768).
  for (double v = -32767.0; v <= 32767.0; v += 1234.5678) {
    drivers::ImuFrameInput s = sample_at(k++);
    s.accel_m_s2 = Vec3(v / 16.0 + 1e-7, -v / 16.0, -v);  // S: (v/16, v/16, v)
    Bytes out;
    e.encode(s, out);
    const Split sp = spec_split(out);
    ASSERT_EQ(sp.messages.size(), 1u);
    const SpecItems it = spec_items(sp.messages[0].data);
    ASSERT_TRUE(it.tiled);
    const Vec3 want(v / 16.0 + 1e-7, v / 16.0, v);
    for (int i = 0; i < 3; ++i) {
      EXPECT_NEAR(it.reals(0x4020)[i], want[i], std::fabs(want[i]) * 6e-8 + 1e-12) << "float32";
      if (std::fabs(want[i]) < 2048.0) {
        EXPECT_NEAR(it.reals(0x4021)[i], want[i], 0.5 / 1048576 + 1e-12) << "fp12.20";
      } else {
        EXPECT_EQ(std::fabs(it.reals(0x4021)[i]), std::copysign(2048.0 - 1.0 / 1048576, 1.0) + (want[i] < 0 ? 1.0 / 1048576 : 0.0))
            << "fp12.20 clamped to int32's range";
      }
      EXPECT_NEAR(it.reals(0x4022)[i], want[i], 0.5 / 4294967296.0 + 1e-12) << "fp16.32";
      EXPECT_EQ(it.reals(0x4023)[i], want[i]) << "float64";
    }
    // Only fp12.20's z beyond 2048 clips: the clipping bits say so.
    const std::uint32_t status = be32(it.at(0xE020).data());
    EXPECT_EQ((status >> 19) & 1u, std::fabs(v) > 2048.0 ? 1u : 0u) << v;
  }
  EXPECT_GT(k, 50u);
}

TEST(XsensDevice, ResetAcknowledgesThenWakesUpMeasuringWithTheKeptSettingsAndNewBaud) {
  drivers::xsens::Encoder e(options(drivers::XsensModel::mti630));
  drivers::CommandResponder& d = *e.command_responder();
  ask(d, spec_message(0x30));
  ask(d, spec_message(0xC0, config_data({{0x1020, 0xFFFF}, {0x8020, 200}})));
  auto r = ask(d, spec_message(0x18, {0x00}));  // 460800
  EXPECT_EQ(r.at(0).mid, 0x19);
  Sink sink;
  r = ask(d, spec_message(0x40), &sink);
  ASSERT_EQ(r.size(), 2u);
  EXPECT_EQ(r[0].mid, 0x41);
  EXPECT_EQ(r[1].mid, 0x3E) << "WakeUp after ResetAck";
  EXPECT_EQ(sink.baud_after, 460800u);
  const std::vector<SpecMessage> m = run(e, 0, 4);
  ASSERT_EQ(m.size(), 2u) << "RateOfTurn at 200 Hz of a 400 Hz scene";
  EXPECT_EQ(spec_items(m[0].data).order, (std::vector<std::uint16_t>{0x1020, 0x8020}));
  // WakeUpAck: config state, nothing streamed.
  ask(d, spec_message(0x3F));
  EXPECT_TRUE(run(e, 4, 4).empty());
  // A power cycle: WakeUp on the stream, then measurement with the kept settings.
  Bytes out;
  e.restart(sample_at(8).t_ns, out);
  EXPECT_EQ(out, (Bytes{0xFA, 0xFF, 0x3E, 0x00, 0xC3}));
  const std::vector<SpecMessage> after = run(e, 8, 4);
  ASSERT_EQ(after.size(), 2u);
  EXPECT_EQ(spec_items(after[0].data).order, (std::vector<std::uint16_t>{0x1020, 0x8020}));
  EXPECT_EQ(be16(spec_items(after[0].data).at(0x1020).data()), 0u) << "the counter restarts";
}

TEST(XsensDevice, DeltaQAndDeltaVSumTheIncrementsSinceTheirLastPacket) {
  drivers::xsens::Encoder e(options(drivers::XsensModel::mti630));
  drivers::CommandResponder& d = *e.command_responder();
  ask(d, spec_message(0x30));
  ask(d, spec_message(0xC0, config_data({{0x8033, 100}, {0x4013, 100}})));
  ask(d, spec_message(0x10));
  const std::vector<SpecMessage> m = run(e, 0, 8);
  ASSERT_EQ(m.size(), 2u);
  const SpecItems second = spec_items(m[1].data);
  const std::vector<double> dq = second.reals(0x8033), dv = second.reals(0x4013);
  // Four samples of 2.5 ms: 0.005 rad about down = -z_S; dv 4 * g / 400 on +z_S.
  EXPECT_NEAR(dq[0], std::cos(0.005 / 2), 1e-12);
  EXPECT_NEAR(dq[3], -std::sin(0.005 / 2), 1e-12);
  EXPECT_NEAR(dv[2], kG / 100, 1e-12);
}

TEST(XsensDevice, TheDecoderTakesWhatTheEncoderSendsAndCountsCorruption) {
  drivers::xsens::Encoder e(options(drivers::XsensModel::mti630));
  Bytes stream;
  for (std::uint64_t k = 0; k < 40; ++k) e.encode(sample_at(k), stream);
  drivers::xsens::Decoder dec;
  std::vector<drivers::DecodedSample> got;
  dec.feed(stream, [&](const drivers::DecodedSample& s) { got.push_back(s); });
  ASSERT_EQ(got.size(), 10u) << "the default 100 Hz of a 400 Hz scene";
  EXPECT_EQ(dec.counters().checksum_errors, 0u);
  EXPECT_NEAR(got[3].gyro_rad_s.z(), kYawRate, 1e-6) << "body FRD";
  EXPECT_NEAR(got[3].accel_m_s2.z(), -kG, 1e-5);
  EXPECT_EQ(got[3].sequence, 3u);
  EXPECT_EQ(got[3].t_ns, 12 * 2'500'000);
  // Corrupt the fifth packet (each 88 bytes: 83 of items, 5 of frame).
  ASSERT_EQ(stream.size(), 10u * 88u);
  Bytes bad = stream;
  bad[4 * 88 + 10] ^= 0x40;
  drivers::xsens::Decoder dec2;
  std::size_t n = 0;
  dec2.feed(bad, [&](const drivers::DecodedSample&) { ++n; });
  EXPECT_EQ(n, 9u);
  EXPECT_EQ(dec2.counters().checksum_errors, 1u);
  EXPECT_EQ(dec2.counters().sequence_gaps, 1u);
}

// ------------------------------------------------ the clients' start-up

// ArduPilot (1056c40f) re-stated: the state machine's waits and its UART framer.
TEST(XsensDevice, ArduPilotStartUpGetsEveryAckThenParsesEveryItemItAsksFor) {
  drivers::xsens::Encoder e(options(drivers::XsensModel::mti680g));
  drivers::CommandResponder& d = *e.command_responder();
  // ENTERING_CONFIG_MODE: FA FF 30 00 D1; WAITING_FOR_CONFIG_MODE until 0x31.
  auto r = ask(d, Bytes{0xFA, 0xFF, 0x30, 0x00, 0xD1});
  ASSERT_EQ(r.size(), 1u);
  EXPECT_EQ(r[0].mid, 0x31);
  // CONFIGURING_OUTPUT: the 14 items at EAHRS_RATE 50.
  const std::vector<std::uint16_t> ids{0x1020, 0x1060, 0x1010, 0x0810, 0x2010, 0x4020, 0x8020,
                                       0xC020, 0xE020, 0x3010, 0x5042, 0x5022, 0xD012, 0x7010};
  std::vector<std::pair<std::uint16_t, std::uint16_t>> cfg;
  for (const std::uint16_t id : ids) cfg.emplace_back(id, 50);
  const Bytes set_output = spec_message(0xC0, config_data(cfg));
  ASSERT_EQ(set_output.size(), 5u + 56u);
  r = ask(d, set_output);
  ASSERT_EQ(r.size(), 1u);
  EXPECT_EQ(r[0].mid, 0xC1) << "OutputConfig moves it on";
  // CONFIGURING_ROTLOCAL / ROTSENSOR: each waits for 0xED.
  const Bytes rot_local{0xFA, 0xFF, 0xEC, 0x11, 0x01, 0x00, 0x00, 0x00, 0x00, 0x3F, 0x35, 0x04, 0xF4,
                        0x3F, 0x35, 0x04, 0xF4, 0x00, 0x00, 0x00, 0x00};
  Bytes with_sum = rot_local;
  with_sum.push_back(spec_checksum(Bytes(rot_local.begin() + 1, rot_local.end())));
  r = ask(d, with_sum);
  ASSERT_EQ(r.size(), 1u);
  EXPECT_EQ(r[0].mid, 0xED);
  const Bytes rot_sensor = spec_message(0xEC, Bytes{0x00, 0x00, 0x00, 0x00, 0x00, 0x3F, 0x80, 0x00, 0x00, 0, 0, 0, 0, 0, 0, 0, 0});
  r = ask(d, rot_sensor);
  ASSERT_EQ(r.size(), 1u);
  EXPECT_EQ(r[0].mid, 0xED);
  r = ask(d, Bytes{0xFA, 0xFF, 0x10, 0x00, 0xF1});
  ASSERT_EQ(r.size(), 1u);
  EXPECT_EQ(r[0].mid, 0x11) << "RUNNING";
  EXPECT_EQ(d.command_counters().nacked, 0u);

  // The stream as ArduPilot's framer reads it: one-byte length, every
  // message complete, 50 Hz.
  Bytes stream;
  for (std::uint64_t k = 0; k < 400; ++k) e.encode(sample_at(k), stream);
  std::size_t i = 0, packets = 0;
  while (i < stream.size()) {
    ASSERT_EQ(stream[i], 0xFA);
    ASSERT_EQ(stream[i + 1], 0xFF);
    const std::size_t len = stream[i + 3];
    ASSERT_NE(len, 0xFFu) << "ArduPilot's UART framer reads one length byte";
    unsigned sum = 0;
    for (std::size_t k = i + 1; k < i + 4 + len + 1; ++k) sum += stream[k];
    ASSERT_EQ(sum % 256, 0u);
    ASSERT_EQ(stream[i + 2], 0x36);
    // parse_mtdata2(): each item at ArduPilot's size.
    const SpecItems it = spec_items(Bytes(stream.begin() + static_cast<std::ptrdiff_t>(i + 4),
                                          stream.begin() + static_cast<std::ptrdiff_t>(i + 4 + len)));
    ASSERT_TRUE(it.tiled);
    EXPECT_EQ(it.order, ids);
    const std::map<std::uint16_t, std::size_t> ap_size{{0x1020, 2}, {0x1060, 4}, {0xE020, 4}, {0x5042, 12}, {0x5022, 6},
                                                       {0xD012, 18}, {0x1010, 12}, {0x2010, 16}, {0x4020, 12},
                                                       {0x8020, 12}, {0xC020, 12}, {0x3010, 4}, {0x0810, 4}, {0x7010, 94}};
    for (const auto& [id, size] : ap_size) EXPECT_EQ(it.at(id).size(), size) << std::hex << id;
    if (packets == 10) {
      // Sample 80 (0.2 s): NED / FRD after the two rotations.
      const double psi = kYawRate * 0.2;
      const std::vector<double> q = it.reals(0x2010);
      EXPECT_NEAR(q[0], std::cos(psi / 2), 1e-6);
      EXPECT_NEAR(q[3], std::sin(psi / 2), 1e-6);
      EXPECT_NEAR(it.reals(0x8020)[2], kYawRate, 1e-6) << "FRD rate about down";
      EXPECT_NEAR(it.reals(0x4020)[2], -kG, 1e-5);
      EXPECT_NEAR(it.reals(0xD012)[0], 1.0, 1e-9) << "north in NED";
      EXPECT_NEAR(it.reals(0xD012)[2], -0.5, 1e-9);
      EXPECT_NEAR(it.reals(0x5042)[0], 41.4, 1e-9);
      const Bytes& pvt = it.at(0x7010);
      EXPECT_EQ(pvt[20], 3) << "fixType 3D";
      EXPECT_EQ(pvt[22], 12) << "numSv";
      EXPECT_EQ(static_cast<std::int32_t>(be32(pvt.data() + 28)), 414000000) << "lat 1e-7 deg";
      EXPECT_NE(be32(it.at(0xE020).data()) & 0x4u, 0u) << "GNSS fix";
      EXPECT_EQ(be16(it.at(0x1010).data() + 4), 2026) << "UTC year of the default GPS time base";
    }
    ++packets;
    i += 4 + len + 1;
  }
  EXPECT_EQ(packets, 50u);
}

// xspublic (e2f611d) re-stated: each request, the reply it waits for and how it reads it.
TEST(XsensDevice, XspublicConnectAndConfigureGetsEveryAckAndTheFirstMtData2Decodes) {
  for (const drivers::XsensModel model : {drivers::XsensModel::mti630, drivers::XsensModel::mti3}) {
    drivers::xsens::Encoder e(options(model));
    drivers::CommandResponder& d = *e.command_responder();
    auto r = ask(d, spec_message(0x30));
    ASSERT_EQ(r.size(), 1u);
    EXPECT_EQ(r[0].mid, 0x31);
    r = ask(d, spec_message(0x00));
    ASSERT_EQ(r.size(), 1u);
    ASSERT_EQ(r[0].mid, 0x01);
    // getDeviceId(): 4 bytes, or 8 read as one id when a half has bit 31.
    std::uint64_t id = be32(r[0].data.data());
    if (r[0].data.size() == 8) {
      const std::uint32_t hi = be32(r[0].data.data()), lo = be32(r[0].data.data() + 4);
      if ((hi & 0x80000000u) != 0 || (lo & 0x80000000u) != 0) id = (std::uint64_t{hi} << 32) | lo;
    }
    EXPECT_NE(id, 0u) << "a device id, else 'No MTi device found'";
    r = ask(d, spec_message(0x1C));
    ASSERT_EQ(r.at(0).mid, 0x1D);
    std::string pc(r[0].data.begin(), r[0].data.end());
    pc = pc.substr(0, pc.find(' '));
    EXPECT_EQ(pc.rfind("MTi-", 0), 0u);
    // XsDeviceId: an MTi-600 (64-bit id) is told by its product code ("MTi-6xx"),
    // a legacy id by its class nibbles (MTi-1 series: 0x0080_0000).
    if (model == drivers::XsensModel::mti630) {
      EXPECT_NE(id & 0x80000000u, 0u);
      EXPECT_EQ(std::atoi(pc.c_str() + 4), 630);
    } else {
      EXPECT_EQ(id & 0x00F00000u, 0x00800000u);
      EXPECT_EQ(id & 0x0F000000u, 0x03000000u);
    }
    r = ask(d, spec_message(0x1E));
    ASSERT_EQ(r.at(0).mid, 0x1F);
    r = ask(d, spec_message(0x12));
    ASSERT_EQ(r.at(0).mid, 0x13);
    EXPECT_EQ(r[0].data.size(), 11u);
    r = ask(d, spec_message(0xC0, config_data({{0x1020, 0xFFFF}, {0x1060, 0xFFFF}, {0x2010, 100}, {0x4020, 100},
                                               {0x8020, 100}, {0xC020, 100}, {0xE020, 0xFFFF}})));
    ASSERT_EQ(r.at(0).mid, 0xC1);
    EXPECT_EQ(r[0].data.size(), 28u);
    r = ask(d, spec_message(0x10));
    ASSERT_EQ(r.at(0).mid, 0x11);
    EXPECT_EQ(d.command_counters().nacked, 0u);
    const double rate = model == drivers::XsensModel::mti3 ? 100.0 : 400.0;
    const std::vector<SpecMessage> m = run(e, 0, 4, rate);
    ASSERT_FALSE(m.empty());
    EXPECT_EQ(m[0].mid, 0x36);
    const SpecItems it = spec_items(m[0].data);
    ASSERT_TRUE(it.tiled);
    EXPECT_EQ(it.order.size(), 7u);
    EXPECT_NEAR(it.reals(0x4020)[2], kG, 1e-5);
    EXPECT_NEAR(it.reals(0x8020)[2], -kYawRate, 1e-6);
    const std::vector<double> q = it.reals(0x2010);
    EXPECT_NEAR(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3], 1.0, 1e-6);
  }
}

// What xspublic's openPort / XsDevice construction asks beyond the scan
// (xsdevice_def.cpp: InitBus, ReqConfiguration read by
// XsDeviceConfiguration_readFromMessage: device id at 0 (+ the high word at
// 4 for a 64-bit id), product code at 32, device count at 96, the device's
// id at 98 and firmware at 112; mtdevice.cpp: ReqStringOutputType).
TEST(XsensDevice, XspublicOpenPortRequestsAreAnsweredInTheLayoutItReads) {
  drivers::xsens::Encoder e(options(drivers::XsensModel::mti680g));
  drivers::CommandResponder& d = *e.command_responder();
  ask(d, spec_message(0x30));
  auto r = ask(d, spec_message(0x02));
  ASSERT_EQ(r.size(), 1u);
  EXPECT_EQ(r[0].mid, 0x03);
  EXPECT_EQ(r[0].data, (Bytes{0x00, 0x00, 0x00, 0x00, 0x80, 0x00, 0x1A, 0x2E}));
  r = ask(d, spec_message(0x0C));
  ASSERT_EQ(r.size(), 1u);
  ASSERT_EQ(r[0].mid, 0x0D);
  ASSERT_EQ(r[0].data.size(), 118u);
  const Bytes& c = r[0].data;
  EXPECT_EQ(be32(&c[0]), 0x80001A2Eu);
  EXPECT_EQ(be32(&c[4]), 0u);
  EXPECT_EQ(std::string(c.begin() + 32, c.begin() + 46), "MTi-680G-8A1G6");
  EXPECT_EQ(be16(&c[96]), 1u);
  EXPECT_EQ(be32(&c[98]), 0x80001A2Eu);
  EXPECT_EQ(Bytes(c.begin() + 112, c.begin() + 115), (Bytes{1, 12, 0}));
  r = ask(d, spec_message(0x8E));
  ASSERT_EQ(r.size(), 1u);
  EXPECT_EQ(r[0].mid, 0x8F);
  EXPECT_EQ(r[0].data, (Bytes{0x00, 0x00}));
  r = ask(d, spec_message(0x8E, {0x00, 0x05}));
  EXPECT_EQ(r.at(0).mid, 0x42) << "NMEA string outputs are not emulated";
  EXPECT_EQ(d.command_counters().nacked, 1u);
}

// The ROS 2 node's start-up (xsenssupport/Xsens_MTi_ROS_Driver_and_Ntrip_Client,
// branch ros2 at 2022373604d9c4aab4a38743832dbc2e60114078,
// src/xsens_mti_ros2_driver/src/xdainterface.cpp connectDevice(), prepare(),
// manualGyroBiasEstimation(), with param/xsens_mti_node.yaml's
// enable_deviceConfig false and enable_logging false, and its xspublic:
// xscontroller/scanner.cpp, serialcommunicator.cpp, devicecommunicator.cpp,
// xsdevice_def.cpp, mtdevice.cpp), every message in order:
//  - XsScanner::scanPort at the `baudrate` parameter (fetchBasicInfo ->
//    SerialCommunicator::openPort(OPS_InitStart)): GotoConfig, ReqDID,
//    ReqProductCode, ReqHardwareVersion, ReqFWRev.
//  - XsControl::openPort (OPS_Full): the same five again.
//  - The device's MtDevice::initialize(): readDeviceConfiguration()
//    (gotoConfig from the initial state: GotoConfig; InitBus; ReqConfiguration;
//    ReqFWRev; outputConfiguration(): ReqOutputConfiguration), then
//    fetchAvailableHardwareScenarios(): ReqAvailableFilterProfiles.
//  - connectDevice(): productCode() ReqProductCode; onboardFilterProfile()
//    ReqFilterProfile (data read as a C string first; empty: the u16
//    profile type, looked up in) ReqAvailableFilterProfiles;
//    deviceOptionFlags() ReqOptionFlags (u32).
//  - prepare(): gotoConfig() (already in config: nothing sent);
//    configureSensorSettings() returns at enable_deviceConfig false;
//    readEmtsAndDeviceConfiguration(): ReqEmts with data {0, 255} (10 s
//    timeout), then ReqConfiguration sent with the same message object, so
//    with the same two data bytes; gotoMeasurement(): GotoMeasurement;
//    manualGyroBiasEstimation(0, 6): SetNoRotation of 6 s (u16), waiting
//    1 s for its acknowledgement.
// xspublic's doTransaction takes the reply whose MID is the request's + 1
// and fails on an Error (0x42).
//
// With the default `scan_for_devices: true` the node only scans ports
// xspublic's udev enumeration lists as Xsens USB devices (isXsensUsbDevice:
// Xsens' vendor id, or FTDI's with product ids 0xD388-0xD38F; /dev/ttyS*
// skipped; without libudev, every /dev/ttyUSB*): a bench's
// UART, USB-serial adapter or pty needs scan_for_devices false and the
// port and baudrate parameters, the path replayed here.
TEST(XsensDevice, Ros2NodeStartUpGetsEveryReplyItWaitsForAndTheFirstMtData2Decodes) {
  for (const drivers::XsensModel model : {drivers::XsensModel::mti630, drivers::XsensModel::mti680g}) {
    drivers::xsens::Encoder e(options(model));
    drivers::CommandResponder& d = *e.command_responder();
    // One transaction: the request's bytes as written, its one reply.
    auto transaction = [&](const Bytes& request, std::uint8_t mid) -> SpecMessage {
      const std::vector<SpecMessage> r = ask(d, request);
      EXPECT_EQ(r.size(), 1u) << "MID " << int(request[2]);
      if (r.empty()) return {};
      EXPECT_EQ(r[0].mid, mid + 1) << "MID " << int(mid) << ": answered " << int(r[0].mid);
      return r[0];
    };
    const Bytes goto_config{0xFA, 0xFF, 0x30, 0x00, 0xD1};
    const Bytes req_did{0xFA, 0xFF, 0x00, 0x00, 0x01};
    const Bytes req_product_code{0xFA, 0xFF, 0x1C, 0x00, 0xE5};
    const Bytes req_hardware_version{0xFA, 0xFF, 0x1E, 0x00, 0xE3};
    const Bytes req_fw_rev{0xFA, 0xFF, 0x12, 0x00, 0xEF};
    const Bytes init_bus{0xFA, 0xFF, 0x02, 0x00, 0xFF};
    const Bytes req_configuration{0xFA, 0xFF, 0x0C, 0x00, 0xF5};
    const Bytes req_output_configuration{0xFA, 0xFF, 0xC0, 0x00, 0x41};
    const Bytes req_available_filter_profiles{0xFA, 0xFF, 0x62, 0x00, 0x9F};
    const Bytes req_filter_profile{0xFA, 0xFF, 0x64, 0x00, 0x9D};
    const Bytes req_option_flags{0xFA, 0xFF, 0x48, 0x00, 0xB9};
    const Bytes req_emts{0xFA, 0xFF, 0x90, 0x02, 0x00, 0xFF, 0x70};
    const Bytes req_configuration_2{0xFA, 0xFF, 0x0C, 0x02, 0x00, 0xFF, 0xF4};
    const Bytes goto_measurement{0xFA, 0xFF, 0x10, 0x00, 0xF1};
    const Bytes set_no_rotation_6s{0xFA, 0xFF, 0x22, 0x02, 0x00, 0x06, 0xD7};
    // The hand-written checksums are the document's.
    for (const Bytes* m : {&goto_config, &req_did, &req_product_code, &req_hardware_version, &req_fw_rev, &init_bus,
                           &req_configuration, &req_output_configuration, &req_available_filter_profiles,
                           &req_filter_profile, &req_option_flags, &req_emts, &req_configuration_2, &goto_measurement,
                           &set_no_rotation_6s})
      EXPECT_EQ(spec_message((*m)[2], Bytes(m->begin() + 4, m->end() - 1)), *m);

    // Scan, then openPort: the same five each time.
    std::string product_code;
    for (int pass = 0; pass < 2; ++pass) {
      transaction(goto_config, 0x30);
      const SpecMessage did = transaction(req_did, 0x00);
      EXPECT_TRUE(did.data.size() == 4 || did.data.size() == 8);
      EXPECT_NE(did.data, Bytes(did.data.size(), 0)) << "a device id, else 'No MTi device found'";
      const SpecMessage pc = transaction(req_product_code, 0x1C);
      product_code = std::string(pc.data.begin(), pc.data.end());
      product_code = product_code.substr(0, product_code.find(' '));
      EXPECT_EQ(transaction(req_hardware_version, 0x1E).data.size(), 2u);
      EXPECT_EQ(transaction(req_fw_rev, 0x12).data.size(), 11u);
    }
    // MtDevice::initialize().
    transaction(goto_config, 0x30);
    transaction(init_bus, 0x02);
    const SpecMessage config = transaction(req_configuration, 0x0C);
    ASSERT_EQ(config.data.size(), 118u);
    const std::uint16_t profile_in_config = be16(&config.data[110]);
    const SpecMessage fw = transaction(req_fw_rev, 0x12);
    ASSERT_EQ(fw.data.size(), 11u);
    EXPECT_EQ(fw.data[0], 1);  // XsVersion(major, minor, revision)
    const SpecMessage output = transaction(req_output_configuration, 0xC0);
    EXPECT_EQ(output.data.size() % 4, 0u);
    EXPECT_FALSE(output.data.empty());
    const SpecMessage profiles = transaction(req_available_filter_profiles, 0x62);
    ASSERT_EQ(profiles.data.size() % 22, 0u);  // type, version, label [20] each
    ASSERT_GE(profiles.data.size(), 22u);
    // connectDevice().
    const SpecMessage pc = transaction(req_product_code, 0x1C);
    std::string code(pc.data.begin(), pc.data.end());
    code = code.substr(0, code.find(' '));
    EXPECT_EQ(code, product_code);
    EXPECT_EQ(code.substr(4, 3), model == drivers::XsensModel::mti630 ? "630" : "680");  // its 670/680 check
    if (model == drivers::XsensModel::mti680g) {
      EXPECT_GE(fw.data[1], 12) << "firmware 1.12 or later: no 'please update' warning on a 670 / 680";
    }
    const SpecMessage profile = transaction(req_filter_profile, 0x64);
    ASSERT_EQ(profile.data.size(), 2u);
    EXPECT_EQ(profile.data[0], 0) << "an empty C string: read as the numeric profile";
    const std::uint16_t type = be16(profile.data.data());
    EXPECT_EQ(type & 0xFF, profile_in_config & 0xFF);
    bool listed = false;
    const SpecMessage profiles_again = transaction(req_available_filter_profiles, 0x62);
    for (std::size_t i = 0; i + 22 <= profiles_again.data.size(); i += 22) listed |= profiles_again.data[i] == type;
    EXPECT_TRUE(listed) << "onboardFilterProfile() finds its profile among the device's";
    const SpecMessage flags = transaction(req_option_flags, 0x48);
    ASSERT_EQ(flags.data.size(), 4u);
    EXPECT_EQ(be32(flags.data.data()), 0u);
    // prepare().
    const SpecMessage emts = transaction(req_emts, 0x90);
    EXPECT_TRUE(emts.data.empty()) << "EmtsData without pages (xspublic keeps it, does not parse it)";
    EXPECT_EQ(transaction(req_configuration_2, 0x0C).data, config.data);
    transaction(goto_measurement, 0x10);
    transaction(set_no_rotation_6s, 0x22);
    EXPECT_EQ(d.command_counters().nacked, 0u);

    // The first MTData2: the factory configuration's items, each at its
    // documented size; the node's imu publisher takes the quaternion, rate
    // of turn and acceleration.
    const std::vector<SpecMessage> m = run(e, 0, 8);
    ASSERT_FALSE(m.empty());
    EXPECT_EQ(m[0].mid, 0x36);
    const SpecItems it = spec_items(m[0].data);
    ASSERT_TRUE(it.tiled);
    ASSERT_EQ(it.at(0x1020).size(), 2u);  // PacketCounter
    ASSERT_EQ(it.at(0x1060).size(), 4u);  // SampleTimeFine
    ASSERT_EQ(it.reals(0x2010).size(), 4u);
    ASSERT_EQ(it.reals(0x4020).size(), 3u);
    ASSERT_EQ(it.reals(0x8020).size(), 3u);
    EXPECT_NEAR(it.reals(0x4020)[2], kG, 1e-5) << "ENU: up";
    EXPECT_NEAR(it.reals(0x8020)[2], -kYawRate, 1e-6);
    const std::vector<double> q = it.reals(0x2010);
    EXPECT_NEAR(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3], 1.0, 1e-6);
    EXPECT_EQ(it.at(0xE020).size(), 4u);  // StatusWord
    if (model == drivers::XsensModel::mti680g) {
      bool latlon = false;
      for (const std::uint16_t id : it.order) latlon |= (id & 0xFFF0) == 0x5040;
      EXPECT_TRUE(latlon) << "the GNSS model's LatLon for the node's positionLLA publisher";
    }
  }
}

TEST(XsensDevice, ReqEmtsIsAConfigStateRequestWithItsTwoBytes) {
  drivers::xsens::Encoder e(options(drivers::XsensModel::mti630));
  drivers::CommandResponder& d = *e.command_responder();
  auto r = ask(d, spec_message(0x90, {0x00, 0xFF}));  // measuring after power-up
  ASSERT_EQ(r.size(), 1u);
  EXPECT_EQ(r[0].mid, 0x42);
  EXPECT_EQ(r[0].data, Bytes{0x04});
  ask(d, spec_message(0x30));
  r = ask(d, spec_message(0x90, {0x00}));
  ASSERT_EQ(r.size(), 1u);
  EXPECT_EQ(r[0].mid, 0x42);
  EXPECT_EQ(r[0].data, Bytes{0x21});
  r = ask(d, spec_message(0x90, {0x00, 0xFF}));
  ASSERT_EQ(r.size(), 1u);
  EXPECT_EQ(r[0].mid, 0x91);
  EXPECT_TRUE(r[0].data.empty());
  EXPECT_EQ(d.command_counters().nacked, 2u);
}

TEST(XsensDevice, TheLinkBudgetBoundsTheWidestConfiguration) {
  // 32 items (the most a configuration holds): every frame of the five
  // framed quantities and the other quantities in float64, the fixed-size
  // ones, and three fp16.32 duplicates.
  std::vector<std::pair<std::uint16_t, std::uint16_t>> all;
  for (const int base : {0x2010, 0x2020, 0x2030, 0x4030, 0xD010})
    for (const int frame : {0x0, 0x4, 0x8}) all.emplace_back(static_cast<std::uint16_t>(base | frame | 0x3), 400);
  for (const int id : {0x8033, 0x4013, 0x4023, 0x8023, 0xC023, 0x5043, 0x5023, 0x0813, 0x7010, 0x1010, 0x1020, 0x1060,
                       0x3010, 0xE020, 0x2022, 0x2012, 0x4032})
    all.emplace_back(static_cast<std::uint16_t>(id), 400);
  ASSERT_EQ(all.size(), 32u);
  drivers::xsens::Encoder e(options(drivers::XsensModel::mti680g));
  drivers::CommandResponder& d = *e.command_responder();
  ask(d, spec_message(0x30));
  const auto r = ask(d, spec_message(0xC0, config_data(all)));
  ASSERT_EQ(r.size(), 1u);
  ASSERT_EQ(r[0].mid, 0xC1);
  EXPECT_EQ(r[0].data.size(), 4u * 32u) << "all applied";
  ask(d, spec_message(0x10));
  Bytes out;
  e.encode(sample_at(0), out);
  ASSERT_EQ(spec_split(out).messages.size(), 1u);
  EXPECT_EQ(out[3], 0xFF) << "extended length";
  EXPECT_GT(out.size(), 700u);
  EXPECT_LE(out.size(), e.max_bytes_per_sample());
  // The bound (the 32 widest distinct identifiers) is not a loose guess.
  EXPECT_LT(e.max_bytes_per_sample(), out.size() + out.size() / 2);
}

}  // namespace
}  // namespace unity_device_test_xsens_device
