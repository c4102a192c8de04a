// Baseline family 2: a C2 cubic spline on SO(3) x R3, in the manner of
// scipy's RotationSpline (rotation vectors cubic per segment, knot rates
// solved so the angular acceleration is continuous at the knots; "Smooth
// Attitude Interpolation", the paper its documentation cites) plus natural
// cubic splines on the positions (naive::NaturalCubicSpline). It is what a
// careful user would write without kernel smoothing, and the yardstick of
// issue 14 acceptance 1: on fast rotation between sparse knots the product's
// default must be at least as accurate as this curve (bench/accuracy_report,
// tests/core/test_so3_spline.cpp).
//
// Segment k (knots k -> k+1, duration h_k, t in [0, h_k] seconds):
//   R(t) = R_k exp([rho_k(t)]),  rho_k cubic,  rho_k(0) = 0,
//   rho_k(h_k) = xi_k = log(R_k^T R_{k+1}),
//   rho_k'(0) = w_k (the body rate at knot k: W(0) = I, Eq. 3.59),
//   rho_k'(h_k) = W^-1(xi_k) w_{k+1}   (the rate at knot k+1 seen in chart k, as Eq. 3.63).
// The body rate is W(rho) rho' (Eq. 3.59) and the angular acceleration
// Eq. 3.61. Continuity of the angular acceleration at interior knot k
// (a = h_{k-1}, b = h_k) is, exactly (W(xi) xi = xi, W(xi) W^-1(xi) = I):
//   b W(xi_{k-1}) w_{k-1} + 2 (a + b) w_k + a W^-1(xi_k) w_{k+1}
//     = 3 (a/b xi_k + b/a xi_{k-1}) - (a b / 2) N(xi_{k-1}, W^-1(xi_{k-1}) w_k),
// where N(r, r') = angular_acceleration(r, r', 0) is the part of Eq. 3.61 that
// is not W r''. N is quadratic in the rates, so the block-tridiagonal system
// is solved by fixed-point iteration on N (as the paper does).
// Ends: natural (zero angular acceleration, scipy's choice) or clamped to a
// given body rate.
//
// KNOWN LIMITS (why a baseline): no smoothing, so its angular acceleration
// and the position's jerk jump at every knot; natural ends bias the first
// and last intervals; the whole trajectory is solved at once (no streaming).
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include "core/naive_spline.hpp"
#include "core/pipeline.hpp"
#include "core/trajectory.hpp"

namespace imuemu::so3spline {

// Body rates at the knots (rad/s) of the C2 spline through their attitudes:
// each end natural (nullopt) or clamped to the given body rate. Knot times
// may be non-uniform; consecutive knots must be less than pi apart (as
// interp::check_knots asserts). Needs at least 2 knots.
std::vector<Vec3> c2_knot_rates(std::span<const Pose> knots, const std::optional<Vec3>& first_rate_rad_s,
                                const std::optional<Vec3>& last_rate_rad_s);

class Spline {
 public:
  // Throws interp::InterpolationError for invalid knots (interp::check_knots).
  explicit Spline(const std::vector<Pose>& knots);

  TimeNs start_ns() const { return times_.front(); }
  TimeNs end_ns() const { return times_.back(); }
  std::size_t segment_count() const { return times_.size() - 1; }
  const std::vector<TimeNs>& knot_times_ns() const { return times_; }
  const std::vector<Vec3>& knot_rates_rad_s() const { return rates_; }

  // Kinematics in the knots' frame on knot interval k (t_k <= t_ns <= t_{k+1}).
  void evaluate_in_segment(std::size_t k, TimeNs t_ns, Kinematics& out) const;
  // Body angular acceleration (Eq. 3.61) on interval k, for tests.
  Vec3 angular_acceleration(std::size_t k, TimeNs t_ns) const;

 private:
  std::vector<TimeNs> times_;
  std::vector<Mat3> attitudes_;
  std::vector<Vec3> rates_;
  std::vector<std::array<Vec3, 3>> rho_;  // rho_k(t) = ((c2 t + c1) t + c0) t, t in seconds
  naive::NaturalCubicSpline position_;
};

// Samples the spline on output_grid(t_0, t_last, rate_hz) (run_batch's times)
// and turns every sample into an ideal IMU sample (Eq. 3.70). The knots are
// in the scene's frame (flat NED or ECEF); the body rate is relative to it.
BatchResult run(const std::vector<Pose>& knots, const SceneModel& scene, std::int64_t rate_hz);

}  // namespace imuemu::so3spline
