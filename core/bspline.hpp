// Alternative trajectory family: a cumulative cubic B-spline on SO(3) x R^3
// with analytic derivatives (Sommer, Usenko, Schubert, Demmel, Cremers,
// "Efficient Derivative Computation for Cumulative B-Splines on Lie Groups",
// CVPR 2020), offered next to the thesis' geodesic + smoothing pipeline
// (core/pipeline.hpp) for comparison. Defined for any increasing knot times
// (real logs jitter and have gaps), not only uniform ones.
//
// Knot vector. The pose times t_0 < ... < t_{n-1} are the B-spline knots,
// with control point k owning the cubic basis function N_k whose support is
// [t_{k-2}, t_{k+2}] (centred on its own pose; de Boor knot vector
// tau_j = t_{j-2}). Segment i (control points i..i+3) covers [t_{i+1}, t_{i+2}];
// its four basis functions depend on the six knots t_{i-1}..t_{i+4}. The two
// knots beyond the data, t_{-1} and t_n, repeat the end intervals:
// t_{-1} = t_0 - (t_1 - t_0), t_n = t_{n-1} + (t_{n-1} - t_{n-2}).
//
// Basis. On segment i, with h = t_{i+2} - t_{i+1} and u = (t - t_{i+1}) / h in
// [0, 1] (integer ns differences), N_i..N_{i+3} are cubic polynomials in u
// whose coefficients (the 4x4 segment matrix of Qin, "General matrix
// representations for B-splines", The Visual Computer 16, 2000) come from the
// Cox-de Boor recursion run on polynomials (Piegl & Tiller, The NURBS Book,
// Algorithm A2.2) once per segment. The cumulative basis is
//   B~_0 = 1,  B~_j = sum_{l=j..3} N_{i+l}  (j = 1..3),
// and B~_j' = dB~_j/du / h (1/s), B~_j'' = d2B~_j/du2 / h^2 (1/s^2).
//
// Control points. With the knot poses themselves as control points, a
// non-uniform cubic B-spline reproduces neither straight lines (that needs
// control point k at its Greville abscissa xi_k = (t_{k-1} + t_k + t_{k+1}) / 3)
// nor, on jittered knots, accelerations (the uniform spline's smoothing
// bias p'' h^2 / 6 turns into one that varies from knot to knot; on the
// aircraft flight with +-30 % jitter: accel error 31 m/s^2 RMS). So the
// control points come from the B-spline blossom (polar form; de Boor-Fix,
// Marsden's identity): a cubic f is reproduced exactly by the control points
// F(t_{k-1}, t_k, t_{k+1}), F its blossom, and the uniform spline of samples
// reproduces a cubic as f + (h^2 / 6) f''. Here
//   c_k = F_k(t_{k-1}, t_k, t_{k+1}) + (S / 2) f''(xi_k),   S = H^2 / 3,
// with H the median knot interval and f the local fit below: the smoothing
// bias of the uniform spline of interval H, (H^2 / 6) f'', everywhere (at
// uniform spacing the two terms are exactly the knot pose). With
// a = t_k - t_{k-1}, b = t_{k+1} - t_k, delta_k = xi_k - t_k = (b - a) / 3 and
// the knot slopes s0 = (p_k - p_{k-1}) / a, s1 = (p_{k+1} - p_k) / b:
//   c_k = p_k + f'(t_k) delta_k + (f''/2) (S - a b / 3),
//   f'(t_k) = (b s0 + a s1) / (a + b),  f'' = 2 (s1 - s0) / (a + b),
// i.e. f is the quadratic through the three knots around k, whose blossom is
// that of any cubic through them (the blossom of (t - t_{k-1})(t - t_k)
// (t - t_{k+1}) at its own roots is 0) and whose f'' is a cubic's f''(xi_k).
// At the ends (k = 0, n - 1; a = b = the end interval, delta = 0) f'' at the
// end knot comes from the cubic through the four end knots (linear
// extrapolation of the two second divided differences). In attitude the same
// in the chart R_k exp(phi) with the slopes d / h expressed in R_k's body
// axes: C_k = R_k exp(phi_k). At uniform spacing (all intervals equal, exactly,
// in ns) the control points ARE the knot poses and the basis is the uniform
// one, B~_1 = (5 + 3u - 3u^2 + u^3)/6, B~_2 = (1 + 3u + 3u^2 - 2u^3)/6,
// B~_3 = u^3/6: the spline is the usual uniform cumulative B-spline (at a
// knot it sits at (p_{k-1} + 4 p_k + p_{k+1})/6).
//
// Evaluation on segment i:
//   R(t) = C_i prod_{j=1..3} exp(B~_j(t) e_j),   e_j = log(C_{i+j-1}^T C_{i+j}),
//   p(t) = c_i + sum_{j=1..3} B~_j(t) (c_{i+j} - c_{i+j-1}).
// Positions are built from differences of nearby knot positions (exact in
// double, Sterbenz) and p_i: nothing cancels at ECEF magnitudes, and a static
// point has exactly zero velocity and acceleration. Body rate and angular
// acceleration use the paper's recursion over A_j = exp(B~_j e_j):
//   w_j = A_j^T w_{j-1} + B~_j' e_j,
//   a_j = A_j^T a_{j-1} + B~_j'' e_j + (A_j^T w_{j-1}) x (B~_j' e_j),
// which gives omega_{frame,b}^b (what Kinematics::angular_rate_rad_s holds).
//
// Reproduced exactly (up to rounding) for ANY increasing knot times: static
// poses; straight lines at constant velocity; cubics p(t) up to the uniform
// spline's bias (H^2 / 6) p''(t) (so parabolas with exact velocity and
// acceleration); one-parameter subgroups R0 exp(t w) (constant body rate
// about a fixed axis: every chart is linear, the e_j are parallel to w, the
// factors commute and sum_k xi_k N_k(t) = t). Everything else is approximated,
// not interpolated: the spline does not pass through the knot poses; beyond
// the bias its error is of fourth order, and in attitude the fits are made in
// a chart (exact for coaxial motion, to second order otherwise).
// Neighbouring control attitudes are joined the short way (principal log), so
// the attitude change between them (up to about 5/3 of a knot interval) must
// stay below pi rad, as with uniform knots, where it is one interval.
//
// C2 everywhere: the non-uniform basis is twice continuously differentiable
// at the knots, so body rate, angular acceleration and linear acceleration are
// continuous with no smoothing step.
//
// Output range: the spline is defined on [t_1, t_{n-2}] only (each segment
// needs one control point before and two after). The output is RESTRICTED to
// that range (no phantom end control points are invented): run() emits
// output_grid(t_1, t_{n-2}, rate_hz), i.e. one knot interval less at each end
// than run_batch().
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "core/pipeline.hpp"
#include "core/trajectory.hpp"

namespace imuemu::bspline {

class Spline {
 public:
  // Throws interp::InterpolationError for invalid knots (interp::check_knots:
  // non-increasing times, non-finite values, antipodal consecutive attitudes)
  // and std::invalid_argument for fewer than 4 knots. Any increasing knot
  // times are accepted.
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
  std::vector<Vec3> positions_m_;  // knot positions p_k
  // Control points (header): c_k - p_k, C_k, and per consecutive pair k
  // (k = 0..n-2) e_k = log(C_k^T C_{k+1}), |e_k| and c_{k+1} - c_k.
  std::vector<Vec3> control_offset_m_;
  std::vector<Mat3> control_attitudes_;
  std::vector<Vec3> e_rad_;
  std::vector<double> e_norm_rad_;
  std::vector<Vec3> dc_m_;
  // Per segment: coefficients of B~_1, B~_2, B~_3 in powers u^0..u^3
  // (entry 4 (j - 1) + power).
  std::vector<std::array<double, 12>> cumulative_basis_;
};

// Samples the spline on output_grid(t_1, t_{n-2}, rate_hz) and turns every
// sample into an ideal IMU sample of the scene (Eq. 3.70). Throws as Spline()
// and output_grid() do.
BatchResult run(const std::vector<Pose>& knots, const SceneModel& scene, std::int64_t rate_hz);

}  // namespace imuemu::bspline
