// The byte-stream protocols (UART, pty) by name, with the options that shape
// what they send. A decoder made with the same options accepts exactly what
// the matching encoder sends.
//
//   "native"   imuemu native v1 (docs/native-protocol.md): f64, CRC-32C
//   "mavlink2" MAVLink 2 HIL_SENSOR (#107) [+ HIGHRES_IMU (#105)] + HEARTBEAT
//              [+ HIL_GPS (#113) at its own rate; barometer and magnetometer
//              fields when configured]
//   "mip"      MicroStrain MIP, IMU data set 0x80
//   "nmea"     a GNSS receiver: NMEA 0183 RMC, VTG, GGA, GSA, ZDA per epoch
//   "ubx"      a GNSS receiver: u-blox UBX NAV-PVT (+ POSLLH, STATUS, DOP,
//              SOL, VELNED, TIMEGPS) per epoch
//   "vectornav" VectorNav VN-100 / VN-200 / VN-300: binary output packets
//              and async ASCII sentences as its registers set them
//   "sbg"      SBG Systems ELLIPSE-A / -N / -D: sbgECom binary logs as its
//              output configuration (OUTPUT_CONF, REST API) sets them
//   "xsens"    Xsens MTi (Xbus): MTData2 as its output configuration sets it
// The GNSS receivers send one navigation epoch per device sample: the
// device's rate is the navigation rate, 1..10 Hz.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "drivers/gnss_fix.hpp"
#include "drivers/protocol.hpp"

namespace imuemu::drivers {

// The time base of trajectory time, for protocols that send absolute time.
enum class MipTimeBase : std::uint8_t { unknown, gps, utc };

// The MIP device that answers its driver (drivers/protocols/mip_device.hpp,
// docs/mip-device.md): scene keys [imu.device]. Defaults: a 3DM-CV7-AHRS as
// its Get Device Information (0x01,0x03) reports it; the identity strings are
// at most 16 characters (the reply's fixed fields).
struct MipDeviceConfig {
  bool answers_commands = true;       // false: input read and discarded, as before issue 27
  bool power_up_idle = false;         // power_up_mode = "idle": silent until Resume (0x01,0x06)
  std::uint16_t firmware_version = 1108;  // "1.1.08": 1000*major + 100*minor + patch (DCP 0x01,0x03)
  std::string model_name = "3DM-CV7-AHRS";
  std::string model_number = "6284-4220";
  std::string serial_number = "6284.100027";
  std::string lot_number = "";
  std::string device_options = "8g,300dps";
  // Reported in status and docs only: Get Device Information has no field for it.
  std::string hardware_revision = "1.0";
};

// The VectorNav device (drivers/protocols/vectornav_device.hpp,
// docs/vectornav-device.md, issue 29): scene keys [imu.vectornav]. The model
// decides the IMU rate the rate divisors divide (VN-100 / VN-200: 800 Hz,
// VN-300: 400 Hz) and the binary groups it has (GNSS and INS: VN-200 and
// VN-300). The identity registers (1-4) report the strings below; empty:
// the model's preset ("VN-100T-CR", ... and firmware "2.1.0.0").
enum class VectorNavModel : std::uint8_t { vn100, vn200, vn300 };
struct VectorNavDeviceConfig {
  bool answers_commands = true;       // false: input read and discarded
  VectorNavModel model = VectorNavModel::vn100;
  std::string model_number;           // register 1 (at most 24 characters)
  std::uint32_t hardware_revision = 2;  // register 2
  std::uint32_t serial_number = 100012345;  // register 3
  std::string firmware_version;       // register 4 ("2.1.0.0")
  std::string user_tag;               // register 0 at power-up (at most 20 characters)
  std::uint8_t port = 1;              // which of the device's two serial ports the pty / UART is (1 or 2)
  // Register 6 / 7 at power-up: the async ASCII output (0: off; default
  // VNYMR (14) for a VN-100, VNINS (22) for the INS models) at this rate (Hz).
  int power_up_ador = -1;             // -1: the model's default
  std::uint16_t power_up_adof_hz = 40;
  // Register writes saved in the device ($VNWRG bodies "ID,VALUES"
  // separated by ';', then $VNWNV): applied over the factory settings at
  // power-up and by $VNRST; $VNRFS restores the factory's. Each is checked
  // as the device checks the write.
  std::string saved_registers;
  // The magnetic field the magnetometer measures, in NED (gauss): a fixed
  // reference (register 21's role), not a field model.
  double mag_reference_ned_gauss[3] = {0.21, 0.0, 0.43};
};

// The SBG Systems sbgECom device (drivers/protocols/sbg_device.hpp,
// docs/sbg-device.md, issue 29): scene keys [imu.sbg]. The model decides
// which logs it has (ELLIPSE-A: an AHRS, no GNSS or EKF_NAV; ELLIPSE-N / -D:
// INS with GNSS) and its preset identity (product code, firmware 3.x).
enum class SbgModel : std::uint8_t { ellipse_a, ellipse_n, ellipse_d };
struct SbgDeviceConfig {
  bool answers_commands = true;       // false: input read and discarded
  SbgModel model = SbgModel::ellipse_n;
  std::string product_code;           // CMD_INFO / GET /api/v1/info (at most 31 characters); empty: the model's
  std::uint32_t serial_number = 45000123;
  // The logs sent after power-up (factory output configuration, docs/sbg-device.md);
  // false: none until the driver configures them.
  bool outputs_at_power_up = true;
  // Output settings saved in the device, port A ("NAME=RATE,..." with the
  // REST API's names and rates): over the factory logs at power-up and after
  // a reboot; restoring the factory settings drops them.
  std::string saved_outputs;
  // The magnetic field the magnetometer measures, in NED (gauss), as
  // VectorNavDeviceConfig's: a fixed reference, not a field model.
  double mag_reference_ned_gauss[3] = {0.21, 0.0, 0.43};
};

// The Xsens MTi device (drivers/protocols/xsens_device.hpp,
// docs/xsens-device.md, issue 29): scene keys [imu.xsens]. The model decides
// the identity presets (device id, product code, hardware and firmware
// versions), the maximum output rate the rates divide and the outputs it has
// (GNSS: MTi-7, MTi-680G, MTi-G-710). Empty strings / 0: the model's preset.
enum class XsensModel : std::uint8_t { mti3, mti7, mti630, mti680g, mti_g710 };
struct XsensDeviceConfig {
  bool answers_commands = true;      // false: input read and discarded
  XsensModel model = XsensModel::mti630;
  std::uint32_t device_id = 0;       // ReqDID (0: the model's preset)
  std::string product_code;          // ReqProductCode (at most 20 characters)
  std::string firmware_version;      // ReqFWRev "major.minor.revision" (build and svn fields below)
  std::uint32_t firmware_build = 0;  // 0: the preset's
  std::uint32_t firmware_svn = 0;
  std::uint32_t baud = 115200;       // ReqBaudrate at power-up
  // The magnetic field the magnetometer measures, in NED, in a.u. (1: the
  // local field's magnitude; [L] MagneticField is normalised).
  double mag_reference_ned_au[3] = {0.44, 0.0, 0.90};
};

// Issue 28: the MIP device's GNSS data set 0x81 and its own navigation
// filter, data set 0x82 (drivers/protocols/mip_nav.hpp, docs/mip-device.md).
// Off by default (both rates 0): the device then lists, answers and streams
// exactly what it did before. Times are seconds since the device powered up
// (sample counter 0 of its stream).
enum class MipFilterStates : std::uint8_t {
  cv7,  // 3DM-CV7 / GQ7 ("prospect") filter states: 1 init, 2 vertical gyro, 3 AHRS, 4 full nav
  gx5,  // 3DM-GX5-45 ("philo") filter states: 0 startup, 1 init, 2 running valid, 3 running error
};
struct MipNavConfig {
  std::int64_t gnss_rate_hz = 0;    // 0x81 power-up rate (its receiver's epochs); 0: no GNSS receiver
  std::int64_t filter_rate_hz = 0;  // 0x82 power-up rate; 0: no filter data
  MipFilterStates filter_states = MipFilterStates::cv7;
  // The filter initialises for this long after power-up (attitude
  // alignment), then runs: AHRS, and full navigation while GNSS has a 3D fix.
  double filter_alignment_s = 5.0;
  // The receiver's first 3D fix after power-up (cold start time to first
  // fix; u-blox M8/M9 and the GX5-45's receiver: 26-30 s cold).
  double gnss_first_fix_s = 30.0;
  // One GNSS outage on the timeline: no fix (0x81,0x0B fix type none, no
  // satellites) in [start, start + duration); duration 0: none.
  double gnss_outage_start_s = 0.0;
  double gnss_outage_duration_s = 0.0;
  // The filter solution's errors, 1 sigma, white per filter epoch, in the
  // datasheet's terms (3DM-GX5-45 datasheet, "Navigation filter
  // performance": attitude 0.25 deg roll/pitch, 0.8 deg heading, position
  // 2.5 m horizontal / 5 m vertical, velocity 0.1 m/s RMS). Seeded with the
  // device's error-model seed (aiding_seed).
  double filter_roll_pitch_sigma_deg = 0.25;
  double filter_heading_sigma_deg = 0.8;
  double filter_horizontal_sigma_m = 2.5;
  double filter_vertical_sigma_m = 5.0;
  double filter_velocity_sigma_m_s = 0.1;
  bool any() const { return gnss_rate_hz > 0 || filter_rate_hz > 0; }
};

struct StreamEncoderOptions {
  // native and mip: send delta-theta / delta-velocity as well as the rates.
  bool include_deltas = true;

  // mavlink2. Source address (MAVLink guide, packet format: 0 is not a valid
  // source for either). 200 = MAV_COMP_ID_IMU (common.xml MAV_COMPONENT).
  std::uint8_t mavlink_system_id = 1;
  std::uint8_t mavlink_component_id = 200;
  bool mavlink_heartbeat = true;       // HEARTBEAT at 1 Hz from periodic()
  bool mavlink_hil_sensor = true;      // HIL_SENSOR (#107), what PX4 takes in HIL mode
  bool mavlink_highres_imu = false;    // HIGHRES_IMU (#105)
  std::uint8_t mavlink_sensor_id = 0;  // the messages' `id` extension field
  // The component answers its ground station / autopilot (issue 27,
  // docs/mavlink-device.md); false: input read and discarded.
  bool mavlink_answers_commands = true;
  // HIL_SENSOR/HIGHRES_IMU `temperature` (degC, fields_updated bit 12) when
  // set; otherwise not sent (bit clear, field zero).
  std::optional<double> mavlink_temperature_degC;
  // Issue 28: the barometer and magnetometer groups of HIL_SENSOR (and
  // HIGHRES_IMU) and HIL_GPS, from the sample's navigation fields (an ecef
  // scene; docs/mavlink-device.md). All off by default: the bytes of a
  // scene that does not ask are those of before.
  //  baro: abs_pressure (hPa) and pressure_alt (m) from the ISA atmosphere
  //    (core/aiding/atmosphere.hpp) at the height above the geoid, through
  //    the barometer model (core/aiding/barometer.hpp) with the errors
  //    below; fields_updated bits 9 and 11, and 12 (temperature: the IMU
  //    model's or the configured one, else the barometer's).
  //  mag: x/y/zmag (gauss, sensor axes) = the WMM2025 field at the position
  //    and date (core/aiding/wmm.hpp) through the magnetometer model; bits 6..8.
  bool mavlink_baro = false;
  bool mavlink_mag = false;
  // HIL_GPS (#113) at this rate on the trajectory-time grid (multiples of
  // 1/rate); 0: not sent.
  std::int64_t mavlink_hil_gps_rate_hz = 0;
  // The decimal year of trajectory time 0 (WMM2025's validity, 2025.0 ..
  // 2030.0): the date the field is evaluated at is this + t / 365.25 d.
  double mavlink_date_at_t0_year = 2026.0;
  // Geoid undulation N: gnss.geoid_separation_m below (geoid above the
  // ellipsoid; no geoid model is carried): the atmosphere's and HIL_GPS
  // alt's mean sea level is h - N.
  // Barometer errors (core/aiding/barometer.hpp terms); magnetometer noise
  // per axis. 0: truth.
  double mavlink_baro_noise_rms_pa = 0.0;
  double mavlink_baro_bias_pa = 0.0;
  double mavlink_mag_noise_rms_ut = 0.0;
  // HIL_GPS is the fix of the GNSS receivers (gnss below, through
  // drivers/gnss_fix.hpp GnssFixSource at mavlink_hil_gps_rate_hz): its
  // satellites, hdop / vdop (eph / epv, sent x 100), geoid_separation_m and
  // position / velocity errors; errors off (the default): the trajectory.
  // The random terms of the barometer, the magnetometer and HIL_GPS: the
  // scene's error-model seed (emit: --seed), streams keyed as the IMU's by
  // that seed and device_name. HIL_GPS takes this seed, not gnss.errors.seed
  // (the receivers' own key): one MAVLink component, one seed.
  std::uint64_t aiding_seed = 0;

  // mip. What trajectory time is, which decides the GPS timestamp field
  // (0x80,0x12): tow and week of a GPS time with the valid flags set
  // (time_initialized | tow_valid | week_number_valid), or, when nothing
  // says the trajectory is on a GPS or UTC time base, the device's internal
  // clock = trajectory time with the valid flags clear (CV7 DCP 0x80,0x12:
  // without external time "this time is equivalent to internal system
  // time"). Before issue 12 every time was flagged valid GPS time, so a
  // trajectory starting at 0 claimed GPS week 0 (January 1980).
  MipTimeBase mip_time_base = MipTimeBase::unknown;
  // kGps: the GPS time (ns since the GPS epoch 1980-01-06T00:00:00, GPS time
  // scale, no leap seconds) that trajectory time t_ns = 0 corresponds to:
  // gps = this + t_ns (0: trajectory time is GPS time itself). Used only
  // with MipTimeBase::gps.
  std::int64_t mip_gps_time_at_t0_ns = 0;
  // kUtc: trajectory time is UTC as POSIX ns (since 1970-01-01T00:00:00Z);
  // gps = t - 315964800 s + (GPS - UTC), GPS - UTC from the leap-second
  // table (drivers/protocols/gps_time.hpp) or this fixed value when set.
  std::optional<int> mip_gps_minus_utc_s;
  // Overrange status field (0x80,0x18): where the saturated bit goes.
  bool mip_overrange_status = true;
  MipDeviceConfig mip_device;
  // GNSS (0x81) and filter (0x82) data sets; GNSS figures and position /
  // velocity errors from `gnss` below (errors seeded with aiding_seed).
  MipNavConfig mip_nav;

  // vectornav (issue 29): the device's model, identity and power-up
  // outputs. GPS time and the GNSS fields (VN-200 / VN-300) come from `gnss`
  // below (time base, satellites, DOPs, accuracies; its position is the
  // trajectory's, without errors).
  VectorNavDeviceConfig vectornav;

  // sbg (issue 29): the SBG device's model, identity and power-up outputs.
  // GPS1_POS / GPS1_VEL / UTC_TIME (ELLIPSE-N / -D) come from `gnss` below.
  SbgDeviceConfig sbg;
  // xsens (issue 29): the MTi model and identity. Position, velocity and UTC
  // (GNSS models) come from `gnss` below as for vectornav.
  XsensDeviceConfig xsens;

  // nmea and ubx (issue 28, drivers/gnss_fix.hpp): the receiver's time base
  // and the figures it reports; mavlink2 HIL_GPS: its satellites, DOPs,
  // geoid separation and errors (the time fields are not used).
  GnssReceiverConfig gnss;
  std::string nmea_talker = "GP";  // GP (GPS) or GN (multi-constellation)
  // ubx: NAV-POSLLH, NAV-STATUS, NAV-DOP, NAV-SOL, NAV-VELNED, NAV-TIMEGPS
  // beside NAV-PVT (what ArduPilot's UBX driver reads); false: NAV-PVT only.
  bool ubx_legacy_nav = true;

  // The device's name (scene [[imu]] name; emit: imu0): with the seed, the
  // key of every random term a protocol adds (MAVLink barometer,
  // magnetometer and HIL_GPS; NMEA/UBX receiver errors), as the IMU noise's.
  std::string device_name = "imu0";

  // The sample rate the encoder will run at, only to spread periodic traffic
  // (heartbeats) over samples in max_bytes_per_sample(); 0 = unknown (then
  // one whole heartbeat is charged to every sample, an upper bound).
  double nominal_sample_rate_hz = 0.0;
};

// The protocol names make_stream_encoder/make_stream_decoder accept.
std::vector<std::string> stream_protocol_names();
// The GNSS receiver personalities among them (nmea, ubx). Their device rate
// is the navigation rate, 1..kMaxGnssRateHz: `imuemu emit` and the scene
// parser refuse more (the encoders themselves send one epoch per sample at
// whatever rate they are driven).
bool is_gnss_protocol(const std::string& protocol);
inline constexpr std::int64_t kMaxGnssRateHz = 10;

// Throws std::invalid_argument naming the protocol or option that is wrong.
std::unique_ptr<StreamEncoder> make_stream_encoder(const std::string& protocol,
                                                   const StreamEncoderOptions& options = {});
std::unique_ptr<StreamDecoder> make_stream_decoder(const std::string& protocol,
                                                   const StreamEncoderOptions& options = {});

}  // namespace imuemu::drivers
