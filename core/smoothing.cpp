#include "core/smoothing.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace imuemu::smoothing {

double bump(double t) {
  const double one_minus_t2 = 1.0 - t * t;
  if (!(one_minus_t2 > 0.0)) return 0.0;
  return std::exp(-1.0 / one_minus_t2);
}

double bump_normalization() {
  // Composite Gauss-Legendre would do; Phi is C-infinity and vanishes with all
  // derivatives at +-1, so the trapezoid rule converges super-algebraically.
  static const double value = [] {
    constexpr int n = 20000;
    double sum = 0.0;
    for (int i = 1; i < n; ++i) sum += bump(-1.0 + 2.0 * i / n);
    return sum * 2.0 / n;
  }();
  return value;
}

KernelWidth kernel_width_from_string(const std::string& name) {
  if (name == "thesis") return KernelWidth::thesis;
  if (name == "window") return KernelWidth::window;
  if (name == "seconds") return KernelWidth::seconds;
  throw std::invalid_argument("kernel width '" + name + "': expected thesis, window or seconds");
}

std::string to_string(KernelWidth w) {
  switch (w) {
    case KernelWidth::thesis: return "thesis";
    case KernelWidth::window: return "window";
    case KernelWidth::seconds: return "seconds";
  }
  return "?";
}

UniformKernel::UniformKernel(const KernelOptions& options, double period_s) : delta_(options.delta) {
  if (delta_ < 0) throw std::invalid_argument("Delta must be >= 0");
  if (!(period_s > 0.0)) throw std::invalid_argument("sample period must be > 0");
  switch (options.width) {
    case KernelWidth::thesis: half_width_s_ = 1.0; break;
    case KernelWidth::window: half_width_s_ = delta_ * period_s; break;
    case KernelWidth::seconds: half_width_s_ = options.half_width_s; break;
  }
  if (delta_ > 0 && !(half_width_s_ > 0.0)) throw std::invalid_argument("kernel half width must be > 0");
  const auto size = static_cast<std::size_t>(2 * delta_ + 1);
  weights_.assign(size, 0.0);
  rates_.assign(size, 0.0);
  accels_.assign(size, 0.0);
  if (options.order != 2 && options.order != 4) throw std::invalid_argument("kernel order must be 2 or 4");
  // Fourth order: c = -sum Phi x^2 / sum Phi x^4 over the window's samples.
  double c = 0.0;
  if (options.order == 4 && delta_ > 0) {
    double m2 = 0.0, m4 = 0.0;
    for (int k = -delta_; k <= delta_; ++k) {
      const double x = k * period_s / half_width_s_;
      m2 += bump(x) * x * x;
      m4 += bump(x) * x * x * x * x;
    }
    if (!(m4 > 0.0)) throw std::invalid_argument("fourth-order kernel needs a window of several samples");
    c = -m2 / m4;
  }
  for (int k = -delta_; k <= delta_; ++k) {
    const auto idx = static_cast<std::size_t>(k + delta_);
    if (delta_ == 0) {  // no smoothing: the single weight must be non-zero
      weights_[idx] = 1.0;
      continue;
    }
    const double x = k * period_s / half_width_s_;
    const double phi = bump(x);
    if (phi == 0.0) continue;
    // Phi' = Phi g1, Phi'' = Phi (g1^2 + g1'), g1 = -2x/(1-x^2)^2,
    // g1' = -(2 + 6x^2)/(1-x^2)^3; weight w = Phi q with q = 1 + c x^2:
    // w' = Phi (g1 q + q'), w'' = Phi ((g1^2 + g1') q + 2 g1 q' + q'').
    const double u = 1.0 - x * x;
    const double g1 = -2.0 * x / (u * u);
    const double g1_prime = -(2.0 + 6.0 * x * x) / (u * u * u);
    const double q = 1.0 + c * x * x, q1 = 2.0 * c * x, q2 = 2.0 * c;
    weights_[idx] = phi * q;
    // d/dt of w((t_j - t)/s) = -w'(x)/s; d2/dt2 = w''(x)/s^2.
    rates_[idx] = -phi * (g1 * q + q1) / half_width_s_;
    accels_[idx] = phi * ((g1 * g1 + g1_prime) * q + 2.0 * g1 * q1 + q2) / (half_width_s_ * half_width_s_);
  }
  // The derivative weights above differentiate the continuous-time sum
  // sum_j w((t_j - t)/s) f_j / sum_j w(..), which ripples between samples when
  // the window holds few of them (Poisson summation): at Delta = 10 its
  // derivative at a sample is off by 4e-3 (rate) and far more (acceleration).
  // Rescale them so that, over a full window, the rate is exact for linear and
  // the acceleration exact for quadratic motion on the sample grid:
  //   rate:  sum_k r_k (k h) = sum_k w_k,
  //   accel: sum_k a_k (k h)^2 - (sum_k w_k (k h)^2)(sum_k a_k)/(sum_k w_k) = 2 sum_k w_k.
  // For Delta >= ~100 the factors differ from 1 by < 1e-9.
  if (delta_ > 0) {
    double w0 = 0.0, w2 = 0.0, r1 = 0.0, a0 = 0.0, a2 = 0.0;
    for (int k = -delta_; k <= delta_; ++k) {
      const auto idx = static_cast<std::size_t>(k + delta_);
      const double x = k * period_s;
      w0 += weights_[idx];
      w2 += weights_[idx] * x * x;
      r1 += rates_[idx] * x;
      a0 += accels_[idx];
      a2 += accels_[idx] * x * x;
    }
    const double accel_moment = a2 - w2 * a0 / w0;
    if (r1 != 0.0 && accel_moment != 0.0) {
      const double rate_scale = w0 / r1, accel_scale = 2.0 * w0 / accel_moment;
      for (double& r : rates_) r *= rate_scale;
      for (double& a : accels_) a *= accel_scale;
    }
  }
  if (weights_[static_cast<std::size_t>(delta_)] <= 0.0)
    throw std::invalid_argument("kernel centre weight is zero");
}

Vec3 smooth_at(const UniformKernel& kernel, std::span<const Vec3> f, std::size_t i) {
  const auto n = static_cast<std::ptrdiff_t>(f.size());
  const auto centre = static_cast<std::ptrdiff_t>(i);
  const std::ptrdiff_t lo = std::max<std::ptrdiff_t>(0, centre - kernel.delta());
  const std::ptrdiff_t hi = std::min<std::ptrdiff_t>(n - 1, centre + kernel.delta());
  const Vec3& fi = f[i];
  Vec3 weighted = Vec3::Zero();
  double weight_sum = 0.0;
  for (std::ptrdiff_t j = lo; j <= hi; ++j) {
    const double w = kernel.weight(static_cast<int>(j - centre));
    weighted += w * (f[static_cast<std::size_t>(j)] - fi);
    weight_sum += w;
  }
  return fi + weighted / weight_sum;
}

Smoothed smooth_with_derivatives(const UniformKernel& kernel, std::span<const Vec3> f, std::size_t i,
                                 bool want_accel) {
  // The window is clipped at 0 and f.size() like Eq. 3.68.
  const auto delta = static_cast<std::size_t>(kernel.delta());
  const std::size_t lo = i >= delta ? i - delta : 0;
  const std::size_t hi = std::min(f.size() - 1, i + delta);
  const Vec3& fi = f[i];
  Vec3 s0 = Vec3::Zero(), s1 = Vec3::Zero(), s2 = Vec3::Zero();
  double d0 = 0.0, d1 = 0.0, d2 = 0.0;
  for (std::size_t j = lo; j <= hi; ++j) {
    const int k = static_cast<int>(static_cast<std::ptrdiff_t>(j) - static_cast<std::ptrdiff_t>(i));
    const double w = kernel.weight(k), wr = kernel.weight_rate(k);
    const Vec3 g = f[j] - fi;
    s0 += w * g;
    s1 += wr * g;
    d0 += w;
    d1 += wr;
    if (want_accel) {
      const double wa = kernel.weight_accel(k);
      s2 += wa * g;
      d2 += wa;
    }
  }
  // N/D with N = f_i D + S0: (N/D)' = (S1 D - S0 D1)/D^2 and
  // (N/D)'' = S2/D - 2 S1 D1/D^2 - S0 D2/D^2 + 2 S0 D1^2/D^3.
  const double inv = 1.0 / d0;
  Smoothed out;
  out.value = fi + s0 * inv;
  out.rate = (s1 - s0 * (d1 * inv)) * inv;
  out.accel = (s2 - 2.0 * s1 * (d1 * inv) - s0 * (d2 * inv) + 2.0 * s0 * (d1 * d1 * inv * inv)) * inv;
  return out;
}

void smooth(const UniformKernel& kernel, std::span<const Vec3> f, std::span<Vec3> out) {
  if (out.size() != f.size()) throw std::invalid_argument("smooth: output size mismatch");
  for (std::size_t i = 0; i < f.size(); ++i) out[i] = smooth_at(kernel, f, i);
}

QuinticStep quintic_step(double u) {
  if (u <= 0.0) return {0.0, 0.0, 0.0};
  if (u >= 1.0) return {1.0, 0.0, 0.0};
  const double v = 1.0 - u;
  return {u * u * u * (10.0 + u * (-15.0 + 6.0 * u)), 30.0 * u * u * v * v, 60.0 * u * v * (1.0 - 2.0 * u)};
}

}  // namespace imuemu::smoothing
