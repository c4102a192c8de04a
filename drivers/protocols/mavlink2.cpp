// MAVLink 2 encoder/decoder for HIL_SENSOR (#107), HIGHRES_IMU (#105),
// HIL_GPS (#113) and HEARTBEAT (#0).
//
// Sources (read, nothing copied):
//  [G] MAVLink developer guide, "Packet Serialization"
//      (mavlink.io/en/guide/serialization.html): packet format, little-endian
//      fields, field reordering by type size with extensions last, CRC_EXTRA,
//      empty-byte payload truncation, CRC-16/MCRF4XX over everything but the
//      magic byte plus CRC_EXTRA.
//  [X] message_definitions/v1.0/common.xml: HIL_SENSOR, HIGHRES_IMU, HIL_GPS,
//      HIL_SENSOR_UPDATED_FLAGS, MAV_COMPONENT; minimal.xml: HEARTBEAT,
//      MAV_TYPE, MAV_AUTOPILOT, MAV_STATE.
//  [H] MAVLink heartbeat microservice (mavlink.io/en/services/heartbeat.html):
//      components send HEARTBEAT at 1 Hz.
//
// Units and axes: HIL_SENSOR/HIGHRES_IMU x/y/zacc are specific force in
// m/s^2 and x/y/zgyro angular rate in rad/s, "in NED body frame" [X], i.e.
// the MAVLink body frame x forward, y right, z down - the same axes as the
// emulator's body FRD, so the axis conversion is the identity (done
// explicitly in frd_to_mavlink_body()); units are already SI. At rest, level,
// zacc = -9.81 (specific force, as PX4's own IMU drivers report it).
#include "drivers/protocols/mavlink2.hpp"

#include <algorithm>
#include <array>
#include <boost/crc.hpp>
#include <cmath>
#include <limits>
#include <numbers>
#include <optional>

#include "core/aiding/atmosphere.hpp"
#include "core/aiding/sample_index.hpp"
#include "core/aiding/wmm.hpp"
#include "core/time_arith.hpp"
#include "drivers/protocols/mavlink_device.hpp"
#include "drivers/protocols/wire_bytes.hpp"

namespace imuemu::drivers::mavlink2 {

namespace {

using X25Engine = boost::crc_optimal<16, 0x1021, 0xFFFF, 0, true, true>;

// [X] minimal.xml HEARTBEAT: "type ... For other components the component
// type" (MAV_TYPE: "All other components must report a value appropriate for
// their type"): MAV_TYPE_IMU = 40; "autopilot ... Use MAV_AUTOPILOT_INVALID
// for components that are not flight controllers": 8.
constexpr std::uint8_t kMavTypeImu = 40;
constexpr std::uint8_t kMavAutopilotInvalid = 8;
// MAV_STATE (minimal.xml): BOOT "System is booting up", ACTIVE "System is
// active and might be already airborne".
constexpr std::uint8_t kMavStateBoot = 1;
constexpr std::uint8_t kMavStateActive = 4;
constexpr std::uint8_t kMavlinkVersion = 3;  // the dialect <version>; "gets added by protocol"

constexpr TimeNs kHeartbeatPeriodNs = kNsPerSecond;  // [H]

// Payload offsets after [G] field reordering of [X]: time_usec (8 bytes)
// first, then the 13 floats in XML order, then fields_updated, then the
// extension field `id` (extensions keep XML order, after the base fields).
constexpr std::size_t kOffTimeUsec = 0;
constexpr std::size_t kOffAcc = 8;     // xacc, yacc, zacc
constexpr std::size_t kOffGyro = 20;   // xgyro, ygyro, zgyro
constexpr std::size_t kOffMag = 32;    // xmag, ymag, zmag (gauss)
constexpr std::size_t kOffAbsPressure = 44;   // hPa
constexpr std::size_t kOffPressureAlt = 52;   // m
constexpr std::size_t kOffTemperature = 56;
constexpr std::size_t kOffFieldsUpdated = 60;
constexpr std::size_t kOffHilSensorId = 64;   // after u32 fields_updated
constexpr std::size_t kOffHighresId = 62;     // after u16 fields_updated

Vec3 frd_to_mavlink_body(const Vec3& v_frd) { return v_frd; }
Vec3 mavlink_body_to_frd(const Vec3& v_body) { return v_body; }

std::uint16_t packet_checksum(std::span<const std::uint8_t> after_magic, std::uint8_t crc_extra) {
  X25Engine crc;
  crc.process_bytes(after_magic.data(), after_magic.size());
  crc.process_byte(crc_extra);
  return crc.checksum();
}

// time_usec [X] is unsigned microseconds; sample time is int64 ns. Floor to
// the microsecond; times before 0 cannot be represented and are sent as 0.
std::uint64_t time_usec_from_ns(TimeNs t_ns) {
  return t_ns <= 0 ? 0 : static_cast<std::uint64_t>(t_ns / 1000);
}

// Writes one float vector at `at`; returns the fields_updated bits of the
// axes that carry a real value (a NaN axis is sent as 0 with its bit clear:
// the receiver is told that axis did not update). Beyond the float range is
// clamped to +-FLT_MAX (HIL_SENSOR has no saturation flag).
std::uint32_t put_vec3_f32(std::uint8_t* at, const Vec3& v, unsigned first_bit) {
  std::uint32_t updated = 0;
  for (int i = 0; i < 3; ++i) {
    const wire::WireValue w = wire::to_wire_float<float>(v[i]);
    wire::put_le<float>(at + 4 * i, static_cast<float>(w.value));
    if (!w.was_nan) updated |= 1u << (first_bit + static_cast<unsigned>(i));
  }
  return updated;
}

Vec3 get_vec3_f32(const std::uint8_t* at) {
  return {wire::get_le<float>(at), wire::get_le<float>(at + 4), wire::get_le<float>(at + 8)};
}

constexpr double kGaussPerMicrotesla = 0.01;  // 1 G = 1e-4 T = 100 uT
constexpr double kHpaPerPa = 0.01;
constexpr double kKelvinAtZeroCelsius = 273.15;
// A Julian year (365.25 d), the unit of WMM's decimal year.
constexpr double kSecondsPerYear = 365.25 * 86400.0;

// The IMU payload shared by HIL_SENSOR and HIGHRES_IMU up to fields_updated
// (the two share the field order and the fields_updated bits [X]), with the
// sample's barometer and magnetometer readings; returns fields_updated.
std::uint32_t fill_imu_payload(std::uint8_t* p, const ImuFrameInput& sample, const StreamEncoderOptions& options,
                               const Encoder::AidingReading& aiding) {
  wire::put_le<std::uint64_t>(p + kOffTimeUsec, time_usec_from_ns(sample.t_ns));
  std::uint32_t updated = put_vec3_f32(p + kOffAcc, frd_to_mavlink_body(sample.accel_m_s2), 0);
  updated |= put_vec3_f32(p + kOffGyro, frd_to_mavlink_body(sample.gyro_rad_s), 3);
  // A faulted sensor sends no update: PX4's simulator interface publishes
  // accel/gyro only for the fields_updated bits that are set.
  if ((sample.status & kStatusFault) != 0) updated &= ~kUpdatedAccelGyro;
  // The sensor model's temperature when the sample has one, else the
  // configured constant (protocol option temperature_degC), else the
  // barometer's (PX4 takes the baro group with its temperature bit), else
  // none.
  std::optional<double> temperature_c =
      sample.has_temperature ? std::optional<double>(sample.temperature_c) : options.mavlink_temperature_degC;
  if (!temperature_c && aiding.has_pressure) temperature_c = aiding.temperature_k - kKelvinAtZeroCelsius;
  if (aiding.has_field) updated |= put_vec3_f32(p + kOffMag, aiding.field_ut * kGaussPerMicrotesla, 6);
  if (aiding.has_pressure) {
    wire::put_le<float>(p + kOffAbsPressure, static_cast<float>(aiding.pressure_pa * kHpaPerPa));
    updated |= kUpdatedAbsPressure;
  }
  if (aiding.has_pressure_altitude) {
    wire::put_le<float>(p + kOffPressureAlt, static_cast<float>(aiding.pressure_altitude_m));
    updated |= kUpdatedPressureAlt;
  }
  if (temperature_c) {
    const wire::WireValue w = wire::to_wire_float<float>(*temperature_c);
    wire::put_le<float>(p + kOffTemperature, static_cast<float>(w.value));
    if (!w.was_nan) updated |= kUpdatedTemperature;
  }
  return updated;
}

}  // namespace

std::uint16_t crc16_mcrf4xx(std::span<const std::uint8_t> bytes) {
  X25Engine crc;
  crc.process_bytes(bytes.data(), bytes.size());
  return crc.checksum();
}

void Encoder::append_packet(const MessageSpec& message, std::span<const std::uint8_t> payload,
                            std::vector<std::uint8_t>& out) {
  // [G] "Empty-Byte Payload Truncation": trailing zero bytes are not sent,
  // but the first payload byte always is.
  std::size_t len = payload.size();
  while (len > 1 && payload[len - 1] == 0) --len;

  std::array<std::uint8_t, kHeaderBytes + 255 + kChecksumBytes> packet{};
  packet[0] = kMagic;
  packet[1] = static_cast<std::uint8_t>(len);
  packet[2] = 0;  // incompat_flags: unsigned
  packet[3] = 0;  // compat_flags
  packet[4] = sequence_++;
  packet[5] = options_.mavlink_system_id;
  packet[6] = options_.mavlink_component_id;
  packet[7] = static_cast<std::uint8_t>(message.id);
  packet[8] = static_cast<std::uint8_t>(message.id >> 8);
  packet[9] = static_cast<std::uint8_t>(message.id >> 16);
  std::copy_n(payload.begin(), len, packet.begin() + kHeaderBytes);
  const std::uint16_t crc = packet_checksum(
      std::span<const std::uint8_t>(packet.data() + 1, kHeaderBytes - 1 + len), message.crc_extra);
  wire::put_le<std::uint16_t>(packet.data() + kHeaderBytes + len, crc);
  out.insert(out.end(), packet.begin(), packet.begin() + static_cast<std::ptrdiff_t>(kHeaderBytes + len + kChecksumBytes));
}

Encoder::Encoder(const StreamEncoderOptions& options) : options_(options) {
  if (options_.mavlink_answers_commands) device_ = std::make_unique<Device>(options_);
  // The models run at the device's rate, one step per sample (encode()
  // measures every sample, sent or not: no catching up on the emission
  // thread). Their constructors validate the specs (SettingError).
  if (options_.mavlink_baro) {
    aiding::BarometerSpec spec;
    spec.noise_rms_pa = options_.mavlink_baro_noise_rms_pa;
    spec.bias_pa = options_.mavlink_baro_bias_pa;
    spec.seed = options_.aiding_seed;
    barometer_.emplace(spec, options_.nominal_sample_rate_hz, options_.device_name);
  }
  if (options_.mavlink_mag) {
    aiding::MagnetometerSpec spec;
    spec.noise_rms_ut = Vec3::Constant(options_.mavlink_mag_noise_rms_ut);
    spec.seed = options_.aiding_seed;
    magnetometer_.emplace(spec, options_.nominal_sample_rate_hz, options_.device_name);
  }
  pressure_min_pa_ = aiding::isa_at_geopotential(aiding::kIsaMaxGeopotential_m).pressure_pa;
  pressure_max_pa_ = aiding::isa_at_geopotential(aiding::kIsaMinGeopotential_m).pressure_pa;
  // HIL_GPS: the GNSS receivers' fix source (drivers/gnss_fix.hpp) at the
  // HIL_GPS rate, seeded as the barometer and magnetometer (one component,
  // one seed: aiding_seed; stream_protocols.hpp). Its constructor validates
  // the error terms.
  if (options_.mavlink_hil_gps_rate_hz > 0) {
    GnssReceiverConfig gps = options_.gnss;
    gps.errors.seed = options_.aiding_seed;
    gps_source_.emplace(gps, static_cast<double>(options_.mavlink_hil_gps_rate_hz), options_.device_name);
  }
}

Encoder::Encoder(const Encoder& other)
    : options_(other.options_),
      sequence_(other.sequence_),
      next_heartbeat_ns_(other.next_heartbeat_ns_),
      barometer_(other.barometer_),
      magnetometer_(other.magnetometer_),
      reading_counter_(other.reading_counter_),
      reading_(other.reading_),
      next_gps_ns_(other.next_gps_ns_),
      gps_source_(other.gps_source_),
      gps_first_index_(other.gps_first_index_),
      pressure_min_pa_(other.pressure_min_pa_),
      pressure_max_pa_(other.pressure_max_pa_) {
  if (options_.mavlink_answers_commands) device_ = std::make_unique<Device>(options_);
}

Encoder& Encoder::operator=(const Encoder& other) {
  if (this != &other) {
    Encoder fresh(other);
    options_ = fresh.options_;
    sequence_ = fresh.sequence_;
    next_heartbeat_ns_ = fresh.next_heartbeat_ns_;
    device_ = std::move(fresh.device_);
    barometer_ = std::move(fresh.barometer_);
    magnetometer_ = std::move(fresh.magnetometer_);
    reading_counter_ = fresh.reading_counter_;
    reading_ = fresh.reading_;
    next_gps_ns_ = fresh.next_gps_ns_;
    gps_source_ = std::move(fresh.gps_source_);
    gps_first_index_ = fresh.gps_first_index_;
    pressure_min_pa_ = fresh.pressure_min_pa_;
    pressure_max_pa_ = fresh.pressure_max_pa_;
  }
  return *this;
}

const Encoder::AidingReading& Encoder::aiding_reading(const ImuFrameInput& sample) {
  const std::uint64_t k = sample.sample_counter;
  if (reading_counter_ && *reading_counter_ == k) return reading_;  // a second message of the same sample
  reading_ = AidingReading{};
  reading_counter_ = k;
  if (!sample.has_navigation) return reading_;  // a flat scene: no position, no reading
  // Every input is checked against the models' stated domains first, so
  // none of them throws here (the emission thread); a sample outside them
  // is sent without that group (its fields_updated bits clear).
  const auto index_ok = [k](std::uint64_t next) { return k >= next && k - next <= aiding::kMaxSkippedSamples; };
  if (barometer_ && index_ok(barometer_->next_index())) {
    // Geometric height above the geoid Z = h - N, geopotential
    // H = r0 Z / (r0 + Z) (US 1976 Eq. 18; atmosphere.hpp), inside the
    // model's range with a metre to spare.
    const double z_m = sample.height_m - options_.gnss.geoid_separation_m;
    const double h_m = aiding::kIsaEarthRadius_m * z_m / (aiding::kIsaEarthRadius_m + z_m);
    if (std::isfinite(h_m) && h_m > aiding::kIsaMinGeopotential_m + 1.0 && h_m < aiding::kIsaMaxGeopotential_m - 1.0) {
      const aiding::IsaState isa =
          aiding::isa_at_ellipsoidal_height(sample.height_m, options_.gnss.geoid_separation_m);
      const aiding::BarometerSample b = barometer_->measure(k, isa.pressure_pa, isa.temperature_k);
      if (std::isfinite(b.pressure_pa) && std::isfinite(b.temperature_k)) {
        reading_.has_pressure = true;
        reading_.pressure_pa = b.pressure_pa;
        reading_.temperature_k = b.temperature_k;
        // What an altimeter set to 1013.25 hPa reads, within the
        // atmosphere's pressures.
        if (b.pressure_pa > pressure_min_pa_ && b.pressure_pa < pressure_max_pa_) {
          reading_.has_pressure_altitude = true;
          reading_.pressure_altitude_m = aiding::pressure_altitude_m(b.pressure_pa);
        }
      }
    }
  }
  if (magnetometer_ && index_ok(magnetometer_->next_index())) {
    const double year = options_.mavlink_date_at_t0_year + static_cast<double>(sample.t_ns) * 1e-9 / kSecondsPerYear;
    const double epoch = aiding::wmm2025_epoch_year();
    const double lat = sample.latitude_rad;
    if (std::isfinite(year) && year >= epoch && year <= epoch + aiding::kWmmValidYears && std::isfinite(lat) &&
        std::abs(lat) <= 0.5 * std::numbers::pi && std::isfinite(sample.longitude_rad) &&
        sample.height_m >= aiding::kWmmMinHeight_m && sample.height_m <= aiding::kWmmMaxHeight_m &&
        sample.sensor_to_ned.allFinite()) {
      const aiding::MagneticElements field =
          aiding::wmm2025({sample.latitude_rad, sample.longitude_rad, sample.height_m}, year);
      // b^s = (R_s^n)^T b^n (magnetometer.hpp; the sensor axes are the
      // sample's, so the model's own mounting is the identity).
      const aiding::MagnetometerSample m =
          magnetometer_->measure(k, aiding::body_field_ut(sample.sensor_to_ned, field.ned_nt));
      reading_.has_field = m.field_ut.allFinite();
      reading_.field_ut = m.field_ut;
    }
  }
  return reading_;
}

Encoder::~Encoder() = default;

CommandResponder* Encoder::command_responder() { return device_.get(); }

void Encoder::append_imu(const ImuFrameInput& sample, std::vector<std::uint8_t>& out) {
  const AidingReading& aiding = aiding_reading(sample);
  if (options_.mavlink_hil_sensor) {
    std::array<std::uint8_t, kHilSensor.payload_bytes> p{};
    const std::uint32_t updated = fill_imu_payload(p.data(), sample, options_, aiding);
    wire::put_le<std::uint32_t>(p.data() + kOffFieldsUpdated, updated);
    p[kOffHilSensorId] = options_.mavlink_sensor_id;
    append_packet(kHilSensor, p, out);
  }
  if (options_.mavlink_highres_imu) {
    std::array<std::uint8_t, kHighresImu.payload_bytes> p{};
    const std::uint32_t updated = fill_imu_payload(p.data(), sample, options_, aiding);
    wire::put_le<std::uint16_t>(p.data() + kOffFieldsUpdated, static_cast<std::uint16_t>(updated));
    p[kOffHighresId] = options_.mavlink_sensor_id;
    append_packet(kHighresImu, p, out);
  }
}

void Encoder::encode(const ImuFrameInput& sample, std::vector<std::uint8_t>& out) {
  // Every sample steps the barometer and magnetometer models, whether or
  // not an IMU message goes out with it (the driver's decimation).
  if (barometer_ || magnetometer_) (void)aiding_reading(sample);
  if (!device_) {
    append_imu(sample, out);
    append_hil_gps(sample, out);
    return;
  }
  // The driver's SET_MESSAGE_INTERVAL, on the sample grid: the IMU
  // message(s) go out on sample counters that are multiples of the
  // decimation (1 at power-up: every sample, the bytes of a device nobody
  // talks to are unchanged).
  device_->note_period(sample.period_ns);
  const std::uint32_t decimation = device_->decimation();
  if (decimation != 0 && sample.sample_counter % decimation == 0) append_imu(sample, out);
  append_hil_gps(sample, out);
  // Replies the io thread decided, after the sample's own packets: whole
  // packets, numbered by the component's one seq (mavlink_device.hpp).
  ReplyItem item;
  for (int i = 0; i < Device::kMaxRepliesPerSample && device_->next_reply(item); ++i) append_reply(item, sample, out);
}

void Encoder::append_reply(const ReplyItem& item, const ImuFrameInput& sample, std::vector<std::uint8_t>& out) {
  if (item.kind == ReplyItem::Kind::param_value) {
    // [X] PARAM_VALUE wire order: param_value f32, param_count u16,
    // param_index u16, param_id char[16], param_type u8.
    const auto params = device_->params();
    const DeviceParam& prm = params[item.param_index];
    std::array<std::uint8_t, kParamValue.payload_bytes> p{};
    wire::put_le<float>(p.data(), prm.value);
    wire::put_le<std::uint16_t>(p.data() + 4, static_cast<std::uint16_t>(params.size()));
    wire::put_le<std::uint16_t>(p.data() + 6, item.param_index);
    for (std::size_t k = 0; k < 16 && prm.id[k] != 0; ++k) p[8 + k] = static_cast<std::uint8_t>(prm.id[k]);
    p[24] = kParamTypeReal32;
    append_packet(kParamValue, p, out);
    return;
  }
  // [X] COMMAND_ACK wire order: command u16, result u8, then the
  // extensions progress u8, result_param2 i32, target_system u8,
  // target_component u8 (the requester).
  std::array<std::uint8_t, kCommandAck.payload_bytes> a{};
  wire::put_le<std::uint16_t>(a.data(), item.command);
  a[2] = item.result;
  a[8] = item.target_system;
  a[9] = item.target_component;
  append_packet(kCommandAck, a, out);
  if (item.kind == ReplyItem::Kind::heartbeat) append_heartbeat(kMavStateActive, out);
  else if (item.kind == ReplyItem::Kind::imu_message) append_imu(sample, out);
}

namespace {

// Instant n of the grid of `rate_hz` per second on trajectory time,
// n * 1 s / rate without overflow (n / rate whole seconds plus the rest).
TimeNs gps_grid_ns(std::int64_t n, std::int64_t rate_hz) {
  const std::int64_t q = n / rate_hz, r = n % rate_hz;
  return saturating_add_ns(saturating_mul_ns(q, kNsPerSecond), r * kNsPerSecond / rate_hz);
}

// The grid instant after t (floor(t * rate / 1 s) + 1), for any t.
std::int64_t gps_grid_index_after(TimeNs t_ns, std::int64_t rate_hz) {
  std::int64_t s = t_ns / kNsPerSecond, ns = t_ns % kNsPerSecond;
  if (ns < 0) {
    --s;
    ns += kNsPerSecond;
  }
  return s * rate_hz + ns * rate_hz / kNsPerSecond + 1;
}

template <typename T>
T rounded_clamped(double v, double lo, double hi) {
  return static_cast<T>(std::llround(std::clamp(v, lo, hi)));
}

}  // namespace

std::optional<GnssFix> Encoder::hil_gps_fix(const ImuFrameInput& sample) {
  const std::int64_t rate = options_.mavlink_hil_gps_rate_hz;
  if (rate <= 0 || !sample.has_navigation || !gps_source_) return std::nullopt;
  const TimeNs t = sample.t_ns;
  // Due at the first sample at or after each grid instant; a timeline that
  // went back by more than a period starts over from its sample.
  const TimeNs period_ns = kNsPerSecond / rate;
  if (next_gps_ns_ && t < *next_gps_ns_ && t >= saturating_sub_ns(*next_gps_ns_, 2 * period_ns)) return std::nullopt;
  const std::int64_t n = gps_grid_index_after(t, rate) - 1;  // the grid instant at or before t
  const bool restart = !next_gps_ns_ || t < *next_gps_ns_;
  next_gps_ns_ = gps_grid_ns(n + 1, rate);
  // The fix index: grid instants since the stream's first HIL_GPS (the
  // error model's j; not the IMU sample counter, not the instant's index
  // since trajectory time 0, which a Unix-time trajectory puts beyond what
  // the model steps through: core/aiding/gnss.hpp). A timeline that went
  // back, or jumped more than 2^28 fixes ahead (over a year at 5 Hz),
  // starts the error sequence over from its initial state.
  if (restart || n < gps_first_index_ || n - gps_first_index_ >= (std::int64_t{1} << 28)) gps_first_index_ = n;
  GnssFix fix = gps_source_->fix(sample, static_cast<std::uint64_t>(n - gps_first_index_));
  if (fix.fix_type == GnssFixType::none) {
    // A time before the GPS epoch on the receivers' time base (the source
    // reports no fix): HIL_GPS has no GPS time field; the trajectory itself.
    fix.latitude_rad = sample.latitude_rad;
    fix.longitude_rad = sample.longitude_rad;
    fix.height_m = sample.height_m;
    fix.velocity_ned_m_s = sample.velocity_ned_m_s;
    fix.geoid_separation_m = options_.gnss.geoid_separation_m;
    fix.hdop = options_.gnss.hdop;
    fix.vdop = options_.gnss.vdop;
    fix.satellites = options_.gnss.satellites;
  }
  if (!std::isfinite(fix.latitude_rad) || !std::isfinite(fix.longitude_rad) ||
      !std::isfinite(fix.height_m - fix.geoid_separation_m) || !fix.velocity_ned_m_s.allFinite())
    return std::nullopt;
  return fix;
}

void Encoder::append_hil_gps(const ImuFrameInput& sample, std::vector<std::uint8_t>& out) {
  const std::optional<GnssFix> due = hil_gps_fix(sample);
  if (!due) return;
  const GnssFix& fix = *due;
  const TimeNs t = sample.t_ns;
  const double lat_deg = fix.latitude_rad * 180.0 / std::numbers::pi;
  const double lon_deg = std::remainder(fix.longitude_rad * 180.0 / std::numbers::pi, 360.0);
  const double msl_m = fix.height_m - fix.geoid_separation_m;
  const Vec3& v = fix.velocity_ned_m_s;
  if (!std::isfinite(lat_deg) || !std::isfinite(lon_deg) || !std::isfinite(msl_m) || !v.allFinite()) return;
  // [X] HIL_GPS wire order ([G] sorted by type size): time_usec u64, lat
  // i32 degE7, lon i32 degE7, alt i32 mm (MSL, up), eph u16, epv u16 (DOP
  // x 100), vel u16 cm/s (ground speed), vn, ve, vd i16 cm/s (NED), cog u16
  // cdeg (0..35999, UINT16_MAX unknown), fix_type u8 (3: 3D), satellites_visible
  // u8; extensions id u8, yaw u16 (0: not available).
  std::array<std::uint8_t, kHilGps.payload_bytes> p{};
  wire::put_le<std::uint64_t>(p.data(), time_usec_from_ns(t));
  wire::put_le<std::int32_t>(p.data() + 8, rounded_clamped<std::int32_t>(lat_deg * 1e7, -9e8, 9e8));
  wire::put_le<std::int32_t>(p.data() + 12, rounded_clamped<std::int32_t>(lon_deg * 1e7, -1.8e9, 1.8e9));
  wire::put_le<std::int32_t>(p.data() + 16, rounded_clamped<std::int32_t>(msl_m * 1e3, -2147483647.0, 2147483647.0));
  wire::put_le<std::uint16_t>(p.data() + 20, rounded_clamped<std::uint16_t>(fix.hdop * 100.0, 0.0, 65534.0));
  wire::put_le<std::uint16_t>(p.data() + 22, rounded_clamped<std::uint16_t>(fix.vdop * 100.0, 0.0, 65534.0));
  const double ground_m_s = std::hypot(v.x(), v.y());
  wire::put_le<std::uint16_t>(p.data() + 24, rounded_clamped<std::uint16_t>(ground_m_s * 100.0, 0.0, 65534.0));
  for (int i = 0; i < 3; ++i)
    wire::put_le<std::int16_t>(p.data() + 26 + 2 * i, rounded_clamped<std::int16_t>(v[i] * 100.0, -32767.0, 32767.0));
  // Course over ground: the direction of the horizontal velocity, unknown
  // when that rounds to 0 cm/s.
  std::uint16_t cog = 65535;
  if (ground_m_s >= 0.005) {
    double cdeg = std::atan2(v.y(), v.x()) * 18000.0 / std::numbers::pi;
    if (cdeg < 0.0) cdeg += 36000.0;
    cog = static_cast<std::uint16_t>(std::llround(cdeg) % 36000);
  }
  wire::put_le<std::uint16_t>(p.data() + 32, cog);
  p[34] = 3;  // 3D fix
  p[35] = static_cast<std::uint8_t>(fix.satellites);
  p[36] = options_.mavlink_sensor_id;
  append_packet(kHilGps, p, out);
}

void Encoder::periodic(TimeNs now_ns, std::vector<std::uint8_t>& out) {
  if (!options_.mavlink_heartbeat) return;
  // Due now if never sent, if the period has elapsed, or if the clock went
  // back by more than a period (a restarted timeline must not go silent).
  const bool due = !next_heartbeat_ns_ || now_ns >= *next_heartbeat_ns_ ||
                   now_ns < *next_heartbeat_ns_ - kHeartbeatPeriodNs;
  if (!due) return;
  // Keep a 1 Hz grid while on schedule; after a stall restart from now
  // instead of bursting the missed ones.
  next_heartbeat_ns_ = (next_heartbeat_ns_ && now_ns >= *next_heartbeat_ns_ &&
                        now_ns - *next_heartbeat_ns_ < kHeartbeatPeriodNs)
                           ? *next_heartbeat_ns_ + kHeartbeatPeriodNs
                           : now_ns + kHeartbeatPeriodNs;

  append_heartbeat(kMavStateActive, out);
}

void Encoder::append_heartbeat(std::uint8_t system_status, std::vector<std::uint8_t>& out) {
  // [X] HEARTBEAT wire order: custom_mode (u32) then the u8 fields in XML
  // order: type, autopilot, base_mode, system_status, mavlink_version.
  std::array<std::uint8_t, kHeartbeat.payload_bytes> p{};
  wire::put_le<std::uint32_t>(p.data(), 0);  // custom_mode
  p[4] = kMavTypeImu;
  p[5] = kMavAutopilotInvalid;
  p[6] = 0;  // base_mode
  p[7] = system_status;
  p[8] = kMavlinkVersion;
  append_packet(kHeartbeat, p, out);
}

void Encoder::restart(TimeNs now_ns, std::vector<std::uint8_t>& out) {
  // A component announces itself with a HEARTBEAT as soon as it is up [H];
  // while booting its system_status is MAV_STATE_BOOT. Its packet counter
  // starts again at 0 [G].
  sequence_ = 0;
  if (!options_.mavlink_heartbeat) return;
  append_heartbeat(kMavStateBoot, out);
  next_heartbeat_ns_ = saturating_add_ns(now_ns, kHeartbeatPeriodNs);
}

StreamFrameLayout Encoder::frame_layout(std::span<const std::uint8_t> frame) const {
  // [G] packet format: len at offset 1, the payload from offset 10, then
  // the 2-byte checksum (this encoder never signs).
  if (frame.size() < kHeaderBytes) return StreamFrameLayout{frame.size()};
  const std::size_t len = frame[1];
  StreamFrameLayout layout;
  layout.frame_bytes = std::min(frame.size(), kHeaderBytes + len + kChecksumBytes);
  layout.length_offset = 1;
  layout.length_bytes = 1;
  layout.checksum_offset = kHeaderBytes + len;
  layout.checksum_bytes = layout.checksum_offset + kChecksumBytes <= frame.size() ? kChecksumBytes : 0;
  return layout;
}

std::size_t Encoder::max_bytes_per_sample() const {
  constexpr std::size_t kOverhead = kHeaderBytes + kChecksumBytes;
  std::size_t bytes = 0;
  if (options_.mavlink_hil_sensor) bytes += kOverhead + kHilSensor.payload_bytes;
  if (options_.mavlink_highres_imu) bytes += kOverhead + kHighresImu.payload_bytes;
  if (options_.mavlink_hil_gps_rate_hz > 0) {
    // HIL_GPS at its rate spread over the samples (one per sample when
    // the sample rate is at or below it, or unknown).
    const std::size_t gps = kOverhead + kHilGps.payload_bytes;
    const double per_sample = static_cast<double>(options_.mavlink_hil_gps_rate_hz) / options_.nominal_sample_rate_hz;
    bytes += options_.nominal_sample_rate_hz > 0.0 && per_sample < 1.0
                 ? static_cast<std::size_t>(std::ceil(static_cast<double>(gps) * per_sample))
                 : gps;
  }
  if (options_.mavlink_heartbeat) {
    const std::size_t heartbeat = kOverhead + kHeartbeat.payload_bytes;
    // One heartbeat per second spread over the samples of that second; at
    // or below 1 Hz (or unknown) at most one per periodic() call, i.e. one
    // per sample.
    const double rate = options_.nominal_sample_rate_hz;
    bytes += rate > 1.0 ? static_cast<std::size_t>(std::ceil(static_cast<double>(heartbeat) / rate)) : heartbeat;
  }
  return bytes;
}

void Decoder::feed(std::span<const std::uint8_t> bytes, const SampleCallback& on_sample) {
  buffer_.insert(buffer_.end(), bytes.begin(), bytes.end());
  static constexpr std::array<std::uint8_t, 1> kSync{kMagic};

  wire::scan_frames(buffer_, kSync, counters_, [&](std::span<const std::uint8_t> c) {
    using wire::Candidate;
    if (c.size() < kHeaderBytes) return wire::CandidateResult{Candidate::kNeedMore};
    // [G] "Incompatibility Flags": a packet with a flag we do not understand
    // must be discarded. Signed packets are accepted (signature not checked:
    // no key here), their 13 signature bytes skipped.
    const std::uint8_t incompat = c[2];
    if ((incompat & ~kIncompatSigned) != 0) return wire::CandidateResult{Candidate::kMalformed};
    const std::uint32_t msgid = std::uint32_t{c[7]} | std::uint32_t{c[8]} << 8 | std::uint32_t{c[9]} << 16;
    const MessageSpec* spec = nullptr;
    for (const MessageSpec* m : {&kHeartbeat, &kHighresImu, &kHilSensor, &kHilGps}) {
      if (m->id == msgid) spec = m;
    }
    // Without its CRC_EXTRA a message cannot be checked: not accepted.
    if (spec == nullptr) return wire::CandidateResult{Candidate::kMalformed};

    const std::size_t len = c[1];
    const std::size_t total = kHeaderBytes + len + kChecksumBytes +
                              ((incompat & kIncompatSigned) != 0 ? kSignatureBytes : 0);
    if (c.size() < total) return wire::CandidateResult{Candidate::kNeedMore};
    const std::uint16_t sent = wire::get_le<std::uint16_t>(c.data() + kHeaderBytes + len);
    if (packet_checksum(c.subspan(1, kHeaderBytes - 1 + len), spec->crc_extra) != sent) {
      return wire::CandidateResult{Candidate::kBadChecksum};
    }
    ++counters_.frames;

    // [G] seq: "Components increment value for each message sent" - one
    // 8-bit counter per (system, component); a step of k means k-1 lost.
    const std::uint8_t seq = c[4];
    const auto key = static_cast<std::uint16_t>(std::uint16_t{c[5]} << 8 | c[6]);
    auto [it, fresh] = sequences_.try_emplace(key, SequenceState{seq, seq});
    if (!fresh) {
      const auto step = static_cast<std::uint8_t>(seq - it->second.last);
      if (step != 0) counters_.sequence_gaps += step - 1u;
      it->second.widened += step;
      it->second.last = seq;
    }

    if (msgid != sample_message_id_) return wire::CandidateResult{Candidate::kAccepted, total};

    // [G] truncation: zero-extend to the full length. Longer than we know
    // means newer extension fields: ignored.
    std::array<std::uint8_t, 255> p{};
    std::copy_n(c.begin() + kHeaderBytes, len, p.begin());
    const std::uint32_t updated = msgid == kHilSensor.id
                                      ? wire::get_le<std::uint32_t>(p.data() + kOffFieldsUpdated)
                                      : wire::get_le<std::uint16_t>(p.data() + kOffFieldsUpdated);
    DecodedSample s;
    s.sequence = it->second.widened;
    s.has_sequence = true;
    const std::uint64_t time_usec = wire::get_le<std::uint64_t>(p.data() + kOffTimeUsec);
    if (time_usec <= static_cast<std::uint64_t>(std::numeric_limits<TimeNs>::max() / 1000)) {
      s.t_ns = static_cast<TimeNs>(time_usec) * 1000;
      s.has_time = true;
    }
    s.accel_m_s2 = mavlink_body_to_frd(get_vec3_f32(p.data() + kOffAcc));
    s.gyro_rad_s = mavlink_body_to_frd(get_vec3_f32(p.data() + kOffGyro));
    if ((updated & kUpdatedAccelGyro) != kUpdatedAccelGyro) s.status |= kStatusFault;

    if (!s.accel_m_s2.allFinite() || !s.gyro_rad_s.allFinite()) {
      ++counters_.other_errors;  // never pass NaN/inf on
    } else {
      ++counters_.samples;
      if (on_sample) on_sample(s);
    }
    return wire::CandidateResult{Candidate::kAccepted, total};
  });
}

}  // namespace imuemu::drivers::mavlink2
