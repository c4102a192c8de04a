// MIP GNSS (0x81) and filter (0x82) data sets. Sources in mip_nav.hpp.
#include "drivers/protocols/mip_nav.hpp"

#include <Eigen/Geometry>

#include <algorithm>
#include <array>
#include <cmath>

#include "core/aiding/gnss.hpp"
#include "core/earth.hpp"
#include "core/sensor/sensor_model.hpp"
#include "drivers/protocols/mip.hpp"
#include "drivers/protocols/wire_bytes.hpp"

namespace imuemu::drivers::mip {

namespace {

// The filter's error streams: beside the barometer (16), magnetometer (17)
// and GNSS (18) of core/aiding.
constexpr unsigned kSensorMipFilter = 19;
constexpr double kNavRadToDeg = 180.0 / 3.14159265358979323846;

// Field sizes incl. the length and descriptor bytes [G], [E], [S].
constexpr std::size_t kNavGnssLlhBytes = 2 + 4 * 8 + 2 * 4 + 2;
constexpr std::size_t kNavGnssVelocityBytes = 2 + 8 * 4 + 2;
constexpr std::size_t kNavTimeBytes = 2 + 8 + 2 + 2;
constexpr std::size_t kNavFixInfoBytes = 2 + 1 + 1 + 2 + 2;
constexpr std::size_t kNavFilterLlhBytes = 2 + 3 * 8 + 2;
constexpr std::size_t kNavVector3Bytes = 2 + 3 * 4 + 2;
constexpr std::size_t kNavQuaternionBytes = 2 + 4 * 4 + 2;
constexpr std::size_t kNavStatusBytes = 2 + 3 * 2;

std::size_t nav_field_bytes(std::uint8_t set, std::uint8_t d) {
  if (set == kGnssDataSet) {
    switch (d) {
      case kGnssLlh: return kNavGnssLlhBytes;
      case kGnssNedVelocity: return kNavGnssVelocityBytes;
      case kGnssGpsTime:
      case kSharedGpsTimestamp: return kNavTimeBytes;
      case kGnssFixInfo: return kNavFixInfoBytes;
      default: return 0;
    }
  }
  switch (d) {
    case kFilterLlh: return kNavFilterLlhBytes;
    case kFilterNedVelocity:
    case kFilterLlhUncertainty:
    case kFilterVelocityUncertainty:
    case kFilterEulerUncertainty: return kNavVector3Bytes;
    case kFilterQuaternion: return kNavQuaternionBytes;
    case kFilterStatus: return kNavStatusBytes;
    case kSharedGpsTimestamp: return kNavTimeBytes;
    default: return 0;
  }
}

// A field is built in a fixed buffer and appended (no allocation beyond
// `out`'s capacity).
struct NavField {
  std::array<std::uint8_t, 64> b{};
  std::size_t n = 2;
  explicit NavField(std::uint8_t descriptor) { b[1] = descriptor; }
  template <class T>
  void put(T v) {
    wire::put_be<T>(b.data() + n, v);
    n += sizeof(T);
  }
  // A float field value: finite (NaN -> 0, beyond range -> clamped).
  void put_f(double v) { put<float>(static_cast<float>(wire::to_wire_float<float>(v).value)); }
  void put_d(double v) { put<double>(std::isfinite(v) ? v : 0.0); }
  void append_to(std::vector<std::uint8_t>& out) {
    b[0] = static_cast<std::uint8_t>(n);
    out.insert(out.end(), b.begin(), b.begin() + static_cast<std::ptrdiff_t>(n));
  }
};

void nav_put_time(std::vector<std::uint8_t>& out, std::uint8_t descriptor, const GpsTimestamp& ts, bool valid) {
  NavField f(descriptor);
  f.put_d(ts.tow_s);
  f.put<std::uint16_t>(ts.week);
  f.put<std::uint16_t>(valid ? 0x0003 : 0x0000);  // tow 0x1, week 0x2 [G 0x09], [S]
  f.append_to(out);
}

void nav_begin(std::vector<std::uint8_t>& out, std::uint8_t set, std::size_t& start) {
  start = out.size();
  out.insert(out.end(), {kSync1, kSync2, set, 0});
}
void nav_end(std::vector<std::uint8_t>& out, std::size_t start) {
  out[start + 3] = static_cast<std::uint8_t>(out.size() - start - kHeaderBytes);
  const std::uint16_t c = fletcher_checksum(std::span<const std::uint8_t>(out.data() + start, out.size() - start));
  out.push_back(static_cast<std::uint8_t>(c >> 8));
  out.push_back(static_cast<std::uint8_t>(c));
}

bool nav_due(std::span<const FieldRate> fields, std::uint64_t counter) {
  return std::any_of(fields.begin(), fields.end(), [&](const FieldRate& f) { return counter % f.decimation == 0; });
}

GnssReceiverConfig nav_gnss_config(const StreamEncoderOptions& o) {
  GnssReceiverConfig g = o.gnss;
  g.errors.seed = o.aiding_seed;  // one device, one seed (as MAVLink HIL_GPS)
  return g;
}

}  // namespace

std::vector<std::uint8_t> gnss_fields(const MipNavConfig& c) {
  if (c.gnss_rate_hz <= 0) return {};
  return {kGnssLlh, kGnssNedVelocity, kGnssFixInfo, kSharedGpsTimestamp, kGnssGpsTime};
}
std::vector<std::uint8_t> gnss_power_up_fields(const MipNavConfig& c) {
  if (c.gnss_rate_hz <= 0) return {};
  return {kGnssLlh, kGnssNedVelocity, kGnssFixInfo, kSharedGpsTimestamp};
}
std::vector<std::uint8_t> filter_fields(const MipNavConfig& c) {
  if (c.filter_rate_hz <= 0) return {};
  return {kFilterStatus,         kFilterLlh,  kFilterNedVelocity, kFilterQuaternion, kSharedGpsTimestamp,
          kFilterLlhUncertainty, kFilterVelocityUncertainty, kFilterEulerUncertainty};
}
std::vector<std::uint8_t> filter_power_up_fields(const MipNavConfig& c) {
  if (c.filter_rate_hz <= 0) return {};
  return {kFilterStatus, kFilterLlh, kFilterNedVelocity, kFilterQuaternion, kSharedGpsTimestamp};
}
std::uint16_t decimation_of(std::int64_t rate_hz, std::uint16_t base_rate_hz) {
  if (rate_hz <= 0) return 1;
  return static_cast<std::uint16_t>(std::clamp<std::int64_t>(std::llround(double(base_rate_hz) / double(rate_hz)), 1, 65535));
}
std::size_t max_gnss_packet_bytes(const MipNavConfig& c) {
  std::size_t n = 0;
  for (const std::uint8_t d : gnss_fields(c)) n += nav_field_bytes(kGnssDataSet, d);
  return n == 0 ? 0 : kHeaderBytes + n + kChecksumBytes;
}
std::size_t max_filter_packet_bytes(const MipNavConfig& c) {
  std::size_t n = 0;
  for (const std::uint8_t d : filter_fields(c)) n += nav_field_bytes(kFilterDataSet, d);
  return n == 0 ? 0 : kHeaderBytes + n + kChecksumBytes;
}

NavEncoder::NavEncoder(const StreamEncoderOptions& options, std::uint16_t base_rate_hz)
    : options_(options),
      config_(options.mip_nav),
      base_rate_hz_(base_rate_hz),
      gnss_decimation_(decimation_of(options.mip_nav.gnss_rate_hz, base_rate_hz)),
      fix_source_(nav_gnss_config(options),
                  options.mip_nav.gnss_rate_hz > 0 ? double(base_rate_hz) / gnss_decimation_ : 1.0,
                  options.device_name),
      device_hash_(sensor::device_hash(options.device_name)) {}

bool NavEncoder::fix_at_epoch(std::uint64_t epoch, const ImuFrameInput& sample) const {
  if (config_.gnss_rate_hz <= 0 || !sample.has_navigation) return false;
  const double s = static_cast<double>(epoch * gnss_decimation_) / base_rate_hz_;
  if (s < config_.gnss_first_fix_s) return false;
  const double end = config_.gnss_outage_start_s + config_.gnss_outage_duration_s;
  return !(config_.gnss_outage_duration_s > 0.0 && s >= config_.gnss_outage_start_s && s < end);
}

void NavEncoder::encode(const ImuFrameInput& sample, std::span<const FieldRate> gnss, std::span<const FieldRate> filter,
                        std::vector<std::uint8_t>& out) {
  if (!gnss.empty() && nav_due(gnss, sample.sample_counter)) gnss_packet(sample, gnss, out);
  if (!filter.empty() && nav_due(filter, sample.sample_counter)) filter_packet(sample, filter, out);
}

void NavEncoder::gnss_packet(const ImuFrameInput& sample, std::span<const FieldRate> fields,
                             std::vector<std::uint8_t>& out) {
  // The receiver's epochs are at its own rate: the packet carries the latest.
  const std::uint64_t epoch = sample.sample_counter / gnss_decimation_;
  const bool fixed = fix_at_epoch(epoch, sample);
  GnssFix fix;
  if (fixed) fix = fix_source_.fix(sample, epoch);
  const bool fix3d = fixed && fix.fix_type == GnssFixType::fix_3d;
  // The receiver knows GPS time from its first fix on (and keeps it through
  // an outage), when trajectory time is on a GPS or UTC base.
  const GpsTimestamp ts = gps_timestamp_of(sample.t_ns, options_);
  const bool time_valid = ts.valid_flags == kGpsTimeValid &&
                          static_cast<double>(sample.sample_counter) / base_rate_hz_ >= config_.gnss_first_fix_s;
  std::size_t start = 0;
  nav_begin(out, kGnssDataSet, start);
  for (const FieldRate& r : fields) {
    if (sample.sample_counter % r.decimation != 0) continue;
    switch (r.descriptor) {
      case kGnssLlh: {
        NavField f(kGnssLlh);
        f.put_d(fix3d ? fix.latitude_rad * kNavRadToDeg : 0.0);
        f.put_d(fix3d ? fix.longitude_rad * kNavRadToDeg : 0.0);
        f.put_d(fix3d ? fix.height_m : 0.0);
        f.put_d(fix3d ? fix.height_m - fix.geoid_separation_m : 0.0);
        f.put_f(options_.gnss.horizontal_accuracy_m);
        f.put_f(options_.gnss.vertical_accuracy_m);
        f.put<std::uint16_t>(fix3d ? 0x001F : 0x0000);
        f.append_to(out);
        break;
      }
      case kGnssNedVelocity: {
        const Vec3 v = fix3d ? fix.velocity_ned_m_s : Vec3::Zero();
        const double ground = std::hypot(v.x(), v.y());
        double heading_deg = std::atan2(v.y(), v.x()) * kNavRadToDeg;
        if (heading_deg < 0.0) heading_deg += 360.0;
        // Heading accuracy: the speed accuracy across the ground speed (deg), at most 180.
        const double heading_acc_deg =
            ground > 0.0 ? std::min(180.0, options_.gnss.speed_accuracy_m_s / ground * kNavRadToDeg) : 180.0;
        NavField f(kGnssNedVelocity);
        f.put_f(v.x());
        f.put_f(v.y());
        f.put_f(v.z());
        f.put_f(v.norm());
        f.put_f(ground);
        f.put_f(heading_deg);
        f.put_f(options_.gnss.speed_accuracy_m_s);
        f.put_f(heading_acc_deg);
        f.put<std::uint16_t>(fix3d ? 0x003F : 0x0000);
        f.append_to(out);
        break;
      }
      case kGnssFixInfo: {
        NavField f(kGnssFixInfo);
        f.put<std::uint8_t>(fix3d ? kFixType3d : kFixTypeNone);
        f.put<std::uint8_t>(static_cast<std::uint8_t>(fix3d ? std::clamp(options_.gnss.satellites, 0, 255) : 0));
        f.put<std::uint16_t>(0);       // no SBAS, not differential
        f.put<std::uint16_t>(0x0007);  // fix type, satellites, fix flags all valid
        f.append_to(out);
        break;
      }
      case kGnssGpsTime:
      case kSharedGpsTimestamp: nav_put_time(out, r.descriptor, ts, time_valid); break;
      default: break;  // only the fields above are accepted (mip_device.cpp)
    }
  }
  nav_end(out, start);
}

void NavEncoder::filter_packet(const ImuFrameInput& sample, std::span<const FieldRate> fields,
                               std::vector<std::uint8_t>& out) {
  const std::uint64_t k = sample.sample_counter;
  const double s = static_cast<double>(k) / base_rate_hz_;
  const bool aligned = s >= config_.filter_alignment_s && sample.has_navigation;
  // The filter takes the receiver's latest epoch.
  const bool gnss_fix = fix_at_epoch(k / gnss_decimation_, sample);
  const bool navigating = aligned && gnss_fix;
  if (navigating) ever_navigated_ = true;

  std::uint16_t state = 0, flags = 0;
  if (config_.filter_states == MipFilterStates::cv7) {
    state = !aligned ? kCv7Init : navigating ? kCv7FullNav : kCv7Ahrs;
  } else if (!aligned || !ever_navigated_) {
    state = kGx5Init;
    if (!aligned) flags |= kGx5InitNoAttitude;
    if (!ever_navigated_) flags |= kGx5InitNoPositionVelocity;
  } else {
    state = kGx5RunValid;
    if (!gnss_fix) flags |= kGx5RunGnssUnavailable;
  }

  // The solution: the trajectory plus white errors of the configured sigmas,
  // drawn from streams keyed by the sample counter (the same sample, the
  // same error, whatever was sent before).
  const double deg = 1.0 / kNavRadToDeg;
  auto draw = [&](unsigned axis) {
    sensor::Stream st{sensor::stream_key(options_.aiding_seed, device_hash_, kSensorMipFilter, axis,
                                         sensor::kTermWhite, static_cast<unsigned>(k))};
    return st.gaussian();
  };
  Mat3 r_sn = sample.sensor_to_ned;
  if (aligned) {
    const Vec3 d(config_.filter_roll_pitch_sigma_deg * deg * draw(0), config_.filter_roll_pitch_sigma_deg * deg * draw(1),
                 config_.filter_heading_sigma_deg * deg * draw(2));
    if (d.norm() > 0.0) r_sn = Eigen::AngleAxisd(d.norm(), d.normalized()).toRotationMatrix() * r_sn;
  }
  if (navigating) {
    const Vec3 dp(config_.filter_horizontal_sigma_m * draw(3), config_.filter_horizontal_sigma_m * draw(4),
                  config_.filter_vertical_sigma_m * draw(5));
    const Vec3 dv = config_.filter_velocity_sigma_m_s * Vec3(draw(6), draw(7), draw(8));
    earth::Geodetic g{sample.latitude_rad, sample.longitude_rad, sample.height_m};
    if (dp.norm() > 0.0) {
      const Vec3 x_e = earth::ecef_from_geodetic(g);
      if (x_e.allFinite()) g = aiding::offset_geodetic(x_e, dp);
    }
    held_.latitude_deg = g.latitude_rad * kNavRadToDeg;
    held_.longitude_deg = g.longitude_rad * kNavRadToDeg;
    held_.height_m = g.height_m;
    held_.velocity_ned_m_s = sample.velocity_ned_m_s + dv;
  }
  const GpsTimestamp ts = gps_timestamp_of(sample.t_ns, options_);
  const std::uint16_t nav_valid = navigating ? 1 : 0;

  std::size_t start = 0;
  nav_begin(out, kFilterDataSet, start);
  for (const FieldRate& r : fields) {
    if (k % r.decimation != 0) continue;
    NavField f(r.descriptor);
    switch (r.descriptor) {
      case kFilterStatus:
        f.put<std::uint16_t>(state);
        f.put<std::uint16_t>(1);  // dynamics mode: GX5 portable / CV7 default
        f.put<std::uint16_t>(flags);
        break;
      case kFilterLlh:
        f.put_d(held_.latitude_deg);
        f.put_d(held_.longitude_deg);
        f.put_d(held_.height_m);
        f.put<std::uint16_t>(nav_valid);
        break;
      case kFilterNedVelocity:
        for (int i = 0; i < 3; ++i) f.put_f(held_.velocity_ned_m_s[i]);
        f.put<std::uint16_t>(nav_valid);
        break;
      case kFilterQuaternion: {
        Eigen::Quaterniond q(r_sn);
        q.normalize();
        if (q.w() < 0.0) q.coeffs() = -q.coeffs();  // one sign: w >= 0
        const bool ok = aligned && q.coeffs().allFinite();
        f.put_f(ok ? q.w() : 1.0);
        f.put_f(ok ? q.x() : 0.0);
        f.put_f(ok ? q.y() : 0.0);
        f.put_f(ok ? q.z() : 0.0);
        f.put<std::uint16_t>(ok ? 1 : 0);
        break;
      }
      case kFilterLlhUncertainty:
        f.put_f(config_.filter_horizontal_sigma_m);
        f.put_f(config_.filter_horizontal_sigma_m);
        f.put_f(config_.filter_vertical_sigma_m);
        f.put<std::uint16_t>(nav_valid);
        break;
      case kFilterVelocityUncertainty:
        for (int i = 0; i < 3; ++i) f.put_f(config_.filter_velocity_sigma_m_s);
        f.put<std::uint16_t>(nav_valid);
        break;
      case kFilterEulerUncertainty:
        f.put_f(config_.filter_roll_pitch_sigma_deg * deg);
        f.put_f(config_.filter_roll_pitch_sigma_deg * deg);
        f.put_f(config_.filter_heading_sigma_deg * deg);
        f.put<std::uint16_t>(aligned ? 1 : 0);
        break;
      case kSharedGpsTimestamp: nav_put_time(out, kSharedGpsTimestamp, ts, ts.valid_flags == kGpsTimeValid); continue;
      default: continue;  // only the fields above are accepted (mip_device.cpp)
    }
    f.append_to(out);
  }
  nav_end(out, start);
}

}  // namespace imuemu::drivers::mip
