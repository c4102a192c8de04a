#include "core/live_emitter.hpp"

#include <cstdint>
#include <stdexcept>
#include <utility>

#include "core/smoothing.hpp"
#include "core/so3.hpp"
#include "core/time_arith.hpp"

namespace imuemu::live {

namespace {

// to - from for to >= from, exactly (core/time_arith.hpp).
std::uint64_t ns_after(TimeNs from_ns, TimeNs to_ns) { return ns_between(from_ns, to_ns); }
double seconds_after(TimeNs from_ns, TimeNs to_ns) { return static_cast<double>(ns_after(from_ns, to_ns)) * 1e-9; }

bool finite(const Vec3& v) { return v.allFinite(); }
bool finite(const Kinematics& k) {
  return finite(k.position_m) && finite(k.velocity_m_s) && finite(k.acceleration_m_s2) && k.attitude.allFinite() &&
         finite(k.angular_rate_rad_s);
}
bool finite(const ImuSample& s) { return finite(s.gyro_rad_s) && finite(s.accel_m_s2); }

bool valid(const ExactSample& sample) {
  return sample.kinematics.t_ns == sample.imu.t_ns && finite(sample.kinematics) && finite(sample.imu);
}

}  // namespace

UnderrunPolicy underrun_policy_from_string(const std::string& name) {
  if (name == "extrapolate") return UnderrunPolicy::extrapolate;
  if (name == "pause") return UnderrunPolicy::pause;
  throw std::invalid_argument("underrun policy '" + name + "': expected extrapolate or pause");
}

std::string to_string(UnderrunPolicy policy) {
  return policy == UnderrunPolicy::extrapolate ? "extrapolate" : "pause";
}

std::string to_string(EmissionStatus status) {
  switch (status) {
    case EmissionStatus::exact: return "exact";
    case EmissionStatus::extrapolated: return "extrapolated";
    case EmissionStatus::blending: return "blending";
    case EmissionStatus::paused: return "paused";
    case EmissionStatus::waiting: return "waiting";
    case EmissionStatus::gap: return "gap";
  }
  return "unknown";
}

LiveEmitter::LiveEmitter(const LiveEmitterOptions& options) : options_(options) {
  if (options.blend_ns < 0) {
    throw std::invalid_argument("live emitter: blend time " + std::to_string(options.blend_ns) +
                                " ns: expected >= 0");
  }
}

std::optional<ExactSample> LiveEmitter::exact_for(TimeNs tick_ns, ExactSampleSource& source) {
  tick_sample_invalid_ = false;
  while (true) {
    std::optional<ExactSample> sample;
    if (ahead_) {
      sample = std::move(ahead_);
      ahead_.reset();
    } else {
      sample = source.next_sample();
      if (!sample) return std::nullopt;  // the smoother has not got this far yet
      if (!valid(*sample)) {
        ++counters_.invalid_discarded;
        if (sample->kinematics.t_ns == tick_ns) tick_sample_invalid_ = true;
        continue;
      }
    }
    const TimeNs t_ns = sample->kinematics.t_ns;
    if (t_ns < tick_ns) {
      ++counters_.stale_discarded;  // its tick has been answered already
      continue;
    }
    if (t_ns == tick_ns) return sample;
    ahead_ = std::move(sample);  // for a later tick: this one has no sample
    return std::nullopt;
  }
}

Kinematics LiveEmitter::extrapolated_at(TimeNs tick_ns) const {
  const double dt_s = seconds_after(anchor_.t_ns, tick_ns);
  Kinematics k;
  k.t_ns = tick_ns;
  k.position_m = anchor_.position_m + anchor_.velocity_m_s * dt_s;
  k.velocity_m_s = anchor_.velocity_m_s;
  k.acceleration_m_s2 = Vec3::Zero();
  // R' = R [omega] with constant omega: R(t) = R_a exp(omega dt).
  k.attitude = anchor_.attitude * so3::exp(anchor_.angular_rate_rad_s * dt_s);
  k.angular_rate_rad_s = anchor_.angular_rate_rad_s;
  return k;
}

Kinematics LiveEmitter::blended_at(TimeNs tick_ns, const Kinematics& exact) const {
  const Kinematics x = extrapolated_at(tick_ns);
  const double blend_s = static_cast<double>(options_.blend_ns) * 1e-9;
  const smoothing::QuinticStep w = smoothing::quintic_step(seconds_after(blend_start_ns_, tick_ns) / blend_s);
  const double s = w.s, ds = w.ds_du / blend_s, d2s = w.d2s_du2 / (blend_s * blend_s);  // d/dt, d2/dt2
  const Vec3 dp = exact.position_m - x.position_m, dv = exact.velocity_m_s - x.velocity_m_s;
  Kinematics k;
  k.t_ns = tick_ns;
  // Product rule on p = (1-s) x + s e = x + s (e - x).
  k.position_m = (1.0 - s) * x.position_m + s * exact.position_m;
  k.velocity_m_s = (1.0 - s) * x.velocity_m_s + s * exact.velocity_m_s + ds * dp;
  k.acceleration_m_s2 = (1.0 - s) * x.acceleration_m_s2 + s * exact.acceleration_m_s2 + 2.0 * ds * dv + d2s * dp;
  k.attitude = x.attitude;
  k.angular_rate_rad_s = x.angular_rate_rad_s;
  so3::geodesic_blend(k.attitude, k.angular_rate_rad_s, exact.attitude, exact.angular_rate_rad_s, s, ds, true);
  return k;
}

Emission LiveEmitter::send(EmissionStatus status, const Kinematics& k, const ImuSample* exact_imu) {
  Emission out;
  out.status = status;
  out.kinematics = k;
  out.imu = exact_imu ? *exact_imu : imu_from_kinematics(options_.scene, k);
  if (!finite(out.kinematics) || !finite(out.imu)) return withhold(EmissionStatus::paused);
  switch (status) {
    case EmissionStatus::exact: ++counters_.exact; break;
    case EmissionStatus::extrapolated: ++counters_.extrapolated; break;
    case EmissionStatus::blending: ++counters_.blending; break;
    case EmissionStatus::paused:
    case EmissionStatus::waiting:
    case EmissionStatus::gap: break;  // not sent through here
  }
  last_sent_ = k;
  return out;
}

Emission LiveEmitter::withhold(EmissionStatus status) {
  if (status == EmissionStatus::waiting) {
    ++counters_.waiting;
  } else if (status == EmissionStatus::gap) {
    ++counters_.gap;
  } else {
    ++counters_.paused;
  }
  Emission out;
  out.status = status;
  return out;
}

Emission LiveEmitter::emit(TimeNs tick_ns, ExactSampleSource& source) {
  if (last_tick_ns_ && tick_ns <= *last_tick_ns_) {
    throw std::invalid_argument("live emitter: tick " + std::to_string(tick_ns) + " ns after tick " +
                                std::to_string(*last_tick_ns_) + " ns: expected strictly increasing ticks");
  }
  ++counters_.ticks;
  const std::optional<ExactSample> exact = exact_for(tick_ns, source);
  Emission out;
  if (exact) {
    if (mode_ == Mode::gap) mode_ = Mode::tracking;  // a new stretch of trajectory: nothing to blend from
    if (mode_ == Mode::extrapolating) {
      // Rejoin: the blend starts at the last extrapolated tick, where the
      // output was the extrapolation itself (s = 0), so it is continuous there.
      blend_start_ns_ = *last_tick_ns_;
      mode_ = Mode::blending;
    }
    const bool still_blending = mode_ == Mode::blending &&
                                ns_after(blend_start_ns_, tick_ns) < static_cast<std::uint64_t>(options_.blend_ns);
    if (still_blending) {
      out = send(EmissionStatus::blending, blended_at(tick_ns, exact->kinematics), nullptr);
    } else {
      mode_ = Mode::tracking;  // also resumes after a pause, at this tick
      out = send(EmissionStatus::exact, exact->kinematics, &exact->imu);
    }
  } else if (ahead_ && !tick_sample_invalid_ && mode_ != Mode::waiting) {
    // The smoother is past this tick without a sample for it: not late, the
    // trajectory has a gap here (its output grid is contiguous otherwise; an
    // invalid sample for this tick is a fault, bridged as an underrun). Also
    // ends an extrapolation begun before the gap was known (live input).
    if (mode_ != Mode::gap) ++counters_.gap_events;
    mode_ = Mode::gap;
    out = withhold(EmissionStatus::gap);
  } else {
    if (mode_ == Mode::tracking || mode_ == Mode::blending) {
      ++counters_.underrun_events;
      if (options_.underrun == UnderrunPolicy::extrapolate) {
        anchor_ = last_sent_;  // continue from what the receiver last got
        mode_ = Mode::extrapolating;
      } else {
        mode_ = Mode::paused;
      }
    }
    switch (mode_) {
      case Mode::waiting: out = withhold(EmissionStatus::waiting); break;
      case Mode::extrapolating: out = send(EmissionStatus::extrapolated, extrapolated_at(tick_ns), nullptr); break;
      default: out = withhold(EmissionStatus::paused); break;
    }
  }
  last_tick_ns_ = tick_ns;
  return out;
}

}  // namespace imuemu::live
