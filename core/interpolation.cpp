#include "core/interpolation.hpp"

#include <cinttypes>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <numbers>

#include "core/so3.hpp"

namespace imuemu::interp {
namespace {

// "12.345678901" from integer nanoseconds, without going through a double
// (absolute times can exceed 2^53 ns).
std::string format_time(TimeNs t_ns) {
  const bool negative = t_ns < 0;
  // Magnitude via unsigned arithmetic so INT64_MIN does not overflow.
  const std::uint64_t mag =
      negative ? std::uint64_t{0} - static_cast<std::uint64_t>(t_ns) : static_cast<std::uint64_t>(t_ns);
  const std::uint64_t ns_per_s = static_cast<std::uint64_t>(kNsPerSecond);
  char buf[48];
  std::snprintf(buf, sizeof buf, "%s%" PRIu64 ".%09" PRIu64, negative ? "-" : "", mag / ns_per_s,
                mag % ns_per_s);
  return buf;
}

std::string knot_name(std::size_t index, TimeNs t_ns) {
  return std::to_string(index) + " (t=" + format_time(t_ns) + " s)";
}

// Slope (m/s) at knot `at` of the polynomial through the `count` knots
// starting there and going in `direction` (+1 forwards, -1 backwards): the
// derivative of the Lagrange form at its first node, on offsets y_i - y_at
// (nothing cancels at ECEF magnitudes).
Vec3 one_sided_slope(std::span<const Pose> w, std::size_t at, std::size_t count, int direction) {
  std::array<double, 4> x{};
  std::array<Vec3, 4> y{};
  for (std::size_t i = 0; i < count; ++i) {
    const std::size_t j = direction > 0 ? at + i : at - i;
    x[i] = seconds_between(w[at].t_ns, w[j].t_ns);
    y[i] = w[j].position_m - w[at].position_m;
  }
  Vec3 slope = Vec3::Zero();
  for (std::size_t i = 1; i < count; ++i) {
    // L_i'(x_0) = 1/(x_i - x_0) prod_{j != 0, i} (x_0 - x_j)/(x_i - x_j), x_0 = 0.
    double d = 1.0 / x[i];
    for (std::size_t j = 1; j < count; ++j)
      if (j != i) d *= -x[j] / (x[i] - x[j]);
    slope += d * y[i];
  }
  return slope;
}

// Slopes (m/s) at every knot of the cubic spline (C2) through the positions
// of `w` (thesis §3.5: d^(4) = 0 gives cubic position segments; §3.6.1
// suggests a C2 cubic spline). Each end is either natural (zero second
// derivative: the thesis' choice for Park-Ravani at the trajectory's ends) or
// clamped to the slope of the parabola through its three nearest knots (a
// natural end forces zero acceleration, wrong for a vehicle that is turning or
// accelerating there; and inside a trajectory, where a window merely stops,
// the parabola is the right guess). Solved for the second derivatives M_j by
// the Thomas algorithm (diagonally dominant, no pivoting), then
//   s_j = (y_{j+1} - y_j)/h_j - h_j (2 M_j + M_{j+1}) / 6.
std::vector<Vec3> spline_slopes(std::span<const Pose> w, bool natural_first, bool natural_last) {
  const std::size_t n = w.size();
  std::vector<Vec3> slope(n);
  std::vector<double> h(n - 1);
  for (std::size_t j = 0; j + 1 < n; ++j) h[j] = seconds_between(w[j].t_ns, w[j + 1].t_ns);
  auto y = [&](std::size_t j) -> const Vec3& { return w[j].position_m; };
  if (n == 2) {  // two knots: the straight line
    slope[0] = slope[1] = (y(1) - y(0)) / h[0];
    return slope;
  }
  std::vector<double> sub(n, 0.0), diag(n), sup(n, 0.0);
  std::vector<Vec3> rhs(n);
  if (natural_first) {
    diag[0] = 1.0;
    rhs[0] = Vec3::Zero();
  } else {
    const Vec3 s0 = one_sided_slope(w, 0, 3, +1);
    diag[0] = 2.0 * h[0];
    sup[0] = h[0];
    rhs[0] = 6.0 * ((y(1) - y(0)) / h[0] - s0);
  }
  for (std::size_t j = 1; j + 1 < n; ++j) {
    sub[j] = h[j - 1];
    diag[j] = 2.0 * (h[j - 1] + h[j]);
    sup[j] = h[j];
    rhs[j] = 6.0 * ((y(j + 1) - y(j)) / h[j] - (y(j) - y(j - 1)) / h[j - 1]);
  }
  if (natural_last) {
    diag[n - 1] = 1.0;
    rhs[n - 1] = Vec3::Zero();
  } else {
    const Vec3 sn = one_sided_slope(w, n - 1, 3, -1);
    sub[n - 1] = h[n - 2];
    diag[n - 1] = 2.0 * h[n - 2];
    rhs[n - 1] = 6.0 * (sn - (y(n - 1) - y(n - 2)) / h[n - 2]);
  }
  for (std::size_t j = 1; j < n; ++j) {
    const double factor = sub[j] / diag[j - 1];
    diag[j] -= factor * sup[j - 1];
    rhs[j] -= factor * rhs[j - 1];
  }
  std::vector<Vec3> M(n);
  M[n - 1] = rhs[n - 1] / diag[n - 1];
  for (std::size_t j = n - 1; j-- > 0;) M[j] = (rhs[j] - sup[j] * M[j + 1]) / diag[j];
  for (std::size_t j = 0; j + 1 < n; ++j) slope[j] = (y(j + 1) - y(j)) / h[j] - h[j] * (2.0 * M[j] + M[j + 1]) / 6.0;
  slope[n - 1] = (y(n - 1) - y(n - 2)) / h[n - 2] + h[n - 2] * (M[n - 2] + 2.0 * M[n - 1]) / 6.0;
  return slope;
}

// The rotation vector of R (angle up to 2 pi) nearest to `prediction`: log(R)
// itself or its other representation, the same axis with angle theta - 2 pi.
// For a relative rotation spanning more than one knot interval, whose angle
// may exceed pi; `prediction` (e.g. the sum of the intervals' logs) only picks
// the branch.
Vec3 lifted_log(const Mat3& R, const Vec3& prediction) {
  const Vec3 f = so3::log(R);
  const double theta = f.norm();
  if (!(theta > 0.0)) return f;
  const Vec3 other = f * (1.0 - 2.0 * std::numbers::pi / theta);
  return (other - prediction).norm() < (f - prediction).norm() ? other : f;
}

// Body rate at every knot for Method::hermite. The ends are clamped to the
// second-order one-sided difference of the neighbours' exponential
// coordinates in the end knot's own chart (where rho = 0 and W(0) = I, so
// rho' is the body rate). Interior rates make the Hermite curve C2 in the
// charts: the cubic-spline condition at knot k,
//   h_k m_{k-1} + 2 (h_{k-1} + h_k) m_k + h_{k-1} m_{k+1}
//     = 3 (h_{k-1}/h_k f_{k+1} - h_k/h_{k-1} f_{k-1}),   f_k = 0,
// written in knot k's chart with f_{k+1} = xi_k = log(R_k^T R_{k+1}),
// f_{k-1} = eta_k = log(R_k^T R_{k-1}), m_k = w_k and the neighbours'
// tangents carried into the chart by W^-1 (Eq. 3.63): m_{k+-1} = W^-1 w_{k+-1}.
// A block-tridiagonal system (3x3 blocks) solved by block elimination.
std::vector<Vec3> hermite_knot_rates(std::span<const Pose> knots) {
  const std::size_t n = knots.size();
  std::vector<Vec3> w(n);
  auto h = [&](std::size_t j) { return seconds_between(knots[j].t_ns, knots[j + 1].t_ns); };
  std::vector<Vec3> seg_log(n - 1);
  for (std::size_t j = 0; j + 1 < n; ++j) seg_log[j] = so3::log(knots[j].attitude.transpose() * knots[j + 1].attitude);
  if (n == 2) {
    w[0] = w[1] = seg_log[0] / h(0);
    return w;
  }
  // f2 spans two knot intervals: beyond 90 deg per interval its rotation
  // passes pi and log() returns the other branch, so it is lifted to the one
  // continuous with the path (before issue 14 it was not: at 90 deg/s with
  // 1 Hz knots every window end's rate was wrong by ~pi rad/s and, damped by
  // 0.27^4, left 4e-3 rad/s of gyro error at the knots).
  {
    const double b1 = h(0), b2 = h(0) + h(1);
    const Vec3 f1 = seg_log[0];
    const Vec3 f2 = lifted_log(knots[0].attitude.transpose() * knots[2].attitude, seg_log[0] + seg_log[1]);
    w[0] = b2 / (b1 * (b2 - b1)) * f1 - b1 / (b2 * (b2 - b1)) * f2;
  }
  {
    const double a1 = h(n - 2), a2 = h(n - 2) + h(n - 3);
    const Vec3 f1 = -seg_log[n - 2];  // log(R_{n-1}^T R_{n-2}) = -log(R_{n-2}^T R_{n-1})
    const Vec3 f2 =
        lifted_log(knots[n - 1].attitude.transpose() * knots[n - 3].attitude, -(seg_log[n - 2] + seg_log[n - 3]));
    w[n - 1] = -a2 / (a1 * (a2 - a1)) * f1 + a1 / (a2 * (a2 - a1)) * f2;
  }
  if (n == 3) {
    // One interior knot: solve its row directly.
    const Vec3 eta = so3::log(knots[1].attitude.transpose() * knots[0].attitude);
    const double a = h(0), b = h(1);
    const Vec3 rhs = 3.0 * (a / b * seg_log[1] - b / a * eta) - b * (so3::W_inverse(eta) * w[0]) -
                     a * (so3::W_inverse(seg_log[1]) * w[2]);
    w[1] = rhs / (2.0 * (a + b));
    return w;
  }
  // Rows k = 1..n-2: L_k w_{k-1} + D_k w_k + U_k w_{k+1} = r_k.
  const std::size_t m = n - 2;
  std::vector<Mat3> lower(m), diag(m), upper(m);
  std::vector<Vec3> rhs(m);
  for (std::size_t r = 0; r < m; ++r) {
    const std::size_t k = r + 1;
    const double a = h(k - 1), b = h(k);
    const Vec3 eta = so3::log(knots[k].attitude.transpose() * knots[k - 1].attitude);
    lower[r] = b * so3::W_inverse(eta);
    diag[r] = 2.0 * (a + b) * Mat3::Identity();
    upper[r] = a * so3::W_inverse(seg_log[k]);
    rhs[r] = 3.0 * (a / b * seg_log[k] - b / a * eta);
  }
  rhs[0] -= lower[0] * w[0];
  rhs[m - 1] -= upper[m - 1] * w[n - 1];
  for (std::size_t r = 1; r < m; ++r) {
    const Mat3 factor = lower[r] * diag[r - 1].inverse();
    diag[r] -= factor * upper[r - 1];
    rhs[r] -= factor * rhs[r - 1];
  }
  w[m] = diag[m - 1].inverse() * rhs[m - 1];
  for (std::size_t r = m - 1; r-- > 0;) w[r + 1] = diag[r].inverse() * (rhs[r] - upper[r] * w[r + 2]);
  return w;
}

}  // namespace

double min_acceleration_warp(double tau, double sigma, double mu) {
  // Lemma 3.22 (Eq. 3.49): the cubic with p(0)=0, p(1)=1, p'(0)=sigma,
  // p'(1)=mu, in the Hermite basis: sigma*h10 + h01 + mu*h11.
  const double t2 = tau * tau;
  const double t3 = t2 * tau;
  const double h10 = t3 - 2.0 * t2 + tau;
  const double h01 = -2.0 * t3 + 3.0 * t2;
  const double h11 = t3 - t2;
  return sigma * h10 + h01 + mu * h11;
}

Pose geodesic(const Pose& a, const Pose& b, double tau) {
  // Eq. 3.44: R(tau) = R_1 exp(tau log(R_1^T R_2)), d(tau) linear.
  Pose out;
  out.t_ns = a.t_ns + static_cast<TimeNs>(std::llround(tau * static_cast<double>(b.t_ns - a.t_ns)));
  out.attitude = a.attitude * so3::exp(tau * so3::log(a.attitude.transpose() * b.attitude));
  out.position_m = a.position_m + tau * (b.position_m - a.position_m);
  return out;
}

void check_knot_finite(const Pose& knot, std::size_t index) {
  if (!knot.position_m.allFinite() || !knot.attitude.allFinite())
    throw InterpolationError("knot " + knot_name(index, knot.t_ns) + ": position or attitude is not finite");
}

void check_next_knot(const Pose& p, const Pose& q, std::size_t index) {
  const std::string names = "knots " + knot_name(index - 1, p.t_ns) + " and " + knot_name(index, q.t_ns) + ": ";
  if (q.t_ns <= p.t_ns) throw InterpolationError(names + "times are not strictly increasing");
  // The thesis requires Tr(R_{i-1}^T R_i) != -1 (§3.6.1, §3.6.2): at a
  // relative angle of pi the logarithm, hence the geodesic, is not unique.
  const double angle_rad = so3::angle(p.attitude.transpose() * q.attitude);
  if (!(angle_rad < std::numbers::pi - kAntipodalMarginRad)) {
    char deg[32];
    std::snprintf(deg, sizeof deg, "%.3f", angle_rad * 180.0 / std::numbers::pi);
    throw InterpolationError(names + "attitudes are antipodal (relative rotation " + deg +
                             " deg); the geodesic between them is not unique");
  }
}

void check_knots(const std::vector<Pose>& knots) {
  if (knots.size() < 2) {
    throw InterpolationError("interpolation needs at least 2 knots, got " + std::to_string(knots.size()));
  }
  for (std::size_t i = 0; i < knots.size(); ++i) check_knot_finite(knots[i], i);
  for (std::size_t i = 1; i < knots.size(); ++i) check_next_knot(knots[i - 1], knots[i], i);
}

namespace {

// Park-Ravani segment 1 (§3.6.1): c_1 = omega_0, b_1 = alpha_0 / 2,
// a_1 = r_1 - b_1 - c_1. The thesis takes h = 1; with tau = (t - t_0)/h the
// tau-derivatives carry factors h and h^2.
ParkRavaniSegment park_ravani_first(const Pose& k0, const Pose& k1, const Options& options) {
  ParkRavaniSegment seg;
  seg.duration_s = seconds_between(k0.t_ns, k1.t_ns);
  const Vec3 r1 = so3::log(k0.attitude.transpose() * k1.attitude);
  const double h = seg.duration_s;
  seg.c = options.initial_rate_from_first_segment ? r1 : Vec3(options.initial_rate_rad_s * h);
  seg.b = 0.5 * h * h * options.initial_angular_accel_rad_s2;
  seg.a = r1 - seg.b - seg.c;
  return seg;
}

// Park-Ravani segment k from segment k-1 (knots k -> k+1; `index` = k+1 for messages).
ParkRavaniSegment park_ravani_next(const ParkRavaniSegment& prev, const Pose& k0, const Pose& k1, std::size_t index) {
  ParkRavaniSegment seg;
  seg.duration_s = seconds_between(k0.t_ns, k1.t_ns);
  // s = r(1), t = r'(1), u = r''(1) of the previous segment (tau units).
  const Vec3 s = prev.a + prev.b + prev.c;  // = r_{i-1} by construction of a_{i-1}
  const Vec3 t = 3.0 * prev.a + 2.0 * prev.b + prev.c;
  const Vec3 u = 6.0 * prev.a + 2.0 * prev.b;
  // Body rate and acceleration at the end of the previous segment are
  // W(s) t / h_prev and alpha(s, t, u) / h_prev^2 (Eq. 3.60, 3.61); at the
  // start of this one (r = 0, W = I) they are c / h and 2 b / h^2. Equating
  // them gives the thesis' c_i = W_{i-1} t and b_i = alpha/2 for h = 1.
  const double ratio = seg.duration_s / prev.duration_s;
  const Vec3 r_i = so3::log(k0.attitude.transpose() * k1.attitude);
  seg.c = ratio * (so3::W(s) * t);
  seg.b = 0.5 * ratio * ratio * so3::angular_acceleration(s, t, u);
  seg.a = r_i - seg.b - seg.c;  // r(1) = r_i: continuity of R
  // The recursion amplifies any error by ~(2 + sqrt 3) per knot (the
  // thesis' "no physical sense" for many knots, App. B): after a few hundred
  // knots even rounding overflows. Refuse instead of returning NaN attitudes.
  if (!seg.a.allFinite() || !seg.b.allFinite() || !seg.c.allFinite()) {
    throw InterpolationError("park-ravani diverged between knots " + knot_name(index - 1, k0.t_ns) + " and " +
                             knot_name(index, k1.t_ns) +
                             ": coefficients overflowed (the §3.6.1 recursion amplifies errors ~3.7x per "
                             "knot); use geodesic interpolation with smoothing (§3.6.2) for long trajectories");
  }
  return seg;
}

bool needs_tangents(Method m) { return m == Method::hermite || m == Method::park_ravani; }

}  // namespace

std::vector<ParkRavaniSegment> park_ravani_coefficients(const std::vector<Pose>& knots, const Options& options) {
  check_knots(knots);
  std::vector<ParkRavaniSegment> seg;
  seg.reserve(knots.size() - 1);
  seg.push_back(park_ravani_first(knots[0], knots[1], options));
  for (std::size_t k = 1; k + 1 < knots.size(); ++k) seg.push_back(park_ravani_next(seg.back(), knots[k], knots[k + 1], k + 1));
  return seg;
}

Pose evaluate(const Segment& segment, TimeNs t_ns, double extra_ns) {
  Pose o;
  o.t_ns = t_ns;
  // At a knot time return the knot itself: every method interpolates the
  // knots (rho(0) = 0, rho(1) = log(R_m^T R_{m+1})), so this only removes rounding.
  if (extra_ns == 0.0 && (t_ns == segment.start.t_ns || t_ns == segment.end.t_ns)) {
    const Pose& kn = t_ns == segment.start.t_ns ? segment.start : segment.end;
    o.position_m = kn.position_m;
    o.attitude = kn.attitude;
    return o;
  }
  const double tau = (static_cast<double>(t_ns - segment.start.t_ns) + extra_ns) /
                     static_cast<double>(segment.end.t_ns - segment.start.t_ns);
  const auto& r = segment.rho;
  const auto& p = segment.position;
  o.attitude.noalias() = segment.start.attitude * so3::exp(((r[2] * tau + r[1]) * tau + r[0]) * tau);
  o.position_m = segment.start.position_m + ((p[2] * tau + p[1]) * tau + p[0]) * tau;
  return o;
}

SegmentBuilder::SegmentBuilder(const Options& options) : options_(options) {
  if (needs_tangents(options.method) && options.spline_window_knots < 1)
    throw std::invalid_argument("spline window must be >= 1 knot, got " + std::to_string(options.spline_window_knots));
  lookahead_ = needs_tangents(options.method) ? options.spline_window_knots : 0;
}

void SegmentBuilder::push(const Pose& knot) {
  if (finished_) throw std::logic_error("SegmentBuilder::push after finish");
  check_knot_finite(knot, pushed_);
  if (!knots_.empty()) check_next_knot(knots_.back(), knot, pushed_);
  knots_.push_back(knot);
  ++pushed_;
  build_available(false);
}

void SegmentBuilder::finish() {
  if (finished_) return;
  if (pushed_ < 2) throw InterpolationError("interpolation needs at least 2 knots, got " + std::to_string(pushed_));
  finished_ = true;
  build_available(true);
}

// Tangents at knot k (push index) from the C2 condition over the knots within
// spline_window_knots of it (clipped at the trajectory's ends).
void SegmentBuilder::compute_tangents(std::size_t k, bool finished) {
  const auto L = static_cast<std::size_t>(options_.spline_window_knots);
  const std::size_t lo = k > L ? k - L : 0;
  const std::size_t hi = finished ? std::min(pushed_ - 1, k + L) : k + L;
  std::vector<Pose> window(knots_.begin() + static_cast<std::ptrdiff_t>(lo - first_),
                           knots_.begin() + static_cast<std::ptrdiff_t>(hi - first_ + 1));
  const std::size_t local = k - lo;
  if (options_.method == Method::hermite) rates_.push_back(hermite_knot_rates(window)[local]);
  // Natural ends only where the window ends at the trajectory's own ends
  // (Park-Ravani's natural spline); inside, a window end is clamped.
  const bool natural = options_.method == Method::park_ravani;
  slopes_.push_back(spline_slopes(window, natural && lo == 0, natural && finished && hi == pushed_ - 1)[local]);
}

void SegmentBuilder::build_available(bool finished) {
  const auto L = static_cast<std::size_t>(lookahead_);
  const bool tangents = needs_tangents(options_.method);
  while (next_segment_ + 1 < pushed_) {
    const std::size_t m = next_segment_;
    if (!finished && m + 1 + L >= pushed_) break;  // knot m + 1 + L not here yet
    if (tangents) {
      while (tangents_done_ <= m + 1) compute_tangents(tangents_done_++, finished);
    }
    const Pose& k0 = knots_[m - first_];
    const Pose& k1 = knots_[m + 1 - first_];
    Segment seg;
    seg.start = k0;
    seg.end = k1;
    const Vec3 step = k1.position_m - k0.position_m;
    const double h = seconds_between(k0.t_ns, k1.t_ns);
    const Vec3 xi = so3::log(k0.attitude.transpose() * k1.attitude);
    switch (options_.method) {
      case Method::geodesic:  // Eq. 3.44
        seg.rho = {xi, Vec3::Zero(), Vec3::Zero()};
        seg.position = {step, Vec3::Zero(), Vec3::Zero()};
        break;
      case Method::min_acceleration: {
        // Lemma 3.22: the geodesic re-timed by p(tau) = sigma (tau - 2tau^2 +
        // tau^3) + (3tau^2 - 2tau^3) + mu (tau^3 - tau^2).
        const double sg = options_.sigma, mu = options_.mu;
        const std::array<double, 3> p{sg, 3.0 - 2.0 * sg - mu, sg + mu - 2.0};
        seg.rho = {p[0] * xi, p[1] * xi, p[2] * xi};
        seg.position = {p[0] * step, p[1] * step, p[2] * step};
        break;
      }
      case Method::park_ravani: {
        const ParkRavaniSegment pr =
            m == 0 ? park_ravani_first(k0, k1, options_)
                   : park_ravani_next({pr_prev_[2], pr_prev_[1], pr_prev_[0], pr_prev_duration_s_}, k0, k1, m + 1);
        seg.rho = {pr.c, pr.b, pr.a};
        pr_prev_ = seg.rho;
        pr_prev_duration_s_ = pr.duration_s;
        break;
      }
      case Method::hermite: {
        // Cubic Hermite in tau with rho(0) = 0, rho(1) = xi, rho'(0) = h w_m,
        // rho'(1) = h W^-1(xi) w_{m+1} (tau units).
        const Vec3 a = h * rates_[m - first_];
        const Vec3 e = h * (so3::W_inverse(xi) * rates_[m + 1 - first_]);
        seg.rho = {a, 3.0 * xi - 2.0 * a - e, a - 2.0 * xi + e};
        break;
      }
    }
    if (tangents) {
      // Cubic Hermite position with the spline's knot slopes.
      const Vec3 s0 = h * slopes_[m - first_], s1 = h * slopes_[m + 1 - first_];
      seg.position = {s0, 3.0 * step - 2.0 * s0 - s1, s0 + s1 - 2.0 * step};
    }
    ready_.push_back(seg);
    ++next_segment_;
  }
  // Keep the knots later tangents and segments still read.
  const std::size_t keep_from = next_segment_ > L ? next_segment_ - L : 0;
  while (first_ < keep_from && !knots_.empty()) {
    knots_.pop_front();
    if (!rates_.empty() && options_.method == Method::hermite) rates_.pop_front();
    if (!slopes_.empty() && tangents) slopes_.pop_front();
    ++first_;
  }
}

std::vector<Segment> build_segments(const std::vector<Pose>& knots, const Options& options) {
  check_knots(knots);
  SegmentBuilder builder(options);
  for (const Pose& k : knots) builder.push(k);
  builder.finish();
  return {builder.ready().begin(), builder.ready().end()};
}

std::vector<Pose> interpolate(const std::vector<Pose>& knots, const std::vector<TimeNs>& times,
                              const Options& options, std::span<const double> extra_ns) {
  if (!extra_ns.empty() && extra_ns.size() != times.size())
    throw std::invalid_argument("interpolate: extra_ns must be empty or match times");
  check_knots(knots);
  if (!times.empty() && (times.front() < knots.front().t_ns || times.back() > knots.back().t_ns)) {
    throw std::invalid_argument("interpolate: output times [" + format_time(times.front()) + ", " +
                                format_time(times.back()) + "] s leave the knot span [" +
                                format_time(knots.front().t_ns) + ", " + format_time(knots.back().t_ns) + "] s");
  }
  const std::vector<Segment> segments = build_segments(knots, options);
  std::vector<Pose> out(times.size());
  std::size_t i = 0;  // current segment
  for (std::size_t k = 0; k < times.size(); ++k) {
    const TimeNs t = times[k];
    if (k > 0 && t < times[k - 1]) {
      throw std::invalid_argument("interpolate: output times are not sorted (index " + std::to_string(k) +
                                  ", t=" + format_time(t) + " s)");
    }
    // Moving segment index: output times are sorted, so this is amortised O(1).
    while (i + 1 < segments.size() && t >= segments[i].end.t_ns) ++i;
    out[k] = evaluate(segments[i], t, extra_ns.empty() ? 0.0 : extra_ns[k]);
  }
  return out;
}

std::vector<PositionCubic> position_cubics(const std::vector<Pose>& knots, const Options& options) {
  std::vector<PositionCubic> out;
  for (const Segment& s : build_segments(knots, options)) out.push_back(s.position);
  return out;
}

Method method_from_string(const std::string& name) {
  if (name == "geodesic") return Method::geodesic;
  if (name == "min-accel") return Method::min_acceleration;
  if (name == "park-ravani") return Method::park_ravani;
  if (name == "hermite") return Method::hermite;
  throw std::invalid_argument("unknown interpolation method '" + name +
                              "' (expected geodesic, min-accel, park-ravani or hermite)");
}

std::string to_string(Method m) {
  switch (m) {
    case Method::geodesic:
      return "geodesic";
    case Method::min_acceleration:
      return "min-accel";
    case Method::park_ravani:
      return "park-ravani";
    case Method::hermite:
      return "hermite";
  }
  return "unknown";
}

}  // namespace imuemu::interp
