// u-blox UBX GNSS receiver output; see ubx.hpp. Payload layouts from the
// u-blox 8 / u-blox M8 receiver description (UBX-13003221), section "UBX-NAV".
#include "drivers/protocols/ubx.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/attitude.hpp"
#include "core/earth.hpp"
#include "drivers/protocols/gps_time.hpp"
#include "drivers/protocols/wire_bytes.hpp"

namespace imuemu::drivers::ubx {

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDegPerRad = 180.0 / kPi;
constexpr std::int64_t kNs = 1'000'000'000;
constexpr std::int64_t kNsPerWeek = 604'800LL * kNs;

std::int32_t i32(double v) {
  if (!std::isfinite(v)) return 0;
  constexpr double kMax = std::numeric_limits<std::int32_t>::max(), kMin = std::numeric_limits<std::int32_t>::min();
  return static_cast<std::int32_t>(std::llround(std::clamp(v, kMin, kMax)));
}
std::uint32_t u32(double v) {
  if (!std::isfinite(v) || v < 0.0) return 0;
  return static_cast<std::uint32_t>(std::llround(std::min(v, 4294967295.0)));
}
std::uint16_t u16(double v) {
  if (!std::isfinite(v) || v < 0.0) return 0;
  return static_cast<std::uint16_t>(std::llround(std::min(v, 65535.0)));
}

bool has_position(const GnssFix& f) { return f.fix_type != GnssFixType::none; }
std::uint8_t fix_code(const GnssFix& f) {  // 0 no fix, 2 2D, 3 3D
  return f.fix_type == GnssFixType::fix_3d ? 3 : f.fix_type == GnssFixType::fix_2d ? 2 : 0;
}

// GPS week, time of week in ms (iTOW) and the rest in ns (fTOW in
// NAV-SOL/TIMEGPS: iTOW * 1e-3 + fTOW * 1e-9 is the epoch's TOW; iTOW is
// rounded to the nearest ms, so fTOW is in [-500000, 500000)).
struct GpsWeekTime {
  std::int64_t week = 0;
  std::uint32_t itow_ms = 0;
  std::int32_t ftow_ns = 0;
};
GpsWeekTime week_time(const GnssFix& f) {
  GpsWeekTime w;
  const std::int64_t t = std::max<std::int64_t>(0, f.gps_time_ns);
  w.week = t / kNsPerWeek;
  const std::int64_t tow_ns = t % kNsPerWeek;
  std::int64_t ms = (tow_ns + 500'000) / 1'000'000;
  w.ftow_ns = static_cast<std::int32_t>(tow_ns - ms * 1'000'000);
  if (ms >= 604'800'000) {  // the last half ms of a week rounds to TOW 0 of the next
    ms -= 604'800'000;
    ++w.week;
  }
  w.itow_ms = static_cast<std::uint32_t>(ms);
  return w;
}

double ground_speed(const GnssFix& f) { return std::hypot(f.velocity_ned_m_s.x(), f.velocity_ned_m_s.y()); }
// Heading of motion in [0, 360) degrees.
double heading_deg(const GnssFix& f) {
  double deg = std::atan2(f.velocity_ned_m_s.y(), f.velocity_ned_m_s.x()) * kDegPerRad;
  if (deg < 0.0) deg += 360.0;
  return deg;
}
std::int32_t heading_1e5(const GnssFix& f) { return i32(heading_deg(f) * 1e5) % 36'000'000; }
// Heading accuracy from the speed accuracy: the angle a speed error of
// sAcc makes at the ground speed (180 degrees when standing still).
double heading_accuracy_deg(const GnssFix& f) {
  const double v = ground_speed(f);
  if (v <= f.speed_accuracy_m_s) return 180.0;
  return std::min(180.0, std::atan2(f.speed_accuracy_m_s, v) * kDegPerRad);
}

template <std::size_t N>
void append_frame(std::uint8_t id, const std::array<std::uint8_t, N>& payload, std::vector<std::uint8_t>& out) {
  const std::size_t start = out.size();
  out.push_back(kSync1);
  out.push_back(kSync2);
  out.push_back(kClassNav);
  out.push_back(id);
  out.push_back(static_cast<std::uint8_t>(N & 0xFF));
  out.push_back(static_cast<std::uint8_t>(N >> 8));
  out.insert(out.end(), payload.begin(), payload.end());
  const auto ck = checksum(std::span<const std::uint8_t>(out.data() + start + 2, 4 + N));
  out.push_back(ck[0]);
  out.push_back(ck[1]);
}

template <class T, std::size_t N>
void put(std::array<std::uint8_t, N>& p, std::size_t at, T v) {
  wire::put_le<T>(p.data() + at, v);
}

}  // namespace

std::array<std::uint8_t, 2> checksum(std::span<const std::uint8_t> bytes) {
  std::uint8_t a = 0, b = 0;
  for (const std::uint8_t x : bytes) {
    a = static_cast<std::uint8_t>(a + x);
    b = static_cast<std::uint8_t>(b + a);
  }
  return {a, b};
}

// UBX-NAV-PVT (0x01 0x07), 92 bytes.
void append_nav_pvt(const GnssFix& f, std::vector<std::uint8_t>& out) {
  std::array<std::uint8_t, kNavPvtPayloadBytes> p{};
  const GpsWeekTime w = week_time(f);
  const std::int64_t utc_ns = f.gps_time_ns + gps_time::kGpsEpochPosixSeconds * kNs -
                              static_cast<std::int64_t>(f.gps_minus_utc_s) * kNs;
  const gps_time::UtcCalendar c = gps_time::calendar_from_posix_ns(utc_ns);
  put<std::uint32_t>(p, 0, w.itow_ms);
  put<std::uint16_t>(p, 4, static_cast<std::uint16_t>(c.year));
  p[6] = static_cast<std::uint8_t>(c.month);
  p[7] = static_cast<std::uint8_t>(c.day);
  p[8] = static_cast<std::uint8_t>(c.hour);
  p[9] = static_cast<std::uint8_t>(c.minute);
  p[10] = static_cast<std::uint8_t>(c.second);
  p[11] = f.time_valid ? 0x07 : 0x00;  // valid: validDate | validTime | fullyResolved
  put<std::uint32_t>(p, 12, u32(f.time_accuracy_ns));
  put<std::int32_t>(p, 16, static_cast<std::int32_t>(c.nanosecond));  // nano: fraction of the UTC second
  p[20] = fix_code(f);
  const bool fix = has_position(f);
  p[21] = fix ? 0x01 : 0x00;  // flags: gnssFixOK (no differential, no carrier solution, headVehValid clear)
  p[22] = f.time_valid ? 0xE0 : 0x20;  // flags2: confirmedAvai | confirmedDate | confirmedTime
  p[23] = static_cast<std::uint8_t>(std::clamp(f.satellites, 0, 255));
  if (fix) {
    put<std::int32_t>(p, 24, i32(f.longitude_rad * kDegPerRad * 1e7));
    put<std::int32_t>(p, 28, i32(f.latitude_rad * kDegPerRad * 1e7));
    put<std::int32_t>(p, 32, i32(f.height_m * 1e3));
    put<std::int32_t>(p, 36, i32((f.height_m - f.geoid_separation_m) * 1e3));
    put<std::uint32_t>(p, 40, u32(f.horizontal_accuracy_m * 1e3));
    put<std::uint32_t>(p, 44, u32(f.vertical_accuracy_m * 1e3));
    put<std::int32_t>(p, 48, i32(f.velocity_ned_m_s.x() * 1e3));
    put<std::int32_t>(p, 52, i32(f.velocity_ned_m_s.y() * 1e3));
    put<std::int32_t>(p, 56, i32(f.velocity_ned_m_s.z() * 1e3));
    put<std::int32_t>(p, 60, i32(ground_speed(f) * 1e3));
    put<std::int32_t>(p, 64, heading_1e5(f));
    put<std::uint32_t>(p, 68, u32(f.speed_accuracy_m_s * 1e3));
    put<std::uint32_t>(p, 72, u32(heading_accuracy_deg(f) * 1e5));
  } else {
    put<std::uint32_t>(p, 40, 0xFFFFFFFFu);  // accuracy unknown
    put<std::uint32_t>(p, 44, 0xFFFFFFFFu);
    put<std::uint32_t>(p, 68, 0xFFFFFFFFu);
    put<std::uint32_t>(p, 72, 18'000'000u);
  }
  put<std::uint16_t>(p, 76, fix ? u16(f.pdop * 100.0) : 9999);
  p[78] = fix ? 0x00 : 0x01;  // flags3: invalidLlh when there is no position
  // 79..83 reserved; 84 headVeh (not valid), 88 magDec, 90 magAcc: 0 (no declination model)
  append_frame(kNavPvt, p, out);
}

// UBX-NAV-POSLLH (0x01 0x02), 28 bytes.
void append_nav_posllh(const GnssFix& f, std::vector<std::uint8_t>& out) {
  std::array<std::uint8_t, 28> p{};
  put<std::uint32_t>(p, 0, week_time(f).itow_ms);
  if (has_position(f)) {
    put<std::int32_t>(p, 4, i32(f.longitude_rad * kDegPerRad * 1e7));
    put<std::int32_t>(p, 8, i32(f.latitude_rad * kDegPerRad * 1e7));
    put<std::int32_t>(p, 12, i32(f.height_m * 1e3));
    put<std::int32_t>(p, 16, i32((f.height_m - f.geoid_separation_m) * 1e3));
    put<std::uint32_t>(p, 20, u32(f.horizontal_accuracy_m * 1e3));
    put<std::uint32_t>(p, 24, u32(f.vertical_accuracy_m * 1e3));
  } else {
    put<std::uint32_t>(p, 20, 0xFFFFFFFFu);
    put<std::uint32_t>(p, 24, 0xFFFFFFFFu);
  }
  append_frame(kNavPosllh, p, out);
}

// UBX-NAV-STATUS (0x01 0x03), 16 bytes.
void append_nav_status(const GnssFix& f, std::vector<std::uint8_t>& out) {
  std::array<std::uint8_t, 16> p{};
  put<std::uint32_t>(p, 0, week_time(f).itow_ms);
  p[4] = fix_code(f);                              // gpsFix
  p[5] = static_cast<std::uint8_t>((has_position(f) ? 0x01 : 0x00) | (f.time_valid ? 0x0C : 0x00));  // gpsFixOk | wknSet | towSet
  p[6] = 0x00;                                     // fixStat
  p[7] = 0x00;                                     // flags2
  put<std::uint32_t>(p, 8, f.time_to_first_fix_ms);  // ttff
  put<std::uint32_t>(p, 12, f.since_start_ms);       // msss
  append_frame(kNavStatus, p, out);
}

// UBX-NAV-DOP (0x01 0x04), 18 bytes: gDOP, pDOP, tDOP, vDOP, hDOP, nDOP,
// eDOP, scale 0.01. The fix carries PDOP, HDOP and VDOP; the time DOP is
// taken as equal to VDOP, gDOP = sqrt(pDOP^2 + tDOP^2), nDOP = eDOP =
// HDOP / sqrt(2) (hDOP^2 = nDOP^2 + eDOP^2).
void append_nav_dop(const GnssFix& f, std::vector<std::uint8_t>& out) {
  std::array<std::uint8_t, 18> p{};
  put<std::uint32_t>(p, 0, week_time(f).itow_ms);
  const double tdop = f.vdop;
  put<std::uint16_t>(p, 4, u16(std::hypot(f.pdop, tdop) * 100.0));
  put<std::uint16_t>(p, 6, u16(f.pdop * 100.0));
  put<std::uint16_t>(p, 8, u16(tdop * 100.0));
  put<std::uint16_t>(p, 10, u16(f.vdop * 100.0));
  put<std::uint16_t>(p, 12, u16(f.hdop * 100.0));
  put<std::uint16_t>(p, 14, u16(f.hdop / std::sqrt(2.0) * 100.0));
  put<std::uint16_t>(p, 16, u16(f.hdop / std::sqrt(2.0) * 100.0));
  append_frame(kNavDop, p, out);
}

// UBX-NAV-SOL (0x01 0x06), 52 bytes: ECEF position (cm) and velocity (cm/s).
void append_nav_sol(const GnssFix& f, std::vector<std::uint8_t>& out) {
  std::array<std::uint8_t, 52> p{};
  const GpsWeekTime w = week_time(f);
  put<std::uint32_t>(p, 0, w.itow_ms);
  put<std::int32_t>(p, 4, w.ftow_ns);
  put<std::int16_t>(p, 8, static_cast<std::int16_t>(w.week));
  p[10] = fix_code(f);
  p[11] = static_cast<std::uint8_t>((has_position(f) ? 0x01 : 0x00) | (f.time_valid ? 0x0C : 0x00));  // GPSfixOK | WKNSET | TOWSET
  if (has_position(f)) {
    const Vec3 x = earth::ecef_from_geodetic({f.latitude_rad, f.longitude_rad, f.height_m});
    const Vec3 v = attitude::ned_to_ecef(f.latitude_rad, f.longitude_rad) * f.velocity_ned_m_s;
    for (int i = 0; i < 3; ++i) put<std::int32_t>(p, 12 + 4 * static_cast<std::size_t>(i), i32(x[i] * 100.0));
    put<std::uint32_t>(p, 24, u32(std::hypot(f.horizontal_accuracy_m, f.vertical_accuracy_m) * 100.0));  // pAcc (3D)
    for (int i = 0; i < 3; ++i) put<std::int32_t>(p, 28 + 4 * static_cast<std::size_t>(i), i32(v[i] * 100.0));
    put<std::uint32_t>(p, 40, u32(f.speed_accuracy_m_s * 100.0));
    put<std::uint16_t>(p, 44, u16(f.pdop * 100.0));
  } else {
    put<std::uint32_t>(p, 24, 0xFFFFFFFFu);
    put<std::uint32_t>(p, 40, 0xFFFFFFFFu);
    put<std::uint16_t>(p, 44, 9999);
  }
  p[47] = static_cast<std::uint8_t>(std::clamp(has_position(f) ? f.satellites : 0, 0, 255));  // numSV
  append_frame(kNavSol, p, out);
}

// UBX-NAV-VELNED (0x01 0x12), 36 bytes: cm/s, heading 1e-5 degree.
void append_nav_velned(const GnssFix& f, std::vector<std::uint8_t>& out) {
  std::array<std::uint8_t, 36> p{};
  put<std::uint32_t>(p, 0, week_time(f).itow_ms);
  if (has_position(f)) {
    put<std::int32_t>(p, 4, i32(f.velocity_ned_m_s.x() * 100.0));
    put<std::int32_t>(p, 8, i32(f.velocity_ned_m_s.y() * 100.0));
    put<std::int32_t>(p, 12, i32(f.velocity_ned_m_s.z() * 100.0));
    put<std::uint32_t>(p, 16, u32(f.velocity_ned_m_s.norm() * 100.0));
    put<std::uint32_t>(p, 20, u32(ground_speed(f) * 100.0));
    put<std::int32_t>(p, 24, heading_1e5(f));
    put<std::uint32_t>(p, 28, u32(f.speed_accuracy_m_s * 100.0));
    put<std::uint32_t>(p, 32, u32(heading_accuracy_deg(f) * 1e5));
  } else {
    put<std::uint32_t>(p, 28, 0xFFFFFFFFu);
    put<std::uint32_t>(p, 32, 18'000'000u);
  }
  append_frame(kNavVelned, p, out);
}

// UBX-NAV-TIMEGPS (0x01 0x20), 16 bytes.
void append_nav_timegps(const GnssFix& f, std::vector<std::uint8_t>& out) {
  std::array<std::uint8_t, 16> p{};
  const GpsWeekTime w = week_time(f);
  put<std::uint32_t>(p, 0, w.itow_ms);
  put<std::int32_t>(p, 4, w.ftow_ns);
  put<std::int16_t>(p, 8, static_cast<std::int16_t>(w.week));
  p[10] = static_cast<std::uint8_t>(static_cast<std::int8_t>(f.gps_minus_utc_s));  // leapS
  p[11] = f.time_valid ? 0x07 : 0x00;  // valid: towValid | weekValid | leapSValid
  put<std::uint32_t>(p, 12, u32(f.time_accuracy_ns));
  append_frame(kNavTimegps, p, out);
}

// UBX-NAV-EOE (0x01 0x61), 4 bytes: the epoch's iTOW.
void append_nav_eoe(const GnssFix& f, std::vector<std::uint8_t>& out) {
  std::array<std::uint8_t, 4> p{};
  put<std::uint32_t>(p, 0, week_time(f).itow_ms);
  append_frame(kNavEoe, p, out);
}

Encoder::Encoder(const StreamEncoderOptions& options)
    : fix_source_(options.gnss, options.nominal_sample_rate_hz, options.device_name), legacy_nav_(options.ubx_legacy_nav) {}

void Encoder::encode(const ImuFrameInput& sample, std::vector<std::uint8_t>& out) {
  const GnssFix fix_value = fix_source_.fix(sample);
  const GnssFix* fix = &fix_value;
  // One navigation epoch: the messages that carry the epoch's time first
  // (NAV-PVT, NAV-TIMEGPS, NAV-SOL), so that a reader which reports on each
  // message never pairs a new position with the previous epoch's time
  // (gpsd 3.22 reports after NAV-DOP, which it takes for the cycle's last
  // message), then the position, velocity, status and DOP messages, and
  // NAV-EOE, the end-of-epoch marker (u-blox 8 protocol 18+: "output after
  // all enabled NAV class messages").
  append_nav_pvt(*fix, out);
  if (legacy_nav_) {
    append_nav_timegps(*fix, out);
    append_nav_sol(*fix, out);
    append_nav_posllh(*fix, out);
    append_nav_velned(*fix, out);
    append_nav_status(*fix, out);
    append_nav_dop(*fix, out);
  }
  append_nav_eoe(*fix, out);
}

std::size_t Encoder::max_bytes_per_sample() const {
  constexpr std::size_t kFrame = kHeaderBytes + kChecksumBytes;
  std::size_t n = kFrame + kNavPvtPayloadBytes + kFrame + 4;  // NAV-PVT, NAV-EOE
  if (legacy_nav_) n += 6 * kFrame + 28 + 16 + 18 + 52 + 36 + 16;
  return n;
}

StreamFrameLayout Encoder::frame_layout(std::span<const std::uint8_t> frame) const {
  if (frame.size() < kHeaderBytes) return StreamFrameLayout{frame.size()};
  const std::size_t payload = wire::get_le<std::uint16_t>(frame.data() + 4);
  StreamFrameLayout layout;
  layout.frame_bytes = std::min(frame.size(), kHeaderBytes + payload + kChecksumBytes);
  layout.length_offset = 4;
  layout.length_bytes = 2;
  layout.checksum_offset = kHeaderBytes + payload;
  layout.checksum_bytes = layout.checksum_offset + kChecksumBytes <= frame.size() ? kChecksumBytes : 0;
  return layout;
}

void Decoder::feed(std::span<const std::uint8_t> bytes, const SampleCallback& on_sample) {
  (void)on_sample;  // a GNSS receiver sends no IMU samples
  buffer_.insert(buffer_.end(), bytes.begin(), bytes.end());
  static constexpr std::array<std::uint8_t, 2> kSync{kSync1, kSync2};
  wire::scan_frames(buffer_, kSync, counters_, [&](std::span<const std::uint8_t> c) {
    using wire::Candidate;
    if (c.size() < kHeaderBytes) return wire::CandidateResult{Candidate::kNeedMore};
    const std::size_t payload = wire::get_le<std::uint16_t>(c.data() + 4);
    if (payload > 1024) return wire::CandidateResult{Candidate::kMalformed};
    const std::size_t total = kHeaderBytes + payload + kChecksumBytes;
    if (c.size() < total) return wire::CandidateResult{Candidate::kNeedMore};
    const auto ck = checksum(c.subspan(2, 4 + payload));
    if (ck[0] != c[kHeaderBytes + payload] || ck[1] != c[kHeaderBytes + payload + 1])
      return wire::CandidateResult{Candidate::kBadChecksum};
    ++counters_.frames;
    return wire::CandidateResult{Candidate::kAccepted, total};
  });
}

}  // namespace imuemu::drivers::ubx
