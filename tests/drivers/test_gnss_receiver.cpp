// The GNSS receiver personalities (issue 28): NMEA 0183 sentences and u-blox
// UBX frames checked against bytes written by hand from the documents, not
// against the encoders' own output:
//   NMEA 0183 v4.10 sentence formats (GGA, RMC, VTG, GSA, ZDA): '$', fields,
//     '*', XOR of the characters between them as two hex digits, CR LF, at
//     most 82 characters;
//   u-blox 8 / M8 receiver description (UBX-13003221): sync 0xB5 0x62,
//     class, id, u16 LE length, payload, 8-bit Fletcher CK_A CK_B over class
//     .. payload; UBX-NAV-PVT class 0x01 id 0x07, 92 bytes, its field offsets.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "drivers/gnss_fix.hpp"
#include "drivers/protocols/nmea.hpp"
#include "drivers/protocols/stream_protocols.hpp"
#include "drivers/protocols/ubx.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_drivers_test_gnss_receiver {
namespace imuemu { using namespace ::imuemu; }

using namespace imuemu;
using namespace imuemu::drivers;

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kRadPerDeg = kPi / 180.0;
constexpr std::int64_t kNs = 1'000'000'000;
// GPS week 2400 starts 2026-01-04T00:00:00 GPS time (1980-01-06 + 16800 days).
constexpr std::int64_t kWeek2400Ns = 2400LL * 604'800LL * kNs;

// The textbook GGA example's position (48 deg 07.038' N, 11 deg 31.000' E,
// 545.4 m above MSL, geoid 46.9 m above the ellipsoid) at 12:35:19 UTC on
// 2026-01-04: GPS time 12:35:37 (GPS - UTC = 18 s since 2017), in GPS week
// 2400 at TOW 12 h 35 min 37 s.
GnssFix known_fix() {
  GnssFix f;
  f.gps_time_ns = kWeek2400Ns + (12LL * 3600 + 35 * 60 + 37) * kNs;
  f.gps_minus_utc_s = 18;
  f.fix_type = GnssFixType::fix_3d;
  f.latitude_rad = (48.0 + 7.038 / 60.0) * kRadPerDeg;
  f.longitude_rad = (11.0 + 31.0 / 60.0) * kRadPerDeg;
  f.geoid_separation_m = 46.9;
  f.height_m = 545.4 + 46.9;
  // 22.4 knots over ground on a true course of 84.4 deg.
  const double v = 22.4 * 1852.0 / 3600.0;
  f.velocity_ned_m_s = Vec3(v * std::cos(84.4 * kRadPerDeg), v * std::sin(84.4 * kRadPerDeg), -0.25);
  f.satellites = 8;
  f.hdop = 0.9;
  f.pdop = 1.5;
  f.vdop = 1.2;
  f.horizontal_accuracy_m = 1.5;
  f.vertical_accuracy_m = 2.5;
  f.speed_accuracy_m_s = 0.05;
  f.time_accuracy_ns = 20.0;
  return f;
}

std::string text(const std::vector<std::uint8_t>& b) { return std::string(b.begin(), b.end()); }

// The NMEA checksum as the standard defines it, written here again.
std::string nmea_checksum(const std::string& between) {
  unsigned x = 0;
  for (const char c : between) x ^= static_cast<unsigned char>(c);
  char hex[3];
  std::snprintf(hex, sizeof hex, "%02X", x);
  return hex;
}

// ---- a UBX reader written from the u-blox document (not the encoder's)
struct UbxFrame {
  std::uint8_t cls = 0, id = 0;
  std::vector<std::uint8_t> payload;
};
std::vector<UbxFrame> ubx_frames(const std::vector<std::uint8_t>& b) {
  std::vector<UbxFrame> frames;
  std::size_t i = 0;
  while (i + 8 <= b.size()) {
    EXPECT_EQ(b[i], 0xB5);
    EXPECT_EQ(b[i + 1], 0x62);
    const std::size_t len = static_cast<std::size_t>(b[i + 4]) | static_cast<std::size_t>(b[i + 5]) << 8;
    if (i + 8 + len > b.size()) break;
    std::uint8_t ck_a = 0, ck_b = 0;
    for (std::size_t k = i + 2; k < i + 6 + len; ++k) {
      ck_a = static_cast<std::uint8_t>(ck_a + b[k]);
      ck_b = static_cast<std::uint8_t>(ck_b + ck_a);
    }
    EXPECT_EQ(b[i + 6 + len], ck_a);
    EXPECT_EQ(b[i + 7 + len], ck_b);
    frames.push_back({b[i + 2], b[i + 3], std::vector<std::uint8_t>(b.begin() + static_cast<std::ptrdiff_t>(i + 6),
                                                                     b.begin() + static_cast<std::ptrdiff_t>(i + 6 + len))});
    i += 8 + len;
  }
  EXPECT_EQ(i, b.size());
  return frames;
}
std::uint32_t u4(const std::vector<std::uint8_t>& p, std::size_t at) {
  return static_cast<std::uint32_t>(p[at]) | static_cast<std::uint32_t>(p[at + 1]) << 8 |
         static_cast<std::uint32_t>(p[at + 2]) << 16 | static_cast<std::uint32_t>(p[at + 3]) << 24;
}
std::int32_t i4(const std::vector<std::uint8_t>& p, std::size_t at) { return static_cast<std::int32_t>(u4(p, at)); }
std::uint16_t u2(const std::vector<std::uint8_t>& p, std::size_t at) {
  return static_cast<std::uint16_t>(p[at] | p[at + 1] << 8);
}

}  // namespace

// GGA of the known fix, field by field as NMEA 0183 lays it out; the
// checksum is the XOR of the characters between '$' and '*', 0x59 (worked
// out by hand, and recomputed here).
TEST(NmeaSentences, GgaOfAKnownPositionAndTimeIsTheHandWrittenSentence) {
  const std::string body = "GPGGA,123519.00,4807.038000,N,01131.000000,E,1,08,0.9,545.40,M,46.9,M,,";
  EXPECT_EQ(nmea_checksum(body), "59");
  std::vector<std::uint8_t> out;
  nmea::append_gga(known_fix(), "GP", out);
  EXPECT_EQ(text(out), "$" + body + "*59\r\n");
  EXPECT_LE(out.size(), nmea::kMaxSentenceChars);
  out.clear();
  nmea::append_gga(known_fix(), "GN", out);
  EXPECT_EQ(text(out), "$GNGGA" + body.substr(5) + "*" + nmea_checksum("GNGGA" + body.substr(5)) + "\r\n");
}

// RMC (v4.10): status A, speed 22.4 knots, course 84.4 deg true, date
// 04-01-26, no magnetic variation, mode A, navigational status V; XOR 0x16.
TEST(NmeaSentences, RmcOfAKnownPositionTimeAndVelocityIsTheHandWrittenSentence) {
  const std::string body = "GPRMC,123519.00,A,4807.038000,N,01131.000000,E,22.400,84.40,040126,,,A,V";
  EXPECT_EQ(nmea_checksum(body), "16");
  std::vector<std::uint8_t> out;
  nmea::append_rmc(known_fix(), "GP", out);
  EXPECT_EQ(text(out), "$" + body + "*16\r\n");
}

TEST(NmeaSentences, VtgGsaZdaAreTheHandWrittenSentences) {
  std::vector<std::uint8_t> out;
  // 22.4 knots = 41.4848 km/h (1 knot = 1.852 km/h).
  const std::string vtg = "GPVTG,84.40,T,,M,22.400,N,41.485,K,A";
  nmea::append_vtg(known_fix(), "GP", out);
  EXPECT_EQ(text(out), "$" + vtg + "*" + nmea_checksum(vtg) + "\r\n");
  out.clear();
  const std::string gsa = "GPGSA,A,3,01,02,03,04,05,06,07,08,,,,,1.50,0.90,1.20,1";
  nmea::append_gsa(known_fix(), "GP", out);
  EXPECT_EQ(text(out), "$" + gsa + "*" + nmea_checksum(gsa) + "\r\n");
  out.clear();
  const std::string zda = "GPZDA,123519.00,04,01,2026,00,00";
  nmea::append_zda(known_fix(), "GP", out);
  EXPECT_EQ(text(out), "$" + zda + "*" + nmea_checksum(zda) + "\r\n");
}

// Southern and western hemispheres, the minutes rounding into the next
// degree, a fraction of a second rounded to the 10 ms of hhmmss.ss, and the
// longest fields together still within the 82 characters of a sentence.
TEST(NmeaSentences, SignsRoundingAndLengthLimit) {
  GnssFix f = known_fix();
  f.latitude_rad = -(33.0 + 59.99999996 / 60.0) * kRadPerDeg;  // rounds to 34 deg 00.000000'
  f.longitude_rad = -(151.0 + 12.5 / 60.0) * kRadPerDeg;
  f.gps_time_ns += 123'456'789;  // 12:35:19.123456789 UTC -> 19.12
  f.geoid_separation_m = -150.27;  // sent to 0.1 m: -150.3; MSL = height + 150.3
  f.height_m = 12345.67 - 150.3;
  f.hdop = 12.3;
  std::vector<std::uint8_t> out;
  nmea::append_gga(f, "GN", out);
  const std::string body = "GNGGA,123519.12,3400.000000,S,15112.500000,W,1,08,12.3,12345.67,M,-150.3,M,,";
  EXPECT_EQ(text(out), "$" + body + "*" + nmea_checksum(body) + "\r\n");
  EXPECT_LE(out.size(), nmea::kMaxSentenceChars);
}

TEST(NmeaSentences, NoFixAndNoTimeSendEmptyFields) {
  GnssFix f = known_fix();
  f.fix_type = GnssFixType::none;
  std::vector<std::uint8_t> out;
  nmea::append_rmc(f, "GP", out);
  const std::string rmc = "GPRMC,123519.00,V,,,,,,,040126,,,N,V";
  EXPECT_EQ(text(out), "$" + rmc + "*" + nmea_checksum(rmc) + "\r\n");
  f.time_valid = false;
  out.clear();
  nmea::append_zda(f, "GP", out);
  const std::string zda = "GPZDA,,,,,,";
  EXPECT_EQ(text(out), "$" + zda + "*" + nmea_checksum(zda) + "\r\n");
}

// NAV-PVT read back with the offsets of the u-blox 8/M8 description
// (UBX-NAV-PVT payload: iTOW 0, year 4, month 6, day 7, hour 8, min 9,
// sec 10, valid 11, tAcc 12, nano 16, fixType 20, flags 21, flags2 22,
// numSV 23, lon 24, lat 28, height 32, hMSL 36, hAcc 40, vAcc 44, velN 48,
// velE 52, velD 56, gSpeed 60, headMot 64, sAcc 68, headAcc 72, pDOP 76).
TEST(UbxFrames, NavPvtFieldsAtTheDocumentsOffsets) {
  GnssFix f = known_fix();
  f.gps_time_ns += 250'000'000;  // a 4 Hz epoch: .25 s
  std::vector<std::uint8_t> out;
  ubx::append_nav_pvt(f, out);
  ASSERT_EQ(out.size(), 6u + 92u + 2u);
  EXPECT_EQ(out[2], 0x01);  // class NAV
  EXPECT_EQ(out[3], 0x07);  // id PVT
  EXPECT_EQ(out[4], 92);
  EXPECT_EQ(out[5], 0);
  const std::vector<UbxFrame> frames = ubx_frames(out);
  ASSERT_EQ(frames.size(), 1u);
  const std::vector<std::uint8_t>& p = frames[0].payload;
  EXPECT_EQ(u4(p, 0), (12u * 3600u + 35u * 60u + 37u) * 1000u + 250u);  // iTOW: GPS time of week, ms
  EXPECT_EQ(u2(p, 4), 2026);
  EXPECT_EQ(p[6], 1);
  EXPECT_EQ(p[7], 4);
  EXPECT_EQ(p[8], 12);
  EXPECT_EQ(p[9], 35);
  EXPECT_EQ(p[10], 19);  // UTC: GPS - 18 s
  EXPECT_EQ(p[11], 0x07);  // validDate | validTime | fullyResolved
  EXPECT_EQ(u4(p, 12), 20u);
  EXPECT_EQ(i4(p, 16), 250'000'000);
  EXPECT_EQ(p[20], 3);     // 3D fix
  EXPECT_EQ(p[21] & 0x01, 0x01);  // gnssFixOK
  EXPECT_EQ(p[23], 8);
  EXPECT_EQ(i4(p, 24), 115'166'667);  // 11.5166667 deg
  EXPECT_EQ(i4(p, 28), 481'173'000);  // 48.1173 deg
  EXPECT_EQ(i4(p, 32), 592'300);      // mm above the ellipsoid
  EXPECT_EQ(i4(p, 36), 545'400);      // mm above MSL
  EXPECT_EQ(u4(p, 40), 1500u);
  EXPECT_EQ(u4(p, 44), 2500u);
  const double v_mm_s = 22.4 * 1852.0 / 3.6;  // 11523.56 mm/s
  EXPECT_EQ(i4(p, 48), std::lround(v_mm_s * std::cos(84.4 * kRadPerDeg)));
  EXPECT_EQ(i4(p, 52), std::lround(v_mm_s * std::sin(84.4 * kRadPerDeg)));
  EXPECT_EQ(i4(p, 56), -250);
  EXPECT_EQ(i4(p, 60), std::lround(v_mm_s));
  EXPECT_EQ(i4(p, 64), 8'440'000);  // 84.4 deg in 1e-5 deg
  EXPECT_EQ(u4(p, 68), 50u);
  EXPECT_EQ(u2(p, 76), 150);
}

// The messages beside NAV-PVT, in class/id order with their documented
// lengths, and the fields ArduPilot's UBX driver reads from them.
TEST(UbxFrames, LegacyNavigationMessagesHaveTheDocumentsLayouts) {
  StreamEncoderOptions o;
  o.gnss.gps_time_at_t0_ns = kWeek2400Ns + 100 * kNs;
  auto enc = make_stream_encoder("ubx", o);
  ImuFrameInput s;
  s.t_ns = 2 * kNs;
  s.period_ns = kNs;
  s.has_navigation = true;
  s.latitude_rad = 0.0;
  s.longitude_rad = 0.0;
  s.height_m = 100.0;
  s.velocity_ned_m_s = Vec3(0.0, 10.0, 1.0);
  std::vector<std::uint8_t> out;
  enc->encode(s, out);
  EXPECT_LE(out.size(), enc->max_bytes_per_sample());
  const std::vector<UbxFrame> frames = ubx_frames(out);
  ASSERT_EQ(frames.size(), 8u);
  // PVT, TIMEGPS, SOL, POSLLH, VELNED, STATUS, DOP, EOE: the time-bearing
  // messages first, the end-of-epoch marker last.
  const std::uint8_t ids[] = {0x07, 0x20, 0x06, 0x02, 0x12, 0x03, 0x04, 0x61};
  const std::size_t lengths[] = {92, 16, 52, 28, 36, 16, 18, 4};
  for (std::size_t i = 0; i < 8; ++i) {
    EXPECT_EQ(frames[i].cls, 0x01);
    EXPECT_EQ(frames[i].id, ids[i]);
    EXPECT_EQ(frames[i].payload.size(), lengths[i]);
    EXPECT_EQ(u4(frames[i].payload, 0), 102'000u);  // iTOW of TOW 102 s, every message
  }
  enum { kPvt, kTimegps, kSol, kPosllh, kVelned, kStatus, kDop };
  // NAV-POSLLH: height mm.
  EXPECT_EQ(i4(frames[kPosllh].payload, 12), 100'000);
  // NAV-STATUS: gpsFix 3, flags gpsFixOk | wknSet | towSet.
  EXPECT_EQ(frames[kStatus].payload[4], 3);
  EXPECT_EQ(frames[kStatus].payload[5], 0x0D);
  // NAV-SOL: week 2400; ECEF at (0, 0, 100 m) is x = a + 100 m = 637823700 cm;
  // velocity east 10 m/s is +y, down 1 m/s is -x.
  EXPECT_EQ(u2(frames[kSol].payload, 8), 2400);
  EXPECT_EQ(i4(frames[kSol].payload, 12), 637'823'700);
  EXPECT_EQ(i4(frames[kSol].payload, 16), 0);
  EXPECT_EQ(i4(frames[kSol].payload, 28), -100);
  EXPECT_EQ(i4(frames[kSol].payload, 32), 1000);
  EXPECT_EQ(frames[kSol].payload[47], 12);
  // NAV-VELNED: cm/s, heading 90 deg.
  EXPECT_EQ(i4(frames[kVelned].payload, 8), 1000);
  EXPECT_EQ(u4(frames[kVelned].payload, 20), 1000u);
  EXPECT_EQ(i4(frames[kVelned].payload, 24), 9'000'000);
  // NAV-TIMEGPS: week, leap seconds 18, valid.
  EXPECT_EQ(u2(frames[kTimegps].payload, 8), 2400);
  EXPECT_EQ(frames[kTimegps].payload[10], 18);
  EXPECT_EQ(frames[kTimegps].payload[11], 0x07);
  // NAV-DOP: hDOP 0.7 (the default) at offset 12, scale 0.01.
  EXPECT_EQ(u2(frames[kDop].payload, 12), 70);
}

// The NMEA device end to end: one epoch per sample, the sample's time on
// the configured GPS time base (default GPS week 2400, TOW 0 at trajectory
// time 0), UTC with the leap seconds; within the link budget; each sentence
// a frame for the link faults.
TEST(GnssReceiverEncoders, OneEpochPerSampleOnTheConfiguredTimeBase) {
  StreamEncoderOptions o;
  o.nmea_talker = "GN";
  auto enc = make_stream_encoder("nmea", o);
  EXPECT_TRUE(enc->needs_navigation());
  ImuFrameInput s;
  s.t_ns = 61 * kNs;  // GPS 00:01:01 on 2026-01-04 = UTC 00:00:43
  s.has_navigation = true;
  s.latitude_rad = 0.5;
  s.height_m = 10.0;
  std::vector<std::uint8_t> out;
  enc->encode(s, out);
  EXPECT_LE(out.size(), enc->max_bytes_per_sample());
  const std::string t = text(out);
  EXPECT_EQ(t.rfind("$GNRMC,000043.00,A,", 0), 0u) << t;
  EXPECT_NE(t.find("$GNZDA,000043.00,04,01,2026,00,00*"), std::string::npos) << t;
  EXPECT_EQ(enc->frame_layout(std::span<const std::uint8_t>(out)).frame_bytes, t.find('\n') + 1);
  // utc: the trajectory is stamped in POSIX UTC.
  o.gnss.time_base = GnssTimeBase::utc;
  s.t_ns = 1'767'225'600LL * kNs;  // 2026-01-01T00:00:00Z
  out.clear();
  make_stream_encoder("nmea", o)->encode(s, out);
  EXPECT_NE(text(out).find("$GNZDA,000000.00,01,01,2026,00,00*"), std::string::npos) << text(out);
  // Talker ids are GP or GN.
  StreamEncoderOptions other;
  other.nmea_talker = "BD";
  EXPECT_THROW(make_stream_encoder("nmea", other), std::invalid_argument);
  // The decoders take what the encoders send.
  for (const char* name : {"nmea", "ubx"}) {
    auto e = make_stream_encoder(name);
    auto d = make_stream_decoder(name);
    std::vector<std::uint8_t> bytes;
    for (int k = 0; k < 3; ++k) {
      s.t_ns = k * kNs;
      e->encode(s, bytes);
    }
    d->feed(bytes, [](const DecodedSample&) {});
    EXPECT_EQ(d->counters().frames, std::string(name) == "nmea" ? 15u : 24u) << name;
    EXPECT_EQ(d->counters().checksum_errors + d->counters().resync_bytes, 0u) << name;
  }
}

// iTOW is the epoch's time of week rounded to the ms, fTOW the rest (u-blox:
// TOW = iTOW * 1e-3 + fTOW * 1e-9 s, fTOW in +-500000 ns); an epoch in the
// last half millisecond of a week is TOW 0 of the next week.
TEST(UbxFrames, TimeOfWeekRoundsToTheMillisecondWithTheRestInFtow) {
  GnssFix f = known_fix();
  f.gps_time_ns = 2401LL * 604'800LL * kNs - 300'000;  // 0.3 ms before week 2401
  std::vector<std::uint8_t> out;
  ubx::append_nav_timegps(f, out);
  std::vector<UbxFrame> frames = ubx_frames(out);
  ASSERT_EQ(frames.size(), 1u);
  EXPECT_EQ(u4(frames[0].payload, 0), 0u);                      // iTOW
  EXPECT_EQ(i4(frames[0].payload, 4), -300'000);                // fTOW
  EXPECT_EQ(u2(frames[0].payload, 8), 2401);                    // week
  f.gps_time_ns = kWeek2400Ns + 1'234'567'891;  // TOW 1.234567891 s
  out.clear();
  ubx::append_nav_sol(f, out);
  frames = ubx_frames(out);
  ASSERT_EQ(frames.size(), 1u);
  EXPECT_EQ(u4(frames[0].payload, 0), 1235u);
  EXPECT_EQ(i4(frames[0].payload, 4), -432'109);
  EXPECT_EQ(u2(frames[0].payload, 8), 2400);
}
}  // namespace unity_drivers_test_gnss_receiver
