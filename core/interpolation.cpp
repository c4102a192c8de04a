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

// Natural cubic spline through the knot positions (thesis §3.5: d^(4) = 0
// gives cubic position segments; §3.6.1 suggests a C2 cubic spline). Returns
// the second derivatives M_j (m/s^2) at the knots, M_0 = M_n = 0, from the
// standard tridiagonal system for non-uniform spacing, solved by the Thomas
// algorithm (diagonally dominant, so no pivoting is needed).
std::vector<Vec3> natural_spline_second_derivatives(const std::vector<Pose>& knots) {
  const std::size_t n = knots.size();
  std::vector<Vec3> M(n, Vec3::Zero());
  if (n < 3) return M;  // two knots: the natural spline is the straight line
  std::vector<double> h(n - 1);
  for (std::size_t j = 0; j + 1 < n; ++j) h[j] = seconds_between(knots[j].t_ns, knots[j + 1].t_ns);
  // Unknowns M_1..M_{n-2}; row j: h_{j-1} M_{j-1} + 2(h_{j-1}+h_j) M_j + h_j M_{j+1} = rhs_j.
  const std::size_t m = n - 2;
  std::vector<double> diag(m), upper(m);
  std::vector<Vec3> rhs(m);
  for (std::size_t k = 0; k < m; ++k) {
    const std::size_t j = k + 1;
    diag[k] = 2.0 * (h[j - 1] + h[j]);
    upper[k] = h[j];
    rhs[k] = 6.0 * ((knots[j + 1].position_m - knots[j].position_m) / h[j] -
                    (knots[j].position_m - knots[j - 1].position_m) / h[j - 1]);
  }
  // Forward elimination: the sub-diagonal of row k is h_{k} (= h[j-1]).
  for (std::size_t k = 1; k < m; ++k) {
    const double factor = h[k] / diag[k - 1];
    diag[k] -= factor * upper[k - 1];
    rhs[k] -= factor * rhs[k - 1];
  }
  M[m] = rhs[m - 1] / diag[m - 1];
  for (std::size_t k = m - 1; k-- > 0;) M[k + 1] = (rhs[k] - upper[k] * M[k + 2]) / diag[k];
  return M;
}

// Clamped cubic spline through the knot positions for Method::hermite: end
// slopes from second-order one-sided differences (a natural spline forces zero
// acceleration at both ends, which is wrong for a vehicle that is turning or
// accelerating there). Returns the second derivatives M_j at every knot.
std::vector<Vec3> clamped_spline_second_derivatives(const std::vector<Pose>& knots) {
  const std::size_t n = knots.size();
  std::vector<Vec3> M(n, Vec3::Zero());
  if (n < 3) return M;  // two knots: the straight line
  std::vector<double> h(n - 1);
  for (std::size_t j = 0; j + 1 < n; ++j) h[j] = seconds_between(knots[j].t_ns, knots[j + 1].t_ns);
  auto y = [&](std::size_t j) -> const Vec3& { return knots[j].position_m; };
  // Slopes at the ends: derivative of the parabola through three knots.
  const double b1 = h[0], b2 = h[0] + h[1];
  const Vec3 s0 = b2 / (b1 * (b2 - b1)) * (y(1) - y(0)) - b1 / (b2 * (b2 - b1)) * (y(2) - y(0));
  const double a1 = h[n - 2], a2 = h[n - 2] + h[n - 3];
  const Vec3 sn = -a2 / (a1 * (a2 - a1)) * (y(n - 2) - y(n - 1)) + a1 / (a2 * (a2 - a1)) * (y(n - 3) - y(n - 1));
  // Rows 0..n-1 of the tridiagonal system (sub, diag, super, rhs).
  std::vector<double> sub(n, 0.0), diag(n), sup(n, 0.0);
  std::vector<Vec3> rhs(n);
  diag[0] = 2.0 * h[0];
  sup[0] = h[0];
  rhs[0] = 6.0 * ((y(1) - y(0)) / h[0] - s0);
  for (std::size_t j = 1; j + 1 < n; ++j) {
    sub[j] = h[j - 1];
    diag[j] = 2.0 * (h[j - 1] + h[j]);
    sup[j] = h[j];
    rhs[j] = 6.0 * ((y(j + 1) - y(j)) / h[j] - (y(j) - y(j - 1)) / h[j - 1]);
  }
  sub[n - 1] = h[n - 2];
  diag[n - 1] = 2.0 * h[n - 2];
  rhs[n - 1] = 6.0 * (sn - (y(n - 1) - y(n - 2)) / h[n - 2]);
  for (std::size_t j = 1; j < n; ++j) {
    const double factor = sub[j] / diag[j - 1];
    diag[j] -= factor * sup[j - 1];
    rhs[j] -= factor * rhs[j - 1];
  }
  M[n - 1] = rhs[n - 1] / diag[n - 1];
  for (std::size_t j = n - 1; j-- > 0;) M[j] = (rhs[j] - sup[j] * M[j + 1]) / diag[j];
  return M;
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
std::vector<Vec3> hermite_knot_rates(const std::vector<Pose>& knots, const std::vector<Vec3>& seg_log) {
  const std::size_t n = knots.size();
  std::vector<Vec3> w(n);
  auto h = [&](std::size_t j) { return seconds_between(knots[j].t_ns, knots[j + 1].t_ns); };
  if (n == 2) {
    w[0] = w[1] = seg_log[0] / h(0);
    return w;
  }
  {
    const double b1 = h(0), b2 = h(0) + h(1);
    const Vec3 f1 = seg_log[0];
    const Vec3 f2 = so3::log(knots[0].attitude.transpose() * knots[2].attitude);
    w[0] = b2 / (b1 * (b2 - b1)) * f1 - b1 / (b2 * (b2 - b1)) * f2;
  }
  {
    const double a1 = h(n - 2), a2 = h(n - 2) + h(n - 3);
    const Vec3 f1 = so3::log(knots[n - 1].attitude.transpose() * knots[n - 2].attitude);
    const Vec3 f2 = so3::log(knots[n - 1].attitude.transpose() * knots[n - 3].attitude);
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

void check_knots(const std::vector<Pose>& knots) {
  if (knots.size() < 2) {
    throw InterpolationError("interpolation needs at least 2 knots, got " +
                             std::to_string(knots.size()));
  }
  for (std::size_t i = 0; i < knots.size(); ++i) {
    if (!knots[i].position_m.allFinite() || !knots[i].attitude.allFinite()) {
      throw InterpolationError("knot " + knot_name(i, knots[i].t_ns) +
                               ": position or attitude is not finite");
    }
  }
  for (std::size_t i = 1; i < knots.size(); ++i) {
    const Pose& p = knots[i - 1];
    const Pose& q = knots[i];
    const std::string names =
        "knots " + knot_name(i - 1, p.t_ns) + " and " + knot_name(i, q.t_ns) + ": ";
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
}

std::vector<ParkRavaniSegment> park_ravani_coefficients(const std::vector<Pose>& knots,
                                                        const Options& options) {
  check_knots(knots);
  const std::size_t n_seg = knots.size() - 1;
  std::vector<ParkRavaniSegment> seg(n_seg);
  for (std::size_t i = 0; i < n_seg; ++i) {
    seg[i].duration_s = seconds_between(knots[i].t_ns, knots[i + 1].t_ns);
  }
  // Segment 1 (§3.6.1): c_1 = omega_0, b_1 = alpha_0 / 2, a_1 = r_1 - b_1 - c_1.
  // The thesis takes h = 1; with tau = (t - t_0)/h the tau-derivatives carry
  // factors h and h^2.
  {
    const Vec3 r1 = so3::log(knots[0].attitude.transpose() * knots[1].attitude);
    const double h = seg[0].duration_s;
    seg[0].c = options.initial_rate_from_first_segment ? r1 : Vec3(options.initial_rate_rad_s * h);
    seg[0].b = 0.5 * h * h * options.initial_angular_accel_rad_s2;
    seg[0].a = r1 - seg[0].b - seg[0].c;
  }
  for (std::size_t k = 1; k < n_seg; ++k) {
    const ParkRavaniSegment& prev = seg[k - 1];
    // s = r(1), t = r'(1), u = r''(1) of the previous segment (tau units).
    const Vec3 s = prev.a + prev.b + prev.c;  // = r_{i-1} by construction of a_{i-1}
    const Vec3 t = 3.0 * prev.a + 2.0 * prev.b + prev.c;
    const Vec3 u = 6.0 * prev.a + 2.0 * prev.b;
    // Body rate and acceleration at the end of the previous segment are
    // W(s) t / h_prev and alpha(s, t, u) / h_prev^2 (Eq. 3.60, 3.61); at the
    // start of this one (r = 0, W = I) they are c / h and 2 b / h^2. Equating
    // them gives the thesis' c_i = W_{i-1} t and b_i = alpha/2 for h = 1.
    const double ratio = seg[k].duration_s / prev.duration_s;
    const Vec3 r_i = so3::log(knots[k].attitude.transpose() * knots[k + 1].attitude);
    seg[k].c = ratio * (so3::W(s) * t);
    seg[k].b = 0.5 * ratio * ratio * so3::angular_acceleration(s, t, u);
    seg[k].a = r_i - seg[k].b - seg[k].c;  // r(1) = r_i: continuity of R
    // The recursion amplifies any error by ~(2 + sqrt 3) per knot (the
    // thesis' "no physical sense" for many knots, App. B): after a few hundred
    // knots even rounding overflows. Refuse instead of returning NaN attitudes.
    if (!seg[k].a.allFinite() || !seg[k].b.allFinite() || !seg[k].c.allFinite()) {
      throw InterpolationError("park-ravani diverged between knots " + knot_name(k, knots[k].t_ns) + " and " +
                               knot_name(k + 1, knots[k + 1].t_ns) +
                               ": coefficients overflowed (the §3.6.1 recursion amplifies errors ~3.7x per "
                               "knot); use geodesic interpolation with smoothing (§3.6.2) for long trajectories");
    }
  }
  return seg;
}

std::vector<Pose> interpolate(const std::vector<Pose>& knots, const std::vector<TimeNs>& times,
                              const Options& options, std::span<const double> extra_ns) {
  if (!extra_ns.empty() && extra_ns.size() != times.size())
    throw std::invalid_argument("interpolate: extra_ns must be empty or match times");
  check_knots(knots);
  const std::size_t n = knots.size();
  if (!times.empty() && (times.front() < knots.front().t_ns || times.back() > knots.back().t_ns)) {
    throw std::invalid_argument("interpolate: output times [" + format_time(times.front()) + ", " +
                                format_time(times.back()) + "] s leave the knot span [" +
                                format_time(knots.front().t_ns) + ", " +
                                format_time(knots.back().t_ns) + "] s");
  }

  // Per-segment data computed once: the geodesic direction log(R_{i-1}^T R_i)
  // (Eq. 3.44) or the Park-Ravani polynomial; position spline curvatures.
  std::vector<Vec3> seg_log;
  std::vector<ParkRavaniSegment> pr;
  std::vector<Vec3> spline_M;
  std::vector<Vec3> knot_rate;  // hermite: body rate at each knot (rad/s)
  if (options.method == Method::park_ravani) {
    pr = park_ravani_coefficients(knots, options);
    spline_M = natural_spline_second_derivatives(knots);
  } else {
    seg_log.resize(n - 1);
    for (std::size_t i = 0; i + 1 < n; ++i) {
      seg_log[i] = so3::log(knots[i].attitude.transpose() * knots[i + 1].attitude);
    }
  }
  std::vector<Vec3> end_tangent;  // hermite: h W^-1(xi_m) w_{m+1}, per segment
  if (options.method == Method::hermite) {
    spline_M = clamped_spline_second_derivatives(knots);
    knot_rate = hermite_knot_rates(knots, seg_log);
    end_tangent.resize(n - 1);
    for (std::size_t m = 0; m + 1 < n; ++m)
      end_tangent[m] = seconds_between(knots[m].t_ns, knots[m + 1].t_ns) * (so3::W_inverse(seg_log[m]) * knot_rate[m + 1]);
  }

  std::vector<Pose> out(times.size());
  std::size_t i = 0;  // current segment: knots[i] .. knots[i+1]
  for (std::size_t k = 0; k < times.size(); ++k) {
    const TimeNs t = times[k];
    if (k > 0 && t < times[k - 1]) {
      throw std::invalid_argument("interpolate: output times are not sorted (index " +
                                  std::to_string(k) + ", t=" + format_time(t) + " s)");
    }
    // Moving segment index: output times are sorted, so this is amortised O(1).
    while (i + 2 < n && t >= knots[i + 1].t_ns) ++i;
    const Pose& k0 = knots[i];
    const Pose& k1 = knots[i + 1];
    Pose& o = out[k];
    o.t_ns = t;
    // At a knot time return the knot itself: every method interpolates the
    // knots (p(0) = 0, p(1) = 1; r(0) = 0, r(1) = r_i), so this only removes
    // rounding.
    const double extra = extra_ns.empty() ? 0.0 : extra_ns[k];
    if (extra == 0.0 && (t == k0.t_ns || t == k1.t_ns)) {
      const Pose& kn = (t == k0.t_ns) ? k0 : k1;
      o.position_m = kn.position_m;
      o.attitude = kn.attitude;
      continue;
    }
    const double tau = (static_cast<double>(t - k0.t_ns) + extra) / static_cast<double>(k1.t_ns - k0.t_ns);
    switch (options.method) {
      case Method::geodesic:
        o.attitude.noalias() = k0.attitude * so3::exp(tau * seg_log[i]);
        o.position_m = k0.position_m + tau * (k1.position_m - k0.position_m);
        break;
      case Method::min_acceleration: {
        // Lemma 3.22: the geodesic re-timed by the cubic warp p(tau).
        const double p = min_acceleration_warp(tau, options.sigma, options.mu);
        o.attitude.noalias() = k0.attitude * so3::exp(p * seg_log[i]);
        o.position_m = k0.position_m + p * (k1.position_m - k0.position_m);
        break;
      }
      case Method::hermite: {
        // Cubic Hermite in tau with rho(0) = 0, rho(1) = xi, rho'(0) = h w_m,
        // rho'(1) = h W^-1(xi) w_{m+1} (tau units).
        const double h = seconds_between(k0.t_ns, k1.t_ns);
        const double t2 = tau * tau, t3 = t2 * tau;
        const Vec3& xi = seg_log[i];
        const Vec3 rho = (t3 - 2.0 * t2 + tau) * h * knot_rate[i] + (3.0 * t2 - 2.0 * t3) * xi +
                         (t3 - t2) * end_tangent[i];
        o.attitude.noalias() = k0.attitude * so3::exp(rho);
        const double A = 1.0 - tau;
        o.position_m = k0.position_m + (tau * (k1.position_m - k0.position_m) +
                                        ((A * A * A - A) * spline_M[i] + (t3 - tau) * spline_M[i + 1]) * (h * h / 6.0));
        break;
      }
      case Method::park_ravani: {
        const ParkRavaniSegment& s = pr[i];
        const Vec3 r = ((s.a * tau + s.b) * tau + s.c) * tau;  // Eq. 3.64
        o.attitude.noalias() = k0.attitude * so3::exp(r);
        // Natural cubic spline on [t_i, t_{i+1}] with A = 1 - tau, B = tau.
        const double A = 1.0 - tau;
        const double h = s.duration_s;
        o.position_m = A * k0.position_m + tau * k1.position_m +
                       ((A * A * A - A) * spline_M[i] + (tau * tau * tau - tau) * spline_M[i + 1]) *
                           (h * h / 6.0);
        break;
      }
    }
  }
  return out;
}

std::vector<PositionCubic> position_cubics(const std::vector<Pose>& knots, const Options& options) {
  const std::size_t n = knots.size();
  std::vector<PositionCubic> out(n - 1);
  std::vector<Vec3> M;
  if (options.method == Method::park_ravani) M = natural_spline_second_derivatives(knots);
  if (options.method == Method::hermite) M = clamped_spline_second_derivatives(knots);
  for (std::size_t m = 0; m + 1 < n; ++m) {
    const Vec3 step = knots[m + 1].position_m - knots[m].position_m;
    switch (options.method) {
      case Method::geodesic:
        out[m] = {step, Vec3::Zero(), Vec3::Zero()};
        break;
      case Method::min_acceleration: {
        // p = sigma (tau - 2tau^2 + tau^3) + (3tau^2 - 2tau^3) + mu (tau^3 - tau^2)
        const double s = options.sigma, u = options.mu;
        out[m] = {s * step, (3.0 - 2.0 * s - u) * step, (s + u - 2.0) * step};
        break;
      }
      case Method::park_ravani:
      case Method::hermite: {
        // tau step + ((A^3 - A) M_m + (tau^3 - tau) M_{m+1}) h^2/6, A = 1 - tau,
        // A^3 - A = -2tau + 3tau^2 - tau^3.
        const double h = seconds_between(knots[m].t_ns, knots[m + 1].t_ns);
        const double k = h * h / 6.0;
        out[m] = {step + (-2.0 * M[m] - M[m + 1]) * k, 3.0 * M[m] * k, (M[m + 1] - M[m]) * k};
        break;
      }
    }
  }
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
