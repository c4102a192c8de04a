// The C2 cubic spline on SO(3) (core/so3_spline.hpp), the baseline of issue
// 14, against independent truth: a constant body rate about any axis is a
// straight line in every knot's chart, so the spline must reproduce it to
// rounding (attitude, body rate, zero angular acceleration); on a motion
// whose rotation axis moves it must interpolate the knots and be C2 there
// (body rate and angular acceleration from both sides agree, evaluated with
// Eq. 3.59/3.61 on each side's own cubic); its natural ends have zero angular
// acceleration; and a pure fixed-axis rotation reduces to a scalar natural
// cubic spline of the angle, checked against one solved here by hand.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <numbers>
#include <vector>

#include "core/attitude.hpp"
#include "core/reference_motion.hpp"
#include "core/so3.hpp"
#include "core/so3_spline.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_core_test_so3_spline {
namespace imuemu { using namespace ::imuemu; }

using namespace imuemu;

namespace {

constexpr double kPi = std::numbers::pi;

}  // namespace

TEST(So3Spline, ReproducesAConstantBodyRateExactly) {
  // 100 deg/s about a tilted axis, non-uniform knots, ends included: the C2
  // system is solved by w_k = omega for natural ends too (zero angular
  // acceleration everywhere).
  const Mat3 R0 = so3::exp(Vec3(0.3, -0.2, 0.9));
  const Vec3 omega = Vec3(0.4, -1.1, 1.2).normalized() * (100.0 * kPi / 180.0);
  const reference::ConstantRate motion(R0, omega, 0, 20 * kNsPerSecond);
  std::vector<Pose> knots;
  for (TimeNs t = 0; t <= 20 * kNsPerSecond; t += (t / kNsPerSecond) % 2 ? 700'000'000 : 1'200'000'000) {
    const Kinematics k = motion.at(t);
    knots.push_back({t, Vec3::Zero(), k.attitude});
  }
  ASSERT_GE(knots.size(), 15u);
  const so3spline::Spline spline(knots);
  double worst_att = 0, worst_rate = 0, worst_acc = 0;
  for (std::size_t k = 0; k < spline.segment_count(); ++k) {
    for (int i = 0; i <= 10; ++i) {
      const TimeNs t = knots[k].t_ns + (knots[k + 1].t_ns - knots[k].t_ns) * i / 10;
      Kinematics out;
      spline.evaluate_in_segment(k, t, out);
      const Kinematics truth = motion.at(t);
      worst_att = std::max(worst_att, so3::angle(truth.attitude.transpose() * out.attitude));
      worst_rate = std::max(worst_rate, (out.angular_rate_rad_s - omega).norm());
      worst_acc = std::max(worst_acc, spline.angular_acceleration(k, t).norm());
    }
  }
  std::cout << "  constant rate: attitude " << worst_att << " rad, rate " << worst_rate << " rad/s, accel "
            << worst_acc << " rad/s^2\n";
  EXPECT_LT(worst_att, 1e-13);
  EXPECT_LT(worst_rate, 1e-13);
  EXPECT_LT(worst_acc, 1e-12);
}

TEST(So3Spline, InterpolatesTheKnotsAndIsC2ThereWithNaturalEnds) {
  const reference::FastYaw motion(0, 30 * kNsPerSecond);  // 90 deg/s, moving axis
  const std::vector<Pose> knots = reference::sample_knots(motion, kNsPerSecond);
  const so3spline::Spline spline(knots);
  double worst_knot = 0, worst_rate_jump = 0, worst_acc_jump = 0, acc_scale = 0;
  for (std::size_t k = 0; k < spline.segment_count(); ++k) {
    Kinematics a, b;
    spline.evaluate_in_segment(k, knots[k].t_ns, a);
    spline.evaluate_in_segment(k, knots[k + 1].t_ns, b);
    worst_knot = std::max({worst_knot, so3::angle(knots[k].attitude.transpose() * a.attitude),
                           so3::angle(knots[k + 1].attitude.transpose() * b.attitude)});
    if (k + 1 < spline.segment_count()) {
      // Knot k+1 seen from segment k (its end, chart k) and from segment k+1 (its start).
      Kinematics c;
      spline.evaluate_in_segment(k + 1, knots[k + 1].t_ns, c);
      worst_rate_jump = std::max(worst_rate_jump, (b.angular_rate_rad_s - c.angular_rate_rad_s).norm());
      const Vec3 acc_end = spline.angular_acceleration(k, knots[k + 1].t_ns);
      const Vec3 acc_start = spline.angular_acceleration(k + 1, knots[k + 1].t_ns);
      worst_acc_jump = std::max(worst_acc_jump, (acc_end - acc_start).norm());
      acc_scale = std::max(acc_scale, acc_start.norm());
    }
  }
  const Vec3 acc_first = spline.angular_acceleration(0, knots.front().t_ns);
  const Vec3 acc_last = spline.angular_acceleration(spline.segment_count() - 1, knots.back().t_ns);
  std::cout << "  knots " << worst_knot << " rad; jumps at knots: rate " << worst_rate_jump << " rad/s, angular accel "
            << worst_acc_jump << " rad/s^2 (largest " << acc_scale << "); ends " << acc_first.norm() << ", "
            << acc_last.norm() << " rad/s^2\n";
  EXPECT_LT(worst_knot, 1e-14);
  EXPECT_LT(worst_rate_jump, 1e-13);
  ASSERT_GT(acc_scale, 0.05);  // the motion really accelerates
  EXPECT_LT(worst_acc_jump, 1e-12);
  EXPECT_LT(acc_first.norm(), 1e-12);
  EXPECT_LT(acc_last.norm(), 1e-12);
}

TEST(So3Spline, AFixedAxisRotationIsTheNaturalCubicSplineOfItsAngle) {
  // About a fixed axis, W acts as the identity on the axis and the problem is
  // the scalar natural cubic spline of the angle, which is solved here from
  // its textbook system (uniform h = 1: M_{k-1} + 4 M_k + M_{k+1} = 6 (y_{k+1}
  // - 2 y_k + y_{k-1}), M_0 = M_n = 0) and differentiated by hand.
  const Vec3 axis = Vec3(1.0, 2.0, -2.0) / 3.0;
  const std::vector<double> angle{0.0, 0.7, 1.9, 2.4, 4.0, 4.5};
  const std::size_t n = angle.size();
  std::vector<Pose> knots;
  for (std::size_t k = 0; k < n; ++k)
    knots.push_back({static_cast<TimeNs>(k) * kNsPerSecond, Vec3::Zero(), so3::exp(angle[k] * axis)});
  // Thomas algorithm on the interior second derivatives.
  std::vector<double> M(n, 0.0), c(n, 0.0), d(n, 0.0);
  for (std::size_t k = 1; k + 1 < n; ++k) {
    const double rhs = 6.0 * (angle[k + 1] - 2.0 * angle[k] + angle[k - 1]);
    const double denom = 4.0 - (k > 1 ? c[k - 1] : 0.0);
    c[k] = 1.0 / denom;
    d[k] = (rhs - (k > 1 ? d[k - 1] : 0.0)) / denom;
  }
  for (std::size_t k = n - 2; k >= 1; --k) M[k] = d[k] - c[k] * M[k + 1];
  const so3spline::Spline spline(knots);
  double worst = 0;
  for (std::size_t k = 0; k + 1 < n; ++k) {
    const double slope = angle[k + 1] - angle[k] - (2.0 * M[k] + M[k + 1]) / 6.0;
    const double expected_rate = slope;  // derivative at the segment start
    worst = std::max(worst, (spline.knot_rates_rad_s()[k] - expected_rate * axis).norm());
  }
  std::cout << "  fixed axis: knot rates vs the scalar natural spline " << worst << " rad/s\n";
  EXPECT_LT(worst, 1e-13);
}
}  // namespace unity_core_test_so3_spline
