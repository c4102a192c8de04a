// One GNSS navigation epoch, as a receiver personality (NMEA 0183, u-blox
// UBX: drivers/protocols/nmea.hpp, ubx.hpp) puts it on the wire (issue 28).
// Kept small and protocol-free so that it can be filled from the truth
// trajectory (errors off: fix_from_frame below) and, later, from the GNSS
// error model (position/velocity noise, outages, degraded fixes) without the
// encoders knowing which.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "core/aiding/gnss.hpp"
#include "core/types.hpp"
#include "drivers/protocol.hpp"

namespace imuemu::drivers {

enum class GnssFixType : std::uint8_t {
  none,     // no fix: position and velocity not valid
  fix_2d,   // 2D fix (height held)
  fix_3d,   // 3D fix
};

struct GnssFix {
  // The epoch: GPS time, ns since 1980-01-06T00:00:00 (IS-GPS-200, no leap
  // seconds); UTC = GPS - gps_minus_utc_s (drivers/protocols/gps_time.hpp).
  std::int64_t gps_time_ns = 0;
  int gps_minus_utc_s = 18;
  // false: the receiver does not know the time (the epoch is before the GPS
  // epoch on the configured time base): time fields sent empty / flagged
  // invalid, and no fix.
  bool time_valid = true;
  GnssFixType fix_type = GnssFixType::none;
  // WGS84 geodetic position of the antenna; height above the ellipsoid.
  double latitude_rad = 0.0;
  double longitude_rad = 0.0;
  double height_m = 0.0;
  // Geoid separation N (geoid above the ellipsoid): height above mean sea
  // level = height_m - N. No geoid model is carried: 0 unless configured,
  // and then what GGA and NAV-PVT report as MSL height is the ellipsoidal one
  // minus this constant.
  double geoid_separation_m = 0.0;
  Vec3 velocity_ned_m_s = Vec3::Zero();  // north, east, down
  int satellites = 0;                    // used in the solution
  double pdop = 0.0, hdop = 0.0, vdop = 0.0;
  // 1-sigma accuracy estimates as u-blox reports them (hAcc, vAcc, sAcc, tAcc).
  double horizontal_accuracy_m = 0.0;
  double vertical_accuracy_m = 0.0;
  double speed_accuracy_m_s = 0.0;
  double time_accuracy_ns = 0.0;
  // Time since the receiver started (ms, NAV-STATUS msss) and its time to
  // first fix (ttff).
  std::uint32_t since_start_ms = 0;
  std::uint32_t time_to_first_fix_ms = 0;
};

// The receiver's position and velocity errors (issue 28; the model is
// core/aiding/gnss.hpp, in the units receiver datasheets use): per axis in
// the local NED at the antenna, horizontal (north, east) and vertical apart,
// white noise plus a first-order Gauss-Markov process (stationary sigma,
// correlation time), and white velocity noise. All zero (the default): the
// receiver reports the trajectory itself, bit for bit as before the errors
// existed. Seeded as the IMU's noise: streams keyed by (seed, device name,
// sensor 18, axis, term).
struct GnssErrorConfig {
  double horizontal_white_m = 0.0;
  double horizontal_gm_sigma_m = 0.0;
  double horizontal_gm_tau_s = 60.0;
  double vertical_white_m = 0.0;
  double vertical_gm_sigma_m = 0.0;
  double vertical_gm_tau_s = 60.0;
  double horizontal_velocity_m_s = 0.0;
  double vertical_velocity_m_s = 0.0;
  std::uint64_t seed = 0;
  bool any() const {
    return horizontal_white_m > 0.0 || horizontal_gm_sigma_m > 0.0 || vertical_white_m > 0.0 ||
           vertical_gm_sigma_m > 0.0 || horizontal_velocity_m_s > 0.0 || vertical_velocity_m_s > 0.0;
  }
};

// How trajectory time becomes GPS time for a GNSS receiver, and the figures
// an error-free receiver reports (scene keys [imu.nmea] / [imu.ubx]).
enum class GnssTimeBase : std::uint8_t {
  gps,  // GPS time = gps_time_at_t0_ns + t_ns
  utc,  // t_ns is POSIX UTC; GPS time with the leap-second table
};

struct GnssReceiverConfig {
  GnssTimeBase time_base = GnssTimeBase::gps;
  // Default: GPS week 2400, TOW 0 (2026-01-04T00:00:00 GPS time), a whole
  // GPS second, so that a trajectory starting at a whole second has its
  // epochs on the top of the GPS second. 0: trajectory time is GPS time.
  std::int64_t gps_time_at_t0_ns = 2400LL * 604'800LL * 1'000'000'000LL;
  // GPS - UTC (s); empty: the leap-second table at the epoch.
  std::optional<int> gps_minus_utc_s;
  int satellites = 12;
  double pdop = 1.2, hdop = 0.7, vdop = 1.0;
  double horizontal_accuracy_m = 1.5, vertical_accuracy_m = 2.5, speed_accuracy_m_s = 0.05,
         time_accuracy_ns = 20.0;
  double geoid_separation_m = 0.0;
  GnssErrorConfig errors;
};

// The epoch of one device sample (the GNSS device's grid is its epochs):
// the sample's navigation fields (ImuFrameInput::has_navigation) with the
// receiver's configured figures, at the sample's time on the GPS scale. No
// navigation fields (a flat scene has no geodetic position): fix_type none.
// A time that does not map to GPS time (before the GPS epoch): time_valid
// false and no fix.
GnssFix fix_from_frame(const ImuFrameInput& frame, const GnssReceiverConfig& config);

// What a GNSS encoder reports per device sample: fix_from_frame, then, when
// config.errors has any term, the error of fix j = the sample's counter
// (aiding::GnssReceiverModel::error: a fix's error depends on its index, not
// on which fixes were sent) added to the position (a NED offset at the
// antenna, through ECEF: aiding::offset_geodetic) and the NED velocity.
// The Gauss-Markov terms are discretised at the whole-millisecond period
// nearest the device's (u-blox CFG-RATE measRate is in ms): exact at 1, 2,
// 4, 5, 8 and 10 Hz, 1e-3 of a period off at 3, 6, 7 and 9 Hz.
// Construction throws SettingError (key: the field) for an error term out
// of core/aiding/gnss.hpp's bounds, std::invalid_argument for errors without
// a device rate (rate_hz <= 0). fix() allocates nothing; the same fix again
// (a link fault's duplicate) has the same error; a fix index that goes
// further back (a restarted stream) restarts the error sequence from its
// initial state, so fix j's error is the same whatever came before.
// device_name: the device's name (StreamEncoderOptions::device_name: the
// scene's [[imu]] name; emit: imu0), part of the error streams' key, so two
// receivers of one scene err independently.
// Users: the NMEA and UBX receivers (fix j = the device's sample counter)
// and MAVLink HIL_GPS (fix j = the count of HIL_GPS instants, mavlink2.hpp).
class GnssFixSource {
 public:
  GnssFixSource(const GnssReceiverConfig& config, double rate_hz, const std::string& device_name);
  // Fix j = frame.sample_counter (the receiver's epochs are its samples).
  GnssFix fix(const ImuFrameInput& frame) { return fix(frame, frame.sample_counter); }
  // Fix j of a source whose epochs are not the frame's samples.
  GnssFix fix(const ImuFrameInput& frame, std::uint64_t j);
  const GnssReceiverConfig& config() const { return config_; }

 private:
  GnssReceiverConfig config_;
  std::optional<aiding::GnssReceiverModel> initial_, model_;
  std::optional<std::uint64_t> last_j_;  // the last fix's index and error
  aiding::GnssError last_error_;
};

}  // namespace imuemu::drivers
