// The causal live method (core/causal_hermite.hpp) against analytic truth:
// a flat-scene motion known in closed form (position, velocity, acceleration,
// attitude and body rate), sampled into poses at 100, 250 and 1000 Hz, with
// and without the poses' own rates. Asserts the cubic Hermite error bounds
// (|p - H| <= h^4/384 max|p''''|, |p'' - H''| <= h^2/12 max|p''''| with exact
// slopes), causality (every sample of (t_{k-1}, t_k] ready when knot k is
// pushed, none earlier), the exact output grid, no NaN, and that a refused
// knot changes nothing.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <stdexcept>
#include <vector>

#include "core/causal_hermite.hpp"
#include "core/imu_model.hpp"
#include "core/so3.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_core_test_causal_hermite {
namespace imuemu { using namespace ::imuemu; }

namespace imuemu {
namespace {

constexpr double kPi = std::numbers::pi;

// p(t) = (A sin(w t), B (1 - cos(w t)), C sin(2 w t)), R(t) = Rz(psi(t))
// Ry(theta(t)) with psi = P sin(w t), theta = Q sin(w t): every derivative
// in closed form.
struct Motion {
  double A = 20, B = 10, C = 2, w = 2 * kPi * 0.5, P = 0.8, Q = 0.2;
  Vec3 p(double t) const { return {A * std::sin(w * t), B * (1 - std::cos(w * t)), C * std::sin(2 * w * t)}; }
  Vec3 v(double t) const { return {A * w * std::cos(w * t), B * w * std::sin(w * t), 2 * C * w * std::cos(2 * w * t)}; }
  Vec3 a(double t) const {
    return {-A * w * w * std::sin(w * t), B * w * w * std::cos(w * t), -4 * C * w * w * std::sin(2 * w * t)};
  }
  double p4_max() const { return std::max({A * std::pow(w, 4), B * std::pow(w, 4), C * std::pow(2 * w, 4)}); }
  Mat3 R(double t) const {
    return so3::exp(Vec3(0, 0, P * std::sin(w * t))) * so3::exp(Vec3(0, Q * std::sin(w * t), 0));
  }
  // omega_b = R^T R': psi' Ry^T e_z + theta' e_y.
  Vec3 omega(double t) const {
    const double psi_dot = P * w * std::cos(w * t), theta_dot = Q * w * std::cos(w * t);
    const Mat3 Ry = so3::exp(Vec3(0, Q * std::sin(w * t), 0));
    return psi_dot * (Ry.transpose() * Vec3::UnitZ()) + theta_dot * Vec3::UnitY();
  }
};

struct Errors {
  double position = 0, acceleration = 0, attitude = 0, gyro = 0;
  std::size_t samples = 0;
};

Errors run(double pose_hz, bool with_rates, std::int64_t rate_hz = 1000, double seconds = 4.0) {
  const Motion m;
  CausalHermiteOptions o;
  o.rate_hz = rate_hz;
  CausalHermite engine(o);
  Errors e;
  const auto h_ns = static_cast<TimeNs>(std::llround(1e9 / pose_hz));
  TimeNs last_t = -1;
  for (TimeNs t_ns = 0; t_ns <= static_cast<TimeNs>(seconds * 1e9); t_ns += h_ns) {
    const double t = static_cast<double>(t_ns) * 1e-9;
    PoseRates rates;
    if (with_rates) {
      rates.velocity_m_s = m.v(t);
      rates.angular_rate_rad_s = m.omega(t);
    }
    engine.push({t_ns, m.p(t), m.R(t)}, rates);
    CausalSample s;
    while (engine.pop(s)) {
      const Kinematics& k = s.kinematics;
      // Causal: nothing beyond the newest knot, and the grid is exact.
      EXPECT_LE(k.t_ns, t_ns);
      EXPECT_EQ(k.t_ns, static_cast<TimeNs>(e.samples) * kNsPerSecond / rate_hz);
      EXPECT_GT(k.t_ns, last_t);
      last_t = k.t_ns;
      ++e.samples;
      EXPECT_TRUE(k.position_m.allFinite() && k.acceleration_m_s2.allFinite() && s.imu.gyro_rad_s.allFinite() &&
                  s.imu.accel_m_s2.allFinite());
      const double tk = static_cast<double>(k.t_ns) * 1e-9;
      // The first three intervals have no four knots behind them yet (chord,
      // quadratic slopes without rates): the estimator's warm-up, not counted.
      if (k.t_ns <= 3 * h_ns) continue;
      e.position = std::max(e.position, (k.position_m - m.p(tk)).norm());
      e.acceleration = std::max(e.acceleration, (k.acceleration_m_s2 - m.a(tk)).norm());
      e.attitude = std::max(e.attitude, so3::angle(m.R(tk).transpose() * k.attitude));
      e.gyro = std::max(e.gyro, (k.angular_rate_rad_s - m.omega(tk)).norm());
    }
    // Every sample up to the newest knot is out: the look-ahead is one interval.
    EXPECT_EQ(engine.current_lag_ns(), t_ns == 0 ? 0 : t_ns - last_t);
  }
  return e;
}

TEST(CausalHermite, WithTheSimulatorsRatesItMeetsTheCubicHermiteBounds) {
  const Motion m;
  for (double pose_hz : {100.0, 250.0, 1000.0}) {
    SCOPED_TRACE(pose_hz);
    const Errors e = run(pose_hz, true);
    const double h = 1.0 / pose_hz;
    EXPECT_EQ(e.samples, 4001u);  // 4 s at 1 kHz, both ends included
    EXPECT_LE(e.position, std::sqrt(3.0) * std::pow(h, 4) / 384 * m.p4_max());
    EXPECT_LE(e.acceleration, std::sqrt(3.0) * h * h / 12 * m.p4_max());
    // Attitude: the same cubic in the chart, to within the chart's curvature.
    EXPECT_LT(e.attitude, 50 * std::pow(h, 4));
    EXPECT_LT(e.gyro, 50 * std::pow(h, 3));
    std::printf("pose %6.0f Hz, rates given:     pos %.2e m, acc %.2e m/s2, att %.2e rad, gyro %.2e rad/s\n", pose_hz,
                e.position, e.acceleration, e.attitude, e.gyro);
  }
}

TEST(CausalHermite, WithoutRatesTheCausalSlopesAreThirdOrder) {
  // The slope of the cubic through the last four knots errs by O(h^3)
  // |p''''|: acceleration (the Hermite cubic's second derivative, slopes
  // weighted up to 4/h) errs by O(h^2) |p''''|, position by O(h^4).
  const Motion m;
  double previous_acc = 0;
  for (double pose_hz : {100.0, 250.0, 1000.0}) {
    SCOPED_TRACE(pose_hz);
    const Errors e = run(pose_hz, false);
    const double h = 1.0 / pose_hz;
    EXPECT_LE(e.position, std::pow(h, 4) * m.p4_max());
    EXPECT_LE(e.acceleration, 2 * h * h * m.p4_max());
    if (previous_acc > 0) {
      EXPECT_LT(e.acceleration, previous_acc);  // converges with the pose rate
    }
    previous_acc = e.acceleration;
    std::printf("pose %6.0f Hz, rates estimated: pos %.2e m, acc %.2e m/s2, att %.2e rad, gyro %.2e rad/s\n", pose_hz,
                e.position, e.acceleration, e.attitude, e.gyro);
  }
}

TEST(CausalHermite, ARefusedKnotChangesNothing) {
  CausalHermiteOptions o;
  o.rate_hz = 1000;
  CausalHermite engine(o);
  engine.push({0, Vec3::Zero(), Mat3::Identity()});
  engine.push({4'000'000, Vec3(0.1, 0, 0), Mat3::Identity()});
  const std::size_t ready = engine.ready();
  EXPECT_EQ(ready, 5u);  // t = 0, 1, 2, 3, 4 ms
  EXPECT_THROW(engine.push({4'000'000, Vec3(0.2, 0, 0), Mat3::Identity()}), std::invalid_argument);  // not later
  EXPECT_THROW(engine.push({8'000'000, Vec3(NAN, 0, 0), Mat3::Identity()}), std::invalid_argument);
  EXPECT_THROW(engine.push({8'000'000, Vec3::Zero(), so3::exp(Vec3(0, 0, kPi))}), std::invalid_argument);
  EXPECT_EQ(engine.ready(), ready);
  EXPECT_EQ(engine.knots_pushed(), 2u);
  engine.push({8'000'000, Vec3(0.2, 0, 0), Mat3::Identity()});
  EXPECT_EQ(engine.ready(), ready + 4);  // 5..8 ms
  // A gap beyond max_gap_ns starts a new run on its own grid: nothing across it.
  engine.push({20'000'000'000, Vec3::Zero(), Mat3::Identity()});
  EXPECT_EQ(engine.ready(), ready + 4);
  EXPECT_EQ(engine.runs(), 2u);
  engine.push({20'004'000'000, Vec3(0.1, 0, 0), Mat3::Identity()});
  CausalSample s;
  std::vector<TimeNs> times;
  while (engine.pop(s)) times.push_back(s.kinematics.t_ns);
  ASSERT_EQ(times.size(), ready + 4 + 5);
  EXPECT_EQ(times[9], 20'000'000'000);
}

}  // namespace
}  // namespace imuemu
}  // namespace unity_core_test_causal_hermite
