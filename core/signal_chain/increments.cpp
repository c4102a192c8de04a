#include "core/signal_chain/increments.hpp"

#include <array>
#include <cmath>
#include <string>

#include "core/earth.hpp"
#include "core/so3.hpp"
#include "core/time_arith.hpp"

namespace imuemu::signal_chain {

namespace {

// Gauss-Legendre nodes and weights on [0, 1] (Abramowitz & Stegun, Table 25.4).
constexpr std::array<double, 3> kGl3Node{0.5 - 0.3872983346207417, 0.5, 0.5 + 0.3872983346207417};
constexpr std::array<double, 3> kGl3Weight{5.0 / 18.0, 8.0 / 18.0, 5.0 / 18.0};
constexpr std::array<double, 4> kGl4Node{0.5 - 0.4305681557970263, 0.5 - 0.1699905217924281,
                                         0.5 + 0.1699905217924281, 0.5 + 0.4305681557970263};
constexpr std::array<double, 4> kGl4Weight{0.1739274225687269, 0.3260725774312731, 0.3260725774312731,
                                           0.1739274225687269};

// ECEF -> inertial after tau seconds: the Earth turned w_ie tau about z.
Mat3 earth_turn(double angle_rad) {
  const double c = std::cos(angle_rad), s = std::sin(angle_rad);
  Mat3 E;
  E << c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0;
  return E;
}

// earth_turn(angle) - I, without the cancellation of 1 - cos(angle)
// (2 sin^2(angle/2)): the inertial velocity change of a slow vehicle is a
// small difference of Earth-rate velocities of ~350 m/s.
Mat3 earth_turn_minus_identity(double angle_rad) {
  const double s = std::sin(angle_rad), vers = 2.0 * std::pow(std::sin(0.5 * angle_rad), 2);
  Mat3 D;
  D << -vers, -s, 0.0, s, -vers, 0.0, 0.0, 0.0, 0.0;
  return D;
}

}  // namespace

std::string to_string(IncrementConvention c) { return c == IncrementConvention::raw ? "raw" : "compensated"; }

HermiteInterval::HermiteInterval(const Kinematics& a, const Kinematics& b, double h_s) : a_(a), h_s_(h_s) {
  const double h = h_s;
  // Quintic Hermite: x = c3 h^3, y = c4 h^4, z = c5 h^5 solve
  // x + y + z = P, 3x + 4y + 5z = V, 6x + 12y + 20z = A.
  const Vec3 P = b.position_m - a.position_m - a.velocity_m_s * h - 0.5 * a.acceleration_m_s2 * h * h;
  const Vec3 V = (b.velocity_m_s - a.velocity_m_s - a.acceleration_m_s2 * h) * h;
  const Vec3 A = (b.acceleration_m_s2 - a.acceleration_m_s2) * h * h;
  c3_ = (10.0 * P - 4.0 * V + 0.5 * A) / (h * h * h);
  c4_ = (-15.0 * P + 7.0 * V - A) / (h * h * h * h);
  c5_ = (6.0 * P - 3.0 * V + 0.5 * A) / (h * h * h * h * h);
  // Attitude in the chart of R_a: rho(0) = 0, rho'(0) = omega_a (W(0) = I),
  // rho(h) = D, rho'(h) = W^-1(D) omega_b (Eq. 3.59).
  const Vec3 D = so3::log(a.attitude.transpose() * b.attitude);
  const Vec3 E = so3::W_inverse(D) * b.angular_rate_rad_s;
  rho1_ = a.angular_rate_rad_s;
  const Vec3 Pr = D - rho1_ * h;
  const Vec3 Qr = (E - rho1_) * h;
  rho2_ = (3.0 * Pr - Qr) / (h * h);
  rho3_ = (Qr - 2.0 * Pr) / (h * h * h);
}

Kinematics HermiteInterval::at(double s) const {
  const double t = s * h_s_;
  Kinematics k;
  k.t_ns = saturating_add_ns(a_.t_ns, static_cast<TimeNs>(std::llround(t * 1e9)));  // core/time_arith.hpp
  k.position_m = position_at(s);
  k.velocity_m_s = a_.velocity_m_s + t * (a_.acceleration_m_s2 + t * (3.0 * c3_ + t * (4.0 * c4_ + t * 5.0 * c5_)));
  k.acceleration_m_s2 = a_.acceleration_m_s2 + t * (6.0 * c3_ + t * (12.0 * c4_ + t * 20.0 * c5_));
  const Vec3 rho = t * (rho1_ + t * (rho2_ + t * rho3_));
  const Vec3 rho_dot = rho1_ + t * (2.0 * rho2_ + t * 3.0 * rho3_);
  k.attitude = a_.attitude * so3::exp(rho);
  k.angular_rate_rad_s = so3::W(rho) * rho_dot;
  return k;
}

Vec3 HermiteInterval::position_at(double s) const {
  const double t = s * h_s_;
  return a_.position_m + t * (a_.velocity_m_s + t * (0.5 * a_.acceleration_m_s2 + t * (c3_ + t * (c4_ + t * c5_))));
}

Vec3 HermiteInterval::angular_acceleration_at(double s) const {
  const double t = s * h_s_;
  const Vec3 rho = t * (rho1_ + t * (rho2_ + t * rho3_));
  const Vec3 rho_dot = rho1_ + t * (2.0 * rho2_ + t * 3.0 * rho3_);
  const Vec3 rho_ddot = 2.0 * rho2_ + 6.0 * t * rho3_;
  return so3::angular_acceleration(rho, rho_dot, rho_ddot);
}

Increment compensated_increment(const SceneModel& scene, const Kinematics& start, const Kinematics& end, double h_s,
                                const IntervalMotion* motion) {
  Increment out;
  if (scene.physics == Physics::flat) {
    // The NED frame of a flat scene is inertial and gravity constant: exact.
    out.delta_theta_rad = so3::log(start.attitude.transpose() * end.attitude);
    out.delta_velocity_m_s =
        start.attitude.transpose() * (end.velocity_m_s - start.velocity_m_s - scene.flat_gravity_m_s2 * h_s);
    return out;
  }
  // ecef: the inertial frame coincides with ECEF at t_{k-1}; E(tau) turns
  // ECEF into it. C(tau) = E(tau) R_b^e(tau).
  const double w = earth::kRotationRate_rad_s;
  const Vec3 w_ie = earth::rotation_rate_ecef();
  const Mat3 E_end = earth_turn(w * h_s);
  out.delta_theta_rad = so3::log(start.attitude.transpose() * E_end * end.attitude);
  // Inertial velocity V = E (v + w x x); dV/dt = E R f + E G, with the
  // gravitation G = g + w x (w x x) (normal gravity g includes the
  // centrifugal term -w x (w x x)).
  // V1 - V0 = (E(h) - I)(v1 + w x x1) + (v1 - v0) + w x (x1 - x0).
  const Vec3 dV = earth_turn_minus_identity(w * h_s) * (end.velocity_m_s + w_ie.cross(end.position_m)) +
                  (end.velocity_m_s - start.velocity_m_s) + w_ie.cross(end.position_m - start.position_m);
  Vec3 gravitation = Vec3::Zero();
  for (std::size_t i = 0; i < kGl3Node.size(); ++i) {
    const Vec3 x = motion->position_at(kGl3Node[i]);
    const Vec3 G = earth::normal_gravity_ecef(x) + w_ie.cross(w_ie.cross(x));
    gravitation += kGl3Weight[i] * (earth_turn(w * kGl3Node[i] * h_s) * G);
  }
  out.delta_velocity_m_s = start.attitude.transpose() * (dV - gravitation * h_s);
  return out;
}

Increment raw_increment(const SceneModel& scene, const IntervalMotion& motion, double h_s) {
  Increment out;
  for (std::size_t i = 0; i < kGl4Node.size(); ++i) {
    const ImuSample s = imu_from_kinematics(scene, motion.at(kGl4Node[i]));
    out.delta_theta_rad += kGl4Weight[i] * s.gyro_rad_s;
    out.delta_velocity_m_s += kGl4Weight[i] * s.accel_m_s2;
  }
  out.delta_theta_rad *= h_s;
  out.delta_velocity_m_s *= h_s;
  return out;
}

Increment increment(IncrementConvention c, const SceneModel& scene, const Kinematics& start, const Kinematics& end,
                    double h_s, const IntervalMotion* motion) {
  return c == IncrementConvention::raw ? raw_increment(scene, *motion, h_s)
                                       : compensated_increment(scene, start, end, h_s, motion);
}

}  // namespace imuemu::signal_chain
