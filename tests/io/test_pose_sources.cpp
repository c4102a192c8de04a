// Tests of the live pose sources (io/pose_source.hpp) and their wire formats
// (io/pose_wire.hpp, docs/pose-wire-format.md): golden datagram bytes written
// out by hand from the byte table, every rejection reason, the line parser's
// messages, and real loopback UDP/TCP sockets, a pipe and a paced file replay
// with every counter asserted exactly.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <limits>
#include <mutex>
#include <numbers>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "core/attitude.hpp"
#include "core/earth.hpp"
#include "core/so3.hpp"
#include "core/stream.hpp"
#include "io/decimal_time.hpp"
#include "io/pose_admission.hpp"
#include "io/pose_source.hpp"
#include "io/pose_wire.hpp"
#include "io/scene_poses.hpp"
#include "io/trajectory_csv.hpp"
#include "tests/support/udp_sender.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace imuemu::io {}
namespace unity_io_test_pose_sources {
namespace imuemu { using namespace ::imuemu; }
namespace imuemu::io { using namespace ::imuemu::io; }

namespace imuemu::io {
namespace {

using Bytes = std::vector<std::uint8_t>;
using namespace std::chrono_literals;
constexpr double kPi = std::numbers::pi;

// ---------------------------------------------------------------- helpers

std::uint64_t bits(double v) { return std::bit_cast<std::uint64_t>(v); }

Bytes to_bytes(const std::array<std::uint8_t, kPoseDatagramV1Size>& a) { return Bytes(a.begin(), a.end()); }

// Recomputes the CRC after a test changed bytes on purpose, so the checks
// behind the checksum are reached (crc32c itself is proven by its check value).
void reseal(Bytes& d) {
  const std::uint32_t crc = crc32c(std::span(d.data(), kDatagramCrcOffset));
  for (int i = 0; i < 4; ++i) d[kDatagramCrcOffset + static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(crc >> (8 * i));
}

void put_f64(Bytes& d, std::size_t offset, double v) {
  const std::uint64_t b = bits(v);
  for (int i = 0; i < 8; ++i) d[offset + static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(b >> (8 * i));
}

TrajectoryRecord ned_quaternion_record(TimeNs t_ns, const Vec3& position_m, double yaw_rad = 0.0) {
  TrajectoryRecord r;
  r.t_ns = t_ns;
  r.position_kind = PositionKind::local_ned;
  r.position = position_m;
  r.attitude_kind = AttitudeKind::quaternion;
  r.attitude = Eigen::Vector4d(std::cos(yaw_rad / 2), 0.0, 0.0, std::sin(yaw_rad / 2));
  return r;
}

Bytes datagram(std::uint64_t sequence, const TrajectoryRecord& record) {
  return to_bytes(encode_pose_datagram(PoseDatagram{sequence, record}));
}

struct Decoded {
  bool ok = false;
  PoseDatagram datagram;
  DatagramDecodeError error;
};
Decoded decode(const Bytes& d) {
  Decoded out;
  out.ok = decode_pose_datagram(d, out.datagram, out.error);
  return out;
}

// Collects log lines from a source's thread.
class LogCapture {
 public:
  std::function<void(std::string_view)> sink() {
    return [this](std::string_view line) {
      const std::lock_guard lock(mutex_);
      lines_.emplace_back(line);
    };
  }
  std::vector<std::string> lines() const {
    const std::lock_guard lock(mutex_);
    return lines_;
  }
  bool contains(std::string_view text) const {
    const std::lock_guard lock(mutex_);
    return std::any_of(lines_.begin(), lines_.end(), [&](const std::string& l) { return l.find(text) != std::string::npos; });
  }

 private:
  mutable std::mutex mutex_;
  std::vector<std::string> lines_;
};

// Polls until pred() holds or 5 s pass (generous: a shared, busy machine).
bool wait_until(const std::function<bool()>& pred, std::chrono::milliseconds timeout = 5000ms) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (!pred()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(1ms);
  }
  return true;
}

std::uint64_t line_error(const PoseSourceCounters& c, LineError e) { return c.line_errors[static_cast<std::size_t>(e)]; }
std::uint64_t datagram_error(const PoseSourceCounters& c, DatagramError e) {
  return c.datagram_errors[static_cast<std::size_t>(e)];
}

// Every received unit ends in exactly one of ignored, accepted, rejected.
void expect_accounted(const PoseSourceCounters& c) {
  EXPECT_EQ(c.received, c.ignored + c.accepted + c.rejected())
      << "received " << c.received << " ignored " << c.ignored << " accepted " << c.accepted << " rejected "
      << c.rejected();
}

// ---------------------------------------------------------------- CRC and golden datagrams

TEST(PoseDatagram, Crc32cCheckValue) {
  // The standard check value of CRC-32C (Castagnoli), e.g. RFC 3720 / the
  // "catalogue of parametrised CRC algorithms": proves the Boost.CRC
  // parameters (polynomial, reflection, init, final xor).
  const std::string check = "123456789";
  EXPECT_EQ(crc32c(std::span(reinterpret_cast<const std::uint8_t*>(check.data()), check.size())), 0xE3069283u);
  EXPECT_EQ(crc32c({}), 0x00000000u);
}

// Example 1 of docs/pose-wire-format.md §2.4, byte by byte from the table:
// sequence 42, t = 1700000000.123456789 s, geodetic (41.5 deg, 2.25 deg,
// 120 m), heading-pitch-roll (90, 2.5, -0.5) deg. The values are exact in
// binary so their IEEE-754 bytes can be written by hand; the CRC bytes were
// computed with an independent bitwise CRC-32C (poly 0x82F63B78 reflected).
const Bytes kGoldenGeodeticHpr = {
    0x49, 0x4d, 0x55, 0x50, 0x01, 0x00, 0x00, 0x00,  // "IMUP", version 1, geodetic, hpr, reserved
    0x2a, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,  // sequence 42
    0x15, 0xcd, 0x85, 0x3d, 0xfe, 0x9c, 0x97, 0x17,  // t_ns 1700000000123456789 = 0x17979cfe3d85cd15
    0x00, 0x00, 0x00, 0x00, 0x00, 0xc0, 0x44, 0x40,  // 41.5   = 0x4044c00000000000
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x02, 0x40,  // 2.25   = 0x4002000000000000
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x5e, 0x40,  // 120.0  = 0x405e000000000000
    0x00, 0x00, 0x00, 0x00, 0x00, 0x80, 0x56, 0x40,  // 90.0   = 0x4056800000000000
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x04, 0x40,  // 2.5    = 0x4004000000000000
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xe0, 0xbf,  // -0.5   = 0xbfe0000000000000
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,  // 0 (unused 4th attitude component)
    0xce, 0x10, 0xb8, 0x50,                          // CRC-32C of bytes 0..79 = 0x50b810ce
};
// Example 2: sequence 7, t = 2.5 s, local NED (10, -3.5, 0.25) m, identity quaternion.
const Bytes kGoldenNedQuaternion = {
    0x49, 0x4d, 0x55, 0x50, 0x01, 0x02, 0x01, 0x00,  // local NED, quaternion
    0x07, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,  // sequence 7
    0x00, 0xf9, 0x02, 0x95, 0x00, 0x00, 0x00, 0x00,  // 2500000000 ns = 0x9502f900
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x24, 0x40,  // 10.0
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x0c, 0xc0,  // -3.5
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xd0, 0x3f,  // 0.25
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xf0, 0x3f,  // qw 1.0
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,  // qx
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,  // qy
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,  // qz
    0x77, 0xc4, 0xfa, 0x3e,                          // CRC-32C = 0x3efac477
};

TEST(PoseDatagram, GoldenBytesEncodeAndDecode) {
  ASSERT_EQ(kGoldenGeodeticHpr.size(), kPoseDatagramV1Size);
  TrajectoryRecord r;
  r.t_ns = 1'700'000'000'123'456'789;
  r.position_kind = PositionKind::geodetic;
  r.position = Vec3(41.5, 2.25, 120.0);
  r.attitude_kind = AttitudeKind::heading_pitch_roll;
  r.attitude = Eigen::Vector4d(90.0, 2.5, -0.5, 0.0);
  EXPECT_EQ(datagram(42, r), kGoldenGeodeticHpr);

  const Decoded d = decode(kGoldenGeodeticHpr);
  ASSERT_TRUE(d.ok) << d.error.message;
  EXPECT_EQ(d.datagram.sequence, 42u);
  EXPECT_EQ(d.datagram.record.t_ns, 1'700'000'000'123'456'789);
  EXPECT_EQ(d.datagram.record.position_kind, PositionKind::geodetic);
  EXPECT_EQ(d.datagram.record.attitude_kind, AttitudeKind::heading_pitch_roll);
  EXPECT_EQ(d.datagram.record.position, Vec3(41.5, 2.25, 120.0));
  EXPECT_EQ(d.datagram.record.attitude, Eigen::Vector4d(90.0, 2.5, -0.5, 0.0));
  EXPECT_EQ(d.datagram.record.line, 0u);

  const TrajectoryRecord q = ned_quaternion_record(2'500'000'000, Vec3(10.0, -3.5, 0.25));
  EXPECT_EQ(datagram(7, q), kGoldenNedQuaternion);
  const Decoded e = decode(kGoldenNedQuaternion);
  ASSERT_TRUE(e.ok) << e.error.message;
  EXPECT_EQ(e.datagram.sequence, 7u);
  EXPECT_EQ(e.datagram.record.t_ns, 2'500'000'000);
  EXPECT_EQ(e.datagram.record.position_kind, PositionKind::local_ned);
  EXPECT_EQ(e.datagram.record.attitude_kind, AttitudeKind::quaternion);
  EXPECT_EQ(e.datagram.record.position, Vec3(10.0, -3.5, 0.25));
  EXPECT_EQ(e.datagram.record.attitude, Eigen::Vector4d(1.0, 0.0, 0.0, 0.0));
}

TEST(PoseDatagram, RandomRoundTripsAreBitExact) {
  std::mt19937_64 rng(77);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const std::uint64_t kSequences[] = {0, 1, 0xffffffffull, 0x100000000ull, std::numeric_limits<std::uint64_t>::max()};
  const TimeNs kTimes[] = {0, -1, std::numeric_limits<TimeNs>::min(), std::numeric_limits<TimeNs>::max(),
                           1'700'000'000'000'000'001};
  for (int n = 0; n < 3000; ++n) {
    TrajectoryRecord r;
    r.t_ns = n < 5 ? kTimes[n] : static_cast<TimeNs>(rng());
    r.position_kind = static_cast<PositionKind>(n % 3);
    r.attitude_kind = static_cast<AttitudeKind>((n / 3) % 3);
    if (!kinds_compatible(r.position_kind, r.attitude_kind)) r.attitude_kind = AttitudeKind::quaternion;
    r.position = r.position_kind == PositionKind::geodetic ? Vec3(90.0 * u(rng), 1e3 * u(rng), 1e4 * u(rng))
                                                           : Vec3(7e6 * u(rng), 7e6 * u(rng), 7e6 * u(rng));
    if (r.attitude_kind == AttitudeKind::heading_pitch_roll) {
      r.attitude = Eigen::Vector4d(720.0 * u(rng), 90.0 * u(rng), 360.0 * u(rng), 0.0);
    } else {
      r.attitude = Eigen::Vector4d(u(rng), u(rng), u(rng), u(rng)).normalized();
    }
    const std::uint64_t sequence = n < 5 ? kSequences[n] : rng();
    const Bytes bytes = datagram(sequence, r);
    const Decoded d = decode(bytes);
    ASSERT_TRUE(d.ok) << n << ": " << d.error.message;
    ASSERT_EQ(d.datagram.sequence, sequence);
    ASSERT_EQ(d.datagram.record.t_ns, r.t_ns);
    ASSERT_EQ(d.datagram.record.position_kind, r.position_kind);
    ASSERT_EQ(d.datagram.record.attitude_kind, r.attitude_kind);
    for (int k = 0; k < 3; ++k) ASSERT_EQ(bits(d.datagram.record.position[k]), bits(r.position[k]));
    if (r.attitude_kind == AttitudeKind::heading_pitch_roll) {
      for (int k = 0; k < 4; ++k) ASSERT_EQ(bits(d.datagram.record.attitude[k]), bits(r.attitude[k]));
    } else {
      // Normalising an already normalised quaternion may move it by an ulp.
      ASSERT_LT((d.datagram.record.attitude - r.attitude).norm(), 4e-16);
    }
    // A decoded datagram encodes back to the same bytes (as far as values go).
    if (r.attitude_kind == AttitudeKind::heading_pitch_roll) {
      ASSERT_EQ(datagram(sequence, d.datagram.record), bytes);
    }
  }
}

// ---------------------------------------------------------------- datagram rejections

void expect_refused(const Bytes& d, DatagramError reason, bool intact, const std::string& message_part) {
  const Decoded r = decode(d);
  ASSERT_FALSE(r.ok) << "accepted, expected " << to_string(reason);
  EXPECT_EQ(r.error.reason, reason) << to_string(r.error.reason) << ": " << r.error.message;
  EXPECT_EQ(r.error.intact, intact) << r.error.message;
  EXPECT_NE(r.error.message.find(message_part), std::string::npos)
      << "message '" << r.error.message << "' lacks '" << message_part << "'";
}

TEST(PoseDatagram, EveryRejectionReason) {
  const Bytes good = kGoldenGeodeticHpr;
  ASSERT_TRUE(decode(good).ok);

  // Structure, in the order checked.
  expect_refused({}, DatagramError::too_short, false, "0 bytes");
  expect_refused(Bytes(good.begin(), good.begin() + 4), DatagramError::too_short, false, "4 bytes");
  Bytes magic = good;
  magic[0] = 'i';
  expect_refused(magic, DatagramError::bad_magic, false, "IMUP");
  Bytes v3 = good;
  v3[4] = 3;
  expect_refused(v3, DatagramError::unsupported_version, false, "version 3");
  v3.resize(100);  // a future version may be longer: the version is reported, not the length
  expect_refused(v3, DatagramError::unsupported_version, false, "version 3");
  Bytes v2 = good;  // version 2 (rates, §2.5) is known: an 84-byte one has the wrong length
  v2[4] = 2;
  expect_refused(v2, DatagramError::bad_length, false, "version 2 pose datagram has 156");
  expect_refused(Bytes(good.begin(), good.end() - 1), DatagramError::bad_length, false, "83 bytes");
  Bytes longer = good;
  longer.push_back(0);
  expect_refused(longer, DatagramError::bad_length, false, "85 bytes");
  // Any single flipped bit is refused: in magic and version by their own
  // checks, elsewhere by the CRC (which catches every 1-bit error).
  for (std::size_t byte = 0; byte < kPoseDatagramV1Size; ++byte) {
    for (int bit = 0; bit < 8; ++bit) {
      Bytes flipped = good;
      flipped[byte] = static_cast<std::uint8_t>(flipped[byte] ^ (1u << bit));
      SCOPED_TRACE("byte " + std::to_string(byte) + " bit " + std::to_string(bit));
      const Decoded r = decode(flipped);
      ASSERT_FALSE(r.ok);
      ASSERT_EQ(r.error.reason, byte < 4    ? DatagramError::bad_magic
                                : byte == 4 ? DatagramError::unsupported_version
                                            : DatagramError::bad_checksum);
    }
  }

  // Behind the checksum (resealed), with the intact flag set.
  Bytes kind = good;
  kind[kDatagramPositionKindOffset] = 3;
  reseal(kind);
  expect_refused(kind, DatagramError::bad_kind, true, "position kind 0x03");
  kind = good;
  kind[kDatagramAttitudeKindOffset] = 0xff;
  reseal(kind);
  expect_refused(kind, DatagramError::bad_kind, true, "attitude kind 0xff");
  kind = kGoldenNedQuaternion;
  kind[kDatagramAttitudeKindOffset] = 2;  // ECEF attitude with a local NED position
  reseal(kind);
  expect_refused(kind, DatagramError::bad_kind, true, "Earth-fixed position");
  Bytes reserved = good;
  reserved[kDatagramReservedOffset] = 0x80;
  reseal(reserved);
  expect_refused(reserved, DatagramError::reserved_not_zero, true, "reserved byte 7");
  Bytes fourth = good;
  put_f64(fourth, kDatagramAttitudeOffset + 24, 1.0);
  reseal(fourth);
  expect_refused(fourth, DatagramError::reserved_not_zero, true, "attitude component 3");

  // Values: the trajectory file's rules and phrases.
  struct ValueCase {
    std::size_t offset;
    double value;
    std::string message_part;
  };
  const std::vector<ValueCase> value_cases = {
      {kDatagramPositionOffset, 90.000000001, "(lat_deg): expected a latitude in [-90, 90] degrees, got 90.000000001"},
      {kDatagramPositionOffset, -91.0, "lat_deg"},
      {kDatagramPositionOffset, std::nan(""), "got nan"},
      {kDatagramPositionOffset + 8, std::numeric_limits<double>::infinity(), "(lon_deg): expected a finite longitude"},
      {kDatagramPositionOffset + 16, -std::numeric_limits<double>::infinity(), "h_m"},
      {kDatagramAttitudeOffset, std::nan(""), "heading_deg"},
      {kDatagramAttitudeOffset + 8, 90.5, "(pitch_deg): expected a pitch in [-90, 90] degrees, got 90.5"},
      {kDatagramAttitudeOffset + 16, std::numeric_limits<double>::infinity(), "roll_deg"},
  };
  for (const ValueCase& c : value_cases) {
    Bytes d = good;
    put_f64(d, c.offset, c.value);
    reseal(d);
    SCOPED_TRACE(c.message_part);
    expect_refused(d, DatagramError::bad_value, true, c.message_part);
  }
  // Quaternion norm: the file reader's tolerance, both sides.
  Bytes q = kGoldenNedQuaternion;
  put_f64(q, kDatagramAttitudeOffset, 1.0 + 2e-6);
  reseal(q);
  expect_refused(q, DatagramError::bad_value, true, "unit quaternion");
  put_f64(q, kDatagramAttitudeOffset, 1e200);
  put_f64(q, kDatagramAttitudeOffset + 8, 1e200);
  reseal(q);
  expect_refused(q, DatagramError::bad_value, true, "unit quaternion");
  put_f64(q, kDatagramAttitudeOffset + 8, 0.0);
  put_f64(q, kDatagramAttitudeOffset, -(1.0 - 9e-7));  // within tolerance, and -q: accepted, normalised
  reseal(q);
  const Decoded ok = decode(q);
  ASSERT_TRUE(ok.ok) << ok.error.message;
  EXPECT_EQ(ok.datagram.record.attitude, Eigen::Vector4d(-1.0, 0.0, 0.0, 0.0));
  put_f64(q, kDatagramAttitudeOffset + 24, std::nan(""));
  reseal(q);
  expect_refused(q, DatagramError::bad_value, true, "(qz): expected a finite quaternion component");
}

// ---------------------------------------------------------------- text lines

TEST(TrajectoryLineParser, HeaderAndRecordErrorsNameTheirLines) {
  TrajectoryLineParser parser("tcp client");
  TrajectoryRecord r;
  using Kind = TrajectoryLineParser::LineKind;
  EXPECT_EQ(parser.feed("# imuemu-pose-lines v1", r), Kind::skipped);
  EXPECT_EQ(parser.feed("", r), Kind::skipped);
  try {
    parser.feed("time_s,lat_deg,lon_deg,heading_deg,pitch_deg,roll_deg", r);
    ADD_FAILURE() << "incomplete header accepted";
  } catch (const TrajectoryFormatError& e) {
    EXPECT_EQ(e.line(), 3u);
    EXPECT_EQ(std::string(e.what()),
              "tcp client:3: incomplete geodetic position: missing column(s) 'h_m'; expected all of lat_deg,lon_deg,h_m");
  }
  EXPECT_FALSE(parser.has_header());
  try {
    parser.feed("time_s,north_m,east_m,down_m,qw,qx,qy,Qz", r);
    ADD_FAILURE() << "unknown column accepted";
  } catch (const TrajectoryFormatError& e) {
    EXPECT_EQ(e.line(), 4u);
    EXPECT_EQ(e.column(), "Qz");
    EXPECT_EQ(e.column_index(), 8u);
  }
  EXPECT_EQ(parser.feed(" time_s, north_m,east_m,down_m,qw,qx,qy,qz\r", r), Kind::header);
  EXPECT_EQ(parser.header_line(), 5u);
  EXPECT_EQ(parser.position_kind(), PositionKind::local_ned);
  EXPECT_EQ(parser.attitude_kind(), AttitudeKind::quaternion);
  try {
    parser.feed("0.5,1,2,3,1,0,0", r);
    ADD_FAILURE() << "short record accepted";
  } catch (const TrajectoryFormatError& e) {
    EXPECT_EQ(std::string(e.what()),
              "tcp client:6: expected 8 comma-separated fields as named by the header (line 5), got 7");
  }
  try {
    parser.feed("0.5,1,2,3,0.5,0,0,0", r);
    ADD_FAILURE() << "non-unit quaternion accepted";
  } catch (const TrajectoryFormatError& e) {
    EXPECT_EQ(e.line(), 7u);
    EXPECT_EQ(e.column(), "qw");
  }
  ASSERT_EQ(parser.feed("0.5,1,2,3,0.6,0,0.8,0", r), Kind::record);
  EXPECT_EQ(r.line, 8u);
  EXPECT_EQ(r.t_ns, 500'000'000);
  EXPECT_EQ(r.position, Vec3(1, 2, 3));
  EXPECT_LT((r.attitude - Eigen::Vector4d(0.6, 0, 0.8, 0)).norm(), 1e-15);
  // No ordering rule in the line parser: the source judges order.
  ASSERT_EQ(parser.feed("0.25,1,2,3,1,0,0,0", r), Kind::record);
  EXPECT_EQ(r.t_ns, 250'000'000);
  EXPECT_EQ(parser.line_number(), 9u);
}

TEST(TrajectoryLineParser, SameRecordsAsTheFileReader) {
  const std::string text =
      "\xEF\xBB\xBF# comment\n"
      "time_s, lat_deg, lon_deg, h_m, heading_deg, pitch_deg, roll_deg\r\n"
      "345600.00, 41.3879, 2.1699, 120.0, 90.0, 2.5, 0.0\r\n"
      "\n"
      "345600.01, 41.38790012, 2.16990305, 120.01, 90.02, 2.5, 0.1\n";
  const Trajectory t = parse_trajectory_csv(text, "f.csv");
  TrajectoryLineParser parser("f.csv");
  std::vector<TrajectoryRecord> streamed;
  std::size_t begin = 0;
  while (begin < text.size()) {
    const std::size_t end = text.find('\n', begin);
    TrajectoryRecord r;
    if (parser.feed(std::string_view(text).substr(begin, end - begin), r) == TrajectoryLineParser::LineKind::record)
      streamed.push_back(r);
    begin = end + 1;
  }
  ASSERT_EQ(streamed.size(), t.records.size());
  for (std::size_t i = 0; i < streamed.size(); ++i) {
    EXPECT_EQ(streamed[i].t_ns, t.records[i].t_ns);
    EXPECT_EQ(streamed[i].line, t.records[i].line);
    EXPECT_EQ(streamed[i].position, t.records[i].position);
    EXPECT_EQ(streamed[i].attitude, t.records[i].attitude);
  }
  EXPECT_EQ(streamed[1].line, 5u);
}

struct DecodedLine {
  PoseLineDecoder::Outcome outcome;
  TrajectoryRecord record;
  LineError error = LineError::bad_record;
  std::string message;
};
DecodedLine decode_line(PoseLineDecoder& decoder, std::string_view line) {
  DecodedLine d;
  d.outcome = decoder.decode(line, d.record, d.error, d.message);
  return d;
}

TEST(PoseLineDecoder, VersionLineRules) {
  using Outcome = PoseLineDecoder::Outcome;
  const std::string header = "time_s,north_m,east_m,down_m,heading_deg,pitch_deg,roll_deg";
  {
    PoseLineDecoder d("s");
    EXPECT_EQ(decode_line(d, "# imuemu-pose-lines v1").outcome, Outcome::ignored);
    EXPECT_EQ(decode_line(d, header).outcome, Outcome::ignored);
    // After the header a version line is just a comment (as in a file).
    EXPECT_EQ(decode_line(d, "# imuemu-pose-lines v7").outcome, Outcome::ignored);
    const DecodedLine r = decode_line(d, "1,2,3,4,5,6,7");
    ASSERT_EQ(r.outcome, Outcome::record) << r.message;
    EXPECT_EQ(r.record.line, 4u);
  }
  {
    PoseLineDecoder d("s");
    const DecodedLine v = decode_line(d, "  # imuemu-pose-lines   v2  \r");
    ASSERT_EQ(v.outcome, Outcome::error);
    EXPECT_EQ(v.error, LineError::unsupported_version);
    EXPECT_EQ(v.message, "s:1: unsupported version 'v2'; this reader knows # imuemu-pose-lines v1");
    EXPECT_EQ(decode_line(d, "# a comment").outcome, Outcome::ignored);
    for (const std::string& line : {header, std::string("1,2,3,4,5,6,7")}) {
      const DecodedLine r = decode_line(d, line);
      ASSERT_EQ(r.outcome, Outcome::error);
      EXPECT_EQ(r.error, LineError::unsupported_version);
      EXPECT_NE(r.message.find("declared an unsupported version (line 1)"), std::string::npos) << r.message;
    }
  }
  {
    PoseLineDecoder d("s");
    EXPECT_EQ(decode_line(d, "# imuemu-pose-lines").error, LineError::unsupported_version);
  }
  {
    // Not the tag: an ordinary comment.
    PoseLineDecoder d("s");
    EXPECT_EQ(decode_line(d, "# imuemu-pose-linesv2").outcome, Outcome::ignored);
    EXPECT_EQ(decode_line(d, header).outcome, Outcome::ignored);
  }
  {
    // A byte order mark is skipped on the first line only.
    PoseLineDecoder d("s");
    EXPECT_EQ(decode_line(d, "\xEF\xBB\xBF# imuemu-pose-lines v1").outcome, Outcome::ignored);
    EXPECT_EQ(decode_line(d, "\xEF\xBB\xBF" + header).error, LineError::bad_header);
    PoseLineDecoder e("s");
    EXPECT_EQ(decode_line(e, "\xEF\xBB\xBF" + header).outcome, Outcome::ignored);
    EXPECT_TRUE(e.has_header());
  }
  {
    // Data before a header is tried as the header.
    PoseLineDecoder d("s");
    const DecodedLine r = decode_line(d, "1,2,3,4,5,6,7");
    ASSERT_EQ(r.outcome, Outcome::error);
    EXPECT_EQ(r.error, LineError::bad_header);
    EXPECT_EQ(r.message.rfind("s:1: column '1' (1): unknown column name", 0), 0u) << r.message;
    EXPECT_EQ(decode_line(d, header).outcome, Outcome::ignored);
    const DecodedLine bad = decode_line(d, "1,2,3,4,5,95,7");
    EXPECT_EQ(bad.error, LineError::bad_record);
    EXPECT_EQ(bad.message, "s:3: column 'pitch_deg' (6): expected a pitch in [-90, 90] degrees, got '95'");
  }
}

// ---------------------------------------------------------------- framing, log, sequence, queue

TEST(LineFramer, SplitsLinesAcrossReadsAndRefusesLongOnes) {
  LineFramer f;
  std::string_view line;
  f.append("ab", 2);
  EXPECT_EQ(f.next(line), LineFramer::Next::none);
  f.append("c\r\nde\n\nf", 8);
  ASSERT_EQ(f.next(line), LineFramer::Next::line);
  EXPECT_EQ(line, "abc\r");
  ASSERT_EQ(f.next(line), LineFramer::Next::line);
  EXPECT_EQ(line, "de");
  ASSERT_EQ(f.next(line), LineFramer::Next::line);
  EXPECT_EQ(line, "");
  EXPECT_EQ(f.next(line), LineFramer::Next::none);
  // A line longer than the limit, arriving in pieces: reported once, when
  // the limit is crossed, and skipped up to its newline.
  const std::string chunk(3000, 'x');
  f.append(chunk.data(), chunk.size());
  EXPECT_EQ(f.next(line), LineFramer::Next::none);
  f.append(chunk.data(), chunk.size());
  EXPECT_EQ(f.next(line), LineFramer::Next::too_long);
  EXPECT_EQ(f.next(line), LineFramer::Next::none);
  f.append(chunk.data(), chunk.size());
  EXPECT_EQ(f.next(line), LineFramer::Next::none);
  f.append("yy\nok\n", 6);
  ASSERT_EQ(f.next(line), LineFramer::Next::line);
  EXPECT_EQ(line, "ok");
  // A complete over-long line in one read.
  const std::string whole = std::string(kMaxPoseLineBytes + 1, 'z') + "\nnext\n";
  f.append(whole.data(), whole.size());
  EXPECT_EQ(f.next(line), LineFramer::Next::too_long);
  ASSERT_EQ(f.next(line), LineFramer::Next::line);
  EXPECT_EQ(line, "next");
  // Exactly at the limit is fine.
  const std::string limit = std::string(kMaxPoseLineBytes, 'w') + "\n";
  f.append(limit.data(), limit.size());
  ASSERT_EQ(f.next(line), LineFramer::Next::line);
  EXPECT_EQ(line.size(), kMaxPoseLineBytes);
  EXPECT_FALSE(f.finish());
  f.append("partial", 7);
  EXPECT_EQ(f.next(line), LineFramer::Next::none);
  EXPECT_TRUE(f.finish());
  EXPECT_FALSE(f.finish());
}

TEST(RateLimitedLog, OneLinePerKeyPerIntervalWithSuppressedCount) {
  std::vector<std::string> lines;
  RateLimitedLog log([&](std::string_view l) { lines.emplace_back(l); }, kNsPerSecond);
  for (int i = 0; i < 5; ++i) log.log("bad_crc", "crc " + std::to_string(i), 100 + i);
  log.log("bad_magic", "magic", 200);
  ASSERT_EQ(lines.size(), 2u);
  EXPECT_EQ(lines[0], "crc 0");
  EXPECT_EQ(lines[1], "magic");
  log.log("bad_crc", "crc late", 100 + kNsPerSecond - 1);  // still inside the interval
  EXPECT_EQ(lines.size(), 2u);
  log.log("bad_crc", "crc 6", 100 + kNsPerSecond);
  ASSERT_EQ(lines.size(), 3u);
  EXPECT_EQ(lines[2], "crc 6 [5 more 'bad_crc' suppressed]");
  log.log("bad_crc", "crc 7", 100 + kNsPerSecond + 5);
  log.flush();
  ASSERT_EQ(lines.size(), 4u);
  EXPECT_EQ(lines[3], "1 more 'bad_crc' suppressed");
  log.flush();
  EXPECT_EQ(lines.size(), 4u);
}

TEST(SequenceTracker, GapsLateRepeatsStaleAndRestarts) {
  using A = SequenceTracker::Arrival;
  SequenceTracker s;
  // Sender sends 10..20 with t = seq ms; the network loses 13 and 17,
  // duplicates 15, delivers 12 after 14 and 16 after 18.
  auto t = [](std::uint64_t seq) { return static_cast<TimeNs>(seq) * 1'000'000; };
  EXPECT_EQ(s.observe(10, t(10)), A::first);
  EXPECT_EQ(s.observe(11, t(11)), A::next);
  EXPECT_EQ(s.observe(14, t(14)), A::jump);  // 12, 13 missing so far
  EXPECT_EQ(s.observe(12, t(12)), A::late);
  EXPECT_EQ(s.observe(15, t(15)), A::next);
  EXPECT_EQ(s.observe(15, t(15)), A::repeat);
  EXPECT_EQ(s.observe(18, t(18)), A::jump);  // 16, 17 missing so far
  EXPECT_EQ(s.observe(16, t(16)), A::late);
  EXPECT_EQ(s.observe(16, t(16)), A::repeat);
  EXPECT_EQ(s.observe(9, t(9)), A::repeat);  // before the start: never counted missing
  EXPECT_EQ(s.observe(19, t(19)), A::next);
  EXPECT_EQ(s.observe(20, t(20)), A::next);
  EXPECT_EQ(s.gaps(), 4u);
  EXPECT_EQ(s.late(), 2u);
  EXPECT_EQ(s.gaps() - s.late(), 2u);  // 13 and 17 never arrived
  // A jump beyond the window, then stragglers.
  EXPECT_EQ(s.observe(20 + 2000, t(20 + 2000)), A::jump);
  EXPECT_EQ(s.gaps(), 4u + 1999u);
  EXPECT_EQ(s.observe(2020 - 5, t(2015)), A::late);
  EXPECT_EQ(s.observe(2020 - kSequenceWindow, t(2020 - kSequenceWindow)), A::stale);
  EXPECT_EQ(s.observe(2020 - kSequenceWindow + 1, t(2020 - kSequenceWindow + 1)), A::late);
  EXPECT_EQ(s.late(), 4u);
  EXPECT_EQ(s.stale(), 1u);
  // The sender restarts at 0 with later times: confirmed by the second
  // consecutive number (a single stray would not move the stream).
  EXPECT_EQ(s.observe(0, t(5000)), A::stale);
  EXPECT_EQ(s.observe(1, t(5001)), A::restart);
  EXPECT_EQ(s.observe(2, t(5002)), A::next);
  EXPECT_EQ(s.restarts(), 1u);
  EXPECT_EQ(s.gaps(), 4u + 1999u);
  // Wrap-free u64 at the top.
  SequenceTracker top;
  const std::uint64_t max = std::numeric_limits<std::uint64_t>::max();
  EXPECT_EQ(top.observe(max - 2, 1), A::first);
  EXPECT_EQ(top.observe(max, 2), A::jump);
  EXPECT_EQ(top.gaps(), 1u);
}

// Issue 17: the consumer (the emission engine's producer) sleeps on the
// queue until a deadline and is woken by a push, not by a poll. Every wait
// here has a 60 s deadline and must end within 30 s: a loaded host delays a
// wake-up by milliseconds, it cannot turn a missing notification into one.
TEST(PoseQueue, AWaitingConsumerIsWokenByAPushAndByWakeConsumer) {
  PoseQueue q(4);
  SourcedPose pose;
  pose.pose.t_ns = 1;
  constexpr TimeNs kLongNs = 60 * kNsPerSecond, kWithinNs = 30 * kNsPerSecond;
  // Nothing queued: the wait lasts to its deadline, and says it found nothing.
  TimeNs t0 = monotonic_now_ns();
  EXPECT_FALSE(q.wait_for_items_until(t0 + 20'000'000));
  EXPECT_GE(monotonic_now_ns() - t0, 20'000'000);
  EXPECT_EQ(q.wait_counters().deadline, 1u);

  // A push from another thread ends a 60 s sleep.
  auto wait_in_thread = [&](bool& result, TimeNs& returned_ns) {
    return std::thread([&] {
      result = q.wait_for_items_until(monotonic_now_ns() + kLongNs);
      returned_ns = monotonic_now_ns();
    });
  };
  bool result = false;
  TimeNs returned_ns = 0;
  std::thread consumer = wait_in_thread(result, returned_ns);
  std::this_thread::sleep_for(50ms);  // most likely asleep by now; if not, it finds the item on entry
  const TimeNs pushed_ns = monotonic_now_ns();
  EXPECT_TRUE(q.try_push(pose));
  consumer.join();
  EXPECT_TRUE(result);
  EXPECT_LT(returned_ns - pushed_ns, kWithinNs);
  PoseQueue::WaitCounters c = q.wait_counters();
  EXPECT_EQ(c.woken_by_push + c.items_on_entry, 1u);
  EXPECT_EQ(c.deadline, 1u);

  // An item already queued: at once, no sleep.
  t0 = monotonic_now_ns();
  EXPECT_TRUE(q.wait_for_items_until(t0 + kLongNs));
  EXPECT_LT(monotonic_now_ns() - t0, kWithinNs);
  EXPECT_EQ(q.wait_counters().items_on_entry, c.items_on_entry + 1);
  std::vector<SourcedPose> out;
  EXPECT_EQ(q.drain(out), 1u);

  // push_or_drop_oldest (the UDP sources' push) wakes it too.
  consumer = wait_in_thread(result, returned_ns);
  std::this_thread::sleep_for(50ms);
  EXPECT_FALSE(q.push_or_drop_oldest(pose));
  consumer.join();
  EXPECT_TRUE(result);
  EXPECT_EQ(q.drain(out), 1u);

  // wake_consumer() (a stop, the end of input) ends a sleep with nothing queued.
  c = q.wait_counters();
  consumer = wait_in_thread(result, returned_ns);
  std::this_thread::sleep_for(50ms);
  const TimeNs woken_ns = monotonic_now_ns();
  q.wake_consumer();
  consumer.join();
  EXPECT_FALSE(result);
  EXPECT_LT(returned_ns - woken_ns, kWithinNs);
  EXPECT_EQ(q.wait_counters().woken, c.woken + 1);
  // ... and one that comes before the wait is not lost: the next wait returns at once.
  q.wake_consumer();
  t0 = monotonic_now_ns();
  EXPECT_FALSE(q.wait_for_items_until(t0 + kLongNs));
  EXPECT_LT(monotonic_now_ns() - t0, kWithinNs);
  EXPECT_EQ(q.wait_counters().woken, c.woken + 2);
}

// The end of an input wakes the consumer sleeping on the queue, so it sees
// finished() at once instead of at its next deadline.
TEST(PoseQueue, TheEndOfTheInputWakesAWaitingConsumer) {
  int fds[2];
  ASSERT_EQ(::pipe(fds), 0);
  PoseSourceOptions options;
  options.log = [](std::string_view) {};
  auto source = make_fd_pose_source(fds[0], options);
  source->start();
  bool result = true;
  TimeNs returned_ns = 0;
  std::thread consumer([&] {
    result = source->queue().wait_for_items_until(monotonic_now_ns() + 60 * kNsPerSecond);
    returned_ns = monotonic_now_ns();
  });
  std::this_thread::sleep_for(50ms);
  const TimeNs closed_ns = monotonic_now_ns();
  ::close(fds[1]);  // end of input
  consumer.join();
  EXPECT_FALSE(result);
  EXPECT_LT(returned_ns - closed_ns, 30 * kNsPerSecond);
  EXPECT_TRUE(source->finished());
  EXPECT_EQ(source->queue().wait_counters().woken, 1u);
  source->stop();
  ::close(fds[0]);
}

TEST(PoseQueue, BoundedDropOldestAndDrain) {
  PoseQueue q(3);
  auto item = [](TimeNs t) {
    SourcedPose p;
    p.pose.t_ns = t;
    return p;
  };
  EXPECT_TRUE(q.try_push(item(1)));
  EXPECT_TRUE(q.try_push(item(2)));
  EXPECT_TRUE(q.try_push(item(3)));
  EXPECT_FALSE(q.try_push(item(4)));
  EXPECT_FALSE(q.wait_for_space(1ms));
  EXPECT_TRUE(q.push_or_drop_oldest(item(5)));  // drops 1
  EXPECT_TRUE(q.push_or_drop_oldest(item(6)));  // drops 2
  std::vector<SourcedPose> out;
  EXPECT_EQ(q.drain(out, 2), 2u);                // 3, 5; left: 6
  EXPECT_FALSE(q.push_or_drop_oldest(item(7)));  // 6, 7: room, nothing dropped
  EXPECT_TRUE(q.wait_for_space(0ms));
  SourcedPose first;
  EXPECT_TRUE(q.try_pop(first));
  EXPECT_EQ(first.pose.t_ns, 6);
  EXPECT_EQ(q.drain(out), 1u);
  EXPECT_FALSE(q.try_pop(first));
  EXPECT_EQ(q.size(), 0u);
  std::vector<TimeNs> times;
  for (const auto& p : out) times.push_back(p.pose.t_ns);
  EXPECT_EQ(times, (std::vector<TimeNs>{3, 5, 7}));
  EXPECT_EQ(q.popped(), 4u);
}

// ---------------------------------------------------------------- admission and scene

TEST(PoseAdmission, OrderingSceneAndAttitudeStepRules) {
  LogCapture log;
  PoseSourceOptions options;
  options.name = "unit";
  options.log = log.sink();
  options.resync_poses = 1;  // the ordering rules alone (acquisition: LiveTime tests)
  PoseAdmission a(options);
  SourcedPose out;
  auto admit = [&](const TrajectoryRecord& r) {
    a.received();
    return a.admit(r, std::nullopt, 7, out);
  };
  EXPECT_TRUE(admit(ned_quaternion_record(100, Vec3(1, 2, 3))));
  EXPECT_EQ(out.pose.t_ns, 100);
  EXPECT_EQ(out.pose.position_m, Vec3(1, 2, 3));
  EXPECT_EQ(out.receive_ns, 7);
  EXPECT_FALSE(out.sequence.has_value());
  EXPECT_FALSE(admit(ned_quaternion_record(100, Vec3(1, 2, 3))));  // duplicate
  EXPECT_FALSE(admit(ned_quaternion_record(99, Vec3(1, 2, 3))));   // out of order
  // Steps at and beyond the interpolation's limit pi - 1e-6 are refused;
  // 3.0 rad is representable.
  EXPECT_FALSE(admit(ned_quaternion_record(200, Vec3::Zero(), kPi - 1e-7)));
  EXPECT_FALSE(admit(ned_quaternion_record(201, Vec3::Zero(), -(kPi - 5e-7))));
  EXPECT_TRUE(admit(ned_quaternion_record(202, Vec3::Zero(), 3.0)));
  EXPECT_NEAR(so3::angle(out.pose.attitude), 3.0, 1e-12);
  // A refused step does not move the reference: 3.0 + 0.2 from the accepted.
  EXPECT_TRUE(admit(ned_quaternion_record(203, Vec3::Zero(), 3.2)));
  // Flat scene: Earth-fixed after local NED has no common frame.
  TrajectoryRecord geo;
  geo.t_ns = 300;
  geo.position = Vec3(45, 7, 100);
  EXPECT_FALSE(admit(geo));
  const PoseSourceCounters c = a.counters();
  EXPECT_EQ(c.received, 8u);
  EXPECT_EQ(c.accepted, 3u);
  EXPECT_EQ(c.duplicate, 1u);
  EXPECT_EQ(c.out_of_order, 1u);
  EXPECT_EQ(c.attitude_step, 2u);
  EXPECT_EQ(c.scene_refused, 1u);
  expect_accounted(c);
  EXPECT_TRUE(log.contains("unit: dropped (duplicate): line 0: time 0.0000001 s is equal to the last accepted pose's 0.0000001 s"));
  EXPECT_TRUE(log.contains("dropped (out_of_order)"));
  EXPECT_TRUE(log.contains("not below 3.141591653589793 rad"));
  EXPECT_TRUE(log.contains("dropped (scene_refused)"));

  // A custom step limit.
  PoseSourceOptions strict = options;
  strict.max_attitude_step_rad = 1.0;
  PoseAdmission b(strict);
  EXPECT_TRUE(b.admit(ned_quaternion_record(1, Vec3::Zero(), 0.0), std::nullopt, 0, out));
  EXPECT_FALSE(b.admit(ned_quaternion_record(2, Vec3::Zero(), 1.01), std::nullopt, 0, out));
  EXPECT_TRUE(b.admit(ned_quaternion_record(3, Vec3::Zero(), 0.99), std::nullopt, 0, out));

  // ecef scene: local NED refused, and an ECEF position that overflows in
  // the conversion never reaches the queue.
  PoseSourceOptions ecef = options;
  ecef.physics = Physics::ecef;
  PoseAdmission e(ecef);
  EXPECT_FALSE(e.admit(ned_quaternion_record(1, Vec3::Zero()), std::nullopt, 0, out));
  PoseSourceOptions flat_options = options;
  PoseAdmission f(flat_options);
  TrajectoryRecord far;
  far.t_ns = 1;
  far.position = Vec3(45, 45, 0);  // geodetic: the tangent frame's origin
  EXPECT_TRUE(f.admit(far, std::nullopt, 0, out));
  // Each ECEF coordinate is finite, but "down" there sums three of them.
  far.t_ns = 2;
  far.position_kind = PositionKind::ecef;
  far.position = Vec3(1.7e308, 1.7e308, 1.7e308);
  EXPECT_FALSE(f.admit(far, std::nullopt, 0, out));
  EXPECT_EQ(f.counters().scene_refused, 1u);
}

// ---------------------------------------------------------------- live time (issue 13 W3/W4/C1)

namespace {

// A circle at 10 m/s, yawing 0.2 rad/s, one pose every 10 ms from t0_ns.
TrajectoryRecord circle_record(TimeNs t0_ns, int k) {
  const double t_s = 0.01 * k;
  return ned_quaternion_record(t0_ns + static_cast<TimeNs>(k) * 10'000'000,
                               Vec3(50.0 * std::sin(0.2 * t_s), 50.0 * (1.0 - std::cos(0.2 * t_s)), 0.0), 0.2 * t_s);
}

// Admits every record (receive time = 10 ms per record) and collects what is released.
std::vector<SourcedPose> admit_all(PoseAdmission& a, const std::vector<TrajectoryRecord>& records) {
  std::vector<SourcedPose> got;
  SourcedPose out;
  for (std::size_t i = 0; i < records.size(); ++i) {
    a.received();
    if (a.admit(records[i], std::nullopt, static_cast<TimeNs>(i) * 10'000'000, out)) {
      got.push_back(out);
      while (a.take_released(out)) got.push_back(out);
    }
  }
  return got;
}

// The smoother's output for the released poses; every push must be accepted.
std::vector<StreamSample> smooth(const std::vector<SourcedPose>& poses, std::size_t& refused, double max_gap_s = 10.0) {
  PipelineOptions o;
  o.rate_hz = 100;
  o.kernel.delta = 20;
  o.gap_policy = GapPolicy::split;
  o.max_gap_s = max_gap_s;
  StreamPipeline engine(o);
  std::vector<StreamSample> samples;
  StreamSample x;
  refused = 0;
  for (const SourcedPose& p : poses) {
    try {
      engine.push(p.pose);
    } catch (const std::exception&) {
      ++refused;
    }
    while (engine.pop(x)) samples.push_back(x);
  }
  if (engine.knots_pushed() >= 2) engine.finish();
  while (engine.pop(x)) samples.push_back(x);
  return samples;
}

}  // namespace

// One stray first datagram (time 0, INT64_MIN, near INT64_MAX, 1 h in the
// future), then the real stream: the stray never reaches the smoother, the
// stream is acquired after resync_poses consistent poses and smooths exactly
// as without the stray.
TEST(LiveTime, AStrayFirstPoseDoesNotBlockTheStream) {
  const TimeNs t0 = 1'700'000'000 * kNsPerSecond;
  std::vector<TrajectoryRecord> real;
  for (int k = 0; k < 200; ++k) real.push_back(circle_record(t0, k));
  PoseSourceOptions options;
  options.name = "unit";
  PoseAdmission clean(options);
  std::size_t refused = 0;
  const std::vector<SourcedPose> clean_poses = admit_all(clean, real);
  ASSERT_EQ(clean_poses.size(), real.size());
  const std::vector<StreamSample> expected = smooth(clean_poses, refused);
  ASSERT_EQ(refused, 0u);
  ASSERT_GT(expected.size(), 150u);
  for (const TimeNs stray_t : {TimeNs{0}, std::numeric_limits<TimeNs>::min(), std::numeric_limits<TimeNs>::max() - 1,
                               t0 + 3600 * kNsPerSecond}) {
    SCOPED_TRACE("stray time " + std::to_string(stray_t));
    LogCapture log;
    options.log = log.sink();
    PoseAdmission a(options);
    std::vector<TrajectoryRecord> records = {ned_quaternion_record(stray_t, Vec3(1e5, -3e4, 7.0), 2.0)};
    records.insert(records.end(), real.begin(), real.end());
    const std::vector<SourcedPose> poses = admit_all(a, records);
    ASSERT_EQ(poses.size(), real.size());
    EXPECT_EQ(poses.front().pose.t_ns, t0);
    const PoseSourceCounters c = a.counters();
    EXPECT_EQ(c.accepted, real.size());
    EXPECT_EQ(c.time_out_of_range + c.time_jump, 1u);
    EXPECT_EQ(c.held, 0u);
    expect_accounted(c);
    const std::vector<StreamSample> got = smooth(poses, refused);
    EXPECT_EQ(refused, 0u);
    ASSERT_EQ(got.size(), expected.size());
    for (std::size_t i = 0; i < got.size(); ++i) {
      ASSERT_EQ(got[i].imu.t_ns, expected[i].imu.t_ns);
      ASSERT_EQ(got[i].imu.gyro_rad_s, expected[i].imu.gyro_rad_s);
      ASSERT_EQ(got[i].imu.accel_m_s2, expected[i].imu.accel_m_s2);
    }
  }
}

// A stray 1 h ahead in the middle of a stream is dropped (time_jump); a
// sender restart (times back to 0) is re-acquired after resync_poses poses,
// counted and logged, on the running timeline: the released times keep
// increasing, one gap limit or more after the last, so the smoother starts a
// new segment and never refuses a pose.
TEST(LiveTime, JumpsAndRestartsAreReacquiredOnTheRunningTimeline) {
  const TimeNs t0 = 1'700'000'000 * kNsPerSecond;
  std::vector<TrajectoryRecord> records;
  for (int k = 0; k < 100; ++k) records.push_back(circle_record(t0, k));
  records.push_back(circle_record(t0 + 3600 * kNsPerSecond, 100));  // stray, 1 h ahead
  for (int k = 100; k < 200; ++k) records.push_back(circle_record(t0, k));
  for (int k = 0; k < 150; ++k) records.push_back(circle_record(0, k));  // the sender restarted: t from 0
  LogCapture log;
  PoseSourceOptions options;
  options.name = "unit";
  options.log = log.sink();
  PoseAdmission a(options);
  const std::vector<SourcedPose> poses = admit_all(a, records);
  const PoseSourceCounters c = a.counters();
  EXPECT_EQ(c.time_jump, 1u);
  EXPECT_EQ(c.resyncs, 1u);
  EXPECT_EQ(c.out_of_order + c.duplicate, 0u);
  EXPECT_EQ(c.accepted, 350u);
  ASSERT_EQ(poses.size(), 350u);
  for (std::size_t i = 1; i < poses.size(); ++i) ASSERT_LT(poses[i - 1].pose.t_ns, poses[i].pose.t_ns) << i;
  // The restarted stream: its own spacing, shifted past one gap limit.
  EXPECT_GT(poses[200].pose.t_ns - poses[199].pose.t_ns, options.max_time_step_ns);
  EXPECT_EQ(poses[201].pose.t_ns - poses[200].pose.t_ns, 10'000'000);
  expect_accounted(c);
  EXPECT_TRUE(log.contains("stream re-acquired"));
  std::size_t refused = 0;
  const std::vector<StreamSample> got = smooth(poses, refused);
  EXPECT_EQ(refused, 0u);
  for (const StreamSample& x : got) ASSERT_TRUE(x.imu.gyro_rad_s.allFinite() && x.imu.accel_m_s2.allFinite());
}

// Issue 13 (left open): a re-acquired stream was placed max_time_step_ns
// (10 s) after the last pose whatever the engine's gap limit, so live output
// stayed silent 10 s after a sender restart. It is placed just beyond the
// engine's gap limit (max_gap_ns, the scene's max_gap_s): with max_gap_s = 1 s
// the hole in the released times is 1 s + 1 ns, the smoother starts a new
// segment there (nothing refused), and its output has a 1 s hole, not 10 s.
TEST(LiveTime, ARestartIsPlacedJustBeyondTheEnginesGapLimit) {
  const TimeNs t0 = 1'700'000'000 * kNsPerSecond;
  std::vector<TrajectoryRecord> records;
  for (int k = 0; k < 100; ++k) records.push_back(circle_record(t0, k));
  for (int k = 0; k < 150; ++k) records.push_back(circle_record(0, k));  // the sender restarted: t from 0
  PoseSourceOptions options;
  options.name = "unit";
  options.max_gap_ns = kNsPerSecond;  // config/live-udp.toml: max_gap_s = 1.0
  PoseAdmission a(options);
  const std::vector<SourcedPose> poses = admit_all(a, records);
  ASSERT_EQ(poses.size(), 250u);
  EXPECT_EQ(a.counters().resyncs, 1u);
  // Receive times 10 ms apart: less real time elapsed than the gap limit.
  EXPECT_EQ(poses[100].pose.t_ns - poses[99].pose.t_ns, kNsPerSecond + 1);
  std::size_t refused = 0;
  const std::vector<StreamSample> got = smooth(poses, refused, 1.0);
  EXPECT_EQ(refused, 0u);
  TimeNs hole_ns = 0;
  for (std::size_t i = 1; i < got.size(); ++i) hole_ns = std::max(hole_ns, got[i].imu.t_ns - got[i - 1].imu.t_ns);
  // The silent interval of the output: the gap limit, to one sample period.
  EXPECT_GE(hole_ns, kNsPerSecond);
  EXPECT_LE(hole_ns, kNsPerSecond + 10'000'000) << "silent for " << hole_ns << " ns";
}

// W2 through admission: a 179 deg heading glitch is below pi (not an
// antipodal step) but more than a smoothing chart holds: dropped, counted,
// logged, and the stream goes on.
TEST(LiveTime, AHeadingGlitchIsDroppedCountedAndLogged) {
  LogCapture log;
  PoseSourceOptions options;
  options.name = "unit";
  options.log = log.sink();
  PoseAdmission a(options);
  std::vector<TrajectoryRecord> records;
  for (int k = 0; k < 100; ++k) records.push_back(circle_record(0, k));
  TrajectoryRecord glitch = circle_record(0, 50);
  glitch.t_ns += 5'000'000;
  glitch.attitude = Eigen::Vector4d(std::cos(kPi * 179.0 / 360.0), 0.0, 0.0, std::sin(kPi * 179.0 / 360.0));
  records.insert(records.begin() + 51, glitch);
  const std::vector<SourcedPose> poses = admit_all(a, records);
  EXPECT_EQ(poses.size(), 100u);
  EXPECT_EQ(a.counters().chart_span, 1u);
  EXPECT_TRUE(log.contains("dropped (chart_span)"));
  std::size_t refused = 0;
  (void)smooth(poses, refused);
  EXPECT_EQ(refused, 0u);
}

// Sequence numbers modulo 2^64 with a plausibility window: one datagram
// numbered 2^64 - 1 in a stream must not make lost() read 1.8e19.
TEST(SequenceTracker, OneStrayNumberDoesNotCountLosses) {
  using A = SequenceTracker::Arrival;
  SequenceTracker s;
  auto t = [](std::uint64_t seq) { return static_cast<TimeNs>(seq) * 1'000'000; };
  for (std::uint64_t k = 1000; k < 1010; ++k) s.observe(k, t(k));
  EXPECT_EQ(s.observe(std::numeric_limits<std::uint64_t>::max(), t(1010)), A::stale);
  EXPECT_EQ(s.observe(1000 + 2'000'000, t(1010)), A::stale);
  EXPECT_EQ(s.observe(1010, t(1010)), A::next);
  EXPECT_EQ(s.gaps(), 0u);
  EXPECT_EQ(s.restarts(), 0u);
  // Modulo 2^64: the successor of 2^64 - 1 is 0.
  SequenceTracker top;
  top.observe(std::numeric_limits<std::uint64_t>::max(), 1);
  EXPECT_EQ(top.observe(0, 2), A::next);
  EXPECT_EQ(top.gaps(), 0u);
}

TEST(ScenePoseConverter, FirstEarthFixedRecordIsTheFlatOrigin) {
  ScenePoseConverter flat(Physics::flat);
  TrajectoryRecord r;
  r.position_kind = PositionKind::geodetic;
  r.position = Vec3(45.0, 7.0, 300.0);
  r.attitude = Eigen::Vector4d(30.0, 0.0, 0.0, 0.0);
  const Pose first = flat.convert(r);
  EXPECT_LT(first.position_m.norm(), 1e-8);
  // heading 30 deg at the origin is heading 30 deg in the tangent frame.
  EXPECT_LT((first.attitude - attitude::rotation_from_hpr({30.0 * kPi / 180, 0, 0})).norm(), 1e-14);
  ASSERT_TRUE(flat.tangent_frame().has_value());
  // 100 m straight up from the origin is 100 m "down" negative.
  r.t_ns = 1;
  r.position.z() = 400.0;
  const Pose second = flat.convert(r);
  EXPECT_LT((second.position_m - Vec3(0, 0, -100.0)).norm(), 1e-8);
  // The same record in ECEF form lands at the same tangent-frame point.
  TrajectoryRecord e = r;
  e.position_kind = PositionKind::ecef;
  e.position = earth::ecef_from_geodetic({45.0 * kPi / 180, 7.0 * kPi / 180, 400.0});
  EXPECT_LT((flat.convert(e).position_m - second.position_m).norm(), 1e-8);
  // Local NED after Earth-fixed records: refused, converter unchanged.
  EXPECT_THROW(flat.convert(ned_quaternion_record(2, Vec3::Zero())), TrajectoryFormatError);
  EXPECT_LT((flat.convert(r).position_m - second.position_m).norm(), 1e-8);

  // poses_in_scene is the converter over a file.
  const Trajectory t = parse_trajectory_csv(
      "time_s,lat_deg,lon_deg,h_m,heading_deg,pitch_deg,roll_deg\n0,45,7,300,30,0,0\n1,45,7,400,30,0,0\n", "t.csv");
  const std::vector<Pose> poses = poses_in_scene(t, Physics::flat);
  ASSERT_EQ(poses.size(), 2u);
  EXPECT_EQ(poses[1].position_m, second.position_m);
  EXPECT_EQ(poses[0].attitude, first.attitude);
}

// ---------------------------------------------------------------- UDP loopback

class UdpSender {
 public:
  explicit UdpSender(std::uint16_t port) : sender_(port) {}
  void send(const Bytes& d) { ASSERT_TRUE(sender_.send(d)); }

 private:
  test::LoopbackUdpSender sender_;
};

TEST(UdpPoseSource, LoopbackCountsEveryDropDuplicateReorderAndCorruption) {
  LogCapture log;
  PoseSourceOptions options;
  options.log = log.sink();
  auto source = make_udp_pose_source({"127.0.0.1", 0}, options);
  ASSERT_NE(source->local_port(), 0);
  EXPECT_EQ(source->name(), "udp 127.0.0.1:" + std::to_string(source->local_port()));
  source->start();

  auto pose_datagram = [](std::uint64_t seq) {
    return datagram(seq, ned_quaternion_record(1'000'000'000 + static_cast<TimeNs>(seq) * 10'000'000,
                                               Vec3(static_cast<double>(seq), 0.5, -2.0), 0.01 * static_cast<double>(seq)));
  };
  Bytes corrupted = pose_datagram(7);
  corrupted[30] ^= 0x10;
  Bytes bad_latitude = datagram(9, [] {
    TrajectoryRecord r;
    r.t_ns = 1'090'000'000;
    r.position = Vec3(95.0, 0, 0);
    return r;
  }());
  const std::string garbage = "hello world";
  const Bytes garbage_bytes(garbage.begin(), garbage.end());
  // After 11, the sender restarts at sequence 0 with a later time (the
  // second consecutive number confirms the restart).
  const Bytes restarted =
      datagram(0, ned_quaternion_record(2'000'000'000, Vec3(0, 0, 0)));
  const Bytes restarted_next =
      datagram(1, ned_quaternion_record(2'010'000'000, Vec3(0, 0, 0)));

  const TimeNs before_ns = monotonic_now_ns();
  {
    UdpSender sender(source->local_port());
    for (const Bytes& d : {pose_datagram(0), pose_datagram(1), pose_datagram(2), /* 3 lost */ pose_datagram(4),
                           pose_datagram(4) /* duplicated */, pose_datagram(6), pose_datagram(5) /* reordered */,
                           corrupted, pose_datagram(8), garbage_bytes, bad_latitude, pose_datagram(10),
                           pose_datagram(11), restarted, restarted_next}) {
      sender.send(d);
    }
  }
  // One snapshot per datagram, published once it is classified and its pose
  // queued (docs/pose-wire-format.md §3.2): received == 15 is the condition
  // that every count and pose below is in (issue 26: counted received first,
  // it let this test read accepted 9 of 10 under ASan).
  ASSERT_TRUE(wait_until([&] { return source->counters().received == 15; })) << source->counters().received;
  const TimeNs after_ns = monotonic_now_ns();
  const PoseSourceCounters c = source->counters();
  EXPECT_EQ(c.accepted, 10u);  // 0 1 2 4 6 8 10 11 and the restarted 0 1
  EXPECT_EQ(c.duplicate, 1u);
  EXPECT_EQ(c.out_of_order, 1u);  // 5 came after 6
  EXPECT_EQ(datagram_error(c, DatagramError::bad_checksum), 1u);
  EXPECT_EQ(datagram_error(c, DatagramError::bad_magic), 1u);
  EXPECT_EQ(datagram_error(c, DatagramError::bad_value), 1u);
  EXPECT_EQ(c.ignored, 0u);
  EXPECT_EQ(c.sequence_gaps, 3u);  // 3, 5, 7 skipped when they were due
  EXPECT_EQ(c.late, 1u);           // 5
  EXPECT_EQ(c.lost(), 2u);         // 3 and 7 (corrupted) never arrived intact
  EXPECT_EQ(c.stale, 0u);
  EXPECT_EQ(c.sequence_restarts, 1u);
  EXPECT_EQ(c.overflow_dropped, 0u);
  EXPECT_EQ(c.attitude_step + c.scene_refused, 0u);
  expect_accounted(c);

  std::vector<SourcedPose> poses;
  source->queue().drain(poses);
  ASSERT_EQ(poses.size(), 10u);
  const std::vector<std::uint64_t> expected_sequences = {0, 1, 2, 4, 6, 8, 10, 11, 0, 1};
  TimeNs previous_receive_ns = before_ns;
  for (std::size_t i = 0; i < poses.size(); ++i) {
    const SourcedPose& p = poses[i];
    ASSERT_TRUE(p.sequence.has_value());
    EXPECT_EQ(*p.sequence, expected_sequences[i]);
    EXPECT_GE(p.receive_ns, previous_receive_ns);
    EXPECT_LE(p.receive_ns, after_ns);
    previous_receive_ns = p.receive_ns;
    EXPECT_EQ(p.line, 0u);
  }
  // Flat scene, local NED input: position as sent, attitude its rotation.
  EXPECT_EQ(poses[3].pose.t_ns, 1'040'000'000);
  EXPECT_EQ(poses[3].pose.position_m, Vec3(4.0, 0.5, -2.0));
  EXPECT_LT((poses[3].pose.attitude - so3::exp(Vec3(0, 0, 0.04))).norm(), 1e-14);
  EXPECT_EQ(poses[8].pose.t_ns, 2'000'000'000);

  source->stop();
  EXPECT_TRUE(log.contains("dropped datagram (bad_checksum): from 127.0.0.1:"));
  EXPECT_TRUE(log.contains("1 datagram(s) missing before sequence 4"));
  EXPECT_TRUE(log.contains("(lat_deg): expected a latitude in [-90, 90] degrees, got 95"));
  EXPECT_TRUE(log.contains("sender restarted: sequence 1 after 11"));
}

// Issue 17: a datagram's receive_ns is when it reached the socket (the
// kernel's time stamp), not when the source's thread got round to reading
// it: datagrams sent before the source's thread even started carry their
// arrival, which lies before the start (the read time would lie after it).
TEST(UdpPoseSource, ReceiveTimeIsTheKernelsArrivalNotTheRead) {
  LogCapture log;
  PoseSourceOptions options;
  options.log = log.sink();
  auto source = make_udp_pose_source({"127.0.0.1", 0}, options);
  std::this_thread::sleep_for(50ms);  // the socket's time stamps are on
  const TimeNs before_send_ns = monotonic_now_ns();
  {
    UdpSender sender(source->local_port());
    sender.send(datagram(0, ned_quaternion_record(1'000'000'000, Vec3::Zero())));
    sender.send(datagram(1, ned_quaternion_record(1'010'000'000, Vec3::Zero())));
  }
  const TimeNs after_send_ns = monotonic_now_ns();
  std::this_thread::sleep_for(200ms);  // queued in the socket, unread
  const TimeNs start_ns = monotonic_now_ns();
  source->start();
  ASSERT_TRUE(wait_until([&] { return source->queue().size() == 2; }));
  std::vector<SourcedPose> poses;
  ASSERT_EQ(source->queue().drain(poses), 2u);
  for (const SourcedPose& p : poses) {
    EXPECT_GE(p.receive_ns, before_send_ns);
    EXPECT_LE(p.receive_ns, after_send_ns);
    EXPECT_LT(p.receive_ns, start_ns);
  }
  EXPECT_LE(poses[0].receive_ns, poses[1].receive_ns);
}

TEST(UdpPoseSource, BurstBeyondTheQueueDropsTheOldest) {
  LogCapture log;
  PoseSourceOptions options;
  options.log = log.sink();
  options.queue_capacity = 4;
  auto source = make_udp_pose_source({"127.0.0.1", 0}, options);
  source->start();
  {
    UdpSender sender(source->local_port());
    for (std::uint64_t seq = 0; seq < 10; ++seq)
      sender.send(datagram(seq, ned_quaternion_record(static_cast<TimeNs>(seq) + 1, Vec3::Zero())));
  }
  ASSERT_TRUE(wait_until([&] { return source->counters().received == 10; }));
  const PoseSourceCounters c = source->counters();
  EXPECT_EQ(c.accepted, 10u);
  EXPECT_EQ(c.overflow_dropped, 6u);
  EXPECT_EQ(c.lost(), 0u);  // overflow is the consumer's loss, not the network's
  std::vector<SourcedPose> poses;
  EXPECT_EQ(source->queue().drain(poses), 4u);
  for (std::size_t i = 0; i < poses.size(); ++i) EXPECT_EQ(*poses[i].sequence, 6 + i);
  EXPECT_EQ(source->queue().popped(), 4u);
}

TEST(UdpPoseSource, BindFailureIsAClearError) {
  auto first = make_udp_pose_source({"127.0.0.1", 0}, {});
  try {
    make_udp_pose_source({"127.0.0.1", first->local_port()}, {});
    ADD_FAILURE() << "second bind to the same port succeeded";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("cannot bind"), std::string::npos) << e.what();
  }
  EXPECT_THROW(make_udp_pose_source({"localhost", 0}, {}), std::runtime_error);  // not an address literal
}

// ---------------------------------------------------------------- TCP loopback

class TcpClient {
 public:
  explicit TcpClient(std::uint16_t port) : fd_(::socket(AF_INET, SOCK_STREAM, 0)) {
    sockaddr_in to{};
    to.sin_family = AF_INET;
    to.sin_port = htons(port);
    to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    connected_ = ::connect(fd_, reinterpret_cast<const sockaddr*>(&to), sizeof to) == 0;
  }
  ~TcpClient() { close(); }
  bool connected() const { return connected_; }
  void send(const std::string& text) {
    std::size_t done = 0;
    while (done < text.size()) {
      const ssize_t n = ::send(fd_, text.data() + done, text.size() - done, MSG_NOSIGNAL);
      ASSERT_GT(n, 0);
      done += static_cast<std::size_t>(n);
    }
  }
  // True if the server closed the connection (read returns 0) within 5 s.
  bool closed_by_peer() {
    timeval timeout{5, 0};
    ::setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &timeout, sizeof timeout);
    char c = 0;
    return ::recv(fd_, &c, 1, 0) == 0;
  }
  void close() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }

 private:
  int fd_;
  bool connected_ = false;
};

std::string ned_line(double t_s, double north_m) {
  char line[128];
  std::snprintf(line, sizeof line, "%.2f,%.3f,0.5,-1,10,0,0\n", t_s, north_m);
  return line;
}

TEST(TcpPoseSource, LoopbackOneClientAtATimeWithBackpressure) {
  LogCapture log;
  PoseSourceOptions options;
  options.log = log.sink();
  options.queue_capacity = 4;
  auto source = make_tcp_pose_source({"127.0.0.1", 0}, options);
  source->start();

  constexpr int kRecords = 50;
  std::string text = "# imuemu-pose-lines v1\ntime_s,north_m,east_m,down_m,heading_deg,pitch_deg,roll_deg\n";
  for (int i = 0; i < kRecords; ++i) {
    text += ned_line(0.01 * i, i);
    if (i == 20) text += ned_line(0.01 * i, 999.0);          // duplicate time
    if (i == 30) text += "0.305,1,2,3,10,91,0\n";             // pitch out of range (line 35)
    if (i == 40) text += "\n# comment\n";
  }
  text += "0.6,1,2";  // no final newline: unterminated
  {
    TcpClient a(source->local_port());
    ASSERT_TRUE(a.connected());
    a.send(text);
    // The source holds 4 poses and stops reading; nobody drains yet.
    ASSERT_TRUE(wait_until([&] { return source->queue().size() == 4; }));
    ASSERT_TRUE(wait_until([&] { return source->counters().backpressure_events >= 1; }));
    // A second client while the first is connected is closed at once.
    TcpClient b(source->local_port());
    ASSERT_TRUE(b.connected());
    EXPECT_TRUE(b.closed_by_peer());
    EXPECT_TRUE(wait_until([&] { return source->counters().connections_refused == 1; }));
    // Drain everything while the client is still connected.
    std::vector<SourcedPose> poses;
    ASSERT_TRUE(wait_until([&] {
      source->queue().drain(poses);
      return poses.size() == kRecords;
    })) << poses.size();
    for (int i = 0; i < kRecords; ++i) {
      ASSERT_EQ(poses[static_cast<std::size_t>(i)].pose.t_ns, i * 10'000'000);
      ASSERT_EQ(poses[static_cast<std::size_t>(i)].pose.position_m, Vec3(i, 0.5, -1.0));
      ASSERT_FALSE(poses[static_cast<std::size_t>(i)].sequence.has_value());
    }
    EXPECT_EQ(poses[0].line, 3u);
    EXPECT_EQ(poses.back().line, static_cast<std::size_t>(kRecords + 2 + 1 + 1 + 2));
    a.close();
  }
  ASSERT_TRUE(wait_until([&] { return line_error(source->counters(), LineError::unterminated_line) == 1; }));
  PoseSourceCounters c = source->counters();
  EXPECT_EQ(c.connections, 1u);
  EXPECT_EQ(c.connections_refused, 1u);
  EXPECT_EQ(c.accepted, static_cast<std::uint64_t>(kRecords));
  EXPECT_EQ(c.duplicate, 1u);
  EXPECT_EQ(line_error(c, LineError::bad_record), 1u);
  EXPECT_EQ(c.ignored, 4u);  // version, header, blank, comment
  EXPECT_EQ(c.received, static_cast<std::uint64_t>(kRecords) + 1 + 1 + 4 + 1);
  EXPECT_GE(c.backpressure_events, 1u);
  EXPECT_EQ(c.overflow_dropped, 0u);
  expect_accounted(c);
  EXPECT_TRUE(log.contains(source->name() + ": client connected: connection 1 (127.0.0.1:"));
  EXPECT_TRUE(log.contains(source->name() + ": dropped line (bad_record): connection 1 (127.0.0.1:"));
  EXPECT_TRUE(log.contains("):35: column 'pitch_deg' (6): expected a pitch in [-90, 90] degrees, got '91'"));

  // The next client starts a new stream (its own header and line numbers);
  // the order rule carries over from the previous client.
  {
    TcpClient d(source->local_port());
    ASSERT_TRUE(d.connected());
    d.send("time_s,north_m,east_m,down_m,heading_deg,pitch_deg,roll_deg\n" + ned_line(0.2, 1) + ned_line(0.7, 2));
    ASSERT_TRUE(wait_until([&] { return source->counters().accepted == kRecords + 1; }));
  }
  c = source->counters();
  EXPECT_EQ(c.connections, 2u);
  EXPECT_EQ(c.out_of_order, 1u);
  SourcedPose last;
  ASSERT_TRUE(source->queue().try_pop(last));
  EXPECT_EQ(last.pose.t_ns, 700'000'000);
  EXPECT_EQ(last.line, 3u);
  source->stop();
}

// Issue 13 H1: a client that connects and sends nothing held the only slot
// forever (no idle timeout), and a sender whose old connection went half-open
// could never reconnect. Now a silent client is closed after the idle timeout
// and a new client replaces one that has been idle for the takeover time.
TEST(TcpPoseSource, SilentClientIsClosedAfterTheIdleTimeout) {
  LogCapture log;
  PoseSourceOptions options;
  options.log = log.sink();
  NetEndpoint endpoint{"127.0.0.1", 0};
  endpoint.tcp_idle_timeout_ns = 200'000'000;
  endpoint.tcp_takeover_idle_ns = 3600 * kNsPerSecond;  // only the idle timeout frees the slot here
  auto source = make_tcp_pose_source(endpoint, options);
  source->start();
  TcpClient silent(source->local_port());
  ASSERT_TRUE(silent.connected());
  EXPECT_TRUE(silent.closed_by_peer());  // within 5 s; before: never
  EXPECT_TRUE(wait_until([&] { return source->counters().connections_idle_closed == 1; }));
  EXPECT_TRUE(log.contains(source->name() + ": client disconnected: connection 1 (127.0.0.1:"));
  EXPECT_TRUE(log.contains("idle timeout 200 ms)"));
  // The slot is free: the real sender is served.
  TcpClient sender(source->local_port());
  ASSERT_TRUE(sender.connected());
  sender.send("time_s,north_m,east_m,down_m,heading_deg,pitch_deg,roll_deg\n" + ned_line(0.1, 1) + ned_line(0.2, 2));
  EXPECT_TRUE(wait_until([&] { return source->counters().accepted == 2; }));
  const PoseSourceCounters c = source->counters();
  EXPECT_EQ(c.connections, 2u);
  EXPECT_EQ(c.connections_refused, 0u);
  EXPECT_EQ(c.connections_replaced, 0u);
  expect_accounted(c);
  source->stop();
}

TEST(TcpPoseSource, NewClientReplacesAnIdleOneAndIsRefusedByAnActiveOne) {
  LogCapture log;
  PoseSourceOptions options;
  options.log = log.sink();
  NetEndpoint endpoint{"127.0.0.1", 0};
  endpoint.tcp_idle_timeout_ns = 0;  // never closed for idleness: only the takeover frees the slot
  endpoint.tcp_takeover_idle_ns = 100'000'000;
  auto source = make_tcp_pose_source(endpoint, options);
  source->start();
  const std::string header = "time_s,north_m,east_m,down_m,heading_deg,pitch_deg,roll_deg\n";
  // The old connection: one pose, then silence, as a connection whose peer
  // vanished without a FIN looks from the server.
  TcpClient old_connection(source->local_port());
  ASSERT_TRUE(old_connection.connected());
  old_connection.send(header + ned_line(0.1, 1) + ned_line(0.2, 1));  // two: the stream is acquired (resync_poses)
  ASSERT_TRUE(wait_until([&] { return source->counters().accepted == 2; }));
  std::this_thread::sleep_for(1000ms);  // >> the 100 ms takeover time
  TcpClient reconnected(source->local_port());
  ASSERT_TRUE(reconnected.connected());
  reconnected.send(header + ned_line(0.3, 2));
  EXPECT_TRUE(wait_until([&] { return source->counters().accepted == 3; }));  // before: refused, stays 2
  EXPECT_TRUE(old_connection.closed_by_peer());
  PoseSourceCounters c = source->counters();
  EXPECT_EQ(c.connections, 2u);
  EXPECT_EQ(c.connections_replaced, 1u);
  EXPECT_EQ(c.connections_refused, 0u);
  EXPECT_TRUE(log.contains("ms, replaced by a new client 127.0.0.1:"));

  // A client that keeps streaming keeps its slot: a third one is refused.
  // (Each pose arrives well within the takeover time; the refusal does not
  // depend on the host's speed as long as the sender is not stalled 100 ms.)
  std::atomic<bool> streaming{true};
  std::thread feeder([&] {
    for (int i = 4; streaming; ++i) {
      reconnected.send(ned_line(0.1 * i, i));
      std::this_thread::sleep_for(5ms);
    }
  });
  ASSERT_TRUE(wait_until([&] { return source->counters().accepted >= 6; }));
  TcpClient intruder(source->local_port());
  ASSERT_TRUE(intruder.connected());
  EXPECT_TRUE(intruder.closed_by_peer());
  streaming = false;
  feeder.join();
  c = source->counters();
  EXPECT_EQ(c.connections_refused, 1u);
  EXPECT_EQ(c.connections_replaced, 1u);
  expect_accounted(c);
  source->stop();
}

// ---------------------------------------------------------------- stdin (a pipe)

TEST(FdPoseSource, PipeWithBackpressureLongLinesAndEndOfInput) {
  int fds[2];
  ASSERT_EQ(::pipe(fds), 0);
  LogCapture log;
  PoseSourceOptions options;
  options.log = log.sink();
  options.queue_capacity = 2;
  options.physics = Physics::ecef;
  auto source = make_fd_pose_source(fds[0], options);
  EXPECT_EQ(source->name(), "fd " + std::to_string(fds[0]));
  source->start();

  constexpr int kRecords = 20;
  std::string text = "time_s,lat_deg,lon_deg,h_m,qw,qx,qy,qz\n";     // line 1
  text += std::string(kMaxPoseLineBytes + 10, '9') + "\n";             // line 2: too long
  for (int i = 0; i < kRecords; ++i) {                                 // lines 3..22
    char line[128];
    std::snprintf(line, sizeof line, "%d,45,7,%d,1,0,0,0\n", i, 100 + i);
    text += line;
  }
  text += "25,45,7,100,1,0,0,0.1\n";  // line 23: not a unit quaternion
  text += "26,45,7,100";              // unterminated
  ASSERT_EQ(::write(fds[1], text.data(), text.size()), static_cast<ssize_t>(text.size()));
  ::close(fds[1]);

  // Queue of 2 and nobody draining: the reader must stop.
  ASSERT_TRUE(wait_until([&] { return source->counters().backpressure_events >= 1; }));
  EXPECT_FALSE(source->finished());
  std::vector<SourcedPose> poses;
  ASSERT_TRUE(wait_until([&] {
    source->queue().drain(poses);
    return source->finished();
  }));
  source->queue().drain(poses);
  ASSERT_EQ(poses.size(), static_cast<std::size_t>(kRecords));
  for (int i = 0; i < kRecords; ++i) {
    const SourcedPose& p = poses[static_cast<std::size_t>(i)];
    EXPECT_EQ(p.pose.t_ns, i * kNsPerSecond);
    EXPECT_EQ(p.line, static_cast<std::size_t>(i) + 3);
    // ecef scene: Eq. 1.1 of the geodetic position.
    EXPECT_LT((p.pose.position_m - earth::ecef_from_geodetic({45 * kPi / 180, 7 * kPi / 180, 100.0 + i})).norm(), 1e-6);
  }
  const PoseSourceCounters c = source->counters();
  EXPECT_EQ(c.received, static_cast<std::uint64_t>(kRecords) + 4);
  EXPECT_EQ(c.ignored, 1u);
  EXPECT_EQ(c.accepted, static_cast<std::uint64_t>(kRecords));
  EXPECT_EQ(line_error(c, LineError::line_too_long), 1u);
  EXPECT_EQ(line_error(c, LineError::bad_record), 1u);
  EXPECT_EQ(line_error(c, LineError::unterminated_line), 1u);
  EXPECT_GE(c.backpressure_events, 1u);
  expect_accounted(c);
  source->stop();
  // Line numbers stay right after the refused long line.
  const std::string name = "fd " + std::to_string(fds[0]);
  EXPECT_TRUE(log.contains(name + ": dropped line (line_too_long): " + name + ":2: line longer than 4096 bytes"));
  EXPECT_TRUE(log.contains(name + ":23: column 'qw' (5): expected a unit quaternion"));
  EXPECT_TRUE(log.contains(name + ":24: the stream ended inside this line"));
  ::close(fds[0]);
}

TEST(FdPoseSource, StopInterruptsABlockedRead) {
  int fds[2];
  ASSERT_EQ(::pipe(fds), 0);
  auto source = make_fd_pose_source(fds[0], {});
  source->start();
  std::this_thread::sleep_for(20ms);
  const auto t0 = std::chrono::steady_clock::now();
  source->stop();
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 1s);
  EXPECT_FALSE(source->finished());
  ::close(fds[0]);
  ::close(fds[1]);
}

// ---------------------------------------------------------------- file replay

class TempFile {
 public:
  explicit TempFile(const std::string& text) {
    char name[] = "/tmp/imuemu_test_pose_sources.XXXXXX";
    const int fd = ::mkstemp(name);
    if (fd < 0) throw std::runtime_error("mkstemp failed");
    path_ = name;
    if (::write(fd, text.data(), text.size()) != static_cast<ssize_t>(text.size())) throw std::runtime_error("write");
    ::close(fd);
  }
  ~TempFile() { ::unlink(path_.c_str()); }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

// n + 1 records at `step_s` intervals, local NED, slowly turning.
std::string replay_file(int n, double step_s) {
  std::string text = "time_s,north_m,east_m,down_m,heading_deg,pitch_deg,roll_deg\n";
  for (int i = 0; i <= n; ++i) {
    char line[128];
    std::snprintf(line, sizeof line, "%.3f,%d,0,0,%d,0,0\n", 1000.0 + step_s * i, i, i % 360);
    text += line;
  }
  return text;
}

// Runs a replay to its end, draining as it goes; returns the poses and the
// time from start() to finished().
std::vector<SourcedPose> replay(PoseSource& source, std::chrono::nanoseconds& elapsed) {
  std::vector<SourcedPose> poses;
  const auto t0 = std::chrono::steady_clock::now();
  source.start();
  EXPECT_TRUE(wait_until([&] {
    source.queue().drain(poses);
    return source.finished();
  }));
  elapsed = std::chrono::steady_clock::now() - t0;
  source.queue().drain(poses);
  return poses;
}

TEST(FileReplaySource, PacedBySpeedFactor) {
  const TempFile file(replay_file(100, 0.01));  // 1 s of poses at 100 Hz
  LogCapture log;
  PoseSourceOptions options;
  options.log = log.sink();
  auto source = make_file_replay_source(file.path(), {.speed = 20.0}, options);
  std::chrono::nanoseconds elapsed{};
  const std::vector<SourcedPose> poses = replay(*source, elapsed);
  ASSERT_EQ(poses.size(), 101u);
  // 1 s at 20x is 50 ms; the loose bounds only say "paced, not flat out,
  // and not at 1x".
  EXPECT_GE(elapsed, 40ms);
  EXPECT_LE(elapsed, 1s);
  // Release times follow the records: the last comes >= 50 ms after the first.
  EXPECT_GE(poses.back().receive_ns - poses.front().receive_ns, 45'000'000);
  for (std::size_t i = 0; i < poses.size(); ++i) {
    EXPECT_EQ(poses[i].pose.t_ns, 1000 * kNsPerSecond + static_cast<TimeNs>(i) * 10'000'000);
    EXPECT_EQ(poses[i].line, i + 2);
  }
  const PoseSourceCounters c = source->counters();
  EXPECT_EQ(c.received, 101u);
  EXPECT_EQ(c.accepted, 101u);
  expect_accounted(c);
  EXPECT_TRUE(log.contains("end of file: 101 records replayed"));
}

TEST(FileReplaySource, AsFastAsPossibleWithBackpressure) {
  const TempFile file(replay_file(1000, 0.1));  // 100 s of poses
  PoseSourceOptions options;
  options.queue_capacity = 8;
  options.log = [](std::string_view) {};
  auto source = make_file_replay_source(file.path(), {.as_fast_as_possible = true}, options);
  std::chrono::nanoseconds elapsed{};
  const std::vector<SourcedPose> poses = replay(*source, elapsed);
  ASSERT_EQ(poses.size(), 1001u);
  EXPECT_LT(elapsed, 5s);  // not paced: 100 s of poses
  for (std::size_t i = 1; i < poses.size(); ++i) ASSERT_GT(poses[i].pose.t_ns, poses[i - 1].pose.t_ns);
  EXPECT_GE(source->counters().backpressure_events, 1u);
  EXPECT_EQ(source->counters().accepted, 1001u);
}

TEST(FileReplaySource, BadFilesAndOptionsFailAtOnceAndStopIsPrompt) {
  const TempFile good(replay_file(1000, 0.1));
  EXPECT_THROW(make_file_replay_source(good.path(), {.speed = 0.0}, {}), std::invalid_argument);
  EXPECT_THROW(make_file_replay_source(good.path(), {.speed = std::nan("")}, {}), std::invalid_argument);
  PoseSourceOptions ecef;
  ecef.physics = Physics::ecef;
  EXPECT_THROW(make_file_replay_source(good.path(), {}, ecef), TrajectoryFormatError);  // local NED in ecef
  const TempFile bad("time_s,north_m,east_m,down_m,heading_deg,pitch_deg,roll_deg\n0,0,0,0,0,0,0\n0,0,0,0,0,0,0\n");
  try {
    make_file_replay_source(bad.path(), {}, {});
    ADD_FAILURE() << "non-increasing file accepted";
  } catch (const TrajectoryFormatError& e) {
    EXPECT_EQ(e.line(), 3u);
  }
  // A 100 s replay at 1x stops promptly.
  PoseSourceOptions quiet;
  quiet.log = [](std::string_view) {};
  auto source = make_file_replay_source(good.path(), {}, quiet);
  source->start();
  ASSERT_TRUE(wait_until([&] { return source->counters().accepted >= 1; }));
  const auto t0 = std::chrono::steady_clock::now();
  source->stop();
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 1s);
  EXPECT_FALSE(source->finished());
  EXPECT_LT(source->counters().accepted, 1001u);
}

}  // namespace
}  // namespace imuemu::io
}  // namespace unity_io_test_pose_sources
