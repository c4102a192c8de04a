#include "core/pipeline.hpp"

#include <algorithm>
#include <array>
#include <optional>
#include <cmath>
#include <stdexcept>
#include <string>

#include "core/derivatives.hpp"
#include "core/so3.hpp"

namespace imuemu {

Chart chart_from_string(const std::string& name) {
  if (name == "global") return Chart::global;
  if (name == "local") return Chart::local;
  throw std::invalid_argument("chart '" + name + "': expected global or local");
}

std::string to_string(Chart c) { return c == Chart::global ? "global" : "local"; }

Derivatives derivatives_from_string(const std::string& name) {
  if (name == "kernel") return Derivatives::kernel;
  if (name == "finite-difference") return Derivatives::finite_difference;
  throw std::invalid_argument("derivatives '" + name + "': expected kernel or finite-difference");
}

std::string to_string(Derivatives d) { return d == Derivatives::kernel ? "kernel" : "finite-difference"; }

Ends ends_from_string(const std::string& name) {
  if (name == "clip") return Ends::clip;
  if (name == "extrapolate") return Ends::extrapolate;
  throw std::invalid_argument("ends '" + name + "': expected clip or extrapolate");
}

GapPolicy gap_policy_from_string(const std::string& name) {
  if (name == "error") return GapPolicy::error;
  if (name == "split") return GapPolicy::split;
  throw std::invalid_argument("gap policy '" + name + "': expected error or split");
}

std::vector<TimeNs> output_grid(TimeNs t_first_ns, TimeNs t_last_ns, std::int64_t rate_hz) {
  if (rate_hz <= 0 || rate_hz > 1'000'000)
    throw std::invalid_argument("output rate " + std::to_string(rate_hz) + " Hz: expected 1..1000000");
  if (t_last_ns < t_first_ns) throw std::invalid_argument("output grid: end before start");
  // Exact floor arithmetic without 128-bit types: split into whole seconds and
  // a remainder so no product exceeds ~1e15.
  const TimeNs span_ns = t_last_ns - t_first_ns;
  const std::int64_t whole_s = span_ns / kNsPerSecond, rem_ns = span_ns % kNsPerSecond;
  const auto count = static_cast<std::size_t>(whole_s * rate_hz + rem_ns * rate_hz / kNsPerSecond) + 1;
  std::vector<TimeNs> times(count);
  for (std::size_t k = 0; k < count; ++k) {
    const auto ks = static_cast<std::int64_t>(k);
    times[k] = t_first_ns + (ks / rate_hz) * kNsPerSecond + (ks % rate_hz) * kNsPerSecond / rate_hz;
  }
  return times;
}

double output_grid_fraction_ns(std::size_t k, std::int64_t rate_hz) {
  const auto ks = static_cast<std::int64_t>(k);
  return static_cast<double>(((ks % rate_hz) * kNsPerSecond) % rate_hz) / static_cast<double>(rate_hz);
}

namespace {

void report(const ProgressFn& progress, double fraction) {
  if (progress) progress(fraction);
}

// C2 step from 0 to 1 on [0, 1] (quintic smoothstep) and its derivative: blends
// two charts' attitudes so the angular rate stays continuous.
double smoothstep(double x) {
  x = std::clamp(x, 0.0, 1.0);
  return x * x * x * (10.0 + x * (-15.0 + 6.0 * x));
}
double smoothstep_rate(double x) {
  if (x <= 0.0 || x >= 1.0) return 0.0;
  return 30.0 * x * x * (1.0 - x) * (1.0 - x);
}

// Prefix sums of the kernel's weights times k^p (p = 0..3) for the weight,
// its rate and its acceleration: sum_{k=k1..k2} w_k k^p in O(1).
class KernelMoments {
 public:
  explicit KernelMoments(const smoothing::UniformKernel& kernel) : delta_(kernel.delta()) {
    const auto size = static_cast<std::size_t>(2 * delta_ + 2);
    for (auto& by_type : prefix_)
      for (auto& v : by_type) v.assign(size, 0.0);
    long double acc[3][4] = {};
    for (int k = -delta_; k <= delta_; ++k) {
      const double w[3] = {kernel.weight(k), kernel.weight_rate(k), kernel.weight_accel(k)};
      long double kp = 1.0L;
      for (int p = 0; p < 4; ++p) {
        for (int t = 0; t < 3; ++t) {
          acc[t][p] += static_cast<long double>(w[t]) * kp;
          prefix_[t][p][static_cast<std::size_t>(k + delta_ + 1)] = static_cast<double>(acc[t][p]);
        }
        kp *= k;
      }
    }
  }
  // sum over k in [k1, k2] of weight-type t (0 value, 1 rate, 2 accel) times k^p.
  double sum(int t, int p, int k1, int k2) const {
    const auto& v = prefix_[static_cast<std::size_t>(t)][static_cast<std::size_t>(p)];
    return v[static_cast<std::size_t>(k2 + delta_ + 1)] - v[static_cast<std::size_t>(k1 + delta_)];
  }

 private:
  int delta_;
  std::array<std::array<std::vector<double>, 4>, 3> prefix_;
};

// The dense positions as the piecewise cubic the interpolation defines
// (interp::position_cubics), so Eq. 3.68 and its kernel derivatives can be
// integrated segment by segment in closed form: O(knots in the window) per
// output sample instead of O(Delta).
struct PositionModel {
  const std::vector<Pose>* knots = nullptr;
  std::vector<interp::PositionCubic> cubics;
  std::vector<std::size_t> first_index;  // first grid index of each segment (+ n at the end)
  const std::vector<TimeNs>* times = nullptr;
  const std::vector<double>* extra_ns = nullptr;
  std::int64_t rate_hz = 1;
};

// Smooths one block of output samples [begin, end) in a chart at its middle
// sample (or, for the global chart, at the identity and the origin).
// Positions, velocities and accelerations are final and written straight into
// the result (position smoothing is linear, so every chart gives the same
// answer). Attitudes (and, with kernel derivatives, body rates) are chart
// dependent at second order, so the block returns them `overlap` samples
// beyond each end, for the caller to blend with the neighbouring block.
class BlockSolver {
 public:
  BlockSolver(const std::vector<Pose>& dense, const smoothing::UniformKernel& kernel, double period_s,
              Derivatives derivatives, const PositionModel* model = nullptr)
      : dense_(dense), kernel_(kernel), h_s_(period_s), n_(dense.size()), derivatives_(derivatives), model_(model) {
    if (model_ != nullptr) moments_.emplace(kernel);
  }

  // Returns false (writing nothing) if some sample of the window is too far
  // from the reference for the local chart.
  bool solve(std::size_t begin, std::size_t end, std::size_t overlap, bool global,
             const std::vector<TimeNs>& times, BatchResult& out) {
    const std::size_t ref = begin + (end - begin) / 2;
    const Mat3 R_ref = global ? Mat3::Identity() : dense_[ref].attitude;
    const Vec3 d_ref = global ? Vec3::Zero() : dense_[ref].position_m;
    // Attitudes are needed on [a_lo, a_hi) (block plus overlap), positions on
    // the block +-4 (finite differences of finite differences), and Eq. 3.68
    // reads +-Delta around those.
    a_lo_ = begin > overlap ? begin - overlap : 0;
    a_hi_ = std::min(n_, end + overlap);
    const std::size_t reach = static_cast<std::size_t>(kernel_.delta()) + std::max<std::size_t>(overlap, 4);
    lo_ = begin > reach ? begin - reach : 0;
    const std::size_t hi = std::min(n_, end + reach);
    const std::size_t m = hi - lo_;
    rho_.resize(m);
    delta_.resize(m);
    for (std::size_t j = lo_; j < hi; ++j) {
      rho_[j - lo_] = so3::log(R_ref.transpose() * dense_[j].attitude);
      if (!global && rho_[j - lo_].norm() > kMaxChartAngleRad) return false;
      delta_[j - lo_] = dense_[j].position_m - d_ref;
    }
    // The local arrays stop short of a full window only at the true ends 0
    // and n, so clipping them reproduces Eq. 3.68's one-sided windows.
    attitudes_.resize(a_hi_ - a_lo_);
    rates_.resize(a_hi_ - a_lo_);
    for (std::size_t j = a_lo_; j < a_hi_; ++j) {
      if (derivatives_ == Derivatives::kernel) {
        const smoothing::Smoothed r = smoothing::smooth_with_derivatives(kernel_, rho_, j - lo_, false);
        attitudes_[j - a_lo_] = R_ref * so3::exp(r.value);
        rates_[j - a_lo_] = so3::W(r.value) * r.rate;  // Eq. 3.59-3.60, exact r~'
      } else {
        attitudes_[j - a_lo_] = R_ref * so3::exp(smoothing::smooth_at(kernel_, rho_, j - lo_));
      }
    }
    if (derivatives_ == Derivatives::kernel && model_ != nullptr) {
      for (std::size_t i = begin; i < end; ++i) {
        const smoothing::Smoothed d = smooth_position_in_closed_form(i, d_ref);
        Kinematics& kin = out.trajectory[i];
        kin.t_ns = times[i];
        kin.position_m = d_ref + d.value;
        kin.velocity_m_s = d.rate;
        kin.acceleration_m_s2 = d.accel;
      }
      return true;
    }
    if (derivatives_ == Derivatives::kernel) {
      for (std::size_t i = begin; i < end; ++i) {
        const smoothing::Smoothed d = smoothing::smooth_with_derivatives(kernel_, delta_, i - lo_);
        Kinematics& kin = out.trajectory[i];
        kin.t_ns = times[i];
        kin.position_m = d_ref + d.value;
        kin.velocity_m_s = d.rate;
        kin.acceleration_m_s2 = d.accel;
      }
      return true;
    }
    const std::size_t s_lo = begin >= 4 ? begin - 4 : 0;
    const std::size_t s_hi = std::min(n_, end + 4);
    delta_s_.resize(m);
    for (std::size_t j = s_lo; j < s_hi; ++j) delta_s_[j - lo_] = smoothing::smooth_at(kernel_, delta_, j - lo_);
    auto at_delta = [&](std::size_t j) -> const Vec3& { return delta_s_[j - lo_]; };
    velocity_.resize(m);
    const std::size_t v_lo = begin >= 2 ? begin - 2 : 0;
    const std::size_t v_hi = std::min(n_, end + 2);
    for (std::size_t j = v_lo; j < v_hi; ++j) velocity_[j - lo_] = derivatives::stencil(at_delta, j, n_, h_s_);
    auto at_velocity = [&](std::size_t j) -> const Vec3& { return velocity_[j - lo_]; };
    for (std::size_t i = begin; i < end; ++i) {
      Kinematics& kin = out.trajectory[i];
      kin.t_ns = times[i];
      kin.position_m = d_ref + delta_s_[i - lo_];
      kin.velocity_m_s = velocity_[i - lo_];
      kin.acceleration_m_s2 = derivatives::stencil(at_velocity, i, n_, h_s_);
    }
    return true;
  }

  // Smoothed attitudes (and kernel-derived body rates) of the last successful
  // solve, on [a_lo(), a_hi()).
  std::size_t a_lo() const { return a_lo_; }
  std::size_t a_hi() const { return a_hi_; }
  const Mat3& attitude(std::size_t j) const { return attitudes_[j - a_lo_]; }
  const Vec3& rate(std::size_t j) const { return rates_[j - a_lo_]; }

 private:
  // smoothing::smooth_with_derivatives of the dense positions (relative to
  // d_ref) at sample i, with the sums over each knot segment's samples done in
  // closed form: on segment m the offset is a cubic in k (the sample offset
  // from i), d(k) = d_m - d_ref + e0 + e1 k + e2 k^2 + e3 k^3, so
  // sum_k w_k d(k) = sum_p e_p (sum_k w_k k^p) from the prefix moments.
  smoothing::Smoothed smooth_position_in_closed_form(std::size_t i, const Vec3& d_ref) const {
    const PositionModel& pm = *model_;
    const auto delta = static_cast<std::ptrdiff_t>(kernel_.delta());
    const auto ii = static_cast<std::ptrdiff_t>(i);
    const auto k_lo = static_cast<int>(std::max<std::ptrdiff_t>(-delta, -ii));
    const auto k_hi = static_cast<int>(std::min<std::ptrdiff_t>(delta, static_cast<std::ptrdiff_t>(n_) - 1 - ii));
    // Exact instant of grid sample i in ns, as interp::interpolate uses it.
    const double t_i = static_cast<double>((*pm.times)[i] - (*pm.knots)[0].t_ns) + (*pm.extra_ns)[i];
    const double step_ns = 1e9 / static_cast<double>(pm.rate_hz);
    // Polynomial of segment m in k around i: coefficients e0..e3 (relative to d_m).
    auto coefficients = [&](std::size_t m, Vec3 e[4]) {
      const double h_ns = static_cast<double>((*pm.knots)[m + 1].t_ns - (*pm.knots)[m].t_ns);
      const double u0 = (t_i - static_cast<double>((*pm.knots)[m].t_ns - (*pm.knots)[0].t_ns)) / h_ns;
      const double sk = step_ns / h_ns;
      const interp::PositionCubic& c = pm.cubics[m];
      e[0] = ((c[2] * u0 + c[1]) * u0 + c[0]) * u0;
      e[1] = (c[0] + (2.0 * c[1] + 3.0 * c[2] * u0) * u0) * sk;
      e[2] = (c[1] + 3.0 * c[2] * u0) * (sk * sk);
      e[3] = c[2] * (sk * sk * sk);
    };
    auto segment_of = [&](std::size_t j) {
      const auto it = std::upper_bound(pm.first_index.begin(), pm.first_index.end(), j);
      return static_cast<std::size_t>(it - pm.first_index.begin()) - 1;
    };
    // The value at i itself: its own segment's polynomial at k = 0.
    Vec3 e[4];
    const std::size_t m_i = segment_of(i);
    coefficients(m_i, e);
    const Vec3 f_i = (*pm.knots)[m_i].position_m - d_ref + e[0];
    Vec3 s_sum[3] = {Vec3::Zero(), Vec3::Zero(), Vec3::Zero()};
    const std::size_t j_lo = static_cast<std::size_t>(ii + k_lo), j_hi = static_cast<std::size_t>(ii + k_hi);
    for (std::size_t m = segment_of(j_lo); m + 1 < pm.first_index.size() && pm.first_index[m] <= j_hi; ++m) {
      const auto k1 = static_cast<int>(std::max<std::ptrdiff_t>(static_cast<std::ptrdiff_t>(pm.first_index[m]) - ii, k_lo));
      const auto k2 = static_cast<int>(std::min<std::ptrdiff_t>(static_cast<std::ptrdiff_t>(pm.first_index[m + 1]) - 1 - ii, k_hi));
      if (k2 < k1) continue;
      coefficients(m, e);
      const Vec3 base = (*pm.knots)[m].position_m - d_ref + e[0] - f_i;
      for (int t = 0; t < 3; ++t)
        s_sum[t] += base * moments_->sum(t, 0, k1, k2) + e[1] * moments_->sum(t, 1, k1, k2) +
                    e[2] * moments_->sum(t, 2, k1, k2) + e[3] * moments_->sum(t, 3, k1, k2);
    }
    const double d0 = moments_->sum(0, 0, k_lo, k_hi), d1 = moments_->sum(1, 0, k_lo, k_hi),
                 d2 = moments_->sum(2, 0, k_lo, k_hi);
    // Same quotient-rule combination as smoothing::smooth_with_derivatives.
    const double inv = 1.0 / d0;
    smoothing::Smoothed out;
    out.value = f_i + s_sum[0] * inv;
    out.rate = (s_sum[1] - s_sum[0] * (d1 * inv)) * inv;
    out.accel = (s_sum[2] - 2.0 * s_sum[1] * (d1 * inv) - s_sum[0] * (d2 * inv) +
                 2.0 * s_sum[0] * (d1 * d1 * inv * inv)) *
                inv;
    return out;
  }

  const std::vector<Pose>& dense_;
  const smoothing::UniformKernel& kernel_;
  double h_s_;
  std::size_t n_;
  Derivatives derivatives_;
  const PositionModel* model_;
  std::optional<KernelMoments> moments_;
  std::size_t lo_ = 0, a_lo_ = 0, a_hi_ = 0;
  std::vector<Vec3> rho_, delta_, delta_s_, velocity_, rates_;
  std::vector<Mat3> attitudes_;
};

// Moves (R, omega) a fraction s of the way to (R_b, omega_b) along the
// geodesic between them, with s'(t) = s_rate: R = R_a exp(s D), D =
// log(R_a^T R_b), and the exact body rate of that curve,
//   omega = exp(sD)^T omega_a + W(sD) (s' D + s D'),
//   D' = W(D)^-1 (omega_b - exp(D)^T omega_a)   (from R_b = R_a exp(D)).
void blend(Mat3& R, Vec3& omega, const Mat3& R_b, const Vec3& omega_b, double s, double s_rate, bool with_rate) {
  const Vec3 D = so3::log(R.transpose() * R_b);
  const Mat3 E = so3::exp(s * D);
  if (with_rate) {
    const Vec3 D_dot = so3::W_inverse(D) * (omega_b - so3::exp(D).transpose() * omega);
    omega = E.transpose() * omega + so3::W(s * D) * (s_rate * D + s * D_dot);
  }
  R = R * E;
}

BatchResult run_segment(const std::vector<Pose>& knots, const PipelineOptions& options, const ProgressFn& progress) {
  const std::vector<TimeNs> times = output_grid(knots.front().t_ns, knots.back().t_ns, options.rate_hz);
  const std::size_t n = times.size();
  if (n < 2)
    throw std::invalid_argument("trajectory from " + std::to_string(knots.front().t_ns) + " ns is shorter than two output samples");
  const double period_s = 1.0 / static_cast<double>(options.rate_hz);
  std::vector<double> extra_ns(n);
  for (std::size_t k = 0; k < n; ++k) extra_ns[k] = output_grid_fraction_ns(k, options.rate_hz);
  const std::vector<Pose> dense = interp::interpolate(knots, times, options.interpolation, extra_ns);
  report(progress, 0.2);

  const smoothing::UniformKernel kernel(options.kernel, period_s);
  const bool kernel_rates = options.derivatives == Derivatives::kernel;
  if (kernel_rates && kernel.delta() < 1)
    throw std::invalid_argument("kernel derivatives need a window: Delta >= 1");
  BatchResult result;
  result.trajectory.resize(n);
  result.imu.resize(n);
  std::vector<Vec3> rates(kernel_rates ? n : 0);
  PositionModel model;
  const bool closed_form = kernel_rates && options.closed_form_positions;
  if (closed_form) {
    model.knots = &knots;
    model.cubics = interp::position_cubics(knots, options.interpolation);
    model.times = &times;
    model.extra_ns = &extra_ns;
    model.rate_hz = options.rate_hz;
    model.first_index.resize(knots.size());
    for (std::size_t m = 0; m < knots.size(); ++m)
      model.first_index[m] = static_cast<std::size_t>(
          std::lower_bound(times.begin(), times.end(), knots[m].t_ns) - times.begin());
    model.first_index.back() = n;  // the last knot closes the last segment
  }
  BlockSolver solver(dense, kernel, period_s, options.derivatives, closed_form ? &model : nullptr);
  if (options.chart == Chart::global) {
    solver.solve(0, n, 0, true, times, result);
    for (std::size_t i = 0; i < n; ++i) {
      result.trajectory[i].attitude = solver.attitude(i);
      if (kernel_rates) rates[i] = solver.rate(i);
    }
  } else {
    // Local chart: blocks of 2*Delta samples (so each log serves ~2 outputs),
    // halved while the window strays more than kMaxChartAngleRad from the
    // block's reference. Neighbouring blocks' attitudes differ at second order
    // (smoothing in exponential coordinates depends on the chart); they are
    // blended over 2*overlap samples centred on each block boundary.
    const std::size_t nominal = std::max<std::size_t>(16, 2 * static_cast<std::size_t>(kernel.delta()));
    const std::size_t overlap = std::max<std::size_t>(4, static_cast<std::size_t>(kernel.delta()) / 4);
    std::size_t begin = 0, last_report = 0;
    while (begin < n) {
      std::size_t length = std::min(nominal, n - begin);
      while (!solver.solve(begin, begin + length, overlap, false, times, result)) {
        if (length == 1) {
          throw std::invalid_argument(
              "the smoothing window around output sample " + std::to_string(begin) +
              " spans more rotation than a chart can hold (> " + std::to_string(kMaxChartAngleRad) +
              " rad from its centre): reduce Delta or the kernel width, or add knots");
        }
        length = (length + 1) / 2;
      }
      const std::size_t blend_lo = solver.a_lo();  // == begin - overlap (or 0)
      const double blend_len = static_cast<double>(begin + overlap - blend_lo);
      for (std::size_t j = solver.a_lo(); j < solver.a_hi(); ++j) {
        Mat3& R = result.trajectory[j].attitude;
        Vec3 unused = Vec3::Zero();
        Vec3& omega = kernel_rates ? rates[j] : unused;
        if (begin == 0 || j >= begin + overlap) {
          R = solver.attitude(j);
          if (kernel_rates) omega = solver.rate(j);
        } else {
          // Samples before begin+overlap already hold the previous blocks'
          // value: move it towards this block's along the geodesic.
          const double x = (static_cast<double>(j - blend_lo) + 0.5) / blend_len;
          blend(R, omega, solver.attitude(j), kernel_rates ? solver.rate(j) : unused, smoothstep(x),
                smoothstep_rate(x) / (blend_len * period_s), kernel_rates);
        }
      }
      begin += length;
      if (begin - last_report > n / 50) {
        report(progress, 0.2 + 0.7 * static_cast<double>(begin) / static_cast<double>(n));
        last_report = begin;
      }
    }
  }
  for (std::size_t i = 0; i < n; ++i) {
    Kinematics& kin = result.trajectory[i];
    if (kernel_rates) {
      kin.angular_rate_rad_s = rates[i];
    } else {
      // Thesis stencils on the final smoothed attitudes, in each sample's own
      // chart: rho_j = log(R~_i^T R~_j) is 0 at i where W(0) = I, so omega_i
      // is the Eq. 3.71-3.74 derivative of rho at i (Eq. 3.59-3.60).
      const Mat3 Rt = kin.attitude.transpose();
      auto at_rho = [&](std::size_t j) -> Vec3 {
        return j == i ? Vec3::Zero() : so3::log(Rt * result.trajectory[j].attitude);
      };
      kin.angular_rate_rad_s = derivatives::stencil(at_rho, i, n, period_s);
    }
    result.imu[i] = imu_from_kinematics(options.scene, kin);
  }
  report(progress, 1.0);
  return result;
}

// Ends::extrapolate: virtual knots continue the first and last segments along
// their geodesics (Eq. 3.44 with tau outside [0, 1]) for a whole number of
// seconds covering the window, so the padded grid contains the real grid's
// instants exactly; the padded samples are computed and then dropped.
BatchResult run_segment_extrapolated(const std::vector<Pose>& knots, const PipelineOptions& options,
                                     const ProgressFn& progress) {
  const std::int64_t pad_samples = options.kernel.delta + 8;
  const std::int64_t pad_s = (pad_samples + options.rate_hz - 1) / options.rate_hz;
  const TimeNs pad_ns = pad_s * kNsPerSecond;
  auto extend = [&](const Pose& from, const Pose& towards, const Pose& beyond, bool before) {
    // Virtual knots at from.t -+ k*h: attitude continues the end segment's
    // geodesic (constant body rate); position follows the parabola through the
    // three end knots (constant acceleration), or the line if only two exist.
    std::vector<Pose> out;
    const TimeNs h = std::abs(towards.t_ns - from.t_ns);
    const Vec3 xi = so3::log(towards.attitude.transpose() * from.attitude);  // one step away from `towards`
    const double t1 = seconds_between(from.t_ns, towards.t_ns), t2 = seconds_between(from.t_ns, beyond.t_ns);
    const Vec3 y1 = towards.position_m - from.position_m, y2 = beyond.position_m - from.position_m;
    const bool quadratic = &beyond != &towards;
    for (std::int64_t k = 1; k * h < pad_ns + h; ++k) {
      const double kd = static_cast<double>(k);
      const TimeNs t_ns = from.t_ns + (before ? -k * h : k * h);
      const double t = seconds_between(from.t_ns, t_ns);
      // Lagrange through (0, 0), (t1, y1), (t2, y2), relative to `from`.
      const Vec3 offset = quadratic ? Vec3(t * (t - t2) / (t1 * (t1 - t2)) * y1 + t * (t - t1) / (t2 * (t2 - t1)) * y2)
                                    : Vec3(t / t1 * y1);
      out.push_back({t_ns, from.position_m + offset, from.attitude * so3::exp(kd * xi)});
    }
    return out;
  };
  const std::size_t last_knot = knots.size() - 1;
  std::vector<Pose> head = extend(knots[0], knots[1], knots.size() > 2 ? knots[2] : knots[1], true);
  const std::vector<Pose> tail =
      extend(knots[last_knot], knots[last_knot - 1], knots.size() > 2 ? knots[last_knot - 2] : knots[last_knot - 1], false);
  std::vector<Pose> padded(head.rbegin(), head.rend());
  padded.insert(padded.end(), knots.begin(), knots.end());
  padded.insert(padded.end(), tail.begin(), tail.end());
  // Grid from t_0 - pad_s to t_n + pad_s: whole seconds, so aligned.
  std::vector<Pose> clipped_knots = padded;
  PipelineOptions clip = options;
  clip.ends = Ends::clip;
  const TimeNs first = knots.front().t_ns - pad_ns, last = knots.back().t_ns + pad_ns;
  // Trim the virtual knots to exactly [first, last] by re-timing the outermost
  // ones: interpolate them at the grid ends along their own segment.
  auto at_time = [](const Pose& a, const Pose& b, TimeNs t) {
    return interp::geodesic(a, b, static_cast<double>(t - a.t_ns) / static_cast<double>(b.t_ns - a.t_ns));
  };
  while (clipped_knots.size() > 2 && clipped_knots[1].t_ns <= first) clipped_knots.erase(clipped_knots.begin());
  if (clipped_knots.front().t_ns < first) {
    Pose p = at_time(clipped_knots[0], clipped_knots[1], first);
    p.t_ns = first;
    clipped_knots.front() = p;
  }
  while (clipped_knots.size() > 2 && clipped_knots[clipped_knots.size() - 2].t_ns >= last) clipped_knots.pop_back();
  if (clipped_knots.back().t_ns > last) {
    const std::size_t m = clipped_knots.size();
    Pose p = at_time(clipped_knots[m - 2], clipped_knots[m - 1], last);
    p.t_ns = last;
    clipped_knots.back() = p;
  }
  BatchResult full;
  try {
    full = run_segment(clipped_knots, clip, progress);
  } catch (const interp::InterpolationError& e) {
    // Knot numbers in the message count the virtual knots; the times are right.
    const auto before = std::count_if(clipped_knots.begin(), clipped_knots.end(),
                                      [&](const Pose& p) { return p.t_ns < knots.front().t_ns; });
    throw interp::InterpolationError(std::string(e.what()) + " [knot numbers include " +
                                     std::to_string(clipped_knots.size() - knots.size()) +
                                     " virtual knots of the extrapolated ends, " + std::to_string(before) +
                                     " before the first; the times are the input's]");
  }
  const auto skip = static_cast<std::size_t>(pad_s * options.rate_hz);
  const std::size_t count = output_grid(knots.front().t_ns, knots.back().t_ns, options.rate_hz).size();
  BatchResult out;
  out.trajectory.assign(full.trajectory.begin() + static_cast<std::ptrdiff_t>(skip),
                        full.trajectory.begin() + static_cast<std::ptrdiff_t>(skip + count));
  out.imu.assign(full.imu.begin() + static_cast<std::ptrdiff_t>(skip),
                 full.imu.begin() + static_cast<std::ptrdiff_t>(skip + count));
  return out;
}

std::string knot_time(TimeNs t_ns) {
  const double s = static_cast<double>(t_ns) * 1e-9;
  return std::to_string(s) + " s";
}

}  // namespace

BatchResult run_batch(const std::vector<Pose>& knots, const PipelineOptions& options,
                      const ProgressFn& progress) {
  interp::check_knots(knots);
  if (!(options.max_gap_s > 0.0)) throw std::invalid_argument("max gap must be > 0 s");
  const auto max_gap_ns = static_cast<TimeNs>(std::min(options.max_gap_s, 1e9) * 1e9);
  // Cut the knots at every gap longer than the limit.
  std::vector<std::size_t> cuts{0};
  for (std::size_t i = 1; i < knots.size(); ++i) {
    if (knots[i].t_ns - knots[i - 1].t_ns <= max_gap_ns) continue;
    if (options.gap_policy == GapPolicy::error)
      throw GapError("knots " + std::to_string(i - 1) + " (t=" + knot_time(knots[i - 1].t_ns) + ") and " +
                     std::to_string(i) + " (t=" + knot_time(knots[i].t_ns) + ") are " +
                     knot_time(knots[i].t_ns - knots[i - 1].t_ns) + " apart, more than the " +
                     std::to_string(options.max_gap_s) +
                     " s gap limit: raise the limit or split the trajectory at gaps");
    cuts.push_back(i);
  }
  cuts.push_back(knots.size());
  BatchResult all;
  for (std::size_t c = 0; c + 1 < cuts.size(); ++c) {
    const std::vector<Pose> segment(knots.begin() + static_cast<std::ptrdiff_t>(cuts[c]),
                                    knots.begin() + static_cast<std::ptrdiff_t>(cuts[c + 1]));
    if (segment.size() < 2)
      throw GapError("knot " + std::to_string(cuts[c]) + " (t=" + knot_time(segment.front().t_ns) +
                     ") is isolated between two gaps: a segment needs at least two knots");
    const double base = static_cast<double>(cuts[c]) / static_cast<double>(knots.size());
    const double span = static_cast<double>(cuts[c + 1] - cuts[c]) / static_cast<double>(knots.size());
    const ProgressFn part_progress = [&](double f) { report(progress, base + span * f); };
    BatchResult part = options.ends == Ends::extrapolate ? run_segment_extrapolated(segment, options, part_progress)
                                                         : run_segment(segment, options, part_progress);
    if (cuts.size() == 2) return part;
    all.trajectory.insert(all.trajectory.end(), part.trajectory.begin(), part.trajectory.end());
    all.imu.insert(all.imu.end(), part.imu.begin(), part.imu.end());
  }
  return all;
}

}  // namespace imuemu
