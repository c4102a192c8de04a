// Attitude parametrizations (thesis §1.3, Eq. 1.2, 1.3, 1.5) and the WGS84
// Earth (Eq. 1.1, normal gravity, local NED) against independent truth:
// elementary rotation products, Hamilton quaternion products, Eq. 1.1
// evaluated by hand in long double, and the published WGS84 normal gravity.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <iostream>
#include <limits>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "core/attitude.hpp"
#include "core/earth.hpp"
#include "core/so3.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_core_test_attitude_earth {
namespace imuemu { using namespace ::imuemu; }

namespace {

using imuemu::Mat3;
using imuemu::Vec3;
namespace attitude = imuemu::attitude;
namespace earth = imuemu::earth;
using attitude::HeadingPitchRoll;

using LD = long double;
using LMat = Eigen::Matrix<LD, 3, 3>;
using LVec = Eigen::Matrix<LD, 3, 1>;

constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180.0;
constexpr double kEps = std::numeric_limits<double>::epsilon();

void report(const std::string& name, double value) {
  std::cout << "[ worst    ] " << name << ": " << value << "\n";
  ::testing::Test::RecordProperty(name, std::to_string(value));
}

// Smallest |a - b| modulo 2 pi.
double angle_diff(double a, double b) { return std::abs(std::remainder(a - b, 2.0 * kPi)); }

LMat rot_x(LD a) {
  LMat m;
  m << 1, 0, 0, 0, std::cos(a), -std::sin(a), 0, std::sin(a), std::cos(a);
  return m;
}
LMat rot_y(LD a) {
  LMat m;
  m << std::cos(a), 0, std::sin(a), 0, 1, 0, -std::sin(a), 0, std::cos(a);
  return m;
}
LMat rot_z(LD a) {
  LMat m;
  m << std::cos(a), -std::sin(a), 0, std::sin(a), std::cos(a), 0, 0, 0, 1;
  return m;
}

double max_abs(const Mat3& a, const LMat& b) {
  return static_cast<double>((a.cast<LD>() - b).cwiseAbs().maxCoeff());
}

// ------------------------------------------------------------------ Eq. 1.2

TEST(Attitude, RotationFromHprIsRzRyRx) {
  // Eq. 1.2 against the product of the three elementary rotations (long double).
  double worst = 0.0;
  for (double psi = -kPi; psi <= kPi; psi += 0.37) {
    for (double theta = -kPi / 2; theta <= kPi / 2; theta += 0.29) {
      for (double gamma = -kPi; gamma <= kPi; gamma += 0.41) {
        const LMat ref = rot_z(psi) * rot_y(theta) * rot_x(gamma);
        worst = std::max(worst, max_abs(attitude::rotation_from_hpr({psi, theta, gamma}), ref));
      }
    }
  }
  report("hpr_vs_RzRyRx_max_abs_err", worst);
  EXPECT_LE(worst, 4 * kEps);
}

TEST(Attitude, HprPhysicalMeaningFrdToNed) {
  // Heading 90 deg: body forward points east.
  const Mat3 Rh = attitude::rotation_from_hpr({kPi / 2, 0.0, 0.0});
  EXPECT_LT((Rh * Vec3::UnitX() - Vec3::UnitY()).norm(), 1e-15);
  // Pitch +90 deg (nose up): forward points up = -down.
  const Mat3 Rp = attitude::rotation_from_hpr({0.0, kPi / 2, 0.0});
  EXPECT_LT((Rp * Vec3::UnitX() + Vec3::UnitZ()).norm(), 1e-15);
  // Roll +90 deg (right wing down): body right points down.
  const Mat3 Rr = attitude::rotation_from_hpr({0.0, 0.0, kPi / 2});
  EXPECT_LT((Rr * Vec3::UnitY() - Vec3::UnitZ()).norm(), 1e-15);
}

// ----------------------------------------------------------- inverse of 1.2

TEST(Attitude, HprRoundTripGridIncludingGimbalLock) {
  const std::vector<double> headings = {-kPi, -3.0, -kPi / 2, -1.0, -1e-9,
                                        0.0,  0.5,  kPi / 2,  3.0,  kPi};
  const std::vector<double> pitches = {
      -kPi / 2, -kPi / 2 + 1e-12, -kPi / 2 + 1e-8, -1.5,   -0.7, -1e-10, 0.0, 0.3, 1.2,
      1.5,      kPi / 2 - 1e-8,   kPi / 2 - 1e-12, kPi / 2};
  const std::vector<double> rolls = {-kPi, -2.0, -kPi / 2, -0.1, 0.0, 0.2, kPi / 2, 2.5, kPi};
  double worst_R = 0.0, worst_angles = 0.0, worst_pitch = 0.0;
  for (const double psi : headings) {
    for (const double theta : pitches) {
      for (const double gamma : rolls) {
        const Mat3 R = attitude::rotation_from_hpr({psi, theta, gamma});
        const HeadingPitchRoll h = attitude::hpr_from_rotation(R);
        // Ranges promised by the header.
        EXPECT_GT(h.heading_rad, -kPi);
        EXPECT_LE(h.heading_rad, kPi);
        EXPECT_GE(h.pitch_rad, -kPi / 2);
        EXPECT_LE(h.pitch_rad, kPi / 2);
        EXPECT_GT(h.roll_rad, -kPi);
        EXPECT_LE(h.roll_rad, kPi);
        // R round trips everywhere, gimbal lock included.
        const Mat3 R2 = attitude::rotation_from_hpr(h);
        worst_R = std::max(worst_R, (R2 - R).cwiseAbs().maxCoeff());
        // Pitch is accurate everywhere (atan2 form), even 1e-12 from +-90 deg.
        worst_pitch = std::max(worst_pitch, std::abs(h.pitch_rad - theta));
        // Heading and roll individually only where they are separable; their
        // conditioning is 1/cos(pitch).
        if (std::abs(theta) <= 1.5) {
          worst_angles = std::max(
              {worst_angles, angle_diff(h.heading_rad, psi), angle_diff(h.roll_rad, gamma)});
        }
      }
    }
  }
  report("hpr_roundtrip_R_max_abs_err", worst_R);
  report("hpr_roundtrip_angles_max_err_rad", worst_angles);
  report("hpr_pitch_max_err_rad", worst_pitch);
  EXPECT_LE(worst_R, 8 * kEps);
  EXPECT_LE(worst_angles, 8 * kEps / std::cos(1.5));
  EXPECT_LE(worst_pitch, 2 * kEps);
}

TEST(Attitude, GimbalLockConvention) {
  // At pitch = +90 deg, R depends on heading - roll only; at -90 deg on
  // heading + roll. The header puts it all into heading with roll = 0.
  for (const double psi : {-2.0, 0.0, 0.3, 3.0}) {
    for (const double gamma : {-1.0, 0.0, 0.2, 2.9}) {
      const HeadingPitchRoll up =
          attitude::hpr_from_rotation(attitude::rotation_from_hpr({psi, kPi / 2, gamma}));
      EXPECT_EQ(up.pitch_rad, kPi / 2);
      EXPECT_EQ(up.roll_rad, 0.0);
      EXPECT_LT(angle_diff(up.heading_rad, psi - gamma), 8 * kEps);  // psi - gamma ~ 4 rounds
      const HeadingPitchRoll down =
          attitude::hpr_from_rotation(attitude::rotation_from_hpr({psi, -kPi / 2, gamma}));
      EXPECT_EQ(down.pitch_rad, -kPi / 2);
      EXPECT_EQ(down.roll_rad, 0.0);
      EXPECT_LT(angle_diff(down.heading_rad, psi + gamma), 8 * kEps);
    }
  }
  // An exactly locked matrix (no cos(pi/2) = 6e-17 residue): forward = up.
  Mat3 R;
  R << 0, 0, 1,  //
      0, 1, 0,   //
      -1, 0, 0;  // = R_y(90 deg)
  const HeadingPitchRoll h = attitude::hpr_from_rotation(R);
  EXPECT_EQ(h.pitch_rad, kPi / 2);
  EXPECT_EQ(h.roll_rad, 0.0);
  EXPECT_EQ(h.heading_rad, 0.0);
}

TEST(Attitude, HeadingAndRollWrap) {
  // Out-of-range inputs describe the same rotation; the output is in range.
  struct Case {
    HeadingPitchRoll in, expect;
  };
  const std::vector<Case> cases = {
      {{3.5, 0.2, -3.5}, {3.5 - 2 * kPi, 0.2, -3.5 + 2 * kPi}},
      {{-kPi, 0.0, -kPi}, {kPi, 0.0, kPi}},  // -pi maps to +pi
      {{7.0, -0.4, 0.1}, {7.0 - 2 * kPi, -0.4, 0.1}},
      {{0.3, 2.0, 0.5}, {0.3 - kPi, kPi - 2.0, 0.5 - kPi}},  // pitch past 90 deg
  };
  for (const Case& c : cases) {
    const HeadingPitchRoll h = attitude::hpr_from_rotation(attitude::rotation_from_hpr(c.in));
    EXPECT_NEAR(h.heading_rad, c.expect.heading_rad, 1e-14);
    EXPECT_NEAR(h.pitch_rad, c.expect.pitch_rad, 1e-14);
    EXPECT_NEAR(h.roll_rad, c.expect.roll_rad, 1e-14);
  }
}

TEST(Attitude, HprFromNoisyNearLockMatrices) {
  // Rotations near +-90 deg pitch built through quaternions carry ~1e-16 noise
  // in R00, R10: whatever heading/roll split is returned, R must round trip.
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-kPi, kPi);
  double worst = 0.0;
  for (int i = 0; i < 2000; ++i) {
    const double theta = (i % 2 ? 1.0 : -1.0) * (kPi / 2 - std::ldexp(1.0, -(i % 60)));
    const Mat3 R0 = attitude::rotation_from_hpr({u(rng), theta, u(rng)});
    const Mat3 R = imuemu::so3::matrix_from_quaternion(imuemu::so3::quaternion_from_matrix(R0));
    const Mat3 R2 = attitude::rotation_from_hpr(attitude::hpr_from_rotation(R));
    worst = std::max(worst, (R2 - R).cwiseAbs().maxCoeff());
  }
  report("hpr_near_lock_roundtrip_R_max_abs_err", worst);
  EXPECT_LE(worst, 8 * kEps);
}

// ------------------------------------------------------------------ Eq. 1.3

// Hamilton product of (w, x, y, z) quaternions.
Eigen::Vector4d qmul(const Eigen::Vector4d& a, const Eigen::Vector4d& b) {
  return {a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
          a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
          a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
          a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0]};
}

TEST(Attitude, QuaternionMatchesHpr) {
  // Heading 90 deg = rotation of 90 deg about down: q = (cos 45, 0, 0, sin 45).
  const double c45 = std::cos(kPi / 4), s45 = std::sin(kPi / 4);
  EXPECT_LT((attitude::rotation_from_quaternion(c45, 0, 0, s45) -
             attitude::rotation_from_hpr({kPi / 2, 0, 0}))
                .cwiseAbs()
                .maxCoeff(),
            4 * kEps);
  EXPECT_LT((attitude::rotation_from_quaternion(c45, 0, s45, 0) -
             attitude::rotation_from_hpr({0, kPi / 2, 0}))
                .cwiseAbs()
                .maxCoeff(),
            4 * kEps);
  EXPECT_LT((attitude::rotation_from_quaternion(c45, s45, 0, 0) -
             attitude::rotation_from_hpr({0, 0, kPi / 2}))
                .cwiseAbs()
                .maxCoeff(),
            4 * kEps);
  // General: q = q_z(psi) q_y(theta) q_x(gamma) mirrors R_z R_y R_x.
  double worst = 0.0;
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-kPi, kPi), v(-kPi / 2, kPi / 2);
  for (int i = 0; i < 500; ++i) {
    const double psi = u(rng), theta = v(rng), gamma = u(rng);
    const Eigen::Vector4d qz(std::cos(psi / 2), 0, 0, std::sin(psi / 2));
    const Eigen::Vector4d qy(std::cos(theta / 2), 0, std::sin(theta / 2), 0);
    const Eigen::Vector4d qx(std::cos(gamma / 2), std::sin(gamma / 2), 0, 0);
    const Eigen::Vector4d q = qmul(qz, qmul(qy, qx));
    const Mat3 Rq = attitude::rotation_from_quaternion(q[0], q[1], q[2], q[3]);
    worst = std::max(worst,
                     (Rq - attitude::rotation_from_hpr({psi, theta, gamma})).cwiseAbs().maxCoeff());
    // Same convention as the SO(3) helper (a convention mismatch would be O(1);
    // the two differ in rounding, and in how they treat |q| = 1 +- 2 eps), and
    // -q is the same rotation.
    EXPECT_LT((Rq - imuemu::so3::matrix_from_quaternion(q)).cwiseAbs().maxCoeff(), 8 * kEps);
    EXPECT_LT(
        (Rq - attitude::rotation_from_quaternion(-q[0], -q[1], -q[2], -q[3])).cwiseAbs().maxCoeff(),
        4 * kEps);
    // Eq. 1.3 exactly as printed is R_l^b, the transpose of ours.
    const double q0 = q[0], q1 = q[1], q2 = q[2], q3 = q[3];
    Mat3 R_l_b;
    R_l_b << q1 * q1 - q2 * q2 - q3 * q3 + q0 * q0, 2 * (q1 * q2 + q3 * q0),
        2 * (q1 * q3 - q2 * q0), 2 * (q1 * q2 - q3 * q0), -q1 * q1 + q2 * q2 - q3 * q3 + q0 * q0,
        2 * (q2 * q3 + q1 * q0), 2 * (q1 * q3 + q2 * q0), 2 * (q2 * q3 - q1 * q0),
        -q1 * q1 - q2 * q2 + q3 * q3 + q0 * q0;
    EXPECT_LT((Rq - R_l_b.transpose()).cwiseAbs().maxCoeff(), 4 * kEps);
    // A non-unit q still gives the exact rotation (normalised internally).
    EXPECT_LT((attitude::rotation_from_quaternion(3 * q0, 3 * q1, 3 * q2, 3 * q3) - Rq)
                  .cwiseAbs()
                  .maxCoeff(),
              4 * kEps);
  }
  report("quaternion_vs_hpr_max_abs_err", worst);
  EXPECT_LE(worst, 4 * kEps);
}

// ------------------------------------------------------------------ Eq. 1.5

TEST(Attitude, NedToEcefColumnsAreNorthEastDown) {
  double worst_cols = 0.0, worst_orth = 0.0, worst_north_fd = 0.0;
  for (double lat_deg = -90.0; lat_deg <= 90.0; lat_deg += 7.5) {
    for (double lon_deg = -180.0; lon_deg <= 180.0; lon_deg += 22.5) {
      const LD lat = lat_deg * std::numbers::pi_v<LD> / 180,
               lon = lon_deg * std::numbers::pi_v<LD> / 180;
      const Mat3 R = attitude::ned_to_ecef(static_cast<double>(lat), static_cast<double>(lon));
      // Down is minus the ellipsoid normal; east is horizontal, towards +lon;
      // north completes the right-handed N = E x D.
      const LVec down(-std::cos(lat) * std::cos(lon), -std::cos(lat) * std::sin(lon),
                      -std::sin(lat));
      const LVec east(-std::sin(lon), std::cos(lon), 0);
      const LVec north = east.cross(down);
      LMat ref;
      ref << north, east, down;
      worst_cols = std::max(worst_cols, max_abs(R, ref));
      const LMat Rl = R.cast<LD>();
      worst_orth = std::max(
          worst_orth,
          static_cast<double>((Rl.transpose() * Rl - LMat::Identity()).cwiseAbs().maxCoeff()));
      EXPECT_NEAR(R.determinant(), 1.0, 4 * kEps);
      // North is the direction in which ECEF position moves as latitude grows
      // (away from the poles, where the meridian turns): central difference.
      if (std::abs(lat_deg) < 89.0) {
        const double h = 1e-6;
        const earth::Geodetic g0{static_cast<double>(lat) - h, static_cast<double>(lon), 100.0};
        const earth::Geodetic g1{static_cast<double>(lat) + h, static_cast<double>(lon), 100.0};
        const Vec3 dir =
            (earth::ecef_from_geodetic(g1) - earth::ecef_from_geodetic(g0)).normalized();
        // |sin angle| (acos near 1 would only resolve ~1e-8 rad).
        worst_north_fd = std::max(worst_north_fd, dir.cross(R.col(0)).norm());
        EXPECT_GT(dir.dot(R.col(0)), 0.0);
      }
    }
  }
  report("ned_to_ecef_columns_max_abs_err", worst_cols);
  report("ned_to_ecef_orthonormality_err", worst_orth);
  report("ned_north_vs_dxdlat_angle_rad", worst_north_fd);
  EXPECT_LE(worst_cols, 4 * kEps);
  EXPECT_LE(worst_orth, 4 * kEps);
  EXPECT_LE(worst_north_fd, 1e-9);
}

// ------------------------------------------------------------------ Eq. 1.1

// Eq. 1.1 by hand in long double with the WGS84 defining constants.
LVec ecef_eq11(LD lat, LD lon, LD h) {
  const LD a = 6378137.0L, f = 1.0L / 298.257223563L;
  const LD b = a * (1 - f);
  const LD e2 = (a * a - b * b) / (a * a);
  const LD N =
      a * a /
      std::sqrt(a * a * std::cos(lat) * std::cos(lat) + b * b * std::sin(lat) * std::sin(lat));
  return LVec((N + h) * std::cos(lat) * std::cos(lon), (N + h) * std::cos(lat) * std::sin(lon),
              ((1 - e2) * N + h) * std::sin(lat));
}

TEST(Earth, GeodeticEcefAgainstEq11AndRoundTrip) {
  const std::vector<double> lats_deg = {-90.0, -89.999, -60.0, -45.0, -10.0,  0.0,
                                        1e-7,  30.0,    45.5,  60.0,  89.999, 90.0};
  const std::vector<double> lons_deg = {-180.0, -179.9, -90.0, 0.0, 45.0, 120.0, 179.9, 180.0};
  const std::vector<double> heights = {-100.0, 0.0, 1000.0, 8848.0, 20000.0};
  double worst_fwd = 0.0, worst_lat = 0.0, worst_lon = 0.0, worst_h = 0.0, worst_x = 0.0;
  for (const double lat_deg : lats_deg) {
    for (const double lon_deg : lons_deg) {
      for (const double h : heights) {
        const earth::Geodetic g{lat_deg * kDeg, lon_deg * kDeg, h};
        const Vec3 x = earth::ecef_from_geodetic(g);
        const LVec ref = ecef_eq11(g.latitude_rad, g.longitude_rad, h);
        worst_fwd =
            std::max(worst_fwd, static_cast<double>((x.cast<LD>() - ref).cwiseAbs().maxCoeff()));

        const earth::Geodetic back = earth::geodetic_from_ecef(x);
        worst_lat = std::max(worst_lat, std::abs(back.latitude_rad - g.latitude_rad));
        if (std::abs(lat_deg) < 90.0) {  // longitude is undefined at the poles
          worst_lon = std::max(worst_lon, angle_diff(back.longitude_rad, g.longitude_rad));
        }
        worst_h = std::max(worst_h, std::abs(back.height_m - h));
        worst_x = std::max(worst_x, (earth::ecef_from_geodetic(back) - x).cwiseAbs().maxCoeff());
      }
    }
  }
  report("ecef_vs_eq1.1_max_abs_err_m", worst_fwd);
  report("geodetic_roundtrip_lat_err_rad", worst_lat);
  report("geodetic_roundtrip_lon_err_rad", worst_lon);
  report("geodetic_roundtrip_h_err_m", worst_h);
  report("ecef_roundtrip_err_m", worst_x);
  // ulp(6.4e6 m) = 9.3e-10 m: a few ulp of the coordinates.
  EXPECT_LE(worst_fwd, 5e-9);
  EXPECT_LE(worst_lat, 1e-14);
  EXPECT_LE(worst_lon, 1e-14);
  EXPECT_LE(worst_h, 5e-9);
  EXPECT_LE(worst_x, 5e-9);
}

TEST(Earth, PolesAndDateLine) {
  // pi/2 rad converts to 90.00000000000001 deg; it must still be the pole.
  for (const double sign : {1.0, -1.0}) {
    const Vec3 x = earth::ecef_from_geodetic({sign * kPi / 2, 0.7, 0.0});
    ASSERT_TRUE(x.allFinite());
    EXPECT_LT(std::hypot(x.x(), x.y()), 1e-9);
    EXPECT_NEAR(x.z(), sign * 6356752.314245179, 1e-8);  // b = a (1 - f)
    const earth::Geodetic g = earth::geodetic_from_ecef(x);
    EXPECT_NEAR(g.latitude_rad, sign * kPi / 2, 1e-15);
    EXPECT_NEAR(g.height_m, 0.0, 1e-9);
  }
  // +180 and -180 deg are the same meridian.
  const Vec3 e = earth::ecef_from_geodetic({0.3, kPi, 50.0});
  const Vec3 w = earth::ecef_from_geodetic({0.3, -kPi, 50.0});
  EXPECT_LT((e - w).cwiseAbs().maxCoeff(), 1e-8);
  EXPECT_LT(e.x(), 0.0);
}

// ------------------------------------------------------------ normal gravity

TEST(Earth, NormalGravityMatchesSomigliana) {
  // WGS84 normal gravity on the ellipsoid (NIMA TR8350.2): equator and pole,
  // and Somigliana's closed form in between. It includes the centrifugal term
  // (gravitation alone is ~9.814 at the equator).
  const double ge = 9.7803253359, gp = 9.8321849378;
  const double a = 6378137.0, f = 1.0 / 298.257223563, b = a * (1 - f), e2 = f * (2 - f);
  const double k = (b * gp) / (a * ge) - 1.0;
  double worst_mag = 0.0, worst_dir = 0.0;
  for (double lat_deg = -90.0; lat_deg <= 90.0; lat_deg += 5.0) {
    for (const double lon_deg : {-180.0, -33.0, 0.0, 100.0}) {
      const double lat = lat_deg * kDeg, lon = lon_deg * kDeg;
      const Vec3 x = earth::ecef_from_geodetic({lat, lon, 0.0});
      const Vec3 g = earth::normal_gravity_ecef(x);
      const double s2 = std::sin(lat) * std::sin(lat);
      const double somigliana = ge * (1 + k * s2) / std::sqrt(1 - e2 * s2);
      worst_mag = std::max(worst_mag, std::abs(g.norm() - somigliana));
      // Along the down direction (-ellipsoid normal) on the level ellipsoid.
      const Vec3 down(-std::cos(lat) * std::cos(lon), -std::cos(lat) * std::sin(lon),
                      -std::sin(lat));
      worst_dir = std::max(worst_dir, down.cross(g.normalized()).norm());
      EXPECT_GT(down.dot(g), 0.0);
    }
  }
  report("normal_gravity_vs_somigliana_m_s2", worst_mag);
  report("normal_gravity_direction_err_rad", worst_dir);
  EXPECT_LE(worst_mag, 1e-9);
  EXPECT_LE(worst_dir, 1e-9);
  EXPECT_NEAR(earth::normal_gravity_ecef(earth::ecef_from_geodetic({0, 0, 0})).norm(), ge, 1e-9);
  EXPECT_NEAR(earth::normal_gravity_ecef(earth::ecef_from_geodetic({kPi / 2, 0, 0})).norm(), gp,
              1e-9);
  // Free-air gradient ~ -3.086e-6 s^-2: 1 km up loses ~3.09 mm/s^2.
  const double g0 = earth::normal_gravity_ecef(earth::ecef_from_geodetic({0.8, 0.1, 0})).norm();
  const double g1 = earth::normal_gravity_ecef(earth::ecef_from_geodetic({0.8, 0.1, 1000})).norm();
  EXPECT_NEAR(g0 - g1, 3.086e-3, 2e-5);
  EXPECT_EQ(earth::rotation_rate_ecef(), Vec3(0, 0, 7.292115e-5));
}

// ---------------------------------------------------------------- LocalNed

TEST(Earth, LocalNedRoundTripAndAxes) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-10000.0, 10000.0);
  double worst_rt = 0.0, worst_up = 0.0;
  for (const earth::Geodetic origin :
       {earth::Geodetic{0.0, 0.0, 0.0}, earth::Geodetic{0.7, -2.1, 350.0},
        earth::Geodetic{-1.2, kPi, -50.0}, earth::Geodetic{kPi / 2, 0.4, 10.0}}) {
    const earth::LocalNed ned(origin);
    EXPECT_LT(ned.ned_from_ecef(ned.origin_ecef_m()).norm(), 1e-12);
    EXPECT_EQ(ned.R_n_to_e(), attitude::ned_to_ecef(origin.latitude_rad, origin.longitude_rad));
    for (int i = 0; i < 200; ++i) {
      const Vec3 n(u(rng), u(rng), u(rng));
      worst_rt =
          std::max(worst_rt, (ned.ned_from_ecef(ned.ecef_from_ned(n)) - n).cwiseAbs().maxCoeff());
      const Vec3 x = ned.origin_ecef_m() + Vec3(u(rng), u(rng), u(rng));
      worst_rt =
          std::max(worst_rt, (ned.ecef_from_ned(ned.ned_from_ecef(x)) - x).cwiseAbs().maxCoeff());
    }
    // Straight up along the ellipsoid normal is NED (0, 0, -dh).
    earth::Geodetic above = origin;
    above.height_m += 1234.5;
    const Vec3 up = ned.ned_from_ecef(earth::ecef_from_geodetic(above));
    worst_up = std::max(worst_up, (up - Vec3(0, 0, -1234.5)).cwiseAbs().maxCoeff());
  }
  report("local_ned_roundtrip_err_m", worst_rt);
  report("local_ned_vertical_err_m", worst_up);
  EXPECT_LE(worst_rt, 5e-9);
  EXPECT_LE(worst_up, 5e-9);
}

}  // namespace
}  // namespace unity_core_test_attitude_earth
