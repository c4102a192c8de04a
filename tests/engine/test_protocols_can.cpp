// CAN protocol encoders/decoders against the specifications: golden frames
// laid out by hand from the DroneCAN DSDL / transport layer and the J1939
// PGN definitions (sources in drivers/protocols/dronecan.hpp, j1939.hpp),
// the published check values and signatures, encode -> decode round trips
// over the value ranges, exact error counts for dropped / corrupted /
// reordered frames, and random garbage.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <chrono>
#include <limits>
#include <mutex>
#include <numbers>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/attitude.hpp"
#include "core/earth.hpp"
#include "daemon/device/device.hpp"
#include "daemon/engine/emission.hpp"
#include "drivers/protocols/can_protocols.hpp"
#include "drivers/protocols/dronecan.hpp"
#include "drivers/protocols/j1939.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_engine_test_protocols_can {
namespace imuemu { using namespace ::imuemu; }

namespace {

using imuemu::TimeNs;
using imuemu::Vec3;
using imuemu::drivers::CanFrame;
using imuemu::drivers::DecodedSample;
using imuemu::drivers::ImuFrameInput;
namespace dc = imuemu::drivers::dronecan;
namespace jj = imuemu::drivers::j1939;

constexpr double kDegToRad = std::numbers::pi / 180.0;

// ---------------------------------------------------------------------------
// Independent reference implementations (bitwise, from the algorithm
// descriptions), each pinned by its published check value.

// CRC-16-CCITT-FALSE: poly 0x1021, init 0xFFFF, MSB first, no final xor.
std::uint16_t reference_crc16(std::uint16_t crc, const std::vector<std::uint8_t>& bytes) {
  for (std::uint8_t b : bytes) {
    for (int bit = 7; bit >= 0; --bit) {
      const bool in = ((b >> bit) & 1) != 0;
      const bool top = (crc & 0x8000) != 0;
      crc = static_cast<std::uint16_t>(crc << 1);
      if (in != top) crc ^= 0x1021;
    }
  }
  return crc;
}

// CRC-64-WE: poly 0x42F0E1EBA9EA3693, init and final xor all ones, MSB first.
struct Crc64We {
  std::uint64_t crc = ~std::uint64_t{0};
  void add(const std::string& s) {
    for (char c : s) add_byte(static_cast<std::uint8_t>(c));
  }
  void add_le64(std::uint64_t v) {
    for (int i = 0; i < 8; ++i) add_byte(static_cast<std::uint8_t>(v >> (8 * i)));
  }
  void add_byte(std::uint8_t b) {
    crc ^= std::uint64_t{b} << 56;
    for (int i = 0; i < 8; ++i) crc = (crc & (std::uint64_t{1} << 63)) ? (crc << 1) ^ 0x42F0E1EBA9EA3693ULL : crc << 1;
  }
  std::uint64_t value() const { return ~crc; }
  static Crc64We extend_from(std::uint64_t value) {
    Crc64We c;
    c.crc = ~value;
    return c;
  }
};

std::vector<std::uint8_t> le_bytes(std::uint64_t v, int n) {
  std::vector<std::uint8_t> out;
  for (int i = 0; i < n; ++i) out.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
  return out;
}
std::vector<std::uint8_t> f32_bytes(float f) { return le_bytes(std::bit_cast<std::uint32_t>(f), 4); }

std::vector<std::uint8_t> frame_bytes(const CanFrame& f) { return {f.data.begin(), f.data.begin() + f.len}; }

ImuFrameInput make_sample(TimeNs t_ns, const Vec3& gyro, const Vec3& accel) {
  ImuFrameInput s;
  s.t_ns = t_ns;
  s.gyro_rad_s = gyro;
  s.accel_m_s2 = accel;
  s.period_ns = 10'000'000;
  s.delta_theta_rad = gyro * 0.01;
  s.delta_velocity_m_s = accel * 0.01;
  return s;
}

// ===========================================================================
// DroneCAN

TEST(DroneCanCrc, CheckValueOf123456789Is0x29B1) {
  // CRC-16-CCITT-FALSE check value (libuavcan crc.hpp, pydronecan common.py).
  const std::vector<std::uint8_t> check = {'1', '2', '3', '4', '5', '6', '7', '8', '9'};
  EXPECT_EQ(reference_crc16(0xFFFF, check), 0x29B1);
  EXPECT_EQ(dc::crc16_ccitt_false(0xFFFF, check), 0x29B1);
  // The transfer CRC is that CRC over the signature's bytes LSB first, then the payload.
  const std::uint64_t signature = 0x0123456789ABCDEFULL;
  std::vector<std::uint8_t> seeded = le_bytes(signature, 8);
  seeded.insert(seeded.end(), check.begin(), check.end());
  EXPECT_EQ(dc::transfer_crc(signature, check), reference_crc16(0xFFFF, seeded));
}

TEST(DroneCanSignature, RawImuSignatureRecomputedFromTheDsdl) {
  // CRC-64-WE check value "123456789" (pydronecan dsdl/signature.py).
  Crc64We check;
  check.add("123456789");
  ASSERT_EQ(check.value(), 0x62EC59E3F1A4F00AULL);

  // uavcan.Timestamp: fields only (constants are not part of the normalised
  // definition), each "<cast mode> <type> <name>".
  Crc64We timestamp;
  timestamp.add("uavcan.Timestamp\ntruncated uint56 usec");
  EXPECT_EQ(timestamp.value(), 0x05BD0B5C81087E0DULL);  // UAVCAN_TIMESTAMP_SIGNATURE (libcanard dsdlc)

  // uavcan.equipment.ahrs.RawIMU (1003.RawIMU.uavcan): primitive fields get
  // the default cast mode "saturated", arrays "<type>[N]" / "<type>[<=N]",
  // nested types their full name.
  Crc64We raw_imu;
  raw_imu.add(
      "uavcan.equipment.ahrs.RawIMU\n"
      "uavcan.Timestamp timestamp\n"
      "saturated float32 integration_interval\n"
      "saturated float16[3] rate_gyro_latest\n"
      "saturated float32[3] rate_gyro_integral\n"
      "saturated float16[3] accelerometer_latest\n"
      "saturated float32[3] accelerometer_integral\n"
      "saturated float16[<=36] covariance");
  // Data type signature: extend the DSDL signature with each nested compound
  // type's signature, then the value before it (get_data_type_signature).
  Crc64We extended = Crc64We::extend_from(raw_imu.value());
  const std::uint64_t before = extended.value();
  extended.add_le64(timestamp.value());
  extended.add_le64(before);
  EXPECT_EQ(extended.value(), 0x8280632C40E574B5ULL);  // the published RawIMU signature
  EXPECT_EQ(dc::kRawImuSignature, extended.value());

  Crc64We node_status;
  node_status.add(
      "uavcan.protocol.NodeStatus\n"
      "saturated uint32 uptime_sec\n"
      "saturated uint2 health\n"
      "saturated uint3 mode\n"
      "saturated uint3 sub_mode\n"
      "saturated uint16 vendor_specific_status_code");
  EXPECT_EQ(dc::kNodeStatusSignature, node_status.value());
}

TEST(DroneCanFloat16, ExactValuesAndLimits) {
  // binary16: sign | 5-bit exponent (bias 15) | 10-bit significand.
  EXPECT_EQ(dc::float16_bits_libuavcan(1.0f), 0x3C00);    // 0 01111 0000000000
  EXPECT_EQ(dc::float16_bits_libuavcan(-2.0f), 0xC000);   // 1 10000 0000000000
  EXPECT_EQ(dc::float16_bits_libuavcan(0.5f), 0x3800);    // 0 01110 0000000000
  EXPECT_EQ(dc::float16_bits_libuavcan(9.75f), 0x48E0);   // 1.21875 * 2^3: 0 10010 0011100000
  EXPECT_EQ(dc::float16_bits_libuavcan(-0.0f), 0x8000);
  EXPECT_EQ(dc::float16_bits_libuavcan(65504.0f), 0x7BFF);  // largest finite: (2 - 2^-10) 2^15
  EXPECT_EQ(dc::float16_bits_libuavcan(65519.0f), 0x7BFF);  // below the half-way point to 2^16
  // 65520 is half way between 65504 and 2^16: rounds up, i.e. overflows to +inf.
  EXPECT_EQ(dc::float16_bits_libuavcan(65520.0f), 0x7C00);
  EXPECT_EQ(dc::float16_bits_libuavcan(-65520.0f), 0xFC00);
  EXPECT_EQ(dc::float16_bits_libuavcan(1e30f), 0x7C00);
}

TEST(DroneCanFloat16, SubnormalsAndTiesRoundAwayFromZeroAsLibuavcan) {
  // libuavcan (uc_float_spec.cpp) adds one when the dropped fraction is >= 0.5:
  // ties go AWAY from zero. IEEE round-to-nearest-even would differ on every
  // case marked "RNE:".
  EXPECT_EQ(dc::float16_bits_libuavcan(std::ldexp(1.0f, -24)), 0x0001);  // smallest subnormal
  EXPECT_EQ(dc::float16_bits_libuavcan(std::ldexp(1.0f, -25)), 0x0001);  // tie 0 | 2^-24 (RNE: 0x0000)
  EXPECT_EQ(dc::float16_bits_libuavcan(std::ldexp(1.0f, -26)), 0x0000);  // a quarter ULP: down
  EXPECT_EQ(dc::float16_bits_libuavcan(std::ldexp(3.0f, -26)), 0x0001);  // three quarters: up
  EXPECT_EQ(dc::float16_bits_libuavcan(std::ldexp(3.0f, -25)), 0x0002);  // tie 1 | 2 (RNE: 0x0002 too)
  EXPECT_EQ(dc::float16_bits_libuavcan(std::ldexp(5.0f, -25)), 0x0003);  // tie 2 | 3 (RNE: 0x0002)
  EXPECT_EQ(dc::float16_bits_libuavcan(std::ldexp(1023.0f, -24)), 0x03FF);  // largest subnormal
  EXPECT_EQ(dc::float16_bits_libuavcan(std::ldexp(2047.0f, -25)), 0x0400);  // tie into the smallest normal
  EXPECT_EQ(dc::float16_bits_libuavcan(std::ldexp(1.0f, -14)), 0x0400);     // smallest normal
  EXPECT_EQ(dc::float16_bits_libuavcan(1.0f + std::ldexp(1.0f, -11)), 0x3C01);   // tie (RNE: 0x3C00)
  EXPECT_EQ(dc::float16_bits_libuavcan(-(1.0f + std::ldexp(1.0f, -11))), 0xBC01);
  EXPECT_EQ(dc::float16_bits_libuavcan(1.0f + std::ldexp(3.0f, -11)), 0x3C02);   // tie (RNE: 0x3C02)
  EXPECT_EQ(dc::float16_bits_libuavcan(2049.0f), 0x6801);  // spacing 2 at 2^11: tie (RNE: 0x6800)
  EXPECT_EQ(dc::float16_bits_libuavcan(2.0f - std::ldexp(1.0f, -12)), 0x4000);  // carries into the exponent
}

TEST(DroneCanFloat16, EveryHalfRoundTripsAndEveryMidpointRoundsAway) {
  // Exhaustive over the positive finite halves h: the value of h converts
  // back to h; the midpoint to h+1 converts to h+1 (away from zero), the
  // float just below the midpoint to h. The same for negative values.
  for (std::uint32_t h = 0; h <= 0x7BFF; ++h) {
    const double v = dc::float16_to_double(static_cast<std::uint16_t>(h));
    ASSERT_EQ(dc::float16_bits_libuavcan(static_cast<float>(v)), h) << h;
    ASSERT_EQ(dc::float16_bits_libuavcan(-static_cast<float>(v)), h | 0x8000u) << h;
    const double next = h < 0x7BFF ? dc::float16_to_double(static_cast<std::uint16_t>(h + 1)) : 65536.0;
    const auto mid = static_cast<float>((v + next) / 2);  // 12 significant bits: exact in float
    ASSERT_EQ(static_cast<double>(mid), (v + next) / 2);
    ASSERT_EQ(dc::float16_bits_libuavcan(mid), h + 1) << h;
    ASSERT_EQ(dc::float16_bits_libuavcan(-mid), (h + 1) | 0x8000u) << h;
    ASSERT_EQ(dc::float16_bits_libuavcan(std::nextafter(mid, 0.0f)), h) << h;
  }
}

TEST(DroneCanFloat16, SaturatedFieldClampsToLargestFiniteAndNeverSendsInfOrNaN) {
  // libuavcan's saturated float16 clamps finite values to +-65504 first.
  EXPECT_EQ(dc::float16_saturated(65504.0).bits, 0x7BFF);
  EXPECT_EQ(dc::float16_saturated(65504.0).clip, dc::WireClip::kExact);
  EXPECT_EQ(dc::float16_saturated(65520.0).bits, 0x7BFF);  // raw conversion would give +inf
  EXPECT_EQ(dc::float16_saturated(65520.0).clip, dc::WireClip::kSaturated);
  EXPECT_EQ(dc::float16_saturated(-1e300).bits, 0xFBFF);
  EXPECT_EQ(dc::float16_saturated(-1e300).clip, dc::WireClip::kSaturated);
  for (double bad : {std::numeric_limits<double>::infinity(), -std::numeric_limits<double>::infinity(),
                     std::numeric_limits<double>::quiet_NaN()}) {
    const dc::Float16Value v = dc::float16_saturated(bad);
    EXPECT_EQ(v.clip, dc::WireClip::kNotFinite);
    EXPECT_EQ(v.bits, 0x0000);
  }
  // A double is rounded to float first (the DSDL field type), then to half.
  EXPECT_EQ(dc::float16_saturated(1.0 + std::ldexp(1.0, -11) + std::ldexp(1.0, -40)).bits,
            dc::float16_bits_libuavcan(static_cast<float>(1.0 + std::ldexp(1.0, -11) + std::ldexp(1.0, -40))));
}

TEST(DroneCanEncoder, RawImuTransferMatchesHandBuiltFrames) {
  dc::DroneCanOptions options;  // node 42, priority 8
  dc::DroneCanEncoder encoder(options);
  ImuFrameInput s;
  s.t_ns = 1'234'567'890;               // 1234567 us (the 890 ns are truncated)
  s.period_ns = 10'000'000;             // 0.01 s
  s.gyro_rad_s = Vec3(1.0, -2.0, 0.5);  // body FRD = DroneCAN body axes
  s.delta_theta_rad = Vec3(0.25, -0.125, 1.5);
  s.accel_m_s2 = Vec3(0.0, 9.75, -9.75);
  s.delta_velocity_m_s = Vec3(0.0625, 0.0, -0.09375);
  std::vector<CanFrame> frames;
  encoder.encode(s, frames);

  // Payload, field by field (all fields are whole bytes, little-endian):
  const std::vector<std::uint8_t> payload = {
      0x87, 0xD6, 0x12, 0x00, 0x00, 0x00, 0x00,  // uint56 usec 1234567 = 0x12D687
      0x0A, 0xD7, 0x23, 0x3C,                    // float32 0.01 = 0x3C23D70A
      0x00, 0x3C, 0x00, 0xC0, 0x00, 0x38,        // float16 1.0, -2.0, 0.5
      0x00, 0x00, 0x80, 0x3E,                    // float32 0.25   = 0x3E800000
      0x00, 0x00, 0x00, 0xBE,                    //        -0.125  = 0xBE000000
      0x00, 0x00, 0xC0, 0x3F,                    //         1.5    = 0x3FC00000
      0x00, 0x00, 0xE0, 0x48, 0xE0, 0xC8,        // float16 0.0, 9.75 = 0x48E0, -9.75 = 0xC8E0
      0x00, 0x00, 0x80, 0x3D,                    // float32 0.0625   = 0x3D800000
      0x00, 0x00, 0x00, 0x00,                    //         0.0
      0x00, 0x00, 0xC0, 0xBD,                    //        -0.09375 = 0xBDC00000
  };
  ASSERT_EQ(payload.size(), dc::kRawImuPayloadBytes);  // covariance: empty tail array, no length
  EXPECT_EQ(dc::serialize_raw_imu(s, options).bytes, payload);

  // Transfer: CRC (LE) then payload, 7 bytes per frame + tail byte.
  std::vector<std::uint8_t> seeded = le_bytes(dc::kRawImuSignature, 8);
  seeded.insert(seeded.end(), payload.begin(), payload.end());
  const std::uint16_t crc = reference_crc16(0xFFFF, seeded);
  std::vector<std::uint8_t> stream = {static_cast<std::uint8_t>(crc & 0xFF), static_cast<std::uint8_t>(crc >> 8)};
  stream.insert(stream.end(), payload.begin(), payload.end());
  ASSERT_EQ(stream.size(), 49u);
  // start | end | toggle | transfer id 0: toggle starts at 0 and alternates.
  const std::uint8_t tails[7] = {0x80, 0x20, 0x00, 0x20, 0x00, 0x20, 0x40};
  ASSERT_EQ(frames.size(), 7u);
  for (std::size_t k = 0; k < 7; ++k) {
    SCOPED_TRACE(k);
    // priority 8 << 24 | 1003 << 8 | service 0 << 7 | node 42
    EXPECT_EQ(frames[k].id, 0x0803EB2Au);
    EXPECT_TRUE(frames[k].extended);
    EXPECT_FALSE(frames[k].fd);
    std::vector<std::uint8_t> expected(stream.begin() + 7 * static_cast<std::ptrdiff_t>(k),
                                       stream.begin() + 7 * static_cast<std::ptrdiff_t>(k + 1));
    expected.push_back(tails[k]);
    EXPECT_EQ(frame_bytes(frames[k]), expected);
  }
  // The next transfer carries transfer id 1 in every tail byte.
  frames.clear();
  encoder.encode(s, frames);
  ASSERT_EQ(frames.size(), 7u);
  EXPECT_EQ(frames.front().data[7], 0x81);
  EXPECT_EQ(frames.back().data[7], 0x41);
}

TEST(DroneCanEncoder, TransferIdWrapsModulo32) {
  dc::DroneCanEncoder encoder;
  std::vector<CanFrame> frames;
  const ImuFrameInput s = make_sample(1'000'000, Vec3(0.1, 0.2, 0.3), Vec3(0, 0, -9.8));
  for (int i = 0; i < 33; ++i) {
    frames.clear();
    encoder.encode(s, frames);
    EXPECT_EQ(frames.front().data[7] & 0x1F, i % 32);
  }
}

TEST(DroneCanEncoder, IntegralsNotAvailableGiveNonPositiveInterval) {
  dc::DroneCanOptions options;
  options.send_integrals = false;
  ImuFrameInput s = make_sample(1'000'000, Vec3(0.1, 0.2, 0.3), Vec3(0, 0, -9.8));
  const std::vector<std::uint8_t> bytes = dc::serialize_raw_imu(s, options).bytes;
  EXPECT_EQ(std::vector<std::uint8_t>(bytes.begin() + 7, bytes.begin() + 11), f32_bytes(-1.0f));
  for (std::size_t i : {17u, 21u, 25u, 35u, 39u, 43u})
    EXPECT_EQ(std::vector<std::uint8_t>(bytes.begin() + static_cast<std::ptrdiff_t>(i),
                                        bytes.begin() + static_cast<std::ptrdiff_t>(i) + 4),
              f32_bytes(0.0f));
}

TEST(DroneCanEncoder, NodeStatusOncePerSecondWithUptimeHealthAndStatusBits) {
  dc::DroneCanEncoder encoder;  // node 42, NodeStatus priority 24
  std::vector<CanFrame> node_status;
  const TimeNs t0 = 3 * imuemu::kNsPerSecond;
  const TimeNs dt = 10'000'000;  // 100 Hz
  std::vector<CanFrame> raw;
  for (int i = 0; i <= 1000; ++i) {  // 10 s of samples
    const TimeNs t = t0 + i * dt;
    ImuFrameInput s = make_sample(t, Vec3(0.1, 0.0, 0.0), Vec3(0, 0, -9.8));
    if (i == 150) s.gyro_rad_s.x() = 1e6;         // clamped to 65504: health WARNING in second 2
    if (i == 160) s.status = imuemu::drivers::kStatusExtrapolated;
    if (i == 420) s.status = imuemu::drivers::kStatusFault;  // health ERROR in second 5
    raw.clear();
    encoder.encode(s, raw);
    encoder.periodic(t, node_status);
  }
  // Due at t0, t0 + 1 s, ..., t0 + 10 s.
  ASSERT_EQ(node_status.size(), 11u);
  for (std::size_t k = 0; k < node_status.size(); ++k) {
    SCOPED_TRACE(k);
    const CanFrame& f = node_status[k];
    EXPECT_EQ(f.id, 0x1801552Au);  // 24 << 24 | 341 << 8 | 42
    ASSERT_EQ(f.len, 8);           // 7-byte payload + tail: single frame, no CRC
    // uint32 uptime_sec LE; then health (2 bits) mode (3) sub_mode (3) packed
    // from the most significant bit; then uint16 vendor code LE.
    std::uint8_t health_mode = 0x00;    // OK, OPERATIONAL
    std::uint16_t vendor = 0;
    if (k == 2) {                       // samples 100..199: the clamp (150) and extrapolation (160)
      health_mode = 0x40;               // WARNING << 6
      vendor = imuemu::drivers::kStatusExtrapolated;
    }
    if (k == 5) {                       // samples 400..499: the fault (420)
      health_mode = 0x80;               // ERROR << 6
      vendor = imuemu::drivers::kStatusFault;
    }
    const std::vector<std::uint8_t> expected = {static_cast<std::uint8_t>(k), 0, 0, 0, health_mode,
                                                static_cast<std::uint8_t>(vendor), 0,
                                                static_cast<std::uint8_t>(0xC0 | k)};
    EXPECT_EQ(frame_bytes(f), expected);
  }
  EXPECT_EQ(encoder.saturated_values(), 1u);
}

TEST(DroneCanEncoder, RejectsInvalidOptionsNamingThem) {
  dc::DroneCanOptions options;
  options.node_id = 0;
  try {
    dc::DroneCanEncoder encoder(options);
    FAIL() << "node_id 0 accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("node_id"), std::string::npos);
  }
  options.node_id = 128;
  EXPECT_THROW(dc::DroneCanEncoder{options}, std::invalid_argument);
  options.node_id = 1;
  options.raw_imu_priority = 32;
  EXPECT_THROW(dc::DroneCanEncoder{options}, std::invalid_argument);
}

// ---- decoder ----

struct Collected {
  std::vector<DecodedSample> samples;
  imuemu::drivers::SampleCallback callback() {
    return [this](const DecodedSample& s) { samples.push_back(s); };
  }
};

std::vector<std::vector<CanFrame>> encode_transfers(dc::DroneCanEncoder& encoder, int count, TimeNs t0 = 1'000'000'000) {
  std::vector<std::vector<CanFrame>> transfers;
  for (int i = 0; i < count; ++i) {
    std::vector<CanFrame> frames;
    encoder.encode(make_sample(t0 + TimeNs{i} * 10'000'000, Vec3(0.01 * i, -0.02 * i, 0.5), Vec3(0.1 * i, 0.0, -9.75)), frames);
    transfers.push_back(frames);
  }
  return transfers;
}

void feed_all(dc::DroneCanDecoder& decoder, const std::vector<CanFrame>& frames, Collected& out) {
  for (const CanFrame& f : frames) decoder.feed(f, out.callback());
}

TEST(DroneCanDecoder, RoundTripOverTheValueRangesIncludingSaturation) {
  dc::DroneCanEncoder encoder;
  dc::DroneCanDecoder decoder;
  Collected out;
  std::mt19937_64 rng(20240611);
  std::uniform_real_distribution<double> exponent(-20.0, 17.5);  // |v| from 1e-6 to ~185000
  std::bernoulli_distribution negative(0.5);
  auto random_value = [&]() {
    const double v = std::exp2(exponent(rng));
    return negative(rng) ? -v : v;
  };
  std::vector<ImuFrameInput> sent;
  for (int i = 0; i < 5000; ++i) {
    ImuFrameInput s;
    s.t_ns = TimeNs{1'000'000'000} + TimeNs{i} * 2'500'000 + 777;  // sub-microsecond part is truncated
    s.period_ns = 2'500'000;
    s.gyro_rad_s = Vec3(random_value(), random_value(), random_value());
    s.accel_m_s2 = Vec3(random_value(), random_value(), random_value());
    s.delta_theta_rad = Vec3(random_value(), random_value(), random_value()) * 1e-3;
    s.delta_velocity_m_s = Vec3(random_value(), random_value(), random_value()) * 1e-3;
    std::vector<CanFrame> frames;
    encoder.encode(s, frames);
    feed_all(decoder, frames, out);
    sent.push_back(s);
  }
  ASSERT_EQ(out.samples.size(), sent.size());
  EXPECT_EQ(decoder.counters().samples, sent.size());
  EXPECT_EQ(decoder.counters().frames, sent.size());
  EXPECT_EQ(decoder.counters().checksum_errors, 0u);
  EXPECT_EQ(decoder.counters().sequence_gaps, 0u);
  EXPECT_EQ(decoder.counters().other_errors, 0u);
  std::uint64_t clamped = 0;
  for (std::size_t i = 0; i < sent.size(); ++i) {
    const DecodedSample& d = out.samples[i];
    ASSERT_TRUE(d.has_time);
    EXPECT_EQ(d.t_ns, sent[i].t_ns - 777);
    ASSERT_TRUE(d.has_sequence);
    EXPECT_EQ(d.sequence, i);  // first transfer id 0, widened past 31
    for (int a = 0; a < 3; ++a) {
      for (const auto& [in, got] : {std::pair{sent[i].gyro_rad_s[a], d.gyro_rad_s[a]},
                                    std::pair{sent[i].accel_m_s2[a], d.accel_m_s2[a]}}) {
        if (std::abs(in) > 65504.0) {
          EXPECT_EQ(got, std::copysign(65504.0, in));
          ++clamped;
        } else if (std::abs(in) >= std::ldexp(1.0, -14)) {
          EXPECT_LE(std::abs(got - in), std::abs(in) * std::ldexp(1.0, -11) * (1 + 1e-9)) << in;  // half an ULP
        } else {
          EXPECT_LE(std::abs(got - in), std::ldexp(1.0, -25) * (1 + 1e-9)) << in;  // subnormal spacing 2^-24
        }
      }
      EXPECT_EQ(d.delta_theta_rad[a], static_cast<double>(static_cast<float>(sent[i].delta_theta_rad[a])));
      EXPECT_EQ(d.delta_velocity_m_s[a], static_cast<double>(static_cast<float>(sent[i].delta_velocity_m_s[a])));
    }
  }
  EXPECT_GT(clamped, 100u);  // the range really was exceeded
  EXPECT_EQ(encoder.saturated_values(), clamped);
}

TEST(DroneCanDecoder, NodeStatusIsDecoded) {
  dc::DroneCanEncoder encoder;
  dc::DroneCanDecoder decoder;
  std::vector<CanFrame> frames;
  encoder.encode(make_sample(2 * imuemu::kNsPerSecond, Vec3(1e6, 0, 0), Vec3(0, 0, -9.8)), frames);
  encoder.periodic(2 * imuemu::kNsPerSecond, frames);
  encoder.periodic(9 * imuemu::kNsPerSecond, frames);
  Collected out;
  feed_all(decoder, frames, out);
  const auto status = decoder.last_node_status(42);
  ASSERT_TRUE(status.has_value());
  EXPECT_EQ(status->uptime_sec, 7u);
  EXPECT_EQ(status->health, dc::NodeHealth::kOk);
  EXPECT_EQ(decoder.counters().frames, 3u);  // one RawIMU + two NodeStatus
  EXPECT_EQ(decoder.counters().samples, 1u);
  EXPECT_FALSE(decoder.last_node_status(41).has_value());
}

TEST(DroneCanDecoder, DroppedMiddleFrameCountsOneBrokenTransferAndOneGap) {
  dc::DroneCanEncoder encoder;
  auto transfers = encode_transfers(encoder, 5);
  transfers[2].erase(transfers[2].begin() + 3);  // frame 3 of transfer id 2
  dc::DroneCanDecoder decoder;
  Collected out;
  for (const auto& t : transfers) feed_all(decoder, t, out);
  EXPECT_EQ(out.samples.size(), 4u);
  EXPECT_EQ(decoder.detail().bad_toggle, 1u);        // frame 4 arrives where frame 3 (toggle 1) was due
  EXPECT_EQ(decoder.counters().other_errors, 1u);    // frames 5, 6 of the broken transfer: silent
  EXPECT_EQ(decoder.counters().checksum_errors, 0u);
  EXPECT_EQ(decoder.counters().sequence_gaps, 1u);   // transfer id 2 never completed
  EXPECT_EQ(out.samples[2].sequence, 3u);
}

TEST(DroneCanDecoder, DroppedFirstFrameCountsOneMissedStart) {
  dc::DroneCanEncoder encoder;
  auto transfers = encode_transfers(encoder, 4);
  transfers[1].erase(transfers[1].begin());
  dc::DroneCanDecoder decoder;
  Collected out;
  for (const auto& t : transfers) feed_all(decoder, t, out);
  EXPECT_EQ(out.samples.size(), 3u);
  EXPECT_EQ(decoder.detail().missed_start, 1u);
  EXPECT_EQ(decoder.counters().other_errors, 1u);
  EXPECT_EQ(decoder.counters().sequence_gaps, 1u);
}

TEST(DroneCanDecoder, DroppedLastFrameCountsOneInterruptedTransfer) {
  dc::DroneCanEncoder encoder;
  auto transfers = encode_transfers(encoder, 4);
  transfers[1].pop_back();
  dc::DroneCanDecoder decoder;
  Collected out;
  for (const auto& t : transfers) feed_all(decoder, t, out);
  EXPECT_EQ(out.samples.size(), 3u);
  EXPECT_EQ(decoder.detail().interrupted_transfer, 1u);  // seen when transfer 2 starts
  EXPECT_EQ(decoder.counters().other_errors, 1u);
  EXPECT_EQ(decoder.counters().sequence_gaps, 1u);
}

TEST(DroneCanDecoder, CorruptedPayloadByteFailsTheCrc) {
  dc::DroneCanEncoder encoder;
  auto transfers = encode_transfers(encoder, 6);
  transfers[1][3].data[2] ^= 0x10;  // one bit in the payload
  transfers[4][0].data[0] ^= 0x01;  // one bit in the transmitted CRC itself
  dc::DroneCanDecoder decoder;
  Collected out;
  for (const auto& t : transfers) feed_all(decoder, t, out);
  EXPECT_EQ(out.samples.size(), 4u);
  EXPECT_EQ(decoder.counters().checksum_errors, 2u);
  EXPECT_EQ(decoder.counters().other_errors, 0u);
  EXPECT_EQ(decoder.counters().sequence_gaps, 2u);
}

TEST(DroneCanDecoder, ReorderedFramesWithinATransferBreakIt) {
  dc::DroneCanEncoder encoder;
  auto transfers = encode_transfers(encoder, 4);
  std::swap(transfers[2][2], transfers[2][3]);
  dc::DroneCanDecoder decoder;
  Collected out;
  for (const auto& t : transfers) feed_all(decoder, t, out);
  EXPECT_EQ(out.samples.size(), 3u);
  EXPECT_EQ(decoder.detail().bad_toggle, 1u);  // frame 3 (toggle 1) where frame 2 (toggle 0) was due
  EXPECT_EQ(decoder.counters().other_errors, 1u);  // the late frame 2 and the rest: silent
  EXPECT_EQ(decoder.counters().checksum_errors, 0u);
  EXPECT_EQ(decoder.counters().sequence_gaps, 1u);
}

TEST(DroneCanDecoder, ReorderedAndDuplicatedTransfers) {
  dc::DroneCanEncoder encoder;
  auto transfers = encode_transfers(encoder, 6);
  std::vector<std::vector<CanFrame>> order = {transfers[0], transfers[2], transfers[1], transfers[3],
                                              transfers[3], transfers[4], transfers[5]};
  dc::DroneCanDecoder decoder;
  Collected out;
  for (const auto& t : order) feed_all(decoder, t, out);
  // 0 ok; 2 ok with a gap of 1; 1 is behind 2: stale; 3 ok; 3 again: duplicate; 4, 5 ok.
  EXPECT_EQ(out.samples.size(), 5u);
  EXPECT_EQ(decoder.counters().sequence_gaps, 1u);
  EXPECT_EQ(decoder.detail().stale_transfer, 1u);
  EXPECT_EQ(decoder.detail().duplicate_transfer, 1u);
  EXPECT_EQ(decoder.counters().other_errors, 2u);
  std::vector<std::uint64_t> sequences;
  for (const auto& s : out.samples) sequences.push_back(s.sequence);
  EXPECT_EQ(sequences, (std::vector<std::uint64_t>{0, 2, 3, 4, 5}));
}

TEST(DroneCanDecoder, LostTransfersAreGapsModulo32) {
  dc::DroneCanEncoder encoder;
  auto transfers = encode_transfers(encoder, 64);
  dc::DroneCanDecoder decoder;
  Collected out;
  for (int i : {0, 1, 2, 10, 11}) feed_all(decoder, transfers[static_cast<std::size_t>(i)], out);
  EXPECT_EQ(decoder.counters().sequence_gaps, 7u);  // 3..9
  // Transfer 56 (id 24) after 11: 44 lost, but the 5-bit id only shows 13 - 1 = 12.
  feed_all(decoder, transfers[56], out);
  EXPECT_EQ(decoder.counters().sequence_gaps, 7u + 12u);
  EXPECT_EQ(out.samples.size(), 6u);
  EXPECT_EQ(out.samples.back().sequence, 24u);
  EXPECT_EQ(decoder.counters().other_errors, 0u);
}

TEST(DroneCanDecoder, SenderRestartIsFollowedAfterOneStaleTransfer) {
  dc::DroneCanEncoder encoder;
  auto transfers = encode_transfers(encoder, 12);  // ids 0..11
  dc::DroneCanDecoder decoder;
  Collected out;
  for (const auto& t : transfers) feed_all(decoder, t, out);
  // The sender restarts: ids 0, 1, 2 again, i.e. 21.. behind 11 in the 5-bit
  // space. The first is taken for a late (stale) transfer; the next one,
  // consecutive to it, shows the sender has moved: the decoder re-anchors.
  dc::DroneCanEncoder restarted;
  for (const auto& t : encode_transfers(restarted, 3)) feed_all(decoder, t, out);
  EXPECT_EQ(decoder.detail().stale_transfer, 1u);
  EXPECT_EQ(decoder.counters().other_errors, 1u);
  EXPECT_EQ(decoder.counters().sequence_gaps, 0u);
  ASSERT_EQ(out.samples.size(), 12u + 2u);
  EXPECT_GT(out.samples[12].sequence, out.samples[11].sequence);  // still increasing
  EXPECT_EQ(out.samples[13].sequence, out.samples[12].sequence + 1);
}

TEST(DroneCanDecoder, InterleavedNodesReassembleSeparately) {
  dc::DroneCanOptions a, b;
  a.node_id = 10;
  b.node_id = 11;
  dc::DroneCanEncoder encoder_a(a), encoder_b(b);
  auto ta = encode_transfers(encoder_a, 3);
  auto tb = encode_transfers(encoder_b, 3, 5'000'000'000);
  dc::DroneCanDecoder decoder;
  Collected out;
  for (std::size_t t = 0; t < 3; ++t)
    for (std::size_t k = 0; k < 7; ++k) {
      decoder.feed(ta[t][k], out.callback());
      decoder.feed(tb[t][k], out.callback());
    }
  EXPECT_EQ(out.samples.size(), 6u);
  EXPECT_EQ(decoder.counters().other_errors, 0u);
  EXPECT_EQ(decoder.counters().sequence_gaps, 0u);
}

TEST(DroneCanDecoder, ForeignFramesAreCountedNotDecoded) {
  dc::DroneCanDecoder decoder;
  Collected out;
  CanFrame standard;
  standard.id = 0x123;
  standard.len = 8;
  decoder.feed(standard, out.callback());
  CanFrame service;
  service.extended = true;
  service.id = dc::message_can_id(8, dc::kRawImuDataTypeId, 42) | 0x80;  // service_not_message
  service.len = 8;
  decoder.feed(service, out.callback());
  CanFrame other_type;
  other_type.extended = true;
  other_type.id = dc::message_can_id(8, 1028, 42);  // uavcan.equipment.air_data.StaticPressure
  other_type.len = 7;
  decoder.feed(other_type, out.callback());
  CanFrame empty;
  empty.extended = true;
  empty.id = dc::message_can_id(8, dc::kRawImuDataTypeId, 42);
  empty.len = 0;
  decoder.feed(empty, out.callback());
  CanFrame toggled_start = empty;  // single-frame transfer with the toggle bit set
  toggled_start.len = 1;
  toggled_start.data[0] = 0xE0;
  decoder.feed(toggled_start, out.callback());
  CanFrame short_single = empty;  // a complete but 3-byte RawIMU
  short_single.len = 4;
  short_single.data[3] = 0xC1;
  decoder.feed(short_single, out.callback());
  EXPECT_EQ(decoder.detail().not_dronecan_frame, 3u);
  EXPECT_EQ(decoder.detail().unknown_data_type, 1u);
  EXPECT_EQ(decoder.detail().bad_toggle, 1u);
  EXPECT_EQ(decoder.detail().bad_payload, 1u);
  EXPECT_EQ(decoder.counters().other_errors, 6u);
  EXPECT_TRUE(out.samples.empty());
}

TEST(DroneCanDecoder, RandomGarbageNeverCrashesNorYieldsNonFinite) {
  std::mt19937_64 rng(7);
  dc::DroneCanDecoder decoder;
  std::uint64_t delivered = 0;
  auto check = [&delivered](const DecodedSample& s) {
    ++delivered;
    for (int a = 0; a < 3; ++a) {
      ASSERT_TRUE(std::isfinite(s.gyro_rad_s[a]) && std::isfinite(s.accel_m_s2[a]) &&
                  std::isfinite(s.delta_theta_rad[a]) && std::isfinite(s.delta_velocity_m_s[a]));
    }
  };
  const std::uint32_t raw_imu_id = dc::message_can_id(8, dc::kRawImuDataTypeId, 42);
  for (int i = 0; i < 100'000; ++i) {
    CanFrame f;
    const std::uint64_t r = rng();
    f.extended = (r & 1) != 0;
    f.fd = (r & 0x30) == 0x30;
    // Half the frames on the RawIMU / NodeStatus ids, so reassembly is exercised.
    switch ((r >> 8) & 3) {
      case 0: f.id = raw_imu_id; break;
      case 1: f.id = dc::message_can_id(24, dc::kNodeStatusDataTypeId, static_cast<std::uint8_t>(r >> 16)); break;
      default: f.id = static_cast<std::uint32_t>(r >> 32) & 0x1FFFFFFF;
    }
    f.len = static_cast<std::uint8_t>((r >> 24) % (f.fd ? 65 : 9));
    for (auto& b : f.data) b = static_cast<std::uint8_t>(rng());
    decoder.feed(f, check);
  }
  const auto& c = decoder.counters();
  EXPECT_EQ(c.samples, delivered);
  EXPECT_GT(c.other_errors, 50'000u);
  // The decoder still works on a clean stream afterwards.
  dc::DroneCanOptions other;
  other.node_id = 99;
  dc::DroneCanEncoder encoder(other);
  std::vector<CanFrame> frames;
  encoder.encode(make_sample(5'000'000, Vec3(0.5, 0, 0), Vec3(0, 0, -9.75)), frames);
  Collected out;
  feed_all(decoder, frames, out);
  ASSERT_EQ(out.samples.size(), 1u);
  EXPECT_EQ(out.samples[0].gyro_rad_s.x(), 0.5);
}

// ===========================================================================
// J1939

jj::J1939Options honeywell_like() {
  jj::J1939Options o;
  o.source_address = 0xE2;
  o.priority = 3;
  return o;
}

TEST(J1939Id, LayoutAndParse) {
  // priority << 26 | PGN << 8 | SA (Honeywell TARS: 0x0CF02AE2 = ARI, priority 3, SA 0xE2).
  EXPECT_EQ(jj::can_id(3, jj::kPgnAngularRateInformation, 0xE2), 0x0CF02AE2u);
  EXPECT_EQ(jj::can_id(3, jj::kPgnAccelerationSensor, 0xE2), 0x0CF02DE2u);
  EXPECT_EQ(jj::can_id(6, jj::kPgnSlopeSensorInformation2, 0x80), 0x18F02980u);
  const jj::IdFields f = jj::parse_can_id(0x0CF02AE2);
  EXPECT_EQ(f.priority, 3);
  EXPECT_EQ(f.pgn, 0xF02Au);
  EXPECT_EQ(f.source_address, 0xE2);
  // PDU1 (PF < 240): PS is a destination address, not part of the PGN.
  EXPECT_EQ(jj::parse_can_id(0x18EA0017).pgn, 0xEA00u);  // Request PGN to address 0x00
}

TEST(J1939Encoder, HoneywellExampleFramesAtRest) {
  jj::J1939Encoder encoder(honeywell_like());
  std::vector<CanFrame> frames;
  // At rest and level: specific force f^b = (0, 0, -g) in body FRD.
  encoder.encode(make_sample(0, Vec3::Zero(), Vec3(0, 0, -9.80665)), frames);
  ASSERT_EQ(frames.size(), 2u);
  // ARI: 0 deg/s -> (0 + 250) * 128 = 32000 = 0x7D00 on each axis.
  EXPECT_EQ(frames[0].id, 0x0CF02AE2u);
  EXPECT_TRUE(frames[0].extended);
  EXPECT_EQ(frame_bytes(frames[0]),
            (std::vector<std::uint8_t>{0x00, 0x7D, 0x00, 0x7D, 0x00, 0x7D,
                                       0xC0,    // FoM 00 00 00, bits 7-8 not defined = 11
                                       0xFF})); // latency not available
  // ACCS: 0, 0 and +9.80665 m/s^2 vertical (z up): (9.80665 + 320) / 0.01 =
  // 32980.665 -> 32981 = 0x80D5, the Honeywell example's D5 80.
  EXPECT_EQ(frames[1].id, 0x0CF02DE2u);
  EXPECT_EQ(frame_bytes(frames[1]),
            (std::vector<std::uint8_t>{0x00, 0x7D, 0x00, 0x7D, 0xD5, 0x80, 0xC0, 0xFF}));
}

TEST(J1939Encoder, ResolutionLimitsAndClamping) {
  jj::J1939Options options = honeywell_like();
  options.measurement_latency_ms = 2.5;  // 5 * 0.5 ms
  jj::J1939Encoder encoder(options);
  std::vector<CanFrame> frames;
  // gyro FRD: w_x (roll) = +1 LSB, w_y (J1939DA pitch, Z-down) = +1 LSB,
  // w_z (yaw, Z-down) = +251.9921875 deg/s (the largest valid code). (Before
  // issue 12 the inputs were w_y = -1 LSB, w_z = -251.99: the old ISO 8855
  // default negated pitch and yaw rates; the expected bytes are unchanged.)
  ImuFrameInput s = make_sample(0, Vec3(1.0 / 128.0, 1.0 / 128.0, 251.9921875) * kDegToRad,
                                // f_x = 322.55 (max), f_y = +1 (right: ISO lateral -1), f_z = 0
                                Vec3(322.55, 1.0, 0.0));
  encoder.encode(s, frames);
  ASSERT_EQ(frames.size(), 2u);
  EXPECT_EQ(frame_bytes(frames[0]),
            (std::vector<std::uint8_t>{0x01, 0x7D,   // pitch 32001
                                       0x01, 0x7D,   // roll 32001
                                       0xFF, 0xFA,   // yaw 0xFAFF: the largest valid code
                                       0xC0, 0x05}));
  EXPECT_EQ(frame_bytes(frames[1]),
            (std::vector<std::uint8_t>{0x9C, 0x7C,   // lateral -1.00 -> 31900 = 0x7C9C
                                       0xFF, 0xFA,   // longitudinal 322.55 -> 64255 = 0xFAFF
                                       0x00, 0x7D,   // vertical 0
                                       0xC0, 0xFF}));
  EXPECT_EQ(encoder.clamped_values(), 0u);

  // Half an LSB rounds to nearest: 0.6 LSB -> 1, 0.4 LSB -> 0.
  frames.clear();
  encoder.encode(make_sample(0, Vec3(0.6 / 128.0, 0.0, 0.0) * kDegToRad, Vec3(0.004, 0.0, -0.006)), frames);
  EXPECT_EQ(frames[0].data[2], 0x01);  // roll 32001
  EXPECT_EQ(frames[1].data[2], 0x00);  // longitudinal +0.4 LSB -> 32000
  EXPECT_EQ(frames[1].data[3], 0x7D);
  EXPECT_EQ(frames[1].data[4], 0x01);  // vertical = -f_z = +0.6 LSB -> 32001
  EXPECT_EQ(frames[1].data[5], 0x7D);

  // Out of range: clamped to the valid ends (never into 0xFB00..0xFFFF), figure of merit "degraded".
  frames.clear();
  encoder.encode(make_sample(0, Vec3(300.0, -300.0, 0.0) * kDegToRad, Vec3(-400.0, 0.0, 1000.0)), frames);
  EXPECT_EQ(frame_bytes(frames[0]),
            (std::vector<std::uint8_t>{0x00, 0x00,   // pitch = w_y = -300 -> 0
                                       0xFF, 0xFA,   // roll = +300 -> 0xFAFF
                                       0x00, 0x7D,
                                       0xC5,         // 11 00 01 01: yaw ok, roll and pitch degraded
                                       0x05}));
  EXPECT_EQ(frame_bytes(frames[1]),
            (std::vector<std::uint8_t>{0x00, 0x7D, 0x00, 0x00, 0x00, 0x00, 0xD4, 0xFF}));  // 11 01 01 00
  EXPECT_EQ(encoder.clamped_values(), 4u);
}

TEST(J1939Encoder, FaultAndNonFiniteValuesUseErrorCodes) {
  jj::J1939Encoder encoder(honeywell_like());
  std::vector<CanFrame> frames;
  ImuFrameInput s = make_sample(0, Vec3(std::numeric_limits<double>::quiet_NaN(), 0, 0), Vec3(0, 0, -9.8));
  encoder.encode(s, frames);
  // roll = w_x = NaN -> error indicator 0xFE00, figure of merit 10.
  EXPECT_EQ(frame_bytes(frames[0]), (std::vector<std::uint8_t>{0x00, 0x7D, 0x00, 0xFE, 0x00, 0x7D, 0xC8, 0xFF}));
  frames.clear();
  s = make_sample(0, Vec3::Zero(), Vec3(0, 0, -9.8));
  s.status = imuemu::drivers::kStatusFault;
  encoder.encode(s, frames);
  EXPECT_EQ(frames[0].data[6], 0xEA);  // 11 10 10 10
  EXPECT_EQ(frames[1].data[6], 0xEA);
  frames.clear();
  s.status = imuemu::drivers::kStatusExtrapolated;
  encoder.encode(s, frames);
  EXPECT_EQ(frames[0].data[6], 0xD5);  // 11 01 01 01
}

TEST(J1939Encoder, SlopeSensor2FromTheSampleAttitudeOrNotAvailable) {
  jj::J1939Options options = honeywell_like();
  options.send_angular_rate = false;
  options.send_acceleration = false;
  options.send_slope = true;
  options.measurement_latency_ms = 10.0;
  jj::J1939Encoder encoder(options);
  EXPECT_TRUE(encoder.needs_level_attitude());
  EXPECT_FALSE(jj::J1939Encoder(honeywell_like()).needs_level_attitude());
  std::vector<CanFrame> frames;
  // A sample without an attitude: everything "not available" but the latency.
  encoder.encode(make_sample(0, Vec3::Zero(), Vec3(0, 0, -9.8)), frames);
  ASSERT_EQ(frames.size(), 1u);
  EXPECT_EQ(frames[0].id, 0x0CF029E2u);
  EXPECT_EQ(frame_bytes(frames[0]),
            (std::vector<std::uint8_t>{0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0x14}));

  // Nose up 10 deg, right side down 5 deg. J1939DA SPN 4976: "The pitch angle
  // for an angle of ascent is reported with a positive value" (Z-down, right
  // hand rule): (10 + 250) * 32768 = 8519680 = 0x820000; SPN 4977 "roll to
  // the right ... positive": (5 + 250) * 32768 = 8355840 = 0x7F8000.
  // Byte 7: SPN 4978 pitch compensation 00 (On), 4979 FoM 00, 4980 roll
  // compensation 00 (On), 4981 FoM 00 = 0x00. Before issue 12 a daemon never
  // filled the attitude, so every SSI2 frame was the "not available" one
  // above; and with an attitude the bytes were 00 00 78 00 80 7F 11 14
  // (pitch -10 deg under the old ISO default, compensation 01 = "Off" by
  // J1939DA).
  ImuFrameInput level = make_sample(123'000, Vec3::Zero(), Vec3(0, 0, -9.8));
  level.has_level_attitude = true;
  level.pitch_rad = 10.0 * kDegToRad;
  level.roll_rad = 5.0 * kDegToRad;
  frames.clear();
  encoder.encode(level, frames);
  EXPECT_EQ(frame_bytes(frames[0]),
            (std::vector<std::uint8_t>{0x00, 0x00, 0x82, 0x00, 0x80, 0x7F, 0x00, 0x14}));
  // Figures of merit follow the sample status; compensation stays On.
  level.status = imuemu::drivers::kStatusExtrapolated;
  frames.clear();
  encoder.encode(level, frames);
  EXPECT_EQ(frames[0].data[6], 0x44);  // 01 00 01 00: roll FoM degraded, roll comp on, pitch FoM degraded, on
  // The all-Z-Up alternative sends minus the aerospace pitch: (-10 + 250) * 32768 = 0x780000.
  options.axes = jj::VehicleAxes::kIso8855ZUp;
  jj::J1939Encoder z_up(options);
  frames.clear();
  level.status = 0;
  z_up.encode(level, frames);
  EXPECT_EQ(frames[0].data[0] | frames[0].data[1] << 8 | frames[0].data[2] << 16, 0x780000);
}

// Independent reference: the J1939DA SPN definitions applied by hand to a
// motion whose signs are known without any axis algebra: a vehicle pitching
// nose up, rolling right and turning clockwise seen from above (a right
// turn), while speeding up, pushed to the right and at rest vertically.
TEST(J1939Encoder, AxisSignsFollowTheJ1939daSpnDefinitions) {
  auto ari_value = [](const CanFrame& f, int field) {
    return (f.data[2 * field] | f.data[2 * field + 1] << 8) / 128.0 - 250.0;
  };
  auto accs_value = [](const CanFrame& f, int field) {
    return (f.data[2 * field] | f.data[2 * field + 1] << 8) * 0.01 - 320.0;
  };
  // Body FRD: nose rising = rotation about +y (right) by the right-hand rule;
  // rolling right = about +x; clockwise from above = about +z (down).
  const Vec3 gyro_frd = Vec3(10.0, 20.0, 30.0) * kDegToRad;
  // Specific force: speeding up forward f_x = +2; the vehicle accelerated to
  // the RIGHT has f_y = +3; level at rest f_z = -9 (gravity reaction up).
  const Vec3 f_frd(2.0, 3.0, -9.0);
  std::vector<CanFrame> frames;
  jj::J1939Encoder da(honeywell_like());  // default axes = J1939DA
  da.encode(make_sample(0, gyro_frd, f_frd), frames);
  // SPN 4983 "pitch rate for increasing ascent ... positive": +20.
  EXPECT_DOUBLE_EQ(ari_value(frames[0], 0), 20.0);
  // SPN 4984 "roll rate for increasing roll to the right ... positive": +10.
  EXPECT_DOUBLE_EQ(ari_value(frames[0], 1), 10.0);
  // SPN 4985 "A positive yaw rate signal results when the object turns clockwise": +30.
  EXPECT_DOUBLE_EQ(ari_value(frames[0], 2), 30.0);
  // SPN 5347 "positive lateral acceleration ... when the vehicle is accelerated to the left": -3.
  EXPECT_NEAR(accs_value(frames[1], 0), -3.0, 1e-9);
  // SPN 5348 "positive ... when the vehicle speed increases in the forward direction": +2.
  EXPECT_NEAR(accs_value(frames[1], 1), 2.0, 1e-9);
  // SPN 5349 "positive vertical acceleration signal of 1 gravity ... stationary on a horizontal surface": +9.
  EXPECT_NEAR(accs_value(frames[1], 2), 9.0, 1e-9);
  // The raw codes, for the record: pitch (20 + 250) * 128 = 34560 = 0x8700,
  // roll 260 * 128 = 0x8200, yaw 280 * 128 = 0x8C00. Before issue 12 (ISO
  // 8855 default) pitch and yaw went out negated: 0x7300 and 0x6E00.
  EXPECT_EQ(frame_bytes(frames[0]),
            (std::vector<std::uint8_t>{0x00, 0x87, 0x00, 0x82, 0x00, 0x8C, 0xC0, 0xFF}));

  // The alternatives: all Z-up (imuemu's old default) and all Z-down.
  jj::J1939Options iso = honeywell_like();
  iso.axes = jj::VehicleAxes::kIso8855ZUp;
  jj::J1939Encoder z_up(iso);
  frames.clear();
  z_up.encode(make_sample(0, gyro_frd, f_frd), frames);
  EXPECT_DOUBLE_EQ(ari_value(frames[0], 0), -20.0);
  EXPECT_DOUBLE_EQ(ari_value(frames[0], 1), 10.0);
  EXPECT_DOUBLE_EQ(ari_value(frames[0], 2), -30.0);
  EXPECT_NEAR(accs_value(frames[1], 0), -3.0, 1e-9);
  EXPECT_NEAR(accs_value(frames[1], 2), 9.0, 1e-9);
  jj::J1939Options j670 = honeywell_like();
  j670.axes = jj::VehicleAxes::kSaeJ670eZDown;
  jj::J1939Encoder z_down(j670);
  frames.clear();
  z_down.encode(make_sample(0, gyro_frd, f_frd), frames);
  EXPECT_DOUBLE_EQ(ari_value(frames[0], 0), 20.0);
  EXPECT_DOUBLE_EQ(ari_value(frames[0], 1), 10.0);
  EXPECT_DOUBLE_EQ(ari_value(frames[0], 2), 30.0);
  EXPECT_NEAR(accs_value(frames[1], 0), 3.0, 1e-9);
  EXPECT_NEAR(accs_value(frames[1], 2), -9.0, 1e-9);
}

TEST(J1939Decoder, RoundTripOverTheRangesIncludingSaturation) {
  for (jj::VehicleAxes axes : {jj::VehicleAxes::kJ1939da, jj::VehicleAxes::kIso8855ZUp, jj::VehicleAxes::kSaeJ670eZDown}) {
    jj::J1939Options options;
    options.axes = axes;
    options.send_slope = true;
    std::mt19937_64 rng(99);
    std::uniform_real_distribution<double> rate_deg_s(-300.0, 300.0);
    std::uniform_real_distribution<double> accel(-400.0, 400.0);
    std::uniform_real_distribution<double> angle_deg(-260.0, 260.0);
    jj::PitchRoll attitude;
    jj::J1939Encoder encoder(options);
    jj::J1939Decoder decoder(options);
    Collected out;
    const jj::Scaling& r = jj::kAngularRateScaling;
    const jj::Scaling& a = jj::kAccelerationScaling;
    const jj::Scaling& p = jj::kSlopeAngleScaling;
    for (int i = 0; i < 20'000; ++i) {
      const Vec3 gyro_deg_s(rate_deg_s(rng), rate_deg_s(rng), rate_deg_s(rng));
      const Vec3 f(accel(rng), accel(rng), accel(rng));
      attitude = {angle_deg(rng) * kDegToRad, angle_deg(rng) * kDegToRad};
      ImuFrameInput s = make_sample(i, gyro_deg_s * kDegToRad, f);
      s.has_level_attitude = true;
      s.pitch_rad = attitude.pitch_rad;
      s.roll_rad = attitude.roll_rad;
      if (i % 7 == 0) s.status = imuemu::drivers::kStatusExtrapolated;
      std::vector<CanFrame> frames;
      encoder.encode(s, frames);
      ASSERT_EQ(frames.size(), 3u);
      for (const CanFrame& frame : frames) decoder.feed(frame, out.callback());
      ASSERT_EQ(out.samples.size(), static_cast<std::size_t>(i + 1));
      const DecodedSample& d = out.samples.back();
      EXPECT_FALSE(d.has_sequence);
      EXPECT_FALSE(d.has_time);
      // Each body axis maps to one vehicle axis with a sign. Expected code:
      // round((v - offset) / resolution), clamped into 0..max_valid_raw.
      // (gyro: Z-down but for all-Z-up; accel: Z-up but for all-Z-down)
      const Vec3 gyro_sign = axes == jj::VehicleAxes::kIso8855ZUp ? Vec3(1, -1, -1) : Vec3(1, 1, 1);
      const Vec3 accel_sign = axes == jj::VehicleAxes::kSaeJ670eZDown ? Vec3(1, 1, 1) : Vec3(1, -1, -1);
      std::uint32_t expected_status = 0;
      auto check = [&](double vehicle_in, double vehicle_got, const jj::Scaling& sc, bool in_sample) {
        const double steps = std::round((vehicle_in - sc.offset) / sc.resolution);
        const double raw = std::clamp(steps, 0.0, static_cast<double>(sc.max_valid_raw));
        EXPECT_NEAR(vehicle_got, raw * sc.resolution + sc.offset, 1e-9);
        EXPECT_LE(std::abs(vehicle_got - std::clamp(vehicle_in, sc.min_value(), sc.max_value())),
                  sc.resolution / 2 + 1e-9);
        const bool clamped = steps != raw;
        const bool degraded = clamped || s.status == imuemu::drivers::kStatusExtrapolated;
        const bool at_limit = raw == 0.0 || raw == static_cast<double>(sc.max_valid_raw);
        if (in_sample && degraded)
          expected_status |= at_limit ? imuemu::drivers::kStatusSaturated : imuemu::drivers::kStatusExtrapolated;
      };
      for (int k = 0; k < 3; ++k) {
        check(gyro_sign[k] * gyro_deg_s[k], gyro_sign[k] * d.gyro_rad_s[k] / kDegToRad, r, true);
        check(accel_sign[k] * f[k], accel_sign[k] * d.accel_m_s2[k], a, true);
      }
      EXPECT_EQ(d.status, expected_status);
      const auto slope = decoder.last_slope(options.source_address);
      ASSERT_TRUE(slope && slope->angles);
      const double pitch_sign = axes == jj::VehicleAxes::kIso8855ZUp ? -1.0 : 1.0;
      check(pitch_sign * attitude.pitch_rad / kDegToRad, pitch_sign * slope->angles->pitch_rad / kDegToRad, p, false);
      check(attitude.roll_rad / kDegToRad, slope->angles->roll_rad / kDegToRad, p, false);
    }
    EXPECT_EQ(decoder.counters().frames, 60'000u);
    EXPECT_EQ(decoder.counters().samples, 20'000u);
    EXPECT_EQ(decoder.counters().other_errors, 0u);
    EXPECT_GT(encoder.clamped_values(), 1000u);
  }
}

TEST(J1939Decoder, PairingNotAvailableAndErrorCodes) {
  const jj::J1939Options options = honeywell_like();
  jj::J1939Encoder encoder(options);
  jj::J1939Decoder decoder(options);
  Collected out;
  std::vector<CanFrame> frames;
  encoder.encode(make_sample(0, Vec3(0.1, 0.2, 0.3), Vec3(1, 2, 3)), frames);
  encoder.encode(make_sample(1, Vec3(0.4, 0.5, 0.6), Vec3(4, 5, 6)), frames);
  // ARI(1) ACCS(1) ARI(2) ACCS(2) -> drop ACCS(1): ARI(1) is emitted alone when ARI(2) arrives.
  decoder.feed(frames[0], out.callback());
  decoder.feed(frames[2], out.callback());
  decoder.feed(frames[3], out.callback());
  ASSERT_EQ(out.samples.size(), 2u);
  EXPECT_NEAR(out.samples[0].gyro_rad_s.x(), 0.1, 1e-3);
  EXPECT_EQ(out.samples[0].accel_m_s2, Vec3::Zero());
  EXPECT_NEAR(out.samples[1].gyro_rad_s.x(), 0.4, 1e-3);
  EXPECT_NEAR(out.samples[1].accel_m_s2.x(), 4.0, 0.005 + 1e-9);
  // An ACCS with no ARI pending is a sample of its own.
  decoder.feed(frames[1], out.callback());
  ASSERT_EQ(out.samples.size(), 3u);
  EXPECT_EQ(out.samples[2].gyro_rad_s, Vec3::Zero());
  EXPECT_NEAR(out.samples[2].accel_m_s2.z(), 3.0, 0.005 + 1e-9);

  // Not available (0xFFxx) decodes as 0 without status; error indicator
  // (0xFExx) sets the fault bit; reserved (0xFB00..0xFDFF) rejects the frame.
  CanFrame ari = frames[0];
  ari.data[0] = 0x34, ari.data[1] = 0xFF;  // pitch n/a
  ari.data[2] = 0x00, ari.data[3] = 0xFE;  // roll error
  ari.data[6] = 0xFF;                      // figures of merit n/a
  decoder.feed(ari, out.callback());
  decoder.feed(frames[1], out.callback());
  ASSERT_EQ(out.samples.size(), 4u);
  EXPECT_EQ(out.samples[3].gyro_rad_s.x(), 0.0);
  EXPECT_EQ(out.samples[3].gyro_rad_s.y(), 0.0);
  EXPECT_EQ(out.samples[3].status, imuemu::drivers::kStatusFault);
  CanFrame reserved = frames[1];
  reserved.data[5] = 0xFB;
  decoder.feed(reserved, out.callback());
  EXPECT_EQ(decoder.detail().reserved_value, 1u);
  CanFrame unknown = frames[1];
  unknown.id = jj::can_id(6, 65265, 0x00);  // CCVS1 wheel-based vehicle speed
  decoder.feed(unknown, out.callback());
  EXPECT_EQ(decoder.detail().unknown_pgn, 1u);
  CanFrame short_frame = frames[1];
  short_frame.len = 6;
  decoder.feed(short_frame, out.callback());
  EXPECT_EQ(decoder.detail().not_j1939_frame, 1u);
  EXPECT_EQ(decoder.counters().other_errors, 3u);
  EXPECT_EQ(decoder.counters().frames, 6u);
  EXPECT_EQ(out.samples.size(), 4u);
}

TEST(J1939Decoder, RandomGarbageNeverCrashesNorYieldsNonFinite) {
  std::mt19937_64 rng(11);
  jj::J1939Options options;
  options.send_slope = true;
  jj::J1939Decoder decoder(options);
  std::uint64_t delivered = 0;
  auto check = [&delivered](const DecodedSample& s) {
    ++delivered;
    for (int a = 0; a < 3; ++a) ASSERT_TRUE(std::isfinite(s.gyro_rad_s[a]) && std::isfinite(s.accel_m_s2[a]));
  };
  const std::uint32_t pgns[] = {jj::kPgnAngularRateInformation, jj::kPgnAccelerationSensor,
                                jj::kPgnSlopeSensorInformation2};
  for (int i = 0; i < 100'000; ++i) {
    CanFrame f;
    const std::uint64_t r = rng();
    f.extended = (r & 7) != 0;
    f.fd = (r & 0x30) == 0x30;
    f.id = (r & 0x100) ? jj::can_id(static_cast<std::uint8_t>(r >> 9), pgns[(r >> 12) % 3], static_cast<std::uint8_t>(r >> 16))
                       : static_cast<std::uint32_t>(r >> 32);
    f.len = (r & 0xC0) ? 8 : static_cast<std::uint8_t>((r >> 24) % 65);
    for (auto& b : f.data) b = static_cast<std::uint8_t>(rng());
    decoder.feed(f, check);
  }
  EXPECT_EQ(decoder.counters().samples, delivered);
  EXPECT_GT(delivered, 10'000u);
  EXPECT_GT(decoder.counters().other_errors, 10'000u);
}

// ===========================================================================
// Factory

TEST(CanProtocols, FactoryByNameAndErrors) {
  using imuemu::drivers::can_protocol_names;
  using imuemu::drivers::make_can_decoder;
  using imuemu::drivers::make_can_encoder;
  EXPECT_EQ(can_protocol_names(), (std::vector<std::string>{"dronecan", "j1939"}));
  for (const std::string& name : can_protocol_names()) {
    auto encoder = make_can_encoder(name);
    auto decoder = make_can_decoder(name);
    ASSERT_TRUE(encoder && decoder);
    EXPECT_EQ(encoder->name(), name);
    std::vector<CanFrame> frames;
    encoder->encode(make_sample(1'000'000'000, Vec3(0.5, -0.25, 0.125), Vec3(1.0, -2.0, -9.75)), frames);
    Collected out;
    for (const CanFrame& f : frames) decoder->feed(f, out.callback());
    ASSERT_EQ(out.samples.size(), 1u) << name;
    EXPECT_NEAR(out.samples[0].gyro_rad_s.x(), 0.5, 1e-3);
    EXPECT_NEAR(out.samples[0].accel_m_s2.z(), -9.75, 0.005 + 1e-9);
  }
  try {
    make_can_encoder("canopen");
    FAIL() << "unknown protocol accepted";
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("canopen"), std::string::npos);
    EXPECT_NE(what.find("dronecan"), std::string::npos);
  }
  imuemu::drivers::CanEncoderOptions bad;
  bad.j1939.source_address = 254;
  try {
    make_can_decoder("j1939", bad);
    FAIL() << "source address 254 accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("source_address"), std::string::npos);
  }
  bad.j1939.source_address = 1;
  bad.j1939.measurement_latency_ms = 200.0;
  EXPECT_THROW(make_can_encoder("j1939", bad), std::invalid_argument);
}

}  // namespace

// A tick the emission engine does not send is not a lost transfer
// (docs/emission.md): ticks 0, 1, 3 of a 100 Hz grid, tick 2 skipped.
TEST(SkippedTick, DroneCanTransferIdsCountTransfersSentSoOnlyTheTimestampJumps) {
  dc::DroneCanEncoder encoder;
  dc::DroneCanDecoder decoder;
  Collected out;
  for (TimeNs k : {0, 1, 3}) {
    std::vector<CanFrame> frames;
    encoder.encode(make_sample(k * 10'000'000, Vec3::Zero(), Vec3(0, 0, -9.8)), frames);
    for (const CanFrame& f : frames) decoder.feed(f, out.callback());
  }
  ASSERT_EQ(out.samples.size(), 3u);
  // DroneCAN 4.1: the transfer id is incremented per transfer of a data type
  // from a node, i.e. per message sent: 0, 1, 2 on the wire.
  EXPECT_EQ(decoder.counters().sequence_gaps, 0u);
  EXPECT_EQ(out.samples[2].sequence - out.samples[1].sequence, 1u);
  EXPECT_EQ(out.samples[2].t_ns - out.samples[1].t_ns, 20'000'000);  // usec 10000 -> 30000
}

TEST(SkippedTick, J1939HasNeitherCounterNorTime) {
  jj::J1939Encoder encoder;
  jj::J1939Decoder decoder;
  Collected out;
  for (TimeNs k : {0, 1, 3}) {
    std::vector<CanFrame> frames;
    encoder.encode(make_sample(k * 10'000'000, Vec3::Zero(), Vec3(0, 0, -9.8)), frames);
    for (const CanFrame& f : frames) decoder.feed(f, out.callback());
  }
  ASSERT_EQ(out.samples.size(), 3u);
  EXPECT_EQ(decoder.counters().sequence_gaps, 0u);
  for (const DecodedSample& d : out.samples) EXPECT_FALSE(d.has_sequence || d.has_time);
}

// uavcan.Timestamp DSDL: "uint56 UNKNOWN = 0". The emulator always knows the
// sample time, so it never sends 0. Before issue 12 the first RawIMU of every
// run that starts at trajectory time 0 (all built-in samples) carried usec 0
// = UNKNOWN, and so did any time below 1 us or negative.
TEST(DroneCanEncoder, KnownSampleTimesAreNeverSentAsUnknownZero) {
  const dc::DroneCanOptions options;
  auto usec_bytes = [&options](TimeNs t_ns) {
    const std::vector<std::uint8_t> b =
        dc::serialize_raw_imu(make_sample(t_ns, Vec3::Zero(), Vec3(0, 0, -9.8)), options).bytes;
    return std::vector<std::uint8_t>(b.begin(), b.begin() + 7);  // uint56, little-endian, byte aligned
  };
  const std::vector<std::uint8_t> one_us{0x01, 0, 0, 0, 0, 0, 0};
  EXPECT_EQ(usec_bytes(0), one_us);      // was 00 00 00 00 00 00 00
  EXPECT_EQ(usec_bytes(999), one_us);    // was 0 (floor to the microsecond)
  EXPECT_EQ(usec_bytes(-5), one_us);     // was 0
  EXPECT_EQ(usec_bytes(1000), one_us);   // unchanged
  EXPECT_EQ(usec_bytes(2'500), (std::vector<std::uint8_t>{0x02, 0, 0, 0, 0, 0, 0}));
  EXPECT_EQ(usec_bytes(1'234'567'000), (std::vector<std::uint8_t>{0x87, 0xD6, 0x12, 0, 0, 0, 0}));
  EXPECT_EQ(dc::raw_imu_timestamp_usec(0, -10'000), dc::kRawImuEarliestKnownUsec);
  EXPECT_EQ(dc::raw_imu_timestamp_usec(0, 5'000), 5u);
  EXPECT_EQ(dc::raw_imu_timestamp_usec(std::numeric_limits<TimeNs>::max(), 0),
            static_cast<std::uint64_t>(std::numeric_limits<TimeNs>::max() / 1000));

  // Through the encoder, frames as a receiver reassembles them: the first
  // transfer's first frame is CRC (2 bytes) then usec bytes 0..4.
  dc::DroneCanEncoder encoder(options);
  std::vector<CanFrame> frames;
  encoder.encode(make_sample(0, Vec3::Zero(), Vec3(0, 0, -9.8)), frames);
  ASSERT_EQ(frames.size(), 7u);
  EXPECT_EQ(std::vector<std::uint8_t>(frames[0].data.begin() + 2, frames[0].data.begin() + 7),
            (std::vector<std::uint8_t>{0x01, 0, 0, 0, 0}));
  EXPECT_EQ(frames[1].data[0], 0);
  EXPECT_EQ(frames[1].data[1], 0);
  dc::DroneCanDecoder decoder(options);
  Collected out;
  for (const CanFrame& f : frames) decoder.feed(f, out.callback());
  ASSERT_EQ(out.samples.size(), 1u);
  EXPECT_TRUE(out.samples[0].has_time);
  EXPECT_EQ(out.samples[0].t_ns, 1000);
}


// End to end through the emission engine: the SSI2 angles are the sensor's
// attitude that the engine knows. Before issue 12 nothing filled them, so
// every SSI2 frame the daemon sent was "not available" (FF FF FF FF FF FF FF,
// latency). A body held at heading 30, pitch 10, roll 5 deg (Eq. 1.2), in the
// flat scene and in the ecef scene near Barcelona.
namespace {
class CapturingCanOutput final : public imuemu::device::CanOutput {
 public:
  bool send(const CanFrame& frame) override {
    std::lock_guard lock(mutex_);
    frames_.push_back(frame);
    return true;
  }
  std::string describe() const override { return "capture"; }
  imuemu::drivers::TransportCounters counters() const override { return {}; }
  std::vector<CanFrame> frames() const {
    std::lock_guard lock(mutex_);
    return frames_;
  }

 private:
  mutable std::mutex mutex_;
  std::vector<CanFrame> frames_;
};
}  // namespace

TEST(J1939Emission, SlopeSensor2CarriesTheSensorAttitudeFromTheEngine) {
  using namespace std::chrono_literals;
  namespace em = imuemu::emission;
  for (const imuemu::Physics physics : {imuemu::Physics::flat, imuemu::Physics::ecef}) {
    SCOPED_TRACE(physics == imuemu::Physics::flat ? "flat" : "ecef");
    imuemu::attitude::HeadingPitchRoll hpr;
    hpr.heading_rad = 30.0 * kDegToRad;
    hpr.pitch_rad = 10.0 * kDegToRad;
    hpr.roll_rad = 5.0 * kDegToRad;
    const imuemu::Mat3 body_to_ned = imuemu::attitude::rotation_from_hpr(hpr);
    std::vector<imuemu::Pose> knots;
    for (int i = 0; i <= 8; ++i) {
      imuemu::Pose p;
      p.t_ns = TimeNs{i} * 1'000'000'000;
      if (physics == imuemu::Physics::flat) {
        p.attitude = body_to_ned;
      } else {
        imuemu::earth::Geodetic g;
        g.latitude_rad = 41.4 * kDegToRad;
        g.longitude_rad = 2.2 * kDegToRad;
        g.height_m = 100.0;
        p.position_m = imuemu::earth::ecef_from_geodetic(g);
        p.attitude = imuemu::attitude::ned_to_ecef(g.latitude_rad, g.longitude_rad) * body_to_ned;
      }
      knots.push_back(p);
    }
    jj::J1939Options options;
    options.send_slope = true;
    em::DeviceOptions d;
    d.name = "j1939";
    d.rate_hz = 50;
    d.pipeline.scene.physics = physics;
    d.pipeline.rate_hz = 50;
    d.pipeline.kernel.delta = 50;
    auto out = std::make_unique<CapturingCanOutput>();
    CapturingCanOutput* capture = out.get();
    d.device = imuemu::device::make_can_device(std::make_unique<jj::J1939Encoder>(options), std::move(out));
    std::vector<em::DeviceOptions> devices;
    devices.push_back(std::move(d));
    em::EngineOptions eo;
    eo.trajectory = knots;
    eo.max_ticks_per_device = 100;
    eo.drop_late_ticks = false;
    eo.ring_capacity = 128;
    em::EmissionEngine engine(std::move(eo), std::move(devices));
    engine.start();
    ASSERT_TRUE(engine.wait(60s));
    engine.stop();

    int slope_frames = 0;
    for (const CanFrame& f : capture->frames()) {
      if (jj::parse_can_id(f.id).pgn != jj::kPgnSlopeSensorInformation2) continue;
      ++slope_frames;
      const double pitch_deg = (f.data[0] | f.data[1] << 8 | f.data[2] << 16) / 32768.0 - 250.0;
      const double roll_deg = (f.data[3] | f.data[4] << 8 | f.data[5] << 16) / 32768.0 - 250.0;
      EXPECT_NEAR(pitch_deg, 10.0, 1.0 / 32768.0);  // SPN 4976, within one resolution step
      EXPECT_NEAR(roll_deg, 5.0, 1.0 / 32768.0);    // SPN 4977
      EXPECT_EQ(f.data[6], 0x00);  // compensation On, figures of merit fully functional
    }
    // One SSI2 per sample sent (a tick the engine could not send in time on a
    // slow host is simply absent; it does not change what is checked).
    EXPECT_GT(slope_frames, 0);
    EXPECT_EQ(static_cast<std::uint64_t>(slope_frames), engine.stats().devices[0].emitted);
  }
}
}  // namespace unity_engine_test_protocols_can
