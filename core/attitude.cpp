#include "core/attitude.hpp"

#include <cmath>
#include <limits>
#include <numbers>

namespace imuemu::attitude {

namespace {

// atan2 returns -pi for (-0.0, negative); the header promises (-pi, pi].
double wrap_half_open(double angle_rad) {
  return angle_rad == -std::numbers::pi ? std::numbers::pi : angle_rad;
}

// At or below this cos(pitch) = hypot(R00, R10) the matrix is treated as
// gimbal locked: rotation_from_hpr at pitch = +-pi/2 (the double) leaves
// cos(pi/2) = 6.1e-17 there, not 0. Forcing roll = 0 then moves R by at most
// ~2 * kGimbalLockCos (the neglected cos(pitch) sin(roll) terms). Above it the
// general branch is exact to rounding (its roll compensates heading noise).
constexpr double kGimbalLockCos = std::numeric_limits<double>::epsilon();

}  // namespace

Mat3 rotation_from_hpr(const HeadingPitchRoll& hpr) {
  // Eq. 1.2, the product R_z(psi) R_y(theta) R_x(gamma) written out as printed.
  const double cp = std::cos(hpr.heading_rad), sp = std::sin(hpr.heading_rad);
  const double ct = std::cos(hpr.pitch_rad), st = std::sin(hpr.pitch_rad);
  const double cg = std::cos(hpr.roll_rad), sg = std::sin(hpr.roll_rad);
  Mat3 R;
  R << ct * cp, sg * st * cp - cg * sp, cg * st * cp + sg * sp,  //
      ct * sp, sg * st * sp + cg * cp, cg * st * sp - sg * cp,   //
      -st, sg * ct, cg * ct;
  return R;
}

HeadingPitchRoll hpr_from_rotation(const Mat3& R) {
  HeadingPitchRoll hpr;
  // cos(theta) >= 0 is the norm of (R00, R10) = cos(theta) (cos psi, sin psi).
  // atan2 against it keeps the pitch accurate where asin(-R20) would lose
  // half the digits (|R20| -> 1).
  const double cos_pitch = std::hypot(R(0, 0), R(1, 0));
  if (cos_pitch <= kGimbalLockCos) {
    // Gimbal lock (Eq. 1.2 with theta = +-pi/2): R depends only on psi - gamma
    // (theta = +pi/2) or psi + gamma (theta = -pi/2); in both cases
    // R01 = -sin(psi'), R11 = cos(psi') with psi' that combination. Put all of
    // it into heading and return roll = 0.
    hpr.pitch_rad = std::copysign(std::numbers::pi / 2.0, -R(2, 0));
    hpr.heading_rad = wrap_half_open(std::atan2(-R(0, 1), R(1, 1)));
    hpr.roll_rad = 0.0;
    return hpr;
  }
  hpr.pitch_rad = std::atan2(-R(2, 0), cos_pitch);
  const double heading = std::atan2(R(1, 0), R(0, 0));
  hpr.heading_rad = wrap_half_open(heading);
  // Roll from row 1 of R_z(-psi) R = R_y(theta) R_x(gamma), which is
  // (0, cos gamma, -sin gamma) whatever theta is. Unlike atan2(R21, R22)
  // (= cos theta * (sin, cos) gamma) this stays well conditioned near the
  // singularity, and compensates any error of psi, so R round trips to ~ulp.
  const double ch = std::cos(heading), sh = std::sin(heading);
  const double cos_roll = ch * R(1, 1) - sh * R(0, 1);
  const double sin_roll = sh * R(0, 2) - ch * R(1, 2);
  hpr.roll_rad = wrap_half_open(std::atan2(sin_roll, cos_roll));
  return hpr;
}

Mat3 rotation_from_quaternion(double q0, double q1, double q2, double q3) {
  // Transpose of Eq. 1.3 (which prints R_l^b), i.e. the Hamilton rotation
  // matrix of q_b^l. Dividing by |q|^2 makes the result an exact rotation even
  // for a slightly non-unit q (Eq. 1.3 as printed scales R by |q|^2).
  const double n2 = q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3;
  const double k = 1.0 / n2;
  Mat3 R;
  R << (q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3) * k, 2.0 * (q1 * q2 - q3 * q0) * k,
      2.0 * (q1 * q3 + q2 * q0) * k,  //
      2.0 * (q1 * q2 + q3 * q0) * k, (q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3) * k,
      2.0 * (q2 * q3 - q1 * q0) * k,  //
      2.0 * (q1 * q3 - q2 * q0) * k, 2.0 * (q2 * q3 + q1 * q0) * k,
      (q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3) * k;
  return R;
}

Mat3 ned_to_ecef(double latitude_rad, double longitude_rad) {
  // Eq. 1.5: columns are the north, east and down unit vectors in ECEF.
  const double sf = std::sin(latitude_rad), cf = std::cos(latitude_rad);
  const double sl = std::sin(longitude_rad), cl = std::cos(longitude_rad);
  Mat3 R;
  R << -sf * cl, -sl, -cf * cl,  //
      -sf * sl, cl, -cf * sl,    //
      cf, 0.0, -sf;
  return R;
}

}  // namespace imuemu::attitude
