// Cumulative cubic B-spline on SO(3) x R^3 (core/bspline.hpp) against
// independent truth: the closed-form reference motions (core/reference_motion)
// through Eq. 3.70 at the same output times, the exact reproduction of
// one-parameter subgroups R0 exp(t w) and straight lines that the cumulative
// basis guarantees (sum B~_j = 1 + u), the classical B-spline value at a knot
// (p_{k-1} + 4 p_k + p_{k+1}) / 6, and finite differences of the spline's own
// attitude/position (its analytic derivatives must be their derivatives).
#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <string>
#include <vector>

#include "core/bspline.hpp"
#include "core/interpolation.hpp"
#include "core/reference_motion.hpp"
#include "core/so3.hpp"
#include "tests/support/imu_errors.hpp"

using namespace imuemu;

namespace {

#if defined(__SANITIZE_ADDRESS__)
constexpr TimeNs kDuration_ns = 120 * kNsPerSecond;
#else
constexpr TimeNs kDuration_ns = 600 * kNsPerSecond;  // 10-minute runs
#endif
constexpr TimeNs kKnotPeriod_ns = kNsPerSecond;  // knots at 1 Hz

using Stats = test_support::ImuErrorStats;

// Runs the B-spline on 1 Hz knots of `motion` and compares every output sample
// with truth_imu of the motion at the same t_ns.
Stats measure(const reference::Motion& motion, std::int64_t rate_hz, BatchResult* keep = nullptr) {
  SceneModel scene;
  scene.physics = motion.physics();
  const std::vector<Pose> knots = reference::sample_knots(motion, kKnotPeriod_ns);
  const auto t0 = std::chrono::steady_clock::now();
  BatchResult out = bspline::run(knots, scene, rate_hz);
  const auto t1 = std::chrono::steady_clock::now();
  Stats s = test_support::imu_errors_against_truth(out, motion, scene, out.imu.front().t_ns, out.imu.back().t_ns);
  s.ns_per_sample = static_cast<double>(std::chrono::duration_cast<std::chrono::nanoseconds>(t1 - t0).count()) /
                    static_cast<double>(s.samples);
  if (keep != nullptr) *keep = std::move(out);
  return s;
}

void print_row(const std::string& scene, std::int64_t rate_hz, const Stats& s) {
  char line[256];
  std::snprintf(line, sizeof line, "| bspline | %-18s | %4lld Hz | %.2e | %.2e | %.2e | %.2e | %4.0f |\n",
                scene.c_str(), static_cast<long long>(rate_hz), s.gyro_rms_rad_s, s.gyro_max_rad_s,
                s.accel_rms_m_s2, s.accel_max_m_s2, s.ns_per_sample);
  std::cout << line;
  const std::string key = "bspline_" + scene + "_" + std::to_string(rate_hz);
  ::testing::Test::RecordProperty(key + "_gyro_max", std::to_string(s.gyro_max_rad_s));
  ::testing::Test::RecordProperty(key + "_accel_max", std::to_string(s.accel_max_m_s2));
}

using Bounds = test_support::ErrorBounds;
using test_support::central_difference;
using test_support::expect_within;

Mat3 R_xyz(double x, double y, double z) { return so3::exp(Vec3(x, y, z)); }


}  // namespace

// The comparison table (method x rate x scene). Bounds are the Release
// measurement (10 minutes, see the report in the test output) times ~3.
TEST(BSpline, AccuracyAgainstReferenceMotions) {
  std::cout << "| method | scene | rate | gyro RMS (rad/s) | gyro max (rad/s) | accel RMS (m/s^2) | "
               "accel max (m/s^2) | ns/sample |\n";
  const reference::AircraftFlight flight_flat(Physics::flat, reference::AircraftFlight::default_origin(), 0,
                                              kDuration_ns);
  const reference::AircraftFlight flight_ecef(Physics::ecef, reference::AircraftFlight::default_origin(), 0,
                                              kDuration_ns);
  const reference::Circle circle(500.0, 50.0, 0, kDuration_ns);
  const reference::ConstantRate spin(R_xyz(0.3, -0.2, 0.5), Vec3(0.02, -0.35, 0.11), 0, kDuration_ns);
  const reference::Static still_flat(reference::AircraftFlight::default_origin(), {0.4, 0.1, -0.2},
                                     Physics::flat, 0, kDuration_ns);
  const reference::Static still_ecef(reference::AircraftFlight::default_origin(), {0.4, 0.1, -0.2},
                                     Physics::ecef, 0, kDuration_ns);
  for (const std::int64_t rate : {100, 400}) {
    const Stats ff = measure(flight_flat, rate);
    print_row("aircraft flat", rate, ff);
    const Stats fe = measure(flight_ecef, rate);
    print_row("aircraft ecef", rate, fe);
    const Stats c = measure(circle, rate);
    print_row("circle r=500 v=50", rate, c);
    const Stats cr = measure(spin, rate);
    print_row("constant rate", rate, cr);
    const Stats sf = measure(still_flat, rate);
    print_row("static flat", rate, sf);
    const Stats se = measure(still_ecef, rate);
    print_row("static ecef", rate, se);

    const std::string r = " at " + std::to_string(rate) + " Hz";
    // Measured (Release, 10 min, both rates): flight gyro RMS 4.1e-4 max
    // 6.6e-4 rad/s, accel RMS 1.6e-2 max 2.8e-2 m/s^2 (flat and ecef agree);
    // circle gyro 7e-15 (a turn at constant rate is a one-parameter subgroup),
    // accel RMS 8.5e-3 max 1.0e-2 (the B-spline's smoothing of the orbit).
    expect_within(ff, {1.2e-3, 2e-3, 5e-2, 9e-2}, "aircraft flat" + r);
    expect_within(fe, {1.2e-3, 2e-3, 5e-2, 9e-2}, "aircraft ecef" + r);
    expect_within(c, {1e-12, 1e-12, 2.5e-2, 3e-2}, "circle" + r);
    expect_within(cr, {1e-12, 1e-12, 1e-12, 1e-12}, "constant rate" + r);
    expect_within(sf, {1e-9, 1e-9, 1e-9, 1e-9}, "static flat" + r);
    expect_within(se, {1e-9, 1e-9, 1e-9, 1e-9}, "static ecef" + r);
    // The flight is not reproduced exactly (approximating spline): a
    // comparison that measured nothing would show up here.
    EXPECT_GT(ff.gyro_rms_rad_s, 1e-6);
    EXPECT_GT(ff.accel_rms_m_s2, 1e-4);
  }
}

// The cumulative spline reproduces one-parameter subgroups: knots of
// R0 exp(t w) have equal d_j = w dt, the factors commute and sum_j B~_j = 1 + u,
// so R(t) = R0 exp(t w) and the gyro is w exactly, with zero angular
// acceleration, even at 2.4 rad per knot interval.
TEST(BSpline, ConstantRateIsReproducedExactly) {
  for (const Vec3& w : {Vec3(0.02, -0.35, 0.11), Vec3(1.1, -2.0, 0.7), Vec3(0.0, 0.0, 1e-7)}) {
    const reference::ConstantRate spin(R_xyz(-1.0, 0.4, 2.0), w, 5 * kNsPerSecond, 60 * kNsPerSecond);
    const bspline::Spline spline(reference::sample_knots(spin, kKnotPeriod_ns));
    double gyro_err = 0.0, att_err = 0.0, alpha_max = 0.0;
    for (TimeNs t = spline.start_ns(); t <= spline.end_ns(); t += 7'654'321) {
      Kinematics k;
      Vec3 alpha;
      spline.evaluate(t, k, &alpha);
      const Kinematics truth = spin.at(t);
      gyro_err = std::max(gyro_err, (k.angular_rate_rad_s - truth.angular_rate_rad_s).norm());
      att_err = std::max(att_err, so3::angle(truth.attitude.transpose() * k.attitude));
      alpha_max = std::max(alpha_max, alpha.norm());
    }
    std::cout << "constant rate |w| = " << w.norm() << " rad/s: gyro err " << gyro_err << " rad/s, attitude err "
              << att_err << " rad, |alpha| " << alpha_max << " rad/s^2\n";
    EXPECT_LT(gyro_err, 1e-12);
    EXPECT_LT(att_err, 1e-12);
    EXPECT_LT(alpha_max, 1e-12);
  }
}

// Static trajectories: every d_j and position difference is exactly zero, so
// the IMU is exactly gravity and Earth rate, and the ECEF acceleration is an
// exact zero (no 6.4e6 m numbers cancel anywhere).
TEST(BSpline, StaticReproducesGravityAndEarthRate) {
  for (const Physics physics : {Physics::flat, Physics::ecef}) {
    const reference::Static still(earth::Geodetic{-0.6, 2.5, 350.0}, {2.0, -0.3, 0.8}, physics, 0,
                                  20 * kNsPerSecond);
    SceneModel scene;
    scene.physics = physics;
    const std::vector<Pose> knots = reference::sample_knots(still, kKnotPeriod_ns);
    const BatchResult out = bspline::run(knots, scene, 400);
    double gyro_err = 0.0, accel_err = 0.0;
    for (std::size_t i = 0; i < out.imu.size(); ++i) {
      const Kinematics& k = out.trajectory[i];
      EXPECT_EQ(k.velocity_m_s, Vec3::Zero());
      EXPECT_EQ(k.acceleration_m_s2, Vec3::Zero());
      EXPECT_EQ(k.angular_rate_rad_s, Vec3::Zero());
      EXPECT_EQ(k.position_m, knots[0].position_m);
      const ImuSample truth = reference::truth_imu(still, scene, out.imu[i].t_ns);
      gyro_err = std::max(gyro_err, (out.imu[i].gyro_rad_s - truth.gyro_rad_s).norm());
      accel_err = std::max(accel_err, (out.imu[i].accel_m_s2 - truth.accel_m_s2).norm());
    }
    std::cout << "static " << (physics == Physics::ecef ? "ecef" : "flat") << ": gyro err " << gyro_err
              << " rad/s, accel err " << accel_err << " m/s^2\n";
    EXPECT_LT(gyro_err, 1e-9);
    EXPECT_LT(accel_err, 1e-9);
  }
}

// A straight line at constant velocity far from the origin (ECEF magnitudes):
// the uniform B-spline reproduces linear functions, so velocity is v and the
// acceleration zero up to the rounding of the knot positions (ulp 9e-10 m).
TEST(BSpline, StraightLineAtEcefScaleIsReproduced) {
  const Vec3 p0(4'846'000.123, 183'600.456, 4'116'000.789);
  const Vec3 v(120.25, -87.5, 33.125);
  std::vector<Pose> knots;
  for (int k = 0; k < 30; ++k) knots.push_back(Pose{k * kNsPerSecond, p0 + static_cast<double>(k) * v, R_xyz(0.1, 0.2, 0.3)});
  const bspline::Spline spline(knots);
  double p_err = 0.0, v_err = 0.0, a_err = 0.0;
  for (TimeNs t = spline.start_ns(); t <= spline.end_ns(); t += 3'333'333) {
    Kinematics k;
    spline.evaluate(t, k);
    const long double s = static_cast<long double>(t) * 1e-9L;
    for (int j = 0; j < 3; ++j) {
      const long double truth = static_cast<long double>(p0[j]) + s * static_cast<long double>(v[j]);
      p_err = std::max(p_err, static_cast<double>(std::fabs(static_cast<long double>(k.position_m[j]) - truth)));
    }
    v_err = std::max(v_err, (k.velocity_m_s - v).norm());
    a_err = std::max(a_err, k.acceleration_m_s2.norm());
  }
  std::cout << "straight line at ECEF scale: position err " << p_err << " m, velocity err " << v_err
            << " m/s, |accel| " << a_err << " m/s^2\n";
  EXPECT_LT(p_err, 5e-9);
  EXPECT_LT(v_err, 1e-8);
  EXPECT_LT(a_err, 1e-8);
}

// The spline approximates: at knot k it is the classical uniform cubic
// B-spline value (p_{k-1} + 4 p_k + p_{k+1}) / 6 with velocity
// (p_{k+1} - p_{k-1}) / 2dt and acceleration (p_{k+1} - 2 p_k + p_{k-1}) / dt^2,
// not the knot itself.
TEST(BSpline, ValueAtKnotIsTheClassicalBSplineAverage) {
  const reference::AircraftFlight flight(Physics::ecef, reference::AircraftFlight::default_origin(), 0,
                                         30 * kNsPerSecond);
  const std::vector<Pose> knots = reference::sample_knots(flight, kKnotPeriod_ns);
  const bspline::Spline spline(knots);
  double p_err = 0.0, v_err = 0.0, a_err = 0.0, off_knot = 0.0;
  for (std::size_t k = 1; k + 1 < knots.size(); ++k) {
    Kinematics kin;
    spline.evaluate(knots[k].t_ns, kin);
    // Long double differences relative to p_k, as an independent evaluation.
    for (int j = 0; j < 3; ++j) {
      const long double pm = knots[k - 1].position_m[j], p = knots[k].position_m[j], pp = knots[k + 1].position_m[j];
      const long double value = p + ((pm - p) + (pp - p)) / 6.0L;
      p_err = std::max(p_err, static_cast<double>(std::fabs(kin.position_m[j] - value)));
      v_err = std::max(v_err, static_cast<double>(std::fabs(kin.velocity_m_s[j] - (pp - pm) / 2.0L)));
      a_err = std::max(a_err, static_cast<double>(std::fabs(kin.acceleration_m_s2[j] - ((pp - p) - (p - pm)))));
    }
    off_knot = std::max(off_knot, (kin.position_m - knots[k].position_m).norm());
  }
  std::cout << "B-spline at the knots vs (p-+4p+p+)/6: position " << p_err << " m, velocity " << v_err
            << " m/s, accel " << a_err << " m/s^2; distance from the knot itself up to " << off_knot << " m\n";
  EXPECT_LT(p_err, 2e-9);
  EXPECT_LT(v_err, 1e-9);
  EXPECT_LT(a_err, 1e-9);
  EXPECT_GT(off_knot, 0.1);  // approximating, not interpolating
}

// The analytic derivatives are the derivatives of the spline's own outputs:
// body rate vs a 4th-order central difference of log(R(t)^T R(t+s)), angular
// acceleration vs the difference of the body rate, velocity/acceleration vs
// differences of position/velocity (stencil inside one segment, where the
// position is a cubic and the difference is exact up to rounding).
TEST(BSpline, DerivativesMatchFiniteDifferencesOfItsOwnOutput) {
  const reference::AircraftFlight flight(Physics::ecef, reference::AircraftFlight::default_origin(), 0,
                                         40 * kNsPerSecond);
  const std::vector<Pose> knots = reference::sample_knots(flight, kKnotPeriod_ns);
  const bspline::Spline spline(knots);
  auto eval = [&](TimeNs t) {
    Kinematics k;
    spline.evaluate(t, k);
    return k;
  };
  double w_err = 0.0, alpha_err = 0.0, v_err = 0.0, a_err = 0.0, w_max = 0.0, alpha_max = 0.0;
  for (TimeNs t = spline.start_ns() + 150'000'000; t < spline.end_ns() - 150'000'000; t += 123'456'789) {
    Kinematics k;
    Vec3 alpha;
    spline.evaluate(t, k, &alpha);
    const Mat3 Rt = k.attitude.transpose();
    const auto step = [](double s) { return static_cast<TimeNs>(std::llround(s * 1e9)); };
    const Vec3 w_fd = central_difference([&](double s) { return Vec3(so3::log(Rt * eval(t + step(s)).attitude)); }, 1e-3);
    w_err = std::max(w_err, (w_fd - k.angular_rate_rad_s).norm());
    w_max = std::max(w_max, k.angular_rate_rad_s.norm());
    alpha_max = std::max(alpha_max, alpha.norm());
    // The attitude is C2 across knots, so its difference is fine anywhere; the
    // angular acceleration is only C0 there and the position a different
    // cubic on each side, so those stencils (+-0.1 s) stay inside a segment.
    const TimeNs into = (t - knots[0].t_ns) % kKnotPeriod_ns;
    if (into > 100'000'000 && into < 900'000'000) {
      const Vec3 alpha_fd = central_difference([&](double s) { return Vec3(eval(t + step(s)).angular_rate_rad_s); }, 1e-3);
      alpha_err = std::max(alpha_err, (alpha_fd - alpha).norm());
      const Vec3 v_fd = central_difference([&](double s) { return Vec3(eval(t + step(s)).position_m - k.position_m); }, 0.05);
      const Vec3 a_fd = central_difference([&](double s) { return Vec3(eval(t + step(s)).velocity_m_s); }, 0.05);
      v_err = std::max(v_err, (v_fd - k.velocity_m_s).norm());
      a_err = std::max(a_err, (a_fd - k.acceleration_m_s2).norm());
    }
  }
  std::cout << "B-spline self-consistency: body rate vs FD of attitude " << w_err << " rad/s (|w| <= " << w_max
            << "), angular accel vs FD of rate " << alpha_err << " rad/s^2 (|alpha| <= " << alpha_max
            << "), velocity vs FD " << v_err << " m/s, accel vs FD " << a_err << " m/s^2\n";
  // Measured 1.2e-13, 1.2e-14, 1.4e-8 (the 9e-10 m ulp of ECEF positions
  // over the 0.05 s step), 8.6e-13.
  EXPECT_LT(w_err, 1e-11);
  EXPECT_LT(alpha_err, 1e-11);
  EXPECT_LT(v_err, 1e-7);
  EXPECT_LT(a_err, 1e-10);
  EXPECT_GT(w_max, 1e-3);  // the comparison measured a moving body
}

// C2 at the knots: the end of segment s and the start of segment s+1 agree in
// attitude, body rate, angular acceleration, position, velocity, acceleration.
TEST(BSpline, IsTwiceContinuousAtTheKnots) {
  const reference::AircraftFlight flight(Physics::flat, reference::AircraftFlight::default_origin(), 0,
                                         30 * kNsPerSecond);
  const std::vector<Pose> knots = reference::sample_knots(flight, kKnotPeriod_ns);
  const bspline::Spline spline(knots);
  double att = 0.0, w = 0.0, alpha = 0.0, p = 0.0, v = 0.0, a = 0.0;
  for (std::size_t s = 0; s + 1 < spline.segment_count(); ++s) {
    const TimeNs t = knots[s + 2].t_ns;
    Kinematics l, r;
    Vec3 al, ar;
    spline.evaluate_in_segment(s, t, l, &al);
    spline.evaluate_in_segment(s + 1, t, r, &ar);
    att = std::max(att, so3::angle(l.attitude.transpose() * r.attitude));
    w = std::max(w, (l.angular_rate_rad_s - r.angular_rate_rad_s).norm());
    alpha = std::max(alpha, (al - ar).norm());
    p = std::max(p, (l.position_m - r.position_m).norm());
    v = std::max(v, (l.velocity_m_s - r.velocity_m_s).norm());
    a = std::max(a, (l.acceleration_m_s2 - r.acceleration_m_s2).norm());
  }
  std::cout << "jumps at knots: attitude " << att << " rad, rate " << w << ", angular accel " << alpha
            << ", position " << p << ", velocity " << v << ", accel " << a << "\n";
  EXPECT_LT(att, 1e-14);
  EXPECT_LT(w, 1e-14);
  EXPECT_LT(alpha, 1e-13);
  EXPECT_LT(p, 1e-10);
  EXPECT_LT(v, 1e-12);
  EXPECT_LT(a, 1e-12);
}

// Knot spacing: jitter within the relative tolerance is accepted (and barely
// changes the result), beyond it the B-spline refuses with a message.
TEST(BSpline, RequiresUniformKnots) {
  const reference::AircraftFlight flight(Physics::flat, reference::AircraftFlight::default_origin(), 0,
                                         60 * kNsPerSecond);
  SceneModel scene;
  auto jittered = [&](TimeNs amplitude_ns) {
    std::vector<Pose> knots;
    for (TimeNs k = 0; k <= 60; ++k) {
      const TimeNs t = k * kNsPerSecond + (k % 3 - 1) * amplitude_ns;  // -a, 0, +a, ...
      const Kinematics kin = flight.at(t);
      knots.push_back(Pose{t, kin.position_m, kin.attitude});
    }
    return knots;
  };
  // 0.45 us on 1 s: intervals deviate by up to 0.9e-6 relative: accepted.
  const BatchResult out = bspline::run(jittered(450), scene, 100);
  double gyro_max = 0.0, accel_max = 0.0;
  for (const ImuSample& s : out.imu) {
    const ImuSample t = reference::truth_imu(flight, scene, s.t_ns);
    gyro_max = std::max(gyro_max, (s.gyro_rad_s - t.gyro_rad_s).norm());
    accel_max = std::max(accel_max, (s.accel_m_s2 - t.accel_m_s2).norm());
  }
  std::cout << "jittered knots (+-0.45 us): gyro max " << gyro_max << " rad/s, accel max " << accel_max << " m/s^2\n";
  EXPECT_LT(gyro_max, 2e-3);
  EXPECT_LT(accel_max, 9e-2);
  // 1.5 us: 3e-6 relative: refused.
  try {
    bspline::run(jittered(1500), scene, 100);
    ADD_FAILURE() << "non-uniform knots accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("uniform"), std::string::npos) << e.what();
  }
  std::vector<Pose> three = jittered(0);
  three.resize(3);
  EXPECT_THROW(bspline::Spline{three}, std::invalid_argument);
  std::vector<Pose> backwards = jittered(0);
  std::swap(backwards[4], backwards[5]);
  EXPECT_THROW(bspline::Spline{backwards}, interp::InterpolationError);
}

// Output range is restricted to [t_1, t_{n-2}] on the usual output grid.
TEST(BSpline, OutputCoversTheSplineRangeOnly) {
  const reference::Circle circle(300.0, 30.0, 1'000'000'000'000, 20 * kNsPerSecond);
  const std::vector<Pose> knots = reference::sample_knots(circle, kKnotPeriod_ns);
  const BatchResult out = bspline::run(knots, SceneModel{}, 400);
  const std::vector<TimeNs> grid = output_grid(knots[1].t_ns, knots[knots.size() - 2].t_ns, 400);
  ASSERT_EQ(out.imu.size(), grid.size());
  ASSERT_EQ(out.trajectory.size(), grid.size());
  for (std::size_t i = 0; i < grid.size(); ++i) {
    EXPECT_EQ(out.imu[i].t_ns, grid[i]);
    EXPECT_EQ(out.trajectory[i].t_ns, grid[i]);
  }
  EXPECT_EQ(out.imu.front().t_ns, knots[1].t_ns);
  EXPECT_EQ(out.imu.back().t_ns, knots[knots.size() - 2].t_ns);
  const bspline::Spline spline(knots);
  Kinematics k;
  EXPECT_THROW(spline.evaluate(knots[1].t_ns - 1, k), std::out_of_range);
  EXPECT_THROW(spline.evaluate(knots[knots.size() - 2].t_ns + 1, k), std::out_of_range);
  EXPECT_NO_THROW(spline.evaluate(knots[knots.size() - 2].t_ns, k));
}
