// Cumulative cubic B-spline on SO(3) x R^3 (core/bspline.hpp) against
// independent truth: the closed-form reference motions (core/reference_motion)
// through Eq. 3.70 at the same output times, the exact reproduction of
// one-parameter subgroups R0 exp(t w) and straight lines that the cumulative
// basis with control points at the Greville abscissae guarantees (also on
// jittered knots), the classical B-spline value at a knot
// (p_{k-1} + 4 p_k + p_{k+1}) / 6, the previous uniform-only formulas (kept here
// as a reference implementation), a textbook Cox-de Boor evaluation of the
// non-uniform spline in long double, and finite differences of the spline's
// own attitude/position (its analytic derivatives must be their derivatives).
#include "tests/support/sanitizer.hpp"
#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <iostream>
#include <random>
#include <string>
#include <vector>

#include "core/bspline.hpp"
#include "core/interpolation.hpp"
#include "core/reference_motion.hpp"
#include "core/so3.hpp"
#include "tests/support/imu_errors.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_core_test_bspline {
namespace imuemu { using namespace ::imuemu; }

using namespace imuemu;

namespace {

#if IMUEMU_UNDER_ASAN
constexpr TimeNs kDuration_ns = 120 * kNsPerSecond;
#else
constexpr TimeNs kDuration_ns = 600 * kNsPerSecond;  // 10-minute runs
#endif
constexpr TimeNs kKnotPeriod_ns = kNsPerSecond;  // knots at 1 Hz

using Stats = test_support::ImuErrorStats;

// Runs the B-spline on the knots (measure: 1 Hz knots) of `motion` and
// compares every output sample with truth_imu of the motion at the same t_ns.
Stats measure_on(const reference::Motion& motion, const std::vector<Pose>& knots, std::int64_t rate_hz,
                 BatchResult* keep = nullptr) {
  SceneModel scene;
  scene.physics = motion.physics();
  const auto t0 = std::chrono::steady_clock::now();
  BatchResult out = bspline::run(knots, scene, rate_hz);
  const auto t1 = std::chrono::steady_clock::now();
  Stats s = test_support::imu_errors_against_truth(out, motion, scene, out.imu.front().t_ns, out.imu.back().t_ns);
  s.ns_per_sample = static_cast<double>(std::chrono::duration_cast<std::chrono::nanoseconds>(t1 - t0).count()) /
                    static_cast<double>(s.samples);
  if (keep != nullptr) *keep = std::move(out);
  return s;
}

Stats measure(const reference::Motion& motion, std::int64_t rate_hz, BatchResult* keep = nullptr) {
  return measure_on(motion, reference::sample_knots(motion, kKnotPeriod_ns), rate_hz, keep);
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

// Knot times start_ns, then intervals period_ns (1 + relative_jitter U(-1, 1))
// rounded to ns, from a fixed-seed generator (reproducible); `gap_at` (if
// below count) makes that one interval gap_factor times the period instead.
std::vector<TimeNs> jittered_times(TimeNs start_ns, TimeNs period_ns, double relative_jitter, std::size_t count,
                                   std::uint64_t seed, std::size_t gap_at = SIZE_MAX, double gap_factor = 1.0) {
  std::mt19937_64 generator(seed);
  std::vector<TimeNs> times;
  TimeNs t = start_ns;
  for (std::size_t k = 0; k < count; ++k) {
    times.push_back(t);
    const double uniform01 = static_cast<double>(generator() >> 11) * 0x1p-53;
    const double factor = k == gap_at ? gap_factor : 1.0 + relative_jitter * (2.0 * uniform01 - 1.0);
    t += static_cast<TimeNs>(std::llround(static_cast<double>(period_ns) * factor));
  }
  return times;
}

std::vector<Pose> knots_at(const reference::Motion& motion, const std::vector<TimeNs>& times) {
  std::vector<Pose> knots;
  for (const TimeNs t : times) {
    const Kinematics k = motion.at(t);
    knots.push_back(Pose{t, k.position_m, k.attitude});
  }
  return knots;
}

// The segment evaluate() uses for t: the last knot at or before t among
// t_1..t_{n-2}, minus one, at most the last segment.
std::size_t segment_of(const std::vector<Pose>& knots, TimeNs t_ns) {
  std::size_t knot = 1;
  while (knot + 2 < knots.size() && knots[knot + 1].t_ns <= t_ns) ++knot;
  return std::min(knot - 1, knots.size() - 4);
}

// The UNIFORM cumulative cubic B-spline exactly as it was implemented before
// non-uniform knots were supported (u-domain basis, Sommer's recursion in u
// units, one division by the segment duration at the end), written here with
// matrices and so3::exp/log: the reference the general implementation must
// reduce to at uniform spacing. The acceleration and angular acceleration are
// sums of terms of size |v| / dt that cancel down to |a| (by a factor
// |v| / (|a| dt), about 7e3 at 100 Hz knots), so their rounding is relative to
// the terms: their magnitudes are returned in *_term_scale.
void uniform_reference(const std::vector<Pose>& knots, std::size_t i, TimeNs t_ns, Kinematics& out, Vec3& alpha,
                       double& accel_term_scale, double& alpha_term_scale) {
  const TimeNs t0_ns = knots[i + 1].t_ns;
  const TimeNs dt_ns = knots[i + 2].t_ns - t0_ns;
  const double u = static_cast<double>(t_ns - t0_ns) / static_cast<double>(dt_ns);
  const double dt_s = static_cast<double>(dt_ns) * 1e-9;
  const double u2 = u * u, u3 = u2 * u, v = 1.0 - u;
  const double b[3] = {(5.0 + 3.0 * u - 3.0 * u2 + u3) / 6.0, (1.0 + 3.0 * u + 3.0 * u2 - 2.0 * u3) / 6.0, u3 / 6.0};
  const double db[3] = {0.5 * v * v, 0.5 + u - u2, 0.5 * u2};
  const double ddb[3] = {-v, 1.0 - 2.0 * u, u};
  Vec3 dp[3], d[3];
  Mat3 A[3];
  for (std::size_t j = 0; j < 3; ++j) {
    dp[j] = knots[i + j + 1].position_m - knots[i + j].position_m;
    d[j] = so3::log(knots[i + j].attitude.transpose() * knots[i + j + 1].attitude);
    A[j] = so3::exp(b[j] * d[j]);
  }
  out.t_ns = t_ns;
  out.position_m = knots[i].position_m + (b[0] * dp[0] + b[1] * dp[1] + b[2] * dp[2]);
  out.velocity_m_s = (db[0] * dp[0] + db[1] * dp[1] + db[2] * dp[2]) / dt_s;
  out.acceleration_m_s2 = (ddb[0] * dp[0] + ddb[1] * dp[1] + ddb[2] * dp[2]) / (dt_s * dt_s);
  out.attitude = knots[i].attitude * A[0] * A[1] * A[2];
  Vec3 w = db[0] * d[0], al = ddb[0] * d[0];
  for (std::size_t j = 1; j < 3; ++j) {
    const Vec3 w_in = A[j].transpose() * w;
    al = A[j].transpose() * al + ddb[j] * d[j] + w_in.cross(db[j] * d[j]);
    w = w_in + db[j] * d[j];
  }
  out.angular_rate_rad_s = w / dt_s;
  alpha = al / (dt_s * dt_s);
  accel_term_scale = alpha_term_scale = 0.0;
  for (std::size_t j = 0; j < 3; ++j) {
    accel_term_scale += std::fabs(ddb[j]) * dp[j].norm() / (dt_s * dt_s);
    alpha_term_scale += std::fabs(ddb[j]) * d[j].norm() / (dt_s * dt_s);
  }
}

// The non-uniform cubic B-spline of the positions straight from the textbook,
// in long double: knot vector tau_j = t_{j-2} (t_{-2}, t_{-1}, t_n, t_{n+1}
// repeating the end intervals); control point k = the blossom (polar form) of
// the cubic through four knots (k-1..k+2, the first / last four at the ends)
// at (tau_{k+1}, tau_{k+2}, tau_{k+3}) plus (H^2 / 6) times its second
// derivative at the Greville abscissa (H the median interval; the header's
// shift), the cubic in monomial form from its divided differences and
// blossomed term by term (1 -> 1, s -> mean, s^2 -> mean of the pairwise
// products, s^3 -> product); N_{k,p} by the recursive Cox-de Boor
// formula and its derivatives by N'_{k,p} = p (N_{k,p-1} / (tau_{k+p} - tau_k)
// - N_{k+1,p-1} / (tau_{k+p+1} - tau_{k+1})). Nothing shared with core/.
class TextbookSpline {
 public:
  explicit TextbookSpline(const std::vector<Pose>& knots) : t0_ns_(knots[0].t_ns) {
    const std::size_t n = knots.size();
    std::vector<long double> t(n);
    for (std::size_t k = 0; k < n; ++k) t[k] = seconds(knots[k].t_ns);
    const long double first = t[1] - t[0], last = t[n - 1] - t[n - 2];
    tau_ = {t[0] - 2 * first, t[0] - first};
    tau_.insert(tau_.end(), t.begin(), t.end());
    tau_.push_back(t[n - 1] + last);
    tau_.push_back(t[n - 1] + 2 * last);
    std::vector<long double> intervals;
    for (std::size_t k = 0; k + 1 < n; ++k) intervals.push_back(t[k + 1] - t[k]);
    std::sort(intervals.begin(), intervals.end());
    const long double median = intervals[(intervals.size() - 1) / 2];
    for (std::size_t k = 0; k < n; ++k) {
      const std::size_t m = k == 0 ? 0 : std::min(k - 1, n - 4);  // cubic through m..m+3
      const long double x = tau_[k + 1] - t[k], y = tau_[k + 2] - t[k], z = tau_[k + 3] - t[k];
      const long double xi = (x + y + z) / 3;
      const long double s0 = t[m] - t[k], s1 = t[m + 1] - t[k], s2 = t[m + 2] - t[k], s3 = t[m + 3] - t[k];
      std::array<long double, 3> c{};
      for (std::size_t j = 0; j < 3; ++j) {
        const auto f = [&](std::size_t i) {
          return static_cast<long double>(knots[i].position_m[static_cast<int>(j)]);
        };
        // Newton form f0 + f01 (s-s0) + f012 (s-s0)(s-s1) + f0123 (s-s0)(s-s1)(s-s2) -> monomials.
        const long double f01 = (f(m + 1) - f(m)) / (s1 - s0), f12 = (f(m + 2) - f(m + 1)) / (s2 - s1),
                          f23 = (f(m + 3) - f(m + 2)) / (s3 - s2);
        const long double f012 = (f12 - f01) / (s2 - s0), f123 = (f23 - f12) / (s3 - s1);
        const long double f0123 = (f123 - f012) / (s3 - s0);
        const long double q3 = f0123;
        const long double q2 = f012 - f0123 * (s0 + s1 + s2);
        const long double q1 = f01 - f012 * (s0 + s1) + f0123 * (s0 * s1 + s1 * s2 + s0 * s2);
        const long double q0 = f(m) - f01 * s0 + f012 * s0 * s1 - f0123 * s0 * s1 * s2;
        const long double blossom = q0 + q1 * (x + y + z) / 3 + q2 * (x * y + y * z + x * z) / 3 + q3 * x * y * z;
        c[j] = blossom + median * median / 6 * (2 * q2 + 6 * q3 * xi);
      }
      control_.push_back(c);
    }
  }
  // Derivative `order` (0, 1, 2) of the spline's position at t_ns, component j.
  long double at(TimeNs t_ns, int order, int j) const {
    const long double t = seconds(t_ns);
    long double sum = 0;
    for (std::size_t k = 0; k < control_.size(); ++k)
      sum += control_[k][static_cast<std::size_t>(j)] * basis(k, 3, order, t);
    return sum;
  }

 private:
  long double seconds(TimeNs t_ns) const { return static_cast<long double>(t_ns - t0_ns_) / 1e9L; }
  long double basis(std::size_t k, int p, int order, long double t) const {
    const std::size_t q = static_cast<std::size_t>(p);
    if (p == 0) return order == 0 && tau_[k] <= t && t < tau_[k + 1] ? 1.0L : 0.0L;
    const long double left = tau_[k + q] - tau_[k], right = tau_[k + q + 1] - tau_[k + 1];
    if (order > 0) {
      return p * (basis(k, p - 1, order - 1, t) / left - basis(k + 1, p - 1, order - 1, t) / right);
    }
    return (t - tau_[k]) / left * basis(k, p - 1, 0, t) + (tau_[k + q + 1] - t) / right * basis(k + 1, p - 1, 0, t);
  }
  TimeNs t0_ns_;
  std::vector<long double> tau_;
  std::vector<std::array<long double, 3>> control_;
};

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

// Static trajectories: every d_j and position difference is exactly zero (so
// are the control-point offsets on jittered knots), so the IMU is exactly
// gravity and Earth rate, and the ECEF acceleration is an exact zero (no
// 6.4e6 m numbers cancel anywhere).
TEST(BSpline, StaticReproducesGravityAndEarthRate) {
  for (const Physics physics : {Physics::flat, Physics::ecef}) {
    for (const bool jittered : {false, true}) {  // uniform 1 Hz, and +-30 % intervals with a gap
      const reference::Static still(earth::Geodetic{-0.6, 2.5, 350.0}, {2.0, -0.3, 0.8}, physics, 0,
                                    20 * kNsPerSecond);
      SceneModel scene;
      scene.physics = physics;
      const std::vector<Pose> knots = jittered
                                          ? knots_at(still, jittered_times(0, kNsPerSecond, 0.3, 20, 29, 8, 4.0))
                                          : reference::sample_knots(still, kKnotPeriod_ns);
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
      std::cout << "static " << (physics == Physics::ecef ? "ecef" : "flat") << (jittered ? ", jittered knots" : "")
                << ": gyro err " << gyro_err << " rad/s, accel err " << accel_err << " m/s^2\n";
      EXPECT_LT(gyro_err, 1e-9);
      EXPECT_LT(accel_err, 1e-9);
    }
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

// Any increasing knot times are accepted: the few-ns jitter the uniform-only
// version tolerated, microseconds, and +-30 % with a gap; fewer than 4 knots
// and non-increasing times are refused with the documented exceptions.
TEST(BSpline, AcceptsAnyIncreasingKnotsAndRefusesInvalidOnes) {
  const reference::AircraftFlight flight(Physics::flat, reference::AircraftFlight::default_origin(), 0,
                                         60 * kNsPerSecond);
  SceneModel scene;
  auto jittered = [&](TimeNs amplitude_ns) {
    std::vector<TimeNs> times;
    for (TimeNs k = 0; k <= 60; ++k) times.push_back(k * kNsPerSecond + (k % 3 - 1) * amplitude_ns);  // -a, 0, +a
    return knots_at(flight, times);
  };
  for (const TimeNs amplitude_ns : {TimeNs{450}, TimeNs{1500}, TimeNs{200'000'000}}) {
    const BatchResult out = bspline::run(jittered(amplitude_ns), scene, 100);
    double gyro_max = 0.0, accel_max = 0.0;
    for (const ImuSample& s : out.imu) {
      const ImuSample t = reference::truth_imu(flight, scene, s.t_ns);
      gyro_max = std::max(gyro_max, (s.gyro_rad_s - t.gyro_rad_s).norm());
      accel_max = std::max(accel_max, (s.accel_m_s2 - t.accel_m_s2).norm());
    }
    std::cout << "knots jittered by +-" << amplitude_ns << " ns: gyro max " << gyro_max << " rad/s, accel max "
              << accel_max << " m/s^2\n";
    // The uniform-knot flight bounds of AccuracyAgainstReferenceMotions.
    EXPECT_LT(gyro_max, 2e-3);
    EXPECT_LT(accel_max, 9e-2);
  }
  const std::vector<Pose> wild =
      knots_at(flight, jittered_times(0, kNsPerSecond, 0.3, 50, 7, /*gap_at=*/20, /*gap_factor=*/4.0));
  EXPECT_NO_THROW(bspline::run(wild, scene, 100));
  std::vector<Pose> four(wild.begin() + 18, wild.begin() + 22);  // one segment, both end knots extrapolated
  const bspline::Spline minimal(four);
  Kinematics k;
  minimal.evaluate(four[2].t_ns - 1, k);
  EXPECT_TRUE(k.position_m.allFinite() && k.acceleration_m_s2.allFinite() && k.angular_rate_rad_s.allFinite());

  std::vector<Pose> three = jittered(0);
  three.resize(3);
  EXPECT_THROW(bspline::Spline{three}, std::invalid_argument);
  std::vector<Pose> backwards = jittered(0);
  std::swap(backwards[4], backwards[5]);
  EXPECT_THROW(bspline::Spline{backwards}, interp::InterpolationError);
  std::vector<Pose> repeated = jittered(0);
  repeated[5].t_ns = repeated[4].t_ns;
  EXPECT_THROW(bspline::Spline{repeated}, interp::InterpolationError);
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

// At uniform spacing the general (non-uniform) construction must be the
// previous uniform-only spline: compared with uniform_reference() above at
// 1 Hz, at 100 Hz and at an odd period, flat and ECEF, to <= 1e-13 relative:
// position relative to |p|, velocity and body rate relative to their largest
// magnitude in the run, acceleration and angular acceleration relative to the
// terms they are summed from (see uniform_reference), attitude in rad.
TEST(BSpline, UniformKnotsGiveThePreviousUniformFormulas) {
  struct Case {
    Physics physics;
    TimeNs period_ns;
    TimeNs step_ns;
  };
  for (const Case& c : {Case{Physics::flat, kNsPerSecond, 3'333'333}, Case{Physics::ecef, kNsPerSecond, 3'333'333},
                        Case{Physics::ecef, 10'000'000, 77'777}, Case{Physics::flat, 370'000'001, 1'234'567}}) {
    const reference::AircraftFlight flight(c.physics, reference::AircraftFlight::default_origin(), 1'000'000'000'000,
                                           40 * c.period_ns);
    const std::vector<Pose> knots = reference::sample_knots(flight, c.period_ns);
    const bspline::Spline spline(knots);
    double p_rel = 0.0, att = 0.0, v_rel = 0.0, w_rel = 0.0, a_rel = 0.0, al_rel = 0.0;
    double dv = 0.0, dw = 0.0, v_max = 0.0, w_max = 0.0, a_max = 0.0, al_max = 0.0;
    for (TimeNs t = spline.start_ns(); t <= spline.end_ns(); t += c.step_ns) {
      Kinematics k, r;
      Vec3 alpha, alpha_ref;
      double a_terms = 0.0, al_terms = 0.0;
      spline.evaluate(t, k, &alpha);
      uniform_reference(knots, segment_of(knots, t), t, r, alpha_ref, a_terms, al_terms);
      p_rel = std::max(p_rel, (k.position_m - r.position_m).norm() / r.position_m.norm());
      att = std::max(att, so3::angle(r.attitude.transpose() * k.attitude));
      dv = std::max(dv, (k.velocity_m_s - r.velocity_m_s).norm());
      dw = std::max(dw, (k.angular_rate_rad_s - r.angular_rate_rad_s).norm());
      a_rel = std::max(a_rel, (k.acceleration_m_s2 - r.acceleration_m_s2).norm() / a_terms);
      al_rel = std::max(al_rel, (alpha - alpha_ref).norm() / al_terms);
      v_max = std::max(v_max, r.velocity_m_s.norm());
      w_max = std::max(w_max, r.angular_rate_rad_s.norm());
      a_max = std::max(a_max, r.acceleration_m_s2.norm());
      al_max = std::max(al_max, alpha_ref.norm());
    }
    v_rel = dv / v_max;
    w_rel = dw / w_max;
    std::cout << (c.physics == Physics::ecef ? "ecef" : "flat") << " knots every " << c.period_ns
              << " ns vs the uniform formulas: position " << p_rel << " rel, attitude " << att << " rad, velocity "
              << v_rel << " rel, body rate " << w_rel << " rel, accel " << a_rel << " rel to its terms, angular accel "
              << al_rel << " rel to its terms\n";
    EXPECT_LT(p_rel, 1e-13);
    EXPECT_LT(att, 1e-13);
    EXPECT_LT(v_rel, 1e-13);
    EXPECT_LT(w_rel, 1e-13);
    EXPECT_LT(a_rel, 1e-13);
    EXPECT_LT(al_rel, 1e-13);
    EXPECT_GT(a_max, 1e-3);  // a moving, turning body was compared
    EXPECT_GT(al_max, 1e-6);
  }
}

// On +-30 % jittered knots with a 4x gap and a 0.1x short interval the
// position, velocity and acceleration are the textbook non-uniform B-spline
// (TextbookSpline above, long double) with control points at the Greville
// abscissae: checks the knot-vector convention, the segment basis matrices,
// the control-point placement and the analytic t-derivatives at once.
TEST(BSpline, NonUniformPositionIsTheTextbookBSpline) {
  for (const Physics physics : {Physics::flat, Physics::ecef}) {
    const reference::AircraftFlight flight(physics, reference::AircraftFlight::default_origin(), 0,
                                           60 * kNsPerSecond);
    std::vector<TimeNs> times = jittered_times(5 * kNsPerSecond, kNsPerSecond, 0.3, 45, 11, 17, 4.0);
    for (std::size_t k = 31; k < times.size(); ++k) times[k] -= 900'000'000;  // interval 30 about 0.1 s
    ASSERT_GT(times[31], times[30]);
    const std::vector<Pose> knots = knots_at(flight, times);
    const bspline::Spline spline(knots);
    const TextbookSpline textbook(knots);
    double p_err = 0.0, v_err = 0.0, a_err = 0.0, a_max = 0.0;
    for (TimeNs t = spline.start_ns() + 1; t < spline.end_ns(); t += 12'345'679) {
      Kinematics k;
      spline.evaluate(t, k);
      for (int j = 0; j < 3; ++j) {
        const auto err = [&](double value, int order) {
          return static_cast<double>(std::fabs(static_cast<long double>(value) - textbook.at(t, order, j)));
        };
        p_err = std::max(p_err, err(k.position_m[j], 0));
        v_err = std::max(v_err, err(k.velocity_m_s[j], 1));
        a_err = std::max(a_err, err(k.acceleration_m_s2[j], 2));
      }
      a_max = std::max(a_max, k.acceleration_m_s2.norm());
    }
    std::cout << (physics == Physics::ecef ? "ecef" : "flat") << " jittered knots vs textbook B-spline: position "
              << p_err << " m, velocity " << v_err << " m/s, accel " << a_err << " m/s^2 (|a| <= " << a_max << ")\n";
    // ECEF positions are stored to their 9.3e-10 m ulp.
    EXPECT_LT(p_err, physics == Physics::ecef ? 2e-9 : 1e-10);
    EXPECT_LT(v_err, 1e-11);
    EXPECT_LT(a_err, 1e-11);
    EXPECT_GT(a_max, 0.1);
  }
}

// C2 on jittered knots (+-30 %, a 4x gap): at every join the one-sided limits
// (the two segments' formulas at the join) agree to rounding, and evaluate()
// 1 ns before and after the join differs only by what the derivatives predict
// over 2 ns (the remainder is the jerk times 2 ns, < 1e-8).
TEST(BSpline, JitteredKnotsAreTwiceContinuous) {
  const reference::AircraftFlight flight(Physics::flat, reference::AircraftFlight::default_origin(), 0,
                                         60 * kNsPerSecond);
  const std::vector<Pose> knots = knots_at(flight, jittered_times(0, kNsPerSecond, 0.3, 50, 3, 25, 4.0));
  const bspline::Spline spline(knots);
  double att = 0.0, w = 0.0, alpha = 0.0, p = 0.0, v = 0.0, a = 0.0;
  double att_1ns = 0.0, w_1ns = 0.0, alpha_1ns = 0.0, p_1ns = 0.0, v_1ns = 0.0, a_1ns = 0.0;
  constexpr double kTwoNs_s = 2e-9;
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
    Kinematics before, after;
    Vec3 al_before, al_after;
    spline.evaluate(t - 1, before, &al_before);
    spline.evaluate(t + 1, after, &al_after);
    att_1ns = std::max(att_1ns, (so3::log(before.attitude.transpose() * after.attitude) -
                                 kTwoNs_s * r.angular_rate_rad_s).norm());
    w_1ns = std::max(w_1ns, (after.angular_rate_rad_s - before.angular_rate_rad_s - kTwoNs_s * ar).norm());
    alpha_1ns = std::max(alpha_1ns, (al_after - al_before).norm());
    p_1ns = std::max(p_1ns, (after.position_m - before.position_m - kTwoNs_s * r.velocity_m_s).norm());
    v_1ns = std::max(v_1ns, (after.velocity_m_s - before.velocity_m_s - kTwoNs_s * r.acceleration_m_s2).norm());
    a_1ns = std::max(a_1ns, (after.acceleration_m_s2 - before.acceleration_m_s2).norm());
  }
  std::cout << "jittered knots, jumps at the joins: attitude " << att << " rad, rate " << w << ", angular accel "
            << alpha << ", position " << p << ", velocity " << v << ", accel " << a << "\n"
            << "  +-1 ns around the joins minus the derivative's share: attitude " << att_1ns << ", rate " << w_1ns
            << ", angular accel " << alpha_1ns << ", position " << p_1ns << ", velocity " << v_1ns << ", accel "
            << a_1ns << "\n";
  EXPECT_LT(att, 1e-14);
  EXPECT_LT(w, 1e-14);
  EXPECT_LT(alpha, 1e-13);
  EXPECT_LT(p, 1e-10);
  EXPECT_LT(v, 1e-12);
  EXPECT_LT(a, 1e-12);
  EXPECT_LT(att_1ns, 1e-14);
  EXPECT_LT(w_1ns, 1e-13);
  EXPECT_LT(alpha_1ns, 1e-8);
  EXPECT_LT(p_1ns, 1e-10);
  EXPECT_LT(v_1ns, 1e-12);
  EXPECT_LT(a_1ns, 1e-8);
}

// The analytic derivatives on jittered knots are the derivatives of the
// spline's own outputs (as DerivativesMatchFiniteDifferencesOfItsOwnOutput,
// with the stencils for the C0 quantities kept inside one segment).
TEST(BSpline, JitteredDerivativesMatchFiniteDifferences) {
  const reference::AircraftFlight flight(Physics::ecef, reference::AircraftFlight::default_origin(), 0,
                                         60 * kNsPerSecond);
  const std::vector<Pose> knots = knots_at(flight, jittered_times(0, kNsPerSecond, 0.3, 50, 5, 30, 4.0));
  const bspline::Spline spline(knots);
  auto eval = [&](TimeNs t) {
    Kinematics k;
    spline.evaluate(t, k);
    return k;
  };
  const auto step = [](double s) { return static_cast<TimeNs>(std::llround(s * 1e9)); };
  double w_err = 0.0, w_err_join = 0.0, alpha_err = 0.0, v_err = 0.0, a_err = 0.0, w_max = 0.0, alpha_max = 0.0;
  std::size_t inside = 0, near_join = 0;
  for (TimeNs t = spline.start_ns() + 150'000'000; t < spline.end_ns() - 150'000'000; t += 23'456'789) {
    Kinematics k;
    Vec3 alpha;
    spline.evaluate(t, k, &alpha);
    const Mat3 Rt = k.attitude.transpose();
    const Vec3 w_fd =
        central_difference([&](double h) { return Vec3(so3::log(Rt * eval(t + step(h)).attitude)); }, 1e-3);
    w_max = std::max(w_max, k.angular_rate_rad_s.norm());
    alpha_max = std::max(alpha_max, alpha.norm());
    const std::size_t segment = segment_of(knots, t);
    const TimeNs from_ns = knots[segment + 1].t_ns, to_ns = knots[segment + 2].t_ns;
    // The attitude's third derivative jumps at the joins (C2, not C3), which
    // a +-2 ms stencil straddling one feels as (jump) * (2 ms)^2.
    if (t - 2'000'000 > from_ns && t + 2'000'000 < to_ns) {
      w_err = std::max(w_err, (w_fd - k.angular_rate_rad_s).norm());
    } else {
      w_err_join = std::max(w_err_join, (w_fd - k.angular_rate_rad_s).norm());
      ++near_join;
    }
    if (t - 100'000'000 > from_ns && t + 100'000'000 < to_ns) {
      ++inside;
      const Vec3 alpha_fd =
          central_difference([&](double h) { return Vec3(eval(t + step(h)).angular_rate_rad_s); }, 1e-3);
      alpha_err = std::max(alpha_err, (alpha_fd - alpha).norm());
      const Vec3 v_fd =
          central_difference([&](double h) { return Vec3(eval(t + step(h)).position_m - k.position_m); }, 0.05);
      const Vec3 a_fd = central_difference([&](double h) { return Vec3(eval(t + step(h)).velocity_m_s); }, 0.05);
      v_err = std::max(v_err, (v_fd - k.velocity_m_s).norm());
      a_err = std::max(a_err, (a_fd - k.acceleration_m_s2).norm());
    }
  }
  std::cout << "jittered knots, self-consistency: body rate vs FD of attitude " << w_err << " rad/s (" << w_err_join
            << " at " << near_join << " points within 2 ms of a join; |w| <= " << w_max
            << "), angular accel vs FD of rate " << alpha_err << " rad/s^2 (|alpha| <= " << alpha_max
            << "), velocity vs FD " << v_err << " m/s, accel vs FD " << a_err << " m/s^2, " << inside
            << " in-segment points\n";
  EXPECT_LT(w_err, 1e-11);
  EXPECT_LT(w_err_join, 1e-9);
  EXPECT_LT(alpha_err, 1e-11);
  EXPECT_LT(v_err, 1e-7);  // ECEF position ulp 9.3e-10 m over the 0.05 s step
  EXPECT_LT(a_err, 1e-10);
  EXPECT_GT(w_max, 1e-3);
  EXPECT_GT(inside, 500u);
}

// Linear precision on jittered knots: with the control points at the Greville
// abscissae, constant-rate rotations and constant-velocity lines (at ECEF
// magnitudes) are reproduced exactly, as on uniform knots.
TEST(BSpline, JitteredKnotsReproduceConstantRateAndStraightLines) {
  const std::vector<TimeNs> times = jittered_times(5 * kNsPerSecond, kNsPerSecond, 0.3, 40, 13, 12, 4.0);
  // Up to 0.7 rad/s: 2.8 rad over the 4 s gap, below pi (header).
  for (const Vec3& w : {Vec3(0.02, -0.35, 0.11), Vec3(0.4, -0.5, 0.2), Vec3(0.0, 0.0, 1e-7)}) {
    const reference::ConstantRate spin(R_xyz(-1.0, 0.4, 2.0), w, 0, 60 * kNsPerSecond);
    const bspline::Spline spline(knots_at(spin, times));
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
    std::cout << "jittered knots, constant rate |w| = " << w.norm() << " rad/s: gyro err " << gyro_err
              << " rad/s, attitude err " << att_err << " rad, |alpha| " << alpha_max << " rad/s^2\n";
    EXPECT_LT(gyro_err, 1e-12);
    EXPECT_LT(att_err, 1e-12);
    EXPECT_LT(alpha_max, 1e-12);
  }
  const Vec3 p0(4'846'000.123, 183'600.456, 4'116'000.789);
  const Vec3 v(120.25, -87.5, 33.125);
  std::vector<Pose> knots;
  for (const TimeNs t : times) knots.push_back(Pose{t, p0 + 1e-9 * static_cast<double>(t) * v, R_xyz(0.1, 0.2, 0.3)});
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
  std::cout << "jittered knots, straight line at ECEF scale: position err " << p_err << " m, velocity err " << v_err
            << " m/s, |accel| " << a_err << " m/s^2\n";
  // Same bounds as on uniform knots: the knot positions carry their 4.7e-10 m
  // rounding, which the shortest (0.7 s) intervals turn into velocity noise.
  EXPECT_LT(p_err, 5e-9);
  EXPECT_LT(v_err, 1e-8);
  EXPECT_LT(a_err, 1e-8);
}

// Accuracy against the analytic flight on jittered 1 Hz knots is of the same
// order as on uniform 1 Hz knots (all printed), for intervals jittered by
// +-30 % and for knot TIMES jittered by +-0.3 s (intervals 0.4..1.6 s, as in
// test_hard_cases): the control points reproduce cubics up to the uniform
// spline's bias (header), so only fourth-order terms see the jitter.
TEST(BSpline, JitteredKnotsAccuracyMatchesUniform) {
  std::cout << "| method | scene | rate | gyro RMS (rad/s) | gyro max (rad/s) | accel RMS (m/s^2) | "
               "accel max (m/s^2) | ns/sample |\n";
  const std::size_t count = static_cast<std::size_t>(kDuration_ns / kKnotPeriod_ns) + 1;
  const std::vector<TimeNs> times = jittered_times(0, kKnotPeriod_ns, 0.3, count, 17);
  std::vector<TimeNs> shaken_times;  // k s + U(-0.3, 0.3) s
  std::mt19937_64 generator(23);
  for (std::size_t k = 0; k < count; ++k) {
    const double uniform01 = static_cast<double>(generator() >> 11) * 0x1p-53;
    shaken_times.push_back(static_cast<TimeNs>(k) * kKnotPeriod_ns +
                           static_cast<TimeNs>(std::llround((0.6 * uniform01 - 0.3) * 1e9)));
  }
  for (const Physics physics : {Physics::flat, Physics::ecef}) {
    const reference::AircraftFlight flight(physics, reference::AircraftFlight::default_origin(), 0, kDuration_ns);
    const std::string name = physics == Physics::ecef ? "aircraft ecef" : "aircraft flat";
    const Stats uniform = measure(flight, 100);
    print_row(name, 100, uniform);
    const Stats jittered = measure_on(flight, knots_at(flight, times), 100);
    print_row(name + " h+-30%", 100, jittered);
    const Stats shaken = measure_on(flight, knots_at(flight, shaken_times), 100);
    print_row(name + " t+-0.3s", 100, shaken);
    // Same order: within 3x of the uniform-knot errors, in every column.
    for (const Stats* s : {&jittered, &shaken}) {
      EXPECT_LT(s->gyro_rms_rad_s, 3.0 * uniform.gyro_rms_rad_s);
      EXPECT_LT(s->gyro_max_rad_s, 3.0 * uniform.gyro_max_rad_s);
      EXPECT_LT(s->accel_rms_m_s2, 3.0 * uniform.accel_rms_m_s2);
      EXPECT_LT(s->accel_max_m_s2, 3.0 * uniform.accel_max_m_s2);
      EXPECT_GT(s->gyro_rms_rad_s, 1e-6);  // measured something
    }
  }
  const reference::Circle circle(500.0, 50.0, 0, kDuration_ns);
  const Stats c_uniform = measure(circle, 100);
  print_row("circle r=500 v=50", 100, c_uniform);
  const Stats c = measure_on(circle, knots_at(circle, times), 100);
  print_row("circle +-30%", 100, c);
  EXPECT_LT(c.gyro_max_rad_s, 1e-12);  // a turn at constant rate: exact on any knots
  EXPECT_LT(c.accel_rms_m_s2, 3.0 * c_uniform.accel_rms_m_s2);
  EXPECT_LT(c.accel_max_m_s2, 3.0 * c_uniform.accel_max_m_s2);
}

// Cubic precision up to the uniform spline's bias: on jittered knots with a
// gap, a cubic p(tau) = p0 + v tau + a tau^2 / 2 + j tau^3 / 6 at ECEF
// magnitudes comes out as p + (H^2 / 6) p'' exactly (H the median knot
// interval, header) - the bias a uniform spline of interval H has on any
// cubic - so the acceleration is a + j tau exactly, in every segment
// including the first and last.
TEST(BSpline, JitteredKnotsReproduceCubicsUpToTheUniformBias) {
  const std::vector<TimeNs> times = jittered_times(0, kNsPerSecond, 0.3, 40, 19, 20, 4.0);
  std::vector<TimeNs> intervals;
  for (std::size_t k = 0; k + 1 < times.size(); ++k) intervals.push_back(times[k + 1] - times[k]);
  std::sort(intervals.begin(), intervals.end());
  const long double median_s = static_cast<long double>(intervals[(intervals.size() - 1) / 2]) * 1e-9L;
  const long double bias_s2 = median_s * median_s / 6;
  const Vec3 p0(4'846'000.123, 183'600.456, 4'116'000.789);
  const Vec3 v(120.25, -87.5, 33.125), a(1.5, -2.25, 0.375), jerk(-0.0625, 0.03125, 0.015625);
  // Derivative `order` of p (+ bias p'' if with_bias) at t, component i, in long double.
  const auto cubic = [&](TimeNs t, int i, int order, bool with_bias) {
    const long double s = static_cast<long double>(t) * 1e-9L;
    const long double c0 = p0[i], c1 = v[i], c2 = a[i], c3 = jerk[i];
    const long double value[4] = {c0 + s * (c1 + s * (c2 / 2 + s * c3 / 6)), c1 + s * (c2 + s * c3 / 2),
                                  c2 + s * c3, c3};
    const int second = order + 2;
    return value[order] + (with_bias && second <= 3 ? bias_s2 * value[second] : 0.0L);
  };
  std::vector<Pose> knots;
  for (const TimeNs t : times) {
    Vec3 p;
    for (int i = 0; i < 3; ++i) p[i] = static_cast<double>(cubic(t, i, 0, false));
    knots.push_back(Pose{t, p, R_xyz(0.1, 0.2, 0.3)});
  }
  const bspline::Spline spline(knots);
  double p_err = 0.0, v_err = 0.0, a_err = 0.0, bias_max = 0.0;
  for (TimeNs t = spline.start_ns(); t <= spline.end_ns(); t += 3'333'333) {
    Kinematics k;
    spline.evaluate(t, k);
    for (int i = 0; i < 3; ++i) {
      const auto err = [&](double value, int order) {
        return static_cast<double>(std::fabs(static_cast<long double>(value) - cubic(t, i, order, true)));
      };
      p_err = std::max(p_err, err(k.position_m[i], 0));
      v_err = std::max(v_err, err(k.velocity_m_s[i], 1));
      a_err = std::max(a_err, err(k.acceleration_m_s2[i], 2));
      bias_max = std::max(bias_max, static_cast<double>(std::fabs(bias_s2 * cubic(t, i, 2, false))));
    }
  }
  std::cout << "jittered knots, cubic at ECEF scale (bias (H^2/6) p'' up to " << bias_max << " m, H = "
            << static_cast<double>(median_s) << " s): position err " << p_err << " m, velocity err " << v_err
            << " m/s, accel err " << a_err << " m/s^2\n";
  EXPECT_LT(p_err, 5e-9);
  EXPECT_LT(v_err, 1e-8);
  EXPECT_LT(a_err, 1e-8);
  EXPECT_GT(bias_max, 0.1);  // the bias is real, and predicted
}
}  // namespace unity_core_test_bspline
