// The fault timeline (core/fault/timeline.hpp).
#include "core/fault/timeline.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "core/time_arith.hpp"

namespace imuemu::fault {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kG = 9.80665;

// SplitMix64's finaliser (Steele, Lea, Flood, OOPSLA 2014): the counter-based
// key of one draw.
constexpr std::uint64_t mix64(std::uint64_t z) noexcept {
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
  return z ^ (z >> 31);
}

// What a draw is for (the last part of its key).
enum Draw : std::uint64_t {
  kDrawEvent = 1,        // spikes, per-packet probabilities
  kDrawBurst = 2,        // drop bursts' starts
  kDrawBits = 3,         // bit error positions' seed
  kDrawGarbage = 16,     // + 3 * triad + axis
  kDrawNoise = 32,       // + 3 * triad + axis
};

std::uint64_t draw_key(std::uint64_t seed, std::uint64_t stream, std::uint64_t k, std::uint64_t what) noexcept {
  std::uint64_t h = mix64(seed ^ 0xFA017FA017FA017FULL);
  h = mix64(h ^ stream);
  h = mix64(h ^ k);
  return mix64(h ^ what);
}

sensor::Stream draw(std::uint64_t seed, std::uint64_t stream, std::uint64_t k, std::uint64_t what) noexcept {
  return sensor::Stream{draw_key(seed, stream, k, what)};
}

double uniform01(std::uint64_t seed, std::uint64_t stream, std::uint64_t k, std::uint64_t what) noexcept {
  sensor::Stream s = draw(seed, stream, k, what);
  return s.uniform();
}

// Stream ids: scene faults by index, random ones by (window, index), the
// injected ones by id: disjoint ranges.
constexpr std::uint64_t kStreamRandom = 1ULL << 63;
constexpr std::uint64_t kStreamInjected = 1ULL << 62;

bool has(const FaultSpec& s, Triad t) { return (static_cast<unsigned>(s.triad) & static_cast<unsigned>(t)) != 0; }

// Integral over [0, tau] of min(cap, rate s) ds (rate >= 0, cap > 0 or inf).
double capped_ramp_integral(double rate, double cap, double tau) noexcept {
  if (tau <= 0.0 || rate <= 0.0) return 0.0;
  if (rate * tau <= cap) return 0.5 * rate * tau * tau;
  const double t_cap = cap / rate;
  return 0.5 * cap * t_cap + cap * (tau - t_cap);
}

std::uint32_t history_samples(std::int64_t rate_hz) {
  // ceil(kMaxDelayNs rate / 1e9) + 1 (the current sample), at most kMaxDelaySamples.
  const double n = std::ceil(static_cast<double>(kMaxDelayNs) * 1e-9 * static_cast<double>(rate_hz)) + 1.0;
  return static_cast<std::uint32_t>(std::min(n, static_cast<double>(kMaxDelaySamples)));
}

}  // namespace

DeviceContext device_context(const std::string& device, std::int64_t rate_hz,
                             const std::optional<sensor::SensorModelSpec>& sensor) {
  DeviceContext c;
  c.device = device;
  c.rate_hz = rate_hz;
  if (sensor) {
    if (sensor->gyro.range > 0.0) c.gyro_range_rad_s = sensor->gyro.range;
    if (sensor->accel.range > 0.0) c.accel_range_m_s2 = sensor->accel.range;
    c.gyro_noise_density = sensor->gyro.white_density;
    c.accel_noise_density = sensor->accel.white_density;
  }
  return c;
}

FaultSpec random_fault_parameters() {
  FaultSpec s;
  s.gyro_bias_rad_s = 1.0 * kPi / 180.0;
  s.accel_bias_m_s2 = 0.050 * kG;
  s.gyro_ramp_rad_s2 = 0.01 * kPi / 180.0;
  s.accel_ramp_m_s3 = 0.001 * kG;
  s.scale_ppm = 10'000.0;
  s.noise_factor = 10.0;
  s.rate_hz = 1.0;
  s.probability = 0.1;
  s.bit_error_rate = 1e-4;
  s.divisor = 10;
  s.on_ns = 100'000'000;
  s.off_ns = 100'000'000;
  s.delay_ns = 50'000'000;
  s.burst_samples = 0;
  s.truncate_bytes = 4;
  s.sequence_step = 100;
  s.time_step_ns = 100'000'000;
  s.babble_factor = 3;
  s.can_id = 0x123;
  s.source = "random";
  return s;
}

namespace {
// The spec of one random fault of `kind` from the settings.
FaultSpec random_spec(const RandomFaults& r, Kind kind) {
  FaultSpec s = r.parameters;
  s.kind = kind;
  s.clock = Clock::since_start;
  s.duration_ns = r.duration_ns;
  s.source = "random";
  if (kind == Kind::plausible_drift) {
    const FaultSpec d = default_spec(Kind::plausible_drift);
    s.gyro_bias_rad_s = d.gyro_bias_rad_s;
    s.gyro_ramp_rad_s2 = d.gyro_ramp_rad_s2;
    s.accel_bias_m_s2 = d.accel_bias_m_s2;
    s.accel_ramp_m_s3 = d.accel_ramp_m_s3;
  }
  return s;
}
}  // namespace

void validate(const RandomFaults& r) {
  if (!(r.per_hour >= 0.0 && r.per_hour <= kMaxRandomPerHour))
    throw std::invalid_argument("random faults: per_hour: expected a rate in [0, " +
                                std::to_string(static_cast<int>(kMaxRandomPerHour)) + "] per hour");
  if (r.per_hour == 0.0) return;
  if (r.kinds.empty()) throw std::invalid_argument("random faults: types: expected at least one fault type");
  if (r.duration_ns <= 0) throw std::invalid_argument("random faults: duration: expected > 0");
  for (Kind k : r.kinds) {
    try {
      validate(random_spec(r, k));
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument(std::string("random faults: ") + e.what());
    }
  }
}

std::uint32_t bit_flip_count(double rate, std::size_t frame_bits, std::uint64_t seed) noexcept {
  if (!(rate > 0.0) || frame_bits == 0) return 0;
  const double n = static_cast<double>(frame_bits);
  const double mean = std::min(rate, 1.0) * n;
  sensor::Stream s{mix64(seed ^ 0xB17F11B5ULL)};
  double count = 0.0;
  if (mean < 30.0) {
    // Knuth's inversion: multiply uniforms until below e^-mean.
    const double limit = std::exp(-mean);
    double p = s.uniform();
    while (p > limit && count < n) {
      count += 1.0;
      p *= s.uniform();
    }
  } else {
    count = std::round(mean + std::sqrt(mean * (1.0 - std::min(rate, 1.0))) * s.gaussian());
  }
  return static_cast<std::uint32_t>(std::clamp(count, 0.0, n));
}

FaultTimeline::FaultTimeline(TimelineOptions options) : options_(std::move(options)) {
  const DeviceContext& c = options_.context;
  if (c.rate_hz < 1 || c.rate_hz > 1'000'000)
    throw std::invalid_argument("fault timeline: rate " + std::to_string(c.rate_hz) + " Hz is not in 1..1000000");
  if (!(std::isfinite(c.gyro_range_rad_s) && c.gyro_range_rad_s > 0.0 && std::isfinite(c.accel_range_m_s2) &&
        c.accel_range_m_s2 > 0.0))
    throw std::invalid_argument("fault timeline: the sensor ranges must be finite and > 0");
  if (!c.gyro_noise_density.allFinite() || !c.accel_noise_density.allFinite())
    throw std::invalid_argument("fault timeline: the noise densities must be finite");
  if (options_.max_faults < 1 || options_.event_capacity < 2)
    throw std::invalid_argument("fault timeline: max_faults >= 1 and event_capacity >= 2 expected");
  if (options_.faults.size() > options_.max_faults)
    throw std::invalid_argument("fault timeline: " + std::to_string(options_.faults.size()) +
                                " faults for device '" + c.device + "'; at most " +
                                std::to_string(options_.max_faults));
  validate(options_.random);
  history_.resize(history_samples(c.rate_hz));
  device_hash_ = sensor::device_hash(c.device);
  for (std::size_t i = 0; i < options_.faults.size(); ++i) {
    FaultSpec& spec = options_.faults[i];
    try {
      validate(spec);
      check_fits(spec);
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument("fault " + std::to_string(i) + " of device '" + c.device + "': " + e.what());
    }
  }
  entries_.reserve(options_.max_faults);
  for (std::size_t i = 0; i < options_.faults.size(); ++i) {
    Entry e;
    e.id = next_id_++;
    e.stream = i;
    e.spec = options_.faults[i];
    e.spec.device = c.device;
    if (e.spec.source.empty()) e.spec.source = "scene";
    entries_.push_back(std::move(e));
  }
  events_.resize(options_.event_capacity);
}

TimeNs max_delay_ns_at(std::int64_t rate_hz) {
  if (rate_hz < 1) return 0;
  // history_samples - 1 samples back.
  const double ns = static_cast<double>(history_samples(rate_hz) - 1) * 1e9 / static_cast<double>(rate_hz);
  return std::min(kMaxDelayNs, static_cast<TimeNs>(std::floor(ns)));
}

TimeNs FaultTimeline::max_delay_ns() const { return max_delay_ns_at(options_.context.rate_hz); }

void FaultTimeline::check_fits(const FaultSpec& spec) const {
  if (spec.kind == Kind::delayed && spec.delay_ns > max_delay_ns())
    throw std::invalid_argument("fault delayed: delay: " + std::to_string(spec.delay_ns) + " ns is beyond this device's history of " +
                                std::to_string(history_.size() - 1) + " samples at " +
                                std::to_string(options_.context.rate_hz) + " Hz (at most " +
                                std::to_string(max_delay_ns()) + " ns)");
}

void FaultTimeline::resolve(Entry& e) const noexcept {
  if (e.resolved || e.start_at_next) return;
  if (e.spec.clock == Clock::since_start) {
    if (!have_t0_) return;
    e.start_t = saturating_add_ns(t0_, e.spec.start_ns);
  } else {
    e.start_t = e.spec.start_ns;
  }
  e.end_t = e.spec.duration_ns > 0 ? saturating_add_ns(e.start_t, e.spec.duration_ns) : kMaxTimeNs;
  e.resolved = true;
}

void FaultTimeline::draw_random_window(std::uint64_t window) {
  const RandomFaults& r = options_.random;
  const double mean = r.per_hour * (static_cast<double>(kRandomWindowNs) * 1e-9 / 3600.0);
  sensor::Stream s{mix64(mix64(mix64(r.seed ^ 0x7A9D0FA17ULL) ^ device_hash_) ^ window)};
  // Poisson count by inversion (mean <= 30 per window).
  std::uint32_t count = 0;
  const double limit = std::exp(-mean);
  for (double p = s.uniform(); p > limit && count < kMaxRandomPerWindow; p *= s.uniform()) ++count;
  for (std::uint32_t i = 0; i < count; ++i) {
    const double u_time = s.uniform(), u_kind = s.uniform();
    const std::uint64_t fault_seed = s.next();
    if (entries_.size() >= options_.max_faults) {
      ++counters_.random_refused;
      continue;
    }
    const std::size_t kind_index =
        std::min(r.kinds.size() - 1, static_cast<std::size_t>(u_kind * static_cast<double>(r.kinds.size())));
    Entry e;
    e.id = next_id_++;
    e.stream = kStreamRandom | (window << 8) | i;
    e.spec = random_spec(r, r.kinds[kind_index]);
    e.spec.device = options_.context.device;
    e.spec.seed = fault_seed;
    e.spec.start_ns = saturating_add_ns(saturating_mul_ns(kRandomWindowNs, static_cast<std::int64_t>(window)),
                                        static_cast<TimeNs>(u_time * static_cast<double>(kRandomWindowNs)));
    resolve(e);
    entries_.push_back(std::move(e));
    ++counters_.random_drawn;
  }
}

void FaultTimeline::push_event(FaultEvent::Phase phase, const Entry& e, std::uint64_t k, TimeNs t) noexcept {
  (phase == FaultEvent::Phase::start ? counters_.started : counters_.ended) += 1;
  if (event_count_ == events_.size()) {
    ++counters_.events_overflowed;
    return;
  }
  FaultEvent& slot = events_[(event_head_ + event_count_) % events_.size()];
  try {
    slot.spec = e.spec;  // reuses the slot's strings once they are long enough
  } catch (...) {        // no memory for a device name: the event is lost, and counted
    ++counters_.events_overflowed;
    return;
  }
  slot.phase = phase;
  slot.fault_id = e.id;
  slot.sample_counter = k;
  slot.t_ns = t;
  ++event_count_;
}

SampleFaults FaultTimeline::step(std::uint64_t k, TimeNs t, SampleValues& values) noexcept {
  SampleFaults out;
  if (finished_) return out;
  if (!have_t0_) {
    have_t0_ = true;
    t0_ = t;
  }
  // Random windows up to this sample's.
  if (options_.random.per_hour > 0.0 && t >= t0_) {
    const std::uint64_t window = ns_between(t0_, t) / static_cast<std::uint64_t>(kRandomWindowNs);
    while (next_window_ <= window) {
      try {
        draw_random_window(next_window_);
      } catch (...) {  // no memory for a spec's strings: that window's rest is refused, counted
        ++counters_.random_refused;
      }
      ++next_window_;
    }
  }
  const double h_s = values.period_ns > 0 ? static_cast<double>(values.period_ns) * 1e-9
                                          : 1.0 / static_cast<double>(options_.context.rate_hz);
  // The unfaulted input into the delay history.
  Vec3 v[4] = {values.gyro_rad_s, values.accel_m_s2, values.delta_theta_rad, values.delta_velocity_m_s};
  {
    History& slot = history_[history_next_];
    slot.k = k;
    for (int i = 0; i < 4; ++i) slot.v[i] = v[i];
    history_next_ = (history_next_ + 1) % history_.size();
    history_count_ = std::min(history_count_ + 1, history_.size());
  }
  if (pending_restart_) {
    out.link.restart = true;
    pending_restart_ = false;
  }
  std::size_t keep = 0;
  for (std::size_t i = 0; i < entries_.size(); ++i) {
    Entry& e = entries_[i];
    if (e.start_at_next) {
      e.start_at_next = false;
      e.start_t = t;
      e.end_t = e.spec.duration_ns > 0 ? saturating_add_ns(t, e.spec.duration_ns) : kMaxTimeNs;
      e.resolved = true;
    }
    resolve(e);
    bool done = false;
    if (e.resolved && e.start_t <= t && t < e.end_t) {
      if (!e.started) {
        e.started = true;
        e.first_k = k;
        e.first_t = t;
        push_event(FaultEvent::Phase::start, e, k, t);
      }
      e.last_k = k;
      e.last_t = t;
      ++out.active;
      if (e.spec.flag_status) out.flags |= kFlagFault;
      if (is_sensor_fault(e.spec.kind))
        apply_sensor(e, k, t, h_s, v, out.flags);
      else
        decide_link(e, k, t, h_s, out.link);
    } else if (e.resolved && t >= e.end_t) {
      done = true;
      if (e.started) {
        push_event(FaultEvent::Phase::end, e, e.last_k, e.last_t);
        if (e.spec.kind == Kind::restart) out.link.restart = true;  // this sample is the first after the off time
      }
    }
    if (!done) {
      if (keep != i) entries_[keep] = std::move(e);
      ++keep;
    }
  }
  entries_.erase(entries_.begin() + static_cast<std::ptrdiff_t>(keep), entries_.end());
  // Never NaN/Inf out: only a non-finite input gets here (the parameters are
  // bounded, the sums saturate above). Sent as 0, flagged saturated and
  // fault, as the encoders flag a NaN they replace (docs/native-protocol.md
  // section 5), so zeroing it here hides nothing from the receiver.
  for (Vec3& x : v)
    for (int a = 0; a < 3; ++a)
      if (!std::isfinite(x[a])) {
        x[a] = 0.0;
        out.flags |= kFlagSaturated | kFlagFault;
      }
  values.gyro_rad_s = v[0];
  values.accel_m_s2 = v[1];
  values.delta_theta_rad = v[2];
  values.delta_velocity_m_s = v[3];
  for (int i = 0; i < 4; ++i) last_out_[i] = v[i];
  have_last_ = true;
  last_k_ = k;
  last_t_ = t;
  return out;
}

const FaultTimeline::History* FaultTimeline::delayed(std::uint64_t k_wanted) const noexcept {
  // The newest recorded sample at or before k_wanted (samples are recorded
  // in increasing k); the oldest one when the history does not reach back.
  if (history_count_ == 0) return nullptr;
  auto back = [&](std::size_t j) -> const History& {  // j = 1: the newest
    return history_[(history_next_ + history_.size() - j) % history_.size()];
  };
  // Without skipped samples the wanted one is exactly newest_k - k_wanted back.
  const std::uint64_t newest_k = back(1).k;
  if (k_wanted <= newest_k && newest_k - k_wanted < history_count_) {
    const History& guess = back(static_cast<std::size_t>(newest_k - k_wanted) + 1);
    if (guess.k == k_wanted) return &guess;
  }
  const History* best = nullptr;
  const History* oldest = nullptr;
  for (std::size_t j = 1; j <= history_count_; ++j) {  // newest first (after skipped samples)
    const History& hst = history_[(history_next_ + history_.size() - j) % history_.size()];
    oldest = &hst;
    if (hst.k <= k_wanted) {
      best = &hst;
      break;
    }
  }
  return best != nullptr ? best : oldest;
}

void FaultTimeline::apply_sensor(Entry& e, std::uint64_t k, TimeNs t, double h, Vec3 (&v)[4],
                                 std::uint32_t& flags) noexcept {
  const FaultSpec& s = e.spec;
  const DeviceContext& c = options_.context;
  const bool first = k == e.first_k;
  // Where the fault's state comes from at its first sample.
  if (first) {
    if (s.kind == Kind::stuck)
      for (int i = 0; i < 4; ++i) e.held[i] = have_last_ ? last_out_[i] : v[i];
  }
  if (s.kind == Kind::slow && (k - e.first_k) % s.divisor == 0)
    for (int i = 0; i < 4; ++i) e.held[i] = v[i];
  const History* past = nullptr;
  if (s.kind == Kind::delayed) {
    const double samples = std::round(static_cast<double>(s.delay_ns) * 1e-9 * static_cast<double>(c.rate_hz));
    const std::uint64_t d = static_cast<std::uint64_t>(std::max(1.0, samples));
    past = delayed(k >= d ? k - d : 0);
  }
  // intermittent: "on" (the fault acting) for on_ns of every on_ns + off_ns from its start.
  bool intermittent_on = false;
  if (s.kind == Kind::intermittent) {
    const std::uint64_t cycle = static_cast<std::uint64_t>(s.on_ns) + static_cast<std::uint64_t>(s.off_ns);
    intermittent_on = ns_between(e.start_t, t) % cycle < static_cast<std::uint64_t>(s.on_ns);
  }
  bool spike = false;
  if (s.kind == Kind::spikes) spike = uniform01(s.seed, e.stream, k, kDrawEvent) < -std::expm1(-s.rate_hz * h);
  // bias_ramp / plausible_drift: b(t) = sign(r) min(cap, |r| (t - start)),
  // the increment its exact integral over the period (t - h, t].
  const double tau = seconds_between(e.start_t, t);
  const double tau_prev = std::max(0.0, tau - h);
  for (int tri = 0; tri < 2; ++tri) {
    const Triad triad = tri == 0 ? Triad::gyro : Triad::accel;
    if (!has(s, triad)) continue;
    Vec3& rate = v[tri];
    Vec3& inc = v[tri + 2];
    const double range = tri == 0 ? c.gyro_range_rad_s : c.accel_range_m_s2;
    const double bias = tri == 0 ? s.gyro_bias_rad_s : s.accel_bias_m_s2;
    const double ramp = tri == 0 ? s.gyro_ramp_rad_s2 : s.accel_ramp_m_s3;
    const Vec3& density = tri == 0 ? c.gyro_noise_density : c.accel_noise_density;
    // The kinds that add to or scale the value can take it beyond the range.
    const bool adds = s.kind == Kind::bias_step || s.kind == Kind::bias_ramp || s.kind == Kind::plausible_drift ||
                      s.kind == Kind::scale_step || s.kind == Kind::noise_gain || s.kind == Kind::spikes;
    for (int a = 0; a < 3; ++a) {
      if ((s.axes & (1u << a)) == 0) continue;
      const std::uint64_t axis_draw = static_cast<std::uint64_t>(3 * tri + a);
      switch (s.kind) {
        case Kind::stuck:
        case Kind::slow:
          rate[a] = e.held[tri][a];
          inc[a] = e.held[tri][a] * h;
          break;
        case Kind::dead:
          rate[a] = 0.0;
          inc[a] = 0.0;
          break;
        case Kind::intermittent:
          if (intermittent_on) {
            rate[a] = 0.0;
            inc[a] = 0.0;
          }
          break;
        case Kind::garbage:
          rate[a] = (2.0 * uniform01(s.seed, e.stream, k, kDrawGarbage + axis_draw) - 1.0) * range;
          inc[a] = rate[a] * h;
          break;
        case Kind::saturation:
          rate[a] = rate[a] < 0.0 ? -range : range;
          inc[a] = rate[a] * h;
          flags |= kFlagSaturated;
          break;
        case Kind::bias_step:
          rate[a] += bias;
          inc[a] += bias * h;
          break;
        case Kind::bias_ramp:
        case Kind::plausible_drift: {
          const double cap = s.kind == Kind::plausible_drift ? bias : std::numeric_limits<double>::infinity();
          const double r = std::abs(ramp), sign = ramp < 0.0 ? -1.0 : 1.0;
          rate[a] += sign * std::min(cap, r * tau);
          inc[a] += sign * (capped_ramp_integral(r, cap, tau) - capped_ramp_integral(r, cap, tau_prev));
          break;
        }
        case Kind::scale_step: {
          const double f = 1.0 + s.scale_ppm * 1e-6;
          rate[a] *= f;
          inc[a] *= f;
          break;
        }
        case Kind::noise_gain: {
          const double sigma = density[a] * std::sqrt(static_cast<double>(c.rate_hz)) *
                               std::sqrt(s.noise_factor * s.noise_factor - 1.0);
          if (sigma > 0.0) {
            sensor::Stream g = draw(s.seed, e.stream, k, kDrawNoise + axis_draw);
            const double n = sigma * g.gaussian();
            rate[a] += n;
            inc[a] += n * h;
          }
          break;
        }
        case Kind::spikes:
          if (spike) {
            rate[a] += bias;
            inc[a] += bias * h;
          }
          break;
        case Kind::delayed:
          if (past != nullptr) {
            rate[a] = past->v[tri][a];
            inc[a] = past->v[tri + 2][a];
          }
          break;
        default:
          break;
      }
      // What this fault moved beyond the part's range saturates there,
      // flagged, as the sensor model saturates the motion (issue 26, N11: a
      // 1e5 deg/s bias_step on a +-2000 deg/s part sent 1745 rad/s
      // unflagged, 256 overlapping steps 7.7e6 rad/s): the rate at +-range,
      // the increment at +-range h, the most a saturated sensor integrates
      // over the period. Here, after each fault, so the next one (a stuck or
      // slow fault holding this sample) never sees a value beyond the range.
      if (adds) {
        if (std::abs(rate[a]) > range) {
          rate[a] = std::copysign(range, rate[a]);
          flags |= kFlagSaturated;
        }
        if (std::abs(inc[a]) > range * h) {
          inc[a] = std::copysign(range * h, inc[a]);
          flags |= kFlagSaturated;
        }
      }
    }
  }
}

void FaultTimeline::decide_link(const Entry& e, std::uint64_t k, TimeNs t, double h, LinkDecision& d) const noexcept {
  const FaultSpec& s = e.spec;
  const bool first = k == e.first_k;
  auto happens = [&] { return uniform01(s.seed, e.stream, k, kDrawEvent) < s.probability; };
  switch (s.kind) {
    case Kind::drop:
      if (s.burst_samples > 0) {
        // Bursts start as a Poisson process (rate_hz) on the samples; a
        // sample is dropped when a burst started on it or on one of the
        // burst_samples - 1 before it (within the fault): no state.
        const double p = -std::expm1(-s.rate_hz * h);
        const std::uint64_t from = k - std::min<std::uint64_t>(k - e.first_k, s.burst_samples - 1);
        for (std::uint64_t j = from; j <= k && !d.drop; ++j)
          if (uniform01(s.seed, e.stream, j, kDrawBurst) < p) d.drop = true;
      } else if (happens()) {
        d.drop = true;
      }
      break;
    case Kind::duplicate:
      if (happens()) d.copies = std::max<std::uint8_t>(d.copies, 2);
      break;
    case Kind::babble:
      d.copies = std::max<std::uint8_t>(d.copies, static_cast<std::uint8_t>(s.babble_factor));
      break;
    case Kind::bad_checksum:
      if (happens()) d.corrupt_checksum = true;
      break;
    case Kind::bit_errors:
      d.bit_error_rate = 1.0 - (1.0 - d.bit_error_rate) * (1.0 - s.bit_error_rate);
      d.bit_error_seed = draw_key(s.seed, e.stream, k, kDrawBits) ^ d.bit_error_seed;
      break;
    case Kind::truncate:
      if (happens()) d.truncate_bytes = std::max(d.truncate_bytes, s.truncate_bytes);
      break;
    case Kind::bad_length:
      if (happens()) d.bad_length = true;
      break;
    case Kind::sequence_jump:
      if (first) d.sequence_step += s.sequence_step;
      break;
    case Kind::sequence_reset:
      if (first) d.sequence_reset = true;
      break;
    case Kind::time_jump:
      d.protocol_time_ns = saturating_add_ns(d.protocol_time_ns.value_or(t), s.time_step_ns);
      break;
    case Kind::time_freeze:
      d.protocol_time_ns = e.first_t;
      break;
    case Kind::silence:
    case Kind::restart:
      d.silence = true;
      break;
    case Kind::can_wrong_id:
      if (happens()) {
        d.can_wrong_id = true;
        d.can_id = s.can_id;
      }
      break;
    case Kind::can_missing_frame:
      if (happens()) d.can_missing_frame = true;
      break;
    default:
      break;
  }
}

std::uint64_t FaultTimeline::inject(FaultSpec spec) {
  // A run-time injection is never the scene's: an empty or default
  // ("scene") source becomes "control"; another one (a test harness's
  // label) is kept.
  if (spec.source.empty() || spec.source == "scene") spec.source = "control";
  spec.device = options_.context.device;
  validate(spec);
  check_fits(spec);
  if (finished_) throw std::invalid_argument("fault: the run has ended");
  if (entries_.size() >= options_.max_faults)
    throw std::invalid_argument("fault: device '" + options_.context.device + "' already has " +
                                std::to_string(entries_.size()) + " faults scheduled or acting (at most " +
                                std::to_string(options_.max_faults) + "); clear some first");
  Entry e;
  e.id = next_id_;
  e.stream = kStreamInjected | e.id;
  e.spec = std::move(spec);
  resolve(e);
  // A start at or before the last sample produced: the next sample.
  if (have_last_ && (!e.resolved || e.start_t <= last_t_)) {
    e.resolved = false;
    e.start_at_next = true;
  }
  entries_.push_back(std::move(e));  // within the reserved capacity: no reallocation, no throw
  return next_id_++;
}

bool FaultTimeline::clear(std::uint64_t id) {
  const auto it = std::find_if(entries_.begin(), entries_.end(), [&](const Entry& e) { return e.id == id; });
  if (it == entries_.end()) return false;
  if (it->started) {
    push_event(FaultEvent::Phase::end, *it, it->last_k, it->last_t);
    if (it->spec.kind == Kind::restart) pending_restart_ = true;
  }
  entries_.erase(it);
  return true;
}

std::size_t FaultTimeline::clear_all() {
  const std::size_t n = entries_.size();
  for (const Entry& e : entries_) {
    if (!e.started) continue;
    push_event(FaultEvent::Phase::end, e, e.last_k, e.last_t);
    if (e.spec.kind == Kind::restart) pending_restart_ = true;
  }
  entries_.clear();
  return n;
}

std::vector<FaultInfo> FaultTimeline::list() const {
  std::vector<FaultInfo> out;
  out.reserve(entries_.size());
  for (const Entry& e : entries_) out.push_back({e.id, e.spec, e.started, e.first_k, e.first_t});
  return out;
}

void FaultTimeline::finish() {
  if (finished_) return;
  for (const Entry& e : entries_)
    if (e.started) push_event(FaultEvent::Phase::end, e, e.last_k, e.last_t);
  entries_.clear();
  finished_ = true;
}

bool FaultTimeline::pop_event(FaultEvent& out) {
  if (event_count_ == 0) return false;
  out = events_[event_head_];
  event_head_ = (event_head_ + 1) % events_.size();
  --event_count_;
  return true;
}

void FaultTimeline::drain_events(std::vector<FaultEvent>& out) {
  FaultEvent e;
  while (pop_event(e)) out.push_back(e);
}

}  // namespace imuemu::fault
