// SO(3) maps of thesis §3.2 and §3.6.1: hat/vee, exp (Eq. 3.9), log
// (Eq. 3.13-3.17), the body-rate Jacobian W(r) (Eq. 3.59) and its inverse, and
// the angular acceleration of Eq. 3.61. Every function is accurate to a few ulp
// over the whole ball |r| <= pi, including |r| = 0 and |r| = pi exactly.
#pragma once

#include "core/types.hpp"

namespace imuemu::so3 {

// [r]: the skew-symmetric matrix with [r] v = r x v.
Mat3 hat(const Vec3& r);
// Inverse of hat on the skew part of M (uses the antisymmetric part only).
Vec3 vee(const Mat3& M);

// exp([r]) = I + sin|r|/|r| [r] + (1-cos|r|)/|r|^2 [r]^2   (Eq. 3.9).
Mat3 exp(const Vec3& r);

// r with exp([r]) = R and |r| in [0, pi]  (Eq. 3.13-3.17).
// Computed through the quaternion of R (largest-pivot extraction) and atan2,
// so nothing divides by sin|r|; accurate at 0, at pi and in between.
// At exactly |r| = pi both r and -r are logarithms; the one whose
// largest-magnitude component is positive is returned (deterministic).
Vec3 log(const Mat3& R);

// Rotation angle of R in [0, pi], accurate everywhere (atan2 form).
double angle(const Mat3& R);

// W(r) of Eq. 3.59: body angular rate omega_b = W(r) r_dot for R = exp([r]).
Mat3 W(const Vec3& r);
// Inverse of W: r_dot = W^-1(r) omega_b (singular only at |r| = 2 pi).
Mat3 W_inverse(const Vec3& r);

// Angular acceleration of Eq. 3.61: d/dt (W(r) r_dot) in the body frame.
Vec3 angular_acceleration(const Vec3& r, const Vec3& r_dot, const Vec3& r_ddot);

// Moves (R, omega) a fraction s of the way to (R_b, omega_b) along the
// geodesic between them, where s = s(t) has rate s_rate = ds/dt (1/s):
//   R(s) = R_a exp(s D),  D = log(R_a^T R_b),
// and, if with_rate, the exact body rate of that curve,
//   omega = exp(sD)^T omega_a + W(sD) (s' D + s D'),
//   D' = W(D)^-1 (omega_b - exp(D)^T omega_a)   (from R_b = R_a exp(D)),
// so that a blend weight s(t) gives a consistent (R, omega) pair (Eq. 3.59).
// Without with_rate only R is moved and omega is left untouched.
// Shared by the pipeline's chart blending and the live emitter's rejoin blend.
void geodesic_blend(Mat3& R, Vec3& omega, const Mat3& R_b, const Vec3& omega_b, double s, double s_rate,
                    bool with_rate);

// Unit quaternion (w, x, y, z), w >= 0, of a rotation matrix (Eq. 1.3 inverse,
// largest-pivot / Shepperd extraction). Also used by log().
Eigen::Vector4d quaternion_from_matrix(const Mat3& R);
// Rotation matrix of a unit quaternion (w, x, y, z), Hamilton convention,
// R = R_b^l for q = q_b^l (the transpose of the thesis' Eq. 1.3 R_l^b).
Mat3 matrix_from_quaternion(const Eigen::Vector4d& q_wxyz);

// Projects a nearly orthogonal matrix onto SO(3) (via its quaternion).
Mat3 orthonormalize(const Mat3& R);

// Coefficients of exp and W as functions of theta = |r|, each with a series
// branch where the closed form cancels. Exposed for tests and for callers that
// already know theta.
struct Coefficients {
  double sin_over_theta;           // A = sin t / t
  double one_minus_cos_over_t2;    // B = (1 - cos t) / t^2
  double t_minus_sin_over_t3;      // C = (t - sin t) / t^3
};
Coefficients coefficients(double theta);

}  // namespace imuemu::so3
