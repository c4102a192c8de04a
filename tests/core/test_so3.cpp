// SO(3) maps (thesis §3.2, §3.6.1) against independent long double references:
//   exp  = sum_k [r]^k / k!                       (matrix power series)
//   W    = sum_k (-1)^k [r]^k / (k+1)!            (the series the thesis sums to Eq. 3.59)
//   W^-1 = adjugate inverse of that W
//   log  = atan2 angle + axis from the symmetric part, of the polar (nearest
//          orthogonal) factor of the double matrix
//   d/dt (W r_dot) = complex-step derivative of the W series along a curve.
// None of these shares a formula or a branch threshold with core/so3.cpp.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <array>
#include <cmath>
#include <complex>
#include <iostream>
#include <limits>
#include <numbers>
#include <random>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "core/so3.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_core_test_so3 {
namespace imuemu { using namespace ::imuemu; }

namespace {

using imuemu::Mat3;
using imuemu::Vec3;
namespace so3 = imuemu::so3;

using LD = long double;
using LVec = Eigen::Matrix<LD, 3, 1>;
using LMat = Eigen::Matrix<LD, 3, 3>;

constexpr double kPi = std::numbers::pi;
constexpr double kEps = std::numeric_limits<double>::epsilon();
// Acceptance bound of the sweep: absolute error of any entry/component.
constexpr double kAbsBound = 1e-15;

// ---------------------------------------------------------------- references

LMat hat_l(const LVec& r) {
  LMat m;
  m << 0, -r.z(), r.y(), r.z(), 0, -r.x(), -r.y(), r.x(), 0;
  return m;
}

// exp([r]) = sum_k [r]^k / k!. For |r| <= pi the largest term is pi^3/3! and
// 80 terms leave a truncation below 1e-60: the rounding (~1e-18) dominates.
LMat exp_ref(const Vec3& r) {
  const LMat K = hat_l(r.cast<LD>());
  LMat term = LMat::Identity();
  LMat sum = LMat::Identity();
  for (int k = 1; k <= 80; ++k) {
    term = (term * K) / static_cast<LD>(k);
    sum += term;
  }
  return sum;
}

// W = sum_k (-1)^k [r]^k / (k+1)!  (thesis §3.6.1, before Eq. 3.59).
LMat W_ref(const Vec3& r) {
  const LMat K = hat_l(r.cast<LD>());
  LMat term = LMat::Identity();
  LMat sum = LMat::Identity();
  for (int k = 1; k <= 80; ++k) {
    term = (term * (-K)) / static_cast<LD>(k + 1);
    sum += term;
  }
  return sum;
}

LMat inverse_l(const LMat& M) {
  LMat adj;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      const int i1 = (j + 1) % 3, i2 = (j + 2) % 3, j1 = (i + 1) % 3, j2 = (i + 2) % 3;
      adj(i, j) = M(i1, j1) * M(i2, j2) - M(i1, j2) * M(i2, j1);
    }
  }
  const LD det = M.row(0).dot(adj.col(0));
  return adj / det;
}

struct LogRef {
  LVec r;
  LD angle;
};

// Logarithm of the nearest rotation to R (polar factor, Newton iteration
// X <- (X + X^-T)/2, quadratic: 8 steps are plenty from 1e-16 off SO(3)).
// Angle from atan2(|sin|, cos); axis from vee(R) below pi/2 and from the
// largest column of the symmetric part (1 - cos) n n^T above, signed by vee(R).
LogRef log_ref(const Mat3& R_d) {
  LMat X = R_d.cast<LD>();
  for (int i = 0; i < 8; ++i) X = (X + inverse_l(X).transpose()) / 2;
  const LVec a(0.5L * (X(2, 1) - X(1, 2)), 0.5L * (X(0, 2) - X(2, 0)), 0.5L * (X(1, 0) - X(0, 1)));
  const LD c = (X.trace() - 1) / 2;
  const LD s = a.norm();
  const LD angle = std::atan2(s, c);
  LogRef out{LVec::Zero(), angle};
  if (s == 0 && c > 0) return out;
  if (angle < std::numbers::pi_v<LD> / 2) {
    out.r = (angle / s) * a;
    return out;
  }
  const LMat S = (X + X.transpose()) / 2 - c * LMat::Identity();
  Eigen::Index j = 0;
  S.diagonal().maxCoeff(&j);
  LVec n = S.col(j).normalized();
  if (n.dot(a) < 0) n = -n;
  out.r = angle * n;
  return out;
}

// ------------------------------------------------------------- sweep inputs

std::vector<double> sweep_angles() {
  return {0.0,  1e-300, 1e-200,     1e-20,      1e-12,      1e-8,        1e-6, 1e-4,
          1e-3, 0.05,   0.0999,     0.1,        0.1001,     0.2,         0.5,  1.0,
          2.0,  3.0,    kPi - 1e-3, kPi - 1e-6, kPi - 1e-9, kPi - 1e-12, kPi};
}

std::vector<Vec3> sweep_axes() {
  std::vector<Vec3> axes = {Vec3::UnitX(),
                            Vec3::UnitY(),
                            Vec3::UnitZ(),
                            -Vec3::UnitX(),
                            -Vec3::UnitY(),
                            -Vec3::UnitZ(),
                            Vec3(1, 1, 0) / std::sqrt(2.0),
                            Vec3(1, 1, 1) / std::sqrt(3.0),
                            Vec3(1, -1, 1) / std::sqrt(3.0),
                            -Vec3(1, 1, 1) / std::sqrt(3.0)};
  std::mt19937_64 rng(20240611);
  std::normal_distribution<double> n01(0.0, 1.0);
  for (int i = 0; i < 200; ++i) {
    const Vec3 v(n01(rng), n01(rng), n01(rng));
    axes.push_back(v.normalized());
  }
  return axes;
}

struct Worst {
  explicit Worst(std::string n) : name(std::move(n)) {}
  std::string name;
  double err = 0.0;
  std::string where;
  void update(double e, double angle, const Vec3& axis) {
    if (e > err || where.empty()) {
      err = std::max(err, e);
      std::ostringstream os;
      os.precision(17);
      os << "angle " << angle << " axis (" << axis.transpose() << ")";
      where = os.str();
    }
  }
  void report(::testing::Test* /*unused*/) const {
    std::cout << "[ worst    ] " << name << ": " << err << " at " << where << "\n";
    ::testing::Test::RecordProperty(name, std::to_string(err));
  }
};

double max_abs_diff(const Mat3& a, const LMat& b) {
  return static_cast<double>((a.cast<LD>() - b).cwiseAbs().maxCoeff());
}
double max_abs_diff(const Vec3& a, const LVec& b) {
  return static_cast<double>((a.cast<LD>() - b).cwiseAbs().maxCoeff());
}

// ------------------------------------------------------------------- tests

TEST(So3Reference, ReferencesAgreeWithClosedForms) {
  // Guards the references themselves: the series against Rodrigues / Eq. 3.59
  // evaluated in long double where those closed forms do not cancel.
  for (const double t : {0.7, 1.3, 2.9}) {
    const LVec n = LVec(1, -2, 2) / 3;
    const Vec3 r = (static_cast<LD>(t) * n).cast<double>();
    const LVec rl = r.cast<LD>();
    const LD th = rl.norm();
    const LMat K = hat_l(rl);
    const LMat R =
        LMat::Identity() + std::sin(th) / th * K + (1 - std::cos(th)) / (th * th) * K * K;
    const LMat Wc = LMat::Identity() - (1 - std::cos(th)) / (th * th) * K +
                    (th - std::sin(th)) / (th * th * th) * K * K;
    EXPECT_LT(static_cast<double>((exp_ref(r) - R).cwiseAbs().maxCoeff()), 1e-17);
    EXPECT_LT(static_cast<double>((W_ref(r) - Wc).cwiseAbs().maxCoeff()), 1e-17);
    const LogRef lr = log_ref(R.cast<double>());
    EXPECT_LT(static_cast<double>((lr.r - rl).cwiseAbs().maxCoeff()), 1e-15);
  }
}

TEST(So3, ExpLogWSweepAgainstLongDouble) {
  const auto angles = sweep_angles();
  const auto axes = sweep_axes();
  Worst exp_w{"exp_max_abs_err"}, log_w{"log_max_abs_err"}, ang_w{"angle_max_abs_err"},
      logrel_w{"log_small_angle_max_rel_err"}, W_w{"W_max_abs_err"},
      Winv_w{"W_inverse_max_abs_err"}, WWinv_w{"W_times_W_inverse_minus_I"},
      orth_w{"exp_orthonormality_err"};
  for (const double angle : angles) {
    for (const Vec3& axis : axes) {
      const Vec3 r = angle * axis;

      // exp of the same double r.
      const LMat R_ref = exp_ref(r);
      const Mat3 R = so3::exp(r);
      exp_w.update(max_abs_diff(R, R_ref), angle, axis);
      // R^T R - I in long double, so the check adds no rounding of its own.
      const LMat Rl = R.cast<LD>();
      orth_w.update(
          static_cast<double>((Rl.transpose() * Rl - LMat::Identity()).cwiseAbs().maxCoeff()),
          angle, axis);

      // log of the double-rounded matrix vs the long double log of that matrix.
      const Mat3 R_d = R_ref.cast<double>();
      const LogRef lr = log_ref(R_d);
      const Vec3 l = so3::log(R_d);
      double e = max_abs_diff(l, lr.r);
      if (angle == kPi) e = std::min(e, max_abs_diff(l, LVec(-lr.r)));  // r and -r
      log_w.update(e, angle, axis);
      const double e_angle =
          std::max(std::abs(static_cast<double>(so3::angle(R_d) - lr.angle)),
                   std::abs(static_cast<double>(l.cast<LD>().norm() - lr.angle)));
      ang_w.update(e_angle, angle, axis);
      if (angle > 0.0 && angle <= 1e-3) {
        // Tiny rotations must keep full relative accuracy, down to 1e-300 rad.
        logrel_w.update(e / static_cast<double>(lr.r.cwiseAbs().maxCoeff()), angle, axis);
      }

      // W and its inverse.
      const LMat Wl = W_ref(r);
      const Mat3 Wd = so3::W(r);
      const Mat3 Wi = so3::W_inverse(r);
      W_w.update(max_abs_diff(Wd, Wl), angle, axis);
      Winv_w.update(max_abs_diff(Wi, inverse_l(Wl)), angle, axis);
      WWinv_w.update((Wd * Wi - Mat3::Identity()).cwiseAbs().maxCoeff(), angle, axis);
    }
  }
  for (const Worst* w : {&exp_w, &orth_w, &log_w, &ang_w, &logrel_w, &W_w, &Winv_w, &WWinv_w}) {
    w->report(nullptr);
  }
  EXPECT_LE(exp_w.err, kAbsBound) << exp_w.where;
  // R^T R - I sums three products of erroneous entries: up to ~2 sqrt(3) times
  // the entry error in principle, ~1.5x in practice.
  EXPECT_LE(orth_w.err, 2 * kAbsBound) << orth_w.where;
  EXPECT_LE(log_w.err, kAbsBound) << log_w.where;
  EXPECT_LE(ang_w.err, kAbsBound) << ang_w.where;
  EXPECT_LE(logrel_w.err, 4.0 * kEps) << logrel_w.where;
  EXPECT_LE(W_w.err, kAbsBound) << W_w.where;
  EXPECT_LE(Winv_w.err, kAbsBound) << Winv_w.where;
  EXPECT_LE(WWinv_w.err, kAbsBound) << WWinv_w.where;
}

TEST(So3, CoefficientsAgainstLongDoubleSeries) {
  // A = sin t/t, B = (1-cos t)/t^2, C = (t - sin t)/t^3 as alternating series
  // sum (-1)^k t^2k / (2k+m)!, m = 1, 2, 3, in long double (converges with
  // terms <= ~1 for t <= pi). B and C (in [0.1, 0.5]) by relative error; A by
  // absolute error, as it goes to 0 at pi where only A*t = sin t matters.
  auto series = [](LD t, int m) {
    LD fact = 1;
    for (int i = 2; i <= m; ++i) fact *= i;
    LD term = 1 / fact, sum = term;
    for (int k = 0; k < 60; ++k) {
      term *= -t * t / static_cast<LD>((2 * k + m + 1) * (2 * k + m + 2));
      sum += term;
    }
    return sum;
  };
  Worst wa{"coef_A_max_abs_err"}, wb{"coef_B_max_rel_err"}, wc{"coef_C_max_rel_err"};
  std::vector<double> thetas = sweep_angles();
  for (double t = 0.0; t < kPi; t += 0.0137) thetas.push_back(t);
  for (const double t : thetas) {
    const so3::Coefficients c = so3::coefficients(t);
    const LD tl = t;
    auto rel = [](double v, LD ref) { return static_cast<double>(std::abs((v - ref) / ref)); };
    wa.update(static_cast<double>(std::abs(c.sin_over_theta - series(tl, 1))), t, Vec3::Zero());
    wb.update(rel(c.one_minus_cos_over_t2, series(tl, 2)), t, Vec3::Zero());
    wc.update(rel(c.t_minus_sin_over_t3, series(tl, 3)), t, Vec3::Zero());
  }
  for (const Worst* w : {&wa, &wb, &wc}) w->report(nullptr);
  EXPECT_LE(wa.err, 4 * kEps) << wa.where;
  EXPECT_LE(wb.err, 4 * kEps) << wb.where;
  EXPECT_LE(wc.err, 16 * kEps) << wc.where;
}

// -------------------------------------------------- angular acceleration

using CL = std::complex<LD>;
using CVec = std::array<CL, 3>;

CVec cross_c(const CVec& a, const CVec& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}

// omega = W(r) r_dot = sum_k (-1)^k [r]^k r_dot / (k+1)!, in complex long double.
CVec omega_series(const CVec& r, const CVec& r_dot) {
  CVec term = r_dot, sum = r_dot;
  for (int k = 1; k <= 80; ++k) {
    const CVec c = cross_c(r, term);
    for (int i = 0; i < 3; ++i) {
      term[i] = -c[i] / static_cast<LD>(k + 1);
      sum[i] += term[i];
    }
  }
  return sum;
}

// Reference d/dt (W(r(t)) r_dot(t)) at t = 0 for r(t) = a + b t + c t^2 + d t^3,
// by the complex step: f'(0) = Im f(i h) / h + O(h^2), with no cancellation.
LVec angular_acceleration_ref(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d) {
  const LD h = 1e-30L;
  const CL t(0, h);
  CVec r, rd;
  for (int i = 0; i < 3; ++i) {
    const LD ai = a[i], bi = b[i], ci = c[i], di = d[i];
    r[i] = ai + t * (bi + t * (ci + t * di));
    rd[i] = bi + t * (2 * ci + t * (3 * di));
  }
  const CVec w = omega_series(r, rd);
  return LVec(w[0].imag() / h, w[1].imag() / h, w[2].imag() / h);
}

TEST(So3, AngularAccelerationAgainstComplexStep) {
  const std::vector<double> norms = {0.0,    1e-300, 1e-12,  1e-8,   1e-6,   1e-4, 1e-2,      0.05,
                                     0.0999, 0.1,    0.1001, 0.15,   0.1999, 0.2,  0.2001,    0.3,
                                     0.5,    0.9999, 1.0,    1.0001, 2.0,    3.0,  kPi - 1e-6};
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Worst w{"angular_acceleration_max_abs_err"};
  Worst wz{"angular_acceleration_r0_abs_err"};
  for (const double n : norms) {
    for (int i = 0; i < 60; ++i) {
      const Vec3 axis = Vec3(u(rng), u(rng), u(rng)).normalized();
      const Vec3 a = n * axis;
      Vec3 b(u(rng), u(rng), u(rng));
      if (i % 4 == 1) b = u(rng) * axis;           // spin about the axis only
      if (i % 4 == 2) b = b - b.dot(axis) * axis;  // perpendicular rate
      const Vec3 c(u(rng), u(rng), u(rng));
      const Vec3 d(u(rng), u(rng), u(rng));
      const LVec ref = angular_acceleration_ref(a, b, c, d);
      const Vec3 got = so3::angular_acceleration(a, b, 2.0 * c);
      // |b|, |2c| <= 2*sqrt(3): errors are absolute for O(1) rates.
      w.update(max_abs_diff(got, ref), n, axis);
    }
  }
  // At r = 0: alpha = r_ddot exactly (all other terms carry a factor r).
  const Vec3 rd(0.3, -0.2, 0.9), rdd(1.0, 2.0, -0.5);
  wz.update((so3::angular_acceleration(Vec3::Zero(), rd, rdd) - rdd).cwiseAbs().maxCoeff(), 0.0,
            Vec3::Zero());
  w.report(nullptr);
  wz.report(nullptr);
  EXPECT_LE(w.err, 1.5 * kAbsBound) << w.where;
  EXPECT_EQ(wz.err, 0.0);
}

// ---------------------------------------------------------------- round trips

TEST(So3, RoundTrips) {
  const auto axes = sweep_axes();
  Worst le{"log_exp_roundtrip_err"}, el{"exp_log_roundtrip_err"}, qm{"quaternion_roundtrip_err"},
      qr{"quaternion_vs_long_double_err"}, mq{"matrix_from_quaternion_err"};
  for (const double angle : sweep_angles()) {
    for (const Vec3& axis : axes) {
      const Vec3 r = angle * axis;
      const Mat3 R = so3::exp(r);
      // log(exp(r)) == r needs |r| < pi strictly: at the double nearest pi the
      // rounded matrix no longer knows the sign of r.
      if (angle < kPi) le.update((so3::log(R) - r).cwiseAbs().maxCoeff(), angle, axis);
      el.update((so3::exp(so3::log(R)) - R).cwiseAbs().maxCoeff(), angle, axis);

      // Quaternion of R vs the long double q = (cos t/2, sin t/2 n) of r.
      const Eigen::Vector4d q = so3::quaternion_from_matrix(R);
      const LVec rl = r.cast<LD>();
      const LD th = rl.norm();
      Eigen::Matrix<LD, 4, 1> q_ref;
      q_ref << std::cos(th / 2), (th > 0 ? std::sin(th / 2) / th : 0.5L) * rl;
      LD dq = (q.cast<LD>() - q_ref).cwiseAbs().maxCoeff();
      if (angle >= kPi - 1e-9) dq = std::min(dq, (q.cast<LD>() + q_ref).cwiseAbs().maxCoeff());
      qr.update(static_cast<double>(dq), angle, axis);
      EXPECT_GE(q[0], 0.0);
      EXPECT_NEAR(q.norm(), 1.0, 2 * kEps);

      // matrix_from_quaternion of the long double q vs the long double exp.
      const Mat3 Rq = so3::matrix_from_quaternion(q_ref.cast<double>());
      mq.update(max_abs_diff(Rq, exp_ref(r)), angle, axis);
      // q -> R -> q.
      const Eigen::Vector4d q2 = so3::quaternion_from_matrix(so3::matrix_from_quaternion(q));
      double e = (q2 - q).cwiseAbs().maxCoeff();
      if (q[0] < 1e-8) e = std::min(e, (q2 + q).cwiseAbs().maxCoeff());  // w ~ 0: q ~ -q
      qm.update(e, angle, axis);
    }
  }
  for (const Worst* w : {&le, &el, &qr, &mq, &qm}) w->report(nullptr);
  // Each round trip composes two maps that are each within kAbsBound, and near
  // pi the log amplifies a perturbation of R by up to (t/2)/sin(t/2) < pi/2.
  EXPECT_LE(le.err, 2 * kAbsBound) << le.where;
  EXPECT_LE(el.err, 2 * kAbsBound) << el.where;
  EXPECT_LE(qr.err, kAbsBound) << qr.where;
  EXPECT_LE(mq.err, kAbsBound) << mq.where;
  EXPECT_LE(qm.err, kAbsBound) << qm.where;
}

TEST(So3, LogAtPiIsDeterministicAndValid) {
  // Exactly pi about tied axes: the returned r must be a logarithm (exp(r) = R)
  // of norm pi whose largest-magnitude component is positive.
  const std::vector<Vec3> axes = {Vec3(1, 1, 0) / std::sqrt(2.0), Vec3(-1, 1, 1) / std::sqrt(3.0),
                                  Vec3(0, 0, -1), Vec3(0, -1, 0)};
  for (const Vec3& n : axes) {
    const Mat3 R = 2.0 * n * n.transpose() - Mat3::Identity();  // rotation by pi about n
    const Vec3 l = so3::log(R);
    EXPECT_NEAR(l.norm(), kPi, 4 * kEps);
    EXPECT_LT((so3::exp(l) - R).cwiseAbs().maxCoeff(), kAbsBound);
    Eigen::Index k = 0;
    l.cwiseAbs().maxCoeff(&k);
    EXPECT_GT(l[k], 0.0);
  }
}

TEST(So3, HatVee) {
  const Vec3 r(0.3, -1.2, 2.5), v(-0.7, 0.1, 0.4);
  EXPECT_EQ(so3::hat(r) * v, r.cross(v));
  EXPECT_EQ(so3::vee(so3::hat(r)), r);
  EXPECT_EQ(so3::hat(r).transpose(), -so3::hat(r));
}

}  // namespace
}  // namespace unity_core_test_so3
