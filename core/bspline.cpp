#include "core/bspline.hpp"

#include <Eigen/Geometry>  // Vec3::cross

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

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

}  // namespace

Spline::Spline(const std::vector<Pose>& knots) {
  interp::check_knots(knots);
  const std::size_t n = knots.size();
  if (n < 4) {
    throw std::invalid_argument("cubic B-spline needs at least 4 knots (control points), got " +
                                std::to_string(n));
  }
  // Uniform spacing within a relative tolerance: real logs jitter by a few ns
  // to us, but the uniform basis is only right when the intervals agree.
  const double mean_ns = static_cast<double>(knots.back().t_ns - knots.front().t_ns) / static_cast<double>(n - 1);
  for (std::size_t k = 0; k + 1 < n; ++k) {
    const double h_ns = static_cast<double>(knots[k + 1].t_ns - knots[k].t_ns);
    if (std::abs(h_ns - mean_ns) > kUniformRelativeTolerance * mean_ns) {
      throw std::invalid_argument(
          "cubic B-spline needs uniform knot spacing (within a relative " +
          std::to_string(kUniformRelativeTolerance) + " of the mean interval): interval " + std::to_string(k) +
          " from " + time_name(knots[k].t_ns) + " to " + time_name(knots[k + 1].t_ns) + " is " +
          std::to_string(static_cast<std::int64_t>(h_ns)) + " ns, the mean is " + std::to_string(mean_ns) +
          " ns; non-uniform knots are not supported yet");
    }
  }
  times_.resize(n);
  positions_m_.resize(n);
  attitudes_.resize(n);
  for (std::size_t k = 0; k < n; ++k) {
    times_[k] = knots[k].t_ns;
    positions_m_[k] = knots[k].position_m;
    attitudes_[k] = knots[k].attitude;
  }
  d_rad_.resize(n - 1);
  d_norm_rad_.resize(n - 1);
  dp_m_.resize(n - 1);
  for (std::size_t k = 0; k + 1 < n; ++k) {
    d_rad_[k] = so3::log(attitudes_[k].transpose() * attitudes_[k + 1]);
    d_norm_rad_[k] = d_rad_[k].norm();
    // Differences of nearby positions are exact (Sterbenz), so the spline
    // below never subtracts two 6.4e6 m numbers.
    dp_m_[k] = positions_m_[k + 1] - positions_m_[k];
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
  const double u2 = u * u, u3 = u2 * u;
  // Cumulative uniform cubic basis and its u-derivatives.
  const double b1 = (5.0 + 3.0 * u - 3.0 * u2 + u3) / 6.0;
  const double b2 = (1.0 + 3.0 * u + 3.0 * u2 - 2.0 * u3) / 6.0;
  const double b3 = u3 / 6.0;
  const double v = 1.0 - u;
  const double db1 = 0.5 * v * v, db2 = 0.5 + u - u2, db3 = 0.5 * u2;
  const double ddb1 = -v, ddb2 = 1.0 - 2.0 * u, ddb3 = u;

  // Position in R^3: p_i plus basis-weighted differences (see the header).
  const Vec3& dp1 = dp_m_[i];
  const Vec3& dp2 = dp_m_[i + 1];
  const Vec3& dp3 = dp_m_[i + 2];
  out.t_ns = t_ns;
  out.position_m = positions_m_[i] + (b1 * dp1 + b2 * dp2 + b3 * dp3);
  out.velocity_m_s = (db1 * dp1 + db2 * dp2 + db3 * dp3) / dt_s;
  out.acceleration_m_s2 = (ddb1 * dp1 + ddb2 * dp2 + ddb3 * dp3) / (dt_s * dt_s);

  // Rotation: R_i A_1 A_2 A_3 with A_j = exp(B~_j d_j).
  const Vec3& d1 = d_rad_[i];
  const Vec3& d2 = d_rad_[i + 1];
  const Vec3& d3 = d_rad_[i + 2];
  const Quat a2 = exp_scaled(b2, d2, d_norm_rad_[i + 1]);
  const Quat a3 = exp_scaled(b3, d3, d_norm_rad_[i + 2]);
  const Quat a = multiply(multiply(exp_scaled(b1, d1, d_norm_rad_[i]), a2), a3);
  out.attitude.noalias() = attitudes_[i] * matrix(a);

  // Body rate by the recursion w_j = A_j^T w_{j-1} + B~_j' d_j (w_0 = 0), in
  // u units; the angular acceleration alongside it.
  const Vec3 w1 = db1 * d1;
  const Vec3 w2_in = rotate_by_conjugate(a2, w1);
  const Vec3 w2 = w2_in + db2 * d2;
  const Vec3 w3_in = rotate_by_conjugate(a3, w2);
  out.angular_rate_rad_s = (w3_in + db3 * d3) / dt_s;
  if (angular_accel_rad_s2 != nullptr) {
    const Vec3 al1 = ddb1 * d1;
    const Vec3 al2 = rotate_by_conjugate(a2, al1) + ddb2 * d2 + w2_in.cross(db2 * d2);
    const Vec3 al3 = rotate_by_conjugate(a3, al2) + ddb3 * d3 + w3_in.cross(db3 * d3);
    *angular_accel_rad_s2 = al3 / (dt_s * dt_s);
  }
}

BatchResult run(const std::vector<Pose>& knots, const SceneModel& scene, std::int64_t rate_hz) {
  const Spline spline(knots);
  const std::vector<TimeNs> times = output_grid(spline.start_ns(), spline.end_ns(), rate_hz);
  if (times.size() < 2) throw std::invalid_argument("B-spline output shorter than two samples");
  BatchResult result;
  result.trajectory.resize(times.size());
  result.imu.resize(times.size());
  // Output times ascend, so the segment only ever moves forward: segment s
  // covers [t_{s+1}, t_{s+2}]; a time on a knot goes to the later segment
  // (u = 0) except the very last (u = 1 of the last segment).
  std::size_t segment = 0;
  const std::size_t last = spline.segment_count() - 1;
  for (std::size_t k = 0; k < times.size(); ++k) {
    while (segment < last && knots[segment + 2].t_ns <= times[k]) ++segment;
    Kinematics& kin = result.trajectory[k];
    spline.evaluate_in_segment(segment, times[k], kin);
    result.imu[k] = imu_from_kinematics(scene, kin);
  }
  return result;
}

}  // namespace imuemu::bspline
