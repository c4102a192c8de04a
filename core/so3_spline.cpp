#include "core/so3_spline.hpp"

#include <algorithm>
#include <stdexcept>

#include "core/grid_sampling.hpp"
#include "core/imu_model.hpp"
#include "core/interpolation.hpp"
#include "core/so3.hpp"

namespace imuemu::so3spline {

namespace {

// The cubic rho(t) = ((c2 t + c1) t + c0) t on [0, h] with rho(0) = 0,
// rho(h) = xi, rho'(0) = m0, rho'(h) = m1 (cubic Hermite, t in seconds).
std::array<Vec3, 3> hermite_cubic(const Vec3& xi, const Vec3& m0, const Vec3& m1, double h) {
  return {m0, (3.0 * xi / h - 2.0 * m0 - m1) / h, (m0 + m1 - 2.0 * xi / h) / (h * h)};
}

// The fixed-point iteration stops when no rate moves by more than this
// (relative to the largest rate, or absolute below 1 rad/s); it converges
// geometrically (N is a small quadratic correction) and needs 5-15 rounds at
// 90 deg per knot interval, 2-3 on an aircraft.
constexpr double kRateTolerance = 1e-14;
constexpr int kMaxIterations = 200;

}  // namespace

std::vector<Vec3> c2_knot_rates(std::span<const Pose> knots, const std::optional<Vec3>& first_rate_rad_s,
                                const std::optional<Vec3>& last_rate_rad_s) {
  const std::size_t n = knots.size();
  if (n < 2) throw std::invalid_argument("C2 SO(3) spline needs at least 2 knots");
  std::vector<double> h(n - 1);
  std::vector<Vec3> xi(n - 1);
  std::vector<Mat3> W_xi(n - 1), W_inv_xi(n - 1);
  for (std::size_t k = 0; k + 1 < n; ++k) {
    h[k] = seconds_between(knots[k].t_ns, knots[k + 1].t_ns);
    xi[k] = so3::log(knots[k].attitude.transpose() * knots[k + 1].attitude);
    W_xi[k] = so3::W(xi[k]);
    W_inv_xi[k] = so3::W_inverse(xi[k]);
  }
  std::vector<Vec3> w(n, Vec3::Zero()), N(n - 1, Vec3::Zero());
  std::vector<Mat3> lower(n), diag(n), upper(n);
  std::vector<Vec3> rhs(n);
  for (int iteration = 0; iteration < kMaxIterations; ++iteration) {
    // Rows as in the header: row k is the C2 condition at knot k.
    for (std::size_t k = 0; k < n; ++k) {
      lower[k] = upper[k] = Mat3::Zero();
      if (k == 0) {
        if (first_rate_rad_s) {
          diag[k] = Mat3::Identity();
          rhs[k] = *first_rate_rad_s;
        } else {  // rho_0''(0) = 0: 2 w_0 + W^-1(xi_0) w_1 = 3 xi_0 / h_0
          diag[k] = 2.0 * Mat3::Identity();
          upper[k] = W_inv_xi[0];
          rhs[k] = 3.0 * xi[0] / h[0];
        }
      } else if (k == n - 1) {
        if (last_rate_rad_s) {
          diag[k] = Mat3::Identity();
          rhs[k] = *last_rate_rad_s;
        } else {  // zero angular acceleration at the end of the last segment
          const double a = h[k - 1];
          lower[k] = W_xi[k - 1];
          diag[k] = 2.0 * Mat3::Identity();
          rhs[k] = 3.0 * xi[k - 1] / a - 0.5 * a * N[k - 1];
        }
      } else {
        const double a = h[k - 1], b = h[k];
        lower[k] = b * W_xi[k - 1];
        diag[k] = 2.0 * (a + b) * Mat3::Identity();
        upper[k] = a * W_inv_xi[k];
        rhs[k] = 3.0 * (a / b * xi[k] + b / a * xi[k - 1]) - 0.5 * a * b * N[k - 1];
      }
    }
    // Block Thomas elimination (the diagonal dominates: |W|, |W^-1| stay
    // near 1 for rotations well below pi per segment).
    for (std::size_t k = 1; k < n; ++k) {
      const Mat3 factor = lower[k] * diag[k - 1].inverse();
      diag[k] -= factor * upper[k - 1];
      rhs[k] -= factor * rhs[k - 1];
    }
    std::vector<Vec3> next(n);
    next[n - 1] = diag[n - 1].inverse() * rhs[n - 1];
    for (std::size_t k = n - 1; k-- > 0;) next[k] = diag[k].inverse() * (rhs[k] - upper[k] * next[k + 1]);
    double change = 0.0, scale = 1.0;
    for (std::size_t k = 0; k < n; ++k) {
      change = std::max(change, (next[k] - w[k]).norm());
      scale = std::max(scale, next[k].norm());
    }
    w = std::move(next);
    for (std::size_t k = 0; k + 1 < n; ++k)
      N[k] = so3::angular_acceleration(xi[k], W_inv_xi[k] * w[k + 1], Vec3::Zero());
    if (iteration > 0 && change <= kRateTolerance * scale) break;
  }
  return w;
}

Spline::Spline(const std::vector<Pose>& knots) {
  interp::check_knots(knots);
  const std::size_t n = knots.size();
  std::vector<Vec3> positions(n);
  for (std::size_t k = 0; k < n; ++k) {
    times_.push_back(knots[k].t_ns);
    attitudes_.push_back(knots[k].attitude);
    positions[k] = knots[k].position_m;
  }
  rates_ = c2_knot_rates(knots, std::nullopt, std::nullopt);  // natural ends, as scipy
  for (std::size_t k = 0; k + 1 < n; ++k) {
    const double h = seconds_between(times_[k], times_[k + 1]);
    const Vec3 xi = so3::log(knots[k].attitude.transpose() * knots[k + 1].attitude);
    rho_.push_back(hermite_cubic(xi, rates_[k], so3::W_inverse(xi) * rates_[k + 1], h));
  }
  position_ = naive::NaturalCubicSpline(times_, positions);
}

void Spline::evaluate_in_segment(std::size_t k, TimeNs t_ns, Kinematics& out) const {
  out.t_ns = t_ns;
  position_.evaluate(k, t_ns, out.position_m, out.velocity_m_s, out.acceleration_m_s2);
  const double t = seconds_between(times_[k], t_ns);
  const auto& c = rho_[k];
  const Vec3 rho = ((c[2] * t + c[1]) * t + c[0]) * t;
  const Vec3 rho_dot = (3.0 * c[2] * t + 2.0 * c[1]) * t + c[0];
  out.attitude.noalias() = attitudes_[k] * so3::exp(rho);
  out.angular_rate_rad_s = so3::W(rho) * rho_dot;  // Eq. 3.59
}

Vec3 Spline::angular_acceleration(std::size_t k, TimeNs t_ns) const {
  const double t = seconds_between(times_[k], t_ns);
  const auto& c = rho_[k];
  const Vec3 rho = ((c[2] * t + c[1]) * t + c[0]) * t;
  const Vec3 rho_dot = (3.0 * c[2] * t + 2.0 * c[1]) * t + c[0];
  const Vec3 rho_ddot = 6.0 * c[2] * t + 2.0 * c[1];
  return so3::angular_acceleration(rho, rho_dot, rho_ddot);  // Eq. 3.61
}

BatchResult run(const std::vector<Pose>& knots, const SceneModel& scene, std::int64_t rate_hz) {
  const Spline spline(knots);
  // Segment k ends at knot k + 1.
  return sample_on_output_grid(spline, std::vector<TimeNs>(spline.knot_times_ns().begin() + 1, spline.knot_times_ns().end()), scene,
                               rate_hz, "SO(3) spline");
}

}  // namespace imuemu::so3spline
