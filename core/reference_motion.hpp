// Analytic reference motions: trajectories whose position, velocity,
// acceleration, attitude and body angular rate are all known in closed form
// (no numerical differentiation anywhere). They are the independent truth for
// the tests and benchmarks: truth_imu() turns them into ideal IMU samples via
// Eq. 3.70, strapdown::integrate (Eq. 3.69) must give the motion back, and
// sample_knots() feeds the interpolation/smoothing pipeline whose output can be
// compared with at().
//
// Conventions as in core/trajectory.hpp: flat motions live in a fixed local
// NED frame, ecef motions in WGS84 ECEF; body axes FRD; attitude R_b^frame;
// angular_rate_rad_s = omega_{frame,b}^b. Every motion is defined for all t
// (not only in [start_ns, end_ns]), so finite-difference checks can straddle
// the ends.
#pragma once

#include <vector>

#include "core/attitude.hpp"
#include "core/earth.hpp"
#include "core/imu_model.hpp"
#include "core/trajectory.hpp"

namespace imuemu::reference {

inline constexpr TimeNs kOneHour_ns = 3600 * kNsPerSecond;

class Motion {
 public:
  Motion(Physics physics, TimeNs start_ns, TimeNs duration_ns)
      : physics_(physics), start_ns_(start_ns), end_ns_(start_ns + duration_ns) {}
  virtual ~Motion() = default;

  // The exact kinematics at time t_ns (k.t_ns == t_ns).
  virtual Kinematics at(TimeNs t_ns) const = 0;

  virtual Physics physics() const { return physics_; }
  virtual TimeNs start_ns() const { return start_ns_; }
  virtual TimeNs end_ns() const { return end_ns_; }

 protected:
  // Seconds since start_ns (a difference, so exact enough for any epoch).
  double tau_s(TimeNs t_ns) const { return seconds_between(start_ns_, t_ns); }

 private:
  Physics physics_;
  TimeNs start_ns_;
  TimeNs end_ns_;
};

// A body at rest on the Earth (ecef: position ecef_from_geodetic, Eq. 1.1,
// attitude R_b^e = R_l^e R_b^l, Eq. 1.4/1.5) or at rest at the origin of the
// flat scene's NED frame (attitude R_b^n = R_b^l, Eq. 1.2).
class Static final : public Motion {
 public:
  Static(const earth::Geodetic& where, const attitude::HeadingPitchRoll& hpr, Physics physics,
         TimeNs start_ns = 0, TimeNs duration_ns = kOneHour_ns);
  Kinematics at(TimeNs t_ns) const override;

 private:
  Vec3 position_m_;
  Mat3 attitude_;
};

// Flat scene: a body fixed at the NED origin spinning at a constant body rate,
// R(t) = R0 exp(tau [omega_b]).
class ConstantRate final : public Motion {
 public:
  ConstantRate(const Mat3& R0, const Vec3& omega_body_rad_s, TimeNs start_ns = 0,
               TimeNs duration_ns = kOneHour_ns);
  Kinematics at(TimeNs t_ns) const override;

 private:
  Mat3 R0_;
  Vec3 omega_b_rad_s_;
};

// Flat scene: a horizontal circle at constant speed, starting at the origin
// heading north and turning right (clockwise seen from above), body x along the
// velocity and z down. Heading psi = (v/r) tau, attitude R_z(psi), body rate
// (0, 0, v/r), centripetal acceleration v^2/r towards the centre (0, r, 0).
// heading_at_start_rad turns the whole circle about the start point's vertical:
// heading psi0 + (v/r) tau, position r (sin psi - sin psi0, cos psi0 - cos psi, 0).
class Circle final : public Motion {
 public:
  Circle(double radius_m, double speed_m_s, TimeNs start_ns = 0,
         TimeNs duration_ns = kOneHour_ns, double heading_at_start_rad = 0.0);
  Kinematics at(TimeNs t_ns) const override;

 private:
  double radius_m_;
  double speed_m_s_;
  double heading0_rad_;
};

// Flat scene: fast rotation between sparse knots (issue 14). A body at the
// NED origin yawing at 90 deg/s on average while its yaw rate, pitch and roll
// wobble, so the rotation axis moves (a constant-rate rotation about a fixed
// axis is reproduced exactly by every chart-based method):
//   psi = w0 tau + A_psi sin(n1 tau),  theta = A_th sin(n2 tau + 0.5),
//   gamma = A_ga sin(n3 tau + 1),  R = R_z(psi) R_y(theta) R_x(gamma) (Eq. 1.2),
// w0 = pi/2 rad/s, A_psi = 0.3 rad, A_th = 5 deg, A_ga = 10 deg, periods 10,
// 20 and 30 s; the yaw rate stays within 79-101 deg/s. Body rate from the
// analytic Euler-angle rates (as AircraftFlight).
class FastYaw final : public Motion {
 public:
  explicit FastYaw(TimeNs start_ns = 0, TimeNs duration_ns = 120 * kNsPerSecond);
  Kinematics at(TimeNs t_ns) const override;
};

// ECEF: a level circle (radius, speed) in the tangent plane of `where`, whose
// attitude R_b^e = R_l^e R_z(psi) passes rotation angle pi at crossing_ns (the
// heading psi_pi where tr(R_l^e R_z(psi)) = -1 exists for any R_l^e, see
// tests/io/test_hard_cases.cpp case 1): log R_b^e flips branch there. Position,
// velocity and acceleration are the circle's rotated into ECEF (a fixed
// tangent frame, as AircraftFlight's ecef version), the body rate relative to
// e is (0, 0, v/r).
class TurnThroughPi final : public Motion {
 public:
  TurnThroughPi(const earth::Geodetic& where, double radius_m, double speed_m_s, TimeNs crossing_ns,
                TimeNs start_ns, TimeNs duration_ns);
  Kinematics at(TimeNs t_ns) const override;
  // Heading (rad) at which R_l^e R_z(psi) has rotation angle pi.
  static double heading_at_pi(const Mat3& R_l_e);

 private:
  Vec3 origin_e_m_;
  Mat3 R_l_e_;
  Circle circle_;
};

// A smooth aircraft-like flight (default one hour) in a local NED frame about a
// geodetic origin. Horizontal velocity is a sum of rotating vectors,
//   v_N + i v_E = sum_k W_k exp(i (w_k tau + phi_k)),
// (an hour-long 170 m/s orbit plus 45/15/6 m/s turn components with periods of
// 480/97/23 s), so speed stays in ~[104, 236] m/s, heading sweeps all
// directions with turn rates below 2 deg/s, and the horizontal acceleration
// stays below 3.5 m/s^2. Altitude changes (climbs/descents of up to ~2 km,
// vertical speed up to ~11 m/s) are a sum of cosines. Every derivative is
// closed form. Attitude follows the velocity:
//   heading psi = atan2(v_E, v_N), pitch theta = atan2(-v_D, |v_h|),
//   roll gamma = atan(|v_h| psi_dot / g0) (coordinated turn),
// R_b^n = R_z(psi) R_y(theta) R_x(gamma) (Eq. 1.2), and the body rate comes
// from the analytic Euler-angle rates:
//   w_b = [gamma' - psi' sin th;  th' cos ga + psi' sin ga cos th;
//          -th' sin ga + psi' cos ga cos th].
// ecef: x^e = origin^e + R_n^e(origin) p^n (v, a rotated likewise) and
// R_b^e = R_n^e(origin) R_b^n: the attitude is taken relative to the FIXED
// origin tangent frame, which is still a valid analytic motion in ECEF, and
// since R_n^e(origin) is constant the body rate relative to e is w_b.
class AircraftFlight final : public Motion {
 public:
  static earth::Geodetic default_origin() {
    // Barcelona (the thesis' home), 1000 m above the ellipsoid.
    return earth::Geodetic{0.72233, 0.03793, 1000.0};
  }

  explicit AircraftFlight(Physics physics, const earth::Geodetic& origin = default_origin(),
                          TimeNs start_ns = 0, TimeNs duration_ns = kOneHour_ns);
  Kinematics at(TimeNs t_ns) const override;
  // The motion in the origin's NED frame (what at() returns for flat).
  Kinematics ned_at(TimeNs t_ns) const;

 private:
  Vec3 origin_e_m_;
  Mat3 R_n_e_;  // R_n^e at the origin (Eq. 1.5)
};

// Poses at start_ns, start_ns + period_ns, ... up to and including end_ns.
std::vector<Pose> sample_knots(const Motion& motion, TimeNs period_ns);

// The ideal IMU sample of the motion at t_ns: imu_from_kinematics of the
// analytic kinematics (Eq. 3.70). Throws std::invalid_argument if the scene's
// physics differs from the motion's.
ImuSample truth_imu(const Motion& motion, const SceneModel& scene, TimeNs t_ns);

// truth_imu at start_ns, start_ns + period_ns, ... up to and including end_ns.
std::vector<ImuSample> truth_imu_series(const Motion& motion, const SceneModel& scene,
                                        TimeNs period_ns);

// Error statistics of IMU samples against truth_imu at the same times.
// Samples with t_ns in [from_ns, to_ns] make the RMS and max; the others only
// the end maxima (methods differ in how they treat the ends).
struct ImuErrors {
  double gyro_rms_rad_s = 0.0, gyro_max_rad_s = 0.0;
  double accel_rms_m_s2 = 0.0, accel_max_m_s2 = 0.0;
  double end_gyro_max_rad_s = 0.0, end_accel_max_m_s2 = 0.0;
  std::size_t samples = 0;     // inside [from_ns, to_ns]
  std::size_t non_finite = 0;  // samples with a NaN/Inf error (must be 0)
};
ImuErrors compare_with_truth(const std::vector<ImuSample>& imu, const Motion& motion, const SceneModel& scene,
                             TimeNs from_ns, TimeNs to_ns);

}  // namespace imuemu::reference
