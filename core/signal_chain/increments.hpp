// Exact increments over one output interval [t_{k-1}, t_k] (issue 16), in
// the two conventions IMUs report, from the continuous trajectory:
//
//  * raw: the integrals of the sensed angular rate and specific force,
//        dtheta = int omega_ib^b dt,   dv = int f^b dt
//    (what a "rate integral" field carries; an INS must add its own coning
//    and sculling corrections, e.g. Savage, J. Guid. Control Dyn. 21(1), 1998).
//  * compensated: what an INS integrating them needs nothing else for,
//        dtheta = Log(C(t_{k-1})^T C(t_k)),
//        dv     = C(t_{k-1})^T int_{t_{k-1}}^{t_k} C(t) f^b(t) dt,
//    C = C_b^i the body attitude relative to an inertial frame: the scene's
//    frame itself for flat, ECEF rotated back by the Earth's rotation over the
//    interval for ecef (C = exp(w_ie (t - t_{k-1}) [z]) R_b^e), so Earth rate
//    is included. Then C_k = C_{k-1} exp(dtheta) and
//    V_k = V_{k-1} + C_{k-1} dv + int gravitation dt reproduce the trajectory.
//
// Closed form where it exists: dtheta (compensated) needs only the end
// attitudes; dv (compensated) is the change of inertial velocity minus the
// integral of gravitation, which is a constant in the flat scene (exact) and
// a smooth function of position in ecef (3-point Gauss-Legendre over the
// interval: exact to degree 5, far below 1e-12 m/s at any vehicle speed).
// The raw integrals have no closed form for a general motion and are
// 4-point Gauss-Legendre quadratures of the continuous motion (degree 7).
#pragma once

#include "core/imu_model.hpp"
#include "core/trajectory.hpp"

namespace imuemu::signal_chain {

enum class IncrementConvention {
  raw,          // integrals of omega_ib^b and f^b
  compensated,  // coning/sculling-compensated (rotation vector, body-frame velocity change)
};
std::string to_string(IncrementConvention c);

// The trajectory over one interval, continuous in time: kinematics (scene
// frame, as the pipeline produces them) at t_{k-1} + s h, s in [0, 1].
class IntervalMotion {
 public:
  virtual ~IntervalMotion() = default;
  virtual Kinematics at(double s) const = 0;
  // The position alone (what the ecef gravitation integral reads).
  virtual Vec3 position_at(double s) const { return at(s).position_m; }
  // d/dt of the body rate, body axes (what vibration on a lever arm reads);
  // a motion that does not know it says zero.
  virtual Vec3 angular_acceleration_at(double s) const {
    (void)s;
    return Vec3::Zero();
  }
};

// The interpolant the daemon uses between two output samples of the smoothed
// trajectory (whose kernel band-limits it far below the output rate, thesis
// Eq. 3.66-3.68): position a quintic Hermite matching position, velocity and
// acceleration at both ends; attitude R(s) = R_a exp(rho(s)) with rho the
// cubic Hermite matching rho = 0, rho' = omega_a at the start and
// rho = log(R_a^T R_b), rho' = W^-1(rho) omega_b at the end (Eq. 3.59), its
// body rate W(rho) rho' exactly consistent with it.
class HermiteInterval final : public IntervalMotion {
 public:
  HermiteInterval(const Kinematics& a, const Kinematics& b, double h_s);
  Kinematics at(double s) const override;
  Vec3 position_at(double s) const override;
  Vec3 angular_acceleration_at(double s) const override;  // Eq. 3.61 on rho

 private:
  Kinematics a_;
  double h_s_;
  Vec3 c3_, c4_, c5_;          // position: a + v t + acc t^2/2 + c3 t^3 + c4 t^4 + c5 t^5
  Vec3 rho1_, rho2_, rho3_;    // rho(t) = rho1 t + rho2 t^2 + rho3 t^3
};

struct Increment {
  Vec3 delta_theta_rad = Vec3::Zero();
  Vec3 delta_velocity_m_s = Vec3::Zero();
};

// Compensated increments from the interval's end kinematics (and `motion`
// for the ecef gravitation integral: required there, unused by flat).
// h_s = t_k - t_{k-1}.
Increment compensated_increment(const SceneModel& scene, const Kinematics& start, const Kinematics& end, double h_s,
                                const IntervalMotion* motion);

// Raw integrals of the ideal IMU over the interval.
Increment raw_increment(const SceneModel& scene, const IntervalMotion& motion, double h_s);

// Either convention; `motion` may be null only for compensated in flat.
Increment increment(IncrementConvention c, const SceneModel& scene, const Kinematics& start, const Kinematics& end,
                    double h_s, const IntervalMotion* motion);

}  // namespace imuemu::signal_chain
