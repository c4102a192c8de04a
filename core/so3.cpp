#include "core/so3.hpp"

#include <Eigen/Geometry>  // Vec3::cross is only declared by Eigen/Core

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <limits>
#include <numbers>

namespace imuemu::so3 {

Mat3 hat(const Vec3& r) {
  Mat3 m;
  m << 0.0, -r.z(), r.y(),  //
      r.z(), 0.0, -r.x(),   //
      -r.y(), r.x(), 0.0;
  return m;
}

Vec3 vee(const Mat3& M) {
  return 0.5 * Vec3(M(2, 1) - M(1, 2), M(0, 2) - M(2, 0), M(1, 0) - M(0, 1));
}

namespace {

// n! in double; exact up to 22! (its odd part is below 2^53), which covers
// every coefficient below that is not already negligible.
constexpr double factorial(int n) {
  double f = 1.0;
  for (int i = 2; i <= n; ++i) f *= i;
  return f;
}

// Horner evaluation of sum_k c[k] x^k.
template <std::size_t N>
constexpr double horner(const std::array<double, N>& c, double x) {
  double p = c[N - 1];
  for (std::size_t k = N - 1; k-- > 0;) p = p * x + c[k];
  return p;
}

// C(t) = (t - sin t)/t^3 = sum_k (-1)^k t^2k / (2k+3)!. Ten terms reach
// t = 1 with truncation 1/23! < 1e-22, i.e. < 1e-21 relative.
constexpr std::array<double, 10> kCSeries = [] {
  std::array<double, 10> c{};
  for (int k = 0; k < 10; ++k) c[k] = (k % 2 ? -1.0 : 1.0) / factorial(2 * k + 3);
  return c;
}();
// B'(t)/t = sum_{k>=1} (-1)^k 2k t^(2k-2) / (2k+2)!, in powers of t^2.
constexpr std::array<double, 10> kDBSeries = [] {
  std::array<double, 10> c{};
  for (int k = 1; k <= 10; ++k) c[k - 1] = (k % 2 ? -1.0 : 1.0) * (2.0 * k) / factorial(2 * k + 2);
  return c;
}();
// C'(t)/t = sum_{k>=1} (-1)^k 2k t^(2k-2) / (2k+3)!, in powers of t^2.
constexpr std::array<double, 10> kDCSeries = [] {
  std::array<double, 10> c{};
  for (int k = 1; k <= 10; ++k) c[k - 1] = (k % 2 ? -1.0 : 1.0) * (2.0 * k) / factorial(2 * k + 3);
  return c;
}();

// Below this angle C, B'/t and C'/t come from their series: the closed forms
// cancel ~t^3..t^5 out of O(1) terms, losing ~eps/t^2 relative (83 ulp of C
// at t = 0.1). At t >= 1 the loss is a few ulp.
constexpr double kSeriesBelow_rad = 1.0;

// |v| without underflow: squaredNorm() flushes components below ~1e-154 to
// zero, which would make log() of a 1e-200 rad rotation return 0.
double norm_no_underflow(const Vec3& v) {
  const double n2 = v.squaredNorm();
  if (n2 >= std::numeric_limits<double>::min() / std::numeric_limits<double>::epsilon()) {
    return std::sqrt(n2);
  }
  const double m = v.cwiseAbs().maxCoeff();
  if (m == 0.0) return 0.0;
  return m * (v / m).norm();
}

// [r]^2 = r r^T - |r|^2 I, with the diagonal -(r_j^2 + r_k^2) summed directly
// instead of subtracting |r|^2 (which was rounded through |r|): saves ~2 ulp
// of |r|^2 on the diagonal near |r| = pi.
Mat3 hat_squared(const Vec3& r) {
  const double xx = r.x() * r.x(), yy = r.y() * r.y(), zz = r.z() * r.z();
  const double xy = r.x() * r.y(), xz = r.x() * r.z(), yz = r.y() * r.z();
  Mat3 m;
  m << -(yy + zz), xy, xz,  //
      xy, -(xx + zz), yz,   //
      xz, yz, -(xx + yy);
  return m;
}

}  // namespace

Coefficients coefficients(double theta) {
  const double t2 = theta * theta;
  Coefficients c{};
  // Below 0.1 rad the Taylor series (truncation < 1e-20 relative) replaces the
  // closed forms of A and B, which are 0/0 at t = 0 (they do not cancel above).
  if (theta < 0.1) {
    c.sin_over_theta = 1.0 - t2 / 6.0 * (1.0 - t2 / 20.0 * (1.0 - t2 / 42.0 * (1.0 - t2 / 72.0)));
    c.one_minus_cos_over_t2 =
        0.5 - t2 / 24.0 * (1.0 - t2 / 30.0 * (1.0 - t2 / 56.0 * (1.0 - t2 / 90.0)));
  } else {
    const double s_half = std::sin(0.5 * theta);
    c.sin_over_theta = std::sin(theta) / theta;
    // 1 - cos t = 2 sin^2(t/2): no cancellation.
    c.one_minus_cos_over_t2 = 2.0 * s_half * s_half / t2;
  }
  c.t_minus_sin_over_t3 = theta < kSeriesBelow_rad ? horner(kCSeries, t2)
                                                   : (theta - std::sin(theta)) / (t2 * theta);
  return c;
}

Mat3 exp(const Vec3& r) {
  const double theta = r.norm();
  const Coefficients c = coefficients(theta);
  const double A = c.sin_over_theta, B = c.one_minus_cos_over_t2;
  const double cos_theta = std::cos(theta);
  const double sq[3] = {r.x() * r.x(), r.y() * r.y(), r.z() * r.z()};
  Mat3 R;
  // Eq. 3.9 entry by entry (Eq. 3.11). A diagonal entry is both
  // 1 - B (r_j^2 + r_k^2) and cos t + B r_i^2; using the form whose B-term is
  // the smaller one keeps that term <= (1 - cos t)/2 <= 1, halving the
  // rounding near |r| = pi, where the other form subtracts ~2 from 1.
  for (int i = 0; i < 3; ++i) {
    const double rest = sq[(i + 1) % 3] + sq[(i + 2) % 3];
    R(i, i) = sq[i] <= rest ? cos_theta + B * sq[i] : 1.0 - B * rest;
  }
  const double bxy = B * r.x() * r.y(), bxz = B * r.x() * r.z(), byz = B * r.y() * r.z();
  const double ax = A * r.x(), ay = A * r.y(), az = A * r.z();
  R(0, 1) = bxy - az;
  R(1, 0) = bxy + az;
  R(0, 2) = bxz + ay;
  R(2, 0) = bxz - ay;
  R(1, 2) = byz - ax;
  R(2, 1) = byz + ax;
  return R;
}

Eigen::Vector4d quaternion_from_matrix(const Mat3& R) {
  // Shepperd's method: pick the largest of 4w^2, 4x^2, 4y^2, 4z^2 as the pivot,
  // so the square root is taken of a number >= 1 and the other components come
  // from well-conditioned sums/differences of off-diagonal entries.
  const double tr = R.trace();
  const double d[4] = {tr, R(0, 0), R(1, 1), R(2, 2)};
  const int pivot = static_cast<int>(std::max_element(d, d + 4) - d);
  Eigen::Vector4d q;
  if (pivot == 0) {
    const double s = 2.0 * std::sqrt(1.0 + tr);  // 4w
    q << 0.25 * s, (R(2, 1) - R(1, 2)) / s, (R(0, 2) - R(2, 0)) / s, (R(1, 0) - R(0, 1)) / s;
  } else if (pivot == 1) {
    const double s = 2.0 * std::sqrt(1.0 + R(0, 0) - R(1, 1) - R(2, 2));  // 4x
    q << (R(2, 1) - R(1, 2)) / s, 0.25 * s, (R(0, 1) + R(1, 0)) / s, (R(0, 2) + R(2, 0)) / s;
  } else if (pivot == 2) {
    const double s = 2.0 * std::sqrt(1.0 - R(0, 0) + R(1, 1) - R(2, 2));  // 4y
    q << (R(0, 2) - R(2, 0)) / s, (R(0, 1) + R(1, 0)) / s, 0.25 * s, (R(1, 2) + R(2, 1)) / s;
  } else {
    const double s = 2.0 * std::sqrt(1.0 - R(0, 0) - R(1, 1) + R(2, 2));  // 4z
    q << (R(1, 0) - R(0, 1)) / s, (R(0, 2) + R(2, 0)) / s, (R(1, 2) + R(2, 1)) / s, 0.25 * s;
  }
  if (q[0] < 0.0) q = -q;
  return q.normalized();
}

Mat3 matrix_from_quaternion(const Eigen::Vector4d& q_wxyz) {
  const double w = q_wxyz[0], x = q_wxyz[1], y = q_wxyz[2], z = q_wxyz[3];
  Mat3 R;
  R << 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),  //
      2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),   //
      2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y);
  return R;
}

Vec3 log(const Mat3& R) {
  const Eigen::Vector4d q = quaternion_from_matrix(R);
  const double w = q[0];
  const Vec3 v = q.tail<3>();
  const double s = norm_no_underflow(v);  // sin(theta/2)
  if (s == 0.0) return Vec3::Zero();
  // theta = 2 atan2(s, w) is accurate for every angle; r = theta * v / s.
  double scale;
  const double u = s / w;  // w >= s*1e-4 whenever u is small
  if (w > 0.0 && u < 1e-4) {
    // 2 atan(u)/s = (2/w)(1 - u^2/3 + u^4/5 - ...): avoids 0/0 as s -> 0.
    const double u2 = u * u;
    scale = 2.0 / w * (1.0 - u2 / 3.0 + u2 * u2 / 5.0);
  } else {
    scale = 2.0 * std::atan2(s, w) / s;
  }
  Vec3 r = scale * v;
  if (w == 0.0) {
    // Exactly pi: r and -r are both logarithms; pick the one whose largest
    // component is positive so ties are resolved deterministically.
    Eigen::Index k = 0;
    r.cwiseAbs().maxCoeff(&k);
    if (r[k] < 0.0) r = -r;
  }
  return r;
}

double angle(const Mat3& R) {
  const Eigen::Vector4d q = quaternion_from_matrix(R);
  return 2.0 * std::atan2(norm_no_underflow(q.tail<3>()), q[0]);
}

Mat3 W(const Vec3& r) {
  // Eq. 3.59: W = I - (1-cos t)/t^2 [r] + (t - sin t)/t^3 [r]^2.
  const double theta = r.norm();
  const Coefficients c = coefficients(theta);
  Mat3 M = Mat3::Identity() - c.one_minus_cos_over_t2 * hat(r);
  M.noalias() += c.t_minus_sin_over_t3 * hat_squared(r);
  return M;
}

Mat3 W_inverse(const Vec3& r) {
  // W^-1 = I + 1/2 [r] + D [r]^2 with D = (1 - (t/2) cot(t/2)) / t^2.
  const double theta = r.norm();
  const double t2 = theta * theta;
  double D;
  if (theta < 0.1) {
    // 1/12 + t^2/720 + t^4/30240 + t^6/1209600 + t^8/47900160
    D = 1.0 / 12.0 + t2 * (1.0 / 720.0 + t2 * (1.0 / 30240.0 + t2 * (1.0 / 1209600.0 + t2 / 47900160.0)));
  } else {
    const double half = 0.5 * theta;
    D = (1.0 - half * std::cos(half) / std::sin(half)) / t2;
  }
  Mat3 M = Mat3::Identity() + 0.5 * hat(r);
  M.noalias() += D * hat_squared(r);
  return M;
}

Vec3 angular_acceleration(const Vec3& r, const Vec3& r_dot, const Vec3& r_ddot) {
  // Eq. 3.61, written as d/dt(W r_dot) = W r_ddot - (B'/t)(r.r_dot)(r x r_dot)
  //   + (C'/t)(r.r_dot) r x (r x r_dot) + C r_dot x (r x r_dot),
  // where B'/t = (t sin t + 2cos t - 2)/t^4 and C'/t = (3 sin t - t cos t - 2t)/t^5.
  const double theta = r.norm();
  const double t2 = theta * theta;
  const Coefficients c = coefficients(theta);
  double dB_over_t, dC_over_t;
  if (theta < kSeriesBelow_rad) {
    // -1/12 + t^2/180 - ... and -1/60 + t^2/1260 - ...
    dB_over_t = horner(kDBSeries, t2);
    dC_over_t = horner(kDCSeries, t2);
  } else {
    const double s = std::sin(theta), co = std::cos(theta);
    dB_over_t = (theta * s + 2.0 * co - 2.0) / (t2 * t2);
    dC_over_t = (3.0 * s - theta * co - 2.0 * theta) / (t2 * t2 * theta);
  }
  const double r_dot_r = r.dot(r_dot);
  const Vec3 r_x_rd = r.cross(r_dot);
  return W(r) * r_ddot - dB_over_t * r_dot_r * r_x_rd + dC_over_t * r_dot_r * r.cross(r_x_rd) +
         c.t_minus_sin_over_t3 * r_dot.cross(r_x_rd);
}

void geodesic_blend(Mat3& R, Vec3& omega, const Mat3& R_b, const Vec3& omega_b, double s, double s_rate,
                    bool with_rate) {
  const Vec3 D = log(R.transpose() * R_b);
  const Mat3 E = exp(s * D);
  if (with_rate) {
    const Vec3 D_dot = W_inverse(D) * (omega_b - exp(D).transpose() * omega);
    omega = E.transpose() * omega + W(s * D) * (s_rate * D + s * D_dot);
  }
  R = R * E;
}

Mat3 orthonormalize(const Mat3& R) { return matrix_from_quaternion(quaternion_from_matrix(R)); }

}  // namespace imuemu::so3
