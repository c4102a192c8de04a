// The MIP device's GNSS data set 0x81 and navigation filter data set 0x82
// (issue 28), written from the MIP DCP manuals (no SDK code):
//
//  [G] 3DM-GX5-45 DCP manual, GNSS data set 0x81: LLH Position 0x03 (double
//      latitude, longitude [deg], height above ellipsoid, height above MSL
//      [m], float horizontal and vertical accuracy [m], u16 valid flags:
//      lat/lon 0x1, ellipsoid height 0x2, MSL height 0x4, horizontal
//      accuracy 0x8, vertical accuracy 0x10); NED Velocity 0x05 (float
//      north, east, down, speed, ground speed [m/s], heading [deg], speed
//      accuracy [m/s], heading accuracy [deg], u16 valid flags: NED 0x1,
//      speed 0x2, ground speed 0x4, heading 0x8, speed accuracy 0x10,
//      heading accuracy 0x20); GPS Time 0x09 (double tow [s], u16 week, u16
//      valid flags: tow 0x1, week 0x2); Fix Information 0x0B (u8 fix type:
//      0 3D, 1 2D, 2 time only, 3 none, 4 invalid; u8 satellites; u16 fix
//      flags: SBAS 0x1, differential 0x2; u16 valid flags: fix type 0x1,
//      satellites 0x2, fix flags 0x4).
//  [E] Estimation filter data set 0x82: LLH Position 0x01 (double latitude,
//      longitude [deg], ellipsoid height [m], u16 valid 1), NED Velocity
//      0x02 (float N, E, D [m/s], u16 valid), Attitude Quaternion 0x03
//      (float q0 (w) .. q3, the sensor (vehicle) frame relative to NED:
//      v_ned = q v_vehicle q*, u16 valid), LLH Position Uncertainty 0x08
//      (float N, E, D [m], 1 sigma, u16 valid), NED Velocity Uncertainty
//      0x09 (float N, E, D [m/s], u16 valid), Euler Angle Uncertainty 0x0A
//      (float roll, pitch, yaw [rad], u16 valid), Filter Status 0x10 (u16
//      filter state, u16 dynamics mode, u16 status flags).
//  [S] Shared data field GPS Timestamp 0xD3, in every data set (double tow
//      [s], u16 week, u16 valid flags: tow 0x1, week 0x2).
//  [M] Filter states and status flags (3DM-GX5-45 DCP 0x82,0x10; 3DM-CV7 /
//      GQ7 DCP 0x82,0x10): GX5 0 startup, 1 initialisation, 2 running
//      solution valid, 3 running solution error; flags init no attitude
//      0x1000, init no position/velocity 0x2000, running GNSS unavailable
//      0x0002. CV7/GQ7: 1 initialisation, 2 vertical gyro, 3 AHRS, 4 full
//      navigation. Dynamics mode 1 (GX5 portable, CV7 default).
//
// The device's state machine (times since power-up, the stream's sample 0):
//   GNSS: no fix until gnss_first_fix_s (cold start), then a 3D fix at each
//     receiver epoch, except in the outage [start, start + duration).
//   filter (cv7): init until filter_alignment_s; then full navigation while
//     the latest GNSS epoch has a 3D fix, AHRS otherwise (before the first
//     fix and in an outage).
//   filter (gx5): init until aligned and the first fix (flags say which is
//     missing), then running solution valid, with the GNSS-unavailable flag
//     while the latest epoch has no fix (the GX5-45 dead-reckons).
// Position and velocity of the filter are valid (flag 1) while it navigates
// with GNSS; otherwise the last valid ones are repeated with the flag clear
// (zeros before the first). No dead-reckoning error growth is modelled.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "drivers/gnss_fix.hpp"
#include "drivers/protocols/mip_device.hpp"
#include "drivers/protocols/stream_protocols.hpp"

namespace imuemu::drivers::mip {

inline constexpr std::uint8_t kGnssDataSet = 0x81;
inline constexpr std::uint8_t kGnssLlh = 0x03;
inline constexpr std::uint8_t kGnssNedVelocity = 0x05;
inline constexpr std::uint8_t kGnssGpsTime = 0x09;
inline constexpr std::uint8_t kGnssFixInfo = 0x0B;
inline constexpr std::uint8_t kSharedGpsTimestamp = 0xD3;

inline constexpr std::uint8_t kFilterLlh = 0x01;
inline constexpr std::uint8_t kFilterNedVelocity = 0x02;
inline constexpr std::uint8_t kFilterQuaternion = 0x03;
inline constexpr std::uint8_t kFilterLlhUncertainty = 0x08;
inline constexpr std::uint8_t kFilterVelocityUncertainty = 0x09;
inline constexpr std::uint8_t kFilterEulerUncertainty = 0x0A;
inline constexpr std::uint8_t kFilterStatus = 0x10;

// [G] fix types.
inline constexpr std::uint8_t kFixType3d = 0x00;
inline constexpr std::uint8_t kFixTypeNone = 0x03;
// [M] filter states and flags.
inline constexpr std::uint16_t kCv7Init = 1, kCv7VerticalGyro = 2, kCv7Ahrs = 3, kCv7FullNav = 4;
inline constexpr std::uint16_t kGx5Startup = 0, kGx5Init = 1, kGx5RunValid = 2, kGx5RunError = 3;
inline constexpr std::uint16_t kGx5InitNoAttitude = 0x1000, kGx5InitNoPositionVelocity = 0x2000,
                               kGx5RunGnssUnavailable = 0x0002;

// The fields of 0x81 / 0x82 the device can send and, in that order, its
// power-up formats (empty when the set is off): GNSS LLH, NED velocity, fix
// information, GPS timestamp 0xD3 (GPS Time 0x09 on request); filter status,
// LLH, NED velocity, quaternion, GPS timestamp 0xD3 (the uncertainties on
// request).
std::vector<std::uint8_t> gnss_fields(const MipNavConfig& config);
std::vector<std::uint8_t> gnss_power_up_fields(const MipNavConfig& config);
std::vector<std::uint8_t> filter_fields(const MipNavConfig& config);
std::vector<std::uint8_t> filter_power_up_fields(const MipNavConfig& config);
// Power-up decimation of a set at `rate_hz` from the base rate (>= 1).
std::uint16_t decimation_of(std::int64_t rate_hz, std::uint16_t base_rate_hz);
// The largest 0x81 and 0x82 packets (every field), 0 for a set that is off.
std::size_t max_gnss_packet_bytes(const MipNavConfig& config);
std::size_t max_filter_packet_bytes(const MipNavConfig& config);

// Builds the 0x81 and 0x82 packets of a sample (emission thread: no
// allocation once `out` has room).
class NavEncoder {
 public:
  // Throws SettingError / std::invalid_argument for GNSS errors out of
  // bounds (GnssFixSource).
  NavEncoder(const StreamEncoderOptions& options, std::uint16_t base_rate_hz);
  // Appends the packet of each set with a field due at this sample.
  void encode(const ImuFrameInput& sample, std::span<const FieldRate> gnss, std::span<const FieldRate> filter,
              std::vector<std::uint8_t>& out);

 private:
  struct FilterSolution {
    double latitude_deg = 0.0, longitude_deg = 0.0, height_m = 0.0;
    Vec3 velocity_ned_m_s = Vec3::Zero();
  };
  bool fix_at_epoch(std::uint64_t epoch, const ImuFrameInput& sample) const;
  void gnss_packet(const ImuFrameInput& sample, std::span<const FieldRate> fields, std::vector<std::uint8_t>& out);
  void filter_packet(const ImuFrameInput& sample, std::span<const FieldRate> fields, std::vector<std::uint8_t>& out);

  StreamEncoderOptions options_;
  MipNavConfig config_;
  double base_rate_hz_;
  std::uint16_t gnss_decimation_;
  GnssFixSource fix_source_;
  std::uint64_t device_hash_;
  bool ever_navigated_ = false;  // the filter has had a GNSS-aided solution
  FilterSolution held_;          // its last one
};

}  // namespace imuemu::drivers::mip
