// Naive baseline trajectory family: what navigation people do without Lie
// groups. Natural cubic splines through the knots (interpolating, C2, knot
// times may be non-uniform):
//   - position: one spline per component of the scene frame (flat NED or ECEF),
//     each segment evaluated relative to its left knot, p_k + b tau + c tau^2
//     + d tau^3 with tau = (t - t_k) from integer ns, so ECEF magnitudes cost
//     no precision; velocity and acceleration are its analytic derivatives.
//   - attitude: heading psi, pitch theta, roll gamma (Eq. 1.2) of R_b^l at each
//     knot (flat: R_b^n; ecef: R_b^l = R_l^e(lat, lon of the knot)^T R_b^e,
//     Eq. 1.4/1.5), heading and roll unwrapped across knots (multiples of 2 pi
//     so consecutive values differ by < pi), one natural spline per angle. At
//     time t: R_b^l = R(psi, theta, gamma) and, for ecef,
//     R_b^e = R_l^e(lat, lon of the spline position at t) R_b^l.
//   - body rate: analytic Euler-angle rates
//       w_lb^b = [g' - p' sin th;  th' cos g + p' sin g cos th;
//                 -th' sin g + p' cos g cos th]
//     plus, for ecef, the transport rate of the local frame,
//       w_eb^b = w_lb^b + R_b^l^T w_el^l,
//       w_el^l = [l' cos phi, -phi', -l' sin phi]
//              = [v_E/(N+h), -v_N/(M+h), -v_E tan(phi)/(N+h)]
//     with the WGS84 meridian (M) and prime-vertical (N) radii and the NED
//     velocity of the position spline.
//
// KNOWN FAILURE MODES (why this is a baseline, not the product):
//   - gimbal lock: at pitch +-90 deg heading and roll are not separable; the
//     knots' heading and roll jump (by up to pi) and the Euler-angle splines
//     swing through them, so attitude and body rate are wrong near vertical
//     flight, and the 1/cos(pitch) amplification of heading/roll makes the
//     spline ill-conditioned already at steep pitch;
//   - wrapping: unwrapping needs consecutive knots to differ by < pi in
//     heading and roll; faster rotations (> pi per knot interval about any
//     axis projected into heading or roll) alias;
//   - Euler-angle interpolation is not frame invariant: the same motion in a
//     rotated frame gives a different trajectory, and the rates of three
//     independent angle splines are not the rates of any geodesic;
//   - ecef near the poles: tan(phi) in the transport rate diverges and the
//     local frame's heading is undefined at the pole itself;
//   - natural end conditions (zero second derivative at the first and last
//     knot) bias acceleration and angular rate in the first and last intervals.
#pragma once

#include <cstdint>
#include <vector>

#include "core/pipeline.hpp"
#include "core/trajectory.hpp"

namespace imuemu::naive {

// A natural cubic spline through (t_k, y_k) for vector values, non-uniform
// knot times allowed (at least 2, strictly increasing). Segment k is stored
// relative to its left knot: y(t) = y_k + tau (b_k + tau (c_k + tau d_k)),
// tau = seconds from t_k.
class NaturalCubicSpline {
 public:
  NaturalCubicSpline() = default;
  NaturalCubicSpline(const std::vector<TimeNs>& times, const std::vector<Vec3>& values);

  std::size_t segment_count() const { return b_.size(); }
  // Segment k with t_k <= t_ns < t_{k+1} (the last segment for t_ns at or after
  // the last knot, the first for t_ns before the first).
  std::size_t segment_of(TimeNs t_ns) const;
  // Value and first/second time derivatives (per s, per s^2) on segment k.
  void evaluate(std::size_t k, TimeNs t_ns, Vec3& y, Vec3& dy, Vec3& ddy) const;

 private:
  std::vector<TimeNs> times_;
  std::vector<Vec3> y_, b_, c_, d_;
};

class Spline {
 public:
  // Throws interp::InterpolationError for invalid knots (interp::check_knots).
  // `physics` says what frame the knots are in (flat NED or ECEF).
  Spline(const std::vector<Pose>& knots, Physics physics);

  TimeNs start_ns() const { return times_.front(); }
  TimeNs end_ns() const { return times_.back(); }

  // Full kinematics at t_ns in [start_ns(), end_ns()] (else std::out_of_range).
  void evaluate(TimeNs t_ns, Kinematics& out) const;
  // Same on a known knot interval k (t_k <= t_ns <= t_{k+1}): no search.
  void evaluate_in_segment(std::size_t k, TimeNs t_ns, Kinematics& out) const;
  std::size_t segment_count() const { return times_.size() - 1; }

 private:
  Physics physics_;
  std::vector<TimeNs> times_;
  NaturalCubicSpline position_;
  NaturalCubicSpline hpr_;  // (heading, pitch, roll), heading and roll unwrapped
};

// Samples the splines on output_grid(t_0, t_last, rate_hz) (the same times as
// run_batch) and turns every sample into an ideal IMU sample (Eq. 3.70).
BatchResult run(const std::vector<Pose>& knots, const SceneModel& scene, std::int64_t rate_hz);

}  // namespace imuemu::naive
