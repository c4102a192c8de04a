// The low-latency live method (GitHub issue 17): causal cubic Hermite
// interpolation between the last two poses, for closed-loop benches where the
// thesis' smoothing window (Eq. 3.68, look-ahead of several knot intervals)
// delays the IMU too much.
//
// Between knots k-1 and k (interval h, tau = (t - t_{k-1}) / h in [0, 1]):
//   position  p(tau) = cubic Hermite of (p_{k-1}, h v_{k-1}, p_k, h v_k);
//   attitude  R(tau) = R_{k-1} exp(rho(tau)), rho the cubic Hermite in the
//             chart of R_{k-1} with rho(0) = 0, rho'(0) = h omega_{k-1},
//             rho(1) = log(R_{k-1}^T R_k), rho'(1) = h W^-1(rho(1)) omega_k,
//             and the body rate omega = W(rho) rho' / h (Eq. 3.59, as the
//             thesis' Hermite base curve carries knot rates between charts by
//             W^-1, Eq. 3.63);
//   v = p'/h, a = p''/h^2: exact derivatives of the curve, so the IMU of
//   Eq. 3.70 integrates back to the emitted poses.
// The knot slopes are the pose's own rates when it carries them (a
// simulator's velocity and body rate: pose datagram v2, MAVLink
// HIL_STATE_QUATERNION), else estimated causally from the last four knots
// (the derivative at the newest knot of the cubic through them, third order
// in h; with fewer knots at a run's start, the quadratic or the chord). The curve is C1 across knots (C2 only
// with exact slopes of a cubic motion); its accelerometer is piecewise linear.
//
// Every output-grid sample in (t_{k-1}, t_k] is final as soon as knot k
// arrives: the look-ahead is one knot interval (plus the time the pose takes
// to arrive), against (1 + spline_window_knots) intervals + 3 windows for the
// smoothing pipeline. What lies beyond the newest knot is the live emitter's
// to bridge (core/live_emitter.hpp: extrapolated with a flag, then blended
// back), bounded by the scene's latency budget.
//
// Grid and output as StreamPipeline (core/stream.hpp): t_n = t_first +
// floor(n 1e9 / rate), the ideal IMU by imu_from_kinematics. Pure maths.
#pragma once

#include <cstdint>
#include <deque>
#include <numbers>
#include <optional>

#include "core/imu_model.hpp"
#include "core/pose_rates.hpp"
#include "core/trajectory.hpp"

namespace imuemu {

// One output sample: the curve's kinematics and the ideal IMU (Eq. 3.70).
struct CausalSample {
  Kinematics kinematics;
  ImuSample imu;
};

struct CausalHermiteOptions {
  SceneModel scene;
  std::int64_t rate_hz = 400;
  // A knot interval longer than this starts a new run (no interpolation
  // across it), as the smoothing pipeline's gap policy split.
  TimeNs max_gap_ns = 10'000'000'000;
};

class CausalHermite {
 public:
  // Throws std::invalid_argument for rate_hz < 1 or max_gap_ns < 1.
  explicit CausalHermite(const CausalHermiteOptions& options);

  // Appends a knot; the samples it completes become ready. Throws
  // std::invalid_argument (changing nothing) for a knot not strictly later
  // than the previous one, a non-finite pose or rate, or an antipodal step
  // (rotation of pi from the previous knot: no unique geodesic, thesis
  // §3.6.1).
  void push(const Pose& knot, const PoseRates& rates = {});
  bool pop(CausalSample& out);
  std::size_t ready() const { return out_.size(); }

  std::size_t knots_pushed() const { return knots_pushed_; }
  TimeNs first_knot_ns() const { return first_knot_ns_; }
  TimeNs last_knot_ns() const { return knots_.empty() ? 0 : knots_.back().pose.t_ns; }
  // Newest knot time minus the newest ready sample's (0 before any).
  TimeNs current_lag_ns() const;
  std::uint64_t estimated_slopes() const { return estimated_slopes_; }  // knots whose slopes were estimated
  std::uint64_t runs() const { return runs_; }                          // gap-free stretches started

  // The look-ahead: one knot interval.
  static TimeNs lookahead_ns(TimeNs knot_interval_ns) { return knot_interval_ns; }

 private:
  struct Knot {
    Pose pose;
    Vec3 velocity_m_s = Vec3::Zero();
    Vec3 rate_rad_s = Vec3::Zero();
    bool estimated_later = false;  // a run's first knot without rates: the chord's slopes once the second arrives
  };
  TimeNs grid_time(std::int64_t n) const;
  void estimate_slopes(Knot& k) const;
  void emit_segment(const Knot& a, const Knot& b);

  CausalHermiteOptions options_;
  std::deque<Knot> knots_;  // this run's last three knots
  std::deque<CausalSample> out_;
  std::size_t knots_pushed_ = 0;
  TimeNs first_knot_ns_ = 0;
  TimeNs run_origin_ns_ = 0;     // the grid of the current run: t_n = origin + floor(n 1e9 / rate)
  std::int64_t next_index_ = 0;  // next grid index to emit
  TimeNs newest_output_ns_ = 0;
  bool any_output_ = false;
  std::uint64_t estimated_slopes_ = 0;
  std::uint64_t runs_ = 0;
};

}  // namespace imuemu
