#include "core/so3.hpp"

#include <algorithm>
#include <cmath>
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

Coefficients coefficients(double theta) {
  const double t2 = theta * theta;
  Coefficients c{};
  // Below 0.1 rad the Taylor series (truncation < 1e-20 relative) replaces the
  // closed forms whose numerators cancel: (t - sin t) loses ~1e-16/t^2.
  if (theta < 0.1) {
    c.sin_over_theta = 1.0 - t2 / 6.0 * (1.0 - t2 / 20.0 * (1.0 - t2 / 42.0 * (1.0 - t2 / 72.0)));
    c.one_minus_cos_over_t2 =
        0.5 - t2 / 24.0 * (1.0 - t2 / 30.0 * (1.0 - t2 / 56.0 * (1.0 - t2 / 90.0)));
    c.t_minus_sin_over_t3 =
        1.0 / 6.0 - t2 / 120.0 * (1.0 - t2 / 42.0 * (1.0 - t2 / 72.0 * (1.0 - t2 / 110.0)));
  } else {
    const double half = 0.5 * theta;
    const double s_half = std::sin(half);
    c.sin_over_theta = std::sin(theta) / theta;
    // 1 - cos t = 2 sin^2(t/2): no cancellation.
    c.one_minus_cos_over_t2 = 2.0 * s_half * s_half / t2;
    c.t_minus_sin_over_t3 = (theta - std::sin(theta)) / (t2 * theta);
  }
  return c;
}

Mat3 exp(const Vec3& r) {
  const double theta = r.norm();
  const Coefficients c = coefficients(theta);
  const Mat3 K = hat(r);
  // Eq. 3.9, with [r]^2 = r r^T - |r|^2 I written out to avoid a matrix product.
  Mat3 R = Mat3::Identity() + c.sin_over_theta * K;
  R.noalias() += c.one_minus_cos_over_t2 * (r * r.transpose() - (theta * theta) * Mat3::Identity());
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
  const double s = v.norm();  // sin(theta/2)
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
  return 2.0 * std::atan2(q.tail<3>().norm(), q[0]);
}

Mat3 W(const Vec3& r) {
  // Eq. 3.59: W = I - (1-cos t)/t^2 [r] + (t - sin t)/t^3 [r]^2.
  const double theta = r.norm();
  const Coefficients c = coefficients(theta);
  Mat3 M = Mat3::Identity() - c.one_minus_cos_over_t2 * hat(r);
  M.noalias() += c.t_minus_sin_over_t3 * (r * r.transpose() - (theta * theta) * Mat3::Identity());
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
  M.noalias() += D * (r * r.transpose() - t2 * Mat3::Identity());
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
  if (theta < 0.2) {
    dB_over_t = -1.0 / 12.0 + t2 * (1.0 / 180.0 + t2 * (-1.0 / 6720.0 + t2 * (1.0 / 453600.0 - t2 / 47900160.0)));
    dC_over_t = -1.0 / 60.0 + t2 * (1.0 / 1260.0 + t2 * (-1.0 / 60480.0 + t2 * (1.0 / 4989600.0 - t2 / 622702080.0)));
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

Mat3 orthonormalize(const Mat3& R) { return matrix_from_quaternion(quaternion_from_matrix(R)); }

}  // namespace imuemu::so3
