#include "core/naive_spline.hpp"

#include <Eigen/Geometry>  // Vec3::cross
#include <GeographicLib/Constants.hpp>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>

#include "core/attitude.hpp"
#include "core/earth.hpp"
#include "core/grid_sampling.hpp"
#include "core/imu_model.hpp"
#include "core/interpolation.hpp"

namespace imuemu::naive {

// ------------------------------------------------------- NaturalCubicSpline

NaturalCubicSpline::NaturalCubicSpline(const std::vector<TimeNs>& times, const std::vector<Vec3>& values)
    : times_(times), y_(values) {
  const std::size_t n = times.size();
  if (n < 2 || values.size() != n) {
    throw std::invalid_argument("natural cubic spline needs at least 2 knots and one value per knot");
  }
  std::vector<double> h(n - 1);
  std::vector<Vec3> slope(n - 1);
  for (std::size_t k = 0; k + 1 < n; ++k) {
    if (times[k + 1] <= times[k]) throw std::invalid_argument("natural cubic spline: times must increase");
    h[k] = seconds_between(times[k], times[k + 1]);
    slope[k] = (values[k + 1] - values[k]) / h[k];  // differences of nearby values: exact
  }
  // Second derivatives M_k with M_0 = M_{n-1} = 0 (natural ends):
  //   h_{k-1} M_{k-1} + 2 (h_{k-1} + h_k) M_k + h_k M_{k+1} = 6 (s_k - s_{k-1}).
  // Strictly diagonally dominant, so the Thomas algorithm needs no pivoting.
  std::vector<Vec3> M(n, Vec3::Zero());
  if (n > 2) {
    const std::size_t m = n - 2;
    std::vector<double> c_prime(m);
    std::vector<Vec3> r_prime(m);
    for (std::size_t j = 0; j < m; ++j) {
      const std::size_t k = j + 1;
      const double lower = h[k - 1], diag = 2.0 * (h[k - 1] + h[k]), upper = h[k];
      const Vec3 rhs = 6.0 * (slope[k] - slope[k - 1]);
      if (j == 0) {
        c_prime[j] = upper / diag;
        r_prime[j] = rhs / diag;
      } else {
        const double denom = diag - lower * c_prime[j - 1];
        c_prime[j] = upper / denom;
        r_prime[j] = (rhs - lower * r_prime[j - 1]) / denom;
      }
    }
    M[m] = r_prime[m - 1];
    for (std::size_t j = m - 1; j-- > 0;) M[j + 1] = r_prime[j] - c_prime[j] * M[j + 2];
  }
  b_.resize(n - 1);
  c_.resize(n - 1);
  d_.resize(n - 1);
  for (std::size_t k = 0; k + 1 < n; ++k) {
    b_[k] = slope[k] - h[k] * (2.0 * M[k] + M[k + 1]) / 6.0;
    c_[k] = 0.5 * M[k];
    d_[k] = (M[k + 1] - M[k]) / (6.0 * h[k]);
  }
}

std::size_t NaturalCubicSpline::segment_of(TimeNs t_ns) const {
  const auto it = std::upper_bound(times_.begin(), times_.end(), t_ns);
  const auto after = static_cast<std::size_t>(it - times_.begin());  // first knot > t
  return std::clamp<std::size_t>(after, 1, segment_count()) - 1;
}

void NaturalCubicSpline::evaluate(std::size_t k, TimeNs t_ns, Vec3& y, Vec3& dy, Vec3& ddy) const {
  const double tau = seconds_between(times_[k], t_ns);
  const Vec3& b = b_[k];
  const Vec3& c = c_[k];
  const Vec3& d = d_[k];
  y = y_[k] + tau * (b + tau * (c + tau * d));
  dy = b + tau * (2.0 * c + 3.0 * tau * d);
  ddy = 2.0 * c + 6.0 * tau * d;
}

// ------------------------------------------------------------------ Spline

namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;

// Adds the multiple of 2 pi to `angle` that brings it within pi of `previous`.
double unwrap_towards(double previous, double angle) {
  return angle + kTwoPi * std::round((previous - angle) / kTwoPi);
}

Mat3 ned_to_ecef_at(const Vec3& x_e_m) {
  const earth::Geodetic g = earth::geodetic_from_ecef(x_e_m);
  return attitude::ned_to_ecef(g.latitude_rad, g.longitude_rad);
}

}  // namespace

Spline::Spline(const std::vector<Pose>& knots, Physics physics) : physics_(physics) {
  interp::check_knots(knots);
  const std::size_t n = knots.size();
  times_.resize(n);
  std::vector<Vec3> positions(n), angles(n);
  for (std::size_t k = 0; k < n; ++k) {
    times_[k] = knots[k].t_ns;
    positions[k] = knots[k].position_m;
    // Eq. 1.4: R_b^e = R_l^e R_b^l, so R_b^l = R_l^e^T R_b^e at the knot.
    const Mat3 R_b_l =
        physics == Physics::ecef ? Mat3(ned_to_ecef_at(knots[k].position_m).transpose() * knots[k].attitude)
                                 : knots[k].attitude;
    const attitude::HeadingPitchRoll hpr = attitude::hpr_from_rotation(R_b_l);
    angles[k] = Vec3(hpr.heading_rad, hpr.pitch_rad, hpr.roll_rad);
    if (k > 0) {
      angles[k].x() = unwrap_towards(angles[k - 1].x(), angles[k].x());
      angles[k].z() = unwrap_towards(angles[k - 1].z(), angles[k].z());
    }
  }
  position_ = NaturalCubicSpline(times_, positions);
  hpr_ = NaturalCubicSpline(times_, angles);
}

void Spline::evaluate(TimeNs t_ns, Kinematics& out) const {
  if (t_ns < start_ns() || t_ns > end_ns()) {
    throw std::out_of_range("naive spline evaluated at " + std::to_string(t_ns) + " ns, outside its knots [" +
                            std::to_string(start_ns()) + ", " + std::to_string(end_ns()) + "] ns");
  }
  evaluate_in_segment(position_.segment_of(t_ns), t_ns, out);
}

void Spline::evaluate_in_segment(std::size_t k, TimeNs t_ns, Kinematics& out) const {
  out.t_ns = t_ns;
  position_.evaluate(k, t_ns, out.position_m, out.velocity_m_s, out.acceleration_m_s2);
  Vec3 angle, rate, unused;
  hpr_.evaluate(k, t_ns, angle, rate, unused);
  const double psi_dot = rate.x(), th_dot = rate.y(), g_dot = rate.z();
  const double st = std::sin(angle.y()), ct = std::cos(angle.y());
  const double sg = std::sin(angle.z()), cg = std::cos(angle.z());
  const Mat3 R_b_l = attitude::rotation_from_hpr({angle.x(), angle.y(), angle.z()});  // Eq. 1.2
  // Body rate of R_z(psi) R_y(theta) R_x(gamma) relative to the local frame.
  const Vec3 w_lb_b(g_dot - psi_dot * st, th_dot * cg + psi_dot * sg * ct, -th_dot * sg + psi_dot * cg * ct);
  if (physics_ == Physics::flat) {
    out.attitude = R_b_l;
    out.angular_rate_rad_s = w_lb_b;
    return;
  }
  // ecef: the local frame at the spline position turns with the transport rate.
  const earth::Geodetic g = earth::geodetic_from_ecef(out.position_m);
  const Mat3 R_l_e = attitude::ned_to_ecef(g.latitude_rad, g.longitude_rad);
  out.attitude.noalias() = R_l_e * R_b_l;  // Eq. 1.4
  const Vec3 v_l = R_l_e.transpose() * out.velocity_m_s;
  const double a = GeographicLib::Constants::WGS84_a(), f = GeographicLib::Constants::WGS84_f();
  const double e2 = f * (2.0 - f);
  const double sphi = std::sin(g.latitude_rad), cphi = std::cos(g.latitude_rad);
  const double w = 1.0 - e2 * sphi * sphi;
  const double N = a / std::sqrt(w);           // prime-vertical radius
  const double M = a * (1.0 - e2) / (w * std::sqrt(w));  // meridian radius
  // phi' = v_N / (M + h), lambda' = v_E / ((N + h) cos phi).
  const double lambda_dot_cos = v_l.y() / (N + g.height_m);
  const Vec3 w_el_l(lambda_dot_cos, -v_l.x() / (M + g.height_m), -lambda_dot_cos * sphi / cphi);
  out.angular_rate_rad_s = w_lb_b + R_b_l.transpose() * w_el_l;
}

BatchResult run(const std::vector<Pose>& knots, const SceneModel& scene, std::int64_t rate_hz) {
  const Spline spline(knots, scene.physics);
  std::vector<TimeNs> segment_end_ns;  // segment k ends at knot k + 1
  for (std::size_t k = 1; k < knots.size(); ++k) segment_end_ns.push_back(knots[k].t_ns);
  return sample_on_output_grid(spline, segment_end_ns, scene, rate_hz, "naive spline");
}

}  // namespace imuemu::naive
