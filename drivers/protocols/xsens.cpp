// Xsens Xbus messages, MTData2 data formats and their decoder. Sources and
// conventions in xsens.hpp.
#include "drivers/protocols/xsens.hpp"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>

#include "core/aiding/atmosphere.hpp"
#include "core/aiding/calendar.hpp"
#include "core/attitude.hpp"
#include "core/earth.hpp"
#include "drivers/gnss_fix.hpp"
#include "drivers/protocols/wire_bytes.hpp"
#include "drivers/protocols/xsens_device.hpp"

namespace imuemu::drivers::xsens {
namespace {

constexpr double kRadToDeg = 180.0 / 3.14159265358979323846;
constexpr std::int64_t kNsPerWeek = 604'800LL * 1'000'000'000LL;
constexpr std::int64_t kGpsEpochPosixNs = 315'964'800LL * 1'000'000'000LL;
constexpr std::size_t kGnssPvtBytes = 94;  // [L] GnssPvtData
constexpr std::uint64_t kSampleTimeFineHz = 10'000;  // [L] SampleTimeFine ticks

// R_{ENU<-NED} (its own inverse) and R_{NWU<-ENU}.
const Mat3& enu_from_ned() {
  static const Mat3 m = (Mat3() << 0, 1, 0, 1, 0, 0, 0, 0, -1).finished();
  return m;
}
// R_{S<-B}: Xsens sensor axes (x forward, y left, z up) from body FRD (its own inverse).
const Mat3& s_from_b() {
  static const Mat3 m = Vec3(1.0, -1.0, -1.0).asDiagonal();
  return m;
}

// R v without the zero entries' products, so that a non-finite component
// stays in its own axis (0 * inf would make every axis NaN).
Vec3 rotate(const Mat3& r, const Vec3& v) {
  Vec3 out = Vec3::Zero();
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      if (r(i, j) != 0.0) out[i] += r(i, j) * v[j];
  return out;
}
// Xsens sensor axes from body FRD, component by component.
Vec3 flu_from_frd(const Vec3& v) { return Vec3(v.x(), -v.y(), -v.z()); }

Mat3 rotation_of(const std::array<double, 4>& q_wxyz) {
  Eigen::Quaterniond q(q_wxyz[0], q_wxyz[1], q_wxyz[2], q_wxyz[3]);
  return q.normalized().toRotationMatrix();
}

// The local frame the identifier's coordinate bits choose, from ENU.
Mat3 local_from_enu(std::uint16_t id) {
  switch (id & xdi::kCoordinateMask) {
    case 0x4: return enu_from_ned();  // NED from ENU: the same swap
    case 0x8: return (Mat3() << 0, 1, 0, -1, 0, 0, 0, 0, 1).finished();
    default: return Mat3::Identity();
  }
}

void copy3(const Vec3& v, double* to) {
  to[0] = v.x();
  to[1] = v.y();
  to[2] = v.z();
}
Vec3 vec3(const double* v) { return Vec3(v[0], v[1], v[2]); }
Mat3 mat3(const double* r) {
  Mat3 m;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) m(i, j) = r[3 * i + j];
  return m;
}

// As vectornav.cpp's: ISA pressure at geometric height z (no allocation).
double isa_pressure_pa(double z_m) {
  constexpr double r0 = aiding::kIsaEarthRadius_m;
  const double z = std::clamp(std::isfinite(z_m) ? z_m : 0.0, -4900.0, 20000.0);
  const double h = r0 * z / (r0 + z);
  if (h <= 11000.0) return 101325.0 * std::pow(1.0 - 0.0065 * h / 288.15, 5.255877);
  return 22632.06 * std::exp(-0.000157688 * (h - 11000.0));
}

// Big-endian writers; the real-valued ones in the identifier's precision,
// clamped to the format's range (non-finite: 0 and flagged).
struct Writer {
  std::vector<std::uint8_t>& out;
  bool clipped = false;
  template <class T>
  void be(T v) {
    std::uint8_t b[sizeof(T)];
    wire::put_be<T>(b, v);
    out.insert(out.end(), b, b + sizeof(T));
  }
  void real(double v, unsigned precision) {
    v += 0.0;  // -0 (a negated zero axis) goes out as +0
    switch (precision) {
      case 0: {
        const wire::WireValue w = wire::to_wire_float<float>(v);
        clipped = clipped || w.clamped || w.was_nan;
        be<float>(static_cast<float>(w.value));
        return;
      }
      case 3: {
        const wire::WireValue w = wire::to_wire_float<double>(v);
        clipped = clipped || w.clamped || w.was_nan;
        be<double>(w.value);
        return;
      }
      case 1: {  // fp12.20: int32 of v * 2^20
        const double scaled = std::isfinite(v) ? std::round(v * 1048576.0) : 0.0;
        constexpr double lo = std::numeric_limits<std::int32_t>::min(), hi = std::numeric_limits<std::int32_t>::max();
        clipped = clipped || !std::isfinite(v) || scaled < lo || scaled > hi;
        be<std::int32_t>(static_cast<std::int32_t>(std::clamp(scaled, lo, hi)));
        return;
      }
      default: {  // fp16.32: the 48-bit v * 2^32, fraction (32 bits) then integer (16 bits)
        const double scaled = std::isfinite(v) ? std::round(v * 4294967296.0) : 0.0;
        constexpr double hi = 140737488355327.0, lo = -140737488355328.0;  // +-2^47
        clipped = clipped || !std::isfinite(v) || scaled < lo || scaled > hi;
        const auto fixed = static_cast<std::int64_t>(std::clamp(scaled, lo, hi));
        be<std::uint32_t>(static_cast<std::uint32_t>(static_cast<std::uint64_t>(fixed) & 0xFFFFFFFFu));
        be<std::uint16_t>(static_cast<std::uint16_t>((static_cast<std::uint64_t>(fixed) >> 32) & 0xFFFFu));
        return;
      }
    }
  }
};

constexpr std::size_t precision_bytes(unsigned precision) { return precision == 0 || precision == 1 ? 4 : precision == 2 ? 6 : 8; }

// How many real values a real-valued identifier carries; 0: not real-valued.
std::size_t real_count(std::uint16_t base) {
  switch (base) {
    case xdi::kTemperature: return 1;
    case xdi::kQuaternion: return 4;
    case xdi::kRotationMatrix: return 9;
    case xdi::kEulerAngles: return 3;
    case xdi::kDeltaV: return 3;
    case xdi::kAcceleration: return 3;
    case xdi::kFreeAcceleration: return 3;
    case xdi::kAltitudeEllipsoid: return 1;
    case xdi::kLatLon: return 2;
    case xdi::kRateOfTurn: return 3;
    case xdi::kDeltaQ: return 4;
    case xdi::kMagneticField: return 3;
    case xdi::kVelocityXyz: return 3;
    default: return 0;
  }
}
// The identifiers whose coordinate bits choose a frame (the others take 0 only).
bool has_coordinate_bits(std::uint16_t base) {
  return base == xdi::kQuaternion || base == xdi::kRotationMatrix || base == xdi::kEulerAngles ||
         base == xdi::kFreeAcceleration || base == xdi::kVelocityXyz;
}

}  // namespace

std::uint8_t checksum(std::span<const std::uint8_t> after_preamble) noexcept {
  unsigned sum = 0;
  for (const std::uint8_t b : after_preamble) sum += b;
  return static_cast<std::uint8_t>(0x100 - (sum & 0xFF));
}

void append_message(std::uint8_t message_id, std::span<const std::uint8_t> data, std::vector<std::uint8_t>& out) {
  const std::size_t start = out.size();
  out.push_back(kPreamble);
  out.push_back(kMasterBusId);
  out.push_back(message_id);
  if (data.size() < kExtendedLength) {
    out.push_back(static_cast<std::uint8_t>(data.size()));
  } else {
    out.push_back(kExtendedLength);
    out.push_back(static_cast<std::uint8_t>(data.size() >> 8));
    out.push_back(static_cast<std::uint8_t>(data.size() & 0xFF));
  }
  out.insert(out.end(), data.begin(), data.end());
  out.push_back(checksum(std::span<const std::uint8_t>(out.data() + start + 1, out.size() - start - 1)));
}

std::vector<std::uint8_t> message(std::uint8_t message_id, std::span<const std::uint8_t> data) {
  std::vector<std::uint8_t> out;
  append_message(message_id, data, out);
  return out;
}

ModelTraits traits_of(XsensModel model) noexcept {
  ModelTraits t;
  switch (model) {
    case XsensModel::mti3: t.max_rate_hz = 100; break;                       // MTi-1 series: fused outputs at 100 Hz
    case XsensModel::mti7: t.max_rate_hz = 100, t.gnss = true; break;
    case XsensModel::mti630: t.max_rate_hz = 400; break;
    case XsensModel::mti680g: t.max_rate_hz = 400, t.gnss = true, t.baro = true; break;
    case XsensModel::mti_g710: t.max_rate_hz = 400, t.gnss = true, t.baro = true; break;
  }
  return t;
}

std::size_t data_bytes(std::uint16_t id) noexcept {
  const auto base = static_cast<std::uint16_t>(id & ~xdi::kFormatMask);
  const unsigned precision = id & xdi::kPrecisionMask;
  const unsigned coordinate = (id & xdi::kCoordinateMask) >> 2;
  if (const std::size_t n = real_count(base); n != 0) {
    if (coordinate == 3 || (coordinate != 0 && !has_coordinate_bits(base))) return 0;
    return n * precision_bytes(precision);
  }
  if ((id & xdi::kFormatMask) != 0) return 0;
  switch (base) {
    case xdi::kUtcTime: return 12;
    case xdi::kPacketCounter: return 2;
    case xdi::kSampleTimeFine: return 4;
    case xdi::kBaroPressure: return 4;
    case xdi::kGnssPvtData: return kGnssPvtBytes;
    case xdi::kStatusWord: return 4;
    default: return 0;
  }
}

bool model_sends(const ModelTraits& traits, std::uint16_t id) noexcept {
  const auto base = static_cast<std::uint16_t>(id & ~xdi::kFormatMask);
  switch (base) {
    case xdi::kQuaternion:
    case xdi::kRotationMatrix:
    case xdi::kEulerAngles:
    case xdi::kFreeAcceleration: return traits.orientation;
    case xdi::kBaroPressure: return traits.baro;
    case xdi::kLatLon:
    case xdi::kAltitudeEllipsoid:
    case xdi::kVelocityXyz:
    case xdi::kGnssPvtData: return traits.gnss;
    default: return data_bytes(id) != 0;
  }
}

std::optional<OutputConfiguration> apply_output_configuration(const ModelTraits& traits,
                                                              std::span<const OutputItem> requested) {
  if (requested.size() > kMaxOutputItems) return std::nullopt;
  OutputConfiguration applied;
  for (const OutputItem& r : requested) {
    const auto base = static_cast<std::uint16_t>(r.id & ~xdi::kFormatMask);
    // [L] a zero identifier ends / empties the list.
    if (r.id == 0) continue;
    if (data_bytes(r.id) == 0 && real_count(base) != 0) return std::nullopt;  // a format this quantity has not
    if (!model_sends(traits, r.id)) continue;
    bool duplicate = false;
    for (std::size_t i = 0; i < applied.count; ++i) duplicate = duplicate || applied.items[i].id == r.id;
    if (duplicate) continue;
    OutputItem a{r.id, r.rate_hz};
    if (base == xdi::kPacketCounter || base == xdi::kSampleTimeFine || r.rate_hz == xdi::kEveryPacket) {
      a.rate_hz = xdi::kEveryPacket;
    } else if (r.rate_hz == 0) {
      continue;  // rate 0: not output
    } else {
      // The largest rate <= the one asked that divides the maximum rate.
      const std::uint16_t max = traits.max_rate_hz;
      std::uint16_t best = 1;
      for (std::uint16_t d = 1; d <= max; ++d) {
        if (max % d != 0) continue;
        const auto rate = static_cast<std::uint16_t>(max / d);
        if (rate <= r.rate_hz) {
          best = rate;
          break;
        }
      }
      a.rate_hz = best;
    }
    applied.items[applied.count++] = a;
  }
  return applied;
}

OutputConfiguration default_output_configuration(const ModelTraits& traits) {
  std::vector<OutputItem> items{{xdi::kPacketCounter, xdi::kEveryPacket}, {xdi::kSampleTimeFine, xdi::kEveryPacket}};
  const std::uint16_t r = std::min<std::uint16_t>(traits.max_rate_hz, 100);
  if (traits.orientation) items.push_back({xdi::kQuaternion, r});
  items.push_back({xdi::kAcceleration, r});
  items.push_back({xdi::kRateOfTurn, r});
  items.push_back({xdi::kMagneticField, r});
  if (traits.gnss) {
    items.push_back({xdi::kLatLon, r});
    items.push_back({xdi::kAltitudeEllipsoid, r});
    items.push_back({xdi::kVelocityXyz, r});
  }
  items.push_back({xdi::kStatusWord, r});
  return *apply_output_configuration(traits, items);
}

void append_item_data(std::uint16_t id, const StreamConfig& frames, const Measurements& m, std::uint16_t packet_counter,
                      std::vector<std::uint8_t>& out, std::uint32_t& clipped) {
  Writer w{out};
  const auto base = static_cast<std::uint16_t>(id & ~xdi::kFormatMask);
  const unsigned p = id & xdi::kPrecisionMask;
  const Mat3 r_os = rotation_of(frames.rot_sensor_wxyz);
  const Mat3 r_local = rotation_of(frames.rot_local_wxyz) * local_from_enu(id);  // L' from ENU
  auto sensor3 = [&](const double* v_s, std::uint32_t clip_x_bit) {
    const Vec3 v = rotate(r_os, vec3(v_s));
    for (int i = 0; i < 3; ++i) {
      w.clipped = false;
      w.real(v[i], p);
      if (w.clipped && clip_x_bit != 0) clipped |= clip_x_bit << i;
    }
  };
  switch (base) {
    case xdi::kTemperature: w.real(m.temperature_c, p); break;
    case xdi::kUtcTime:
      w.be<std::uint32_t>(m.utc_ns);
      w.be<std::uint16_t>(m.utc_year);
      for (const std::uint8_t b : {m.utc_month, m.utc_day, m.utc_hour, m.utc_minute, m.utc_second, m.utc_flags})
        w.be<std::uint8_t>(b);
      break;
    case xdi::kPacketCounter: w.be<std::uint16_t>(packet_counter); break;
    case xdi::kSampleTimeFine:
      w.be<std::uint32_t>(static_cast<std::uint32_t>(m.since_power_up_ns / (1'000'000'000 / kSampleTimeFineHz)));
      break;
    case xdi::kQuaternion:
    case xdi::kRotationMatrix:
    case xdi::kEulerAngles: {
      const Mat3 r = r_local * mat3(m.r_enu_s) * r_os.transpose();  // R_{L'<-O}
      if (base == xdi::kQuaternion) {
        Eigen::Quaterniond q(r);
        q.normalize();
        if (q.w() < 0) q.coeffs() *= -1.0;
        for (const double c : {q.w(), q.x(), q.y(), q.z()}) w.real(c, p);
      } else if (base == xdi::kRotationMatrix) {
        // [L] RotationMatrix: a..i with R = [a d g; b e h; c f i] (column by column).
        for (int j = 0; j < 3; ++j)
          for (int i = 0; i < 3; ++i) w.real(r(i, j), p);
      } else {
        // [L] EulerAngles: roll, pitch, yaw of R = Rz(yaw) Ry(pitch) Rx(roll), degrees.
        const double roll = std::atan2(r(2, 1), r(2, 2));
        const double pitch = -std::asin(std::clamp(r(2, 0), -1.0, 1.0));
        const double yaw = std::atan2(r(1, 0), r(0, 0));
        for (const double a : {roll, pitch, yaw}) w.real(a * kRadToDeg, p);
      }
      break;
    }
    case xdi::kBaroPressure:
      w.be<std::uint32_t>(static_cast<std::uint32_t>(std::clamp(std::round(m.pressure_pa), 0.0, 4294967295.0)));
      break;
    case xdi::kDeltaV: sensor3(m.delta_v_s_m_s, status_bit::kClipAccX); break;
    case xdi::kAcceleration: sensor3(m.acc_s_m_s2, status_bit::kClipAccX); break;
    case xdi::kRateOfTurn: sensor3(m.gyr_s_rad_s, status_bit::kClipGyrX); break;
    case xdi::kMagneticField: sensor3(m.mag_s_au, status_bit::kClipMagX); break;
    case xdi::kDeltaQ: {
      // ΔQ in O: the rotation's axis turned by R_OS.
      const Vec3 v = r_os * Vec3(m.delta_q_wxyz[1], m.delta_q_wxyz[2], m.delta_q_wxyz[3]);
      for (const double c : {m.delta_q_wxyz[0], v.x(), v.y(), v.z()}) w.real(c, p);
      break;
    }
    case xdi::kFreeAcceleration: {
      const Vec3 a = r_local * vec3(m.free_acc_enu_m_s2);
      for (int i = 0; i < 3; ++i) w.real(a[i], p);
      break;
    }
    case xdi::kVelocityXyz: {
      const Vec3 v = r_local * vec3(m.vel_enu_m_s);
      for (int i = 0; i < 3; ++i) w.real(v[i], p);
      break;
    }
    case xdi::kAltitudeEllipsoid: w.real(m.altitude_m, p); break;
    case xdi::kLatLon:
      w.real(m.latitude_deg, p);
      w.real(m.longitude_deg, p);
      break;
    case xdi::kStatusWord: w.be<std::uint32_t>(m.status_word | clipped | (clipped != 0 ? status_bit::kClipping : 0u)); break;
    case xdi::kGnssPvtData: {
      // [L] GnssPvtData: the u-blox NAV-PVT fields, big-endian.
      auto i32 = [&](double v) {
        w.be<std::int32_t>(static_cast<std::int32_t>(std::clamp(std::isfinite(v) ? std::round(v) : 0.0, -2147483648.0, 2147483647.0)));
      };
      auto u32 = [&](double v) {
        w.be<std::uint32_t>(static_cast<std::uint32_t>(std::clamp(std::isfinite(v) ? std::round(v) : 0.0, 0.0, 4294967295.0)));
      };
      auto u16 = [&](double v) {
        w.be<std::uint16_t>(static_cast<std::uint16_t>(std::clamp(std::isfinite(v) ? std::round(v) : 0.0, 0.0, 65535.0)));
      };
      w.be<std::uint32_t>(m.gnss_itow_ms);
      w.be<std::uint16_t>(m.utc_year);
      for (const std::uint8_t b : {m.utc_month, m.utc_day, m.utc_hour, m.utc_minute, m.utc_second})
        w.be<std::uint8_t>(b);
      w.be<std::uint8_t>(static_cast<std::uint8_t>((m.utc_flags & 0x04) != 0 ? 0x07 : 0x00));  // valid: date, time, fully resolved
      u32(m.gnss_t_acc_ns);
      i32(static_cast<double>(m.utc_ns));
      w.be<std::uint8_t>(m.gnss_fix_type);
      w.be<std::uint8_t>(static_cast<std::uint8_t>(m.gnss_fix_type >= 2 ? 0x01 : 0x00));  // flags: gnssFixOK
      w.be<std::uint8_t>(m.gnss_num_sv);
      w.be<std::uint8_t>(0);
      i32(m.longitude_deg * 1e7);
      i32(m.latitude_deg * 1e7);
      i32(m.altitude_m * 1e3);
      i32(m.gnss_height_msl_m * 1e3);
      u32(m.gnss_h_acc_m * 1e3);
      u32(m.gnss_v_acc_m * 1e3);
      for (int i = 0; i < 3; ++i) i32(m.gnss_vel_ned_m_s[i] * 1e3);
      const double ground_speed = std::hypot(m.gnss_vel_ned_m_s[0], m.gnss_vel_ned_m_s[1]);
      i32(ground_speed * 1e3);
      double heading = std::atan2(m.gnss_vel_ned_m_s[1], m.gnss_vel_ned_m_s[0]) * kRadToDeg;
      if (heading < 0) heading += 360.0;
      i32(heading * 1e5);
      u32(m.gnss_s_acc_m_s * 1e3);
      u32(0.5 * 1e5);  // heading accuracy 0.5 deg
      i32(heading * 1e5);
      const double tdop = 1.0;
      u16(std::hypot(m.gnss_pdop, tdop) * 100.0);
      u16(m.gnss_pdop * 100.0);
      u16(tdop * 100.0);
      u16(m.gnss_vdop * 100.0);
      u16(m.gnss_hdop * 100.0);
      u16(m.gnss_hdop / std::sqrt(2.0) * 100.0);
      u16(m.gnss_hdop / std::sqrt(2.0) * 100.0);
      break;
    }
    default: break;
  }
  if (w.clipped && (base == xdi::kAcceleration || base == xdi::kRateOfTurn || base == xdi::kMagneticField ||
                    base == xdi::kDeltaV))
    clipped |= status_bit::kClipping;
}

std::uint32_t append_mtdata2(std::span<const OutputItem> items, const StreamConfig& frames, const Measurements& m,
                             std::uint16_t packet_counter, std::vector<std::uint8_t>& out) {
  std::size_t payload = 0;
  for (const OutputItem& it : items) payload += 3 + data_bytes(it.id);
  const std::size_t start = out.size();
  out.push_back(kPreamble);
  out.push_back(kMasterBusId);
  out.push_back(mid::kMtData2);
  if (payload < kExtendedLength) {
    out.push_back(static_cast<std::uint8_t>(payload));
  } else {
    out.push_back(kExtendedLength);
    out.push_back(static_cast<std::uint8_t>(payload >> 8));
    out.push_back(static_cast<std::uint8_t>(payload & 0xFF));
  }
  // The StatusWord reports the clipping of the values before it and of the
  // sample's own saturation: sensor data first, StatusWord in its list place.
  std::uint32_t clipped = 0;
  for (const OutputItem& it : items) {
    out.push_back(static_cast<std::uint8_t>(it.id >> 8));
    out.push_back(static_cast<std::uint8_t>(it.id & 0xFF));
    out.push_back(static_cast<std::uint8_t>(data_bytes(it.id)));
    append_item_data(it.id, frames, m, packet_counter, out, clipped);
  }
  out.push_back(checksum(std::span<const std::uint8_t>(out.data() + start + 1, out.size() - start - 1)));
  return clipped;
}

// ------------------------------------------------------------------ encoder

StreamConfig Encoder::power_up_config(const XsensDeviceConfig& config) {
  StreamConfig c;
  c.measurement = true;
  c.output = default_output_configuration(traits_of(config.model));
  return c;
}

Encoder::Encoder(const StreamEncoderOptions& options)
    : DeviceEncoderBase(options, traits_of(options.xsens.model).max_rate_hz, power_up_config(options.xsens)),
      traits_(traits_of(options.xsens.model)) {
  if (options_.xsens.answers_commands) install_device(std::make_unique<Device>(options_.xsens, traits_));
}

Encoder::~Encoder() = default;

Encoder& Encoder::operator=(const Encoder& other) {
  // As the copy constructor: a fresh device of the same options.
  if (this != &other) *this = Encoder(other.options_);
  return *this;
}

Encoder& Encoder::operator=(Encoder&& other) = default;

void Encoder::restart(TimeNs now_ns, std::vector<std::uint8_t>& out) {
  DeviceEncoderBase::restart(now_ns, out);
  packet_counter_ = 0;
  // [L] "WakeUp": the first message after power-up.
  const std::uint8_t wake[] = {kPreamble, kMasterBusId, mid::kWakeUp, 0x00,
                               checksum(std::array<std::uint8_t, 3>{kMasterBusId, mid::kWakeUp, 0x00})};
  out.insert(out.end(), std::begin(wake), std::end(wake));
}

Measurements Encoder::measurements_of(const ImuFrameInput& s) const {
  Measurements m;
  m.since_power_up_ns = static_cast<std::uint64_t>(since_power_up_ns(s));
  const Mat3 r_enu_s = enu_from_ned() * s.sensor_to_ned * s_from_b();
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) m.r_enu_s[3 * i + j] = r_enu_s(i, j);
  copy3(flu_from_frd(s.accel_m_s2), m.acc_s_m_s2);
  copy3(flu_from_frd(s.gyro_rad_s), m.gyr_s_rad_s);
  const double* ref = options_.xsens.mag_reference_ned_au;
  copy3(r_enu_s.transpose() * (enu_from_ned() * Vec3(ref[0], ref[1], ref[2])), m.mag_s_au);
  if (s.has_temperature) m.temperature_c = s.temperature_c;
  Vec3 gravity_ned(0.0, 0.0, earth::kStandardGravity_m_s2);
  if (s.has_navigation) {
    const Vec3 ecef = earth::ecef_from_geodetic({s.latitude_rad, s.longitude_rad, s.height_m});
    gravity_ned = attitude::ned_to_ecef(s.latitude_rad, s.longitude_rad).transpose() * earth::normal_gravity_ecef(ecef);
    m.pressure_pa = isa_pressure_pa(s.height_m);
  }
  copy3(enu_from_ned() * (s.sensor_to_ned * s.accel_m_s2 + gravity_ned), m.free_acc_enu_m_s2);

  m.status_word = status_bit::kSelfTest | (traits_.orientation ? status_bit::kFilterValid : 0u);
  if ((s.status & kStatusSaturated) != 0)
    m.status_word |= status_bit::kClipping | (0x7u * status_bit::kClipAccX) | (0x7u * status_bit::kClipGyrX);

  if (traits_.gnss) {
    const GnssFix fix = fix_from_frame(s, options_.gnss);
    if (s.has_navigation) {
      m.has_navigation = true;
      m.latitude_deg = s.latitude_rad * kRadToDeg;
      m.longitude_deg = s.longitude_rad * kRadToDeg;
      m.altitude_m = s.height_m;
      m.gnss_height_msl_m = s.height_m - fix.geoid_separation_m;
      copy3(enu_from_ned() * s.velocity_ned_m_s, m.vel_enu_m_s);
      copy3(s.velocity_ned_m_s, m.gnss_vel_ned_m_s);
    }
    if (fix.time_valid && fix.gps_time_ns >= 0) {
      const aiding::UtcCalendar c = aiding::calendar_from_posix_ns(
          fix.gps_time_ns + kGpsEpochPosixNs - std::int64_t{fix.gps_minus_utc_s} * 1'000'000'000LL);
      m.utc_ns = static_cast<std::uint32_t>(c.nanosecond);
      m.utc_year = static_cast<std::uint16_t>(std::clamp(c.year, 0, 65535));
      m.utc_month = static_cast<std::uint8_t>(c.month);
      m.utc_day = static_cast<std::uint8_t>(c.day);
      m.utc_hour = static_cast<std::uint8_t>(c.hour);
      m.utc_minute = static_cast<std::uint8_t>(c.minute);
      m.utc_second = static_cast<std::uint8_t>(c.second);
      m.utc_flags = 0x07;
      m.gnss_itow_ms = static_cast<std::uint32_t>((fix.gps_time_ns % kNsPerWeek) / 1'000'000);
    }
    m.gnss_fix_type = fix.fix_type == GnssFixType::fix_3d ? 3 : fix.fix_type == GnssFixType::fix_2d ? 2 : 0;
    m.gnss_num_sv = static_cast<std::uint8_t>(std::clamp(fix.satellites, 0, 255));
    m.gnss_h_acc_m = fix.horizontal_accuracy_m;
    m.gnss_v_acc_m = fix.vertical_accuracy_m;
    m.gnss_s_acc_m_s = fix.speed_accuracy_m_s;
    m.gnss_t_acc_ns = fix.time_accuracy_ns;
    m.gnss_pdop = fix.pdop, m.gnss_hdop = fix.hdop, m.gnss_vdop = fix.vdop;
    if (m.gnss_fix_type >= 2) m.status_word |= status_bit::kGnssFix;
  }
  // One sample's increments (the encoder replaces them with its accumulated ones).
  const Vec3 dtheta_s = flu_from_frd(s.delta_theta_rad);
  const double angle = dtheta_s.norm();
  const Vec3 axis = angle > 0.0 ? Vec3(dtheta_s / angle) : Vec3::UnitX();
  m.delta_q_wxyz[0] = std::cos(angle / 2);
  for (int i = 0; i < 3; ++i) m.delta_q_wxyz[i + 1] = axis[i] * std::sin(angle / 2);
  copy3(flu_from_frd(s.delta_velocity_m_s), m.delta_v_s_m_s);
  return m;
}

const StreamConfig& Encoder::streamed_config(StreamConfig& after_restart) const {
  if (!device_) return power_up_;
  const EmitConfig& published = device_->emit_config();
  if (!restart_pending(published) || published.measurement) return published;
  // Power-cycled, the io thread not yet told: measurement with the kept settings.
  after_restart = published;
  after_restart.measurement = true;
  return after_restart;
}

// The outputs of `c` due at sample k of a scene at scene_rate_hz, into
// due_items (n of them); false when no packet goes. An output at rate_hz is
// due on the sample that crosses the next multiple of its period on the
// scene's grid (every sample when the scene is slower); a packet goes when a
// timed output is due (or, when every output is "every packet", on every
// sample).
bool Encoder::packet_due(std::uint64_t k, std::uint64_t scene_rate_hz, const OutputConfiguration& c,
                         std::span<OutputItem> due_items, std::size_t& n) noexcept {
  n = 0;
  bool any_timed = false, only_every = true;
  for (std::size_t i = 0; i < c.count; ++i) {
    const OutputItem& it = c.items[i];
    only_every = only_every && it.rate_hz == xdi::kEveryPacket;
    if (it.rate_hz != xdi::kEveryPacket && !due_on_scene_grid(k, it.rate_hz, 1, scene_rate_hz)) continue;
    due_items[n++] = it;
    any_timed = any_timed || it.rate_hz != xdi::kEveryPacket;
  }
  return n != 0 && (any_timed || only_every);
}

void Encoder::encode(const ImuFrameInput& sample, std::vector<std::uint8_t>& out) {
  StreamConfig after_restart;
  const StreamConfig* c = &streamed_config(after_restart);
  start_sample(sample);
  IncrementSums& sums = increments_[0];
  if (!c->measurement) {
    // Config mode: nothing measured goes out, and the increments restart.
    sums = IncrementSums{};
    return;
  }
  std::size_t n = 0;
  if (!packet_due(sample.sample_counter, scene_rate_hz_, c->output, due_items_, n)) return;
  Measurements m = measurements_of(sample);
  // The sums are in body FRD; S is FLU (negating y and z commutes with the
  // sums, to the bit).
  const Vec3 dtheta_s_rad = flu_from_frd(sums.dtheta_rad);
  const double angle = dtheta_s_rad.norm();
  const Vec3 axis = angle > 0.0 ? Vec3(dtheta_s_rad / angle) : Vec3::UnitX();
  m.delta_q_wxyz[0] = std::cos(angle / 2);
  for (int i = 0; i < 3; ++i) m.delta_q_wxyz[i + 1] = axis[i] * std::sin(angle / 2);
  copy3(flu_from_frd(sums.dvel_m_s), m.delta_v_s_m_s);
  sums = IncrementSums{};
  if (device_) device_->publish_measurements(m);
  append_mtdata2(std::span<const OutputItem>(due_items_.data(), n), *c, m, packet_counter_, out);
  ++packet_counter_;
}

std::size_t Encoder::max_bytes_per_sample() const {
  // The largest MTData2 any configuration makes: the kMaxOutputItems widest
  // distinct identifiers (with their format bits) this model sends (an
  // applied configuration has no duplicates), plus a WakeUp.
  std::vector<std::size_t> sizes;
  for (const std::uint16_t base :
       {xdi::kTemperature, xdi::kUtcTime, xdi::kPacketCounter, xdi::kSampleTimeFine, xdi::kQuaternion,
        xdi::kRotationMatrix, xdi::kEulerAngles, xdi::kBaroPressure, xdi::kDeltaV, xdi::kAcceleration,
        xdi::kFreeAcceleration, xdi::kAltitudeEllipsoid, xdi::kLatLon, xdi::kGnssPvtData, xdi::kRateOfTurn,
        xdi::kDeltaQ, xdi::kMagneticField, xdi::kVelocityXyz, xdi::kStatusWord})
    for (std::uint16_t format = 0; format <= xdi::kFormatMask; ++format) {
      const auto id = static_cast<std::uint16_t>(base | format);
      if (data_bytes(id) != 0 && model_sends(traits_, id)) sizes.push_back(3 + data_bytes(id));
    }
  std::sort(sizes.begin(), sizes.end(), std::greater<>());
  std::size_t payload = 0;
  for (std::size_t i = 0; i < sizes.size() && i < kMaxOutputItems; ++i) payload += sizes[i];
  return 7 + payload + 5;  // preamble, bus id, MID, extended length (3), checksum; WakeUp
}

double Encoder::configured_bytes_per_second(double sample_rate_hz) const {
  // The packets of one second of the scene, counted: a packet's size
  // depends on which outputs are due together, and outputs at rates that do
  // not divide each other share some packets and not others.
  StreamConfig after_restart;
  const StreamConfig& c = streamed_config(after_restart);
  if (!c.measurement || !(sample_rate_hz > 0.0)) return 0.0;
  const auto samples = static_cast<std::uint64_t>(std::max<long long>(1, std::llround(sample_rate_hz)));
  std::array<OutputItem, kMaxOutputItems> items{};
  double bytes = 0.0;
  for (std::uint64_t k = 0; k < samples; ++k) {
    std::size_t n = 0;
    if (!packet_due(k, samples, c.output, items, n)) continue;
    std::size_t payload = 0;
    for (std::size_t i = 0; i < n; ++i) payload += 3 + data_bytes(items[i].id);
    // [L] preamble, bus id, MID, length (3 bytes when extended), checksum.
    bytes += static_cast<double>(payload + (payload < kExtendedLength ? 5 : 7));
  }
  return bytes * sample_rate_hz / static_cast<double>(samples);
}

StreamFrameLayout Encoder::frame_layout(std::span<const std::uint8_t> frame) const {
  StreamFrameLayout l;
  if (frame.size() < 5 || frame[0] != kPreamble) return StreamFrameLayout{frame.size()};
  std::size_t header = 4;
  std::size_t length = frame[3];
  l.length_offset = 3;
  l.length_bytes = 1;
  if (frame[3] == kExtendedLength) {
    if (frame.size() < 7) return StreamFrameLayout{frame.size()};
    header = 6;
    length = (std::size_t{frame[4]} << 8) | frame[5];
    l.length_offset = 4;
    l.length_bytes = 2;
    l.length_big_endian = true;
  }
  if (header + length + 1 > frame.size()) return StreamFrameLayout{frame.size()};
  l.frame_bytes = header + length + 1;
  l.checksum_offset = header + length;
  l.checksum_bytes = 1;
  return l;
}

// ------------------------------------------------------------------ decoder

double read_value(const std::uint8_t* p, unsigned precision) noexcept {
  switch (precision) {
    case 0: return wire::get_be<float>(p);
    case 1: return static_cast<double>(wire::get_be<std::int32_t>(p)) / 1048576.0;
    case 2: {
      const std::uint64_t fraction = wire::get_be<std::uint32_t>(p);
      const auto integer = static_cast<std::int16_t>(wire::get_be<std::uint16_t>(p + 4));
      const std::int64_t fixed = static_cast<std::int64_t>(static_cast<std::uint64_t>(static_cast<std::int64_t>(integer)) << 32 | fraction);
      return static_cast<double>(fixed) / 4294967296.0;
    }
    default: return wire::get_be<double>(p);
  }
}

std::size_t Decoder::decode_buffer(const SampleCallback& on_sample) {
  std::size_t pos = 0;
  const std::size_t n = buffer_.size();
  constexpr std::uint8_t kSync[] = {kPreamble, kMasterBusId};
  while (pos < n) {
    // The bus identifier is checked once the length byte is in too.
    const FrameStart start = frame_start_at(pos, kSync, 4);
    if (start == FrameStart::need_more) break;
    if (start == FrameStart::skipped) continue;
    std::size_t header = 4, length = buffer_[pos + 3];
    if (length == kExtendedLength) {
      if (pos + 6 > n) break;
      header = 6;
      length = (std::size_t{buffer_[pos + 4]} << 8) | buffer_[pos + 5];
      if (length > kMaxPayloadBytes) {
        skip_byte(pos, &DecoderCounters::other_errors);
        continue;
      }
    }
    const std::size_t total = header + length + 1;
    if (pos + total > n) break;
    unsigned sum = 0;
    for (std::size_t i = pos + 1; i < pos + total; ++i) sum += buffer_[i];
    if ((sum & 0xFF) != 0) {
      skip_byte(pos, &DecoderCounters::checksum_errors);
      continue;
    }
    ++counters_.frames;
    if (buffer_[pos + 2] == mid::kMtData2) {
      DecodedSample d;
      bool imu = false, tiled = true;
      const std::uint8_t* data = buffer_.data() + pos + header;
      std::size_t at = 0;
      while (at < length) {
        if (at + 3 > length) {
          tiled = false;
          break;
        }
        const std::uint16_t id = static_cast<std::uint16_t>((data[at] << 8) | data[at + 1]);
        const std::size_t size = data[at + 2];
        at += 3;
        if (at + size > length) {
          tiled = false;
          break;
        }
        const std::uint8_t* p = data + at;
        const auto base = static_cast<std::uint16_t>(id & ~xdi::kFormatMask);
        const unsigned precision = id & xdi::kPrecisionMask;
        const std::size_t step = size / 3;
        auto frd = [&](const std::uint8_t* q) {
          return Vec3(read_value(q, precision), -read_value(q + step, precision), -read_value(q + 2 * step, precision));
        };
        if (base == xdi::kPacketCounter && size == 2) {
          const std::uint16_t c = wire::get_be<std::uint16_t>(p);
          if (have_counter_ && c != static_cast<std::uint16_t>(last_counter_ + 1)) ++counters_.sequence_gaps;
          have_counter_ = true;
          last_counter_ = c;
          d.sequence = c;
          d.has_sequence = true;
        } else if (base == xdi::kSampleTimeFine && size == 4) {
          d.t_ns = static_cast<TimeNs>(wire::get_be<std::uint32_t>(p)) * 100'000;
          d.has_time = true;
        } else if (base == xdi::kRateOfTurn && size == data_bytes(id)) {
          d.gyro_rad_s = frd(p), imu = true;
        } else if (base == xdi::kAcceleration && size == data_bytes(id)) {
          d.accel_m_s2 = frd(p), imu = true;
        } else if (base == xdi::kDeltaV && size == data_bytes(id)) {
          d.delta_velocity_m_s = frd(p);
        } else if (base == xdi::kDeltaQ && size == data_bytes(id)) {
          const std::size_t q = size / 4;
          const double w = read_value(p, precision);
          const Vec3 v(read_value(p + q, precision), -read_value(p + 2 * q, precision), -read_value(p + 3 * q, precision));
          const double s = v.norm();
          d.delta_theta_rad = s > 0.0 ? Vec3(v / s * 2.0 * std::atan2(s, w)) : Vec3::Zero();
        } else if (base == xdi::kStatusWord && size == 4) {
          if ((wire::get_be<std::uint32_t>(p) & status_bit::kClipping) != 0) d.status |= kStatusSaturated;
        }
        at += size;
      }
      if (!tiled) ++counters_.other_errors;
      if (imu && tiled) {
        ++counters_.samples;
        if (on_sample) on_sample(d);
      }
    }
    pos += total;
  }
  return pos;
}

}  // namespace imuemu::drivers::xsens
