#include "core/bspline.hpp"

#include <Eigen/Geometry>  // Vec3::cross

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>
#include <string>

#include "core/grid_sampling.hpp"
#include "core/imu_model.hpp"
#include "core/interpolation.hpp"
#include "core/so3.hpp"

namespace imuemu::bspline {

namespace {

// A unit quaternion (w, v), Hamilton convention, as the factors
// A_j = exp(B~_j d_j) are cheapest to build (one sin/cos pair) and chain.
struct Quat {
  double w;
  Vec3 v;
};

Quat multiply(const Quat& a, const Quat& b) {
  return Quat{a.w * b.w - a.v.dot(b.v), a.w * b.v + b.w * a.v + a.v.cross(b.v)};
}

// A^T x for A the rotation matrix of unit q, i.e. x rotated by q's conjugate:
// x + 2w (u x x) + 2 u x (u x x) with u = -v.
Vec3 rotate_by_conjugate(const Quat& q, const Vec3& x) {
  const Vec3 t = 2.0 * x.cross(q.v);  // = 2 (-v) x x
  return x + q.w * t - q.v.cross(t);  // u x t = -v x t
}

Mat3 matrix(const Quat& q) {
  const double w = q.w, x = q.v.x(), y = q.v.y(), z = q.v.z();
  Mat3 R;
  R << 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),  //
      2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),   //
      2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y);
  return R;
}

// Below this |d| the factor sin(b |d| / 2) / |d| comes from its series: with
// b <= 1 the next term, (b|d|/2)^4 / 120, is below 1e-19 relative.
constexpr double kSeriesBelow_rad = 1e-4;

// exp(b d) as a quaternion: (cos(b theta / 2), sin(b theta / 2) d / theta).
Quat exp_scaled(double b, const Vec3& d, double theta) {
  const double half = 0.5 * b * theta;
  const double s = theta < kSeriesBelow_rad ? 0.5 * b * (1.0 - half * half / 6.0) : std::sin(half) / theta;
  return Quat{std::cos(half), s * d};
}

std::string time_name(TimeNs t_ns) { return std::to_string(t_ns) + " ns"; }

// Coefficients of a cubic polynomial in u, powers u^0..u^3.
using Cubic = std::array<double, 4>;

// (c0 + c1 u) q for a polynomial q of degree <= 2.
Cubic times_linear(double c0, double c1, const Cubic& q) {
  return Cubic{c0 * q[0], c0 * q[1] + c1 * q[0], c0 * q[2] + c1 * q[1], c0 * q[3] + c1 * q[2]};
}

Cubic plus(const Cubic& a, const Cubic& b) { return Cubic{a[0] + b[0], a[1] + b[1], a[2] + b[2], a[3] + b[3]}; }

// The four cubic B-spline basis functions that are non-zero on the knot span
// [a[2], a[3]] = [0, 1], as polynomials in u, from the six local knots a[0..5]
// (in units of the span's length). Cox-de Boor in the triangular form of
// Piegl & Tiller, The NURBS Book, Algorithm A2.2 (BasisFuns), with
// left_k = u - a[3 - k], right_k = a[2 + k] - u, run on polynomials instead of
// numbers: every denominator a[3 + r] - a[3 + r - j] is a knot difference (no
// u) spanning at least [a[2], a[3]], so it is >= 1. The four coefficient
// rows together are Qin's (2000) 4x4 segment matrix.
std::array<Cubic, 4> span_basis(const std::array<double, 6>& a) {
  std::array<Cubic, 4> N{};
  N[0] = Cubic{1.0, 0.0, 0.0, 0.0};
  for (std::size_t j = 1; j <= 3; ++j) {
    Cubic saved{};
    for (std::size_t r = 0; r < j; ++r) {
      const double right_knot = a[3 + r], left_knot = a[3 + r - j];
      const double inv = 1.0 / (right_knot - left_knot);
      const Cubic temp{N[r][0] * inv, N[r][1] * inv, N[r][2] * inv, N[r][3] * inv};
      N[r] = plus(saved, times_linear(right_knot, -1.0, temp));  // + (right_knot - u) temp
      saved = times_linear(-left_knot, 1.0, temp);               // (u - left_knot) temp
    }
    N[j] = saved;
  }
  return N;
}

double seconds(TimeNs duration_ns) { return static_cast<double>(duration_ns) * 1e-9; }

// The local fits behind the control points (header, "Control points").
// Quadratic through t_{k-1}, t_k, t_{k+1} (slopes s0, s1 over h0, h1): its
// slope at t_k and its second derivative (for a cubic f, f'' at xi_k).
struct MiddleFit {
  Vec3 slope, second;
};
MiddleFit middle_fit(const Vec3& s0, const Vec3& s1, double h0_s, double h1_s) {
  return MiddleFit{(h1_s * s0 + h0_s * s1) / (h0_s + h1_s), 2.0 * (s1 - s0) / (h0_s + h1_s)};
}

// Second derivative at an end knot of the cubic through it and the next three
// (slopes s0, s1, s2 over h0, h1, h2, in the direction away from the end):
// the two second divided differences are f'' at the means of their knots, so
// f'' is extrapolated linearly from them (exact for a cubic).
Vec3 end_second_derivative(const Vec3& s0, const Vec3& s1, const Vec3& s2, double h0_s, double h1_s,
                           double h2_s) {
  const Vec3 near = 2.0 * (s1 - s0) / (h0_s + h1_s), far = 2.0 * (s2 - s1) / (h1_s + h2_s);
  return near - ((2.0 * h0_s + h1_s) / (h0_s + h1_s + h2_s)) * (far - near);
}

}  // namespace

Spline::Spline(const std::vector<Pose>& knots) {
  interp::check_knots(knots);
  const std::size_t n = knots.size();
  if (n < 4) {
    throw std::invalid_argument("cubic B-spline needs at least 4 knots (control points), got " +
                                std::to_string(n));
  }
  times_.resize(n);
  positions_m_.resize(n);
  for (std::size_t k = 0; k < n; ++k) {
    times_[k] = knots[k].t_ns;
    positions_m_[k] = knots[k].position_m;
  }
  // Knot intervals h_k = t_{k+1} - t_k for k = -1..n-1 at index k + 1, the two
  // outside the data repeating the end intervals (header: t_{-1}, t_n).
  std::vector<TimeNs> interval_ns(n + 1);
  for (std::size_t k = 0; k + 1 < n; ++k) interval_ns[k + 1] = times_[k + 1] - times_[k];
  interval_ns[0] = interval_ns[1];
  interval_ns[n] = interval_ns[n - 1];

  // Consecutive knot pairs: d_k = log(R_k^T R_{k+1}) and p_{k+1} - p_k.
  // Differences of nearby positions are exact (Sterbenz), so the spline below
  // never subtracts two 6.4e6 m numbers.
  std::vector<Vec3> d_rad(n - 1), dp_m(n - 1);
  for (std::size_t k = 0; k + 1 < n; ++k) {
    d_rad[k] = so3::log(knots[k].attitude.transpose() * knots[k + 1].attitude);
    dp_m[k] = positions_m_[k + 1] - positions_m_[k];
  }

  // Control points (header): c_k = p_k + offset_k, C_k = R_k exp(phi_k), the
  // blossom of the local fit plus the uniform spline's shift (S/2) f''. A
  // control point whose two blossom intervals both equal the median interval
  // H is the knot pose itself (checked on the integer ns, so uniform knots
  // give exactly the uniform spline).
  std::vector<TimeNs> sorted_ns(interval_ns.begin() + 1, interval_ns.end() - 1);
  const auto median_it = sorted_ns.begin() + static_cast<std::ptrdiff_t>((sorted_ns.size() - 1) / 2);
  std::nth_element(sorted_ns.begin(), median_it, sorted_ns.end());
  const TimeNs median_ns = *median_it;
  const double shift_s2 = seconds(median_ns) * seconds(median_ns) / 3.0;  // S = H^2 / 3
  control_offset_m_.resize(n);
  control_attitudes_.resize(n);
  std::vector<bool> moved(n, false);
  for (std::size_t k = 0; k < n; ++k) {
    // Blossom intervals: t_k - t_{k-1} and t_{k+1} - t_k (the end ones
    // repeated at k = 0 and n - 1).
    const TimeNs before_ns = interval_ns[k], after_ns = interval_ns[k + 1];
    if (before_ns == median_ns && after_ns == median_ns) {
      control_offset_m_[k] = Vec3::Zero();
      control_attitudes_[k] = knots[k].attitude;
      continue;
    }
    moved[k] = true;
    // offset = f'(t_k) delta_k + (f''/2) (S - a b / 3), a = t_k - t_{k-1},
    // b = t_{k+1} - t_k (header). Attitude slopes are the logs d over their
    // intervals in the body axes of R_k: d_{k-1} has the same coordinates in
    // the axes of R_{k-1} and R_k; at the ends the farther logs are rotated in.
    const double a_s = seconds(before_ns), b_s = seconds(after_ns);
    const double curvature_weight_s2 = 0.5 * (shift_s2 - a_s * b_s / 3.0);
    Vec3 position_offset_m, rotation_offset_rad;
    if (k == 0) {
      const double h0_s = seconds(interval_ns[1]), h1_s = seconds(interval_ns[2]), h2_s = seconds(interval_ns[3]);
      const Mat3 to_0_from_1 = so3::exp(d_rad[0]);
      const Mat3 to_0_from_2 = to_0_from_1 * so3::exp(d_rad[1]);
      position_offset_m = curvature_weight_s2 * end_second_derivative(dp_m[0] / h0_s, dp_m[1] / h1_s,
                                                                      dp_m[2] / h2_s, h0_s, h1_s, h2_s);
      rotation_offset_rad =
          curvature_weight_s2 * end_second_derivative(d_rad[0] / h0_s, to_0_from_1 * d_rad[1] / h1_s,
                                                      to_0_from_2 * d_rad[2] / h2_s, h0_s, h1_s, h2_s);
    } else if (k == n - 1) {  // the same backwards in time: slopes change sign, f'' does not
      const double h0_s = seconds(interval_ns[n - 1]), h1_s = seconds(interval_ns[n - 2]);
      const double h2_s = seconds(interval_ns[n - 3]);
      const Mat3 to_last_from_1 = so3::exp(-d_rad[n - 2]);
      const Mat3 to_last_from_2 = to_last_from_1 * so3::exp(-d_rad[n - 3]);
      position_offset_m = curvature_weight_s2 * end_second_derivative(-dp_m[n - 2] / h0_s, -dp_m[n - 3] / h1_s,
                                                                      -dp_m[n - 4] / h2_s, h0_s, h1_s, h2_s);
      rotation_offset_rad = curvature_weight_s2 *
                            end_second_derivative(-d_rad[n - 2] / h0_s, -(to_last_from_1 * d_rad[n - 3]) / h1_s,
                                                  -(to_last_from_2 * d_rad[n - 4]) / h2_s, h0_s, h1_s, h2_s);
    } else {
      const double delta_s = seconds(after_ns - before_ns) / 3.0;
      const MiddleFit p = middle_fit(dp_m[k - 1] / a_s, dp_m[k] / b_s, a_s, b_s);
      const MiddleFit r = middle_fit(d_rad[k - 1] / a_s, d_rad[k] / b_s, a_s, b_s);
      position_offset_m = delta_s * p.slope + curvature_weight_s2 * p.second;
      rotation_offset_rad = delta_s * r.slope + curvature_weight_s2 * r.second;
    }
    control_offset_m_[k] = position_offset_m;
    control_attitudes_[k] = knots[k].attitude * so3::exp(rotation_offset_rad);
  }
  e_rad_.resize(n - 1);
  e_norm_rad_.resize(n - 1);
  dc_m_.resize(n - 1);
  for (std::size_t k = 0; k + 1 < n; ++k) {
    if (!moved[k] && !moved[k + 1]) {
      e_rad_[k] = d_rad[k];
      dc_m_[k] = dp_m[k];
    } else {
      e_rad_[k] = so3::log(control_attitudes_[k].transpose() * control_attitudes_[k + 1]);
      dc_m_[k] = dp_m[k] + (control_offset_m_[k + 1] - control_offset_m_[k]);
    }
    e_norm_rad_[k] = e_rad_[k].norm();
  }

  // Cumulative basis per segment i from the knots t_{i-1}..t_{i+4}, i.e. the
  // intervals h_{i-1}..h_{i+3} (interval_ns[i..i+4]), scaled by the segment's
  // own interval h_{i+1}.
  cumulative_basis_.resize(n - 3);
  for (std::size_t i = 0; i + 3 < n; ++i) {
    const TimeNs h_prev2 = interval_ns[i], h_prev = interval_ns[i + 1], h = interval_ns[i + 2];
    const TimeNs h_next = interval_ns[i + 3], h_next2 = interval_ns[i + 4];
    const double scale = static_cast<double>(h);
    const std::array<double, 6> a{-static_cast<double>(h_prev2 + h_prev) / scale,
                                  -static_cast<double>(h_prev) / scale,
                                  0.0,
                                  1.0,
                                  static_cast<double>(h + h_next) / scale,
                                  static_cast<double>(h + h_next + h_next2) / scale};
    const std::array<Cubic, 4> N = span_basis(a);
    const Cubic b3 = N[3];
    const Cubic b2 = plus(N[2], b3);
    const Cubic b1 = plus(N[1], b2);
    auto& c = cumulative_basis_[i];
    for (std::size_t p = 0; p < 4; ++p) {
      c[p] = b1[p];
      c[4 + p] = b2[p];
      c[8 + p] = b3[p];
    }
  }
}

void Spline::evaluate(TimeNs t_ns, Kinematics& out, Vec3* angular_accel_rad_s2) const {
  if (t_ns < start_ns() || t_ns > end_ns()) {
    throw std::out_of_range("B-spline evaluated at " + time_name(t_ns) + ", outside its range [" +
                            time_name(start_ns()) + ", " + time_name(end_ns()) + "]");
  }
  // Last knot at or before t, among t_1..t_{n-2}; segment s starts at t_{s+1}.
  const auto it = std::upper_bound(times_.begin() + 1, times_.end() - 1, t_ns);
  const auto knot = static_cast<std::size_t>(it - times_.begin()) - 1;
  evaluate_in_segment(std::min(knot - 1, segment_count() - 1), t_ns, out, angular_accel_rad_s2);
}

void Spline::evaluate_in_segment(std::size_t i, TimeNs t_ns, Kinematics& out, Vec3* angular_accel_rad_s2) const {
  const TimeNs t0_ns = times_[i + 1];
  const TimeNs dt_ns = times_[i + 2] - t0_ns;
  const double u = static_cast<double>(t_ns - t0_ns) / static_cast<double>(dt_ns);
  const double dt_s = static_cast<double>(dt_ns) * 1e-9;
  // Cumulative basis B~_j, B~_j' (1/s) and B~_j'' (1/s^2), j = 1..3 at index
  // j - 1, from the segment's cubic coefficients (Horner).
  const std::array<double, 12>& c = cumulative_basis_[i];
  double b[3], db[3], ddb[3];
  for (std::size_t j = 0; j < 3; ++j) {
    const double c0 = c[4 * j], c1 = c[4 * j + 1], c2 = c[4 * j + 2], c3 = c[4 * j + 3];
    b[j] = c0 + u * (c1 + u * (c2 + u * c3));
    db[j] = (c1 + u * (2.0 * c2 + 3.0 * c3 * u)) / dt_s;
    ddb[j] = (2.0 * c2 + 6.0 * c3 * u) / (dt_s * dt_s);
  }

  // Position in R^3: p_i plus the control offset and basis-weighted
  // control-point differences (see the header), all small numbers.
  const Vec3& dc1 = dc_m_[i];
  const Vec3& dc2 = dc_m_[i + 1];
  const Vec3& dc3 = dc_m_[i + 2];
  out.t_ns = t_ns;
  out.position_m = positions_m_[i] + (control_offset_m_[i] + (b[0] * dc1 + b[1] * dc2 + b[2] * dc3));
  out.velocity_m_s = db[0] * dc1 + db[1] * dc2 + db[2] * dc3;
  out.acceleration_m_s2 = ddb[0] * dc1 + ddb[1] * dc2 + ddb[2] * dc3;

  // Rotation: C_i A_1 A_2 A_3 with A_j = exp(B~_j e_j).
  const Vec3& e1 = e_rad_[i];
  const Vec3& e2 = e_rad_[i + 1];
  const Vec3& e3 = e_rad_[i + 2];
  const Quat a2 = exp_scaled(b[1], e2, e_norm_rad_[i + 1]);
  const Quat a3 = exp_scaled(b[2], e3, e_norm_rad_[i + 2]);
  const Quat a = multiply(multiply(exp_scaled(b[0], e1, e_norm_rad_[i]), a2), a3);
  out.attitude.noalias() = control_attitudes_[i] * matrix(a);

  // Body rate by the recursion w_j = A_j^T w_{j-1} + B~_j' e_j (w_0 = 0), the
  // angular acceleration alongside it.
  const Vec3 w1 = db[0] * e1;
  const Vec3 w2_in = rotate_by_conjugate(a2, w1);
  const Vec3 w2 = w2_in + db[1] * e2;
  const Vec3 w3_in = rotate_by_conjugate(a3, w2);
  out.angular_rate_rad_s = w3_in + db[2] * e3;
  if (angular_accel_rad_s2 != nullptr) {
    const Vec3 al1 = ddb[0] * e1;
    const Vec3 al2 = rotate_by_conjugate(a2, al1) + ddb[1] * e2 + w2_in.cross(db[1] * e2);
    *angular_accel_rad_s2 = rotate_by_conjugate(a3, al2) + ddb[2] * e3 + w3_in.cross(db[2] * e3);
  }
}

BatchResult run(const std::vector<Pose>& knots, const SceneModel& scene, std::int64_t rate_hz) {
  const Spline spline(knots);
  // Segment s covers [t_{s+1}, t_{s+2}]; a time on a knot goes to the later
  // segment (u = 0) except the very last (u = 1 of the last segment).
  std::vector<TimeNs> segment_end_ns;
  for (std::size_t s = 0; s < spline.segment_count(); ++s) segment_end_ns.push_back(knots[s + 2].t_ns);
  return sample_on_output_grid(spline, segment_end_ns, scene, rate_hz, "B-spline");
}

}  // namespace imuemu::bspline
