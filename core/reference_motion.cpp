#include "core/reference_motion.hpp"

#include <array>
#include <cmath>
#include <complex>
#include <numbers>
#include <stdexcept>
#include <string>

#include <Eigen/Geometry>

#include "core/so3.hpp"

namespace imuemu::reference {

namespace {

// Rotates the vector parts of a frame-A kinematics into frame B (constant
// rotation R_a^b) and shifts the position: for the ecef version of a motion
// defined in a fixed tangent frame. A constant rotation leaves the body rate
// relative to the frame unchanged.
Kinematics rotate_into(const Kinematics& k, const Mat3& R_a_b, const Vec3& origin_b_m) {
  Kinematics out = k;
  out.position_m = origin_b_m + R_a_b * k.position_m;
  out.velocity_m_s = R_a_b * k.velocity_m_s;
  out.acceleration_m_s2 = R_a_b * k.acceleration_m_s2;
  out.attitude = R_a_b * k.attitude;
  return out;
}

// R_b^n = R_z(psi) R_y(theta) R_x(gamma) (Eq. 1.2) and its body rate from
// the Euler-angle rates:
//   w_b = [gamma' - psi' sin th;  th' cos ga + psi' sin ga cos th;
//          -th' sin ga + psi' cos ga cos th].
void set_attitude_from_euler(Kinematics& k, double psi, double theta, double gamma, double psi_dot,
                             double theta_dot, double gamma_dot) {
  k.attitude = attitude::rotation_from_hpr({psi, theta, gamma});
  const double sth = std::sin(theta), cth = std::cos(theta);
  const double sga = std::sin(gamma), cga = std::cos(gamma);
  k.angular_rate_rad_s = Vec3(gamma_dot - psi_dot * sth,              //
                              theta_dot * cga + psi_dot * sga * cth,  //
                              -theta_dot * sga + psi_dot * cga * cth);
}

}  // namespace

// ---------------------------------------------------------------- Static

Static::Static(const earth::Geodetic& where, const attitude::HeadingPitchRoll& hpr,
               Physics physics, TimeNs start_ns, TimeNs duration_ns)
    : Motion(physics, start_ns, duration_ns) {
  const Mat3 R_b_l = attitude::rotation_from_hpr(hpr);  // Eq. 1.2
  if (physics == Physics::ecef) {
    position_m_ = earth::ecef_from_geodetic(where);  // Eq. 1.1
    attitude_ = attitude::ned_to_ecef(where.latitude_rad, where.longitude_rad) * R_b_l;  // Eq. 1.4
  } else {
    position_m_ = Vec3::Zero();  // the flat NED frame is anchored at the point
    attitude_ = R_b_l;
  }
}

Kinematics Static::at(TimeNs t_ns) const {
  Kinematics k;
  k.t_ns = t_ns;
  k.position_m = position_m_;
  k.attitude = attitude_;
  return k;  // velocity, acceleration and rate are zero
}

// ---------------------------------------------------------------- ConstantRate

ConstantRate::ConstantRate(const Mat3& R0, const Vec3& omega_body_rad_s, TimeNs start_ns,
                           TimeNs duration_ns)
    : Motion(Physics::flat, start_ns, duration_ns), R0_(R0), omega_b_rad_s_(omega_body_rad_s) {}

Kinematics ConstantRate::at(TimeNs t_ns) const {
  Kinematics k;
  k.t_ns = t_ns;
  // R^T R' = [w] for R = R0 exp(tau [w]).
  k.attitude = R0_ * so3::exp(tau_s(t_ns) * omega_b_rad_s_);
  k.angular_rate_rad_s = omega_b_rad_s_;
  return k;
}

// ---------------------------------------------------------------- Circle

Circle::Circle(double radius_m, double speed_m_s, TimeNs start_ns, TimeNs duration_ns, double heading_at_start_rad)
    : Motion(Physics::flat, start_ns, duration_ns),
      radius_m_(radius_m),
      speed_m_s_(speed_m_s),
      heading0_rad_(heading_at_start_rad) {
  if (!(radius_m > 0.0)) throw std::invalid_argument("Circle: radius must be positive");
}

Kinematics Circle::at(TimeNs t_ns) const {
  const double w = speed_m_s_ / radius_m_;  // heading rate, rad/s
  const double psi = heading0_rad_ + w * tau_s(t_ns);
  const double c = std::cos(psi), s = std::sin(psi);
  Kinematics k;
  k.t_ns = t_ns;
  k.position_m = Vec3(radius_m_ * (s - std::sin(heading0_rad_)), radius_m_ * (std::cos(heading0_rad_) - c), 0.0);
  k.velocity_m_s = Vec3(speed_m_s_ * c, speed_m_s_ * s, 0.0);
  k.acceleration_m_s2 = Vec3(-speed_m_s_ * w * s, speed_m_s_ * w * c, 0.0);
  k.attitude << c, -s, 0.0,  //
      s, c, 0.0,             //
      0.0, 0.0, 1.0;
  k.angular_rate_rad_s = Vec3(0.0, 0.0, w);
  return k;
}

// ---------------------------------------------------------------- FastYaw

FastYaw::FastYaw(TimeNs start_ns, TimeNs duration_ns) : Motion(Physics::flat, start_ns, duration_ns) {}

Kinematics FastYaw::at(TimeNs t_ns) const {
  constexpr double kPi = std::numbers::pi, kDeg = kPi / 180.0;
  constexpr double w0 = kPi / 2.0, a_psi = 0.3, a_th = 5.0 * kDeg, a_ga = 10.0 * kDeg;
  constexpr double n1 = 2.0 * kPi / 10.0, n2 = 2.0 * kPi / 20.0, n3 = 2.0 * kPi / 30.0;
  const double tau = tau_s(t_ns);
  const double psi = w0 * tau + a_psi * std::sin(n1 * tau);
  const double psi_dot = w0 + a_psi * n1 * std::cos(n1 * tau);
  const double theta = a_th * std::sin(n2 * tau + 0.5), theta_dot = a_th * n2 * std::cos(n2 * tau + 0.5);
  const double gamma = a_ga * std::sin(n3 * tau + 1.0), gamma_dot = a_ga * n3 * std::cos(n3 * tau + 1.0);
  Kinematics k;
  k.t_ns = t_ns;
  set_attitude_from_euler(k, psi, theta, gamma, psi_dot, theta_dot, gamma_dot);
  return k;
}

// ---------------------------------------------------------------- TurnThroughPi

double TurnThroughPi::heading_at_pi(const Mat3& A) {
  // tr(A R_z(psi)) = A22 + (A00 + A11) cos psi + (A01 - A10) sin psi; its
  // minimum, -1 for any rotation A, is at this psi.
  return std::atan2(-(A(0, 1) - A(1, 0)), -(A(0, 0) + A(1, 1)));
}

TurnThroughPi::TurnThroughPi(const earth::Geodetic& where, double radius_m, double speed_m_s, TimeNs crossing_ns,
                             TimeNs start_ns, TimeNs duration_ns)
    : Motion(Physics::ecef, start_ns, duration_ns),
      origin_e_m_(earth::ecef_from_geodetic(where)),
      R_l_e_(attitude::ned_to_ecef(where.latitude_rad, where.longitude_rad)),
      circle_(radius_m, speed_m_s, start_ns, duration_ns,
              heading_at_pi(R_l_e_) - speed_m_s / radius_m * seconds_between(start_ns, crossing_ns)) {}

Kinematics TurnThroughPi::at(TimeNs t_ns) const { return rotate_into(circle_.at(t_ns), R_l_e_, origin_e_m_); }

// ---------------------------------------------------------------- AircraftFlight

namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;
// g0 for the coordinated-turn roll law only (any constant gives a valid motion).
constexpr double kTurnGravity_m_s2 = 9.80665;

// Horizontal velocity components W exp(i (w tau + phi)); w != 0 for each.
struct Rotor {
  double speed_m_s;
  double rate_rad_s;
  double phase_rad;
};
constexpr std::array<Rotor, 4> kRotors{{
    {170.0, kTwoPi / 3600.0, 0.0},  // cruise: one right-hand orbit per hour
    {45.0, -kTwoPi / 480.0, 1.0},   // slow left/right turns
    {15.0, kTwoPi / 97.0, 2.0},
    {6.0, -kTwoPi / 23.0, 0.5},  // brisk S-turns
}};

// Down position H (cos(w tau + chi) - cos chi): zero at tau = 0.
struct Wave {
  double amplitude_m;
  double rate_rad_s;
  double phase_rad;
};
constexpr std::array<Wave, 3> kWaves{{
    {900.0, kTwoPi / 1500.0, 0.0},  // climb to 1800 m and back, 25 min
    {120.0, kTwoPi / 200.0, 1.0},
    {15.0, kTwoPi / 31.0, 2.0},
}};

}  // namespace

AircraftFlight::AircraftFlight(Physics physics, const earth::Geodetic& origin, TimeNs start_ns,
                               TimeNs duration_ns)
    : Motion(physics, start_ns, duration_ns),
      origin_e_m_(earth::ecef_from_geodetic(origin)),
      R_n_e_(attitude::ned_to_ecef(origin.latitude_rad, origin.longitude_rad)) {}

Kinematics AircraftFlight::ned_at(TimeNs t_ns) const {
  using C = std::complex<double>;
  const double tau = tau_s(t_ns);
  const C I(0.0, 1.0);

  // Horizontal: z = N + i E and its first three derivatives.
  C p(0.0), v(0.0), a(0.0), j(0.0);
  for (const Rotor& r : kRotors) {
    const C e = std::polar(r.speed_m_s, r.rate_rad_s * tau + r.phase_rad);
    p += (e - std::polar(r.speed_m_s, r.phase_rad)) / (I * r.rate_rad_s);
    v += e;
    a += I * r.rate_rad_s * e;
    j += -r.rate_rad_s * r.rate_rad_s * e;
  }
  // Vertical (down) position and its first two derivatives.
  double d = 0.0, vd = 0.0, ad = 0.0;
  for (const Wave& w : kWaves) {
    const double arg = w.rate_rad_s * tau + w.phase_rad;
    d += w.amplitude_m * (std::cos(arg) - std::cos(w.phase_rad));
    vd -= w.amplitude_m * w.rate_rad_s * std::sin(arg);
    ad -= w.amplitude_m * w.rate_rad_s * w.rate_rad_s * std::cos(arg);
  }

  Kinematics k;
  k.t_ns = t_ns;
  k.position_m = Vec3(p.real(), p.imag(), d);
  k.velocity_m_s = Vec3(v.real(), v.imag(), vd);
  k.acceleration_m_s2 = Vec3(a.real(), a.imag(), ad);

  // Euler angles and their rates, all from v, a, jerk in closed form.
  const double vn = v.real(), ve = v.imag();
  const double an = a.real(), ae = a.imag();
  const double jn = j.real(), je = j.imag();
  const double vh2 = vn * vn + ve * ve;
  const double vh = std::sqrt(vh2);
  const double cross = vn * ae - ve * an;  // vh^2 psi'
  const double dot = vn * an + ve * ae;    // vh vh'
  const double psi = std::atan2(ve, vn);
  const double psi_dot = cross / vh2;
  // (vn ae - ve an)' = vn je - ve jn, so psi'' = (vn je - ve jn)/vh^2 - 2 psi' vh'/vh.
  const double psi_ddot = (vn * je - ve * jn) / vh2 - 2.0 * cross * dot / (vh2 * vh2);
  const double vh_dot = dot / vh;
  const double theta = std::atan2(-vd, vh);
  const double theta_dot = (-vh * ad + vd * vh_dot) / (vh2 + vd * vd);
  const double q = vh * psi_dot / kTurnGravity_m_s2;  // tan(roll)
  const double q_dot = (vh_dot * psi_dot + vh * psi_ddot) / kTurnGravity_m_s2;
  const double gamma = std::atan(q);
  const double gamma_dot = q_dot / (1.0 + q * q);

  set_attitude_from_euler(k, psi, theta, gamma, psi_dot, theta_dot, gamma_dot);
  return k;
}

Kinematics AircraftFlight::at(TimeNs t_ns) const {
  const Kinematics k = ned_at(t_ns);
  if (physics() == Physics::flat) return k;
  return rotate_into(k, R_n_e_, origin_e_m_);
}

// ---------------------------------------------------------------- sampling

std::vector<Pose> sample_knots(const Motion& motion, TimeNs period_ns) {
  if (period_ns <= 0) throw std::invalid_argument("sample_knots: period must be positive");
  std::vector<Pose> knots;
  knots.reserve(static_cast<std::size_t>((motion.end_ns() - motion.start_ns()) / period_ns + 1));
  for (TimeNs t = motion.start_ns(); t <= motion.end_ns(); t += period_ns) {
    const Kinematics k = motion.at(t);
    knots.push_back(Pose{t, k.position_m, k.attitude});
  }
  return knots;
}

ImuSample truth_imu(const Motion& motion, const SceneModel& scene, TimeNs t_ns) {
  if (scene.physics != motion.physics()) {
    throw std::invalid_argument("truth_imu: scene physics differs from the motion's");
  }
  return imu_from_kinematics(scene, motion.at(t_ns));
}

std::vector<ImuSample> truth_imu_series(const Motion& motion, const SceneModel& scene,
                                        TimeNs period_ns) {
  if (period_ns <= 0) throw std::invalid_argument("truth_imu_series: period must be positive");
  std::vector<ImuSample> out;
  out.reserve(static_cast<std::size_t>((motion.end_ns() - motion.start_ns()) / period_ns + 1));
  for (TimeNs t = motion.start_ns(); t <= motion.end_ns(); t += period_ns) {
    out.push_back(truth_imu(motion, scene, t));
  }
  return out;
}

ImuErrors compare_with_truth(const std::vector<ImuSample>& imu, const Motion& motion, const SceneModel& scene,
                             TimeNs from_ns, TimeNs to_ns) {
  ImuErrors e;
  double g2 = 0.0, a2 = 0.0;
  for (const ImuSample& s : imu) {
    const ImuSample t = truth_imu(motion, scene, s.t_ns);
    const double g = (s.gyro_rad_s - t.gyro_rad_s).norm(), a = (s.accel_m_s2 - t.accel_m_s2).norm();
    if (!std::isfinite(g) || !std::isfinite(a)) {
      ++e.non_finite;
      continue;
    }
    if (s.t_ns < from_ns || s.t_ns > to_ns) {
      e.end_gyro_max_rad_s = std::max(e.end_gyro_max_rad_s, g);
      e.end_accel_max_m_s2 = std::max(e.end_accel_max_m_s2, a);
      continue;
    }
    ++e.samples;
    g2 += g * g;
    a2 += a * a;
    e.gyro_max_rad_s = std::max(e.gyro_max_rad_s, g);
    e.accel_max_m_s2 = std::max(e.accel_max_m_s2, a);
  }
  const auto count = static_cast<double>(std::max<std::size_t>(e.samples, 1));
  e.gyro_rms_rad_s = std::sqrt(g2 / count);
  e.accel_rms_m_s2 = std::sqrt(a2 / count);
  return e;
}

}  // namespace imuemu::reference
