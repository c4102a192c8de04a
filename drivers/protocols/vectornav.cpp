// VectorNav binary output packets, async ASCII sentences and their decoder.
// Sources and conventions in vectornav.hpp.
#include "drivers/protocols/vectornav.hpp"

#include <Eigen/Geometry>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>

#include "core/aiding/atmosphere.hpp"
#include "core/aiding/calendar.hpp"
#include "core/attitude.hpp"
#include "core/earth.hpp"
#include "drivers/gnss_fix.hpp"
#include "drivers/protocols/vectornav_device.hpp"
#include "drivers/protocols/wire_bytes.hpp"

namespace imuemu::drivers::vectornav {

namespace {

constexpr double kRadToDeg = 180.0 / 3.14159265358979323846;
constexpr std::int64_t kNsPerWeek = 604'800LL * 1'000'000'000LL;
constexpr std::int64_t kGpsEpochPosixNs = 315'964'800LL * 1'000'000'000LL;
constexpr std::size_t kAsciiMaxBytes = 320;

// [U]/[S] field sizes, per group, bit 0..15 (0: not sent by this device).
constexpr std::array<std::array<std::uint8_t, 16>, kGroupCount> kFieldBytes{{
    // Common: TimeStartup, TimeGps, TimeSyncIn, Ypr, Quaternion, AngularRate, Position, Velocity,
    // Accel, Imu, MagPres, DeltaThetaVel, InsStatus, SyncInCnt, TimeGpsPps
    {8, 8, 8, 12, 16, 12, 24, 12, 12, 24, 20, 28, 2, 4, 8, 0},
    // Time: TimeStartup, TimeGps, GpsTow, GpsWeek, TimeSyncIn, TimeGpsPps, TimeUtc, SyncInCnt,
    // SyncOutCnt, TimeStatus
    {8, 8, 8, 2, 8, 8, 8, 4, 4, 1, 0, 0, 0, 0, 0, 0},
    // IMU: ImuStatus, UncompMag, UncompAccel, UncompGyro, Temp, Pres, DeltaTheta, DeltaVel, Mag,
    // Accel, AngularRate, SensSat
    {2, 12, 12, 12, 4, 4, 16, 12, 12, 12, 12, 2, 0, 0, 0, 0},
    // GNSS1: Utc, Tow, Week, NumSats, Fix, PosLla, PosEcef, VelNed, VelEcef, PosU, VelU, TimeU,
    // TimeInfo, Dop (SatInfo, RawMeas: variable length, not sent)
    {8, 8, 2, 1, 1, 24, 24, 12, 12, 12, 4, 4, 2, 28, 0, 0},
    // Attitude: VpeStatus, Ypr, Quaternion, Dcm, MagNed, AccelNed, LinearAccelBody,
    // LinearAccelNed, YprU
    {2, 12, 16, 36, 12, 12, 12, 12, 12, 0, 0, 0, 0, 0, 0, 0},
    // INS: InsStatus, PosLla, PosEcef, VelBody, VelNed, VelEcef, MagEcef, AccelEcef,
    // LinearAccelEcef, PosU, VelU
    {2, 24, 24, 12, 12, 12, 12, 12, 12, 4, 4, 0, 0, 0, 0, 0},
    // GNSS2: as GNSS1
    {8, 8, 2, 1, 1, 24, 24, 12, 12, 12, 4, 4, 2, 28, 0, 0},
}};

// Little-endian field writers; floats through to_wire_float (never NaN/Inf).
struct FieldWriter {
  std::vector<std::uint8_t>& out;
  void u8(std::uint8_t v) { out.push_back(v); }
  void u16(std::uint16_t v) {
    std::uint8_t b[2];
    wire::put_le<std::uint16_t>(b, v);
    out.insert(out.end(), b, b + 2);
  }
  void u32(std::uint32_t v) {
    std::uint8_t b[4];
    wire::put_le<std::uint32_t>(b, v);
    out.insert(out.end(), b, b + 4);
  }
  void u64(std::uint64_t v) {
    std::uint8_t b[8];
    wire::put_le<std::uint64_t>(b, v);
    out.insert(out.end(), b, b + 8);
  }
  void f(double v) {
    std::uint8_t b[4];
    wire::put_le<float>(b, static_cast<float>(wire::to_wire_float<float>(v).value));
    out.insert(out.end(), b, b + 4);
  }
  void d(double v) {
    std::uint8_t b[8];
    wire::put_le<double>(b, wire::to_wire_float<double>(v).value);
    out.insert(out.end(), b, b + 8);
  }
  void f3(const double* v) { f(v[0]), f(v[1]), f(v[2]); }
  void d3(const double* v) { d(v[0]), d(v[1]), d(v[2]); }
};

void write_gnss_field(FieldWriter& w, int bit, const Measurements& m) {
  switch (bit) {
    case 0: for (const std::int8_t b : m.utc) w.u8(static_cast<std::uint8_t>(b)); break;
    case 1: w.u64(m.gnss_tow_ns); break;
    case 2: w.u16(m.gnss_week); break;
    case 3: w.u8(m.gnss_sats); break;
    case 4: w.u8(m.gnss_fix); break;
    case 5: w.d3(m.lla); break;
    case 6: w.d3(m.ecef_m); break;
    case 7: w.f3(m.vel_ned_m_s); break;
    case 8: w.f3(m.vel_ecef_m_s); break;
    case 9: w.f3(m.gnss_pos_u_m); break;
    case 10: w.f(m.gnss_vel_u_m_s); break;
    case 11: w.f(m.gnss_time_u_s); break;
    case 12:  // TimeInfo: status (bit 0 tow valid, 1 date valid, 2 UTC valid), leap seconds
      w.u8(m.time_status);
      w.u8(static_cast<std::uint8_t>(m.leap_seconds));
      break;
    case 13: for (const double x : m.gnss_dop) w.f(x); break;
    default: break;
  }
}

void write_field(FieldWriter& w, int group, int bit, const Measurements& m) {
  switch (group) {
    case kCommon:
      switch (bit) {
        case 0: w.u64(m.time_startup_ns); break;
        case 1: w.u64(m.time_gps_ns); break;
        case 2: w.u64(0); break;  // TimeSyncIn: no SyncIn event (the line is not emulated)
        case 3: w.f3(m.ypr_deg); break;
        case 4: for (const double q : m.quat_xyzw) w.f(q); break;
        case 5: w.f3(m.gyro_rad_s); break;
        case 6: w.d3(m.lla); break;
        case 7: w.f3(m.vel_ned_m_s); break;
        case 8: w.f3(m.accel_m_s2); break;
        case 9: w.f3(m.accel_m_s2), w.f3(m.gyro_rad_s); break;  // UncompAccel, UncompGyro
        case 10: w.f3(m.mag_gauss), w.f(m.temperature_c), w.f(m.pressure_kpa); break;
        case 11: w.f(m.dtime_s), w.f3(m.dtheta_deg), w.f3(m.dvel_m_s); break;
        case 12: w.u16(m.ins_status); break;
        case 13: w.u32(0); break;  // SyncInCnt
        case 14: w.u64(0); break;  // TimeGpsPps: no PPS
        default: break;
      }
      break;
    case kTime:
      switch (bit) {
        case 0: w.u64(m.time_startup_ns); break;
        case 1: w.u64(m.time_gps_ns); break;
        case 2: w.u64(m.gnss_tow_ns); break;
        case 3: w.u16(m.gnss_week); break;
        case 4: w.u64(0); break;
        case 5: w.u64(0); break;
        case 6: for (const std::int8_t b : m.utc) w.u8(static_cast<std::uint8_t>(b)); break;
        case 7: w.u32(0); break;
        case 8: w.u32(0); break;
        case 9: w.u8(m.time_status); break;
        default: break;
      }
      break;
    case kImu:
      switch (bit) {
        case 0: w.u16(0); break;  // ImuStatus: reserved
        case 1: case 8: w.f3(m.mag_gauss); break;
        case 2: case 9: w.f3(m.accel_m_s2); break;
        case 3: case 10: w.f3(m.gyro_rad_s); break;
        case 4: w.f(m.temperature_c); break;
        case 5: w.f(m.pressure_kpa); break;
        case 6: w.f(m.dtime_s), w.f3(m.dtheta_deg); break;
        case 7: w.f3(m.dvel_m_s); break;
        case 11: w.u16(m.sens_sat); break;
        default: break;
      }
      break;
    case kGnss1:
    case kGnss2: write_gnss_field(w, bit, m); break;
    case kAttitude:
      switch (bit) {
        case 0: w.u16(m.sens_sat != 0 ? 0x0204 : 0); break;  // VpeStatus: gyro (2) / accel (9) saturation
        case 1: w.f3(m.ypr_deg); break;
        case 2: for (const double q : m.quat_xyzw) w.f(q); break;
        case 3: for (const double c : m.dcm) w.f(c); break;
        case 4: w.f3(m.mag_ned_gauss); break;
        case 5: w.f3(m.accel_ned_m_s2); break;
        case 6: w.f3(m.lin_accel_body_m_s2); break;
        case 7: w.f3(m.lin_accel_ned_m_s2); break;
        case 8: w.f3(m.ypr_u_deg); break;
        default: break;
      }
      break;
    case kIns:
      switch (bit) {
        case 0: w.u16(m.ins_status); break;
        case 1: w.d3(m.lla); break;
        case 2: w.d3(m.ecef_m); break;
        case 3: w.f3(m.vel_body_m_s); break;
        case 4: w.f3(m.vel_ned_m_s); break;
        case 5: w.f3(m.vel_ecef_m_s); break;
        case 6: w.f3(m.mag_ecef_gauss); break;
        case 7: w.f3(m.accel_ecef_m_s2); break;
        case 8: w.f3(m.lin_accel_ecef_m_s2); break;
        case 9: w.f(m.pos_u_m); break;
        case 10: w.f(m.vel_u_m_s); break;
        default: break;
      }
      break;
    default: break;
  }
}

// snprintf into buf at len, never past capacity.
template <class... Args>
void put(char* buf, std::size_t& len, std::size_t capacity, const char* fmt, Args... args) {
  if (len >= capacity) return;
  const int n = std::snprintf(buf + len, capacity - len, fmt, args...);
  if (n > 0) len = std::min(capacity - 1, len + static_cast<std::size_t>(n));
}
// A finite value for an ASCII field (NaN -> 0, beyond what the field shows -> its limit).
double ascii_value(double v, double limit) {
  if (std::isnan(v)) return 0.0;
  return std::clamp(v, -limit, limit);
}
void put3(char* buf, std::size_t& len, std::size_t cap, const char* fmt, const double* v, double limit) {
  for (int i = 0; i < 3; ++i) put(buf, len, cap, fmt, ascii_value(v[i], limit));
}

// The current sample's VN quaternion (x, y, z, w) of R_s^n, w >= 0.
void quaternion_of(const Mat3& r_sn, double* q_xyzw) {
  Eigen::Quaterniond q(r_sn);
  q.normalize();
  if (q.w() < 0.0) q.coeffs() *= -1.0;
  q_xyzw[0] = q.x();
  q_xyzw[1] = q.y();
  q_xyzw[2] = q.z();
  q_xyzw[3] = q.w();
}

// US Standard Atmosphere 1976 (the ISA of core/aiding/atmosphere.hpp)
// pressure at geometric height z, written out here for the emission path
// (aiding::isa_at_ellipsoidal_height builds its refusal messages on every
// call): geopotential H = r0 z / (r0 + z); below 11 km the troposphere's
// lapse rate 6.5 K/km from 101325 Pa / 288.15 K, above it the isothermal
// layer at 216.65 K from 22632.06 Pa, held at 20 km (the device's
// barometer range ends long before).
double isa_pressure_pa(double z_m) {
  constexpr double r0 = aiding::kIsaEarthRadius_m;
  const double z = std::clamp(std::isfinite(z_m) ? z_m : 0.0, -4900.0, 20000.0);
  const double h = r0 * z / (r0 + z);
  if (h <= 11000.0) return 101325.0 * std::pow(1.0 - 0.0065 * h / 288.15, 5.255877);
  return 22632.06 * std::exp(-0.000157688 * (h - 11000.0));
}

void copy3(const Vec3& v, double* to) {
  to[0] = v.x();
  to[1] = v.y();
  to[2] = v.z();
}

}  // namespace

std::uint16_t crc16(std::span<const std::uint8_t> bytes) noexcept {
  std::uint16_t crc = 0;
  for (const std::uint8_t b : bytes) {
    crc = static_cast<std::uint16_t>(crc ^ (std::uint16_t{b} << 8));
    for (int i = 0; i < 8; ++i)
      crc = static_cast<std::uint16_t>((crc & 0x8000) != 0 ? (crc << 1) ^ 0x1021 : crc << 1);
  }
  return crc;
}

std::uint8_t checksum8(std::string_view body) noexcept {
  std::uint8_t c = 0;
  for (const char ch : body) c = static_cast<std::uint8_t>(c ^ static_cast<std::uint8_t>(ch));
  return c;
}

ModelTraits traits_of(VectorNavModel model) noexcept {
  constexpr std::uint8_t ahrs = (1u << kCommon) | (1u << kTime) | (1u << kImu) | (1u << kAttitude);
  switch (model) {
    case VectorNavModel::vn100: return {800, ahrs, false};
    case VectorNavModel::vn200:
      return {800, static_cast<std::uint8_t>(ahrs | (1u << kGnss1) | (1u << kIns)), true};
    case VectorNavModel::vn300:
      return {400, static_cast<std::uint8_t>(ahrs | (1u << kGnss1) | (1u << kIns) | (1u << kGnss2)), true};
  }
  return {};
}

std::size_t field_bytes(int group, int bit) noexcept {
  if (group < 0 || group >= kGroupCount || bit < 0 || bit >= 16) return 0;
  return kFieldBytes[static_cast<std::size_t>(group)][static_cast<std::size_t>(bit)];
}

std::size_t payload_bytes(const BinaryOutput& o) noexcept {
  std::size_t n = 0;
  for (int g = 0; g < kGroupCount; ++g) {
    if ((o.groups & (1u << g)) == 0) continue;
    for (int b = 0; b < 16; ++b)
      if ((o.fields[static_cast<std::size_t>(g)] & (1u << b)) != 0) n += field_bytes(g, b);
  }
  return n;
}

std::size_t packet_bytes(const BinaryOutput& o) noexcept {
  std::size_t groups = 0;
  for (int g = 0; g < kGroupCount; ++g) groups += (o.groups >> g) & 1u;
  return 2 + 2 * groups + payload_bytes(o) + kCrcBytes;
}

const char* ador_header(std::uint8_t ador) noexcept {
  switch (ador) {
    case kAdorYpr: return "YPR";
    case kAdorQtn: return "QTN";
    case kAdorQmr: return "QMR";
    case kAdorMag: return "MAG";
    case kAdorAcc: return "ACC";
    case kAdorGyr: return "GYR";
    case kAdorMar: return "MAR";
    case kAdorYmr: return "YMR";
    case kAdorImu: return "IMU";
    case kAdorIns: return "INS";
    case kAdorDtv: return "DTV";
    default: return nullptr;
  }
}

void append_binary_packet(const BinaryOutput& o, const Measurements& m, std::vector<std::uint8_t>& out) {
  const std::size_t start = out.size();
  FieldWriter w{out};
  w.u8(kSync);
  w.u8(o.groups);
  for (int g = 0; g < kGroupCount; ++g)
    if ((o.groups & (1u << g)) != 0) w.u16(o.fields[static_cast<std::size_t>(g)]);
  for (int g = 0; g < kGroupCount; ++g) {
    if ((o.groups & (1u << g)) == 0) continue;
    for (int b = 0; b < 16; ++b)
      if ((o.fields[static_cast<std::size_t>(g)] & (1u << b)) != 0 && field_bytes(g, b) != 0) write_field(w, g, b, m);
  }
  // [U] CRC over everything after the sync byte, most significant byte first.
  const std::uint16_t crc = crc16(std::span<const std::uint8_t>(out.data() + start + 1, out.size() - start - 1));
  out.push_back(static_cast<std::uint8_t>(crc >> 8));
  out.push_back(static_cast<std::uint8_t>(crc));
}

std::size_t format_ascii_fields(std::uint8_t ador, const Measurements& m, char* buf, std::size_t cap) noexcept {
  // [U] register and async output formats: angles "%+08.3f" deg, magnetic
  // "%+07.4f" gauss, acceleration "%+07.3f" m/s^2, angular rate "%+09.6f"
  // rad/s. Each field is clamped to what its format shows.
  std::size_t len = 0;
  const char* ypr = "%+08.3f,";
  const char* mag = "%+07.4f,";
  const char* acc = "%+07.3f,";
  const char* gyr = "%+09.6f,";
  switch (ador) {
    case kAdorYpr: put3(buf, len, cap, ypr, m.ypr_deg, 999.999); break;
    case kAdorQtn:
      for (const double q : m.quat_xyzw) put(buf, len, cap, "%+09.6f,", ascii_value(q, 1.0));
      break;
    case kAdorQmr:
      for (const double q : m.quat_xyzw) put(buf, len, cap, "%+09.6f,", ascii_value(q, 1.0));
      put3(buf, len, cap, mag, m.mag_gauss, 99.9999);
      put3(buf, len, cap, acc, m.accel_m_s2, 999.999);
      put3(buf, len, cap, gyr, m.gyro_rad_s, 99.999999);
      break;
    case kAdorMag: put3(buf, len, cap, mag, m.mag_gauss, 99.9999); break;
    case kAdorAcc: put3(buf, len, cap, acc, m.accel_m_s2, 999.999); break;
    case kAdorGyr: put3(buf, len, cap, gyr, m.gyro_rad_s, 99.999999); break;
    case kAdorMar:
      put3(buf, len, cap, mag, m.mag_gauss, 99.9999);
      put3(buf, len, cap, acc, m.accel_m_s2, 999.999);
      put3(buf, len, cap, gyr, m.gyro_rad_s, 99.999999);
      break;
    case kAdorYmr:
      put3(buf, len, cap, ypr, m.ypr_deg, 999.999);
      put3(buf, len, cap, mag, m.mag_gauss, 99.9999);
      put3(buf, len, cap, acc, m.accel_m_s2, 999.999);
      put3(buf, len, cap, gyr, m.gyro_rad_s, 99.999999);
      break;
    case kAdorImu:  // uncompensated mag, accel, gyro, temperature, pressure
      put3(buf, len, cap, mag, m.mag_gauss, 99.9999);
      put3(buf, len, cap, acc, m.accel_m_s2, 999.999);
      put3(buf, len, cap, gyr, m.gyro_rad_s, 99.999999);
      put(buf, len, cap, "%+05.1f,", ascii_value(m.temperature_c, 999.9));
      put(buf, len, cap, "%+07.3f,", ascii_value(m.pressure_kpa, 999.999));
      break;
    case kAdorIns:  // GPS time of week s, week, INS status (hex), YPR, LLA, NED velocity, uncertainties
      put(buf, len, cap, "%010.3f,", static_cast<double>(m.gnss_tow_ns) * 1e-9);
      put(buf, len, cap, "%04u,", static_cast<unsigned>(m.gnss_week));
      put(buf, len, cap, "%04X,", static_cast<unsigned>(m.ins_status));
      put3(buf, len, cap, ypr, m.ypr_deg, 999.999);
      put(buf, len, cap, "%+012.8f,", ascii_value(m.lla[0], 90.0));
      put(buf, len, cap, "%+013.8f,", ascii_value(m.lla[1], 180.0));
      put(buf, len, cap, "%+09.3f,", ascii_value(m.lla[2], 99999.999));
      put3(buf, len, cap, acc, m.vel_ned_m_s, 999.999);
      put(buf, len, cap, "%+07.3f,", ascii_value(m.ypr_u_deg[0], 999.999));
      put(buf, len, cap, "%+07.3f,", ascii_value(m.pos_u_m, 999.999));
      put(buf, len, cap, "%+07.3f,", ascii_value(m.vel_u_m_s, 999.999));
      break;
    case kAdorDtv:  // delta time s, delta theta deg, delta velocity m/s
      put(buf, len, cap, "%+09.6f,", ascii_value(m.dtime_s, 99.999999));
      put3(buf, len, cap, "%+09.4f,", m.dtheta_deg, 9999.9999);
      put3(buf, len, cap, "%+09.4f,", m.dvel_m_s, 9999.9999);
      break;
    default: return 0;
  }
  if (len > 0 && buf[len - 1] == ',') buf[--len] = '\0';  // no comma after the last field
  return len;
}

std::size_t finish_sentence(char* buf, std::size_t len, std::size_t cap, bool crc16_mode) noexcept {
  if (len == 0 || len + 8 > cap) return 0;
  const std::string_view body(buf + 1, len - 1);
  int n = 0;
  if (crc16_mode) {
    const std::uint16_t c =
        crc16(std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(body.data()), body.size()));
    n = std::snprintf(buf + len, cap - len, "*%04X\r\n", static_cast<unsigned>(c));
  } else {
    n = std::snprintf(buf + len, cap - len, "*%02X\r\n", static_cast<unsigned>(checksum8(body)));
  }
  return n > 0 ? len + static_cast<std::size_t>(n) : 0;
}

std::size_t format_ascii_output(std::uint8_t ador, const Measurements& m, bool crc16_mode, char* buf,
                                std::size_t cap) noexcept {
  const char* header = ador_header(ador);
  if (header == nullptr || cap < 16) return 0;
  std::size_t len = 0;
  put(buf, len, cap, "$VN%s,", header);
  const std::size_t fields = format_ascii_fields(ador, m, buf + len, cap - len);
  if (fields == 0) return 0;
  return finish_sentence(buf, len + fields, cap, crc16_mode);
}

// ------------------------------------------------------------------ encoder

StreamConfig Encoder::power_up_config(const VectorNavDeviceConfig& config) {
  StreamConfig c;
  const ModelTraits t = traits_of(config.model);
  c.ador = config.power_up_ador >= 0 ? static_cast<std::uint8_t>(config.power_up_ador) : (t.ins ? kAdorIns : kAdorYmr);
  c.adof_hz = config.power_up_adof_hz;
  return c;
}

Encoder::Encoder(const StreamEncoderOptions& options)
    : DeviceEncoderBase(options, traits_of(options.vectornav.model).imu_rate_hz, power_up_config(options.vectornav)),
      traits_(traits_of(options.vectornav.model)) {
  // The device keeps its settings (saved registers included) whether or not
  // its driver can talk to it; answers_commands = false only hides its
  // command side (a line with its receive wire not connected).
  install_device(std::make_unique<Device>(options_.vectornav, traits_), options_.vectornav.answers_commands);
}

Encoder::~Encoder() = default;

Encoder& Encoder::operator=(const Encoder& other) {
  // As the copy constructor: a fresh device of the same options.
  if (this != &other) *this = Encoder(other.options_);
  return *this;
}

Encoder& Encoder::operator=(Encoder&& other) = default;

Measurements Encoder::measurements_of(const ImuFrameInput& s) const {
  Measurements m;
  m.time_startup_ns = static_cast<std::uint64_t>(since_power_up_ns(s));

  const Mat3& r_sn = s.sensor_to_ned;  // identity when the producer has no attitude
  const attitude::HeadingPitchRoll hpr = attitude::hpr_from_rotation(r_sn);
  m.ypr_deg[0] = hpr.heading_rad * kRadToDeg;
  m.ypr_deg[1] = hpr.pitch_rad * kRadToDeg;
  m.ypr_deg[2] = hpr.roll_rad * kRadToDeg;
  quaternion_of(r_sn, m.quat_xyzw);
  const Mat3 r_ns = r_sn.transpose();
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) m.dcm[3 * i + j] = r_ns(i, j);
  copy3(s.gyro_rad_s, m.gyro_rad_s);
  copy3(s.accel_m_s2, m.accel_m_s2);
  const double* ref = options_.vectornav.mag_reference_ned_gauss;
  const Vec3 mag_ned(ref[0], ref[1], ref[2]);
  copy3(r_ns * mag_ned, m.mag_gauss);
  copy3(mag_ned, m.mag_ned_gauss);
  if (s.has_temperature) m.temperature_c = s.temperature_c;

  Vec3 gravity_ned(0.0, 0.0, earth::kStandardGravity_m_s2);
  Mat3 r_ne = Mat3::Identity();  // NED -> ECEF (identity without a position)
  if (s.has_navigation) {
    m.has_navigation = true;
    m.lla[0] = s.latitude_rad * kRadToDeg;
    m.lla[1] = s.longitude_rad * kRadToDeg;
    m.lla[2] = s.height_m;
    const Vec3 ecef = earth::ecef_from_geodetic({s.latitude_rad, s.longitude_rad, s.height_m});
    copy3(ecef, m.ecef_m);
    r_ne = attitude::ned_to_ecef(s.latitude_rad, s.longitude_rad);
    gravity_ned = r_ne.transpose() * earth::normal_gravity_ecef(ecef);
    m.pressure_kpa = isa_pressure_pa(s.height_m) / 1000.0;
    copy3(s.velocity_ned_m_s, m.vel_ned_m_s);
    copy3(r_ne * s.velocity_ned_m_s, m.vel_ecef_m_s);
    copy3(r_ns * s.velocity_ned_m_s, m.vel_body_m_s);
  }
  copy3(r_ne * mag_ned, m.mag_ecef_gauss);
  const Vec3 f_ned = r_sn * s.accel_m_s2;
  copy3(f_ned, m.accel_ned_m_s2);
  copy3(r_ne * f_ned, m.accel_ecef_m_s2);
  const Vec3 a_ned = f_ned + gravity_ned;  // true (kinematic) acceleration
  copy3(a_ned, m.lin_accel_ned_m_s2);
  copy3(r_ns * a_ned, m.lin_accel_body_m_s2);
  copy3(r_ne * a_ned, m.lin_accel_ecef_m_s2);

  // Uncertainties the device reports (1 sigma): a VN-100's datasheet
  // heading 2 deg (magnetic), pitch / roll 0.5 deg; the INS models' 0.3 /
  // 0.05 deg with a fix.
  const bool ins_fix = traits_.ins && s.has_navigation;
  m.ypr_u_deg[0] = ins_fix ? 0.3 : 2.0;
  m.ypr_u_deg[1] = m.ypr_u_deg[2] = ins_fix ? 0.05 : 0.5;
  if ((s.status & kStatusSaturated) != 0) m.sens_sat = 0x01F8;  // accel x/y/z (3-5), gyro x/y/z (6-8)
  for (int i = 0; i < 3; ++i) {
    for (const double v : {s.accel_m_s2[i], s.gyro_rad_s[i]}) {
      const wire::WireValue wv = wire::to_wire_float<float>(v);
      if (wv.clamped || wv.was_nan) m.sens_sat = static_cast<std::uint16_t>(m.sens_sat | 0x01F8);
    }
  }

  if (traits_.ins) {
    // GNSS (drivers/gnss_fix.hpp: the trajectory at the sample with the
    // receiver's configured figures).
    const GnssFix fix = fix_from_frame(s, options_.gnss);
    if (fix.time_valid && fix.gps_time_ns >= 0) {
      m.gps_time_valid = true;
      m.time_gps_ns = static_cast<std::uint64_t>(fix.gps_time_ns);
      m.gnss_week = static_cast<std::uint16_t>(std::min<std::int64_t>(fix.gps_time_ns / kNsPerWeek, 65535));
      m.gnss_tow_ns = static_cast<std::uint64_t>(fix.gps_time_ns % kNsPerWeek);
      m.leap_seconds = static_cast<std::int8_t>(fix.gps_minus_utc_s);
      m.time_status = 0x07;  // tow, date and UTC valid
      const aiding::UtcCalendar c = aiding::calendar_from_posix_ns(
          fix.gps_time_ns + kGpsEpochPosixNs - std::int64_t{fix.gps_minus_utc_s} * 1'000'000'000LL);
      m.utc[0] = static_cast<std::int8_t>(std::clamp(c.year - 2000, -128, 127));
      m.utc[1] = static_cast<std::int8_t>(c.month);
      m.utc[2] = static_cast<std::int8_t>(c.day);
      m.utc[3] = static_cast<std::int8_t>(c.hour);
      m.utc[4] = static_cast<std::int8_t>(c.minute);
      m.utc[5] = static_cast<std::int8_t>(c.second);
      const auto ms = static_cast<std::uint16_t>(c.nanosecond / 1'000'000);
      m.utc[6] = static_cast<std::int8_t>(ms & 0xFF);
      m.utc[7] = static_cast<std::int8_t>(ms >> 8);
    }
    m.gnss_fix = fix.fix_type == GnssFixType::fix_3d ? 3 : fix.fix_type == GnssFixType::fix_2d ? 2 : 0;
    m.gnss_sats = static_cast<std::uint8_t>(std::clamp(fix.satellites, 0, 255));
    m.gnss_pos_u_m[0] = m.gnss_pos_u_m[1] = fix.horizontal_accuracy_m;
    m.gnss_pos_u_m[2] = fix.vertical_accuracy_m;
    m.gnss_vel_u_m_s = fix.speed_accuracy_m_s;
    m.gnss_time_u_s = fix.time_accuracy_ns * 1e-9;
    const double tdop = 1.0;  // not configured: 1
    m.gnss_dop[0] = std::hypot(fix.pdop, tdop);
    m.gnss_dop[1] = fix.pdop;
    m.gnss_dop[2] = tdop;
    m.gnss_dop[3] = fix.vdop;
    m.gnss_dop[4] = fix.hdop;
    m.gnss_dop[5] = m.gnss_dop[6] = fix.hdop / std::sqrt(2.0);
    // [U] InsStatus: mode (bits 0-1: 0 initialising, 1 aligning, 2 tracking,
    // 3 loss of GNSS), bit 2 GNSS fix.
    if (m.gnss_fix >= 2) m.ins_status = 0x0002 | 0x0004;
    m.pos_u_m = m.gnss_fix >= 2 ? fix.horizontal_accuracy_m : 0.0;
    m.vel_u_m_s = m.gnss_fix >= 2 ? fix.speed_accuracy_m_s : 0.0;
  }
  m.dtime_s = static_cast<double>(s.period_ns) * 1e-9;
  copy3(s.delta_theta_rad * kRadToDeg, m.dtheta_deg);
  copy3(s.delta_velocity_m_s, m.dvel_m_s);
  return m;
}

void Encoder::encode(const ImuFrameInput& sample, std::vector<std::uint8_t>& out) {
  const StreamConfig* c = &published_or_startup_config();
  start_sample(sample);
  Measurements m = measurements_of(sample);
  if (device_) device_->publish_measurements(m);
  // SyncOut follows the IMU's events, not the async outputs: $VNASY,0 leaves it on.
  sync_pulse_ = sync_out_for(*c, sample.sample_counter, m);
  if (!c->async_enabled) return;  // $VNASY,0: nothing until $VNASY,1
  const std::uint8_t port_bit = static_cast<std::uint8_t>(1u << (options_.vectornav.port - 1));
  // [U] each output's deltas are integrated since its own last packet.
  auto take = [&](IncrementSums& d) {
    m.dtime_s = d.dtime_s;
    copy3(d.dtheta_rad * kRadToDeg, m.dtheta_deg);
    copy3(d.dvel_m_s, m.dvel_m_s);
    d = IncrementSums{};
  };
  for (std::size_t i = 0; i < c->binary.size(); ++i) {
    const BinaryOutput& o = c->binary[i];
    if ((o.async_mode & port_bit) == 0 || o.groups == 0 || !due_on_grid(sample.sample_counter, traits_.imu_rate_hz, o.rate_divisor))
      continue;
    take(increments_[i]);
    append_binary_packet(o, m, out);
  }
  if (c->ador != kAdorOff && due_on_grid(sample.sample_counter, c->adof_hz, 1)) {
    take(increments_[3]);
    char line[kAsciiMaxBytes];
    const std::size_t n = format_ascii_output(c->ador, m, c->crc16_mode, line, sizeof line);
    out.insert(out.end(), line, line + n);
  }
}

// [U] register 32: SyncOutMode ItStart / ImuReady pulse on the IMU's
// samples (its IMU rate), Ins when an attitude solution is ready (400 Hz on
// each model: the VN-100's / VN-200's filter runs at half their 800 Hz IMU
// rate), GpsPps on each whole second of GPS time (an INS with a time fix);
// every (SyncOutSkipFactor + 1)-th event. The events are counted on the
// scene's sample grid as the rate divisors are (due_on_grid()): a scene slower than
// the event rate pulses on every sample the skip factor allows.
std::optional<DeviceSyncPulse> Encoder::sync_out_for(const StreamConfig& c, std::uint64_t k,
                                                     const Measurements& m) noexcept {
  if (c.sync_out_mode == kSyncOutNone) {
    last_gps_second_ = -1;
    return std::nullopt;
  }
  DeviceSyncPulse p;
  p.width_ns = static_cast<TimeNs>(c.sync_out_width_ns);
  p.active_low = !c.sync_out_positive;
  const std::uint64_t every = std::uint64_t{c.sync_out_skip} + 1;
  switch (c.sync_out_mode) {
    case kSyncOutItStart:
    case kSyncOutImuReady: p.pulse = due_on_grid(k, traits_.imu_rate_hz, every); break;
    case kSyncOutIns: p.pulse = due_on_grid(k, 400, every); break;
    case kSyncOutGpsPps: {
      const std::int64_t second = m.gps_time_valid ? static_cast<std::int64_t>(m.time_gps_ns / 1'000'000'000ULL) : -1;
      p.pulse = second >= 0 && last_gps_second_ >= 0 && second != last_gps_second_ &&
                second % static_cast<std::int64_t>(every) == 0;
      last_gps_second_ = second;
      break;
    }
    default: break;
  }
  return p;
}

std::size_t Encoder::max_bytes_per_sample() const {
  // Three binary outputs with every field of every group, and one sentence.
  BinaryOutput all;
  all.groups = 0x7F;
  all.fields.fill(0xFFFF);
  return 3 * packet_bytes(all) + kAsciiMaxBytes;
}

double Encoder::configured_bytes_per_second(double sample_rate_hz) const {
  // The outputs on at this port now: each binary packet at the IMU rate
  // over its divisor, the ASCII sentence (fixed-width fields [U]: its
  // length does not depend on the values) at register 7's rate.
  const StreamConfig& c = published_or_startup_config();
  if (!c.async_enabled) return 0.0;
  const std::uint8_t port_bit = static_cast<std::uint8_t>(1u << (options_.vectornav.port - 1));
  double bytes = 0.0;
  for (const BinaryOutput& o : c.binary) {
    if ((o.async_mode & port_bit) == 0 || o.groups == 0) continue;
    bytes += sent_per_second(traits_.imu_rate_hz, o.rate_divisor, sample_rate_hz) * static_cast<double>(packet_bytes(o));
  }
  if (c.ador != kAdorOff) {
    char line[kAsciiMaxBytes];
    const std::size_t n = format_ascii_output(c.ador, Measurements{}, c.crc16_mode, line, sizeof line);
    bytes += sent_per_second(c.adof_hz, 1, sample_rate_hz) * static_cast<double>(n);
  }
  return bytes;
}

StreamFrameLayout Encoder::frame_layout(std::span<const std::uint8_t> frame) const {
  StreamFrameLayout l;
  if (frame.empty()) return l;
  if (frame[0] == kSync && frame.size() >= 2) {
    BinaryOutput o;
    o.groups = frame[1];
    std::size_t at = 2;
    for (int g = 0; g < kGroupCount; ++g) {
      if ((o.groups & (1u << g)) == 0) continue;
      if (at + 2 > frame.size()) return l;
      o.fields[static_cast<std::size_t>(g)] = wire::get_le<std::uint16_t>(frame.data() + at);
      at += 2;
    }
    const std::size_t n = packet_bytes(o);
    if (n > frame.size()) return l;
    l.frame_bytes = n;
    l.checksum_offset = n - kCrcBytes;
    l.checksum_bytes = kCrcBytes;
    return l;
  }
  if (frame[0] == '$') {
    for (std::size_t i = 1; i < frame.size(); ++i) {
      if (frame[i] == '*') {
        l.checksum_offset = i + 1;
        l.checksum_bytes = 0;
        while (l.checksum_offset + l.checksum_bytes < frame.size() &&
               std::isxdigit(frame[l.checksum_offset + l.checksum_bytes]) != 0)
          ++l.checksum_bytes;
      }
      if (frame[i] == '\n') {
        l.frame_bytes = i + 1;
        return l;
      }
    }
  }
  return StreamFrameLayout{frame.size()};
}

// ------------------------------------------------------------------ decoder

std::size_t Decoder::decode_buffer(const SampleCallback& on_sample) {
  std::size_t pos = 0;
  const std::size_t n = buffer_.size();
  while (pos < n) {
    const std::uint8_t b = buffer_[pos];
    if (b == '$') {
      std::size_t end = pos + 1;
      while (end < n && buffer_[end] != '\n' && end - pos < kAsciiMaxBytes) ++end;
      if (end >= n) break;  // wait for the rest
      if (buffer_[end] != '\n') {
        skip_byte(pos, &DecoderCounters::other_errors);
        continue;
      }
      const std::string_view line(reinterpret_cast<const char*>(buffer_.data() + pos), end + 1 - pos);
      const std::size_t star = line.rfind('*');
      bool ok = star != std::string_view::npos;
      if (ok) {
        const std::string_view body = line.substr(1, star - 1);
        std::string_view sum = line.substr(star + 1);
        while (!sum.empty() && (sum.back() == '\n' || sum.back() == '\r')) sum.remove_suffix(1);
        unsigned value = 0;
        for (const char ch : sum) value = value * 16 + static_cast<unsigned>(std::isdigit(ch) ? ch - '0' : (ch | 0x20) - 'a' + 10);
        if (sum.size() == 2) ok = value == checksum8(body);
        else if (sum.size() == 4)
          ok = value == crc16(std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(body.data()), body.size()));
        else ok = false;
      }
      if (!ok) {
        skip_byte(pos, &DecoderCounters::checksum_errors);
        continue;
      }
      ++counters_.frames;
      pos = end + 1;
      continue;
    }
    constexpr std::uint8_t kSyncBytes[] = {kSync};
    const FrameStart start = frame_start_at(pos, kSyncBytes, 2);  // sync and group byte
    if (start == FrameStart::need_more) break;
    if (start == FrameStart::skipped) continue;
    BinaryOutput o;
    o.groups = buffer_[pos + 1];
    bool malformed = (o.groups & 0x80) != 0 || o.groups == 0;
    std::size_t at = pos + 2;
    bool need_more = false;
    for (int g = 0; g < kGroupCount && !malformed; ++g) {
      if ((o.groups & (1u << g)) == 0) continue;
      if (at + 2 > n) {
        need_more = true;
        break;
      }
      const auto mask = wire::get_le<std::uint16_t>(buffer_.data() + at);
      for (int bit = 0; bit < 16; ++bit)
        if ((mask & (1u << bit)) != 0 && field_bytes(g, bit) == 0) malformed = true;
      o.fields[static_cast<std::size_t>(g)] = mask;
      at += 2;
    }
    if (malformed) {
      skip_byte(pos, &DecoderCounters::other_errors);
      continue;
    }
    if (need_more) break;
    const std::size_t len = packet_bytes(o);
    if (pos + len > n) break;
    if (crc16(std::span<const std::uint8_t>(buffer_.data() + pos + 1, len - 1)) != 0) {
      skip_byte(pos, &DecoderCounters::checksum_errors);
      continue;
    }
    ++counters_.frames;
    // The IMU fields, wherever the packet carries them.
    DecodedSample d;
    bool imu = false;
    const std::uint8_t* p = buffer_.data() + at;
    auto vec3 = [](const std::uint8_t* q) {
      return Vec3(wire::get_le<float>(q), wire::get_le<float>(q + 4), wire::get_le<float>(q + 8));
    };
    constexpr double kDegToRad = 1.0 / kRadToDeg;
    for (int g = 0; g < kGroupCount; ++g) {
      if ((o.groups & (1u << g)) == 0) continue;
      for (int bit = 0; bit < 16; ++bit) {
        if ((o.fields[static_cast<std::size_t>(g)] & (1u << bit)) == 0) continue;
        if ((g == kCommon || g == kTime) && bit == 0) {
          d.t_ns = static_cast<TimeNs>(wire::get_le<std::uint64_t>(p));
          d.has_time = true;
        } else if ((g == kCommon && bit == 5) || (g == kImu && bit == 10)) {
          d.gyro_rad_s = vec3(p), imu = true;
        } else if ((g == kCommon && bit == 8) || (g == kImu && bit == 9)) {
          d.accel_m_s2 = vec3(p), imu = true;
        } else if (g == kCommon && bit == 11) {
          d.delta_theta_rad = vec3(p + 4) * kDegToRad;
          d.delta_velocity_m_s = vec3(p + 16);
        } else if (g == kImu && bit == 6) {
          d.delta_theta_rad = vec3(p + 4) * kDegToRad;
        } else if (g == kImu && bit == 7) {
          d.delta_velocity_m_s = vec3(p);
        } else if ((g == kImu && bit == 11) && wire::get_le<std::uint16_t>(p) != 0) {
          d.status |= kStatusSaturated;
        }
        p += field_bytes(g, bit);
      }
    }
    if (imu) {
      ++counters_.samples;
      if (on_sample) on_sample(d);
    }
    pos += len;
  }
  return pos;
}

}  // namespace imuemu::drivers::vectornav
