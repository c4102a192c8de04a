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
  weights_.resize(static_cast<std::size_t>(2 * delta_ + 1));
  for (int k = -delta_; k <= delta_; ++k) {
    // Delta = 0 means no smoothing: the single weight must be non-zero.
    weights_[static_cast<std::size_t>(k + delta_)] =
        delta_ == 0 ? 1.0 : bump(k * period_s / half_width_s_);
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

void smooth(const UniformKernel& kernel, std::span<const Vec3> f, std::span<Vec3> out) {
  if (out.size() != f.size()) throw std::invalid_argument("smooth: output size mismatch");
  for (std::size_t i = 0; i < f.size(); ++i) out[i] = smooth_at(kernel, f, i);
}

}  // namespace imuemu::smoothing
