// Interpolation on SE(3) (thesis §3.5, §3.6.1) against analytic truth:
// constant-rate rotations R0 exp(t[w]) (Eigen::AngleAxis as the independent
// reference), closed-form warps and splines, and one-sided finite differences
// of the interpolated rotations for the Park-Ravani continuity conditions.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <iostream>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "core/interpolation.hpp"
#include "core/so3.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_core_test_interpolation {
namespace imuemu { using namespace ::imuemu; }

namespace {

using imuemu::kNsPerSecond;
using imuemu::Mat3;
using imuemu::Pose;
using imuemu::TimeNs;
using imuemu::Vec3;
namespace interp = imuemu::interp;
namespace so3 = imuemu::so3;

constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180.0;

Mat3 axis_angle(const Vec3& axis, double angle_rad) {
  return Eigen::AngleAxisd(angle_rad, axis.normalized()).toRotationMatrix();
}
Mat3 rz(double a) { return axis_angle(Vec3::UnitZ(), a); }

// Eq. 1.2: R = R_z(heading) R_y(pitch) R_x(roll), angles in degrees.
Mat3 hpr_deg(double h, double p, double r) {
  return rz(h * kDeg) * axis_angle(Vec3::UnitY(), p * kDeg) * axis_angle(Vec3::UnitX(), r * kDeg);
}

double rotation_distance(const Mat3& a, const Mat3& b) { return so3::angle(a.transpose() * b); }

TimeNs ns(double seconds) { return static_cast<TimeNs>(std::llround(seconds * 1e9)); }

Mat3 random_rotation(std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::Quaterniond q(n(rng), n(rng), n(rng), n(rng));
  return q.normalized().toRotationMatrix();
}

std::vector<TimeNs> uniform_times(TimeNs t0, TimeNs t1, TimeNs step) {
  std::vector<TimeNs> t;
  for (TimeNs x = t0; x <= t1; x += step) t.push_back(x);
  if (t.back() != t1) t.push_back(t1);
  return t;
}

interp::Options with_method(interp::Method m) {
  interp::Options o;
  o.method = m;
  return o;
}

// ---------------------------------------------------------------- geodesic

TEST(Geodesic, ReproducesConstantRateRotationBetweenKnots) {
  // R(t) = R0 exp(t [w]) has R_{i-1}^T R_i = exp(h_i [w]), so Eq. 3.44 must
  // return R0 exp(t [w]) exactly between knots when |w| h_i < pi.
  std::mt19937_64 rng(7);
  const std::vector<double> knot_s = {0.0, 1.0, 1.7, 3.2, 4.0};  // non-uniform, h_max = 1.5 s
  double worst_rad = 0.0, worst_pos_m = 0.0;
  for (double max_segment_deg : {5.0, 90.0, 170.0}) {
    for (int trial = 0; trial < 4; ++trial) {
      const Mat3 R0 = random_rotation(rng);
      const Vec3 axis = Eigen::Vector3d::Random().normalized();
      const double rate_rad_s = max_segment_deg * kDeg / 1.5;
      const Vec3 v_m_s(3.0, -2.0, 0.5);
      std::vector<Pose> knots;
      for (double t : knot_s) {
        knots.push_back({ns(t), Vec3(1.0, 2.0, 3.0) + t * v_m_s, R0 * axis_angle(axis, rate_rad_s * t)});
      }
      const auto times = uniform_times(0, ns(4.0), ns(0.0013));
      const auto out = interp::interpolate(knots, times, with_method(interp::Method::geodesic));
      ASSERT_EQ(out.size(), times.size());
      for (std::size_t k = 0; k < times.size(); ++k) {
        const double t = static_cast<double>(times[k]) * 1e-9;
        EXPECT_EQ(out[k].t_ns, times[k]);
        worst_rad = std::max(worst_rad, rotation_distance(out[k].attitude, R0 * axis_angle(axis, rate_rad_s * t)));
        worst_pos_m = std::max(worst_pos_m, (out[k].position_m - (Vec3(1.0, 2.0, 3.0) + t * v_m_s)).norm());
      }
    }
  }
  std::cout << "geodesic vs R0 exp(t[w]): worst attitude error " << worst_rad
            << " rad, worst position error " << worst_pos_m << " m\n";
  EXPECT_LT(worst_rad, 1e-13);
  EXPECT_LT(worst_pos_m, 1e-13);
}

TEST(Geodesic, MidpointBetweenIdentityAndRzIsHalfAngle) {
  double worst = 0.0;
  for (double phi : {1e-9, 1e-4, 0.3, 1.0, 2.0, 3.0, kPi - 1e-5}) {
    const Pose a{0, Vec3(0.0, 0.0, 0.0), Mat3::Identity()};
    const Pose b{2 * kNsPerSecond, Vec3(2.0, -4.0, 6.0), rz(phi)};
    const Pose m = interp::geodesic(a, b, 0.5);
    worst = std::max(worst, rotation_distance(m.attitude, rz(0.5 * phi)));
    EXPECT_EQ(m.t_ns, kNsPerSecond);
    EXPECT_LT((m.position_m - Vec3(1.0, -2.0, 3.0)).norm(), 1e-15);
    // The rotation stays about z: the z axis is fixed.
    EXPECT_LT((m.attitude * Vec3::UnitZ() - Vec3::UnitZ()).norm(), 1e-15);
    EXPECT_LT((m.attitude * Vec3::UnitZ()).cross(Vec3::UnitZ()).norm(), 1e-15);
  }
  std::cout << "geodesic midpoint vs Rz(phi/2): worst " << worst << " rad\n";
  EXPECT_LT(worst, 1e-15);
  // Endpoints.
  const Pose a{0, Vec3::Zero(), hpr_deg(20, 0, 30)};
  const Pose b{kNsPerSecond, Vec3::Ones(), hpr_deg(20, 10, 5)};
  EXPECT_LT(rotation_distance(interp::geodesic(a, b, 0.0).attitude, a.attitude), 1e-15);
  EXPECT_LT(rotation_distance(interp::geodesic(a, b, 1.0).attitude, b.attitude), 1e-15);
}

TEST(Geodesic, PositionIsLinearInTimeAtEcefScale) {
  // ECEF-sized coordinates: the linear interpolation must not lose precision.
  const Vec3 p0(4.2e6, 1.1e6, 4.6e6), p1(4.2e6 + 30.0, 1.1e6 - 12.0, 4.6e6 + 7.0);
  const std::vector<Pose> knots = {{ns(10.0), p0, Mat3::Identity()}, {ns(10.5), p1, rz(0.2)}};
  const auto times = uniform_times(ns(10.0), ns(10.5), ns(0.01));
  const auto out = interp::interpolate(knots, times, with_method(interp::Method::geodesic));
  double worst = 0.0;
  for (std::size_t k = 0; k < times.size(); ++k) {
    const double tau = static_cast<double>(times[k] - ns(10.0)) / 5e8;
    worst = std::max(worst, (out[k].position_m - (p0 + tau * (p1 - p0))).norm());
  }
  std::cout << "geodesic position vs linear (ECEF scale): worst " << worst << " m\n";
  EXPECT_LT(worst, 1e-8);  // a few ulp of 6e6 m
}

// ------------------------------------------------------ minimum acceleration

TEST(MinAcceleration, WarpIsTheLemma322Cubic) {
  // Closed form of the cubic with p(0)=0, p(1)=1, p'(0)=s, p'(1)=m:
  // p = (s + m - 2) tau^3 + (3 - 2 s - m) tau^2 + s tau.
  double worst = 0.0;
  for (auto [s, m] : {std::pair{1.0, 1.0}, {1.0, 3.0}, {10.0, -5.0}, {0.0, 0.0}, {-2.0, 7.5}}) {
    for (int k = 0; k <= 100; ++k) {
      const double tau = k / 100.0;
      const double p = ((s + m - 2.0) * tau + (3.0 - 2.0 * s - m)) * tau * tau + s * tau;
      worst = std::max(worst, std::abs(interp::min_acceleration_warp(tau, s, m) - p));
    }
    EXPECT_EQ(interp::min_acceleration_warp(0.0, s, m), 0.0);
    EXPECT_NEAR(interp::min_acceleration_warp(1.0, s, m), 1.0, 1e-15);
    const double d = 1e-6;
    EXPECT_NEAR((interp::min_acceleration_warp(d, s, m) - interp::min_acceleration_warp(0.0, s, m)) / d, s, 1e-4);
    EXPECT_NEAR((interp::min_acceleration_warp(1.0, s, m) - interp::min_acceleration_warp(1.0 - d, s, m)) / d, m, 1e-4);
  }
  EXPECT_LT(worst, 1e-14);
  // (10, -5): p = 3 tau^3 - 12 tau^2 + 10 tau.
  EXPECT_NEAR(interp::min_acceleration_warp(0.5, 10.0, -5.0), 3.0 / 8 - 3.0 + 5.0, 1e-15);
}

TEST(MinAcceleration, SigmaMuOneEqualsGeodesic) {
  const std::vector<Pose> knots = {{ns(1.0), Vec3(0, 0, 0), hpr_deg(20, 0, 30)},
                                   {ns(2.0), Vec3(5, 1, -2), hpr_deg(20, 10, 5)},
                                   {ns(2.3), Vec3(6, 1, -2), hpr_deg(60, 40, -50)}};
  const auto times = uniform_times(ns(1.0), ns(2.3), ns(0.01));
  const auto g = interp::interpolate(knots, times, with_method(interp::Method::geodesic));
  auto opt = with_method(interp::Method::min_acceleration);
  opt.sigma = 1.0;
  opt.mu = 1.0;
  const auto m = interp::interpolate(knots, times, opt);
  double worst = 0.0;
  for (std::size_t k = 0; k < times.size(); ++k) {
    worst = std::max(worst, rotation_distance(g[k].attitude, m[k].attitude));
    EXPECT_LT((g[k].position_m - m[k].position_m).norm(), 1e-14);
  }
  std::cout << "min-accel(1,1) vs geodesic: worst " << worst << " rad\n";
  EXPECT_LT(worst, 1e-15);
}

TEST(MinAcceleration, FollowsGeodesicWithWarpAndKeepsEndpoints) {
  // R(tau) = R_1 exp(p(tau) log(R_1^T R_2)) with p = 3 tau^3 - 12 tau^2 + 10 tau
  // for (sigma, mu) = (10, -5); the rotation axis is a known z axis here.
  const double phi = 0.4;
  const std::vector<Pose> knots = {{ns(1.0), Vec3(0, 0, 0), Mat3::Identity()},
                                   {ns(2.0), Vec3(2, 0, 0), rz(phi)}};
  auto opt = with_method(interp::Method::min_acceleration);
  opt.sigma = 10.0;
  opt.mu = -5.0;
  const auto times = uniform_times(ns(1.0), ns(2.0), ns(0.001));
  const auto out = interp::interpolate(knots, times, opt);
  double worst = 0.0;
  for (std::size_t k = 0; k < times.size(); ++k) {
    const double tau = static_cast<double>(times[k] - ns(1.0)) * 1e-9;
    const double p = ((3.0 * tau - 12.0) * tau + 10.0) * tau;
    worst = std::max(worst, rotation_distance(out[k].attitude, rz(p * phi)));
    EXPECT_NEAR(out[k].position_m.x(), 2.0 * p, 1e-13);
  }
  std::cout << "min-accel(10,-5) vs R exp(p(tau) r): worst " << worst << " rad\n";
  EXPECT_LT(worst, 1e-14);
  EXPECT_LT(rotation_distance(out.front().attitude, knots[0].attitude), 1e-15);
  EXPECT_LT(rotation_distance(out.back().attitude, knots[1].attitude), 1e-15);
  // Boundary speeds are sigma and mu times the geodesic's (Lemma 3.22).
  const std::vector<TimeNs> edge = {ns(1.0), ns(1.0) + 1000, ns(2.0) - 1000, ns(2.0)};
  const auto e = interp::interpolate(knots, edge, opt);
  const double rate0 = so3::log(e[0].attitude.transpose() * e[1].attitude).z() / 1e-6;
  const double rate1 = so3::log(e[2].attitude.transpose() * e[3].attitude).z() / 1e-6;
  EXPECT_NEAR(rate0, 10.0 * phi, 1e-4);
  EXPECT_NEAR(rate1, -5.0 * phi, 1e-4);
}

// --------------------------------------------------------------- Park-Ravani

// Body rate and acceleration at t_k from one side, by one-sided differences of
// phi(s) = log(R(t_k)^T R(t_k + s)): omega_b = phi'(0) and alpha_b = phi''(0)
// (W(0) = I and dW/ds phi' = -phi' x phi' / 2 = 0 at s = 0).
struct OneSided {
  Vec3 omega_rad_s;
  Vec3 alpha_rad_s2;
};
OneSided one_sided(const std::vector<Pose>& knots, const interp::Options& opt, TimeNs t_k, int side,
                   TimeNs step_ns) {
  std::vector<TimeNs> times;
  for (int j = 0; j <= 3; ++j) times.push_back(t_k + side * j * step_ns);
  if (side < 0) std::reverse(times.begin(), times.end());
  auto out = interp::interpolate(knots, times, opt);
  if (side < 0) std::reverse(out.begin(), out.end());
  Vec3 f[4];
  for (int j = 0; j <= 3; ++j) f[j] = so3::log(out[0].attitude.transpose() * out[static_cast<std::size_t>(j)].attitude);
  const double d = static_cast<double>(step_ns) * 1e-9;
  // Exact for cubics in s; phi is smooth on each side of the knot.
  const Vec3 first = (-3.0 * f[0] + 4.0 * f[1] - f[2]) / (2.0 * d);
  const Vec3 second = (2.0 * f[0] - 5.0 * f[1] + 4.0 * f[2] - f[3]) / (d * d);
  return {side * first, second};
}

std::vector<Pose> wiggly_knots() {
  // Table 2 (left)-like attitudes with non-uniform knot times.
  const double t[] = {0.0, 0.8, 2.0, 2.5, 4.0, 4.6};
  const double hpr[][3] = {{10, 0, 0}, {15, 3, 5}, {30, 10, 15}, {40, 20, 15}, {50, 25, 20}, {40, 20, 30}};
  std::vector<Pose> knots;
  for (int i = 0; i < 6; ++i) {
    knots.push_back({ns(t[i]), Vec3(t[i], t[i] * t[i], 0.0), hpr_deg(hpr[i][0], hpr[i][1], hpr[i][2])});
  }
  return knots;
}

TEST(ParkRavani, PassesThroughEveryKnot) {
  const auto knots = wiggly_knots();
  const auto opt = with_method(interp::Method::park_ravani);
  const auto seg = interp::park_ravani_coefficients(knots, opt);
  ASSERT_EQ(seg.size(), knots.size() - 1);
  double worst = 0.0;
  for (std::size_t i = 0; i < seg.size(); ++i) {
    const Mat3 end = knots[i].attitude * so3::exp(seg[i].a + seg[i].b + seg[i].c);
    worst = std::max(worst, rotation_distance(end, knots[i + 1].attitude));
  }
  // The interpolated output 1 ns either side of each knot is within |omega| * 1 ns.
  std::vector<TimeNs> near;
  for (std::size_t i = 0; i < knots.size(); ++i) {
    if (i > 0) near.push_back(knots[i].t_ns - 1);
    near.push_back(knots[i].t_ns);
    if (i + 1 < knots.size()) near.push_back(knots[i].t_ns + 1);
  }
  const auto out = interp::interpolate(knots, near, opt);
  double worst_near = 0.0;
  std::size_t k = 0;
  for (std::size_t i = 0; i < knots.size(); ++i) {
    const std::size_t count = (i > 0 ? 1u : 0u) + 1u + (i + 1 < knots.size() ? 1u : 0u);
    for (std::size_t j = 0; j < count; ++j, ++k) {
      worst_near = std::max(worst_near, rotation_distance(out[k].attitude, knots[i].attitude));
      EXPECT_LT((out[k].position_m - knots[i].position_m).norm(), 1e-7);
    }
  }
  // Bound for +-1 ns: the largest body rate on these knots (analytic, c / h at
  // each segment start, and W r' / h at the end) times 1 ns, with margin.
  double max_rate_rad_s = 0.0;
  for (const auto& sg : seg) {
    max_rate_rad_s = std::max(max_rate_rad_s, sg.c.norm() / sg.duration_s);
    max_rate_rad_s = std::max(max_rate_rad_s, (so3::W(sg.a + sg.b + sg.c) * (3.0 * sg.a + 2.0 * sg.b + sg.c)).norm() / sg.duration_s);
  }
  std::cout << "park-ravani knot error: coefficients " << worst << " rad, output at t_i +- 1 ns "
            << worst_near << " rad (max knot rate " << max_rate_rad_s << " rad/s)\n";
  EXPECT_LT(worst, 1e-12);
  EXPECT_LT(worst_near, 1.5 * max_rate_rad_s * 1e-9);
}

TEST(ParkRavani, AngularVelocityAndAccelerationContinuousAtInteriorKnots) {
  const auto knots = wiggly_knots();
  // Non-zero initial acceleration so that alpha is non-zero at every knot (the
  // default, a geodesic first segment, has alpha = 0 at knot 1 on both sides).
  auto opt = with_method(interp::Method::park_ravani);
  opt.initial_rate_from_first_segment = false;
  opt.initial_rate_rad_s = Vec3(0.05, 0.1, 0.05);
  opt.initial_angular_accel_rad_s2 = Vec3(0.1, -0.1, 0.2);
  const TimeNs step = 100'000;  // 0.1 ms
  double worst_omega = 0.0, worst_alpha = 0.0, min_alpha = 1e300, min_geodesic_jump = 1e300;
  for (std::size_t i = 1; i + 1 < knots.size(); ++i) {
    const OneSided l = one_sided(knots, opt, knots[i].t_ns, -1, step);
    const OneSided r = one_sided(knots, opt, knots[i].t_ns, +1, step);
    worst_omega = std::max(worst_omega, (l.omega_rad_s - r.omega_rad_s).norm());
    worst_alpha = std::max(worst_alpha, (l.alpha_rad_s2 - r.alpha_rad_s2).norm());
    min_alpha = std::min(min_alpha, l.alpha_rad_s2.norm());
    // Sensitivity: the same probe sees the geodesic's rate jump at the knot.
    const auto g = with_method(interp::Method::geodesic);
    const OneSided gl = one_sided(knots, g, knots[i].t_ns, -1, step);
    const OneSided gr = one_sided(knots, g, knots[i].t_ns, +1, step);
    min_geodesic_jump = std::min(min_geodesic_jump, (gl.omega_rad_s - gr.omega_rad_s).norm());
    // Analytic: W(r(1)) r'(1) / h_prev and alpha(r, r'/h, r''/h^2) of Eq. 3.61
    // against c / h and 2 b / h^2 of the next segment.
    const auto seg = interp::park_ravani_coefficients(knots, opt);
    const auto& p = seg[i - 1];
    const auto& q = seg[i];
    const Vec3 s = p.a + p.b + p.c, t = 3.0 * p.a + 2.0 * p.b + p.c, u = 6.0 * p.a + 2.0 * p.b;
    const double hp = p.duration_s, hq = q.duration_s;
    EXPECT_LT((so3::W(s) * t / hp - q.c / hq).norm(), 1e-12);
    EXPECT_LT((so3::angular_acceleration(s, t / hp, u / (hp * hp)) - 2.0 * q.b / (hq * hq)).norm(), 1e-11);
    // Finite differences agree with the analytic values.
    EXPECT_LT((r.omega_rad_s - q.c / hq).norm(), 1e-5);
    EXPECT_LT((r.alpha_rad_s2 - 2.0 * q.b / (hq * hq)).norm(), 1e-4);
  }
  std::cout << "park-ravani at interior knots (finite differences, 0.1 ms): max |omega jump| "
            << worst_omega << " rad/s, max |alpha jump| " << worst_alpha
            << " rad/s^2; min |alpha| " << min_alpha << " rad/s^2; geodesic min |omega jump| "
            << min_geodesic_jump << " rad/s\n";
  EXPECT_LT(worst_omega, 1e-5);
  EXPECT_LT(worst_alpha, 1e-4);
  EXPECT_GT(min_alpha, 0.05);          // the continuity is not 0 = 0
  EXPECT_GT(min_geodesic_jump, 0.01);  // the probe would see a kink
}

TEST(ParkRavani, InitialConditionsAreHonoured) {
  auto knots = wiggly_knots();
  auto opt = with_method(interp::Method::park_ravani);
  opt.initial_rate_from_first_segment = false;
  opt.initial_rate_rad_s = Vec3(0.1, -0.2, 0.3);
  opt.initial_angular_accel_rad_s2 = Vec3(-0.5, 0.25, 0.4);
  const OneSided r = one_sided(knots, opt, knots[0].t_ns, +1, 1'000'000);
  std::cout << "park-ravani initial omega error " << (r.omega_rad_s - opt.initial_rate_rad_s).norm()
            << " rad/s, alpha error " << (r.alpha_rad_s2 - opt.initial_angular_accel_rad_s2).norm()
            << " rad/s^2\n";
  EXPECT_LT((r.omega_rad_s - opt.initial_rate_rad_s).norm(), 1e-5);
  EXPECT_LT((r.alpha_rad_s2 - opt.initial_angular_accel_rad_s2).norm(), 1e-3);
  // Default: the first geodesic segment's constant rate, zero acceleration.
  const auto d = with_method(interp::Method::park_ravani);
  const OneSided r0 = one_sided(knots, d, knots[0].t_ns, +1, 1'000'000);
  const Vec3 geodesic_rate = so3::log(knots[0].attitude.transpose() * knots[1].attitude) / 0.8;
  EXPECT_LT((r0.omega_rad_s - geodesic_rate).norm(), 1e-5);
  EXPECT_LT(r0.alpha_rad_s2.norm(), 1e-3);
}

TEST(ParkRavani, ReproducesConstantRateRotation) {
  // Knots sampled from R0 exp(t [w]) and the matching initial rate: a = b = 0
  // and c_i = w h_i on every segment, so the output is R0 exp(t [w]) itself.
  // The recursion amplifies any inconsistency by ~3.7 per segment (see
  // ErrorGrowthFactor), so the knots are computed from the same integer-ns
  // times the interpolator sees, and only 10 segments are used.
  std::mt19937_64 rng(11);
  double worst = 0.0;
  for (bool uniform : {true, false}) {
    for (bool explicit_rate : {false, true}) {
      const Mat3 R0 = random_rotation(rng);
      const Vec3 w_rad_s = Vec3(0.7, -1.1, 0.4);
      std::vector<Pose> knots;
      for (int i = 0; i <= 10; ++i) {
        const TimeNs t_ns = ns(uniform ? 0.5 * i : 0.5 * i + 0.13 * std::sin(3.0 * i));
        const double t = static_cast<double>(t_ns) * 1e-9;
        knots.push_back({t_ns, Vec3::Zero(), R0 * axis_angle(w_rad_s, w_rad_s.norm() * t)});
      }
      auto opt = with_method(interp::Method::park_ravani);
      opt.initial_rate_from_first_segment = !explicit_rate;
      opt.initial_rate_rad_s = w_rad_s;
      const auto times = uniform_times(knots.front().t_ns, knots.back().t_ns, ns(0.01));
      const auto out = interp::interpolate(knots, times, opt);
      for (std::size_t k = 0; k < times.size(); ++k) {
        const double t = static_cast<double>(times[k]) * 1e-9;
        worst = std::max(worst, rotation_distance(out[k].attitude, R0 * axis_angle(w_rad_s, w_rad_s.norm() * t)));
      }
    }
  }
  std::cout << "park-ravani vs constant rate over 10 segments: worst " << worst << " rad\n";
  EXPECT_LT(worst, 1e-9);
}

TEST(ParkRavani, ErrorGrowthFactor) {
  // Why the thesis finds the scheme erratic for many knots (§3.6.1, App. B):
  // for small rotations W ~ I and alpha ~ r'', so a perturbation (dc, db) of
  // one segment propagates as dc' = -2 dc - db, db' = -3 dc - 2 db, whose
  // dominant eigenvalue is -(2 + sqrt 3) = -3.732. Perturb the initial rate
  // of a slow constant-rate trajectory and measure the growth.
  std::vector<Pose> knots;
  const Vec3 w_rad_s(1e-4, -2e-4, 1.5e-4);
  for (int i = 0; i <= 14; ++i) knots.push_back({i * kNsPerSecond, Vec3::Zero(), so3::exp(static_cast<double>(i) * w_rad_s)});
  auto base = with_method(interp::Method::park_ravani);
  base.initial_rate_from_first_segment = false;
  base.initial_rate_rad_s = w_rad_s;
  auto pert = base;
  pert.initial_rate_rad_s += Vec3(1e-9, 0.0, 0.0);
  const auto s0 = interp::park_ravani_coefficients(knots, base);
  const auto s1 = interp::park_ravani_coefficients(knots, pert);
  std::vector<double> dc;
  for (std::size_t i = 0; i < s0.size(); ++i) dc.push_back((s1[i].c - s0[i].c).norm());
  const double factor = dc[12] / dc[11];
  std::cout << "park-ravani perturbation growth per segment: " << factor << " (theory "
            << 2.0 + std::sqrt(3.0) << "); after 13 segments x" << dc[12] / dc[0] << "\n";
  EXPECT_NEAR(factor, 2.0 + std::sqrt(3.0), 0.01);
  EXPECT_GT(dc[12] / dc[0], 1e6);
}

TEST(ParkRavani, DivergenceOnLongTrajectoriesIsReportedNotReturnedAsNaN) {
  // Even exact constant-rate knots: rounding grows ~3.7x per knot and
  // overflows after a few hundred knots.
  std::vector<Pose> knots;
  for (int i = 0; i <= 1000; ++i) {
    knots.push_back({i * kNsPerSecond, Vec3::Zero(), so3::exp(static_cast<double>(i) * Vec3(0.01, 0.02, -0.015))});
  }
  const auto opt = with_method(interp::Method::park_ravani);
  std::string msg;
  try {
    interp::interpolate(knots, {0, 1000 * kNsPerSecond}, opt);
  } catch (const interp::InterpolationError& e) {
    msg = e.what();
  }
  std::cout << "1001 constant-rate knots: " << msg << "\n";
  EXPECT_NE(msg.find("park-ravani diverged between knots"), std::string::npos) << msg;
  // The geodesic has no such problem.
  const auto g = interp::interpolate(knots, {0, 500 * kNsPerSecond + 1, 1000 * kNsPerSecond},
                                     with_method(interp::Method::geodesic));
  EXPECT_TRUE(g[1].attitude.allFinite());
}

TEST(ParkRavani, PositionIsTheNaturalCubicSpline) {
  // Hand-solved natural spline through (0,0), (1,1), (3,0) (t in s, x in m):
  // M1 = -1.5; S = 1.25 t - 0.25 t^3 on [0,1], S = 2A - A^3, A = (3-t)/2 on [1,3].
  const std::vector<Pose> knots = {{ns(0.0), Vec3(0, 0, 0), Mat3::Identity()},
                                   {ns(1.0), Vec3(1, 0, 0), rz(0.1)},
                                   {ns(3.0), Vec3(0, 0, 0), rz(0.2)}};
  const auto times = uniform_times(0, ns(3.0), ns(0.01));
  const auto out = interp::interpolate(knots, times, with_method(interp::Method::park_ravani));
  double worst = 0.0;
  for (std::size_t k = 0; k < times.size(); ++k) {
    const double t = static_cast<double>(times[k]) * 1e-9;
    const double A = (3.0 - t) / 2.0;
    const double truth = t <= 1.0 ? 1.25 * t - 0.25 * t * t * t : 2.0 * A - A * A * A;
    worst = std::max(worst, std::abs(out[k].position_m.x() - truth));
    EXPECT_EQ(out[k].position_m.y(), 0.0);
  }
  std::cout << "natural spline vs hand solution: worst " << worst << " m\n";
  EXPECT_LT(worst, 1e-14);

  // Six non-uniform knots: linear data reproduced; natural ends and C2 joins
  // (one-sided second differences are exact for cubics).
  auto wk = wiggly_knots();
  for (auto& k : wk) k.position_m = Vec3(2.0, -1.0, 0.5) * (static_cast<double>(k.t_ns) * 1e-9) + Vec3(7, 8, 9);
  const auto lin_times = uniform_times(wk.front().t_ns, wk.back().t_ns, ns(0.037));
  const auto lin = interp::interpolate(wk, lin_times, with_method(interp::Method::park_ravani));
  double worst_lin = 0.0;
  for (std::size_t k = 0; k < lin.size(); ++k) {
    const double t = static_cast<double>(lin_times[k]) * 1e-9;
    worst_lin = std::max(worst_lin, (lin[k].position_m - (Vec3(2.0, -1.0, 0.5) * t + Vec3(7, 8, 9))).norm());
  }
  EXPECT_LT(worst_lin, 1e-13);

  wk = wiggly_knots();  // positions (t, t^2, 0): curved
  // The whole-trajectory natural spline: a spline window reaching every knot
  // (the default window solves the C2 condition over +-4 knots only, see
  // interp::Options::spline_window_knots; tests/core/test_stream.cpp measures it).
  auto whole = with_method(interp::Method::park_ravani);
  whole.spline_window_knots = static_cast<int>(wk.size()) - 1;
  const TimeNs d = 1'000'000;
  const double d_s = 1e-3;
  auto second = [&](TimeNs t_k, int side) {
    std::vector<TimeNs> ts;
    for (int j = 0; j <= 3; ++j) ts.push_back(t_k + side * j * d);
    if (side < 0) std::reverse(ts.begin(), ts.end());
    auto o = interp::interpolate(wk, ts, whole);
    if (side < 0) std::reverse(o.begin(), o.end());
    return Vec3((2.0 * o[0].position_m - 5.0 * o[1].position_m + 4.0 * o[2].position_m - o[3].position_m) / (d_s * d_s));
  };
  auto first = [&](TimeNs t_k, int side) {
    std::vector<TimeNs> ts;
    for (int j = 0; j <= 3; ++j) ts.push_back(t_k + side * j * d);
    if (side < 0) std::reverse(ts.begin(), ts.end());
    auto o = interp::interpolate(wk, ts, whole);
    if (side < 0) std::reverse(o.begin(), o.end());
    // Four-point one-sided first derivative, exact for cubics.
    return Vec3(side * (-11.0 * o[0].position_m + 18.0 * o[1].position_m - 9.0 * o[2].position_m + 2.0 * o[3].position_m) / (6.0 * d_s));
  };
  double worst_c1 = 0.0, worst_c2 = 0.0;
  for (std::size_t i = 1; i + 1 < wk.size(); ++i) {
    worst_c1 = std::max(worst_c1, (first(wk[i].t_ns, -1) - first(wk[i].t_ns, +1)).norm());
    worst_c2 = std::max(worst_c2, (second(wk[i].t_ns, -1) - second(wk[i].t_ns, +1)).norm());
  }
  const double end0 = second(wk.front().t_ns, +1).norm();
  const double end1 = second(wk.back().t_ns, -1).norm();
  std::cout << "spline joins: max velocity jump " << worst_c1 << " m/s, max acceleration jump "
            << worst_c2 << " m/s^2; end accelerations " << end0 << ", " << end1 << " m/s^2\n";
  EXPECT_LT(worst_c1, 1e-8);
  EXPECT_LT(worst_c2, 1e-4);
  EXPECT_LT(end0, 1e-4);
  EXPECT_LT(end1, 1e-4);
}

// ------------------------------------------------------------ knot checking

std::string error_of(const std::vector<Pose>& knots) {
  try {
    interp::check_knots(knots);
  } catch (const interp::InterpolationError& e) {
    return e.what();
  }
  return "";
}

TEST(CheckKnots, AntipodalPairIsRefusedWithBothKnotsNamed) {
  std::vector<Pose> knots;
  for (int i = 0; i <= 4; ++i) knots.push_back({i * kNsPerSecond, Vec3::Zero(), rz(0.1 * i)});
  knots.push_back({5 * kNsPerSecond, Vec3::Zero(), rz(0.4 + kPi)});
  const std::string msg = error_of(knots);
  std::cout << "antipodal: " << msg << "\n";
  EXPECT_NE(msg.find("knots 4 (t=4.000000000 s) and 5 (t=5.000000000 s)"), std::string::npos) << msg;
  EXPECT_NE(msg.find("antipodal"), std::string::npos) << msg;
  EXPECT_NE(msg.find("180.000 deg"), std::string::npos) << msg;
  EXPECT_THROW(interp::interpolate(knots, {0}, {}), interp::InterpolationError);

  // Rz(pi) directly after the identity.
  EXPECT_NE(error_of({{0, Vec3::Zero(), Mat3::Identity()}, {kNsPerSecond, Vec3::Zero(), rz(kPi)}}).find("antipodal"),
            std::string::npos);
  // Just inside the margin is accepted; just outside is refused.
  EXPECT_EQ(error_of({{0, Vec3::Zero(), Mat3::Identity()}, {1, Vec3::Zero(), rz(kPi - 1e-4)}}), "");
  EXPECT_NE(error_of({{0, Vec3::Zero(), Mat3::Identity()}, {1, Vec3::Zero(), rz(kPi - 1e-8)}}), "");
}

TEST(CheckKnots, TimesAndCount) {
  EXPECT_NE(error_of({}).find("at least 2 knots, got 0"), std::string::npos);
  EXPECT_NE(error_of({{0, Vec3::Zero(), Mat3::Identity()}}).find("at least 2 knots, got 1"), std::string::npos);
  const std::string dup = error_of({{0, Vec3::Zero(), Mat3::Identity()},
                                    {ns(1.5), Vec3::Zero(), Mat3::Identity()},
                                    {ns(1.5), Vec3::Zero(), Mat3::Identity()}});
  std::cout << "duplicate: " << dup << "\n";
  EXPECT_NE(dup.find("knots 1 (t=1.500000000 s) and 2 (t=1.500000000 s)"), std::string::npos) << dup;
  EXPECT_NE(dup.find("not strictly increasing"), std::string::npos);
  EXPECT_NE(error_of({{-ns(0.25), Vec3::Zero(), Mat3::Identity()}, {-ns(0.5), Vec3::Zero(), Mat3::Identity()}})
                .find("knots 0 (t=-0.250000000 s) and 1 (t=-0.500000000 s)"),
            std::string::npos);
  Pose bad{ns(2.0), Vec3(std::nan(""), 0, 0), Mat3::Identity()};
  EXPECT_NE(error_of({{0, Vec3::Zero(), Mat3::Identity()}, bad}).find("not finite"), std::string::npos);
}

TEST(Interpolate, OutputTimesMustBeInsideTheKnotSpanAndSorted) {
  const std::vector<Pose> knots = {{ns(1.0), Vec3::Zero(), Mat3::Identity()}, {ns(2.0), Vec3::Zero(), rz(0.5)}};
  for (auto m : {interp::Method::geodesic, interp::Method::min_acceleration, interp::Method::park_ravani}) {
    EXPECT_THROW(interp::interpolate(knots, {ns(1.0) - 1}, with_method(m)), std::invalid_argument);
    EXPECT_THROW(interp::interpolate(knots, {ns(2.0) + 1}, with_method(m)), std::invalid_argument);
    EXPECT_THROW(interp::interpolate(knots, {ns(1.5), ns(1.2)}, with_method(m)), std::invalid_argument);
    EXPECT_TRUE(interp::interpolate(knots, {}, with_method(m)).empty());
    const auto both = interp::interpolate(knots, {ns(1.0), ns(1.0), ns(2.0)}, with_method(m));
    ASSERT_EQ(both.size(), 3u);
    EXPECT_EQ(both[2].attitude, knots[1].attitude);
  }
}

TEST(Interpolate, MethodNames) {
  for (auto m : {interp::Method::geodesic, interp::Method::min_acceleration, interp::Method::park_ravani}) {
    EXPECT_EQ(interp::method_from_string(interp::to_string(m)), m);
  }
  EXPECT_EQ(interp::to_string(interp::Method::min_acceleration), "min-accel");
  EXPECT_THROW(interp::method_from_string("slerp"), std::invalid_argument);
}

TEST(Interpolate, ManySamplesAcrossManySegments) {
  // 2000 knots at 1 Hz to 200 Hz output: the moving segment index must land
  // every sample in its own segment (checked against the per-pair geodesic).
  std::mt19937_64 rng(3);
  std::vector<Pose> knots;
  Mat3 R = Mat3::Identity();
  for (int i = 0; i < 2000; ++i) {
    knots.push_back({i * kNsPerSecond, Vec3(i, 0, 0), R});
    R = R * so3::exp(0.3 * Eigen::Vector3d::Random());
  }
  const auto times = uniform_times(0, knots.back().t_ns, ns(0.005));
  const auto out = interp::interpolate(knots, times, with_method(interp::Method::geodesic));
  double worst = 0.0;
  for (std::size_t k = 0; k < times.size(); k += 37) {
    const std::size_t i = std::min<std::size_t>(static_cast<std::size_t>(times[k] / kNsPerSecond), knots.size() - 2);
    const double tau = static_cast<double>(times[k] - knots[i].t_ns) * 1e-9;
    worst = std::max(worst, rotation_distance(out[k].attitude, interp::geodesic(knots[i], knots[i + 1], tau).attitude));
  }
  EXPECT_LT(worst, 1e-14);
}

}  // namespace
}  // namespace unity_core_test_interpolation
