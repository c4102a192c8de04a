#include "core/signal_chain/signal_chain.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "core/setting_error.hpp"

namespace imuemu::signal_chain {

namespace {

// Presets that run above the output rate do so at about 8 kHz: enough for the
// filters' stop bands and for a vibration of a few kHz to be represented
// before the anti-alias filter (issue 16; 8x oversampling at 1 kHz).
constexpr std::int64_t kPresetInternalRateHz = 8000;

int oversampling_for(std::int64_t rate_hz) {
  return static_cast<int>(std::max<std::int64_t>(2, (kPresetInternalRateHz + rate_hz - 1) / rate_hz));
}

std::string hz(double f) {
  char b[48];
  std::snprintf(b, sizeof b, "%.6g Hz", f);
  return b;
}

struct Preset {
  int oversampling = 1;
  std::vector<Stage> stages;
};

Preset preset_for(const std::string& name, std::int64_t r) {
  Preset p;
  const double rate = static_cast<double>(r);
  if (name == "ideal") return p;
  if (name == "icm42688p") {
    // TDK ICM-42688-P (DS-000347 v1.7): a second-order anti-alias filter
    // (§5.2, -3 dB programmable 42..3979 Hz through AAF_DELT/DELTSQR/BITSHIFT;
    // the 258 Hz row, DELT = 6, is taken here) and the UI low-pass filter of
    // order 1-3 (GYRO_UI_FILT_ORD) whose bandwidth index 1 (the reset value)
    // is max(400 Hz, ODR)/4 (GYRO_ACCEL_CONFIG0). The datasheet gives order and
    // -3 dB bandwidth, not the pole positions: Butterworth poles are assumed.
    // Order 2 and index 1 are the reset values (GYRO_CONFIG1 = 0x16: bits 3:2
    // GYRO_UI_FILT_ORD = 01, 2nd order; GYRO_ACCEL_CONFIG0 = 0x11: bits 3:0
    // GYRO_UI_FILT_BW = 1), as independent register maps of the part state;
    // the AAF row is a configured choice, not the reset value.
    p.oversampling = oversampling_for(r);
    p.stages.push_back({.kind = StageKind::anti_alias, .frequency_hz = 258.0});
    p.stages.push_back({.kind = StageKind::low_pass, .frequency_hz = std::max(400.0, rate) / 4.0, .order = 2});
    return p;
  }
  if (name == "adis16470") {
    // Analog Devices ADIS16470 (data sheet Rev. C, FILT_CTRL and DEC_RATE
    // registers): sampled at 2000 SPS, a Bartlett window FIR filter of two
    // averaging stages of 2^N taps each (FILT_CTRL = N; N = 2 taken here), then
    // the decimation filter, which averages DEC_RATE + 1 samples and outputs
    // every (DEC_RATE + 1)-th: 2000 / rate. FILT_CTRL resets to 0 (no
    // Bartlett stage); N = 2 is a configured choice, -3 dB at 164 Hz, which
    // matches the Linux IIO driver's table for the family (adis16475.c:
    // 360/164/80/40 Hz for N = 1..4; AdisBartlettBandwidthsMatchTheIndependentTable).
    if (r > 2000 || 2000 % r != 0)
      throw std::invalid_argument("signal chain preset adis16470 samples at 2000 Hz and decimates by an integer "
                                  "(DEC_RATE + 1): the output rate " +
                                  std::to_string(r) + " Hz does not divide 2000");
    p.oversampling = static_cast<int>(2000 / r);
    p.stages.push_back({.kind = StageKind::bartlett, .length = 4});
    if (p.oversampling > 1) p.stages.push_back({.kind = StageKind::average, .length = p.oversampling});
    return p;
  }
  if (name == "stim300") {
    // Tactical-grade IMUs with a configurable output low-pass (Safran
    // Sensonor STIM300 datasheet TS1524: "low pass filter -3dB frequency"
    // configurable; KVH 1775 likewise): a Butterworth at half the output
    // rate. The order is not stated in what was read; 4 is taken.
    p.oversampling = oversampling_for(r);
    p.stages.push_back({.kind = StageKind::butterworth, .frequency_hz = rate / 2.0, .order = 4});
    return p;
  }
  if (name == "mip") {
    // MicroStrain MIP devices (3DM-GX5, CV7; MIP DCP command 0x0C,0x50): "a
    // single-pole IIR low-pass filter ... with a -3dB cutoff frequency of half
    // the reporting frequency" by default.
    p.oversampling = oversampling_for(r);
    p.stages.push_back({.kind = StageKind::low_pass, .frequency_hz = rate / 2.0, .order = 1});
    return p;
  }
  throw std::invalid_argument("unknown signal chain preset '" + name +
                              "' (expected ideal, icm42688p, adis16470, stim300 or mip)");
}

}  // namespace

std::vector<std::string> chain_presets() { return {"ideal", "icm42688p", "adis16470", "stim300", "mip"}; }

ResolvedChain resolve(const ChainSpec& spec, std::int64_t output_rate_hz) {
  if (output_rate_hz < 1) throw std::invalid_argument("signal chain: output rate must be >= 1 Hz");
  Preset p = preset_for(spec.preset, output_rate_hz);
  ResolvedChain c;
  c.preset = spec.preset;
  c.oversampling = spec.oversampling.value_or(p.oversampling);
  if (c.oversampling < 1 || c.oversampling > kMaxOversampling)
    throw SettingError("oversampling", "signal chain: oversampling " + std::to_string(c.oversampling) + " is not in 1.." +
                                           std::to_string(kMaxOversampling));
  if (output_rate_hz > 1'000'000 / c.oversampling)
    throw std::invalid_argument("signal chain: internal rate " + std::to_string(output_rate_hz) + " Hz x " +
                                std::to_string(c.oversampling) + " is above 1 MHz");
  c.internal_rate_hz = output_rate_hz * c.oversampling;
  c.stages = spec.stages.value_or(p.stages);
  c.design = design(c.stages, static_cast<double>(c.internal_rate_hz));
  c.compensate_delay = spec.compensate_delay;
  c.has_vibration = !spec.vibration.empty();
  c.group_delay_s = group_delay_samples(c.design, 0.0) / static_cast<double>(c.internal_rate_hz);
  // The stamp shift t_k - delay must be an int64 ns that means something.
  if (c.compensate_delay && !(std::abs(c.group_delay_s) <= kMaxCompensatedDelayS))
    throw SettingError("compensate_delay", "signal chain: compensate_delay: the chain's group delay at DC, " +
                                               setting_number(c.group_delay_s) + " s, is beyond " +
                                               setting_number(kMaxCompensatedDelayS) +
                                               " s (the ADIS16470's slowest decimation delays 0.5 s); raise the "
                                               "stages' frequencies or compensate nothing");
  return c;
}

std::vector<std::string> describe(const ResolvedChain& c, std::int64_t output_rate_hz) {
  std::vector<std::string> out;
  if (c.is_ideal()) {
    out.push_back("signal chain: ideal (sampled at the output rate, no filter)");
    return out;
  }
  out.push_back("signal chain " + c.preset + ": internal rate " + std::to_string(c.internal_rate_hz) + " Hz (" +
                std::to_string(c.oversampling) + " x " + std::to_string(output_rate_hz) +
                " Hz), decimated to the output rate");
  for (std::size_t i = 0; i < c.stages.size(); ++i) {
    const Stage& s = c.stages[i];
    std::string line = "  stage " + std::to_string(i + 1) + ": " + to_string(s.kind);
    switch (s.kind) {
      case StageKind::low_pass:
      case StageKind::butterworth: line += " order " + std::to_string(s.order) + ", -3 dB at " + hz(s.frequency_hz); break;
      case StageKind::anti_alias:
        line += " (2nd order), -3 dB at " + hz(s.frequency_hz) + ", Q " + std::to_string(s.q > 0 ? s.q : 0.7071067811865476);
        break;
      case StageKind::notch: line += " at " + hz(s.frequency_hz) + ", Q " + std::to_string(s.q); break;
      case StageKind::average:
      case StageKind::bartlett: line += " of " + std::to_string(s.length) + " samples"; break;
    }
    out.push_back(line);
  }
  char b[200];
  const double quarter = static_cast<double>(output_rate_hz) / 4.0;
  std::snprintf(b, sizeof b, "  group delay: %.6g ms at DC, %.6g ms at %s (analytic)", c.group_delay_s * 1e3,
                group_delay_samples(c.design, quarter) / static_cast<double>(c.internal_rate_hz) * 1e3, hz(quarter).c_str());
  out.push_back(b);
  std::snprintf(b, sizeof b, "  gain at %s: %.4g dB", hz(quarter).c_str(), 20.0 * std::log10(std::abs(response(c.design, quarter))));
  out.push_back(b);
  if (c.has_vibration) out.push_back("  vibration as rigid-body motion on the smoothed trajectory (docs/signal-chain.md)");
  out.push_back(c.compensate_delay ? "  time stamps compensated: each sample stamped t_k - group delay"
                                   : "  time stamps not compensated (the output lags the motion by the group delay)");
  return out;
}

ChainWork predict_work(const ResolvedChain& chain, bool sensor, std::size_t random_components,
                       std::optional<IncrementConvention> increments, Physics physics) {
  ChainWork w;
  w.ticks = 1.0;
  const double M = chain.oversampling;
  if (sensor || !chain.is_ideal()) w.internal_samples = M;
  const bool raw = increments == IncrementConvention::raw;
  if (raw)
    w.increment_nodes = 4.0;
  else if (increments && physics == Physics::ecef)
    w.increment_nodes = 3.0;
  if (chain.has_vibration && random_components > 0) {
    const double n = static_cast<double>(random_components);
    const double resync = M / static_cast<double>(Vibration::kResyncSteps + 1);
    w.vibration_rotations = (M - resync) * n;
    w.vibration_direct = (resync + (raw ? 4.0 : 0.0)) * n;
  }
  return w;
}

ChainWork DeviceChain::work() const {
  ChainWork w;
  w.ticks = static_cast<double>(ticks_);
  w.internal_samples = static_cast<double>(internal_samples_);
  w.increment_nodes = static_cast<double>(increment_nodes_);
  if (vibration_) {
    w.vibration_rotations = static_cast<double>(vibration_->work().rotations);
    w.vibration_direct = static_cast<double>(vibration_->work().direct);
  }
  return w;
}

DeviceChain::DeviceChain(const SceneModel& scene, const std::optional<sensor::SensorModelSpec>& sensor,
                         const ChainSpec& chain, std::int64_t output_rate_hz, const std::string& device)
    : scene_(scene),
      chain_(resolve(chain, output_rate_hz)),
      period_s_(1.0 / static_cast<double>(output_rate_hz)),
      filter_(chain_.design) {
  if (sensor && !sensor->is_ideal()) {
    sensor_.emplace(*sensor, static_cast<double>(chain_.internal_rate_hz), device);
    gyro_range_ = sensor->gyro.range;
    accel_range_ = sensor->accel.range;
  }
  if (!chain.vibration.empty()) {
    vibration_.emplace(chain.vibration, device);
    vibration_->set_grid_step(period_s_ / chain_.oversampling);
  }
  if (chain_.compensate_delay) stamp_shift_ns_ = static_cast<TimeNs>(std::llround(chain_.group_delay_s * 1e9));
}

ChainOutput DeviceChain::step(std::uint64_t k, const Kinematics& now, const ImuSample& ideal_now,
                              const Kinematics* previous, std::optional<IncrementConvention> increments,
                              const IntervalMotion* motion) {
  ChainOutput out;
  ++ticks_;
  out.gyro_rad_s = ideal_now.gyro_rad_s;
  out.accel_m_s2 = ideal_now.accel_m_s2;
  out.stamp_shift_ns = stamp_shift_ns_;
  const bool contiguous = have_last_ && k == last_k_ + 1;
  have_last_ = true;
  last_k_ = k;
  if (!previous) motion = nullptr;
  const int M = chain_.oversampling;
  // The motion over the interval, when something reads inside it.
  std::optional<HermiteInterval> hermite;
  const bool needs_motion = M > 1 || vibration_ ||
                            (increments && (*increments == IncrementConvention::raw || scene_.physics == Physics::ecef));
  if (previous && !motion && needs_motion) {
    hermite.emplace(*previous, now, period_s_);
    motion = &*hermite;
  }
  // Vibration: the interval's motion, its ends and the ideal sample at t_k
  // become the vibrating sensor's (the ends from the given kinematics, so
  // consecutive intervals share their attitude and velocity exactly). The
  // end at t_k is evaluated after the interval's internal samples, so the
  // vibration is asked for its instants in grid order (Vibration::set_grid_step).
  std::optional<VibratingInterval> vibrating;
  Kinematics previous_v, now_v;
  ImuSample ideal_v;
  const double t_k_s = static_cast<double>(k) * period_s_;
  const IntervalMotion* base_motion = motion;
  if (vibration_ && previous) {
    vibrating.emplace(*motion, *vibration_, t_k_s - period_s_, period_s_);
    previous_v = vibration_->apply(*previous, motion->angular_acceleration_at(0.0), t_k_s - period_s_);
    previous = &previous_v;
    motion = &*vibrating;
  }
  auto vibrate_now = [&] {
    now_v = vibration_->apply(now, base_motion ? base_motion->angular_acceleration_at(1.0) : Vec3::Zero(), t_k_s);
    ideal_v = imu_from_kinematics(scene_, now_v);
    ideal_v.t_ns = ideal_now.t_ns;
  };
  // Without a previous tick the interval is held at the (vibrated) sample of t_k.
  if (vibration_ && !previous) vibrate_now();
  const Kinematics& now_k = vibration_ ? now_v : now;
  const ImuSample& ideal_k = vibration_ ? ideal_v : ideal_now;
  Vec3 error_theta = Vec3::Zero(), error_v = Vec3::Zero();
  if (!ideal()) {
    // Internal samples j = M (k - 1) + 1 .. M k over the interval (only j = 0
    // for k = 0): the last one is at t_k itself and takes ideal_now, so M = 1
    // is exactly the output-rate model.
    const std::uint64_t first_i = k == 0 ? static_cast<std::uint64_t>(M) : 1;
    const double dt_s = period_s_ / M;
    internal_samples_ += static_cast<std::uint64_t>(M) - first_i + 1;
    Filter::Channels y{};
    for (std::uint64_t i = first_i; i <= static_cast<std::uint64_t>(M); ++i) {
      if (vibration_ && previous && i == static_cast<std::uint64_t>(M)) vibrate_now();
      ImuSample u = ideal_k;
      if (i < static_cast<std::uint64_t>(M) && motion)
        u = imu_from_kinematics(scene_, motion->at(static_cast<double>(i) / M));
      Vec3 g = u.gyro_rad_s, f = u.accel_m_s2;
      if (sensor_) {
        const std::uint64_t j = k * static_cast<std::uint64_t>(M) - static_cast<std::uint64_t>(M) + i;
        const sensor::Measurement m = sensor_->measure(j, u.gyro_rad_s, u.accel_m_s2);
        g = m.gyro_rad_s;
        f = m.accel_m_s2;
        out.saturated_axes |= m.saturated_axes;
        out.has_temperature = true;
        out.temperature_c = m.temperature_c;
        error_theta += (g - u.gyro_rad_s) * dt_s;
        error_v += (f - u.accel_m_s2) * dt_s;
      }
      y = {g.x(), g.y(), g.z(), f.x(), f.y(), f.z()};
      if (!filter_.empty()) {
        // A start or a gap: the filter starts settled on this input rather
        // than ringing from zero.
        if (!contiguous && i == first_i) filter_.settle(y);
        y = filter_.step(y);
      }
    }
    // The output register holds the part's full scale: a filter's overshoot
    // on a saturated input (a Butterworth's step response rises ~4 % above
    // its final value at order 2) saturates there again, flagged.
    if (!filter_.empty() && (gyro_range_ > 0.0 || accel_range_ > 0.0))
      for (unsigned c = 0; c < 6; ++c) {
        const double range = c < 3 ? gyro_range_ : accel_range_;
        if (range > 0.0 && std::abs(y[c]) > range) {
          y[c] = std::copysign(range, y[c]);
          out.saturated_axes = static_cast<std::uint8_t>(out.saturated_axes | (1u << c));
        }
      }
    out.gyro_rad_s = Vec3(y[0], y[1], y[2]);
    out.accel_m_s2 = Vec3(y[3], y[4], y[5]);
  }
  if (increments) {
    Increment inc;
    if (previous) {
      // motion is set whenever this convention and scene read it (needs_motion).
      inc = increment(*increments, scene_, *previous, now_k, period_s_, motion);
      increment_nodes_ += *increments == IncrementConvention::raw ? 4 : scene_.physics == Physics::ecef ? 3 : 0;
    } else {
      // Nothing to integrate over: the rectangle of the sample at t_k.
      inc.delta_theta_rad = ideal_k.gyro_rad_s * period_s_;
      inc.delta_velocity_m_s = ideal_k.accel_m_s2 * period_s_;
    }
    out.delta_theta_rad = inc.delta_theta_rad + error_theta;
    out.delta_velocity_m_s = inc.delta_velocity_m_s + error_v;
  }
  return out;
}

}  // namespace imuemu::signal_chain
