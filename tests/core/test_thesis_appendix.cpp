// The thesis' Appendix A and B cases (Table 1, Table 2 left and right) as
// measurements: the numbers behind Figures 2-8, printed and bounded.
//
//   Fig. 2/3  Table 1, geodesic (Eq. 3.44): endpoints exact, constant rate,
//             heading differs from linear heading interpolation.
//   Fig. 4    Table 1, Lemma 3.22 warp, (sigma, mu) = (1, 3) stays on the
//             geodesic arc, (10, -5) overshoots it (roll leaves [5, 30] deg).
//   Fig. 5/6  Table 2 left/right, Park-Ravani §3.6.1: smooth for 4 knots,
//             erratic for 10 (error growth ~(2 + sqrt 3) per segment).
//   Fig. 7/8  Table 2 left/right, §3.6.2: geodesic + literal Eq. 3.68 bump
//             smoothing (Delta = 10, Phi(t_j - t_i), t in seconds) on the global
//             exponential coordinates r = log R, written out here as an
//             independent reference.
// All attitude-only, 100 Hz output (Appendix A, B). Angular rates are from
// finite differences of the output rotations, omega_b = vee(log(R_k^T R_k+1))/dt,
// except where a test says "analytic".
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <vector>

#include "core/interpolation.hpp"
#include "core/so3.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_core_test_thesis_appendix {
namespace imuemu { using namespace ::imuemu; }

namespace {

using imuemu::kNsPerSecond;
using imuemu::Mat3;
using imuemu::Pose;
using imuemu::TimeNs;
using imuemu::Vec3;
namespace interp = imuemu::interp;
namespace so3 = imuemu::so3;

constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180.0;
constexpr TimeNs kStepNs = kNsPerSecond / 100;  // 100 Hz
constexpr double kStepS = 0.01;

struct Hpr {
  double heading_deg, pitch_deg, roll_deg;
};

// Eq. 1.2, R_b^l = R_z(psi) R_y(theta) R_x(gamma), built here from Eigen's
// AngleAxis as an independent reference.
Mat3 rotation_from_hpr_deg(const Hpr& a) {
  return (Eigen::AngleAxisd(a.heading_deg * kDeg, Vec3::UnitZ()) *
          Eigen::AngleAxisd(a.pitch_deg * kDeg, Vec3::UnitY()) *
          Eigen::AngleAxisd(a.roll_deg * kDeg, Vec3::UnitX()))
      .toRotationMatrix();
}

Hpr hpr_deg(const Mat3& R) {
  return {std::atan2(R(1, 0), R(0, 0)) / kDeg, std::atan2(-R(2, 0), std::hypot(R(2, 1), R(2, 2))) / kDeg,
          std::atan2(R(2, 1), R(2, 2)) / kDeg};
}

double wrap_deg(double a) { return std::remainder(a, 360.0); }

double distance_deg(const Mat3& a, const Mat3& b) { return so3::angle(a.transpose() * b) / kDeg; }

struct Knot {
  double t_s;
  Hpr hpr;
};

const std::vector<Knot> kTable1 = {{1, {20, 0, 30}}, {2, {20, 10, 5}}};
const std::vector<Knot> kTable2Right = {{1, {10, 0, 0}},   {2, {15, 3, 5}},   {3, {30, 10, 15}}, {4, {40, 20, 15}},
                                        {5, {50, 25, 20}}, {6, {40, 20, 30}}, {7, {35, 25, 35}}, {8, {30, 30, 40}},
                                        {9, {25, 35, 45}}, {10, {45, 25, 50}}};
const std::vector<Knot> kTable2Left(kTable2Right.begin(), kTable2Right.begin() + 4);

std::vector<Pose> poses(const std::vector<Knot>& table) {
  std::vector<Pose> out;
  for (const Knot& k : table) {
    out.push_back({static_cast<TimeNs>(std::llround(k.t_s * 1e9)), Vec3::Zero(), rotation_from_hpr_deg(k.hpr)});
  }
  return out;
}

std::vector<TimeNs> output_times(const std::vector<Pose>& knots, TimeNs step = kStepNs) {
  std::vector<TimeNs> t;
  for (TimeNs x = knots.front().t_ns; x <= knots.back().t_ns; x += step) t.push_back(x);
  return t;
}

std::vector<Mat3> run(const std::vector<Knot>& table, interp::Method method, double sigma = 1.0, double mu = 1.0) {
  const auto knots = poses(table);
  interp::Options o;
  o.method = method;
  o.sigma = sigma;
  o.mu = mu;
  std::vector<Mat3> R;
  for (const Pose& p : interp::interpolate(knots, output_times(knots), o)) R.push_back(p.attitude);
  return R;
}

// Literal Eq. 3.68 with Phi of Eq. 3.66 evaluated at t_j - t_i in seconds:
// at 100 Hz and Delta = 10 the weights only span Phi(0.1 s)/Phi(0) = 0.990,
// so this is nearly a 21-sample moving average (the thesis' choice).
std::vector<Mat3> smoothed(const std::vector<Knot>& table, int delta) {
  const std::vector<Mat3> g = run(table, interp::Method::geodesic);
  const std::size_t m = g.size();
  std::vector<Vec3> r(m);
  for (std::size_t i = 0; i < m; ++i) r[i] = so3::log(g[i]);  // §3.6.2: [r(t)] = log R(t)
  std::vector<Mat3> out;
  const std::size_t d = static_cast<std::size_t>(delta);
  for (std::size_t i = 0; i < m; ++i) {
    Vec3 num = Vec3::Zero();
    double den = 0.0;
    for (std::size_t j = (i >= d ? i - d : 0); j <= std::min(m - 1, i + d); ++j) {
      const double t = (static_cast<double>(j) - static_cast<double>(i)) * kStepS;
      const double w = std::exp(-1.0 / (1.0 - t * t));
      num += w * r[j];
      den += w;
    }
    out.push_back(so3::exp(num / den));  // R_Delta = exp(r~)
  }
  return out;
}

std::vector<Vec3> body_rates_rad_s(const std::vector<Mat3>& R, double dt_s = kStepS) {
  std::vector<Vec3> w;
  for (std::size_t k = 0; k + 1 < R.size(); ++k) w.push_back(so3::log(R[k].transpose() * R[k + 1]) / dt_s);
  return w;
}

double peak_rate_deg_s(const std::vector<Mat3>& R) {
  double peak = 0.0;
  for (const Vec3& w : body_rates_rad_s(R)) peak = std::max(peak, w.norm() / kDeg);
  return peak;
}

// Largest |heading - heading of the piecewise-linear interpolation of the
// knots' headings| (wrapped), at 100 Hz.
double heading_excursion_deg(const std::vector<Knot>& table, const std::vector<Mat3>& R) {
  double worst = 0.0;
  for (std::size_t k = 0; k < R.size(); ++k) {
    const double t = table.front().t_s + static_cast<double>(k) * kStepS;
    std::size_t i = 0;
    while (i + 2 < table.size() && t > table[i + 1].t_s) ++i;
    const double tau = (t - table[i].t_s) / (table[i + 1].t_s - table[i].t_s);
    const double lin = table[i].hpr.heading_deg + tau * (table[i + 1].hpr.heading_deg - table[i].hpr.heading_deg);
    worst = std::max(worst, std::abs(wrap_deg(hpr_deg(R[k]).heading_deg - lin)));
  }
  return worst;
}

// Peak body rate of the Park-Ravani solution from its polynomial (analytic,
// omega_b = W(r) r' / h, Eq. 3.60), sampled 1000 times per segment: the 100 Hz
// finite differences alias once the rotation per sample exceeds 180 deg.
double park_ravani_peak_rate_deg_s(const std::vector<Knot>& table) {
  interp::Options o;
  o.method = interp::Method::park_ravani;
  double peak = 0.0;
  for (const auto& s : interp::park_ravani_coefficients(poses(table), o)) {
    for (int j = 0; j <= 1000; ++j) {
      const double tau = j / 1000.0;
      const Vec3 r = ((s.a * tau + s.b) * tau + s.c) * tau;
      const Vec3 r_dot = (3.0 * s.a * tau + 2.0 * s.b) * tau + s.c;
      peak = std::max(peak, (so3::W(r) * r_dot).norm() / s.duration_s / kDeg);
    }
  }
  return peak;
}

// ------------------------------------------------------------- Appendix A

TEST(ThesisAppendixA, Fig2Fig3GeodesicTable1) {
  const auto R = run(kTable1, interp::Method::geodesic);
  ASSERT_EQ(R.size(), 101u);
  const auto knots = poses(kTable1);
  EXPECT_LT(distance_deg(R.front(), knots[0].attitude), 1e-12);
  EXPECT_LT(distance_deg(R.back(), knots[1].attitude), 1e-12);
  EXPECT_NEAR(hpr_deg(R.back()).pitch_deg, 10.0, 1e-12);
  EXPECT_NEAR(hpr_deg(R.back()).roll_deg, 5.0, 1e-12);

  // Constant body rate = relative angle / 1 s (Eigen's AngleAxis as reference).
  const double angle_deg = Eigen::AngleAxisd(knots[0].attitude.transpose() * knots[1].attitude).angle() / kDeg;
  double rate_spread = 0.0;
  for (const Vec3& w : body_rates_rad_s(R)) rate_spread = std::max(rate_spread, std::abs(w.norm() / kDeg - angle_deg));

  // Fig. 3: linear interpolation of the angles keeps heading at 20 deg; the
  // geodesic does not.
  double max_dev = 0.0, at_s = 0.0;
  for (std::size_t k = 0; k < R.size(); ++k) {
    const double dev = std::abs(hpr_deg(R[k]).heading_deg - 20.0);
    if (dev > max_dev) max_dev = dev, at_s = 1.0 + 0.01 * static_cast<double>(k);
  }
  std::printf("Fig 2/3: geodesic relative angle %.4f deg, rate spread %.2e deg/s; heading deviates from linear "
              "(20 deg) by up to %.4f deg at t = %.2f s\n",
              angle_deg, rate_spread, max_dev, at_s);
  EXPECT_LT(rate_spread, 1e-9);
  EXPECT_GT(max_dev, 0.2);
  EXPECT_LT(max_dev, 2.0);
}

TEST(ThesisAppendixA, Fig4MinimumAccelerationTable1) {
  const auto knots = poses(kTable1);
  const double theta_deg = Eigen::AngleAxisd(knots[0].attitude.transpose() * knots[1].attitude).angle() / kDeg;
  const auto geo = run(kTable1, interp::Method::geodesic);
  // The geodesic arc and its extension beyond R_2, finely sampled, to measure
  // how far a curve leaves the arc: R_1 exp(s log(R_1^T R_2)), s in [0, 1].
  const Vec3 r12 = so3::log(knots[0].attitude.transpose() * knots[1].attitude);
  auto distance_from_arc_deg = [&](const Mat3& R) {
    double best = 1e9;
    for (int j = 0; j <= 2000; ++j) best = std::min(best, distance_deg(R, knots[0].attitude * so3::exp(j / 2000.0 * r12)));
    return best;
  };
  struct Result {
    double timing_dev_deg, arc_dev_deg, roll_min, roll_max, peak_rate;
  };
  auto measure = [&](double sigma, double mu) {
    const auto R = run(kTable1, interp::Method::min_acceleration, sigma, mu);
    Result res{0.0, 0.0, 1e9, -1e9, peak_rate_deg_s(R)};
    for (std::size_t k = 0; k < R.size(); ++k) {
      res.timing_dev_deg = std::max(res.timing_dev_deg, distance_deg(R[k], geo[k]));
      res.arc_dev_deg = std::max(res.arc_dev_deg, distance_from_arc_deg(R[k]));
      res.roll_min = std::min(res.roll_min, hpr_deg(R[k]).roll_deg);
      res.roll_max = std::max(res.roll_max, hpr_deg(R[k]).roll_deg);
    }
    EXPECT_LT(distance_deg(R.front(), knots[0].attitude), 1e-12);
    EXPECT_LT(distance_deg(R.back(), knots[1].attitude), 1e-12);
    std::printf("Fig 4 (sigma, mu) = (%g, %g): max deviation from the geodesic at equal time %.3f deg, from the "
                "geodesic arc %.3f deg; roll [%.2f, %.2f] deg; peak rate %.2f deg/s\n",
                sigma, mu, res.timing_dev_deg, res.arc_dev_deg, res.roll_min, res.roll_max, res.peak_rate);
    return res;
  };
  const Result mild = measure(1.0, 3.0);
  const Result wild = measure(10.0, -5.0);
  const double grid_deg = theta_deg / 2000.0;

  // (1, 3): p = 2 tau^3 - 2 tau^2 + tau is monotone in [0, 1], so the curve is
  // the geodesic arc re-timed: off the arc by nothing, off in time by
  // max|p - tau| theta = (8/27) theta; roll stays between the knots' 30 and 5.
  EXPECT_LT(mild.arc_dev_deg, grid_deg);
  EXPECT_NEAR(mild.timing_dev_deg, 8.0 / 27.0 * theta_deg, 0.01 * theta_deg);
  EXPECT_GE(mild.roll_min, 5.0 - 1e-9);
  EXPECT_LE(mild.roll_max, 30.0 + 1e-9);
  // (10, -5): p = 3 tau^3 - 12 tau^2 + 10 tau peaks at tau* = (24 - sqrt 216)/18
  // with p* = 2.37, overshooting R_2 along the geodesic by (p* - 1) theta.
  const double tau_star = (24.0 - std::sqrt(216.0)) / 18.0;
  const double p_star = ((3.0 * tau_star - 12.0) * tau_star + 10.0) * tau_star;
  EXPECT_NEAR(wild.arc_dev_deg, (p_star - 1.0) * theta_deg, 0.02 * theta_deg);
  EXPECT_LT(wild.roll_min, -25.0);  // far outside [5, 30]
  // Peak rates sigma theta and mu theta (per second); forward differences at
  // 100 Hz read them within a few percent.
  EXPECT_NEAR(mild.peak_rate, 3.0 * theta_deg, 0.03 * 3.0 * theta_deg);
  EXPECT_NEAR(wild.peak_rate, 10.0 * theta_deg, 0.03 * 10.0 * theta_deg);
  EXPECT_GT(wild.peak_rate, 3.0 * mild.peak_rate);
}

// ------------------------------------------------------------- Appendix B

TEST(ThesisAppendixB, Fig5To8ParkRavaniAgainstBumpSmoothedGeodesic) {
  const auto pr4 = run(kTable2Left, interp::Method::park_ravani);
  const auto pr10 = run(kTable2Right, interp::Method::park_ravani);
  const auto sm4 = smoothed(kTable2Left, 10);
  const auto sm10 = smoothed(kTable2Right, 10);
  const auto geo10 = run(kTable2Right, interp::Method::geodesic);
  ASSERT_EQ(pr4.size(), 301u);
  ASSERT_EQ(pr10.size(), 901u);

  const double pr4_rate = peak_rate_deg_s(pr4), pr10_rate = peak_rate_deg_s(pr10);
  const double pr4_analytic = park_ravani_peak_rate_deg_s(kTable2Left);
  const double pr10_analytic = park_ravani_peak_rate_deg_s(kTable2Right);
  const double sm4_rate = peak_rate_deg_s(sm4), sm10_rate = peak_rate_deg_s(sm10);
  const double geo10_rate = peak_rate_deg_s(geo10);
  const double pr4_head = heading_excursion_deg(kTable2Left, pr4);
  const double pr10_head = heading_excursion_deg(kTable2Right, pr10);
  const double sm4_head = heading_excursion_deg(kTable2Left, sm4);
  const double sm10_head = heading_excursion_deg(kTable2Right, sm10);
  std::printf("Fig 5  Park-Ravani, 4 knots : peak rate %.2f deg/s (analytic %.2f), heading excursion %.2f deg\n",
              pr4_rate, pr4_analytic, pr4_head);
  std::printf("Fig 6  Park-Ravani, 10 knots: peak rate %.2f deg/s at 100 Hz (analytic %.4g), heading excursion "
              "%.2f deg\n",
              pr10_rate, pr10_analytic, pr10_head);
  std::printf("Fig 7  smoothed,    4 knots : peak rate %.2f deg/s, heading excursion %.2f deg\n", sm4_rate, sm4_head);
  std::printf("Fig 8  smoothed,   10 knots : peak rate %.2f deg/s, heading excursion %.2f deg (geodesic peak %.2f)\n",
              sm10_rate, sm10_head, geo10_rate);
  std::printf("ratios: PR10/smoothed10 peak rate %.0f (analytic %.3g), PR10/PR4 %.0f\n", pr10_rate / sm10_rate,
              pr10_analytic / sm10_rate, pr10_rate / pr4_rate);

  // Fig. 5: smooth and moderate (it overshoots the last knot's heading by
  // ~12 deg, but no abrupt change); finite differences read the analytic peak.
  EXPECT_LT(pr4_analytic, 120.0);
  EXPECT_NEAR(pr4_rate, pr4_analytic, 0.03 * pr4_analytic);
  EXPECT_LT(pr4_head, 20.0);
  // Fig. 6: erratic. The true peak body rate is ~1e6 deg/s (each segment
  // amplifies the previous one's rate error ~3.7x); sampled at 100 Hz the
  // heading wraps through +-180 deg.
  EXPECT_GT(pr10_analytic, 1e5);
  EXPECT_GT(pr10_rate, 5000.0);
  EXPECT_GT(pr10_head, 150.0);
  EXPECT_GT(pr10_rate, 50.0 * pr4_rate);
  EXPECT_GT(pr10_rate, 200.0 * sm10_rate);
  // Figs. 7/8: the smoothed geodesic stays near the knots' headings and its
  // rate never exceeds the fastest geodesic segment.
  EXPECT_LT(sm4_head, 3.0);
  EXPECT_LT(sm10_head, 3.0);
  EXPECT_LT(sm4_rate, 1.02 * peak_rate_deg_s(run(kTable2Left, interp::Method::geodesic)));
  EXPECT_LT(sm10_rate, 1.02 * geo10_rate);
  EXPECT_LT(pr4_rate / sm4_rate, 10.0);  // Fig. 5 is faster than Fig. 7, not erratic
}

TEST(ThesisAppendixB, Fig7Fig8SmoothingRemovesTheGeodesicKinks) {
  // The §3.6.2 argument: the piecewise geodesic has rate jumps at the knots;
  // the bump convolution spreads each over the 0.2 s window. The prices: the
  // smoothed curve no longer passes through the knots, and Eq. 3.68's clipped
  // windows at the ends (sum over j = 0..i+Delta for i < Delta) move the
  // window's centre at half speed, so the first and last Delta samples turn at
  // about half the geodesic rate and the rate steps at sample Delta.
  constexpr std::size_t kDelta = 10;
  for (const auto* table : {&kTable2Left, &kTable2Right}) {
    const auto geo = run(*table, interp::Method::geodesic);
    const auto sm = smoothed(*table, static_cast<int>(kDelta));
    const auto w_geo = body_rates_rad_s(geo);
    const auto w_sm = body_rates_rad_s(sm);
    double geo_jump = 0.0, interior_jump = 0.0;
    for (std::size_t k = 0; k + 1 < w_geo.size(); ++k) geo_jump = std::max(geo_jump, (w_geo[k + 1] - w_geo[k]).norm() / kDeg);
    for (std::size_t k = kDelta; k + kDelta + 1 < w_sm.size(); ++k) {
      interior_jump = std::max(interior_jump, (w_sm[k + 1] - w_sm[k]).norm() / kDeg);
    }
    const double end_jump = (w_sm[kDelta] - w_sm[kDelta - 1]).norm() / kDeg;
    const double start_ratio = w_sm[0].norm() / w_geo[0].norm();
    const auto knots = poses(*table);
    double knot_miss = 0.0, interior_miss = 0.0;
    for (std::size_t i = 0; i < knots.size(); ++i) {
      const double d = distance_deg(sm[i * 100], knots[i].attitude);
      knot_miss = std::max(knot_miss, d);
      if (i > 0 && i + 1 < knots.size()) interior_miss = std::max(interior_miss, d);
    }
    std::printf("%zu knots: max rate change per 10 ms sample: geodesic %.3f deg/s, smoothed interior %.3f deg/s, "
                "smoothed at sample Delta %.3f deg/s (start rate %.3f x geodesic); smoothed misses the knots by up "
                "to %.3f deg (interior %.3f deg)\n",
                knots.size(), geo_jump, interior_jump, end_jump, start_ratio, knot_miss, interior_miss);
    // Interior: a kink of size J becomes a ramp over 2 Delta + 1 samples.
    EXPECT_LT(interior_jump, 0.1 * geo_jump);
    // Ends: half speed inside the clipped window, then a step.
    EXPECT_NEAR(start_ratio, 0.5, 0.05);
    EXPECT_GT(end_jump, 0.3 * w_geo[kDelta].norm() / kDeg);
    EXPECT_GT(interior_miss, 0.01);  // not an interpolant any more
    EXPECT_LT(knot_miss, 2.0);
  }
}

}  // namespace
}  // namespace unity_core_test_thesis_appendix
