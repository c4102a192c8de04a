// The analytic reference motions are the truth for every closed-loop test, so
// their closed-form derivatives are checked here against high-order central
// finite differences of their own position and attitude (catches algebra
// slips), and their IMU output against physics written out independently.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <iostream>
#include <numbers>

#include <Eigen/Dense>

#include "core/earth.hpp"
#include "core/reference_motion.hpp"
#include "core/so3.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_core_test_reference_motion {
namespace imuemu { using namespace ::imuemu; }

namespace imuemu {
namespace {

using reference::AircraftFlight;
using reference::Circle;
using reference::ConstantRate;
using reference::Motion;
using reference::Static;

constexpr double kDeg = std::numbers::pi / 180.0;

// Sixth-order central difference: Richardson extrapolation of the five-point
// stencil of thesis Eq. 3.74, D6 = (16 D4(h) - D4(2h)) / 15, accumulated in
// long double. Truncation ~h^6 f^(7) / 140; rounding ~1.7 eps |f| / h.
template <typename M>
M derivative(const std::function<M(TimeNs)>& f, TimeNs t_ns, TimeNs h_ns) {
  const long double h = static_cast<long double>(h_ns) * 1e-9L;
  using LM = Eigen::Matrix<long double, M::RowsAtCompileTime, M::ColsAtCompileTime>;
  auto F = [&](TimeNs s) -> LM { return f(s).template cast<long double>(); };
  auto d4 = [&](TimeNs step, long double hs) -> LM {
    return (-F(t_ns + 2 * step) + 8.0L * F(t_ns + step) - 8.0L * F(t_ns - step) +
            F(t_ns - 2 * step)) /
           (12.0L * hs);
  };
  const LM d = (16.0L * d4(h_ns, h) - d4(2 * h_ns, 2.0L * h)) / 15.0L;
  return d.template cast<double>();
}

struct FdErrors {
  double velocity_m_s = 0.0;
  double acceleration_m_s2 = 0.0;
  double rate_rad_s = 0.0;
};

// Worst disagreement of the analytic derivatives with finite differences over
// `points` times spread across [start, end].
FdErrors finite_difference_errors(const Motion& m, int points, TimeNs h_ns) {
  FdErrors e;
  const std::function<Vec3(TimeNs)> pos = [&](TimeNs t) { return m.at(t).position_m; };
  const std::function<Vec3(TimeNs)> vel = [&](TimeNs t) { return m.at(t).velocity_m_s; };
  const std::function<Mat3(TimeNs)> att = [&](TimeNs t) { return m.at(t).attitude; };
  const TimeNs span = m.end_ns() - m.start_ns();
  for (int i = 0; i < points; ++i) {
    const TimeNs t = m.start_ns() + span / (points - 1) * i;
    const Kinematics k = m.at(t);
    EXPECT_EQ(k.t_ns, t);
    e.velocity_m_s = std::max(e.velocity_m_s, (derivative(pos, t, h_ns) - k.velocity_m_s).norm());
    e.acceleration_m_s2 =
        std::max(e.acceleration_m_s2, (derivative(vel, t, h_ns) - k.acceleration_m_s2).norm());
    // R^T R' = [omega_b].
    const Mat3 Rdot = derivative(att, t, h_ns);
    const Vec3 w = so3::vee(k.attitude.transpose() * Rdot);
    e.rate_rad_s = std::max(e.rate_rad_s, (w - k.angular_rate_rad_s).norm());
    // The attitude itself must be a rotation.
    EXPECT_LT((k.attitude.transpose() * k.attitude - Mat3::Identity()).norm(), 1e-14);
    EXPECT_NEAR(k.attitude.determinant(), 1.0, 1e-14);
  }
  return e;
}

void report(const char* name, const FdErrors& e) {
  std::cout << name << ": max |v - FD| = " << e.velocity_m_s
            << " m/s, |a - FD| = " << e.acceleration_m_s2
            << " m/s^2, |w - FD| = " << e.rate_rad_s << " rad/s\n";
  ::testing::Test::RecordProperty(std::string(name) + "_velocity_err", std::to_string(e.velocity_m_s));
}

// FD step 10 ms: truncation (h^6 times the 7th derivative, < 1e-12 for these
// motions) and rounding (~1.7 eps |x| / h: 2e-9 m/s for 1e5 m flat positions,
// 1.2e-7 m/s for 6.4e6 m ECEF ones) both stay far below any algebra slip, which
// would show up at the 1e-3 level of the quantities (~0.01 m/s, ~1e-4 rad/s).
// The attitude's rounding is relative to the accumulated rotation angle (up to
// ~150 rad for the spin below): eps * 150 * 1.7 / h ~ 3e-12 rad/s, hence the
// 2e-11 rad/s rate bound.
constexpr TimeNs kFdStep_ns = 10'000'000;

TEST(ReferenceMotion, AircraftFlatDerivativesMatchFiniteDifferences) {
  const AircraftFlight m(Physics::flat);
  const FdErrors e = finite_difference_errors(m, 301, kFdStep_ns);
  report("aircraft_flat", e);
  EXPECT_LT(e.velocity_m_s, 2e-8);
  EXPECT_LT(e.acceleration_m_s2, 1e-10);
  EXPECT_LT(e.rate_rad_s, 2e-11);
}

TEST(ReferenceMotion, AircraftEcefDerivativesMatchFiniteDifferences) {
  const AircraftFlight m(Physics::ecef);
  const FdErrors e = finite_difference_errors(m, 301, kFdStep_ns);
  report("aircraft_ecef", e);
  EXPECT_LT(e.velocity_m_s, 1e-6);
  EXPECT_LT(e.acceleration_m_s2, 1e-10);
  EXPECT_LT(e.rate_rad_s, 2e-11);
}

TEST(ReferenceMotion, CircleDerivativesMatchFiniteDifferences) {
  const Circle m(300.0, 60.0, 5 * kNsPerSecond, 600 * kNsPerSecond);
  const FdErrors e = finite_difference_errors(m, 101, kFdStep_ns);
  report("circle", e);
  EXPECT_LT(e.velocity_m_s, 1e-9);
  EXPECT_LT(e.acceleration_m_s2, 1e-10);
  EXPECT_LT(e.rate_rad_s, 2e-11);
}

TEST(ReferenceMotion, ConstantRateDerivativesMatchFiniteDifferences) {
  const Mat3 R0 = so3::exp(Vec3(0.3, -1.1, 2.0));
  const ConstantRate m(R0, Vec3(0.7, -0.4, 1.3), -20 * kNsPerSecond, 120 * kNsPerSecond);
  const FdErrors e = finite_difference_errors(m, 101, kFdStep_ns);
  report("constant_rate", e);
  EXPECT_EQ(e.velocity_m_s, 0.0);
  EXPECT_EQ(e.acceleration_m_s2, 0.0);
  EXPECT_LT(e.rate_rad_s, 2e-11);
  // After one full turn about the (fixed) rate axis the attitude is R0 again.
  const Vec3 w(0.0, 0.6, -0.8);  // |w| = 1 rad/s
  const ConstantRate turn(R0, w, 0, kNsPerSecond);
  const double period_s = 2.0 * std::numbers::pi;
  const Mat3 R = turn.at(static_cast<TimeNs>(std::llround(period_s * 1e9))).attitude;
  EXPECT_LT((R - R0).norm(), 1e-8);  // 1 ns of rounding in the period -> 1e-9 rad
}

TEST(ReferenceMotion, AircraftFlightStaysInItsEnvelope) {
  // The flight's advertised envelope, and its defining geometry: body x along
  // the velocity, roll of a coordinated turn.
  const AircraftFlight m(Physics::flat);
  EXPECT_EQ(m.end_ns() - m.start_ns(), reference::kOneHour_ns);
  double min_speed = 1e9, max_speed = 0.0, max_roll = 0.0, max_pitch = 0.0, max_yaw_rate = 0.0;
  double max_climb = 0.0, max_descent = 0.0, max_sideslip = 0.0;
  for (TimeNs t = m.start_ns(); t <= m.end_ns(); t += kNsPerSecond / 4) {
    const Kinematics k = m.at(t);
    const double speed = k.velocity_m_s.norm();
    min_speed = std::min(min_speed, speed);
    max_speed = std::max(max_speed, speed);
    // Forward axis = velocity direction: v^b = (|v|, 0, 0).
    const Vec3 v_b = k.attitude.transpose() * k.velocity_m_s;
    max_sideslip = std::max(max_sideslip, std::hypot(v_b.y(), v_b.z()) / speed);
    // Eq. 1.2: R(2,0) = -sin(pitch), R(2,1)/R(2,2) = tan(roll).
    max_pitch = std::max(max_pitch, std::abs(std::asin(-k.attitude(2, 0))));
    const double roll = std::atan2(k.attitude(2, 1), k.attitude(2, 2));
    max_roll = std::max(max_roll, std::abs(roll));
    // Heading rate from the body rate, z-y-x sequence:
    // psi' = (sin ga w_y + cos ga w_z) / cos th.
    const Vec3& w = k.angular_rate_rad_s;
    const double cth = std::sqrt(1.0 - k.attitude(2, 0) * k.attitude(2, 0));
    const double yaw_rate = (std::sin(roll) * w.y() + std::cos(roll) * w.z()) / cth;
    max_yaw_rate = std::max(max_yaw_rate, std::abs(yaw_rate));
    // Coordinated turn: tan(roll) = |v_h| psi' / g0.
    const double vh = std::hypot(k.velocity_m_s.x(), k.velocity_m_s.y());
    EXPECT_NEAR(std::tan(roll), vh * yaw_rate / 9.80665, 1e-12);
    max_climb = std::max(max_climb, -k.position_m.z());
    max_descent = std::max(max_descent, k.position_m.z());
  }
  std::cout << "aircraft envelope: speed [" << min_speed << ", " << max_speed
            << "] m/s, |roll| <= " << max_roll / kDeg << " deg, |pitch| <= " << max_pitch / kDeg
            << " deg, |heading rate| <= " << max_yaw_rate / kDeg << " deg/s, height ["
            << -max_descent << ", " << max_climb << "] m, sideslip " << max_sideslip << "\n";
  EXPECT_GE(min_speed, 100.0);
  EXPECT_LE(max_speed, 250.0);
  EXPECT_LT(max_sideslip, 1e-14);
  EXPECT_GT(max_roll, 10.0 * kDeg);  // it does turn
  EXPECT_LT(max_roll, 30.0 * kDeg);
  EXPECT_GT(max_pitch, 2.0 * kDeg);  // it does climb and descend
  EXPECT_LT(max_pitch, 10.0 * kDeg);
  EXPECT_LT(max_yaw_rate, 3.0 * kDeg);  // far below 180 deg/s
  EXPECT_GT(max_climb, 1000.0);
}

TEST(ReferenceMotion, AircraftEcefIsTheFlatFlightAboutItsOrigin) {
  const earth::Geodetic origin = AircraftFlight::default_origin();
  const AircraftFlight flat(Physics::flat, origin, 7 * kNsPerSecond);
  const AircraftFlight ecef(Physics::ecef, origin, 7 * kNsPerSecond);
  // Starts at the origin...
  EXPECT_LT((ecef.at(ecef.start_ns()).position_m - earth::ecef_from_geodetic(origin)).norm(), 1e-9);
  EXPECT_LT(flat.at(flat.start_ns()).position_m.norm(), 1e-12);
  // ... and is the flat flight rotated by R_n^e of Eq. 1.5, written out here.
  const double sf = std::sin(origin.latitude_rad), cf = std::cos(origin.latitude_rad);
  const double sl = std::sin(origin.longitude_rad), cl = std::cos(origin.longitude_rad);
  Mat3 R_n_e;
  R_n_e << -sf * cl, -sl, -cf * cl,  //
      -sf * sl, cl, -cf * sl,        //
      cf, 0.0, -sf;
  for (TimeNs t = flat.start_ns(); t <= flat.end_ns(); t += 600 * kNsPerSecond) {
    const Kinematics kn = flat.at(t), ke = ecef.at(t);
    EXPECT_LT((ke.position_m - earth::ecef_from_geodetic(origin) - R_n_e * kn.position_m).norm(), 1e-8);
    EXPECT_LT((ke.velocity_m_s - R_n_e * kn.velocity_m_s).norm(), 1e-12);
    EXPECT_LT((ke.acceleration_m_s2 - R_n_e * kn.acceleration_m_s2).norm(), 1e-14);
    EXPECT_LT((ke.attitude - R_n_e * kn.attitude).norm(), 1e-14);
    EXPECT_EQ(ke.angular_rate_rad_s, kn.angular_rate_rad_s);
  }
}

TEST(ReferenceMotion, StaticEcefMeasuresEarthRateAndGravity) {
  const SceneModel scene{Physics::ecef};
  const earth::Geodetic where{41.0 * kDeg, -3.5 * kDeg, 0.0};
  const Static m(where, {30.0 * kDeg, 5.0 * kDeg, -12.0 * kDeg}, Physics::ecef);
  const Kinematics k = m.at(1234567);
  const ImuSample s = reference::truth_imu(m, scene, 1234567);
  EXPECT_EQ(s.t_ns, 1234567);
  const Mat3& R = k.attitude;
  EXPECT_LT((s.gyro_rad_s - R.transpose() * earth::rotation_rate_ecef()).norm(), 1e-12 * 7.3e-5);
  const Vec3 g = earth::normal_gravity_ecef(k.position_m);
  EXPECT_LT((s.accel_m_s2 + R.transpose() * g).norm(), 1e-12 * 9.8);
  EXPECT_EQ(k.velocity_m_s, Vec3::Zero());

  // Level body on the ellipsoid: the specific force is straight up in body
  // axes (normal gravity is normal to the ellipsoid, an equipotential) with the
  // Somigliana magnitude gamma_e (1 + k sin^2 phi) / sqrt(1 - e^2 sin^2 phi).
  const Static level(where, {0.0, 0.0, 0.0}, Physics::ecef);
  const ImuSample sl = reference::truth_imu(level, scene, 0);
  const double s2 = std::sin(where.latitude_rad) * std::sin(where.latitude_rad);
  const double somigliana =
      9.7803253359 * (1.0 + 0.00193185265241 * s2) / std::sqrt(1.0 - 0.00669437999013 * s2);
  EXPECT_NEAR(sl.accel_m_s2.z(), -somigliana, 1e-9);
  EXPECT_LT(std::hypot(sl.accel_m_s2.x(), sl.accel_m_s2.y()), 1e-9);
  // Earth rate in NED = (w cos phi, 0, -w sin phi).
  const double w = earth::kRotationRate_rad_s;
  EXPECT_NEAR(sl.gyro_rad_s.x(), w * std::cos(where.latitude_rad), 1e-18);
  EXPECT_NEAR(sl.gyro_rad_s.y(), 0.0, 1e-18);
  EXPECT_NEAR(sl.gyro_rad_s.z(), -w * std::sin(where.latitude_rad), 1e-18);
}

TEST(ReferenceMotion, StaticFlatMeasuresOnlyGravity) {
  const SceneModel scene{Physics::flat};
  const double th = 5.0 * kDeg, ga = -12.0 * kDeg;
  const Static m({0.5, 0.1, 100.0}, {30.0 * kDeg, th, ga}, Physics::flat);
  const ImuSample s = reference::truth_imu(m, scene, 0);
  EXPECT_EQ(m.at(0).position_m, Vec3::Zero());
  EXPECT_EQ(s.gyro_rad_s, Vec3::Zero());
  // f^b = -g R^T e_down = -g (third row of Eq. 1.2).
  const double g = scene.flat_gravity_m_s2.z();
  const Vec3 expected = -g * Vec3(-std::sin(th), std::sin(ga) * std::cos(th), std::cos(ga) * std::cos(th));
  EXPECT_LT((s.accel_m_s2 - expected).norm(), 1e-14);
}

TEST(ReferenceMotion, CircleHasCentripetalAcceleration) {
  const double r = 250.0, v = 80.0;
  const Circle m(r, v);
  const SceneModel scene{Physics::flat};
  const Vec3 centre(0.0, r, 0.0);
  for (TimeNs t = 0; t <= 100 * kNsPerSecond; t += 7 * kNsPerSecond) {
    const Kinematics k = m.at(t);
    EXPECT_NEAR((k.position_m - centre).norm(), r, 1e-12 * r);
    EXPECT_NEAR(k.velocity_m_s.norm(), v, 1e-12 * v);
    EXPECT_NEAR(k.acceleration_m_s2.norm(), v * v / r, 1e-12 * v * v / r);
    // Pointing at the centre.
    EXPECT_NEAR(k.acceleration_m_s2.normalized().dot((centre - k.position_m).normalized()), 1.0, 1e-14);
    EXPECT_LT((k.angular_rate_rad_s - Vec3(0.0, 0.0, v / r)).norm(), 1e-15);
    // Body axes: x along the velocity, z down -> f^b = (0, v^2/r, -g).
    const ImuSample s = reference::truth_imu(m, scene, t);
    EXPECT_LT((s.accel_m_s2 - Vec3(0.0, v * v / r, -9.80665)).norm(), 1e-12);
  }
}

TEST(ReferenceMotion, SampleKnotsAndTruthSeries) {
  const AircraftFlight m(Physics::flat, AircraftFlight::default_origin(), 1000, 10 * kNsPerSecond);
  const auto knots = reference::sample_knots(m, kNsPerSecond);
  ASSERT_EQ(knots.size(), 11u);
  for (std::size_t i = 0; i < knots.size(); ++i) {
    const TimeNs t = 1000 + static_cast<TimeNs>(i) * kNsPerSecond;
    EXPECT_EQ(knots[i].t_ns, t);
    EXPECT_EQ(knots[i].position_m, m.at(t).position_m);
    EXPECT_EQ(knots[i].attitude, m.at(t).attitude);
  }
  EXPECT_EQ(reference::sample_knots(m, 3 * kNsPerSecond).size(), 4u);  // 0, 3, 6, 9 s
  const auto imu = reference::truth_imu_series(m, SceneModel{Physics::flat}, kNsPerSecond / 2);
  ASSERT_EQ(imu.size(), 21u);
  EXPECT_EQ(imu.back().t_ns, m.end_ns());
  EXPECT_THROW(reference::truth_imu(m, SceneModel{Physics::ecef}, 0), std::invalid_argument);
  EXPECT_THROW(reference::sample_knots(m, 0), std::invalid_argument);
}

}  // namespace
}  // namespace imuemu
}  // namespace unity_core_test_reference_motion
