// NMEA 0183 GNSS receiver output; see nmea.hpp. Field layouts from the NMEA
// 0183 v4.10 sentence definitions (as the u-blox 8/M8 receiver description
// reproduces them in its "NMEA Protocol" chapter).
#include "drivers/protocols/nmea.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "drivers/protocols/gps_time.hpp"

namespace imuemu::drivers::nmea {

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDegPerRad = 180.0 / kPi;
// 1 knot = 1852 m per hour (international nautical mile).
constexpr double kKnotsPerMps = 3600.0 / 1852.0;
constexpr double kKmhPerMps = 3.6;
constexpr std::int64_t kNs = 1'000'000'000;

// One sentence under construction: the text between '$' and '*' in a stack
// buffer (no allocation on the emission thread).
class Sentence {
 public:
  explicit Sentence(std::string_view talker, const char* formatter) {
    add("%.2s%s", talker.data(), formatter);
  }
  // Fixed text, copied as is (never read as a format: clang's
  // -Wformat-security refuses a non-literal format without arguments).
  void add(const char* text) { add("%s", text); }
  template <class... Args>
  void add(const char* format, Args... args) {
    if (n_ >= sizeof(text_)) return;
    const int w = std::snprintf(text_ + n_, sizeof(text_) - n_, format, args...);
    if (w > 0) n_ = std::min(sizeof(text_) - 1, n_ + static_cast<std::size_t>(w));
  }
  void append_to(std::vector<std::uint8_t>& out) const {
    const std::uint8_t sum = checksum(std::string_view(text_, n_));
    static constexpr char kHex[] = "0123456789ABCDEF";
    out.push_back('$');
    out.insert(out.end(), text_, text_ + n_);
    out.push_back('*');
    out.push_back(static_cast<std::uint8_t>(kHex[sum >> 4]));
    out.push_back(static_cast<std::uint8_t>(kHex[sum & 0x0F]));
    out.push_back('\r');
    out.push_back('\n');
  }

 private:
  char text_[128] = {};
  std::size_t n_ = 0;
};

bool has_position(const GnssFix& f) { return f.fix_type != GnssFixType::none; }

// Every number printed is bounded (and NaN printed as 0), so that a field
// never outgrows the sentence's buffer and printf never needs more than
// its stack (no allocation on the emission thread).
double bounded(double v, double lo, double hi) {
  if (std::isnan(v)) return 0.0;
  return std::clamp(v, lo, hi);  // +-inf to the bound of its sign
}


// The epoch's UTC time rounded to the 10 ms the time fields carry (before
// the split into date and time, so that a rounding up carries into the date).
gps_time::UtcCalendar utc_of(const GnssFix& f) {
  const std::int64_t utc_ns = f.gps_time_ns + gps_time::kGpsEpochPosixSeconds * kNs -
                              static_cast<std::int64_t>(f.gps_minus_utc_s) * kNs;
  constexpr std::int64_t kStep = 10'000'000;
  const std::int64_t rounded = (utc_ns >= 0 ? (utc_ns + kStep / 2) / kStep : -((-utc_ns + kStep / 2) / kStep)) * kStep;
  return gps_time::calendar_from_posix_ns(rounded);
}

void add_time(Sentence& s, const GnssFix& f, const gps_time::UtcCalendar& c) {
  if (!f.time_valid) return;  // an empty field: the receiver does not know the time
  s.add("%02d%02d%02d.%02d", c.hour, c.minute, c.second, static_cast<int>(c.nanosecond / 10'000'000));
}

// ddmm.mmmmmm,N (or dddmm.mmmmmm,E): whole degrees, then minutes rounded to
// 1e-6 in integers (a value of 59.9999996' carries into the degrees
// instead of printing 60.000000).
void add_angle(Sentence& s, double rad, int degree_digits, char positive, char negative) {
  const double deg = rad * kDegPerRad;
  const long long micro_minutes = std::llround(bounded(std::fabs(deg), 0.0, 999.0) * 60.0 * 1e6);
  const long long whole_deg = micro_minutes / 60'000'000;
  const long long rest = micro_minutes % 60'000'000;
  s.add(",%0*lld%02lld.%06lld,%c", degree_digits, whole_deg, rest / 1'000'000, rest % 1'000'000,
        deg < 0.0 ? negative : positive);
}

double ground_speed_m_s(const GnssFix& f) {
  return bounded(std::hypot(f.velocity_ned_m_s.x(), f.velocity_ned_m_s.y()), 0.0, 9999.0);
}

// Course over ground, true, in hundredths of a degree in [0, 36000).
long long course_centideg(const GnssFix& f) {
  double deg = std::atan2(f.velocity_ned_m_s.y(), f.velocity_ned_m_s.x()) * kDegPerRad;
  if (!std::isfinite(deg)) return 0;
  if (deg < 0.0) deg += 360.0;
  return std::llround(deg * 100.0) % 36000;
}

void add_course(Sentence& s, const GnssFix& f) {
  const long long c = course_centideg(f);
  s.add(",%lld.%02lld", c / 100, c % 100);
}

}  // namespace

std::uint8_t checksum(std::string_view between_dollar_and_star) {
  std::uint8_t sum = 0;
  for (const char c : between_dollar_and_star) sum ^= static_cast<std::uint8_t>(c);
  return sum;
}

// GGA: time, lat, N/S, lon, E/W, quality (0 invalid, 1 GPS fix), satellites
// used, HDOP, altitude above MSL, M, geoid separation, M, age of DGPS data,
// reference station id (both empty: no differential corrections).
void append_gga(const GnssFix& f, std::string_view talker, std::vector<std::uint8_t>& out) {
  Sentence s(talker, "GGA");
  s.add(",");
  add_time(s, f, utc_of(f));
  if (has_position(f)) {
    add_angle(s, f.latitude_rad, 2, 'N', 'S');
    add_angle(s, f.longitude_rad, 3, 'E', 'W');
    // The separation to 0.1 m (what keeps the worst case within 82
    // characters), and the MSL altitude from that rounded value, so that a
    // reader's MSL + separation is the ellipsoidal height to the 0.01 m of
    // the altitude field.
    const double separation_m = std::round(bounded(f.geoid_separation_m, -999.9, 999.9) * 10.0) / 10.0;
    s.add(",1,%02d,%.1f,%.2f,M,%.1f,M,,", std::clamp(f.satellites, 0, 99), bounded(f.hdop, 0.0, 99.9),
          bounded(f.height_m - separation_m, -9999.99, 99999.99), separation_m);
  } else {
    s.add(",,,,,0,00,99.9,,,,,,");
  }
  s.append_to(out);
}

// RMC (v4.10): time, status (A valid, V warning), lat, N/S, lon, E/W, speed
// over ground (knots), course over ground (degrees true), date ddmmyy,
// magnetic variation and its E/W (empty: none computed), mode indicator
// (A autonomous, N not valid), navigational status (V: the receiver does not
// claim a safety status, as u-blox sends it).
void append_rmc(const GnssFix& f, std::string_view talker, std::vector<std::uint8_t>& out) {
  Sentence s(talker, "RMC");
  const gps_time::UtcCalendar c = utc_of(f);
  s.add(",");
  add_time(s, f, c);
  if (has_position(f)) {
    s.add(",A");
    add_angle(s, f.latitude_rad, 2, 'N', 'S');
    add_angle(s, f.longitude_rad, 3, 'E', 'W');
    s.add(",%.3f", ground_speed_m_s(f) * kKnotsPerMps);
    add_course(s, f);
  } else {
    s.add(",V,,,,,,");
  }
  if (f.time_valid) s.add(",%02d%02d%02d", c.day, c.month, c.year % 100);
  else s.add(",");
  s.add(",,,%c,V", has_position(f) ? 'A' : 'N');
  s.append_to(out);
}

// VTG: course true, T, course magnetic (empty), M, speed knots, N, speed
// km/h, K, mode indicator.
void append_vtg(const GnssFix& f, std::string_view talker, std::vector<std::uint8_t>& out) {
  Sentence s(talker, "VTG");
  if (has_position(f)) {
    add_course(s, f);
    const double v = ground_speed_m_s(f);
    s.add(",T,,M,%.3f,N,%.3f,K,A", v * kKnotsPerMps, v * kKmhPerMps);
  } else {
    s.add(",,T,,M,,N,,K,N");
  }
  s.append_to(out);
}

// GSA (v4.10): selection mode (A automatic), fix mode (1 none, 2 2D, 3 3D),
// twelve fields of satellite ids used, PDOP, HDOP, VDOP, GNSS system id
// (1 = GPS). The emulated receiver has no constellation: ids 1..n stand
// for the n satellites it reports used.
void append_gsa(const GnssFix& f, std::string_view talker, std::vector<std::uint8_t>& out) {
  Sentence s(talker, "GSA");
  const int mode = f.fix_type == GnssFixType::fix_3d ? 3 : f.fix_type == GnssFixType::fix_2d ? 2 : 1;
  s.add(",A,%d", mode);
  const int used = has_position(f) ? std::clamp(f.satellites, 0, 12) : 0;
  for (int i = 1; i <= 12; ++i) {
    if (i <= used) s.add(",%02d", i);
    else s.add(",");
  }
  if (has_position(f))
    s.add(",%.2f,%.2f,%.2f,1", bounded(f.pdop, 0.0, 99.99), bounded(f.hdop, 0.0, 99.99), bounded(f.vdop, 0.0, 99.99));
  else s.add(",99.99,99.99,99.99,1");
  s.append_to(out);
}

// ZDA: time, day, month, year (4 digits), local zone hours and minutes (00).
void append_zda(const GnssFix& f, std::string_view talker, std::vector<std::uint8_t>& out) {
  Sentence s(talker, "ZDA");
  const gps_time::UtcCalendar c = utc_of(f);
  s.add(",");
  add_time(s, f, c);
  if (f.time_valid) s.add(",%02d,%02d,%04d,00,00", c.day, c.month, c.year);
  else s.add(",,,,,");
  s.append_to(out);
}

Encoder::Encoder(const StreamEncoderOptions& options)
    : fix_source_(options.gnss, options.nominal_sample_rate_hz, options.device_name) {
  if (options.nmea_talker != "GP" && options.nmea_talker != "GN")
    throw std::invalid_argument("stream protocol 'nmea': talker '" + options.nmea_talker + "' is not GP or GN");
  talker_[0] = options.nmea_talker[0];
  talker_[1] = options.nmea_talker[1];
}

void Encoder::encode(const ImuFrameInput& sample, std::vector<std::uint8_t>& out) {
  const GnssFix fix = fix_source_.fix(sample);
  const std::string_view talker(talker_, 2);
  append_rmc(fix, talker, out);
  append_vtg(fix, talker, out);
  append_gga(fix, talker, out);
  append_gsa(fix, talker, out);
  append_zda(fix, talker, out);
}

StreamFrameLayout Encoder::frame_layout(std::span<const std::uint8_t> frame) const {
  StreamFrameLayout layout{frame.size()};
  // One sentence: up to and including its <LF>; the checksum's two hex
  // digits after the '*'.
  const auto lf = std::find(frame.begin(), frame.end(), std::uint8_t{'\n'});
  if (lf != frame.end()) layout.frame_bytes = static_cast<std::size_t>(lf - frame.begin()) + 1;
  const auto star = std::find(frame.begin(), frame.begin() + static_cast<std::ptrdiff_t>(layout.frame_bytes),
                              std::uint8_t{'*'});
  const std::size_t at = static_cast<std::size_t>(star - frame.begin()) + 1;
  if (at + 2 <= layout.frame_bytes) {
    layout.checksum_offset = at;
    layout.checksum_bytes = 2;
  }
  return layout;
}

void Decoder::feed(std::span<const std::uint8_t> bytes, const SampleCallback& on_sample) {
  (void)on_sample;  // a GNSS receiver sends no IMU samples
  buffer_.insert(buffer_.end(), bytes.begin(), bytes.end());
  std::size_t pos = 0;
  const auto hex = [](std::uint8_t c) -> int {
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
  };
  while (pos < buffer_.size()) {
    const auto dollar = std::find(buffer_.begin() + static_cast<std::ptrdiff_t>(pos), buffer_.end(), std::uint8_t{'$'});
    counters_.resync_bytes += static_cast<std::uint64_t>(dollar - (buffer_.begin() + static_cast<std::ptrdiff_t>(pos)));
    pos = static_cast<std::size_t>(dollar - buffer_.begin());
    if (pos >= buffer_.size()) break;
    const auto lf = std::find(dollar, buffer_.end(), std::uint8_t{'\n'});
    if (lf == buffer_.end()) {
      if (buffer_.size() - pos > kMaxSentenceChars) {  // no end within a sentence's length: not one
        ++counters_.other_errors;
        ++counters_.resync_bytes;
        ++pos;
        continue;
      }
      break;
    }
    const std::size_t len = static_cast<std::size_t>(lf - dollar) + 1;
    // $ body * h h CR LF
    bool ok = len >= 7 && len <= kMaxSentenceChars && buffer_[pos + len - 2] == '\r' && buffer_[pos + len - 5] == '*';
    if (ok) {
      const int hi = hex(buffer_[pos + len - 4]), lo = hex(buffer_[pos + len - 3]);
      const std::string_view body(reinterpret_cast<const char*>(buffer_.data() + pos + 1), len - 6);
      if (hi < 0 || lo < 0 || checksum(body) != (hi << 4 | lo)) {
        ++counters_.checksum_errors;
        ok = false;
      }
    } else {
      ++counters_.other_errors;
    }
    if (ok) {
      ++counters_.frames;
      pos += len;
    } else {
      ++counters_.resync_bytes;
      ++pos;
    }
  }
  buffer_.erase(buffer_.begin(), buffer_.begin() + static_cast<std::ptrdiff_t>(pos));
}

}  // namespace imuemu::drivers::nmea
