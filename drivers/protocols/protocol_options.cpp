// The protocol option table (protocol_options.hpp). Ranges are the wire's:
// the cited field widths and reserved values of each protocol.
#include "drivers/protocols/protocol_options.hpp"

#include <charconv>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "core/aiding/gnss.hpp"
#include "core/sensor/sensor_model.hpp"

namespace imuemu::drivers {

namespace {

constexpr std::int64_t kInt62 = std::numeric_limits<std::int64_t>::max() / 2;

std::int64_t as_int(const OptionValue& v) { return std::get<std::int64_t>(v); }
double as_number(const OptionValue& v) { return std::get<double>(v); }
bool as_bool(const OptionValue& v) { return std::get<bool>(v); }
const std::string& as_choice(const OptionValue& v) { return std::get<std::string>(v); }

ProtocolOption boolean(std::string protocol, std::string key, bool fallback, std::string help,
                       std::function<void(ProtocolOptions&, bool)> set) {
  ProtocolOption o;
  o.protocol = std::move(protocol);
  o.key = std::move(key);
  o.type = OptionType::boolean;
  o.default_text = fallback ? "true" : "false";
  o.help = std::move(help);
  o.apply = [set = std::move(set)](ProtocolOptions& p, const OptionValue& v) { set(p, as_bool(v)); };
  return o;
}

ProtocolOption integer(std::string protocol, std::string key, std::int64_t lo, std::int64_t hi, std::string fallback,
                       std::string help, std::function<void(ProtocolOptions&, std::int64_t)> set) {
  ProtocolOption o;
  o.protocol = std::move(protocol);
  o.key = std::move(key);
  o.type = OptionType::integer;
  o.integer_min = lo;
  o.integer_max = hi;
  o.default_text = std::move(fallback);
  o.help = std::move(help);
  o.apply = [set = std::move(set)](ProtocolOptions& p, const OptionValue& v) { set(p, as_int(v)); };
  return o;
}

ProtocolOption number(std::string protocol, std::string key, double lo, double hi, bool lo_open, std::string fallback,
                      std::string help, std::function<void(ProtocolOptions&, double)> set) {
  ProtocolOption o;
  o.protocol = std::move(protocol);
  o.key = std::move(key);
  o.type = OptionType::number;
  o.number_min = lo;
  o.number_max = hi;
  o.number_min_open = lo_open;
  o.default_text = std::move(fallback);
  o.help = std::move(help);
  o.apply = [set = std::move(set)](ProtocolOptions& p, const OptionValue& v) { set(p, as_number(v)); };
  return o;
}

ProtocolOption choice(std::string protocol, std::string key, std::vector<std::string> choices, std::string help,
                      std::function<void(ProtocolOptions&, const std::string&)> set) {
  ProtocolOption o;
  o.protocol = std::move(protocol);
  o.key = std::move(key);
  o.type = OptionType::choice;
  o.default_text = choices.front();
  o.choices = std::move(choices);
  o.help = std::move(help);
  o.apply = [set = std::move(set)](ProtocolOptions& p, const OptionValue& v) { set(p, as_choice(v)); };
  return o;
}

ProtocolOption text(std::string protocol, std::string key, std::size_t max_chars, std::string form,
                    std::string fallback, std::string example, std::string help,
                    std::function<void(ProtocolOptions&, const std::string&)> set) {
  ProtocolOption o;
  o.protocol = std::move(protocol);
  o.key = std::move(key);
  o.type = OptionType::text;
  o.text_max_chars = max_chars;
  o.text_form = std::move(form);
  o.default_text = std::move(fallback);
  o.text_example = std::move(example);
  o.help = std::move(help);
  o.apply = [set = std::move(set)](ProtocolOptions& p, const OptionValue& v) { set(p, as_choice(v)); };
  return o;
}

// The GNSS receiver's error rows (drivers/gnss_fix.hpp GnssErrorConfig;
// bounds of core/aiding/gnss.hpp validate): per axis, 1 sigma, local NED.
// One set for every protocol that sends a GNSS fix: nmea and ubx (keys as
// they are), mavlink2's HIL_GPS (keys prefixed gps_). Vertical velocity
// only where the wire carries it.
void add_gnss_error_rows(std::vector<ProtocolOption>& t, const std::string& p, const std::string& prefix,
                         const std::string& help_prefix, bool vertical_velocity) {
  const auto sigma = [&](const char* key, const char* help, double GnssErrorConfig::*field) {
    t.push_back(number(p, prefix + key, 0.0, aiding::kGnssMaxSigma_m, false, "0", help_prefix + help,
                       [field](ProtocolOptions& o, double v) { o.stream.gnss.errors.*field = v; }));
  };
  const auto tau = [&](const char* key, const char* help, double GnssErrorConfig::*field) {
    t.push_back(number(p, prefix + key, sensor::kMinTauS, sensor::kMaxTauS, false, "60", help_prefix + help,
                       [field](ProtocolOptions& o, double v) { o.stream.gnss.errors.*field = v; }));
  };
  const auto velocity = [&](const char* key, const char* help, double GnssErrorConfig::*field) {
    t.push_back(number(p, prefix + key, 0.0, aiding::kGnssMaxVelocitySigma_m_s, false, "0", help_prefix + help,
                       [field](ProtocolOptions& o, double v) { o.stream.gnss.errors.*field = v; }));
  };
  sigma("horizontal_white_m", "position white noise, north and east each (m, 1 sigma per fix)",
        &GnssErrorConfig::horizontal_white_m);
  sigma("horizontal_gm_sigma_m", "position first-order Gauss-Markov error, north and east each (m, stationary sigma)",
        &GnssErrorConfig::horizontal_gm_sigma_m);
  tau("horizontal_gm_tau_s", "correlation time of the horizontal Gauss-Markov error (s)",
      &GnssErrorConfig::horizontal_gm_tau_s);
  sigma("vertical_white_m", "height white noise (m, 1 sigma per fix)", &GnssErrorConfig::vertical_white_m);
  sigma("vertical_gm_sigma_m", "height first-order Gauss-Markov error (m, stationary sigma)",
        &GnssErrorConfig::vertical_gm_sigma_m);
  tau("vertical_gm_tau_s", "correlation time of the vertical Gauss-Markov error (s)",
      &GnssErrorConfig::vertical_gm_tau_s);
  velocity("horizontal_velocity_m_s", "velocity white noise, north and east each (m/s, 1 sigma per fix)",
           &GnssErrorConfig::horizontal_velocity_m_s);
  if (vertical_velocity)
    velocity("vertical_velocity_m_s", "vertical velocity white noise (m/s, 1 sigma per fix)",
             &GnssErrorConfig::vertical_velocity_m_s);
}

std::vector<ProtocolOption> make_table() {
  std::vector<ProtocolOption> t;
  // ---- native (docs/native-protocol.md)
  t.push_back(boolean("native", "include_deltas", true, "send delta-theta / delta-velocity as well as the rates",
                      [](ProtocolOptions& p, bool v) { p.stream.include_deltas = v; }));

  // ---- mavlink2 (mavlink2.hpp; MAVLink guide: 0 is not a valid source id)
  t.push_back(integer("mavlink2", "system_id", 1, 255, "1", "source system id (0 is broadcast)",
                      [](ProtocolOptions& p, std::int64_t v) { p.stream.mavlink_system_id = static_cast<std::uint8_t>(v); }));
  t.push_back(integer("mavlink2", "component_id", 1, 255, "200", "source component id (200 = MAV_COMP_ID_IMU)",
                      [](ProtocolOptions& p, std::int64_t v) { p.stream.mavlink_component_id = static_cast<std::uint8_t>(v); }));
  t.push_back(boolean("mavlink2", "heartbeat", true, "HEARTBEAT (MAV_TYPE_IMU, MAV_AUTOPILOT_INVALID) at 1 Hz",
                      [](ProtocolOptions& p, bool v) { p.stream.mavlink_heartbeat = v; }));
  t.push_back(boolean("mavlink2", "hil_sensor", true, "HIL_SENSOR (#107) per sample",
                      [](ProtocolOptions& p, bool v) { p.stream.mavlink_hil_sensor = v; }));
  t.push_back(boolean("mavlink2", "highres_imu", false, "HIGHRES_IMU (#105) per sample; at least one of the two",
                      [](ProtocolOptions& p, bool v) { p.stream.mavlink_highres_imu = v; }));
  t.push_back(integer("mavlink2", "sensor_id", 0, 255, "0", "the messages' `id` field",
                      [](ProtocolOptions& p, std::int64_t v) { p.stream.mavlink_sensor_id = static_cast<std::uint8_t>(v); }));
  t.push_back(number("mavlink2", "temperature_degC", -273.15, 1000.0, false, "not sent",
                     "`temperature` field (degC, fields_updated bit 12)",
                     [](ProtocolOptions& p, double v) { p.stream.mavlink_temperature_degC = v; }));
  // Issue 28: the barometer and magnetometer groups and HIL_GPS (an ecef
  // scene; mavlink2.hpp, docs/mavlink-device.md).
  t.push_back(boolean("mavlink2", "baro", false,
                      "abs_pressure (hPa) and pressure_alt (m) from the ISA atmosphere at the trajectory's height, "
                      "fields_updated bits 9, 11 and 12 (temperature)",
                      [](ProtocolOptions& p, bool v) { p.stream.mavlink_baro = v; }));
  t.push_back(boolean("mavlink2", "mag", false,
                      "x/y/zmag (gauss, sensor axes): the WMM2025 field at the position and date, fields_updated bits 6..8",
                      [](ProtocolOptions& p, bool v) { p.stream.mavlink_mag = v; }));
  t.push_back(integer("mavlink2", "hil_gps_rate_hz", 0, 50, "0",
                      "HIL_GPS (#113) per second, on the trajectory-time grid (0: not sent); at most the device's rate",
                      [](ProtocolOptions& p, std::int64_t v) { p.stream.mavlink_hil_gps_rate_hz = v; }));
  t.push_back(number("mavlink2", "date_at_t0_year", 2025.0, 2030.0, false, "2026.0",
                     "decimal year of trajectory time 0: the date of the magnetic field (WMM2025 is valid 2025..2030)",
                     [](ProtocolOptions& p, double v) { p.stream.mavlink_date_at_t0_year = v; }));
  t.push_back(number("mavlink2", "geoid_undulation_m", -200.0, 200.0, false, "0.0",
                     "geoid above the ellipsoid (no geoid model is carried): mean sea level for the atmosphere and "
                     "HIL_GPS alt is the ellipsoidal height minus this",
                     [](ProtocolOptions& p, double v) { p.stream.gnss.geoid_separation_m = v; }));
  t.push_back(number("mavlink2", "baro_noise_rms_pa", 0.0, 1000.0, false, "0.0",
                     "barometer white noise per sample (Pa RMS; MS5611 at OSR 4096: 1.2)",
                     [](ProtocolOptions& p, double v) { p.stream.mavlink_baro_noise_rms_pa = v; }));
  t.push_back(number("mavlink2", "baro_bias_pa", -10000.0, 10000.0, false, "0.0",
                     "barometer fixed offset (Pa; datasheets' absolute accuracy, BMP280 +-100)",
                     [](ProtocolOptions& p, double v) { p.stream.mavlink_baro_bias_pa = v; }));
  t.push_back(number("mavlink2", "mag_noise_rms_ut", 0.0, 1000.0, false, "0.0",
                     "magnetometer white noise per sample and axis (uT RMS; LIS3MDL at +-4 G: 0.32)",
                     [](ProtocolOptions& p, double v) { p.stream.mavlink_mag_noise_rms_ut = v; }));
  t.push_back(integer("mavlink2", "gps_satellites", 0, 254, "12", "HIL_GPS satellites_visible (255 means unknown)",
                      [](ProtocolOptions& p, std::int64_t v) { p.stream.gnss.satellites = static_cast<int>(v); }));
  t.push_back(number("mavlink2", "gps_hdop", 0.0, 99.0, true, "0.7", "HIL_GPS eph: horizontal dilution of precision (sent x 100)",
                     [](ProtocolOptions& p, double v) { p.stream.gnss.hdop = v; }));
  t.push_back(number("mavlink2", "gps_vdop", 0.0, 99.0, true, "1.0", "HIL_GPS epv: vertical dilution of precision (sent x 100)",
                     [](ProtocolOptions& p, double v) { p.stream.gnss.vdop = v; }));
  // HIL_GPS's position and velocity errors: the GNSS receivers' (one
  // source, drivers/gnss_fix.hpp GnssFixSource, fix j = the j-th HIL_GPS
  // instant), seeded by the device's seed as the barometer and magnetometer
  // (no key of their own: stream_protocols.hpp aiding_seed).
  add_gnss_error_rows(t, "mavlink2", "gps_", "HIL_GPS ", true);

  // ---- mip (mip.hpp)
  t.push_back(boolean("mip", "include_deltas", true, "delta-theta / delta-velocity fields (0x80, 0x07 / 0x08)",
                      [](ProtocolOptions& p, bool v) { p.stream.include_deltas = v; }));
  t.push_back(choice("mip", "time_base", {"unknown", "gps", "utc"},
                     "what trajectory time is: unknown = the GPS timestamp field carries it as the device's internal "
                     "clock with the valid flags clear; gps = GPS time (+ gps_time_at_t0_ns), flagged valid; utc = "
                     "POSIX UTC, converted to GPS time with the leap seconds (default gps when gps_time_at_t0_ns is "
                     "given)",
                     [](ProtocolOptions& p, const std::string& v) {
                       p.stream.mip_time_base = v == "gps"   ? MipTimeBase::gps
                                                : v == "utc" ? MipTimeBase::utc
                                                             : MipTimeBase::unknown;
                     }));
  t.push_back(integer("mip", "gps_time_at_t0_ns", 0, kInt62, "0",
                      "time_base gps: GPS time (ns since 1980-01-06, no leap seconds) of trajectory time 0",
                      [](ProtocolOptions& p, std::int64_t v) { p.stream.mip_gps_time_at_t0_ns = v; }));
  t.push_back(integer("mip", "gps_minus_utc_s", 0, 255, "leap-second table (18 since 2017)",
                      "time_base utc: GPS - UTC in whole seconds, instead of the built-in leap-second table",
                      [](ProtocolOptions& p, std::int64_t v) { p.stream.mip_gps_minus_utc_s = static_cast<int>(v); }));
  t.push_back(boolean("mip", "overrange_status", true, "overrange status field (0x80, 0x18)",
                      [](ProtocolOptions& p, bool v) { p.stream.mip_overrange_status = v; }));
  // Issue 28: the GNSS receiver (0x81) and navigation filter (0x82) of the
  // device (mip_nav.hpp); both off by default.
  t.push_back(integer("mip", "gnss_rate_hz", 0, kMaxGnssRateHz, "0",
                      "GNSS data set 0x81 (LLH, NED velocity, fix info, GPS timestamp) at this rate, its receiver's "
                      "epochs; 0: no GNSS receiver",
                      [](ProtocolOptions& p, std::int64_t v) { p.stream.mip_nav.gnss_rate_hz = v; }));
  t.push_back(integer("mip", "filter_rate_hz", 0, 1000, "0",
                      "filter data set 0x82 (status, LLH, NED velocity, quaternion, GPS timestamp) at this rate "
                      "(at most the device rate); 0: no filter data",
                      [](ProtocolOptions& p, std::int64_t v) { p.stream.mip_nav.filter_rate_hz = v; }));
  t.push_back(choice("mip", "filter_states", {"cv7", "gx5"},
                     "filter state values (0x82,0x10): cv7 = 3DM-CV7/GQ7 (1 init, 3 AHRS, 4 full nav); gx5 = "
                     "3DM-GX5-45 (1 init, 2 running valid)",
                     [](ProtocolOptions& p, const std::string& v) {
                       p.stream.mip_nav.filter_states = v == "gx5" ? MipFilterStates::gx5 : MipFilterStates::cv7;
                     }));
  t.push_back(number("mip", "filter_alignment_s", 0.0, 3600.0, false, "5.0",
                     "time after power-up the filter initialises (attitude alignment) before it runs (s)",
                     [](ProtocolOptions& p, double v) { p.stream.mip_nav.filter_alignment_s = v; }));
  t.push_back(number("mip", "gnss_first_fix_s", 0.0, 3600.0, false, "30.0",
                     "the receiver's first 3D fix after power-up (cold-start time to first fix, s)",
                     [](ProtocolOptions& p, double v) { p.stream.mip_nav.gnss_first_fix_s = v; }));
  t.push_back(number("mip", "gnss_outage_start_s", 0.0, 1e7, false, "0.0",
                     "start of a GNSS outage (no fix) after power-up (s)",
                     [](ProtocolOptions& p, double v) { p.stream.mip_nav.gnss_outage_start_s = v; }));
  t.push_back(number("mip", "gnss_outage_duration_s", 0.0, 1e7, false, "0.0", "length of that outage (s); 0: none",
                     [](ProtocolOptions& p, double v) { p.stream.mip_nav.gnss_outage_duration_s = v; }));
  t.push_back(number("mip", "filter_roll_pitch_sigma_deg", 0.0, 90.0, false, "0.25",
                     "filter roll and pitch error (deg, 1 sigma, white per epoch; GX5-45 datasheet 0.25)",
                     [](ProtocolOptions& p, double v) { p.stream.mip_nav.filter_roll_pitch_sigma_deg = v; }));
  t.push_back(number("mip", "filter_heading_sigma_deg", 0.0, 180.0, false, "0.8",
                     "filter heading error (deg, 1 sigma; GX5-45 datasheet 0.8)",
                     [](ProtocolOptions& p, double v) { p.stream.mip_nav.filter_heading_sigma_deg = v; }));
  t.push_back(number("mip", "filter_horizontal_sigma_m", 0.0, aiding::kGnssMaxSigma_m, false, "2.5",
                     "filter position error north and east each (m, 1 sigma; GX5-45 datasheet 2.5)",
                     [](ProtocolOptions& p, double v) { p.stream.mip_nav.filter_horizontal_sigma_m = v; }));
  t.push_back(number("mip", "filter_vertical_sigma_m", 0.0, aiding::kGnssMaxSigma_m, false, "5.0",
                     "filter height error (m, 1 sigma; GX5-45 datasheet 5)",
                     [](ProtocolOptions& p, double v) { p.stream.mip_nav.filter_vertical_sigma_m = v; }));
  t.push_back(number("mip", "filter_velocity_sigma_m_s", 0.0, aiding::kGnssMaxVelocitySigma_m_s, false, "0.1",
                     "filter velocity error per axis (m/s, 1 sigma; GX5-45 datasheet 0.1)",
                     [](ProtocolOptions& p, double v) { p.stream.mip_nav.filter_velocity_sigma_m_s = v; }));
  t.push_back(integer("mip", "gnss_satellites", 0, 255, "12", "0x81,0x0B satellites used, with a fix",
                      [](ProtocolOptions& o, std::int64_t v) { o.stream.gnss.satellites = static_cast<int>(v); }));
  t.push_back(number("mip", "gnss_horizontal_accuracy_m", 0.0, 1e4, false, "1.5",
                     "0x81,0x03 horizontal accuracy (m)",
                     [](ProtocolOptions& o, double v) { o.stream.gnss.horizontal_accuracy_m = v; }));
  t.push_back(number("mip", "gnss_vertical_accuracy_m", 0.0, 1e4, false, "2.5", "0x81,0x03 vertical accuracy (m)",
                     [](ProtocolOptions& o, double v) { o.stream.gnss.vertical_accuracy_m = v; }));
  t.push_back(number("mip", "gnss_speed_accuracy_m_s", 0.0, 1e3, false, "0.05", "0x81,0x05 speed accuracy (m/s)",
                     [](ProtocolOptions& o, double v) { o.stream.gnss.speed_accuracy_m_s = v; }));
  t.push_back(number("mip", "gnss_geoid_separation_m", -200.0, 200.0, false, "0.0",
                     "geoid above the ellipsoid (no geoid model is carried): 0x81,0x03 MSL height = ellipsoidal - this",
                     [](ProtocolOptions& o, double v) { o.stream.gnss.geoid_separation_m = v; }));
  // The receiver's position and velocity errors, seeded with the device's
  // error-model seed (aiding_seed) as the filter's.
  add_gnss_error_rows(t, "mip", "gnss_", "GNSS ", true);

  // ---- nmea and ubx: a GNSS receiver (drivers/gnss_fix.hpp, nmea.hpp,
  // ubx.hpp). The rows both take, then each one's own.
  for (const char* gnss : {"nmea", "ubx"}) {
    const std::string p = gnss;
    t.push_back(choice(p, "time_base", {"gps", "utc"},
                       "what trajectory time is: gps = GPS time minus gps_time_at_t0_ns; utc = POSIX UTC, turned "
                       "into GPS time with the leap-second table",
                       [](ProtocolOptions& o, const std::string& v) {
                         o.stream.gnss.time_base = v == "utc" ? GnssTimeBase::utc : GnssTimeBase::gps;
                       }));
    t.push_back(integer(p, "gps_time_at_t0_ns", 0, kInt62, "1451520000000000000",
                        "time_base gps: GPS time (ns since 1980-01-06, no leap seconds) of trajectory time 0; the "
                        "default is GPS week 2400 TOW 0 (2026-01-04), 0 for a trajectory stamped in GPS time",
                        [](ProtocolOptions& o, std::int64_t v) { o.stream.gnss.gps_time_at_t0_ns = v; }));
    // NMEA GGA carries two digits of satellites used; UBX numSV is a U1.
    t.push_back(integer(p, "satellites", 0, p == "nmea" ? 99 : 255, "12", "satellites used in the solution",
                        [](ProtocolOptions& o, std::int64_t v) { o.stream.gnss.satellites = static_cast<int>(v); }));
    t.push_back(number(p, "pdop", 0.0, 99.0, true, "1.2", "position dilution of precision",
                       [](ProtocolOptions& o, double v) { o.stream.gnss.pdop = v; }));
    t.push_back(number(p, "hdop", 0.0, 99.0, true, "0.7", "horizontal dilution of precision",
                       [](ProtocolOptions& o, double v) { o.stream.gnss.hdop = v; }));
    t.push_back(number(p, "vdop", 0.0, 99.0, true, "1.0", "vertical dilution of precision",
                       [](ProtocolOptions& o, double v) { o.stream.gnss.vdop = v; }));
    t.push_back(number(p, "geoid_separation_m", -200.0, 200.0, false, "0.0",
                       "geoid above the ellipsoid (no geoid model is carried): MSL height = ellipsoidal height - this",
                       [](ProtocolOptions& o, double v) { o.stream.gnss.geoid_separation_m = v; }));
    // NMEA's sentences (GGA, RMC, VTG) carry no vertical velocity.
    add_gnss_error_rows(t, p, "", "", p == "ubx");
    t.push_back(integer(p, "seed", 0, std::numeric_limits<std::int64_t>::max(), "0",
                        "seed of the error terms (streams keyed by seed and device name, as the IMU's noise)",
                        [](ProtocolOptions& o, std::int64_t v) { o.stream.gnss.errors.seed = static_cast<std::uint64_t>(v); }));
  }
  t.push_back(choice("nmea", "talker", {"GP", "GN"}, "talker id: GP (GPS) or GN (multi-constellation)",
                     [](ProtocolOptions& o, const std::string& v) { o.stream.nmea_talker = v; }));
  t.push_back(number("ubx", "horizontal_accuracy_m", 0.0, 1e4, false, "1.5", "hAcc (m; with errors configured: from them, the 2-D RMS)",
                     [](ProtocolOptions& o, double v) { o.stream.gnss.horizontal_accuracy_m = v; }));
  t.push_back(number("ubx", "vertical_accuracy_m", 0.0, 1e4, false, "2.5", "vAcc (1 sigma, m; with errors configured: from them)",
                     [](ProtocolOptions& o, double v) { o.stream.gnss.vertical_accuracy_m = v; }));
  t.push_back(number("ubx", "speed_accuracy_m_s", 0.0, 1e3, false, "0.05", "sAcc (1 sigma, m/s; with errors configured: from them)",
                     [](ProtocolOptions& o, double v) { o.stream.gnss.speed_accuracy_m_s = v; }));
  t.push_back(boolean("ubx", "legacy_nav", true,
                      "NAV-POSLLH, NAV-STATUS, NAV-DOP, NAV-SOL, NAV-VELNED and NAV-TIMEGPS beside NAV-PVT",
                      [](ProtocolOptions& o, bool v) { o.stream.ubx_legacy_nav = v; }));

  // ---- vectornav (vectornav.hpp, vectornav_device.hpp, issue 29)
  t.push_back(choice("vectornav", "model", {"vn100", "vn200", "vn300"},
                     "VN-100 (AHRS, 800 Hz IMU rate), VN-200 (GNSS/INS, 800 Hz) or VN-300 (dual-GNSS INS, 400 Hz): "
                     "the rate divisors' base and the binary groups the device has",
                     [](ProtocolOptions& o, const std::string& v) {
                       o.stream.vectornav.model = v == "vn300"   ? VectorNavModel::vn300
                                                  : v == "vn200" ? VectorNavModel::vn200
                                                                 : VectorNavModel::vn100;
                     }));
  t.push_back(integer("vectornav", "power_up_ador", -1, 30, "-1",
                      "register 6 at power-up: the async ASCII output (0 off, 1 YPR, 2 QTN, 8 QMR, 10 MAG, 11 ACC, "
                      "12 GYR, 13 MAR, 14 YMR, 19 IMU, 22 INS, 30 DTV); -1: YMR, INS on a VN-200 / VN-300",
                      [](ProtocolOptions& o, std::int64_t v) { o.stream.vectornav.power_up_ador = static_cast<int>(v); }));
  t.push_back(integer("vectornav", "power_up_adof_hz", 1, 200, "40",
                      "register 7 at power-up: the async ASCII output rate (1, 2, 4, 5, 10, 20, 25, 40, 50, 100 or 200 Hz)",
                      [](ProtocolOptions& o, std::int64_t v) {
                        o.stream.vectornav.power_up_adof_hz = static_cast<std::uint16_t>(v);
                      }));

  // Identity (what the driver reads and may check) and the settings saved in
  // the device's flash ($VNWNV): a bench sets them to the unit it replaces.
  t.push_back(text("vectornav", "model_number", 24, "a model number", "\"\"", "VN-100S-CR",
                   "register 1, the model number (no , * or $); empty: the model's (VN-100T-CR, VN-200T-CR, "
                   "VN-300T-CR)",
                   [](ProtocolOptions& o, const std::string& v) { o.stream.vectornav.model_number = v; }));
  t.push_back(integer("vectornav", "serial_number", 0, 4294967295LL, "100012345", "register 3, the serial number",
                      [](ProtocolOptions& o, std::int64_t v) {
                        o.stream.vectornav.serial_number = static_cast<std::uint32_t>(v);
                      }));
  t.push_back(integer("vectornav", "port", 1, 2, "1",
                      "the device's serial port this line is (registers 5-7 read and written without a port name "
                      "it; a binary output streams here when its async mode has this port's bit)",
                      [](ProtocolOptions& o, std::int64_t v) { o.stream.vectornav.port = static_cast<std::uint8_t>(v); }));
  t.push_back(text("vectornav", "saved_registers", 1000, "register writes ID,VALUES separated by ;", "\"\"",
                   "6,0;75,1,4,01,0121",
                   "settings saved in the device ($VNWRG bodies then $VNWNV): applied at power-up and by $VNRST, "
                   "each checked as the device checks the write (e.g. 75,1,4,01,0121: binary output 1 on port 1 at "
                   "the IMU rate / 4, common group time, rates, acceleration); $VNRFS restores the factory's",
                   [](ProtocolOptions& o, const std::string& v) { o.stream.vectornav.saved_registers = v; }));

  // ---- sbg (sbg.hpp, sbg_device.hpp, issue 29)
  t.push_back(choice("sbg", "model", {"ellipse_n", "ellipse_d", "ellipse_a"},
                     "ELLIPSE-N (INS, one GNSS antenna), ELLIPSE-D (INS, dual antenna) or ELLIPSE-A (AHRS: no GNSS, "
                     "EKF_NAV or GPS1 logs): the logs the device has and its product code",
                     [](ProtocolOptions& o, const std::string& v) {
                       o.stream.sbg.model = v == "ellipse_a"   ? SbgModel::ellipse_a
                                            : v == "ellipse_d" ? SbgModel::ellipse_d
                                                               : SbgModel::ellipse_n;
                     }));
  t.push_back(boolean("sbg", "outputs_at_power_up", true,
                      "send the factory logs from power-up (STATUS, UTC_TIME, IMU_SHORT, MAG, EKF_EULER, EKF_QUAT; "
                      "EKF_NAV, GPS1_VEL, GPS1_POS on an INS); false: nothing until the driver configures outputs",
                      [](ProtocolOptions& o, bool v) { o.stream.sbg.outputs_at_power_up = v; }));
  t.push_back(text("sbg", "product_code", 31, "a product code", "\"\"", "ELLIPSE2-N-G4A2-B1",
                   "CMD_INFO and GET /api/v1/info product code (no spaces, \" or \\); empty: the model's "
                   "(ELLIPSE-N-G4A3-B1, ELLIPSE-D-G4A3-B1, ELLIPSE-A-G4A3-B1)",
                   [](ProtocolOptions& o, const std::string& v) { o.stream.sbg.product_code = v; }));
  t.push_back(integer("sbg", "serial_number", 0, 999999999, "45000123",
                      "CMD_INFO serial number (GET /api/v1/info: nine digits)",
                      [](ProtocolOptions& o, std::int64_t v) { o.stream.sbg.serial_number = static_cast<std::uint32_t>(v); }));
  t.push_back(text("sbg", "saved_outputs", 1000, "NAME=RATE pairs separated by ,", "\"\"",
                   "imuData=5ms,imuShort=disabled",
                   "output settings saved in the device (port A, REST API names and rates: imuShort, imuData, "
                   "imuFast, mag, ekfEuler, ekfQuat, ekfNav, gps1Vel, gps1Pos, utcTime, status; 5ms ... 1000ms, "
                   "newData, pps, disabled): over the factory logs at power-up and after a reboot; restoring "
                   "the factory settings drops them",
                   [](ProtocolOptions& o, const std::string& v) { o.stream.sbg.saved_outputs = v; }));
  // ---- xsens (xsens.hpp, xsens_device.hpp, issue 29)
  t.push_back(choice("xsens", "model", {"mti630", "mti3", "mti7", "mti680g", "mti-g-710"},
                     "MTi-630 (AHRS, 400 Hz), MTi-3 (AHRS, 100 Hz), MTi-7 (GNSS/INS, 100 Hz), MTi-680G (RTK GNSS/INS, "
                     "400 Hz) or MTi-G-710 (GNSS/INS, 400 Hz): the identity presets (device id, product code, "
                     "firmware), the maximum rate the output rates divide and the outputs the device has",
                     [](ProtocolOptions& o, const std::string& v) {
                       o.stream.xsens.model = v == "mti3"        ? XsensModel::mti3
                                              : v == "mti7"      ? XsensModel::mti7
                                              : v == "mti680g"   ? XsensModel::mti680g
                                              : v == "mti-g-710" ? XsensModel::mti_g710
                                                                 : XsensModel::mti630;
                     }));
  t.push_back(integer("xsens", "device_id", 0, 4294967295LL, "0",
                      "ReqDID, the device id (0: the model's preset, 0x0080001A2D on an MTi-630; on the MTi-600 models, which "
                      "report a 64-bit id, this is its low 32 bits)",
                      [](ProtocolOptions& o, std::int64_t v) { o.stream.xsens.device_id = static_cast<std::uint32_t>(v); }));
  t.push_back(text("xsens", "product_code", 20, "a product code", "\"\"", "MTi-630R-8A1G6",
                   "ReqProductCode; empty: the model's (MTi-630-8A1G6, MTi-3-8A7G6, MTi-7-8A7G6, MTi-680G-8A1G6, "
                   "MTi-G-710-2A8G4)",
                   [](ProtocolOptions& o, const std::string& v) { o.stream.xsens.product_code = v; }));

  // ---- dronecan (dronecan.hpp)
  t.push_back(integer("dronecan", "node_id", 1, 127, "42", "source node id, unique per CAN interface",
                      [](ProtocolOptions& p, std::int64_t v) { p.can.dronecan.node_id = static_cast<std::uint8_t>(v); }));
  t.push_back(integer("dronecan", "raw_imu_priority", 0, 31, "8", "RawIMU transfer priority (lower is more urgent)",
                      [](ProtocolOptions& p, std::int64_t v) { p.can.dronecan.raw_imu_priority = static_cast<std::uint8_t>(v); }));
  t.push_back(integer("dronecan", "node_status_priority", 0, 31, "24", "NodeStatus transfer priority",
                      [](ProtocolOptions& p, std::int64_t v) {
                        p.can.dronecan.node_status_priority = static_cast<std::uint8_t>(v);
                      }));
  t.push_back(number("dronecan", "node_status_period_s", 0.0, 1.0, true, "1.0",
                     "NodeStatus period (s; DSDL MAX_BROADCASTING_PERIOD_MS = 1000)", [](ProtocolOptions& p, double v) {
                       p.can.dronecan.node_status_period_ns = static_cast<TimeNs>(std::llround(v * 1e9));
                     }));
  t.push_back(integer("dronecan", "timestamp_offset_ns", -kInt62, kInt62, "0",
                      "added to the sample time in RawIMU timestamp.usec",
                      [](ProtocolOptions& p, std::int64_t v) { p.can.dronecan.timestamp_offset_ns = v; }));
  t.push_back(boolean("dronecan", "send_integrals", true, "delta-theta / delta-velocity as the RawIMU integrals",
                      [](ProtocolOptions& p, bool v) { p.can.dronecan.send_integrals = v; }));

  // ---- j1939 (j1939.hpp)
  t.push_back(integer("j1939", "source_address", 0, 253, "128",
                      "source address, unique per CAN interface (254 null, 255 global)",
                      [](ProtocolOptions& p, std::int64_t v) { p.can.j1939.source_address = static_cast<std::uint8_t>(v); }));
  t.push_back(integer("j1939", "priority", 0, 7, "3", "CAN id priority of the three PGNs",
                      [](ProtocolOptions& p, std::int64_t v) { p.can.j1939.priority = static_cast<std::uint8_t>(v); }));
  t.push_back(boolean("j1939", "send_angular_rate", true, "Angular Rate Information (PGN 61482)",
                      [](ProtocolOptions& p, bool v) { p.can.j1939.send_angular_rate = v; }));
  t.push_back(boolean("j1939", "send_acceleration", true, "Acceleration Sensor (PGN 61485)",
                      [](ProtocolOptions& p, bool v) { p.can.j1939.send_acceleration = v; }));
  t.push_back(boolean("j1939", "send_slope", false,
                      "Slope Sensor Information 2 (PGN 61481): pitch and roll of the sensor; at least one of the three",
                      [](ProtocolOptions& p, bool v) { p.can.j1939.send_slope = v; }));
  t.push_back(number("j1939", "measurement_latency_ms", 0.0, 125.0, false, "not available",
                     "ARI / SSI2 byte 8 (SPN 4989 / 4982, 0.5 ms/bit)",
                     [](ProtocolOptions& p, double v) { p.can.j1939.measurement_latency_ms = v; }));
  t.push_back(choice("j1939", "axes", {"j1939da", "iso8855", "sae-j670e"},
                     "vehicle axes on the wire: j1939da = the SPN definitions (ARI, SSI2 z down; ACCS z up), iso8855 "
                     "= all z up, sae-j670e = all z down",
                     [](ProtocolOptions& p, const std::string& v) {
                       p.can.j1939.axes = v == "iso8855"     ? j1939::VehicleAxes::kIso8855ZUp
                                          : v == "sae-j670e" ? j1939::VehicleAxes::kSaeJ670eZDown
                                                             : j1939::VehicleAxes::kJ1939da;
                     }));
  return t;
}

std::string join_choices(const std::vector<std::string>& names) {
  std::string s;
  for (std::size_t i = 0; i < names.size(); ++i) {
    if (i > 0) s += (i + 1 == names.size()) ? " or " : ", ";
    s += names[i];
  }
  return s;
}

}  // namespace

const std::vector<ProtocolOption>& protocol_option_table() {
  static const std::vector<ProtocolOption> table = make_table();
  return table;
}

std::vector<const ProtocolOption*> protocol_options_of(const std::string& protocol) {
  std::vector<const ProtocolOption*> rows;
  for (const ProtocolOption& o : protocol_option_table())
    if (o.protocol == protocol) rows.push_back(&o);
  return rows;
}

std::string protocol_option_table_name(const std::string& protocol) {
  return protocol == "mavlink2" ? "mavlink" : protocol;
}

std::string command_line_flag(const ProtocolOption& option) {
  std::string key = option.key;
  for (char& c : key)
    if (c == '_') c = '-';
  return "--" + protocol_option_table_name(option.protocol) + "-" + key;
}

std::string allowed_text(const ProtocolOption& option) {
  switch (option.type) {
    case OptionType::boolean:
      return "true or false";
    case OptionType::integer:
      return "an integer in " + std::to_string(option.integer_min) + ".." + std::to_string(option.integer_max);
    case OptionType::number: {
      std::ostringstream range;
      range << "a number in " << (option.number_min_open ? "(" : "[") << option.number_min << ", " << option.number_max
            << "]";
      return range.str();
    }
    case OptionType::choice:
      return "one of " + join_choices(option.choices);
    case OptionType::text:
      return option.text_form + ", at most " + std::to_string(option.text_max_chars) + " printable characters";
  }
  return "";
}

std::optional<std::string> text_problem(const ProtocolOption& option, const std::string& text) {
  if (text.size() > option.text_max_chars)
    return "has " + std::to_string(text.size()) + " characters, more than " + std::to_string(option.text_max_chars);
  for (const char c : text)
    if (c < ' ' || c > '~') return "has a character that is not printable ASCII";
  return std::nullopt;
}

OptionValue parse_option_text(const ProtocolOption& option, const std::string& text) {
  auto refuse = [&](const std::string& why) -> std::invalid_argument {
    return std::invalid_argument("'" + text + "' " + why + "; expected " + allowed_text(option));
  };
  switch (option.type) {
    case OptionType::boolean:
      if (text == "true" || text == "1" || text == "yes" || text == "on") return true;
      if (text == "false" || text == "0" || text == "no" || text == "off") return false;
      throw refuse("is not a boolean");
    case OptionType::integer: {
      std::int64_t v = 0;
      const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
      if (text.empty() || ec != std::errc() || end != text.data() + text.size()) throw refuse("is not an integer");
      if (v < option.integer_min || v > option.integer_max) throw refuse("is out of range");
      return v;
    }
    case OptionType::number: {
      double v = 0.0;
      const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
      if (text.empty() || ec != std::errc() || end != text.data() + text.size() || !std::isfinite(v))
        throw refuse("is not a finite number");
      if (v < option.number_min || v > option.number_max || (option.number_min_open && v == option.number_min))
        throw refuse("is out of range");
      return v;
    }
    case OptionType::choice:
      for (const std::string& c : option.choices)
        if (c == text) return text;
      throw refuse("is not allowed");
    case OptionType::text:
      if (const std::optional<std::string> why = text_problem(option, text)) throw refuse(*why);
      return text;
  }
  throw refuse("is not understood");
}

ProtocolOptions default_protocol_options(double rate_hz) {
  ProtocolOptions p;
  p.stream.nominal_sample_rate_hz = rate_hz;
  return p;
}

std::optional<OptionProblem> finish_protocol_options(const std::string& protocol, ProtocolOptions& options,
                                                     const std::set<std::string>& given) {
  const auto has = [&given](const char* key) { return given.count(key) != 0; };
  if (protocol == "mavlink2" && !options.stream.mavlink_hil_sensor && !options.stream.mavlink_highres_imu)
    return OptionProblem{has("hil_sensor") ? "hil_sensor" : "highres_imu",
                         "with hil_sensor and highres_imu both false no sample is sent; enable at least one"};
  if (protocol == "mavlink2" && options.stream.nominal_sample_rate_hz > 0.0 &&
      static_cast<double>(options.stream.mavlink_hil_gps_rate_hz) > options.stream.nominal_sample_rate_hz)
    return OptionProblem{"hil_gps_rate_hz", "is above the device's rate_hz: HIL_GPS goes out with a sample"};
  if (protocol == "mip") {
    StreamEncoderOptions& s = options.stream;
    // gps_time_at_t0_ns states a GPS time base by itself.
    if (has("gps_time_at_t0_ns") && !has("time_base")) s.mip_time_base = MipTimeBase::gps;
    if (has("gps_time_at_t0_ns") && s.mip_time_base != MipTimeBase::gps)
      return OptionProblem{"gps_time_at_t0_ns", "applies to time_base = \"gps\" only"};
    if (has("gps_minus_utc_s") && s.mip_time_base != MipTimeBase::utc)
      return OptionProblem{"gps_minus_utc_s", "applies to time_base = \"utc\" only"};
  }
  if (protocol == "ubx" && options.stream.gnss.errors.any()) {
    // With errors configured, the accuracy a receiver reports is what they
    // are (aiding::stated_accuracy: hAcc the 2-D RMS of the horizontal
    // terms, vAcc and sAcc 1 sigma), unless stated otherwise.
    const GnssErrorConfig& e = options.stream.gnss.errors;
    aiding::GnssSpec spec;
    spec.horizontal_white_m = e.horizontal_white_m;
    spec.horizontal_gm_sigma_m = e.horizontal_gm_sigma_m;
    spec.vertical_white_m = e.vertical_white_m;
    spec.vertical_gm_sigma_m = e.vertical_gm_sigma_m;
    spec.horizontal_velocity_m_s = e.horizontal_velocity_m_s;
    spec.vertical_velocity_m_s = e.vertical_velocity_m_s;
    const aiding::GnssAccuracy a = aiding::stated_accuracy(spec);
    GnssReceiverConfig& g = options.stream.gnss;
    if (!has("horizontal_accuracy_m")) g.horizontal_accuracy_m = a.horizontal_m;
    if (!has("vertical_accuracy_m")) g.vertical_accuracy_m = a.vertical_m;
    if (!has("speed_accuracy_m_s")) g.speed_accuracy_m_s = a.speed_m_s;
  }
  if (protocol == "vectornav" || protocol == "sbg" || protocol == "xsens") {
    // The devices check their identity and saved settings themselves
    // (stream_protocols.cpp, as the device checks a driver's write); the
    // refusal names the key it is about.
    try {
      (void)make_stream_encoder(protocol, options.stream);
    } catch (const std::invalid_argument& e) {
      const std::string what = e.what();
      for (const ProtocolOption* row : protocol_options_of(protocol))
        if (given.count(row->key) != 0 && what.find(row->key) != std::string::npos) return OptionProblem{row->key, what};
      if (!given.empty()) return OptionProblem{*given.begin(), what};
    }
  }
  if (protocol == "j1939") {
    const j1939::J1939Options& j = options.can.j1939;
    if (!j.send_angular_rate && !j.send_acceleration && !j.send_slope)
      return OptionProblem{"send_angular_rate",
                           "send_angular_rate, send_acceleration and send_slope are all false; nothing would be sent"};
  }
  return std::nullopt;
}

}  // namespace imuemu::drivers
