// Live emission (core/live_emitter.hpp) and its time mapping
// (core/time_mapping.hpp) against independent truth:
//   - extrapolation: a constant-velocity, constant-body-rate motion written
//     here in closed form (attitude through Eigen::AngleAxis, not so3::exp,
//     IMU f = -R^T g, w = omega by hand), which the continuation must equal;
//   - rejoin: the reference Circle with a rolling oscillation added (so both
//     position and attitude extrapolations drift), with injected underruns;
//     the emitted stream is checked for flags, grid timestamps, trapezoid
//     consistency of p/v/a and R/omega between neighbouring ticks, central
//     finite differences, a strapdown navigator (core/strapdown.hpp) and
//     1 ns probes at both ends of the blend;
//   - time mapping: hand-computed values and the defining integer
//     inequalities of ceil/floor checked by multiplication in 128 bits.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <deque>
#include <functional>
#include <limits>
#include <numbers>
#include <optional>
#include <random>
#include <set>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "core/imu_model.hpp"
#include "core/live_emitter.hpp"
#include "core/reference_motion.hpp"
#include "core/so3.hpp"
#include "core/strapdown.hpp"
#include "core/time_mapping.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_core_test_live_emitter {
namespace imuemu { using namespace ::imuemu; }

namespace {

using imuemu::ImuSample;
using imuemu::Kinematics;
using imuemu::kNsPerSecond;
using imuemu::Mat3;
using imuemu::SceneModel;
using imuemu::TimeNs;
using imuemu::Vec3;
namespace live = imuemu::live;
namespace reference = imuemu::reference;
namespace so3 = imuemu::so3;
using live::EmissionStatus;

__extension__ typedef __int128 Int128;

// ------------------------------------------------------------------ motions

// Flat scene: p = p0 + v tau, a = 0, R = R0 exp(tau [w]) with constant w,
// written with Eigen's angle-axis so it shares no code with so3::exp.
class ConstantVelocityRate final : public reference::Motion {
 public:
  ConstantVelocityRate(const Vec3& p0, const Vec3& v, const Mat3& R0, const Vec3& w, TimeNs start_ns)
      : Motion(imuemu::Physics::flat, start_ns, reference::kOneHour_ns), p0_(p0), v_(v), R0_(R0), w_(w) {}
  Kinematics at(TimeNs t_ns) const override {
    const double tau = tau_s(t_ns);
    Kinematics k;
    k.t_ns = t_ns;
    k.position_m = p0_ + v_ * tau;
    k.velocity_m_s = v_;
    k.attitude = R0_ * Eigen::AngleAxisd(w_.norm() * tau, w_.normalized()).toRotationMatrix();
    k.angular_rate_rad_s = w_;
    return k;
  }

 private:
  Vec3 p0_, v_;
  Mat3 R0_;
  Vec3 w_;
};

// The reference Circle (heading psi = w tau, R_z(psi)) with the body rolling
// phi = A sin(W tau) about its x axis: R = R_z(psi) R_x(phi), so
//   R^T R' = R_x^T [psi' e_z] R_x + [phi' e_x]
//   omega  = (phi', psi' sin phi, psi' cos phi).
// Position, velocity and acceleration are the Circle's.
class RollingCircle final : public reference::Motion {
 public:
  RollingCircle(double radius_m, double speed_m_s, double roll_amplitude_rad, double roll_rate_rad_s,
                TimeNs start_ns)
      : Motion(imuemu::Physics::flat, start_ns, reference::kOneHour_ns),
        circle_(radius_m, speed_m_s, start_ns),
        heading_rate_rad_s_(speed_m_s / radius_m),
        amplitude_rad_(roll_amplitude_rad),
        rate_rad_s_(roll_rate_rad_s) {}
  Kinematics at(TimeNs t_ns) const override {
    Kinematics k = circle_.at(t_ns);
    const double tau = tau_s(t_ns);
    const double phi = amplitude_rad_ * std::sin(rate_rad_s_ * tau);
    const double phi_dot = amplitude_rad_ * rate_rad_s_ * std::cos(rate_rad_s_ * tau);
    k.attitude = k.attitude * Eigen::AngleAxisd(phi, Vec3::UnitX()).toRotationMatrix();
    k.angular_rate_rad_s =
        Vec3(phi_dot, heading_rate_rad_s_ * std::sin(phi), heading_rate_rad_s_ * std::cos(phi));
    return k;
  }

 private:
  reference::Circle circle_;
  double heading_rate_rad_s_, amplitude_rad_, rate_rad_s_;
};

// ------------------------------------------------------------------ sources

// The smoother's output queue: the test decides when each sample "arrives".
class QueueSource final : public live::ExactSampleSource {
 public:
  std::optional<live::ExactSample> next_sample() override {
    if (queue_.empty()) return std::nullopt;
    live::ExactSample s = queue_.front();
    queue_.pop_front();
    ++pulled_;
    return s;
  }
  void push(const live::ExactSample& s) { queue_.push_back(s); }
  std::size_t pulled() const { return pulled_; }

 private:
  std::deque<live::ExactSample> queue_;
  std::size_t pulled_ = 0;
};

live::ExactSample exact_sample(const reference::Motion& motion, const SceneModel& scene, TimeNs t_ns) {
  const Kinematics k = motion.at(t_ns);
  return {k, imuemu::imu_from_kinematics(scene, k)};
}

constexpr TimeNs kMs = 1'000'000;

std::vector<TimeNs> grid(TimeNs start_ns, TimeNs period_ns, std::size_t count) {
  std::vector<TimeNs> t(count);
  for (std::size_t k = 0; k < count; ++k) t[k] = start_ns + static_cast<TimeNs>(k) * period_ns;
  return t;
}

// Runs an emitter over `ticks`; before tick j the samples of ticks
// [delivered, ready(j)] are pushed (ready(j) < j: the smoother is behind).
std::vector<live::Emission> run(live::LiveEmitter& emitter, const reference::Motion& motion,
                                const SceneModel& scene, const std::vector<TimeNs>& ticks,
                                const std::function<std::ptrdiff_t(std::size_t)>& ready,
                                QueueSource* source_out = nullptr) {
  QueueSource local;
  QueueSource& source = source_out ? *source_out : local;
  std::vector<live::Emission> out;
  std::ptrdiff_t delivered = -1;
  for (std::size_t j = 0; j < ticks.size(); ++j) {
    for (; delivered < ready(j); ++delivered) {
      source.push(exact_sample(motion, scene, ticks[static_cast<std::size_t>(delivered + 1)]));
    }
    out.push_back(emitter.emit(ticks[j], source));
  }
  return out;
}

double angle_between(const Mat3& A, const Mat3& B) { return so3::angle(A.transpose() * B); }

bool all_finite(const live::Emission& e) {
  return e.kinematics.position_m.allFinite() && e.kinematics.velocity_m_s.allFinite() &&
         e.kinematics.acceleration_m_s2.allFinite() && e.kinematics.attitude.allFinite() &&
         e.kinematics.angular_rate_rad_s.allFinite() && e.imu.gyro_rad_s.allFinite() &&
         e.imu.accel_m_s2.allFinite();
}

// ------------------------------------------------------------------ extrapolation

TEST(LiveEmitter, ExtrapolationIsTheConstantVelocityRateContinuation) {
  // A long epoch-like start checks that only time differences enter.
  const TimeNs t0 = 1'700'000'000 * kNsPerSecond + 123'456'789;
  const Mat3 R0 = Eigen::AngleAxisd(0.7, Vec3(1.0, -2.0, 0.5).normalized()).toRotationMatrix();
  const Vec3 w(0.31, -0.12, 0.45);
  const ConstantVelocityRate motion(Vec3(100.0, -50.0, 20.0), Vec3(12.0, -3.0, 0.5), R0, w, t0);
  const SceneModel scene;  // flat, g = (0, 0, 9.80665)
  live::LiveEmitter emitter({scene, live::UnderrunPolicy::extrapolate, 200 * kMs});
  const std::vector<TimeNs> ticks = grid(t0, 10 * kMs, 501);  // 100 Hz, 5 s
  // Exact samples for the first second (ticks 0..100), then none at all.
  const auto out = run(emitter, motion, scene, ticks, [](std::size_t j) { return std::min<std::ptrdiff_t>(j, 100); });

  double pos_err = 0, vel_err = 0, acc_err = 0, att_err = 0, rate_err = 0, gyro_err = 0, accel_err = 0;
  for (std::size_t j = 0; j < ticks.size(); ++j) {
    const live::Emission& e = out[j];
    ASSERT_EQ(e.status, j <= 100 ? EmissionStatus::exact : EmissionStatus::extrapolated) << "tick " << j;
    ASSERT_EQ(e.kinematics.t_ns, ticks[j]);
    ASSERT_EQ(e.imu.t_ns, ticks[j]);
    const Kinematics truth = motion.at(ticks[j]);
    pos_err = std::max(pos_err, (e.kinematics.position_m - truth.position_m).norm());
    vel_err = std::max(vel_err, (e.kinematics.velocity_m_s - truth.velocity_m_s).norm());
    acc_err = std::max(acc_err, e.kinematics.acceleration_m_s2.norm());
    att_err = std::max(att_err, angle_between(e.kinematics.attitude, truth.attitude));
    rate_err = std::max(rate_err, (e.kinematics.angular_rate_rad_s - w).norm());
    // Ideal IMU of this motion, by hand: gyro = w, f = R^T (0 - g).
    gyro_err = std::max(gyro_err, (e.imu.gyro_rad_s - w).norm());
    accel_err = std::max(accel_err, (e.imu.accel_m_s2 + truth.attitude.transpose() * scene.flat_gravity_m_s2).norm());
  }
  std::printf("extrapolation vs truth over 4 s: pos %.2e m vel %.2e m/s att %.2e rad gyro %.2e accel %.2e\n", pos_err,
              vel_err, att_err, gyro_err, accel_err);
  EXPECT_LT(pos_err, 1e-12);
  EXPECT_EQ(vel_err, 0.0);
  EXPECT_EQ(acc_err, 0.0);
  EXPECT_LT(att_err, 1e-12);
  EXPECT_EQ(rate_err, 0.0);
  EXPECT_LT(gyro_err, 1e-12);
  EXPECT_LT(accel_err, 1e-12);
  const live::LiveCounters& c = emitter.counters();
  EXPECT_EQ(c.ticks, 501u);
  EXPECT_EQ(c.exact, 101u);
  EXPECT_EQ(c.extrapolated, 400u);
  EXPECT_EQ(c.underrun_events, 1u);
  EXPECT_EQ(c.blending + c.paused + c.waiting + c.stale_discarded + c.invalid_discarded, 0u);
}

// ------------------------------------------------------------------ rejoin

struct RejoinCase {
  RollingCircle motion{40.0, 8.0, 0.3, 2.0 * std::numbers::pi * 0.5, 1000 * kNsPerSecond};
  SceneModel scene;
  TimeNs period_ns = kMs;  // 1 kHz
  TimeNs blend_ns = 200 * kMs;
  std::vector<TimeNs> ticks = grid(1000 * kNsPerSecond, kMs, 1500);
};

// Statuses the rule predicts: a tick whose sample has not arrived by its
// deadline is extrapolated; after a run of such ticks ending at tick L, the
// ticks with t - t_L < blend are blending; everything else is exact.
std::vector<EmissionStatus> expected_statuses(const std::vector<TimeNs>& ticks, const std::set<std::size_t>& missing,
                                              TimeNs blend_ns) {
  std::vector<EmissionStatus> s(ticks.size(), EmissionStatus::exact);
  std::optional<TimeNs> last_missing;
  for (std::size_t j = 0; j < ticks.size(); ++j) {
    if (missing.count(j)) {
      s[j] = EmissionStatus::extrapolated;
      last_missing = ticks[j];
    } else if (last_missing && ticks[j] - *last_missing < blend_ns) {
      s[j] = EmissionStatus::blending;
    }
  }
  return s;
}

// The smoother stalls for trajectory times [0.3, 0.6) s after the start
// (those samples arrive all at once at 0.6 s, too late) and again for
// [0.7, 0.72) s, in the middle of the first rejoin blend. per_ms ticks a ms.
struct TwoUnderruns {
  std::vector<TimeNs> ticks;
  std::set<std::size_t> missing;
  std::vector<live::Emission> out;
  std::vector<EmissionStatus> expected;
  live::LiveCounters counters;
};
TwoUnderruns two_underruns(const RejoinCase& rc, std::size_t per_ms) {
  TwoUnderruns r;
  r.ticks = grid(rc.ticks[0], kMs / static_cast<TimeNs>(per_ms), 1500 * per_ms);
  std::vector<std::ptrdiff_t> ready(r.ticks.size());
  for (std::size_t j = 0; j < r.ticks.size(); ++j) {
    const bool stalled1 = j >= 300 * per_ms && j < 600 * per_ms, stalled2 = j >= 700 * per_ms && j < 720 * per_ms;
    ready[j] = stalled1   ? static_cast<std::ptrdiff_t>(300 * per_ms) - 1
               : stalled2 ? static_cast<std::ptrdiff_t>(700 * per_ms) - 1
                          : static_cast<std::ptrdiff_t>(j);
    if (stalled1 || stalled2) r.missing.insert(j);
  }
  live::LiveEmitter emitter({rc.scene, live::UnderrunPolicy::extrapolate, rc.blend_ns});
  r.out = run(emitter, rc.motion, rc.scene, r.ticks, [&](std::size_t j) { return ready[j]; });
  r.expected = expected_statuses(r.ticks, r.missing, rc.blend_ns);
  r.counters = emitter.counters();
  return r;
}

TEST(LiveEmitter, RejoinBlendIsFlaggedConsistentAndContinuous) {
  const RejoinCase rc;
  const TwoUnderruns r = two_underruns(rc, 1);
  const std::vector<live::Emission>& out = r.out;
  const std::vector<EmissionStatus>& expected = r.expected;
  const std::set<std::size_t>& missing = r.missing;
  ASSERT_EQ(r.ticks, rc.ticks);

  std::size_t n_blend = 0;
  for (std::size_t j = 0; j < out.size(); ++j) {
    const live::Emission& e = out[j];
    ASSERT_EQ(e.status, expected[j]) << "tick " << j << ": " << live::to_string(e.status);
    ASSERT_TRUE(e.has_sample());
    ASSERT_EQ(e.exact(), !missing.count(j) && expected[j] == EmissionStatus::exact);
    // Timestamps: every grid tick is sent, stamped with its own time.
    ASSERT_EQ(e.kinematics.t_ns, rc.ticks[j]);
    ASSERT_EQ(e.imu.t_ns, rc.ticks[j]);
    ASSERT_TRUE(all_finite(e));
    n_blend += expected[j] == EmissionStatus::blending;
    if (e.exact()) {
      const Kinematics truth = rc.motion.at(rc.ticks[j]);
      ASSERT_EQ(e.kinematics.position_m, truth.position_m);
    }
    // The sent IMU is the ideal IMU (Eq. 3.70) of the sent kinematics.
    const ImuSample ideal = imuemu::imu_from_kinematics(rc.scene, e.kinematics);
    ASSERT_LT((e.imu.gyro_rad_s - ideal.gyro_rad_s).norm(), 1e-13) << "tick " << j;
    ASSERT_LT((e.imu.accel_m_s2 - ideal.accel_m_s2).norm(), 1e-13) << "tick " << j;
  }
  // First blend 600..798 is cut short by the second underrun at 700; the
  // second blend runs from t_719: 720..918.
  EXPECT_EQ(n_blend, 100u + 199u);
  const live::LiveCounters& c = r.counters;
  EXPECT_EQ(c.ticks, 1500u);
  EXPECT_EQ(c.extrapolated, 320u);
  EXPECT_EQ(c.blending, 299u);
  EXPECT_EQ(c.exact, 1500u - 320u - 299u);
  EXPECT_EQ(c.underrun_events, 2u);
  EXPECT_EQ(c.stale_discarded, 320u);  // the late samples of the missing ticks
  EXPECT_EQ(c.paused + c.waiting + c.invalid_discarded, 0u);

  // The extrapolation and the truth really part (else the blend is vacuous):
  // at the rejoin tick 600 the truth is far from where the output was.
  const Kinematics truth600 = rc.motion.at(rc.ticks[600]);
  const double rejoin_pos_gap = (truth600.position_m - out[599].kinematics.position_m).norm();
  const double rejoin_vel_gap = (truth600.velocity_m_s - out[599].kinematics.velocity_m_s).norm();
  const double rejoin_att_gap = angle_between(truth600.attitude, out[599].kinematics.attitude);
  std::printf("at rejoin: truth - extrapolation = %.3f m, %.3f m/s, %.3f rad\n", rejoin_pos_gap, rejoin_vel_gap,
              rejoin_att_gap);
  ASSERT_GT(rejoin_pos_gap, 0.05);
  ASSERT_GT(rejoin_vel_gap, 0.4);
  ASSERT_GT(rejoin_att_gap, 0.05);

  // Neighbouring ticks are one C2 trajectory: the trapezoid rule links p to v,
  // v to a and R to omega with an O(h^3) remainder (h^3/12 max|p'''| etc.; the
  // blend's jerk is ~1.5e3 m/s^3 and snap ~5e4 m/s^4 here, so remainders
  // ~1.3e-7 m and ~4e-6 m/s). A step at the rejoin as small as 1 mm/s or a
  // missing s' term (~1 m/s) fails by orders of magnitude.
  const double h = 1e-3;
  double p_res = 0, v_res = 0, R_res = 0;
  for (std::size_t j = 0; j + 1 < out.size(); ++j) {
    const Kinematics& a = out[j].kinematics;
    const Kinematics& b = out[j + 1].kinematics;
    p_res = std::max(p_res, (b.position_m - a.position_m - 0.5 * h * (a.velocity_m_s + b.velocity_m_s)).norm());
    // Acceleration jumps where an extrapolation begins (to 0): only v and p
    // need be continuous there, so the v-a link is checked elsewhere.
    if (!(expected[j + 1] == EmissionStatus::extrapolated && expected[j] != EmissionStatus::extrapolated)) {
      v_res = std::max(v_res,
                       (b.velocity_m_s - a.velocity_m_s - 0.5 * h * (a.acceleration_m_s2 + b.acceleration_m_s2)).norm());
    }
    R_res = std::max(R_res, (so3::log(a.attitude.transpose() * b.attitude) -
                             0.5 * h * (a.angular_rate_rad_s + b.angular_rate_rad_s))
                                .norm());
  }
  std::printf("trapezoid residuals: p %.2e m, v %.2e m/s, R %.2e rad\n", p_res, v_res, R_res);
  EXPECT_LT(p_res, 1e-6);
  EXPECT_LT(v_res, 2e-5);
  EXPECT_LT(R_res, 1e-6);

  // Central differences during the blends: finite-difference velocity of the
  // emitted positions is the emitted velocity (h^2/6 |p'''| ~ 3e-4 m/s), and
  // of the attitudes the emitted body rate. Contrast: how far the emitted
  // velocity is from the naive (1-s) x' + s e' (the s'(e - x) term).
  double fd_v = 0, fd_w = 0, s_prime_term = 0;
  for (std::size_t j = 601; j < 918; ++j) {
    // Skip the tick before a new underrun: its right neighbour lies on the
    // next extrapolation, whose acceleration steps to 0 at this tick.
    if (expected[j] != EmissionStatus::blending || expected[j + 1] == EmissionStatus::extrapolated) continue;
    const Kinematics& a = out[j - 1].kinematics;
    const Kinematics& k = out[j].kinematics;
    const Kinematics& b = out[j + 1].kinematics;
    fd_v = std::max(fd_v, ((b.position_m - a.position_m) / (2 * h) - k.velocity_m_s).norm());
    fd_w = std::max(fd_w, (so3::log(a.attitude.transpose() * b.attitude) / (2 * h) - k.angular_rate_rad_s).norm());
    if (j < 700) {
      // First blend: x = extrapolation from tick 299, e = truth, t_b = t_599.
      const Kinematics& x0 = out[299].kinematics;
      const double u = static_cast<double>(rc.ticks[j] - rc.ticks[599]) / static_cast<double>(rc.blend_ns);
      const double s = u * u * u * (10 - 15 * u + 6 * u * u);
      const Vec3 naive = (1 - s) * x0.velocity_m_s + s * rc.motion.at(rc.ticks[j]).velocity_m_s;
      s_prime_term = std::max(s_prime_term, (k.velocity_m_s - naive).norm());
    }
  }
  std::printf("blend central differences: v %.2e m/s, omega %.2e rad/s; s' term up to %.3f m/s\n", fd_v, fd_w,
              s_prime_term);
  // Truncation h^2/6 |p'''| with |p'''| <~ 60/T^3 |e - x| + ... ~ 2e3 m/s^3
  // (~3e-4 m/s); for the rate h^2/6 |omega''|, |omega''| ~ 60/T^3 0.12 rad.
  EXPECT_LT(fd_v, 1e-3);
  EXPECT_LT(fd_w, 1e-3);

  EXPECT_GT(s_prime_term, 100 * 1e-3);

}

// Largest position, velocity and attitude differences between a strapdown
// navigator fed the emitted IMU of ticks [first, last] (started from the
// emitted state at `first`) and the emitted kinematics.
struct NavErrors {
  double pos_m = 0, vel_m_s = 0, att_rad = 0;
};
NavErrors navigate(const SceneModel& scene, const std::vector<live::Emission>& out, std::size_t first,
                   std::size_t last) {
  std::vector<ImuSample> imu;
  for (std::size_t j = first; j <= last; ++j) imu.push_back(out[j].imu);
  const Kinematics& k0 = out[first].kinematics;
  imuemu::strapdown::NavState initial;
  initial.t_ns = k0.t_ns;
  initial.position_m = k0.position_m;
  initial.velocity_m_s = k0.velocity_m_s;
  initial.attitude = k0.attitude;
  const auto nav = imuemu::strapdown::integrate(scene, initial, imu);
  NavErrors e;
  for (std::size_t i = 0; i < nav.size(); ++i) {
    const Kinematics& k = out[first + 2 * i].kinematics;
    e.pos_m = std::max(e.pos_m, (nav[i].position_m - k.position_m).norm());
    e.vel_m_s = std::max(e.vel_m_s, (nav[i].velocity_m_s - k.velocity_m_s).norm());
    e.att_rad = std::max(e.att_rad, angle_between(nav[i].attitude, k.attitude));
  }
  return e;
}

TEST(LiveEmitter, NavigatorIntegratingTheEmittedImuFollowsTheEmittedTrajectory) {
  // The emitted IMU is the exact IMU of the emitted kinematics' trajectory iff
  // a strapdown navigator (4th order, core/strapdown.hpp) converges to that
  // trajectory at 4th order as the tick period shrinks: the rejoin blend moves
  // ~0.1-0.2 m and 0.1 rad in 0.2 s (accelerations ~30 m/s^2), so at 1 kHz the
  // navigator's own truncation error is visible, and at 4 kHz it must be
  // ~4^4 = 256x smaller. An IMU inconsistent with the kinematics (e.g. without
  // the s' terms, ~1 m/s) leaves an error that does not shrink.
  // Where the navigator may start and step: at an anchor the acceleration
  // steps to 0 (constant-velocity continuation), and at both ends of a blend
  // the jerk steps (the quintic is C2, not C3). Sampled integration resolves
  // neither inside a step (Simpson over a jerk step in mid-step errs by
  // h^2 |jump| / 6, ~9e-5 m/s here: 2nd order), so each segment starts one
  // tick after an anchor, which puts every blend end on a step boundary (a
  // step spans two ticks).
  const RejoinCase rc;
  const TwoUnderruns coarse = two_underruns(rc, 1), fine = two_underruns(rc, 4);
  // Anchors at 299 and 699 ms; blends start at 599 and 719 ms, the second ends at 919 ms.
  for (const auto& [first_ms, last_ms] : {std::pair<std::size_t, std::size_t>{300, 699}, {700, 1499}}) {
    const NavErrors c = navigate(rc.scene, coarse.out, first_ms + 1, last_ms);
    const NavErrors f = navigate(rc.scene, fine.out, 4 * first_ms + 1, 4 * last_ms + 3);
    std::printf("navigator vs emitted, %zu..%zu ms: 1 kHz %.2e m %.2e m/s %.2e rad; 4 kHz %.2e m %.2e m/s %.2e rad\n",
                first_ms, last_ms, c.pos_m, c.vel_m_s, c.att_rad, f.pos_m, f.vel_m_s, f.att_rad);
    EXPECT_LT(c.pos_m, 1e-7);
    EXPECT_LT(c.vel_m_s, 1e-7);
    EXPECT_LT(f.pos_m, c.pos_m / 100);
    EXPECT_LT(f.vel_m_s, c.vel_m_s / 100);
    EXPECT_LT(f.att_rad, c.att_rad / 100);
  }
}

TEST(LiveEmitter, BlendMeetsBothTrajectoriesC1AtItsEnds) {
  // Probe ticks 1 ns inside each end of the blend: there the output must equal
  // the extrapolation (start) and the truth (end) in position, velocity,
  // attitude and rate to rounding (s, s' ~ 1e-15 at 1 ns into a 0.2 s blend).
  const RejoinCase rc;
  live::LiveEmitter emitter({rc.scene, live::UnderrunPolicy::extrapolate, rc.blend_ns});
  QueueSource source;
  const TimeNs h = rc.period_ns;
  const TimeNs t_anchor = rc.ticks[0] + 99 * h;    // last exact tick
  const TimeNs t_b = rc.ticks[0] + 400 * h;        // last extrapolated tick
  std::vector<TimeNs> ticks;
  for (TimeNs t = rc.ticks[0]; t <= t_b; t += h) ticks.push_back(t);
  ticks.push_back(t_b + 1);
  for (TimeNs t = t_b + h; t < t_b + rc.blend_ns; t += h) ticks.push_back(t);
  ticks.push_back(t_b + rc.blend_ns - 1);
  ticks.push_back(t_b + rc.blend_ns);
  std::vector<live::Emission> out;
  for (const TimeNs t : ticks) {
    if (t <= t_anchor || t > t_b) source.push(exact_sample(rc.motion, rc.scene, t));
    out.push_back(emitter.emit(t, source));
  }
  ASSERT_EQ(out[400].status, EmissionStatus::extrapolated);
  const live::Emission& start = out[401];
  const live::Emission& end = out[out.size() - 2];
  ASSERT_EQ(start.status, EmissionStatus::blending);
  ASSERT_EQ(end.status, EmissionStatus::blending);
  ASSERT_EQ(out.back().status, EmissionStatus::exact);

  // Extrapolation from the anchor, written out here.
  const Kinematics a = rc.motion.at(t_anchor);
  const double dt = imuemu::seconds_between(t_anchor, t_b + 1);
  const Vec3 x_pos = a.position_m + a.velocity_m_s * dt;
  const Mat3 x_att = a.attitude * Eigen::AngleAxisd(a.angular_rate_rad_s.norm() * dt,
                                                    a.angular_rate_rad_s.normalized())
                                      .toRotationMatrix();
  EXPECT_LT((start.kinematics.position_m - x_pos).norm(), 1e-12);
  EXPECT_LT((start.kinematics.velocity_m_s - a.velocity_m_s).norm(), 1e-12);
  EXPECT_LT(angle_between(start.kinematics.attitude, x_att), 1e-12);
  EXPECT_LT((start.kinematics.angular_rate_rad_s - a.angular_rate_rad_s).norm(), 1e-12);
  // C2 in fact: the acceleration starts from the extrapolation's 0 (s'' ~ 60 u / T^2).
  EXPECT_LT(start.kinematics.acceleration_m_s2.norm(), 1e-5);

  const Kinematics e = rc.motion.at(t_b + rc.blend_ns - 1);
  EXPECT_LT((end.kinematics.position_m - e.position_m).norm(), 1e-12);
  EXPECT_LT((end.kinematics.velocity_m_s - e.velocity_m_s).norm(), 1e-12);
  EXPECT_LT(angle_between(end.kinematics.attitude, e.attitude), 1e-12);
  EXPECT_LT((end.kinematics.angular_rate_rad_s - e.angular_rate_rad_s).norm(), 1e-12);
  EXPECT_LT((end.kinematics.acceleration_m_s2 - e.acceleration_m_s2).norm(), 1e-5);
  // ...while 1 ns before the blend the truth was far away.
  EXPECT_GT((rc.motion.at(t_b).position_m - out[400].kinematics.position_m).norm(), 0.05);
}

// ------------------------------------------------------------------ pause

TEST(LiveEmitter, PausePolicySkipsMissingTicksAndResumesAtTheCurrentTick) {
  const RejoinCase rc;
  live::LiveEmitter emitter({rc.scene, live::UnderrunPolicy::pause, rc.blend_ns});
  std::set<std::size_t> missing;
  for (std::size_t j = 300; j < 600; ++j) missing.insert(j);
  for (std::size_t j = 900; j < 950; ++j) missing.insert(j);
  const auto ready = [&](std::size_t j) -> std::ptrdiff_t {
    if (j >= 300 && j < 600) return 299;
    if (j >= 900 && j < 950) return 899;
    return static_cast<std::ptrdiff_t>(j);
  };
  const auto out = run(emitter, rc.motion, rc.scene, rc.ticks, ready);
  for (std::size_t j = 0; j < out.size(); ++j) {
    if (missing.count(j)) {
      ASSERT_EQ(out[j].status, EmissionStatus::paused) << "tick " << j;
      ASSERT_FALSE(out[j].has_sample());
    } else {
      // Resumes with the exact sample of the current tick (not the late ones),
      // no blend.
      ASSERT_EQ(out[j].status, EmissionStatus::exact) << "tick " << j;
      ASSERT_EQ(out[j].kinematics.t_ns, rc.ticks[j]);
      ASSERT_EQ(out[j].kinematics.position_m, rc.motion.at(rc.ticks[j]).position_m);
    }
  }
  const live::LiveCounters& c = emitter.counters();
  EXPECT_EQ(c.ticks, 1500u);
  EXPECT_EQ(c.paused, 350u);
  EXPECT_EQ(c.exact, 1150u);
  EXPECT_EQ(c.underrun_events, 2u);
  EXPECT_EQ(c.stale_discarded, 350u);
  EXPECT_EQ(c.extrapolated + c.blending + c.waiting + c.invalid_discarded, 0u);
}

// ------------------------------------------------------------------ edge cases

TEST(LiveEmitter, WaitsForTheFirstSampleWithoutCountingAnUnderrun) {
  const RejoinCase rc;
  for (const auto policy : {live::UnderrunPolicy::extrapolate, live::UnderrunPolicy::pause}) {
    live::LiveEmitter emitter({rc.scene, policy, rc.blend_ns});
    // The smoother's first output appears at tick 5, with ticks 0..5 at once.
    const auto out = run(emitter, rc.motion, rc.scene, grid(rc.ticks[0], kMs, 20),
                         [](std::size_t j) -> std::ptrdiff_t { return j < 5 ? -1 : static_cast<std::ptrdiff_t>(j); });
    for (std::size_t j = 0; j < out.size(); ++j) {
      ASSERT_EQ(out[j].status, j < 5 ? EmissionStatus::waiting : EmissionStatus::exact) << j;
      ASSERT_EQ(out[j].has_sample(), j >= 5);
    }
    EXPECT_EQ(emitter.counters().waiting, 5u);
    EXPECT_EQ(emitter.counters().exact, 15u);
    EXPECT_EQ(emitter.counters().stale_discarded, 5u);
    EXPECT_EQ(emitter.counters().underrun_events, 0u);
  }
}

TEST(LiveEmitter, InvalidSamplesAreMissingAndNothingNonFiniteIsSent) {
  const RejoinCase rc;
  live::LiveEmitter emitter({rc.scene, live::UnderrunPolicy::extrapolate, 20 * kMs});
  QueueSource source;
  const std::vector<TimeNs> ticks = grid(rc.ticks[0], kMs, 400);
  std::vector<live::Emission> out;
  for (std::size_t j = 0; j < ticks.size(); ++j) {
    live::ExactSample s = exact_sample(rc.motion, rc.scene, ticks[j]);
    if (j == 100) s.kinematics.velocity_m_s.x() = std::numeric_limits<double>::quiet_NaN();
    if (j == 200) s.imu.accel_m_s2.z() = std::numeric_limits<double>::infinity();
    if (j == 300) s.imu.t_ns += 1;  // stamped inconsistently
    source.push(s);
    out.push_back(emitter.emit(ticks[j], source));
    ASSERT_TRUE(all_finite(out.back())) << j;
  }
  for (const std::size_t bad : {100u, 200u, 300u}) {
    EXPECT_EQ(out[bad].status, EmissionStatus::extrapolated) << bad;
    EXPECT_EQ(out[bad + 1].status, EmissionStatus::blending) << bad;
    EXPECT_EQ(out[bad + 20].status, EmissionStatus::exact) << bad;  // 20 ms blend from t_bad
  }
  EXPECT_EQ(emitter.counters().invalid_discarded, 3u);
  EXPECT_EQ(emitter.counters().underrun_events, 3u);
  EXPECT_EQ(emitter.counters().extrapolated, 3u);
  EXPECT_EQ(emitter.counters().blending, 3u * 19u);
  EXPECT_EQ(emitter.counters().stale_discarded, 0u);
}

// A tick the smoother skipped (it has produced the next one) is a gap of the
// trajectory, not lateness: nothing is sent, and the next tick is exact, with
// no extrapolation into the gap and no blend out of it.
TEST(LiveEmitter, SkippedSampleIsAGapAndTheEmitterPullsAtMostOneAhead) {
  const RejoinCase rc;
  live::LiveEmitter emitter({rc.scene, live::UnderrunPolicy::extrapolate, 5 * kMs});
  QueueSource source;
  const std::vector<TimeNs> ticks = grid(rc.ticks[0], kMs, 60);
  // The smoother runs ahead (all samples already queued) but never produced tick 30.
  for (std::size_t j = 0; j < ticks.size(); ++j) {
    if (j != 30) source.push(exact_sample(rc.motion, rc.scene, ticks[j]));
  }
  for (std::size_t j = 0; j < ticks.size(); ++j) {
    const live::Emission e = emitter.emit(ticks[j], source);
    ASSERT_EQ(e.status, j == 30 ? EmissionStatus::gap : EmissionStatus::exact) << j;
    ASSERT_EQ(e.has_sample(), j != 30) << j;
    // Samples with t <= tick, plus one ahead at most (bounded memory; the rest
    // stays with the smoother).
    const std::size_t samples_due = j < 30 ? j + 1 : j;
    ASSERT_LE(source.pulled(), samples_due + 1) << j;
  }
  EXPECT_EQ(emitter.counters().stale_discarded, 0u);
  EXPECT_EQ(emitter.counters().underrun_events, 0u);
  EXPECT_EQ(emitter.counters().gap, 1u);
  EXPECT_EQ(emitter.counters().gap_events, 1u);
}

// Two stretches of trajectory far apart (a loop seam: the end of a flight,
// then its start again): the ticks between them are a silent gap, the second
// stretch is sent exact from its first tick. Before the gap was a mechanism,
// the emitter extrapolated through it and blended across kilometres (W1 of
// issue 13: 4.8e5 m/s^2 on the wire).
TEST(LiveEmitter, LoopSeamIsASilentGapWithNoExtrapolationOrBlend) {
  const RejoinCase rc;
  live::LiveEmitter emitter({rc.scene, live::UnderrunPolicy::extrapolate, rc.blend_ns});
  QueueSource source;
  const std::vector<TimeNs> ticks = grid(rc.ticks[0], kMs, 3000);
  const TimeNs shift_ns = 500 * kNsPerSecond;  // the second stretch is the motion 500 s later
  const std::size_t gap_from = 1000, gap_to = 2000;  // ticks without a sample
  for (std::size_t j = 0; j < ticks.size(); ++j) {
    if (j >= gap_from && j < gap_to) continue;
    live::ExactSample s = exact_sample(rc.motion, rc.scene, j < gap_from ? ticks[j] : ticks[j] + shift_ns);
    s.kinematics.t_ns = s.imu.t_ns = ticks[j];
    source.push(s);
  }
  double max_accel_m_s2 = 0.0;
  for (std::size_t j = 0; j < ticks.size(); ++j) {
    const live::Emission e = emitter.emit(ticks[j], source);
    const bool in_gap = j >= gap_from && j < gap_to;
    ASSERT_EQ(e.status, in_gap ? EmissionStatus::gap : EmissionStatus::exact) << j;
    if (e.has_sample()) max_accel_m_s2 = std::max(max_accel_m_s2, e.imu.accel_m_s2.norm());
  }
  const live::LiveCounters& c = emitter.counters();
  EXPECT_EQ(c.gap, gap_to - gap_from);
  EXPECT_EQ(c.gap_events, 1u);
  EXPECT_EQ(c.extrapolated + c.blending + c.underrun_events, 0u);
  EXPECT_EQ(c.exact + c.gap, ticks.size());
  // The circle's own specific force: sqrt(g^2 + (v^2/r)^2) = 9.9 m/s^2, plus roll.
  EXPECT_LT(max_accel_m_s2, 12.0);
}

// Live input: the emitter extrapolates while no sample comes; once the
// smoother's next sample is past the current tick (the sender resumed after a
// gap longer than max_gap_s), the extrapolation ends in silence and output
// resumes exact, never blending across the gap.
TEST(LiveEmitter, ExtrapolationThatRunsIntoAGapStopsThere) {
  const RejoinCase rc;
  live::LiveEmitter emitter({rc.scene, live::UnderrunPolicy::extrapolate, rc.blend_ns});
  QueueSource source;
  const std::vector<TimeNs> ticks = grid(rc.ticks[0], kMs, 400);
  for (std::size_t j = 0; j < 100; ++j) source.push(exact_sample(rc.motion, rc.scene, ticks[j]));
  std::vector<EmissionStatus> got;
  for (std::size_t j = 0; j < 150; ++j) got.push_back(emitter.emit(ticks[j], source).status);
  // The sender is back: samples from tick 300 on.
  for (std::size_t j = 300; j < ticks.size(); ++j) source.push(exact_sample(rc.motion, rc.scene, ticks[j]));
  for (std::size_t j = 150; j < ticks.size(); ++j) got.push_back(emitter.emit(ticks[j], source).status);
  for (std::size_t j = 0; j < ticks.size(); ++j) {
    const EmissionStatus want = j < 100   ? EmissionStatus::exact
                                : j < 150 ? EmissionStatus::extrapolated
                                : j < 300 ? EmissionStatus::gap
                                          : EmissionStatus::exact;
    ASSERT_EQ(got[j], want) << j;
  }
  EXPECT_EQ(emitter.counters().underrun_events, 1u);
  EXPECT_EQ(emitter.counters().gap_events, 1u);
  EXPECT_EQ(emitter.counters().blending, 0u);
}

TEST(LiveEmitter, ZeroBlendRejoinsWithTheExactSample) {
  const RejoinCase rc;
  live::LiveEmitter emitter({rc.scene, live::UnderrunPolicy::extrapolate, 0});
  const auto out = run(emitter, rc.motion, rc.scene, grid(rc.ticks[0], kMs, 100),
                       [](std::size_t j) -> std::ptrdiff_t { return j >= 40 && j < 50 ? 39 : static_cast<std::ptrdiff_t>(j); });
  for (std::size_t j = 0; j < out.size(); ++j) {
    ASSERT_EQ(out[j].status, j >= 40 && j < 50 ? EmissionStatus::extrapolated : EmissionStatus::exact) << j;
  }
  EXPECT_EQ(emitter.counters().blending, 0u);
}

TEST(LiveEmitter, RejectsBadUse) {
  const RejoinCase rc;
  EXPECT_THROW(live::LiveEmitter({rc.scene, live::UnderrunPolicy::extrapolate, -1}), std::invalid_argument);
  live::LiveEmitter emitter({rc.scene, live::UnderrunPolicy::extrapolate, rc.blend_ns});
  QueueSource source;
  emitter.emit(1000, source);
  try {
    emitter.emit(1000, source);
    FAIL() << "repeated tick accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("1000"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("increasing"), std::string::npos) << e.what();
  }
  EXPECT_THROW(emitter.emit(999, source), std::invalid_argument);
  EXPECT_EQ(live::underrun_policy_from_string("pause"), live::UnderrunPolicy::pause);
  EXPECT_EQ(live::underrun_policy_from_string("extrapolate"), live::UnderrunPolicy::extrapolate);
  try {
    live::underrun_policy_from_string("hold");
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("'hold'"), std::string::npos) << e.what();
  }
}

// ------------------------------------------------------------------ time mapping

TEST(TimeMapping, ParsesSpeedFactorsExactly) {
  using live::SpeedFactor;
  EXPECT_EQ(live::parse_speed_factor("1"), (SpeedFactor{1, 1}));
  EXPECT_EQ(live::parse_speed_factor("2.5"), (SpeedFactor{5, 2}));
  EXPECT_EQ(live::parse_speed_factor("1/3"), (SpeedFactor{1, 3}));
  EXPECT_EQ(live::parse_speed_factor("10/4"), (SpeedFactor{5, 2}));
  EXPECT_EQ(live::parse_speed_factor("0.125"), (SpeedFactor{1, 8}));
  EXPECT_EQ(live::parse_speed_factor(".5"), (SpeedFactor{1, 2}));
  EXPECT_EQ(live::parse_speed_factor("0.000000000001"), (SpeedFactor{1, 1'000'000'000'000}));
  EXPECT_EQ(live::parse_speed_factor("1000000000000"), (SpeedFactor{1'000'000'000'000, 1}));
  EXPECT_EQ(live::to_string(live::parse_speed_factor("2.5")), "5/2");
  EXPECT_EQ(live::to_string(live::parse_speed_factor("3.0")), "3");
  for (const char* bad : {"", "0", "0.0", "-1", "+1", "1e3", "abc", "1/0", "0/5", "2.5.1", " 2", "3.", "1/2/3",
                          "1.0000000000001", "1000000000001", "99999999999999999999999999"}) {
    try {
      live::parse_speed_factor(bad);
      FAIL() << "accepted '" << bad << "'";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("'" + std::string(bad) + "'"), std::string::npos) << e.what();
    }
  }
  EXPECT_THROW(live::make_speed_factor(0, 1), std::invalid_argument);
  EXPECT_THROW(live::make_speed_factor(1, -3), std::invalid_argument);
  EXPECT_EQ(live::make_speed_factor(6, 4), (SpeedFactor{3, 2}));
}

TEST(TimeMapping, HandComputedValues) {
  // Speed 5/2, anchor (t0 = 10, m0 = 1000): m(t) = 1000 + (t - 10) * 2/5.
  const live::TimeMapping fast(10, 1000, live::make_speed_factor(5, 2));
  EXPECT_EQ(fast.monotonic_at(10), 1000);
  EXPECT_EQ(fast.monotonic_at(11), 1001);  // 1000.4 -> ceil
  EXPECT_EQ(fast.monotonic_at(12), 1001);  // 1000.8
  EXPECT_EQ(fast.monotonic_at(13), 1002);  // 1001.2
  EXPECT_EQ(fast.monotonic_at(15), 1002);  // exact
  EXPECT_EQ(fast.monotonic_at(9), 1000);   // 999.6
  EXPECT_EQ(fast.monotonic_at(5), 998);    // exact
  EXPECT_EQ(fast.trajectory_at(1001), 12);  // 12.5 -> floor
  EXPECT_EQ(fast.trajectory_at(999), 7);    // 7.5 -> floor
  EXPECT_EQ(fast.trajectory_at(998), 5);

  // Speed 1/3, anchor (0, 0): m = 3 t, t = floor(m / 3).
  const live::TimeMapping slow(0, 0, live::make_speed_factor(1, 3));
  EXPECT_EQ(slow.monotonic_at(7), 21);
  EXPECT_EQ(slow.monotonic_at(-7), -21);
  EXPECT_EQ(slow.trajectory_at(5), 1);
  EXPECT_EQ(slow.trajectory_at(-1), -1);
  EXPECT_EQ(slow.trajectory_at(-3), -1);
  EXPECT_EQ(slow.trajectory_at(-4), -2);

  // Beyond int64 in between: t0 = -2^62, t = 2^62 (t - t0 = 2^63), speed 5/2:
  // m = ceil(2^64 / 5) = ceil(3689348814741910323.2) = 3689348814741910324,
  // and back: -2^62 + floor(3689348814741910324 * 5 / 2) = 2^62 + 2.
  const TimeNs two62 = TimeNs{1} << 62;
  const live::TimeMapping wide(-two62, 0, live::make_speed_factor(5, 2));
  EXPECT_EQ(wide.monotonic_at(two62), 3689348814741910324);
  EXPECT_EQ(wide.trajectory_at(3689348814741910324), two62 + 2);
  EXPECT_EQ(wide.monotonic_at(two62 + 2), 3689348814741910324);

  // Speed 1/3 with anchor (2^62, -2^62): t = 2^62 + 2^60 -> -2^62 + 3 * 2^60 = -2^60.
  const live::TimeMapping slow_wide(two62, -two62, live::make_speed_factor(1, 3));
  EXPECT_EQ(slow_wide.monotonic_at(two62 + (TimeNs{1} << 60)), -(TimeNs{1} << 60));
  EXPECT_EQ(slow_wide.trajectory_at(-(TimeNs{1} << 60)), two62 + (TimeNs{1} << 60));
  // t = int64 max: -2^62 + 3 (2^62 - 1) = 2^63 - 3 still fits;
  // t = int64 min: -2^62 + 3 (-2^63 - 2^62) does not.
  EXPECT_EQ(slow_wide.monotonic_at(std::numeric_limits<TimeNs>::max()), std::numeric_limits<TimeNs>::max() - 2);
  EXPECT_THROW(slow_wide.monotonic_at(std::numeric_limits<TimeNs>::min()), std::overflow_error);
  EXPECT_THROW(slow.monotonic_at(two62), std::overflow_error);

  // Speed 1 is a pure offset over the whole int64 range.
  const live::TimeMapping same(0, 0);
  EXPECT_EQ(same.monotonic_at(std::numeric_limits<TimeNs>::max()), std::numeric_limits<TimeNs>::max());
  EXPECT_EQ(same.trajectory_at(std::numeric_limits<TimeNs>::min()), std::numeric_limits<TimeNs>::min());
  const live::TimeMapping shifted(-5, 5);
  EXPECT_THROW(shifted.monotonic_at(std::numeric_limits<TimeNs>::max() - 5), std::overflow_error);
  EXPECT_EQ(shifted.monotonic_at(std::numeric_limits<TimeNs>::max() - 10), std::numeric_limits<TimeNs>::max());
}

TEST(TimeMapping, RoundTripsAndDefiningInequalitiesAtLargeTimes) {
  // For each speed p/q and random anchors/times with |.| <= 2^62, check
  //   M = monotonic_at(t):  (M - m0) p >= (t - t0) q > (M - 1 - m0) p   (ceil)
  //   T = trajectory_at(m): (T - t0) q <= (m - m0) p < (T + 1 - t0) q   (floor)
  // by 128-bit multiplication (no division), the Galois link between them,
  // and the round trip the speed guarantees.
  const TimeNs two62 = TimeNs{1} << 62;
  std::mt19937_64 rng(20240611);
  std::uniform_int_distribution<TimeNs> any(-two62, two62);
  const std::vector<live::SpeedFactor> speeds = {
      live::make_speed_factor(1, 1), live::parse_speed_factor("2.5"), live::parse_speed_factor("1/3"),
      live::make_speed_factor(7, 1000), live::make_speed_factor(1'000'000'000'000, 999'999'999'999)};
  const Int128 lo = std::numeric_limits<TimeNs>::min(), hi = std::numeric_limits<TimeNs>::max();
  std::size_t checked = 0, overflowed = 0;
  for (const auto& speed : speeds) {
    const Int128 p = speed.numerator, q = speed.denominator;
    for (int trial = 0; trial < 20000; ++trial) {
      const TimeNs t0 = any(rng), m0 = any(rng);
      // Half the times near the anchor (all fit), half anywhere.
      const TimeNs t = trial % 2 ? any(rng) : t0 / 2 + any(rng) / 1024;
      const TimeNs m = trial % 2 ? any(rng) : m0 / 2 + any(rng) / 1024;
      const live::TimeMapping map(t0, m0, speed);
      // True values as exact rationals: fits iff ceil/floor in int64 range.
      const Int128 m_num = static_cast<Int128>(m0) * p + (static_cast<Int128>(t) - t0) * q;  // m(t) * p
      const bool m_fits = m_num <= hi * p && m_num > (lo - 1) * p;
      if (!m_fits) {
        EXPECT_THROW(map.monotonic_at(t), std::overflow_error);
        ++overflowed;
      } else {
        const Int128 M = map.monotonic_at(t);
        ASSERT_GE((M - m0) * p, (static_cast<Int128>(t) - t0) * q);
        ASSERT_LT((M - 1 - m0) * p, (static_cast<Int128>(t) - t0) * q);
        if (p <= q) {
          ASSERT_EQ(map.trajectory_at(static_cast<TimeNs>(M)), t);  // speed <= 1
        } else {
          ASSERT_GE(map.trajectory_at(static_cast<TimeNs>(M)), t);
        }
        ++checked;
      }
      const Int128 t_num = static_cast<Int128>(t0) * q + (static_cast<Int128>(m) - m0) * p;  // t(m) * q
      const bool t_fits = t_num < (hi + 1) * q && t_num >= lo * q;
      if (!t_fits) {
        EXPECT_THROW(map.trajectory_at(m), std::overflow_error);
        ++overflowed;
        continue;
      }
      const Int128 T = map.trajectory_at(m);
      ASSERT_LE((T - t0) * q, (static_cast<Int128>(m) - m0) * p);
      ASSERT_GT((T + 1 - t0) * q, (static_cast<Int128>(m) - m0) * p);
      if (p >= q) {
        ASSERT_EQ(map.monotonic_at(static_cast<TimeNs>(T)), m);  // speed >= 1
      } else {
        ASSERT_LE(map.monotonic_at(static_cast<TimeNs>(T)), m);
      }
      // Galois: trajectory_at(m) >= t  <=>  m >= monotonic_at(t).
      if (m_fits) {
        ASSERT_EQ(map.trajectory_at(m) >= t, m >= map.monotonic_at(t));
      }
      ++checked;
    }
  }
  std::printf("time mapping: %zu exact checks, %zu overflow reports\n", checked, overflowed);
  EXPECT_GT(overflowed, 0u);
  EXPECT_GT(checked, 150000u);
}

TEST(TimeMapping, StartAlignments) {
  const auto speed = live::make_speed_factor(5, 2);
  // Start now: the start time is due at the monotonic reading.
  const auto now = live::TimeMapping::start_now(123'000'000'000, 42'000'000'000, speed);
  EXPECT_EQ(now.monotonic_at(123'000'000'000), 42'000'000'000);
  EXPECT_EQ(now.trajectory_at(42'000'000'000), 123'000'000'000);
  EXPECT_EQ(now.monotonic_at(128'000'000'000), 44'000'000'000);  // 5 s of trajectory in 2 s

  // Next whole realtime second, hand-computed:
  // realtime ...000.250 s with monotonic 5.000 s -> edge 0.750 s later.
  const TimeNs rt = 1'700'000'000'250'000'000;
  auto pps = live::TimeMapping::start_at_next_realtime_second(7, 5'000'000'000, rt);
  EXPECT_EQ(pps.anchor_monotonic_ns(), 5'750'000'000);
  EXPECT_EQ(pps.monotonic_at(7), 5'750'000'000);
  // Exactly on a second: the next one, 1 s later.
  pps = live::TimeMapping::start_at_next_realtime_second(0, 42, 1'700'000'000'000'000'000);
  EXPECT_EQ(pps.anchor_monotonic_ns(), 1'000'000'042);
  // One ns before a second: that second.
  pps = live::TimeMapping::start_at_next_realtime_second(0, 42, 1'699'999'999'999'999'999);
  EXPECT_EQ(pps.anchor_monotonic_ns(), 43);
  // Before 1970: realtime -1.25 s -> edge at -1 s, 0.25 s later.
  pps = live::TimeMapping::start_at_next_realtime_second(0, 100, -1'250'000'000);
  EXPECT_EQ(pps.anchor_monotonic_ns(), 250'000'100);
  // A lead of 0.75 s still makes the 0.75 s edge; 0.8 s needs the one after.
  pps = live::TimeMapping::start_at_next_realtime_second(0, 5'000'000'000, rt, 750'000'000);
  EXPECT_EQ(pps.anchor_monotonic_ns(), 5'750'000'000);
  pps = live::TimeMapping::start_at_next_realtime_second(0, 5'000'000'000, rt, 800'000'000);
  EXPECT_EQ(pps.anchor_monotonic_ns(), 6'750'000'000);
  // With a speed: trajectory 7 + 5 s is due 2 s after the edge.
  pps = live::TimeMapping::start_at_next_realtime_second(7, 5'000'000'000, rt, 0, speed);
  EXPECT_EQ(pps.monotonic_at(7 + 5'000'000'000), 7'750'000'000);
  EXPECT_THROW(live::TimeMapping::start_at_next_realtime_second(0, 0, rt, -1), std::invalid_argument);
  EXPECT_THROW(live::TimeMapping::start_at_next_realtime_second(0, std::numeric_limits<TimeNs>::max(), rt),
               std::overflow_error);
}

}  // namespace
}  // namespace unity_core_test_live_emitter
