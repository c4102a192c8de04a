// Causal cubic Hermite live method (core/causal_hermite.hpp).
#include "core/causal_hermite.hpp"

#include <array>
#include <cmath>
#include <stdexcept>
#include <string>

#include "core/so3.hpp"
#include "core/time_arith.hpp"

namespace imuemu {
namespace {

// Weights w_j with y'(x_n) = sum_j w_j y_j for the polynomial through
// (x_j, y_j), j = 0..n, at its last node (Lagrange basis differentiated):
//   w_j = prod_{m != j, n} (x_n - x_m) / prod_{m != j} (x_j - x_m)   (j < n),
//   w_n = sum_{m < n} 1 / (x_n - x_m).
// x_j are offsets from x_n (x_n = 0), strictly increasing.
std::array<double, 4> slope_weights(const std::array<double, 4>& x, std::size_t count) {
  std::array<double, 4> w{};
  const std::size_t n = count - 1;
  for (std::size_t j = 0; j < n; ++j) {
    double num = 1.0, den = 1.0;
    for (std::size_t m = 0; m < count; ++m) {
      if (m == j) continue;
      den *= x[j] - x[m];
      if (m != n) num *= x[n] - x[m];
    }
    w[j] = num / den;
    w[n] += 1.0 / (x[n] - x[j]);
  }
  return w;
}

}  // namespace

CausalHermite::CausalHermite(const CausalHermiteOptions& options) : options_(options) {
  if (options_.rate_hz < 1) throw std::invalid_argument("causal Hermite: rate_hz must be >= 1");
  if (options_.max_gap_ns < 1) throw std::invalid_argument("causal Hermite: max_gap_ns must be >= 1");
}

TimeNs CausalHermite::grid_time(std::int64_t n) const {
  // origin + floor(n 1e9 / rate) without overflow for any n a run reaches.
  const std::int64_t whole = n / options_.rate_hz, rest = n % options_.rate_hz;
  return saturating_add_ns(saturating_add_ns(run_origin_ns_, saturating_mul_ns(whole, kNsPerSecond)),
                           rest * kNsPerSecond / options_.rate_hz);
}

void CausalHermite::estimate_slopes(Knot& k) const {
  // Causal: only this knot and the ones before it (up to three). The slope
  // at the newest knot of the polynomial through them: third order in h with
  // four knots (a cubic motion's slopes are exact), second with three, the
  // chord with two. Attitudes in the chart of the newest knot, rho_j =
  // log(R_k^T R_j); at rho = 0 the body rate is rho' (W(0) = I, Eq. 3.59).
  const std::size_t count = knots_.size() + 1;
  std::array<double, 4> x{};
  std::array<Vec3, 4> p{}, r{};
  for (std::size_t j = 0; j < knots_.size(); ++j) {
    const Knot& kj = knots_[j];
    x[j] = -static_cast<double>(ns_between(kj.pose.t_ns, k.pose.t_ns)) * 1e-9;
    p[j] = kj.pose.position_m - k.pose.position_m;
    r[j] = so3::log(k.pose.attitude.transpose() * kj.pose.attitude);
  }
  x[count - 1] = 0.0;
  p[count - 1] = r[count - 1] = Vec3::Zero();
  const std::array<double, 4> w = slope_weights(x, count);
  k.velocity_m_s = k.rate_rad_s = Vec3::Zero();
  for (std::size_t j = 0; j < count; ++j) {
    k.velocity_m_s += w[j] * p[j];
    k.rate_rad_s += w[j] * r[j];
  }
}

void CausalHermite::push(const Pose& pose, const PoseRates& rates) {
  auto finite = [](const std::optional<Vec3>& v) { return !v || v->allFinite(); };
  if (!pose.position_m.allFinite() || !pose.attitude.allFinite() || !finite(rates.velocity_m_s) ||
      !finite(rates.angular_rate_rad_s))
    throw std::invalid_argument("causal Hermite: knot at " + std::to_string(pose.t_ns) + " ns is not finite");
  const bool first = knots_pushed_ == 0;
  if (!first && pose.t_ns <= knots_.back().pose.t_ns)
    throw std::invalid_argument("causal Hermite: knot at " + std::to_string(pose.t_ns) +
                                " ns is not later than the previous one at " + std::to_string(knots_.back().pose.t_ns) +
                                " ns");
  const bool new_run = first || ns_between(knots_.back().pose.t_ns, pose.t_ns) >
                                    static_cast<std::uint64_t>(options_.max_gap_ns);
  if (!new_run && !(so3::angle(knots_.back().pose.attitude.transpose() * pose.attitude) <
                    std::numbers::pi - 1e-6))
    throw std::invalid_argument("causal Hermite: knot at " + std::to_string(pose.t_ns) +
                                " ns is rotated by pi from the previous one (no unique geodesic, thesis §3.6.1)");

  Knot k;
  k.pose = pose;
  if (new_run) {
    knots_.clear();
    run_origin_ns_ = pose.t_ns;
    next_index_ = 0;
    ++runs_;
    if (first) first_knot_ns_ = pose.t_ns;
  }
  if (!knots_.empty() && (!rates.velocity_m_s || !rates.angular_rate_rad_s)) {
    estimate_slopes(k);
    ++estimated_slopes_;
  }
  if (rates.velocity_m_s) k.velocity_m_s = *rates.velocity_m_s;
  if (rates.angular_rate_rad_s) k.rate_rad_s = *rates.angular_rate_rad_s;
  // The run's first knot without rates gets the chord's slopes when the
  // second arrives (below), so the first segment is still a proper cubic.
  ++knots_pushed_;
  if (knots_.size() == 1 && knots_.front().estimated_later) {
    Knot& a = knots_.front();
    const double h = seconds_between(a.pose.t_ns, k.pose.t_ns);
    a.velocity_m_s = (k.pose.position_m - a.pose.position_m) / h;
    a.rate_rad_s = so3::log(a.pose.attitude.transpose() * k.pose.attitude) / h;
  }
  k.estimated_later = knots_.empty() && (!rates.velocity_m_s || !rates.angular_rate_rad_s);
  if (!knots_.empty()) emit_segment(knots_.back(), k);
  knots_.push_back(k);
  if (knots_.size() > 3) knots_.pop_front();  // three kept: with the next, four for its slopes
}

void CausalHermite::emit_segment(const Knot& a, const Knot& b) {
  const double h = seconds_between(a.pose.t_ns, b.pose.t_ns);
  const Vec3 dp = b.pose.position_m - a.pose.position_m;
  const Vec3 m0 = a.velocity_m_s * h, m1 = b.velocity_m_s * h;
  // Attitude chart of a: rho(1) = log(R_a^T R_b), slopes carried by W^-1 (Eq. 3.63).
  const Vec3 phi = so3::log(a.pose.attitude.transpose() * b.pose.attitude);
  const Vec3 n0 = a.rate_rad_s * h, n1 = so3::W_inverse(phi) * b.rate_rad_s * h;
  for (;;) {
    const TimeNs t = grid_time(next_index_);
    if (t > b.pose.t_ns) break;
    const double u = seconds_between(a.pose.t_ns, t) / h;
    // Cubic Hermite basis and its first two derivatives in u.
    const double u2 = u * u, u3 = u2 * u;
    const double h10 = u3 - 2 * u2 + u, h01 = -2 * u3 + 3 * u2, h11 = u3 - u2;
    const double d10 = 3 * u2 - 4 * u + 1, d01 = -6 * u2 + 6 * u, d11 = 3 * u2 - 2 * u;
    const double s10 = 6 * u - 4, s01 = -12 * u + 6, s11 = 6 * u - 2;
    CausalSample s;
    Kinematics& k = s.kinematics;
    k.t_ns = t;
    // p(u) = p_a + h10 m0 + h01 dp + h11 m1 (h00 p_a + h01 p_b rewritten about p_a).
    k.position_m = a.pose.position_m + h10 * m0 + h01 * dp + h11 * m1;
    k.velocity_m_s = (d10 * m0 + d01 * dp + d11 * m1) / h;
    k.acceleration_m_s2 = (s10 * m0 + s01 * dp + s11 * m1) / (h * h);
    const Vec3 rho = h10 * n0 + h01 * phi + h11 * n1;
    const Vec3 rho_dot = (d10 * n0 + d01 * phi + d11 * n1) / h;
    k.attitude = a.pose.attitude * so3::exp(rho);
    k.angular_rate_rad_s = so3::W(rho) * rho_dot;  // Eq. 3.59
    s.imu = imu_from_kinematics(options_.scene, k);
    s.imu.t_ns = t;
    out_.push_back(s);
    newest_output_ns_ = t;
    any_output_ = true;
    ++next_index_;
  }
}

bool CausalHermite::pop(CausalSample& out) {
  if (out_.empty()) return false;
  out = out_.front();
  out_.pop_front();
  return true;
}

TimeNs CausalHermite::current_lag_ns() const {
  if (!any_output_ || knots_.empty()) return 0;
  return saturating_sub_ns(knots_.back().pose.t_ns, newest_output_ns_);
}

}  // namespace imuemu
