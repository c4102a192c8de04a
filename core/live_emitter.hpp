// Live emission: what to send at each output-grid tick when the streaming
// smoother may not have produced that tick's sample in time (underrun).
//
// The caller (the daemon's emission loop) asks, in strictly increasing tick
// order and at each tick's monotonic deadline (core/time_mapping.hpp), for the
// sample of trajectory time t_ns. The emitter pulls the smoother's exact output
// through ExactSampleSource and answers with one of:
//   exact         the smoother's sample for t, unchanged;
//   extrapolated  (policy extrapolate) underrun: the exact IMU (Eq. 3.70, via
//                 imu_from_kinematics) of the constant-velocity, constant-body-
//                 rate continuation of the last emitted kinematics K_a (t_a):
//                   p = p_a + v_a dt, v = v_a, a = 0,
//                   R = R_a exp(omega_a dt), omega = omega_a,  dt = t - t_a,
//                 so a navigator integrating the stream follows that trajectory;
//   blending      exact samples are back after an extrapolation: over
//                 blend_ns the output moves from the extrapolated trajectory x
//                 to the exact one e with the C2 quintic smoothstep
//                 s(u) = 10u^3 - 15u^4 + 6u^5, u = (t - t_b) / blend_ns, where
//                 t_b is the last extrapolated tick (where the output was x):
//                   p = (1-s) x + s e,
//                   v = (1-s) x' + s e' + s' (e - x),
//                   a = (1-s) x'' + s e'' + 2 s' (e' - x') + s'' (e - x),
//                   R = R_x exp(s log(R_x^T R_e)) with its exact body rate
//                   (so3::geodesic_blend),
//                 and the IMU of those blended kinematics, so the output stays
//                 one consistent C1 (in fact C2) trajectory through the rejoin;
//                 the first tick with u >= 1 is exact again;
//   paused        (policy pause) underrun: nothing is sent; when exact samples
//                 are back the emitter resumes at the current tick (missed
//                 ticks are not sent late) without blending;
//   waiting       no exact sample has arrived yet since construction: nothing
//                 to send and nothing to extrapolate from (start-up, not an
//                 underrun).
// extrapolated and blending samples are both "not exact" (Emission::exact()).
//
// Exact samples are taken for tick t only when their t_ns == t. A sample with
// t_ns < t arrived too late for its tick (its tick was already answered) and
// is discarded (stale). A sample with t_ns > t means the smoother has no
// sample for t (it skipped it); it is kept for its own tick and t counts as
// missing. A sample with a non-finite value, or whose ImuSample.t_ns differs
// from its Kinematics.t_ns, is discarded as invalid and treated as missing.
// No output is ever non-finite: an extrapolation or blend that would not be
// finite (only possible with absurd magnitudes) is withheld and counted as
// paused.
//
// Memory is O(1): the last emitted kinematics, the extrapolation anchor and at
// most one exact sample pulled ahead of the current tick. The emitter never
// pulls past the first sample at or after the current tick, so a smoother that
// runs ahead keeps its own samples until they are due.
//
// Pure logic: no clocks, no I/O; time comes in as the tick.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "core/imu_model.hpp"
#include "core/stream.hpp"
#include "core/trajectory.hpp"

namespace imuemu::live {

// One output sample of the streaming smoother: its kinematics and the ideal
// IMU computed from them, both stamped with the same grid time.
// The smoother's output sample (core/stream.hpp).
using ExactSample = StreamSample;

// The smoother's output as the emitter sees it. Samples come in strictly
// increasing t_ns order on the output grid.
class ExactSampleSource {
 public:
  virtual ~ExactSampleSource() = default;
  // The next sample the smoother has produced and not yet handed out, or
  // nullopt if it has produced nothing further yet (a later call may then
  // return one). A returned sample is consumed.
  virtual std::optional<ExactSample> next_sample() = 0;
};

// The streaming engine as a sample source.
class StreamSampleSource final : public ExactSampleSource {
 public:
  explicit StreamSampleSource(StreamPipeline& engine) : engine_(engine) {}
  std::optional<ExactSample> next_sample() override {
    StreamSample s;
    if (!engine_.pop(s)) return std::nullopt;
    return s;
  }

 private:
  StreamPipeline& engine_;
};

enum class UnderrunPolicy {
  extrapolate,  // keep sending: constant-velocity/rate continuation, then blend back
  pause,        // send nothing until exact samples are back
};
// "extrapolate" or "pause"; throws std::invalid_argument naming the text otherwise.
UnderrunPolicy underrun_policy_from_string(const std::string& name);
std::string to_string(UnderrunPolicy policy);

struct LiveEmitterOptions {
  SceneModel scene;  // physics of the extrapolated/blended IMU (Eq. 3.70)
  UnderrunPolicy underrun = UnderrunPolicy::extrapolate;
  // Rejoin blend length after an extrapolation; 0 rejoins with a step.
  TimeNs blend_ns = 200'000'000;
};

// gap: the trajectory itself has no sample at this tick (the smoother's
// output goes on after it: a gap split by gap_policy split, a loop seam), so
// nothing is sent, as from a device that is off; output resumes exact at the
// first tick after the gap, without extrapolating into it or blending out of
// it (what lies across a gap is not one motion).
enum class EmissionStatus { exact, extrapolated, blending, paused, waiting, gap };
std::string to_string(EmissionStatus status);

struct Emission {
  EmissionStatus status = EmissionStatus::waiting;
  // Valid only if has_sample(); stamped with the tick time.
  Kinematics kinematics;
  ImuSample imu;

  // Something is to be sent for this tick.
  bool has_sample() const {
    return status == EmissionStatus::exact || status == EmissionStatus::extrapolated ||
           status == EmissionStatus::blending;
  }
  // The sent sample is the smoother's own (not extrapolated, not blended).
  bool exact() const { return status == EmissionStatus::exact; }
};

// Counters since construction. Every tick is counted in exactly one of
// exact/extrapolated/blending/paused/waiting/gap, so they sum to ticks.
struct LiveCounters {
  std::uint64_t ticks = 0;         // emit() calls
  std::uint64_t exact = 0;         // ticks sent with the smoother's sample
  std::uint64_t extrapolated = 0;  // ticks sent extrapolated
  std::uint64_t blending = 0;      // ticks sent blended (rejoin)
  std::uint64_t paused = 0;        // ticks sent nothing after a first sample (pause policy, withheld output)
  std::uint64_t waiting = 0;       // ticks before the first exact sample (nothing sent)
  std::uint64_t gap = 0;           // ticks inside a gap of the trajectory (nothing sent)
  std::uint64_t gap_events = 0;    // gaps entered
  // Transitions into underrun: a tick without an exact sample right after a
  // tick that was exact or blending (a run of missing ticks counts once).
  std::uint64_t underrun_events = 0;
  std::uint64_t stale_discarded = 0;    // exact samples for ticks already answered
  std::uint64_t invalid_discarded = 0;  // non-finite or inconsistently stamped samples
};

class LiveEmitter {
 public:
  // Throws std::invalid_argument if blend_ns < 0.
  explicit LiveEmitter(const LiveEmitterOptions& options);

  // What to send for tick_ns. Ticks must strictly increase (std::invalid_argument
  // otherwise, naming both ticks). Pulls from `source` only as far as tick_ns
  // (plus at most one sample ahead, kept for its own tick).
  Emission emit(TimeNs tick_ns, ExactSampleSource& source);

  const LiveCounters& counters() const { return counters_; }
  const LiveEmitterOptions& options() const { return options_; }

 private:
  enum class Mode { waiting, tracking, extrapolating, blending, paused, gap };

  // The exact sample for tick_ns if the source has it; discards stale and
  // invalid samples on the way and keeps one future sample in ahead_.
  std::optional<ExactSample> exact_for(TimeNs tick_ns, ExactSampleSource& source);
  Kinematics extrapolated_at(TimeNs tick_ns) const;
  Kinematics blended_at(TimeNs tick_ns, const Kinematics& exact) const;
  Emission send(EmissionStatus status, const Kinematics& k, const ImuSample* exact_imu);
  Emission withhold(EmissionStatus status);

  LiveEmitterOptions options_;
  LiveCounters counters_;
  Mode mode_ = Mode::waiting;
  std::optional<TimeNs> last_tick_ns_;
  Kinematics last_sent_;             // last kinematics actually sent
  Kinematics anchor_;                // extrapolation start (valid while extrapolating/blending)
  TimeNs blend_start_ns_ = 0;        // t_b: last extrapolated tick
  std::optional<ExactSample> ahead_; // a pulled sample for a later tick
  bool tick_sample_invalid_ = false;  // exact_for discarded an invalid sample for its tick
};

}  // namespace imuemu::live
