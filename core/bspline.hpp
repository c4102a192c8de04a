// Alternative trajectory family: a cumulative cubic B-spline on SO(3) x R^3
// with analytic derivatives (Sommer, Usenko, Schubert, Demmel, Cremers,
// "Efficient Derivative Computation for Cumulative B-Splines on Lie Groups",
// CVPR 2020), offered next to the thesis' geodesic + smoothing pipeline
// (core/pipeline.hpp) for comparison.
//
// The knot poses are the CONTROL POINTS, not interpolated points: the spline is
// approximating (it does not pass through the knots; at a knot it sits at about
// (p_{k-1} + 4 p_k + p_{k+1}) / 6) and is C2 everywhere, so it needs no
// smoothing step and its body rate and acceleration are continuous.
//
// Segment i (control points i..i+3) covers the knot interval [t_{i+1}, t_{i+2}]
// with u = (t - t_{i+1}) / (t_{i+2} - t_{i+1}) in [0, 1] computed from integer
// ns differences:
//   R(u) = R_i prod_{j=1..3} exp(B~_j(u) d_j),   d_j = log(R_{i+j-1}^T R_{i+j}),
//   p(u) = p_i + sum_{j=1..3} B~_j(u) (p_{i+j} - p_{i+j-1}),
// with the cumulative uniform cubic basis
//   B~_1 = (5 + 3u - 3u^2 + u^3)/6,  B~_2 = (1 + 3u + 3u^2 - 2u^3)/6,  B~_3 = u^3/6.
// Positions are built from differences of nearby knot positions (exact in
// double, Sterbenz), so nothing cancels at ECEF magnitudes: a static point has
// exactly zero velocity and acceleration. Body rate and angular acceleration
// use the paper's recursion over the three factors A_j = exp(B~_j d_j):
//   w_j = A_j^T w_{j-1} + B~_j' d_j,
//   a_j = A_j^T a_{j-1} + B~_j'' d_j + (A_j^T w_{j-1}) x (B~_j' d_j),
// which gives omega_{frame,b}^b (what Kinematics::angular_rate_rad_s holds).
// Because sum_j B~_j = 1 + u and the d_j of a one-parameter subgroup
// R0 exp(t w) are all equal, such motions are reproduced exactly (constant
// gyro); likewise constant-velocity straight lines.
//
// Knot spacing must be uniform: every knot interval within
// kUniformRelativeTolerance of the mean interval, else std::invalid_argument
// (non-uniform B-splines are not supported yet). The residual jitter is
// absorbed by giving each segment its own duration: position and attitude stay
// continuous at the knots; the rates jump by the relative jitter (<= 1e-6).
//
// Output range: the spline is defined on [t_1, t_{n-2}] only (each segment
// needs one control point before and two after). The output is RESTRICTED to
// that range (no phantom end control points are invented): run() emits
// output_grid(t_1, t_{n-2}, rate_hz), i.e. one knot interval less at each end
// than run_batch().
#pragma once

#include <cstdint>
#include <vector>

#include "core/pipeline.hpp"
#include "core/trajectory.hpp"

namespace imuemu::bspline {

// Largest accepted relative deviation of a knot interval from the mean.
inline constexpr double kUniformRelativeTolerance = 1e-6;

class Spline {
 public:
  // Throws interp::InterpolationError for invalid knots (interp::check_knots:
  // non-increasing times, non-finite values, antipodal consecutive attitudes)
  // and std::invalid_argument for fewer than 4 knots or non-uniform spacing.
  explicit Spline(const std::vector<Pose>& knots);

  TimeNs start_ns() const { return times_[1]; }                  // t_1
  TimeNs end_ns() const { return times_[times_.size() - 2]; }    // t_{n-2}

  // Position, velocity, acceleration, attitude R_b^frame and body rate
  // omega_{frame,b}^b at t_ns in [start_ns(), end_ns()] (else
  // std::out_of_range). If angular_accel_rad_s2 is given it receives the body
  // angular acceleration d/dt omega (body axes).
  void evaluate(TimeNs t_ns, Kinematics& out, Vec3* angular_accel_rad_s2 = nullptr) const;

  // Same, for a caller that already knows the segment (0 <= segment <
  // segment_count(), t_ns within [t_{segment+1}, t_{segment+2}]): no search.
  void evaluate_in_segment(std::size_t segment, TimeNs t_ns, Kinematics& out,
                           Vec3* angular_accel_rad_s2 = nullptr) const;
  std::size_t segment_count() const { return times_.size() - 3; }

 private:
  std::vector<TimeNs> times_;
  std::vector<Vec3> positions_m_;
  std::vector<Mat3> attitudes_;
  // Per consecutive pair k (k = 0..n-2): d = log(R_k^T R_{k+1}), |d|, and
  // p_{k+1} - p_k.
  std::vector<Vec3> d_rad_;
  std::vector<double> d_norm_rad_;
  std::vector<Vec3> dp_m_;
};

// Samples the spline on output_grid(t_1, t_{n-2}, rate_hz) and turns every
// sample into an ideal IMU sample of the scene (Eq. 3.70). Throws as Spline()
// and output_grid() do.
BatchResult run(const std::vector<Pose>& knots, const SceneModel& scene, std::int64_t rate_hz);

}  // namespace imuemu::bspline
