// Naive baseline (core/naive_spline.hpp): natural cubic splines on position
// and on heading-pitch-roll, against independent truth: the closed-form
// reference motions through Eq. 3.70 at the same output times, the defining
// properties of a natural cubic spline (interpolation, C2, zero second
// derivative at the ends), exact reproduction of motions whose Euler angles
// are linear in time, and finite differences of the baseline's own outputs.
// Also documents its failure at pitch near +-90 deg, where the B-spline
// (core/bspline.hpp) is unaffected.
#include "tests/support/sanitizer.hpp"
#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <numbers>
#include <string>
#include <vector>

#include "core/attitude.hpp"
#include "core/bspline.hpp"
#include "core/interpolation.hpp"
#include "core/naive_spline.hpp"
#include "core/reference_motion.hpp"
#include "core/so3.hpp"
#include "tests/support/imu_errors.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_core_test_naive_spline {
namespace imuemu { using namespace ::imuemu; }

using namespace imuemu;

namespace {

#if IMUEMU_UNDER_ASAN
constexpr TimeNs kDuration_ns = 120 * kNsPerSecond;
#else
constexpr TimeNs kDuration_ns = 600 * kNsPerSecond;  // 10-minute runs
#endif
constexpr TimeNs kKnotPeriod_ns = kNsPerSecond;  // knots at 1 Hz
// The natural end conditions (zero second derivative) bias the ends: the
// acceleration error is ~3-5 m/s^2 at the first/last knot of the flight and
// circle and decays by about 2 - sqrt(3) = 0.27 per knot. Samples within
// kEdge_ns of the first or last knot are reported separately.
constexpr TimeNs kEdge_ns = 10 * kNsPerSecond;

using Stats = test_support::ImuErrorStats;

// Runs `method` on 1 Hz knots of `motion` and compares every output sample
// with truth_imu of the motion at the same t_ns; samples within kEdge_ns of the
// first or last knot go to the end maxima.
template <typename Method>
Stats measure(const Method& method, const reference::Motion& motion, std::int64_t rate_hz) {
  SceneModel scene;
  scene.physics = motion.physics();
  const std::vector<Pose> knots = reference::sample_knots(motion, kKnotPeriod_ns);
  const auto t0 = std::chrono::steady_clock::now();
  const BatchResult out = method(knots, scene, rate_hz);
  const auto t1 = std::chrono::steady_clock::now();
  Stats s = test_support::imu_errors_against_truth(out, motion, scene, knots.front().t_ns + kEdge_ns,
                                              knots.back().t_ns - kEdge_ns);
  s.ns_per_sample = static_cast<double>(std::chrono::duration_cast<std::chrono::nanoseconds>(t1 - t0).count()) /
                    static_cast<double>(out.imu.size());
  return s;
}

void print_row(const std::string& method, const std::string& scene, std::int64_t rate_hz, const Stats& s) {
  char line[320];
  std::snprintf(line, sizeof line,
                "| %-7s | %-18s | %4lld Hz | %.2e | %.2e | %.2e | %.2e | %.2e / %.2e | %4.0f |\n", method.c_str(),
                scene.c_str(), static_cast<long long>(rate_hz), s.gyro_rms_rad_s, s.gyro_max_rad_s, s.accel_rms_m_s2,
                s.accel_max_m_s2, s.end_gyro_max_rad_s, s.end_accel_max_m_s2, s.ns_per_sample);
  std::cout << line;
  const std::string key = method + "_" + scene + "_" + std::to_string(rate_hz);
  ::testing::Test::RecordProperty(key + "_gyro_max", std::to_string(s.gyro_max_rad_s));
  ::testing::Test::RecordProperty(key + "_accel_max", std::to_string(s.accel_max_m_s2));
}

using Bounds = test_support::ErrorBounds;
using test_support::central_difference;
using test_support::expect_within;

Mat3 R_xyz(double x, double y, double z) { return so3::exp(Vec3(x, y, z)); }


TimeNs step_ns(double s) { return static_cast<TimeNs>(std::llround(s * 1e9)); }

}  // namespace

// The comparison table (method x rate x scene). Bounds: the Release
// measurement (10 minutes) times ~3.
TEST(NaiveSpline, AccuracyAgainstReferenceMotions) {
  std::cout << "| method | scene | rate | gyro RMS (rad/s) | gyro max (rad/s) | accel RMS (m/s^2) | "
               "accel max (m/s^2) | first/last 10 s max gyro / accel | ns/sample |\n";
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
  const auto naive_run = [](const std::vector<Pose>& k, const SceneModel& s, std::int64_t r) {
    return naive::run(k, s, r);
  };
  for (const std::int64_t rate : {100, 400}) {
    const Stats ff = measure(naive_run, flight_flat, rate);
    print_row("naive", "aircraft flat", rate, ff);
    const Stats fe = measure(naive_run, flight_ecef, rate);
    print_row("naive", "aircraft ecef", rate, fe);
    const Stats c = measure(naive_run, circle, rate);
    print_row("naive", "circle r=500 v=50", rate, c);
    const Stats cr = measure(naive_run, spin, rate);
    print_row("naive", "constant rate", rate, cr);
    const Stats sf = measure(naive_run, still_flat, rate);
    print_row("naive", "static flat", rate, sf);
    const Stats se = measure(naive_run, still_ecef, rate);
    print_row("naive", "static ecef", rate, se);

    const std::string r = " at " + std::to_string(rate) + " Hz";
    // Measured (Release, 10 min, both rates, outside the end regions): flight
    // gyro RMS 4.2e-6 max 9.8e-6 rad/s, accel RMS 4.7e-3 max 1.1e-2 m/s^2
    // (flat and ecef agree; the truth's attitude is itself built from smooth
    // Euler angles, which suits this baseline); circle gyro 9e-15 (heading
    // linear in time), accel RMS 1.9e-3 max 4.2e-3.
    expect_within(ff, {1.3e-5, 3e-5, 1.4e-2, 3.3e-2}, "aircraft flat" + r);
    expect_within(fe, {1.3e-5, 3e-5, 1.4e-2, 3.3e-2}, "aircraft ecef" + r);
    expect_within(c, {1e-12, 1e-12, 6e-3, 1.3e-2}, "circle" + r);
    // The generic constant-rate tumble passes through pitch +-90 deg every few
    // tens of seconds: gimbal lock (measured gyro RMS 0.125 max 0.53 rad/s,
    // accel RMS 0.37 max 1.6 m/s^2; the B-spline reproduces it exactly).
    expect_within(cr, {0.4, 1.6, 1.1, 4.7}, "constant rate" + r);
    EXPECT_GT(cr.gyro_rms_rad_s, 0.02) << "the gimbal-lock failure disappeared?";
    expect_within(sf, {1e-9, 1e-9, 1e-9, 1e-9}, "static flat" + r);
    expect_within(se, {1e-9, 1e-9, 1e-9, 1e-9}, "static ecef" + r);
  }
}

// The defining properties of the natural cubic spline (which determine it
// uniquely): it interpolates the knots, value, first and second derivative
// are continuous at interior knots, the second derivative vanishes at both
// ends. Non-uniform knot times, ECEF-sized values.
TEST(NaiveSpline, NaturalCubicSplineProperties) {
  const std::vector<TimeNs> t = {1'000'000'000'000, 1'000'700'000'000, 1'001'900'000'000, 1'002'300'000'000,
                                 1'003'300'000'001, 1'005'000'000'000};
  std::vector<Vec3> y;
  for (std::size_t k = 0; k < t.size(); ++k) {
    const double s = static_cast<double>(k);
    y.push_back(Vec3(4.8e6 + 100.0 * std::sin(s), -3.0 * s * s, 2.0 + std::cos(3.0 * s)));
  }
  const naive::NaturalCubicSpline spline(t, y);
  ASSERT_EQ(spline.segment_count(), t.size() - 1);
  double value_err = 0.0, jump_v = 0.0, jump_d = 0.0, jump_dd = 0.0;
  for (std::size_t k = 0; k + 1 < t.size(); ++k) {
    Vec3 a, da, dda, b, db, ddb;
    spline.evaluate(k, t[k], a, da, dda);
    spline.evaluate(k, t[k + 1], b, db, ddb);  // right end of segment k
    value_err = std::max({value_err, (a - y[k]).norm(), (b - y[k + 1]).norm()});
    if (k == 0) {
      EXPECT_LT(dda.norm(), 1e-12) << "natural start";
    }
    if (k + 2 == t.size()) {
      EXPECT_LT(ddb.norm(), 1e-9) << "natural end";
    }
    if (k + 2 < t.size()) {
      Vec3 c, dc, ddc;
      spline.evaluate(k + 1, t[k + 1], c, dc, ddc);
      jump_v = std::max(jump_v, (b - c).norm());
      jump_d = std::max(jump_d, (db - dc).norm());
      jump_dd = std::max(jump_dd, (ddb - ddc).norm());
    }
    EXPECT_EQ(spline.segment_of(t[k]), k);
    EXPECT_EQ(spline.segment_of(t[k + 1] - 1), k);
  }
  std::cout << "natural spline: knot values " << value_err << ", jumps of value/first/second derivative " << jump_v
            << " / " << jump_d << " / " << jump_dd << "\n";
  EXPECT_LT(value_err, 3e-9);  // ulp of 4.8e6 is 9.3e-10
  EXPECT_LT(jump_v, 3e-9);
  EXPECT_LT(jump_d, 1e-9);
  EXPECT_LT(jump_dd, 1e-9);
  // Linear data is reproduced exactly (its natural spline is the line).
  std::vector<Vec3> line;
  for (const TimeNs tk : t) line.push_back(Vec3(1.0, -2.0, 0.5) * seconds_between(t[0], tk) + Vec3(7.0, 8.0, 9.0));
  const naive::NaturalCubicSpline straight(t, line);
  for (TimeNs tt = t[0]; tt <= t.back(); tt += 12'345'678) {
    Vec3 v, dv, ddv;
    straight.evaluate(straight.segment_of(tt), tt, v, dv, ddv);
    EXPECT_LT((dv - Vec3(1.0, -2.0, 0.5)).norm(), 1e-13);
    EXPECT_LT(ddv.norm(), 1e-13);
  }
  EXPECT_THROW(naive::NaturalCubicSpline({t[0]}, {y[0]}), std::invalid_argument);
}

// Static trajectories reproduce gravity and Earth rate.
TEST(NaiveSpline, StaticReproducesGravityAndEarthRate) {
  for (const Physics physics : {Physics::flat, Physics::ecef}) {
    const reference::Static still(earth::Geodetic{-0.6, 2.5, 350.0}, {2.0, -0.3, 0.8}, physics, 0,
                                  20 * kNsPerSecond);
    SceneModel scene;
    scene.physics = physics;
    const BatchResult out = naive::run(reference::sample_knots(still, kKnotPeriod_ns), scene, 400);
    double gyro_err = 0.0, accel_err = 0.0;
    for (const ImuSample& s : out.imu) {
      const ImuSample truth = reference::truth_imu(still, scene, s.t_ns);
      gyro_err = std::max(gyro_err, (s.gyro_rad_s - truth.gyro_rad_s).norm());
      accel_err = std::max(accel_err, (s.accel_m_s2 - truth.accel_m_s2).norm());
    }
    std::cout << "static " << (physics == Physics::ecef ? "ecef" : "flat") << ": gyro err " << gyro_err
              << " rad/s, accel err " << accel_err << " m/s^2\n";
    EXPECT_LT(gyro_err, 1e-9);
    EXPECT_LT(accel_err, 1e-9);
  }
}

// Motions whose Euler angles are linear in time (a level circle: heading
// ramps through +-pi many times; a pure roll spin: roll ramps through +-pi)
// are reproduced exactly once heading and roll are unwrapped.
TEST(NaiveSpline, UnwrapsHeadingAndRoll) {
  const reference::Circle circle(200.0, 60.0, 0, 60 * kNsPerSecond);  // 0.3 rad/s heading rate
  const reference::ConstantRate roll(attitude::rotation_from_hpr({0.7, 0.0, 0.0}), Vec3(2.5, 0.0, 0.0), 0,
                                     60 * kNsPerSecond);  // 2.5 rad per knot interval
  for (const reference::Motion* m : {static_cast<const reference::Motion*>(&circle),
                                     static_cast<const reference::Motion*>(&roll)}) {
    const BatchResult out = naive::run(reference::sample_knots(*m, kKnotPeriod_ns), SceneModel{}, 100);
    double gyro_err = 0.0;
    for (const ImuSample& s : out.imu)
      gyro_err = std::max(gyro_err, (s.gyro_rad_s - reference::truth_imu(*m, SceneModel{}, s.t_ns).gyro_rad_s).norm());
    std::cout << (m == &circle ? "circle" : "roll spin") << ": gyro max err " << gyro_err << " rad/s\n";
    EXPECT_LT(gyro_err, 1e-12);
  }
}

// The analytic derivatives are the derivatives of the baseline's own
// outputs: body rate (plus transport rate in ecef) vs a 4th-order central
// difference of log(R(t)^T R(t+s)); velocity and acceleration vs differences
// of position and velocity inside one knot interval (cubic: exact).
TEST(NaiveSpline, DerivativesMatchFiniteDifferencesOfItsOwnOutput) {
  for (const Physics physics : {Physics::flat, Physics::ecef}) {
    const reference::AircraftFlight flight(physics, reference::AircraftFlight::default_origin(), 0,
                                           40 * kNsPerSecond);
    const std::vector<Pose> knots = reference::sample_knots(flight, kKnotPeriod_ns);
    const naive::Spline spline(knots, physics);
    auto eval = [&](TimeNs t) {
      Kinematics k;
      spline.evaluate(t, k);
      return k;
    };
    double w_err = 0.0, v_err = 0.0, a_err = 0.0, w_max = 0.0;
    for (TimeNs t = spline.start_ns() + 10'000'000; t < spline.end_ns() - 10'000'000; t += 123'456'789) {
      const Kinematics k = eval(t);
      const Mat3 Rt = k.attitude.transpose();
      const Vec3 w_fd = central_difference([&](double s) { return Vec3(so3::log(Rt * eval(t + step_ns(s)).attitude)); }, 1e-3);
      w_err = std::max(w_err, (w_fd - k.angular_rate_rad_s).norm());
      w_max = std::max(w_max, k.angular_rate_rad_s.norm());
      const TimeNs into = (t - knots[0].t_ns) % kKnotPeriod_ns;
      if (into > 100'000'000 && into < 900'000'000) {
        const Vec3 v_fd = central_difference([&](double s) { return Vec3(eval(t + step_ns(s)).position_m - k.position_m); }, 0.05);
        const Vec3 a_fd = central_difference([&](double s) { return Vec3(eval(t + step_ns(s)).velocity_m_s); }, 0.05);
        v_err = std::max(v_err, (v_fd - k.velocity_m_s).norm());
        a_err = std::max(a_err, (a_fd - k.acceleration_m_s2).norm());
      }
    }
    std::cout << "naive self-consistency " << (physics == Physics::ecef ? "ecef" : "flat")
              << ": body rate vs FD of attitude " << w_err << " rad/s (|w| <= " << w_max << "), velocity vs FD "
              << v_err << " m/s, accel vs FD " << a_err << " m/s^2\n";
    // Measured 2.8e-13 (ecef), 1.5e-8 (the 9e-10 m ulp of ECEF positions over
    // the 0.05 s step), 3.9e-13.
    EXPECT_LT(w_err, 1e-11);
    EXPECT_LT(v_err, 1e-7);
    EXPECT_LT(a_err, 1e-10);
    EXPECT_GT(w_max, 1e-3);
  }
}

// Non-uniform knot times are fine for the baseline; the output covers the
// whole knot span on the usual output grid.
TEST(NaiveSpline, AcceptsNonUniformKnotsAndCoversTheKnotSpan) {
  const reference::AircraftFlight flight(Physics::flat, reference::AircraftFlight::default_origin(), 0,
                                         60 * kNsPerSecond);
  std::vector<Pose> knots;
  for (TimeNs t = 0; t <= 60 * kNsPerSecond; t += (t / kNsPerSecond % 2 == 0 ? 700'000'000 : 1'300'000'000)) {
    const Kinematics k = flight.at(t);
    knots.push_back(Pose{t, k.position_m, k.attitude});
  }
  const BatchResult out = naive::run(knots, SceneModel{}, 100);
  const std::vector<TimeNs> grid = output_grid(knots.front().t_ns, knots.back().t_ns, 100);
  ASSERT_EQ(out.imu.size(), grid.size());
  for (std::size_t i = 0; i < grid.size(); ++i) ASSERT_EQ(out.imu[i].t_ns, grid[i]);
  double gyro_max = 0.0, accel_max = 0.0;
  for (const ImuSample& s : out.imu) {
    if (s.t_ns < knots.front().t_ns + kEdge_ns || s.t_ns > knots.back().t_ns - kEdge_ns) continue;
    const ImuSample t = reference::truth_imu(flight, SceneModel{}, s.t_ns);
    gyro_max = std::max(gyro_max, (s.gyro_rad_s - t.gyro_rad_s).norm());
    accel_max = std::max(accel_max, (s.accel_m_s2 - t.accel_m_s2).norm());
  }
  std::cout << "naive, knots every 0.7/1.3 s: gyro max " << gyro_max << " rad/s, accel max " << accel_max
            << " m/s^2\n";
  EXPECT_LT(gyro_max, 1e-4);   // measured 3.3e-5
  EXPECT_LT(accel_max, 4e-2);  // measured 1.4e-2
  const naive::Spline spline(knots, Physics::flat);
  Kinematics k;
  EXPECT_THROW(spline.evaluate(knots.back().t_ns + 1, k), std::out_of_range);
  std::vector<Pose> backwards = knots;
  std::swap(backwards[3], backwards[4]);
  EXPECT_THROW(naive::run(backwards, SceneModel{}, 100), interp::InterpolationError);
}

// The known weakness: near pitch +-90 deg heading and roll are ill defined and
// swing by up to pi between knots, so the Euler-angle splines (and their
// rates) are wrong; the Lie-group B-spline does not care. Body rate about the
// (rolled) pitch axis: the nose climbs to 90 - roll0 deg and over.
TEST(NaiveSpline, FailsNearPitch90WhereTheBSplineDoesNot) {
  for (const double roll0_deg : {30.0, 5.0, 0.5, 0.0}) {
    const double roll0 = roll0_deg * std::numbers::pi / 180.0;
    // A loop every 31.4 s: pitch +-90 deg (less roll0) at 7.9, 23.6, 39.3 and
    // 55.0 s, the middle two outside the end regions.
    const reference::ConstantRate loop(attitude::rotation_from_hpr({0.3, 0.0, roll0}), Vec3(0.0, 0.2, 0.0), 0,
                                       60 * kNsPerSecond);
    const std::vector<Pose> knots = reference::sample_knots(loop, kKnotPeriod_ns);
    double peak_pitch = -10.0;
    for (const Pose& p : knots) peak_pitch = std::max(peak_pitch, attitude::hpr_from_rotation(p.attitude).pitch_rad);
    const BatchResult naive_out = naive::run(knots, SceneModel{}, 100);
    const BatchResult bspline_out = bspline::run(knots, SceneModel{}, 100);
    auto worst = [&](const BatchResult& out) {
      double g = 0.0;
      for (const ImuSample& s : out.imu) {
        if (s.t_ns < knots.front().t_ns + kEdge_ns || s.t_ns > knots.back().t_ns - kEdge_ns) continue;
        g = std::max(g, (s.gyro_rad_s - reference::truth_imu(loop, SceneModel{}, s.t_ns).gyro_rad_s).norm());
      }
      return g;
    };
    const double naive_err = worst(naive_out), bspline_err = worst(bspline_out);
    std::cout << "loop at 0.2 rad/s, roll " << roll0_deg << " deg (peak knot pitch "
              << peak_pitch * 180.0 / std::numbers::pi << " deg): gyro max err naive " << naive_err
              << " rad/s, B-spline " << bspline_err << " rad/s\n";
    EXPECT_LT(bspline_err, 1e-12);
    if (roll0_deg <= 5.0) {
      EXPECT_GT(naive_err, 0.02);  // > 10% of the 0.2 rad/s rate (measured 0.08 .. 7.4)
    } else {
      EXPECT_LT(naive_err, 2e-3);  // away from vertical it is fine (measured 6.3e-4)
    }
  }
}
}  // namespace unity_core_test_naive_spline
