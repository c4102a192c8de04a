// sbgECom framing, the logs an ELLIPSE sends, and their decoder. Sources and
// conventions in sbg.hpp.
#include "drivers/protocols/sbg.hpp"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>

#include "core/aiding/calendar.hpp"
#include "core/attitude.hpp"
#include "drivers/gnss_fix.hpp"
#include "drivers/protocols/sbg_device.hpp"
#include "drivers/protocols/wire_bytes.hpp"

namespace imuemu::drivers::sbg {

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kRadToDeg = 180.0 / kPi;
constexpr std::int64_t kNsPerWeek = 604'800LL * 1'000'000'000LL;
constexpr std::int64_t kGpsEpochPosixNs = 315'964'800LL * 1'000'000'000LL;

// [L] payload sizes of what this device writes (the ...ReadFromStream
// functions' fields, the optional tails included where noted).
constexpr std::array<OutputInfo, kOutputCount> kOutputs{{
    {kClassLog0, kLogStatus, "status", 27, false},      // + uptime (4) + cpuUsage (1)
    {kClassLog0, kLogUtcTime, "utcTime", 21, false},    // without the clock error tail
    {kClassLog0, kLogImuData, "imuData", 58, false},
    {kClassLog0, kLogImuShort, "imuShort", 32, false},
    {kClassLog1, kLog1FastImu, "imuFast", 18, false},
    {kClassLog0, kLogMag, "mag", 30, false},
    {kClassLog0, kLogEkfEuler, "ekfEuler", 40, false},  // + declination / inclination
    {kClassLog0, kLogEkfQuat, "ekfQuat", 44, false},    // + declination / inclination
    {kClassLog0, kLogEkfNav, "ekfNav", 72, true},
    {kClassLog0, kLogGps1Vel, "gps1Vel", 44, true},
    {kClassLog0, kLogGps1Pos, "gps1Pos", 62, true},     // + numSvUsed .. diffAge, numSvTracked, statusExt
}};

struct RestRate {
  std::uint16_t mode;
  const char* name;
};
// The REST API's rate names: a period, "disabled" or "newData" / "pps".
constexpr std::array<RestRate, 16> kRestRates{{{kModeDisabled, "disabled"},
                                               {kMode1Ms, "1ms"},
                                               {kMode2Ms, "2ms"},
                                               {kMode4Ms, "4ms"},
                                               {1, "5ms"},
                                               {2, "10ms"},
                                               {4, "20ms"},
                                               {5, "25ms"},
                                               {8, "40ms"},
                                               {10, "50ms"},
                                               {20, "100ms"},
                                               {40, "200ms"},
                                               {100, "500ms"},
                                               {200, "1000ms"},
                                               {kModeNewData, "newData"},
                                               {kModePps, "pps"}}};

// Little-endian writer into a fixed buffer.
struct PayloadWriter {
  std::uint8_t* p;
  std::size_t n = 0;
  void u8(std::uint8_t v) { p[n++] = v; }
  void u16(std::uint16_t v) { wire::put_le<std::uint16_t>(p + n, v), n += 2; }
  void i16(std::int16_t v) { wire::put_le<std::int16_t>(p + n, v), n += 2; }
  void u32(std::uint32_t v) { wire::put_le<std::uint32_t>(p + n, v), n += 4; }
  void i32(std::int32_t v) { wire::put_le<std::int32_t>(p + n, v), n += 4; }
  void f(double v) { wire::put_le<float>(p + n, static_cast<float>(wire::to_wire_float<float>(v).value)), n += 4; }
  void d(double v) { wire::put_le<double>(p + n, wire::to_wire_float<double>(v).value), n += 8; }
  void f3(const double* v) { f(v[0]), f(v[1]), f(v[2]); }
};

// A value scaled to a fixed-point field of type T, saturated at the type's
// limits; NaN -> 0. `clipped` tells whether it was.
template <class T>
T fixed(double v, double scale, bool& clipped) {
  if (std::isnan(v)) {
    clipped = true;
    return 0;
  }
  const double x = std::round(v * scale);
  constexpr double lo = static_cast<double>(std::numeric_limits<T>::min());
  constexpr double hi = static_cast<double>(std::numeric_limits<T>::max());
  if (x > hi) return clipped = true, std::numeric_limits<T>::max();
  if (x < lo) return clipped = true, std::numeric_limits<T>::min();
  return static_cast<T>(x);
}

void copy3(const Vec3& v, double* to) { to[0] = v.x(), to[1] = v.y(), to[2] = v.z(); }

// [L] sbgEComLogEkf.c: EKF_EULER and EKF_QUAT are the same log but for the
// attitude after the time stamp (roll, pitch, yaw or the quaternion w, x, y,
// z): then the Euler angles' standard deviations, the solution status and
// the magnetic declination / inclination.
void write_ekf_attitude_log(PayloadWriter& w, const Measurements& m, std::span<const double> attitude) {
  w.u32(m.time_stamp_us);
  for (const double a : attitude) w.f(a);
  w.f3(m.euler_sigma_rad);
  w.u32(m.solution_status);
  w.f(m.mag_declination_rad);
  w.f(m.mag_inclination_rad);
}

bool all_finite_within(const double* v, double limit) {
  for (int i = 0; i < 3; ++i)
    if (!std::isfinite(v[i]) || std::fabs(v[i]) > limit) return false;
  return true;
}

}  // namespace

std::uint16_t crc16(std::span<const std::uint8_t> bytes) noexcept {
  std::uint16_t crc = 0;
  for (const std::uint8_t b : bytes) {
    crc = static_cast<std::uint16_t>(crc ^ b);
    for (int i = 0; i < 8; ++i) crc = static_cast<std::uint16_t>((crc & 1u) != 0 ? (crc >> 1) ^ 0x8408 : crc >> 1);
  }
  return crc;
}

void append_frame(std::uint8_t msg, std::uint8_t cls, std::span<const std::uint8_t> payload,
                  std::vector<std::uint8_t>& out) {
  const std::size_t n = std::min(payload.size(), kMaxPayloadBytes);
  out.push_back(kSync1);
  out.push_back(kSync2);
  const std::size_t crc_from = out.size();
  out.push_back(msg);
  out.push_back(cls);
  out.push_back(static_cast<std::uint8_t>(n & 0xFF));
  out.push_back(static_cast<std::uint8_t>(n >> 8));
  out.insert(out.end(), payload.begin(), payload.begin() + static_cast<std::ptrdiff_t>(n));
  const std::uint16_t crc = crc16(std::span<const std::uint8_t>(out.data() + crc_from, out.size() - crc_from));
  out.push_back(static_cast<std::uint8_t>(crc & 0xFF));  // [L] LSB first
  out.push_back(static_cast<std::uint8_t>(crc >> 8));
  out.push_back(kEtx);
}

bool valid_output_mode(std::uint16_t mode) noexcept {
  switch (mode) {
    case kModeDisabled: case 1: case 2: case 4: case 5: case 8: case 10: case 20: case 40: case 100: case 200:
    case kMode1Ms: case kMode2Ms: case kMode4Ms: case kModePps: case kModeNewData: case kModeHighFreqLoop:
      return true;
    default: return false;
  }
}

const OutputInfo& output_info(int output) noexcept { return kOutputs[static_cast<std::size_t>(output)]; }

int output_of(std::uint8_t cls, std::uint8_t msg) noexcept {
  for (int i = 0; i < kOutputCount; ++i)
    if (kOutputs[static_cast<std::size_t>(i)].cls == cls && kOutputs[static_cast<std::size_t>(i)].msg == msg) return i;
  return -1;
}

const char* rest_rate_name(std::uint16_t mode) noexcept {
  for (const RestRate& r : kRestRates)
    if (r.mode == mode) return r.name;
  return nullptr;
}

int rest_rate_mode(std::string_view name) noexcept {
  for (const RestRate& r : kRestRates)
    if (name == r.name) return r.mode;
  return -1;
}

ModelTraits traits_of(SbgModel model) noexcept {
  // ELLIPSE datasheet: gyroscopes +-450 deg/s, accelerometers +-40 g (the
  // "G4A3" part numbers).
  const double gyro = 450.0 / kRadToDeg, accel = 40.0 * 9.80665;
  return {model != SbgModel::ellipse_a, gyro, accel};
}

bool model_has(SbgModel model, int output) noexcept {
  return output >= 0 && output < kOutputCount && (!output_info(output).ins_only || traits_of(model).ins);
}

int output_named(std::string_view name) noexcept {
  for (int i = 0; i < kOutputCount; ++i)
    if (name == output_info(i).rest_name) return i;
  return -1;
}

const char* rest_rate_of(int output, std::uint16_t mode) noexcept {
  if (output == kOutFastImu && mode == kModeHighFreqLoop) return "1ms";
  return rest_rate_name(mode);
}

int rest_mode_of(int output, std::string_view rate) noexcept {
  const int mode = rest_rate_mode(rate);
  if (output != kOutFastImu) return mode;
  if (mode == kMode1Ms) return kModeHighFreqLoop;
  return mode == kModeDisabled ? mode : -1;
}

StreamConfig power_up_config(const SbgDeviceConfig& config) {
  StreamConfig c = factory_config(config);
  // "NAME=RATE,NAME=RATE": the REST API's names and rates, as a driver posts
  // them to /api/v1/settings before /api/v1/settings/save.
  std::string_view rest = config.saved_outputs;
  while (!rest.empty()) {
    const std::size_t comma = rest.find(',');
    const std::string_view pair = rest.substr(0, comma);
    rest = comma == std::string_view::npos ? std::string_view() : rest.substr(comma + 1);
    if (pair.empty()) continue;
    const std::size_t equals = pair.find('=');
    const std::string_view name = pair.substr(0, equals);
    const std::string_view rate = equals == std::string_view::npos ? std::string_view() : pair.substr(equals + 1);
    const int output = output_named(name);
    const int mode = output < 0 ? -1 : rest_mode_of(output, rate);
    if (equals == std::string_view::npos || output < 0 || !model_has(config.model, output) || mode < 0)
      throw std::invalid_argument(
          "saved output '" + std::string(pair) + "': " +
          (equals == std::string_view::npos ? std::string("expected NAME=RATE")
           : output < 0                     ? "no output message '" + std::string(name) + "'"
           : !model_has(config.model, output) ? "this model has no " + std::string(name)
                                              : "'" + std::string(rate) + "' is not a rate " + std::string(name) +
                                                    " takes (5ms ... 1000ms, newData, pps, disabled; imuFast: 1ms)"));
    c.modes[static_cast<std::size_t>(output)] = static_cast<std::uint16_t>(mode);
  }
  return c;
}

std::optional<std::string> saved_outputs_problem(const SbgDeviceConfig& config) {
  try {
    (void)power_up_config(config);
  } catch (const std::invalid_argument& e) {
    return std::string(e.what());
  }
  return std::nullopt;
}

StreamConfig factory_config(const SbgDeviceConfig& config) {
  StreamConfig c;
  if (!config.outputs_at_power_up) return c;
  // The factory configuration this emulator uses (docs/sbg-device.md): the
  // logs ArduPilot's and PX4's drivers read (configured beforehand with
  // sbgCenter on a real unit), at rates that fit the ELLIPSE's factory
  // 115200 baud below 70 % (7821 B/s on an INS: 68 %).
  c.modes[kOutStatus] = 200;        // 1 Hz
  c.modes[kOutUtcTime] = 40;        // 5 Hz
  c.modes[kOutImuShort] = 4;        // 50 Hz
  c.modes[kOutMag] = 20;            // 10 Hz
  c.modes[kOutEkfEuler] = 8;        // 25 Hz
  c.modes[kOutEkfQuat] = 8;         // 25 Hz
  if (traits_of(config.model).ins) {
    c.modes[kOutEkfNav] = 8;        // 25 Hz
    c.modes[kOutGps1Vel] = kModeNewData;  // each GNSS epoch (5 Hz)
    c.modes[kOutGps1Pos] = kModeNewData;
  }
  return c;
}

std::size_t write_log_payload(int output, const Measurements& m, std::uint8_t* buf) noexcept {
  PayloadWriter w{buf};
  switch (output) {
    case kOutStatus: {
      // [L] sbgEComLogStatus.h: general status (power, settings, temperature,
      // CPU ok), com status (port A valid, rx / tx ok), aiding status.
      w.u32(m.time_stamp_us);
      w.u16(0x0001 | 0x0002 | 0x0004 | 0x0008 | 0x0010 | 0x0040);
      w.u16(0);                                  // comStatus2
      w.u32((1u << 0) | (1u << 5) | (1u << 6));  // PORTA_VALID, PORTA_RX_OK, PORTA_TX_OK
      w.u32(m.aiding_status);
      w.u32(0);                                  // reserved2
      w.u16(0);                                  // reserved3
      w.u32(m.uptime_s);
      w.u8(20);                                  // cpuUsage %
      break;
    }
    case kOutUtcTime: {
      // [L] sbgEComLogUtc.c: clock state in bits 1-4, UTC status in bits 6-9;
      // bit 0 a stable clock input (PPS), bit 5 UTC synchronised.
      const std::uint16_t status = m.time_valid ? static_cast<std::uint16_t>(0x0001 | (3u << 1) | 0x0020 | (2u << 6))
                                                : static_cast<std::uint16_t>(1u << 1);  // free running, UTC invalid
      w.u32(m.time_stamp_us);
      w.u16(status);
      w.u16(m.utc_year);
      w.u8(static_cast<std::uint8_t>(m.utc_month));
      w.u8(static_cast<std::uint8_t>(m.utc_day));
      w.u8(static_cast<std::uint8_t>(m.utc_hour));
      w.u8(static_cast<std::uint8_t>(m.utc_minute));
      w.u8(static_cast<std::uint8_t>(m.utc_second));
      w.i32(m.utc_nanosecond);
      w.u32(m.gps_tow_ms);
      break;
    }
    case kOutImuData:
      w.u32(m.time_stamp_us);
      w.u16(m.imu_status);
      w.f3(m.accel_m_s2);
      w.f3(m.gyro_rad_s);
      w.f(m.temperature_c);
      w.f3(m.dvel_rate_m_s2);     // [L] "delta velocity in m/s^2 (same as accelerometers)"
      w.f3(m.dtheta_rate_rad_s);  // [L] "delta angle in rad/s (same as gyroscopes)"
      break;
    case kOutImuShort: {
      std::uint16_t status = m.imu_status;
      bool clipped = false;
      bool high = false;
      for (const double r : m.dtheta_rate_rad_s)
        if (!std::isfinite(r) || std::fabs(r) > 2147483647.0 / kImuShortGyroScaleStd) high = true;
      if (high) status |= kImuGyrosUseHighScale;
      const double gyro_scale = high ? kImuShortGyroScaleHigh : kImuShortGyroScaleStd;
      std::int32_t dv[3], dt[3];
      for (int i = 0; i < 3; ++i) {
        dv[i] = fixed<std::int32_t>(m.dvel_rate_m_s2[i], kImuShortAccelScale, clipped);
        dt[i] = fixed<std::int32_t>(m.dtheta_rate_rad_s[i], gyro_scale, clipped);
      }
      if (clipped) status &= static_cast<std::uint16_t>(~(kImuAccelsInRange | kImuGyrosInRange));
      w.u32(m.time_stamp_us);
      w.u16(status);
      for (const std::int32_t v : dv) w.i32(v);
      for (const std::int32_t v : dt) w.i32(v);
      bool t_clipped = false;
      w.i16(fixed<std::int16_t>(m.temperature_c, kImuShortTempScale, t_clipped));
      break;
    }
    case kOutFastImu: {
      // [L] sbgEComLogImu.c: accelerations 0.01 m/s^2, rates 0.001 rad/s (int16).
      std::uint16_t status = m.imu_status;
      bool accel_clipped = false, gyro_clipped = false;
      std::int16_t a[3], g[3];
      for (int i = 0; i < 3; ++i) {
        a[i] = fixed<std::int16_t>(m.accel_m_s2[i], 100.0, accel_clipped);
        g[i] = fixed<std::int16_t>(m.gyro_rad_s[i], 1000.0, gyro_clipped);
      }
      if (accel_clipped) status &= static_cast<std::uint16_t>(~kImuAccelsInRange);
      if (gyro_clipped) status &= static_cast<std::uint16_t>(~kImuGyrosInRange);
      w.u32(m.time_stamp_us);
      w.u16(status);
      for (const std::int16_t v : a) w.i16(v);
      for (const std::int16_t v : g) w.i16(v);
      break;
    }
    case kOutMag:
      w.u32(m.time_stamp_us);
      w.u16(m.mag_status);
      w.f3(m.mag);
      w.f3(m.accel_m_s2);
      break;
    case kOutEkfEuler: write_ekf_attitude_log(w, m, m.euler_rad); break;
    case kOutEkfQuat: write_ekf_attitude_log(w, m, m.quat_wxyz); break;
    case kOutEkfNav:
      w.u32(m.time_stamp_us);
      w.f3(m.vel_ned_m_s);
      w.f3(m.vel_sigma_m_s);
      w.d(m.lat_deg);
      w.d(m.lon_deg);
      w.d(m.alt_msl_m);
      w.f(m.undulation_m);
      w.f3(m.pos_sigma_m);
      w.u32(m.solution_status);
      break;
    case kOutGps1Vel: {
      // [L] sbgEComLogGnssVel.c: status in bits 0-5 (0 computed, 1 insufficient
      // observations), type in bits 6-11 (0 none, 2 Doppler).
      const std::uint32_t status = m.gnss_fix ? (0u | (2u << 6)) : 1u;
      w.u32(m.time_stamp_us);
      w.u32(status);
      w.u32(m.gps_tow_ms);
      w.f3(m.vel_ned_m_s);
      w.f3(m.gnss_vel_acc_m_s);
      w.f(m.gnss_course_deg);
      w.f(m.gnss_course_acc_deg);
      break;
    }
    case kOutGps1Pos: {
      // [L] sbgEComLogGnssPos.c: status bits 0-5, type bits 6-11 (2 single
      // point), signals from bit 12 (GPS L1 used).
      const std::uint32_t status = m.gnss_fix ? (0u | (2u << 6) | (1u << 12)) : 1u;
      w.u32(m.time_stamp_us);
      w.u32(status);
      w.u32(m.gps_tow_ms);
      w.d(m.lat_deg);
      w.d(m.lon_deg);
      w.d(m.alt_msl_m);
      w.f(m.undulation_m);
      w.f3(m.gnss_pos_acc_m);
      w.u8(m.gnss_sats);
      w.u16(0xFFFF);  // baseStationId: no differential corrections
      w.u16(0xFFFF);  // differentialAge
      w.u8(m.gnss_sats);  // numSvTracked
      w.u32(0);           // statusExt: no interference / spoofing information
      break;
    }
    default: break;
  }
  return w.n;
}

void append_log(int output, const Measurements& m, std::vector<std::uint8_t>& out) {
  std::uint8_t buf[128];
  const std::size_t n = write_log_payload(output, m, buf);
  const OutputInfo& info = output_info(output);
  append_frame(info.msg, info.cls, std::span<const std::uint8_t>(buf, n), out);
}

// ------------------------------------------------------------------ encoder

Encoder::Encoder(const StreamEncoderOptions& options)
    : DeviceEncoderBase(options, kMainLoopHz, power_up_config(options.sbg)), traits_(traits_of(options.sbg.model)) {
  if (options_.sbg.answers_commands) install_device(std::make_unique<Device>(options_.sbg));
}

Encoder::~Encoder() = default;

Encoder& Encoder::operator=(const Encoder& other) {
  // As the copy constructor: a fresh device of the same options.
  if (this != &other) *this = Encoder(other.options_);
  return *this;
}

Encoder& Encoder::operator=(Encoder&& other) = default;

// The clock of an output in `mode`: the 200 Hz main loop over N, the 1 kHz
// loop over 1 / 2 / 4 (1001, 1002, 1004, 20001). New data: every sample for
// the IMU logs, each 5 Hz GNSS epoch for GPS1_*, the main loop otherwise.
// Disabled and PPS (no PPS line is emulated): never.
Encoder::Schedule Encoder::schedule_of(int output, std::uint16_t mode) noexcept {
  switch (mode) {
    case kModeDisabled: case kModePps: return {0, 0, false};
    case kMode1Ms: case kMode2Ms: case kMode4Ms: return {1000, mode - 1000u, false};
    case kModeHighFreqLoop: return {1000, 1, false};
    case kModeNewData:
      if (output == kOutGps1Vel || output == kOutGps1Pos) return {5, 1, false};
      if (output == kOutImuData || output == kOutImuShort || output == kOutFastImu || output == kOutMag)
        return {0, 0, true};
      return {kMainLoopHz, 1, false};
    default: return {kMainLoopHz, mode, false};
  }
}

// Sample k is due when it crosses a multiple of the mode's period on its
// clock; a scene slower than the output sends every sample.
bool Encoder::due(std::uint64_t k, int output, std::uint16_t mode) const noexcept {
  const Schedule s = schedule_of(output, mode);
  return s.every_sample || due_on_grid(k, s.rate_per_s, s.divisor);
}

Measurements Encoder::measurements_of(const ImuFrameInput& s) const {
  Measurements m;
  const TimeNs since_ns = since_power_up_ns(s);
  m.time_stamp_us = static_cast<std::uint32_t>(static_cast<std::uint64_t>(since_ns / 1000) & 0xFFFFFFFFu);
  m.uptime_s = static_cast<std::uint32_t>(std::min<std::int64_t>(since_ns / 1'000'000'000LL, 0xFFFFFFFFLL));
  copy3(s.accel_m_s2, m.accel_m_s2);
  copy3(s.gyro_rad_s, m.gyro_rad_s);
  if (s.has_temperature) m.temperature_c = s.temperature_c;
  // [L] IMU status: communication, built-in tests, in range; "in range"
  // cleared when an axis is beyond the model's range, not finite, or the
  // emulated sensor saturated.
  m.imu_status = static_cast<std::uint16_t>(kImuComOk | kImuStatusBit | kImuAccelXyzBits | kImuGyroXyzBits);
  const bool saturated = (s.status & kStatusSaturated) != 0;
  if (!saturated && all_finite_within(m.accel_m_s2, traits_.accel_range_m_s2)) m.imu_status |= kImuAccelsInRange;
  if (!saturated && all_finite_within(m.gyro_rad_s, traits_.gyro_range_rad_s)) m.imu_status |= kImuGyrosInRange;
  const double period_s = static_cast<double>(s.period_ns) * 1e-9;
  for (int i = 0; i < 3; ++i) {
    m.dvel_rate_m_s2[i] = period_s > 0 ? s.delta_velocity_m_s[i] / period_s : m.accel_m_s2[i];
    m.dtheta_rate_rad_s[i] = period_s > 0 ? s.delta_theta_rad[i] / period_s : m.gyro_rad_s[i];
  }

  // Attitude: R_s^n (identity when the producer has none).
  const Mat3& r_sn = s.sensor_to_ned;
  const attitude::HeadingPitchRoll hpr = attitude::hpr_from_rotation(r_sn);
  m.euler_rad[0] = hpr.roll_rad;
  m.euler_rad[1] = hpr.pitch_rad;
  m.euler_rad[2] = hpr.heading_rad;
  Eigen::Quaterniond q(r_sn);
  q.normalize();
  if (q.w() < 0.0) q.coeffs() *= -1.0;
  m.quat_wxyz[0] = q.w(), m.quat_wxyz[1] = q.x(), m.quat_wxyz[2] = q.y(), m.quat_wxyz[3] = q.z();
  const double* ref = options_.sbg.mag_reference_ned_gauss;
  const Vec3 mag_ned(ref[0], ref[1], ref[2]);
  copy3(r_sn.transpose() * mag_ned, m.mag);
  m.mag_status = 0x01FF;  // [L] mag / accel X Y Z BIT, both in range, calibration ok
  m.mag_declination_rad = std::atan2(mag_ned.y(), mag_ned.x());
  m.mag_inclination_rad = std::atan2(mag_ned.z(), std::hypot(mag_ned.x(), mag_ned.y()));

  // [F] ELLIPSE datasheet accuracies (1 sigma): roll / pitch 0.1 deg, heading
  // 0.8 deg magnetic (ELLIPSE-A) or 0.2 deg with GNSS (ELLIPSE-N / -D).
  constexpr double kDeg = 1.0 / kRadToDeg;
  m.euler_sigma_rad[0] = m.euler_sigma_rad[1] = 0.1 * kDeg;
  m.euler_sigma_rad[2] = 0.8 * kDeg;
  m.solution_status = kSolModeAhrs | kSolAttitudeValid | kSolHeadingValid | kSolVertRefUsed | kSolMagRefUsed |
                      kSolAlignValid;
  m.aiding_status = 1u << 8;  // SBG_ECOM_AIDING_MAG_RECV

  if (traits_.ins) {
    const GnssFix fix = fix_from_frame(s, options_.gnss);
    if (fix.time_valid && fix.gps_time_ns >= 0) {
      m.time_valid = true;
      m.gps_tow_ms = static_cast<std::uint32_t>((fix.gps_time_ns % kNsPerWeek) / 1'000'000);
      const aiding::UtcCalendar c = aiding::calendar_from_posix_ns(
          fix.gps_time_ns + kGpsEpochPosixNs - std::int64_t{fix.gps_minus_utc_s} * 1'000'000'000LL);
      m.utc_year = static_cast<std::uint16_t>(std::clamp(c.year, 0, 65535));
      m.utc_month = static_cast<std::int8_t>(c.month);
      m.utc_day = static_cast<std::int8_t>(c.day);
      m.utc_hour = static_cast<std::int8_t>(c.hour);
      m.utc_minute = static_cast<std::int8_t>(c.minute);
      m.utc_second = static_cast<std::int8_t>(c.second);
      m.utc_nanosecond = static_cast<std::int32_t>(c.nanosecond);
      m.aiding_status |= 1u << 3;  // GPS1_UTC_RECV
    }
    m.gnss_fix = s.has_navigation && (fix.fix_type == GnssFixType::fix_3d || fix.fix_type == GnssFixType::fix_2d);
    m.gnss_sats = static_cast<std::uint8_t>(std::clamp(fix.satellites, 0, 255));
    m.undulation_m = fix.geoid_separation_m;
    if (s.has_navigation) {
      m.lat_deg = s.latitude_rad * kRadToDeg;
      m.lon_deg = s.longitude_rad * kRadToDeg;
      m.alt_msl_m = s.height_m - fix.geoid_separation_m;
      copy3(s.velocity_ned_m_s, m.vel_ned_m_s);
    }
    m.gnss_pos_acc_m[0] = m.gnss_pos_acc_m[1] = fix.horizontal_accuracy_m;
    m.gnss_pos_acc_m[2] = fix.vertical_accuracy_m;
    for (double& a : m.gnss_vel_acc_m_s) a = fix.speed_accuracy_m_s;
    const double ground_speed = std::hypot(m.vel_ned_m_s[0], m.vel_ned_m_s[1]);
    double course = std::atan2(m.vel_ned_m_s[1], m.vel_ned_m_s[0]) * kRadToDeg;
    if (course < 0.0) course += 360.0;
    m.gnss_course_deg = course;
    m.gnss_course_acc_deg = ground_speed > 0.1 ? std::min(180.0, fix.speed_accuracy_m_s / ground_speed * kRadToDeg) : 180.0;
    if (m.gnss_fix) {
      m.solution_status = kSolModeNavPosition | kSolAttitudeValid | kSolHeadingValid | kSolVelocityValid |
                          kSolPositionValid | kSolVertRefUsed | kSolMagRefUsed | kSolGps1VelUsed | kSolGps1PosUsed |
                          kSolAlignValid;
      m.euler_sigma_rad[2] = 0.2 * kDeg;
      m.aiding_status |= (1u << 0) | (1u << 1);  // GPS1_POS_RECV, GPS1_VEL_RECV
      // [F] ELLIPSE-N datasheet: position 1.2 m horizontal / 1.5 m vertical
      // (single point), velocity 0.03 m/s.
      m.pos_sigma_m[0] = m.pos_sigma_m[1] = std::max(1.2, fix.horizontal_accuracy_m);
      m.pos_sigma_m[2] = std::max(1.5, fix.vertical_accuracy_m);
      for (double& v : m.vel_sigma_m_s) v = std::max(0.03, fix.speed_accuracy_m_s);
    }
  }
  return m;
}

void Encoder::encode(const ImuFrameInput& sample, std::vector<std::uint8_t>& out) {
  const StreamConfig* c = &published_or_startup_config();
  start_sample(sample);
  Measurements m = measurements_of(sample);
  if (device_) device_->publish_measurements(m);
  for (int i = 0; i < kOutputCount; ++i) {
    const std::uint16_t mode = c->modes[static_cast<std::size_t>(i)];
    if (mode == kModeDisabled || !model_has(options_.sbg.model, i) || !due(sample.sample_counter, i, mode)) continue;
    IncrementSums& d = increments_[static_cast<std::size_t>(i)];
    if ((i == kOutImuData || i == kOutImuShort) && d.dtime_s > 0.0) {
      // [L] the increments over the output's interval, as mean rates.
      copy3(d.dvel_m_s / d.dtime_s, m.dvel_rate_m_s2);
      copy3(d.dtheta_rad / d.dtime_s, m.dtheta_rate_rad_s);
    }
    d = IncrementSums{};
    append_log(i, m, out);
  }
}

std::size_t Encoder::max_bytes_per_sample() const {
  std::size_t n = 0;
  for (const OutputInfo& o : kOutputs) n += o.payload_bytes + kFrameOverheadBytes;
  return n;
}

double Encoder::configured_bytes_per_second(double sample_rate_hz) const {
  // Each log this model has, in its mode now: its frame times how often it goes.
  const StreamConfig& c = published_or_startup_config();
  double bytes = 0.0;
  for (int i = 0; i < kOutputCount; ++i) {
    if (!model_has(options_.sbg.model, i)) continue;
    const Schedule s = schedule_of(i, c.modes[static_cast<std::size_t>(i)]);
    const double per_second = s.every_sample ? sample_rate_hz : sent_per_second(s.rate_per_s, s.divisor, sample_rate_hz);
    bytes += per_second * static_cast<double>(output_info(i).payload_bytes + kFrameOverheadBytes);
  }
  return bytes;
}

StreamFrameLayout Encoder::frame_layout(std::span<const std::uint8_t> frame) const {
  StreamFrameLayout l;
  if (frame.size() < kFrameOverheadBytes || frame[0] != kSync1 || frame[1] != kSync2)
    return StreamFrameLayout{frame.size()};
  const std::size_t len = wire::get_le<std::uint16_t>(frame.data() + 4);
  if (len + kFrameOverheadBytes > frame.size()) return StreamFrameLayout{frame.size()};
  l.frame_bytes = len + kFrameOverheadBytes;
  l.length_offset = 4;
  l.length_bytes = 2;
  l.checksum_offset = 6 + len;
  l.checksum_bytes = 2;
  return l;
}

// ------------------------------------------------------------------ decoder

std::size_t Decoder::decode_buffer(const SampleCallback& on_sample) {
  std::size_t pos = 0;
  const std::size_t n = buffer_.size();
  constexpr std::uint8_t kSync[] = {kSync1, kSync2};
  while (pos < n) {
    const FrameStart start = frame_start_at(pos, kSync, sizeof kSync);
    if (start == FrameStart::need_more) break;
    if (start == FrameStart::skipped) continue;
    if (pos + 6 > n) break;
    const std::size_t len = wire::get_le<std::uint16_t>(buffer_.data() + pos + 4);
    if (len > kMaxPayloadBytes) {
      skip_byte(pos, &DecoderCounters::other_errors);
      continue;
    }
    if (pos + len + kFrameOverheadBytes > n) break;
    const std::uint8_t* f = buffer_.data() + pos;
    const std::uint16_t crc = wire::get_le<std::uint16_t>(f + 6 + len);
    if (f[8 + len] != kEtx) {
      skip_byte(pos, &DecoderCounters::other_errors);
      continue;
    }
    if (crc16(std::span<const std::uint8_t>(f + 2, len + 4)) != crc) {
      skip_byte(pos, &DecoderCounters::checksum_errors);
      continue;
    }
    ++counters_.frames;
    const std::uint8_t msg = f[2], cls = f[3];
    const std::uint8_t* p = f + 6;
    DecodedSample d;
    bool imu = false;
    auto vec3f = [](const std::uint8_t* q) {
      return Vec3(wire::get_le<float>(q), wire::get_le<float>(q + 4), wire::get_le<float>(q + 8));
    };
    std::uint16_t status = 0;
    if (cls == kClassLog0 && msg == kLogImuData && len >= 58) {
      status = wire::get_le<std::uint16_t>(p + 4);
      d.accel_m_s2 = vec3f(p + 6);
      d.gyro_rad_s = vec3f(p + 18);
      imu = true;
    } else if (cls == kClassLog0 && msg == kLogImuShort && len >= 32) {
      status = wire::get_le<std::uint16_t>(p + 4);
      const double gs = (status & kImuGyrosUseHighScale) != 0 ? kImuShortGyroScaleHigh : kImuShortGyroScaleStd;
      for (int i = 0; i < 3; ++i) {
        d.accel_m_s2[i] = wire::get_le<std::int32_t>(p + 6 + 4 * i) / kImuShortAccelScale;
        d.gyro_rad_s[i] = wire::get_le<std::int32_t>(p + 18 + 4 * i) / gs;
      }
      imu = true;
    } else if (cls == kClassLog1 && msg == kLog1FastImu && len >= 18) {
      status = wire::get_le<std::uint16_t>(p + 4);
      for (int i = 0; i < 3; ++i) {
        d.accel_m_s2[i] = wire::get_le<std::int16_t>(p + 6 + 2 * i) * 0.01;
        d.gyro_rad_s[i] = wire::get_le<std::int16_t>(p + 12 + 2 * i) * 0.001;
      }
      imu = true;
    }
    if (imu) {
      d.t_ns = static_cast<TimeNs>(wire::get_le<std::uint32_t>(p)) * 1000;
      d.has_time = true;
      if ((status & (kImuAccelsInRange | kImuGyrosInRange)) != (kImuAccelsInRange | kImuGyrosInRange))
        d.status |= kStatusSaturated;
      ++counters_.samples;
      if (on_sample) on_sample(d);
    }
    pos += len + kFrameOverheadBytes;
  }
  return pos;
}

}  // namespace imuemu::drivers::sbg
