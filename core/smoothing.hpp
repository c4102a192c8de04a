// Kernel smoothing of thesis §3.6.2: the bump function of Eq. 3.66 and the
// windowed discrete convolution of Eq. 3.68 with window parameter Delta.
#pragma once

#include <span>
#include <string>
#include <vector>

#include "core/types.hpp"

namespace imuemu::smoothing {

// Phi(t) = exp(-1 / (1 - t^2)) for |t| < 1, else 0   (Eq. 3.66 numerator).
double bump(double t);
// N_G = integral of Phi over [-1, 1] (Eq. 3.66), = 0.443993816168079...
double bump_normalization();

// How the kernel's time axis relates to the window.
enum class KernelWidth {
  // Literal Eq. 3.68: Phi(t_j - t_i) with t in seconds, so the bump's support
  // is fixed at +-1 s whatever Delta and the rate are (Appendix B: 100 Hz,
  // Delta = 10 averages +-0.1 s of a nearly flat kernel; Appendix C: 50 Hz,
  // Delta = 50 spans exactly +-1 s).
  thesis,
  // Phi((t_j - t_i) / (Delta * period)): the support equals the window, so the
  // kernel reaches zero exactly at the window edge (the default).
  window,
  // Phi((t_j - t_i) / half_width_s) with an explicit half width; samples
  // beyond Delta are still cut off.
  seconds,
};

struct KernelOptions {
  int delta = 10;  // Delta of Eq. 3.68: window is +-delta samples
  KernelWidth width = KernelWidth::window;
  double half_width_s = 1.0;  // used by KernelWidth::seconds only
  // 2: the thesis' bump Phi (positive; preserves linear motion, attenuates
  //    curvature by ~sigma^2 f''/2).
  // 4: Phi(x) (1 + c x^2) with c chosen so the discrete second moment
  //    vanishes: still C-infinity with compact support, preserves cubic
  //    motion, attenuation ~sigma^4 f^(4). Has small negative lobes.
  int order = 2;
};

KernelWidth kernel_width_from_string(const std::string& name);  // thesis|window|seconds
std::string to_string(KernelWidth w);

// The weights Phi(k * period / scale) for k = -delta..delta on a uniform grid.
class UniformKernel {
 public:
  UniformKernel(const KernelOptions& options, double period_s);
  int delta() const { return delta_; }
  // Weight for offset k in [-delta, delta].
  double weight(int k) const { return weights_[static_cast<std::size_t>(k + delta_)]; }
  // First and second time derivatives of that weight as the output time t
  // moves (the sample time t_j stays): d/dt Phi((t_j - t)/s) = -Phi'(x)/s and
  // d2/dt2 = Phi''(x)/s^2, with x = (t_j - t)/s and s the half width.
  double weight_rate(int k) const { return rates_[static_cast<std::size_t>(k + delta_)]; }
  double weight_accel(int k) const { return accels_[static_cast<std::size_t>(k + delta_)]; }
  // Half width of the bump in seconds (support is +-this).
  double half_width_s() const { return half_width_s_; }

 private:
  int delta_;
  double half_width_s_;
  std::vector<double> weights_, rates_, accels_;
};

// The smoothed value of Eq. 3.68 at sample i and its first and second time
// derivatives, differentiating the kernel weights exactly (the bump is C-inf):
// the derivative of the function t -> sum Phi((t_j - t)/s) f_j / sum Phi(..)
// at t = t_i, over the same clipped window. Computed on offsets f_j - f_i, so
// nothing cancels at ECEF magnitudes. Needs delta >= 1.
struct Smoothed {
  Vec3 value, rate, accel;
};
// With want_accel false the second derivative is skipped (left zero): a third
// less work where only the rate is needed (attitude).
Smoothed smooth_with_derivatives(const UniformKernel& kernel, std::span<const Vec3> f, std::size_t i,
                                 bool want_accel = true);

// Eq. 3.68 on a uniformly sampled sequence, including its one-sided windows at
// both ends (the sums are clipped to the available samples and renormalised).
// Evaluated as f_i + sum w (f_j - f_i) / sum w, algebraically identical to the
// thesis' sum w f_j / sum w but exact for constant input and free of the
// rounding of large offsets (ECEF coordinates ~6.4e6 m).
// The C2 quintic step s(u) = 10u^3 - 15u^4 + 6u^5 on [0, 1] (0 below, 1
// above) with its first two derivatives in u: s' and s'' vanish at both ends,
// so a blend weighted by it meets both curves with matching value, first and
// second derivative. Used to blend neighbouring charts' attitudes
// (core/stream.cpp) and extrapolated samples back into exact ones
// (core/live_emitter.cpp).
struct QuinticStep {
  double s, ds_du, d2s_du2;
};
QuinticStep quintic_step(double u);

Vec3 smooth_at(const UniformKernel& kernel, std::span<const Vec3> f, std::size_t i);
void smooth(const UniformKernel& kernel, std::span<const Vec3> f, std::span<Vec3> out);

}  // namespace imuemu::smoothing
