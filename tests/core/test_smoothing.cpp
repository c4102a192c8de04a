// Eq. 3.66 bump kernel, Eq. 3.68 windowed smoothing and Eq. 3.71-3.74
// derivatives against closed-form truth.
#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <random>
#include <vector>

#include "core/derivatives.hpp"
#include "core/smoothing.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_core_test_smoothing {
namespace imuemu { using namespace ::imuemu; }

using namespace imuemu;

TEST(Bump, ValuesAndNormalization) {
  EXPECT_DOUBLE_EQ(smoothing::bump(0.0), std::exp(-1.0));
  EXPECT_EQ(smoothing::bump(1.0), 0.0);
  EXPECT_EQ(smoothing::bump(-1.0), 0.0);
  EXPECT_EQ(smoothing::bump(1.5), 0.0);
  EXPECT_DOUBLE_EQ(smoothing::bump(0.5), std::exp(-1.0 / 0.75));
  EXPECT_EQ(smoothing::bump(0.3), smoothing::bump(-0.3));
  // N_G from adaptive quadrature (scipy.integrate.quad, tolerance 1e-15).
  EXPECT_NEAR(smoothing::bump_normalization(), 0.4439938161680793, 1e-14);
}

TEST(Kernel, ThesisWidthUsesSecondsOnTheBumpAxis) {
  // Appendix B: 100 Hz, Delta = 10: weights Phi(k * 0.01 s), support fixed at 1 s.
  const smoothing::UniformKernel k({10, smoothing::KernelWidth::thesis, 0.0}, 0.01);
  EXPECT_DOUBLE_EQ(k.half_width_s(), 1.0);
  for (int j = -10; j <= 10; ++j) EXPECT_DOUBLE_EQ(k.weight(j), smoothing::bump(j * 0.01));
  // Appendix C: 50 Hz, Delta = 50 spans exactly +-1 s: edge weight is zero.
  const smoothing::UniformKernel c({50, smoothing::KernelWidth::thesis, 0.0}, 0.02);
  EXPECT_EQ(c.weight(50), 0.0);
  EXPECT_GT(c.weight(49), 0.0);
}

TEST(Kernel, WindowWidthReachesZeroAtTheEdge) {
  const smoothing::UniformKernel k({40, smoothing::KernelWidth::window, 0.0}, 1.0 / 400);
  EXPECT_NEAR(k.half_width_s(), 0.1, 1e-15);
  EXPECT_EQ(k.weight(40), 0.0);
  EXPECT_EQ(k.weight(-40), 0.0);
  EXPECT_DOUBLE_EQ(k.weight(20), smoothing::bump(0.5));
}

namespace {
std::vector<Vec3> sampled(std::size_t n, double h, auto f) {
  std::vector<Vec3> v(n);
  for (std::size_t i = 0; i < n; ++i) v[i] = f(static_cast<double>(i) * h);
  return v;
}
}  // namespace

TEST(Smoothing, ConstantAtEcefScaleIsReproducedBitExactly) {
  const Vec3 c(4'510'731.123456789, 4'510'731.987654321, -0.000123);
  const std::vector<Vec3> f(500, c);
  std::vector<Vec3> out(f.size());
  smoothing::smooth(smoothing::UniformKernel({50, smoothing::KernelWidth::window, 0.0}, 0.0025), f, out);
  for (const Vec3& v : out) EXPECT_EQ(v, c);
}

TEST(Smoothing, MatchesTheLiteralThesisSumOnRandomData) {
  // Eq. 3.68 as printed: sum Phi f / sum Phi over the clipped window.
  std::mt19937_64 rng(42);
  std::normal_distribution<double> n01;
  std::vector<Vec3> f(300);
  for (Vec3& v : f) v = Vec3(n01(rng), n01(rng), n01(rng)) * 10.0;
  for (auto width : {smoothing::KernelWidth::thesis, smoothing::KernelWidth::window}) {
    const double h = 0.01;
    const int delta = 10;
    const smoothing::UniformKernel k({delta, width, 0.0}, h);
    double worst = 0.0;
    for (int i = 0; i < 300; ++i) {
      Vec3 num = Vec3::Zero();
      double den = 0.0;
      for (int j = std::max(0, i - delta); j <= std::min(299, i + delta); ++j) {
        const double s = width == smoothing::KernelWidth::thesis ? (j - i) * h : (j - i) / double(delta);
        num += smoothing::bump(s) * f[static_cast<std::size_t>(j)];
        den += smoothing::bump(s);
      }
      worst = std::max(worst, (smoothing::smooth_at(k, f, static_cast<std::size_t>(i)) - num / den).norm());
    }
    std::cout << "  [smoothing vs literal Eq. 3.68, " << smoothing::to_string(width) << "] worst " << worst << "\n";
    EXPECT_LT(worst, 1e-13);
  }
}

TEST(Smoothing, LinearSignalIsExactInsideAndBiasedByTheOneSidedWindowAtTheEnds) {
  const double h = 0.01;
  const int delta = 20;
  const Vec3 slope(1.5, -2.0, 0.25);
  const auto f = sampled(200, h, [&](double t) { return Vec3(slope * t + Vec3(3, 4, 5)); });
  const smoothing::UniformKernel k({delta, smoothing::KernelWidth::window, 0.0}, h);
  for (std::size_t i = delta; i + delta < f.size(); ++i)
    EXPECT_LT((smoothing::smooth_at(k, f, i) - f[i]).norm(), 1e-13) << i;
  // At i = 0 the window is one-sided: the result is the kernel-weighted mean
  // of t over [0, delta*h], a known positive shift along the slope.
  double num = 0.0, den = 0.0;
  for (int j = 0; j <= delta; ++j) {
    num += smoothing::bump(j / double(delta)) * j * h;
    den += smoothing::bump(j / double(delta));
  }
  EXPECT_LT((smoothing::smooth_at(k, f, 0) - (f[0] + slope * (num / den))).norm(), 1e-13);
}

TEST(Derivatives, StencilsAreExactForTheirPolynomialDegree) {
  const double h = 0.01;
  // Five-point (Eq. 3.74) is exact for quartics; centred (3.73) for quadratics;
  // forward/backward (3.71/3.72) for linear functions.
  const auto quartic = sampled(50, h, [](double t) { return Vec3(t * t * t * t, t * t * t, 2 * t); });
  for (std::size_t i = 2; i + 2 < 50; ++i) {
    const double t = static_cast<double>(i) * h;
    EXPECT_NEAR(derivatives::derivative_at(quartic, h, i).x(), 4 * t * t * t, 1e-12);
    EXPECT_NEAR(derivatives::derivative_at(quartic, h, i).y(), 3 * t * t, 1e-12);
  }
  const auto quadratic = sampled(50, h, [](double t) { return Vec3(t * t, 0, 0); });
  EXPECT_NEAR(derivatives::derivative_at(quadratic, h, 1).x(), 2 * h, 1e-12);
  EXPECT_NEAR(derivatives::derivative_at(quadratic, h, 48).x(), 2 * 48 * h, 1e-12);
  const auto linear = sampled(50, h, [](double t) { return Vec3(7 * t, 0, 0); });
  EXPECT_NEAR(derivatives::derivative_at(linear, h, 0).x(), 7, 1e-12);
  EXPECT_NEAR(derivatives::derivative_at(linear, h, 49).x(), 7, 1e-12);
}

TEST(Derivatives, FivePointErrorIsFourthOrder) {
  // Halving h divides the Eq. 3.74 error by ~16 (h^4/30 f^(5)).
  double err[2];
  for (int pass = 0; pass < 2; ++pass) {
    const double h = pass == 0 ? 0.02 : 0.01;
    const auto f = sampled(400, h, [](double t) { return Vec3(std::sin(3 * t), 0, 0); });
    const std::size_t i = pass == 0 ? 50 : 100;  // t = 1 s both times
    err[pass] = std::abs(derivatives::derivative_at(f, h, i).x() - 3 * std::cos(3.0));
  }
  std::cout << "  [five-point] error h=0.02: " << err[0] << ", h=0.01: " << err[1] << "\n";
  EXPECT_NEAR(err[0] / err[1], 16.0, 0.5);
}

TEST(KernelDerivatives, ExactForQuadraticMotionEvenWithFewSamplesPerWindow) {
  // Regression (found by tests/io/test_hard_cases.cpp): differentiating the
  // continuous-time sum gave -66% acceleration at Delta = 10. The derivative
  // weights are rescaled so a full window is exact for quadratics.
  const double h = 0.01;
  const auto f = sampled(201, h, [](double t) { return Vec3(0.5 * 3.0 * t * t + 2.0 * t, -t, 7.0); });
  double worst_rate = 0, worst_accel = 0;
  for (int order : {2, 4}) {
    for (int delta : {2, 3, 5, 10, 20, 100}) {
      const smoothing::UniformKernel k({delta, smoothing::KernelWidth::window, 0.0, order}, h);
      const smoothing::Smoothed s = smoothing::smooth_with_derivatives(k, f, 100);
      const double t = 1.0;
      worst_rate = std::max(worst_rate, (s.rate - Vec3(3.0 * t + 2.0, -1.0, 0.0)).norm());
      worst_accel = std::max(worst_accel, (s.accel - Vec3(3.0, 0.0, 0.0)).norm());
    }
  }
  std::cout << "  [kernel derivatives, Delta 2..100] worst rate error " << worst_rate << ", accel error " << worst_accel
            << "\n";
  EXPECT_LT(worst_rate, 1e-10);
  EXPECT_LT(worst_accel, 1e-8);
}
}  // namespace unity_core_test_smoothing
