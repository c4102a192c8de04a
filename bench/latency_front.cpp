// The latency-versus-error front of the live methods (issue 17, acceptance 3):
// a maneuvering flat-scene trajectory known in closed form, streamed as poses
// with their velocity and body rate (a simulator's) at 100, 250 and 1000 Hz,
// emitted at 1 kHz under each latency budget exactly as imuemud does: the
// smoothing method (Eq. 3.68) when the budget covers its look-ahead, else the
// causal Hermite method (core/causal_hermite.hpp); a pose is available at
// its own time (arrival = pose time) and the tick of time t is computed at
// t + budget - producer lead (daemon/scene/scene_config.cpp latency_plan), where
// the live emitter (core/live_emitter.hpp) extrapolates (flagged) what is not
// there yet and blends back. Every emitted IMU sample is compared with the
// analytic IMU (Eq. 3.70 of the exact motion).
//
//   build/release/bench/latency_front > docs/latency_front.csv
//   /usr/bin/python3 scripts/latency_front_plot.py docs/latency_front.csv docs/latency_front.png
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <vector>

#include "core/imu_model.hpp"
#include "core/live_emitter.hpp"
#include "core/so3.hpp"
#include "core/stream.hpp"

namespace imuemu {
namespace {

constexpr double kPi = std::numbers::pi;

// A turning, climbing, rolling vehicle: circle of radius 200 m at 40 m/s
// (omega_turn = 0.2 rad/s, 8 m/s^2 centripetal), a 3 m altitude wobble at
// 0.7 Hz, heading following the track, roll 0.3 rad + 0.15 rad at 1.3 Hz.
struct Maneuver {
  static constexpr double r = 200.0, w = 0.2, dz = 3.0, fz = 2 * kPi * 0.7, roll0 = 0.3, droll = 0.15,
                          fr = 2 * kPi * 1.3;
  Kinematics at(double t) const {
    Kinematics k;
    k.position_m = {r * std::sin(w * t), r * (1 - std::cos(w * t)), -dz * std::sin(fz * t)};
    k.velocity_m_s = {r * w * std::cos(w * t), r * w * std::sin(w * t), -dz * fz * std::cos(fz * t)};
    k.acceleration_m_s2 = {-r * w * w * std::sin(w * t), r * w * w * std::cos(w * t),
                           dz * fz * fz * std::sin(fz * t)};
    const double psi = w * t, phi = roll0 + droll * std::sin(fr * t);
    const double psi_dot = w, phi_dot = droll * fr * std::cos(fr * t);
    const Mat3 Rx = so3::exp(Vec3(phi, 0, 0));
    k.attitude = so3::exp(Vec3(0, 0, psi)) * Rx;
    // omega_b = Rx^T psi' e_z + phi' e_x.
    k.angular_rate_rad_s = psi_dot * (Rx.transpose() * Vec3::UnitZ()) + phi_dot * Vec3::UnitX();
    return k;
  }
};

struct Result {
  double gyro_rms = 0, gyro_max = 0, accel_rms = 0, accel_max = 0, flagged = 0;
  bool causal = false;
  TimeNs lookahead_ns = 0;
};

Result run(double pose_hz, double budget_ms, double seconds) {
  const Maneuver m;
  PipelineOptions po;
  po.scene.physics = Physics::flat;
  po.rate_hz = 1000;
  po.gap_policy = GapPolicy::split;
  po.max_gap_s = 1.0;
  const auto h_ns = static_cast<TimeNs>(std::llround(1e9 / pose_hz));
  po.kernel.delta = static_cast<int>(std::llround(1000.0 / pose_hz));  // window = one knot interval (the daemon's default)
  const TimeNs smoothing_lookahead = StreamPipeline::lookahead_ns(po, h_ns);
  const auto budget_ns = static_cast<TimeNs>(std::llround(budget_ms * 1e6));
  Result r;
  r.causal = budget_ns < smoothing_lookahead + 20'000'000;  // daemon/scene/scene_config.cpp latency_plan
  po.causal = r.causal;
  r.lookahead_ns = StreamPipeline::lookahead_ns(po, h_ns);
  const TimeNs lead_ns = r.causal ? std::clamp<TimeNs>((budget_ns - h_ns) / 2, 500'000, 20'000'000) : 20'000'000;
  StreamPipeline engine(po);
  live::StreamSampleSource source(engine);
  live::LiveEmitterOptions eo;
  eo.scene = po.scene;
  eo.blend_ns = r.causal ? 20'000'000 : 200'000'000;
  live::LiveEmitter emitter(eo);
  const TimeNs end_ns = static_cast<TimeNs>(seconds * 1e9);
  TimeNs next_pose_ns = 0;
  double g2 = 0, a2 = 0;
  std::size_t n = 0, flagged = 0;
  // Skip the first second: start-up (waiting) is not the steady state.
  for (TimeNs t = 0; t <= end_ns; t += 1'000'000) {
    const TimeNs computed_at = t + budget_ns - lead_ns;
    while (next_pose_ns <= computed_at && next_pose_ns <= end_ns + h_ns * 8) {
      const Kinematics k = m.at(static_cast<double>(next_pose_ns) * 1e-9);
      PoseRates rates;
      rates.velocity_m_s = k.velocity_m_s;
      rates.angular_rate_rad_s = k.angular_rate_rad_s;
      engine.push({next_pose_ns, k.position_m, k.attitude}, rates);
      next_pose_ns += h_ns;
    }
    const live::Emission e = emitter.emit(t, source);
    if (t < kNsPerSecond || !e.has_sample()) continue;
    Kinematics truth = m.at(static_cast<double>(t) * 1e-9);
    truth.t_ns = t;
    const ImuSample ideal = imu_from_kinematics(po.scene, truth);
    const double ge = (e.imu.gyro_rad_s - ideal.gyro_rad_s).norm(), ae = (e.imu.accel_m_s2 - ideal.accel_m_s2).norm();
    g2 += ge * ge;
    a2 += ae * ae;
    r.gyro_max = std::max(r.gyro_max, ge);
    r.accel_max = std::max(r.accel_max, ae);
    if (!e.exact()) ++flagged;
    ++n;
  }
  r.gyro_rms = std::sqrt(g2 / static_cast<double>(n));
  r.accel_rms = std::sqrt(a2 / static_cast<double>(n));
  r.flagged = static_cast<double>(flagged) / static_cast<double>(n);
  return r;
}

}  // namespace
}  // namespace imuemu

int main() {
  std::printf("pose_hz,budget_ms,method,lookahead_ms,gyro_rms_rad_s,gyro_max_rad_s,accel_rms_m_s2,accel_max_m_s2,flagged_fraction\n");
  for (double pose_hz : {100.0, 250.0, 1000.0}) {
    for (double budget_ms : {1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 300.0}) {
      const imuemu::Result r = imuemu::run(pose_hz, budget_ms, 20.0);
      std::printf("%.0f,%.0f,%s,%.1f,%.3e,%.3e,%.3e,%.3e,%.4f\n", pose_hz, budget_ms, r.causal ? "causal" : "smoothing",
                  static_cast<double>(r.lookahead_ns) * 1e-6, r.gyro_rms, r.gyro_max, r.accel_rms, r.accel_max,
                  r.flagged);
    }
  }
  return 0;
}
