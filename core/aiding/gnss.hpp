// GNSS truth and the receiver's errors (issue 28): the antenna's position
// and velocity from the trajectory, the receiver's fix epochs on GPS time,
// and a seeded error model in the units receiver datasheets use. Pure
// maths, no I/O, no encoding (the NMEA/UBX receiver device builds on it).
//
// Lever arm. The trajectory gives, in its frame f (ECEF for the ecef scene,
// the local NED for the flat one; core/trajectory.hpp Kinematics): the
// body's position x^f, velocity v^f, attitude R_b^f and the body rate
// relative to that frame omega_fb^b. The antenna phase centre at l^b (body
// FRD, m) is (rigid body, thesis §1.3 conventions):
//     x_a^f = x^f + R_b^f l^b
//     v_a^f = v^f + R_b^f (omega_fb^b x l^b)
// (d/dt R_b^f = R_b^f [omega_fb^b x]). In the ecef frame this is the
// velocity relative to the Earth, which is what a receiver reports.
//
// Errors (per fix, in the local NED at the antenna), as datasheets and
// EKF tuning state them:
//  * position: per axis white noise plus a first-order Gauss-Markov process
//    (the slowly wandering multipath/ionosphere part), horizontal (north and
//    east alike) and vertical separately: _white_m, _gm_sigma_m (stationary
//    sigma), _gm_tau_s (correlation time). The GM process is discretised
//    exactly at the fix period dt: x[j+1] = phi x[j] + sigma sqrt(1 - phi^2) w,
//    phi = exp(-dt/tau), started stationary, so its variance is sigma^2 and
//    its autocorrelation at lag L fixes exp(-L dt / tau), whatever dt is.
//    A datasheet's "2.5 m CEP" is a per-axis sigma of 2.5 / 1.1774 m (CEP
//    of a circular Gaussian = sqrt(2 ln 2) sigma; sigma_from_cep_m).
//  * velocity: per axis white noise _m_s (horizontal and vertical; a
//    datasheet's "0.05 m/s" speed accuracy).
//  * output rate (Hz, an integer number of ms per fix: u-blox CFG-RATE
//    takes milliseconds), latency_ms (a fix measured at its epoch is
//    delivered that much later), time_to_first_fix_s (no fix before it).
//    Fix epochs sit on whole multiples of the fix period in GPS time (a
//    receiver's fixes are at the top of the GPS second and its fractions).
//  * fix type, satellites, DOP: stated values, reported as given.
// Random terms: own streams keyed by (seed, device, sensor 18, axis, term)
// as the IMU's; bit-reproducible for one binary.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "core/earth.hpp"
#include "core/sensor/sensor_model.hpp"
#include "core/types.hpp"

namespace imuemu::aiding {

struct AntennaTruth {
  Vec3 position_m = Vec3::Zero();    // frame f
  Vec3 velocity_m_s = Vec3::Zero();  // frame f axes, relative to f
};

// Throws SettingError for a non-finite input or a lever arm beyond
// kMaxLeverArm_m.
AntennaTruth antenna_truth(const Vec3& position_m, const Vec3& velocity_m_s, const Mat3& R_b_f,
                           const Vec3& omega_fb_b_rad_s, const Vec3& lever_arm_b_m);
inline constexpr double kMaxLeverArm_m = 100.0;  // an airliner's wing span is 80 m

// The geodetic position of x^e moved by d^n (m, local NED at x^e), and the
// NED velocity of v^e at a geodetic position: for applying the NED errors
// in the ecef scene. Throw SettingError for non-finite input.
earth::Geodetic offset_geodetic(const Vec3& x_e_m, const Vec3& d_ned_m);
Vec3 ned_from_ecef_velocity(const earth::Geodetic& at, const Vec3& v_e_m_s);

// CEP (50 % circle) of a circular Gaussian -> its per-axis sigma.
double sigma_from_cep_m(double cep_m);

enum class GnssFixType : std::uint8_t { none = 0, dead_reckoning = 1, fix_2d = 2, fix_3d = 3, gnss_dr = 4 };

struct GnssSpec {
  double horizontal_white_m = 0.0;   // per axis (north, east), 1 sigma
  double horizontal_gm_sigma_m = 0.0;
  double horizontal_gm_tau_s = 60.0;
  double vertical_white_m = 0.0;
  double vertical_gm_sigma_m = 0.0;
  double vertical_gm_tau_s = 60.0;
  double horizontal_velocity_m_s = 0.0;  // per axis, 1 sigma
  double vertical_velocity_m_s = 0.0;
  double rate_hz = 1.0;
  double latency_ms = 0.0;
  double time_to_first_fix_s = 0.0;
  GnssFixType fix_type = GnssFixType::fix_3d;
  int satellites = 12;
  double hdop = 0.8, vdop = 1.2, pdop = 1.4;
  std::uint64_t seed = 0;
};

// Bounds: sigmas within 10 km (a fix worse than that is no fix), velocity
// sigma within 100 m/s, tau in [1e-3, 1e8] s as the IMU's, rate in
// [0.001, 1000] Hz with an integer number of ms per fix, latency within
// 10 s, time to first fix within a day (a cold start is ~30 s), satellites
// 0..255 (UBX numSV is a byte), DOPs within [0, 99.99] (NMEA prints 2.2).
inline constexpr double kGnssMaxSigma_m = 10000.0;
inline constexpr double kGnssMaxVelocitySigma_m_s = 100.0;
// Throws SettingError (key: the field) for a spec outside the bounds.
void validate(const GnssSpec& spec);

struct GnssError {
  Vec3 position_ned_m = Vec3::Zero();
  Vec3 velocity_ned_m_s = Vec3::Zero();
};

// The accuracy figures a receiver reports with a fix (UBX NAV-PVT hAcc,
// vAcc, sAcc): horizontal = sqrt(2) x per-axis sigma (2-D RMS), vertical
// and speed 1 sigma, each from the stated white and GM sigmas.
struct GnssAccuracy {
  double horizontal_m = 0.0, vertical_m = 0.0, speed_m_s = 0.0;
};
GnssAccuracy stated_accuracy(const GnssSpec& spec);

class GnssReceiverModel {
 public:
  // gps_at_start_ns: GPS time of the receiver's power-on (trajectory time
  // 0 through gnss_time.hpp's gps_ns_at). Throws as validate, and for a
  // negative GPS time.
  GnssReceiverModel(const GnssSpec& spec, TimeNs gps_at_start_ns, const std::string& device);

  TimeNs period_ns() const { return period_ns_; }
  TimeNs latency_ns() const { return latency_ns_; }
  // GPS time of fix j (j = 0: the first whole period at or after power-on
  // + time to first fix); nullopt beyond int64.
  std::optional<TimeNs> epoch_gps_ns(std::uint64_t j) const;
  // The error of fix j (j >= next_index(); skipped fixes are simulated so
  // fix j's error does not depend on which were asked for). Throws
  // std::invalid_argument for j < next_index() or more than 2^28 after it
  // (sample_index.hpp).
  GnssError error(std::uint64_t j);
  std::uint64_t next_index() const { return next_j_; }

 private:
  GnssSpec spec_;
  TimeNs period_ns_ = 0, latency_ns_ = 0, first_epoch_ns_ = 0;
  std::uint64_t next_j_ = 0;
  double phi_[3] = {0, 0, 0}, drive_[3] = {0, 0, 0}, gm_[3] = {0, 0, 0};
  double white_[3] = {0, 0, 0}, vel_[3] = {0, 0, 0};
  sensor::Stream white_stream_[3], gm_stream_[3], vel_stream_[3];
};

}  // namespace imuemu::aiding
