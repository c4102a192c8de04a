// Fault kinds, defaults, validation and descriptions (core/fault/fault.hpp).
#include "core/fault/fault.hpp"

#include <array>
#include <cmath>
#include <cstdio>
#include <stdexcept>

namespace imuemu::fault {
namespace {

struct KindInfo {
  Kind kind;
  std::string_view name;
};
constexpr std::array<KindInfo, 28> kKinds{{
    {Kind::stuck, "stuck"},
    {Kind::dead, "dead"},
    {Kind::garbage, "garbage"},
    {Kind::bias_step, "bias_step"},
    {Kind::bias_ramp, "bias_ramp"},
    {Kind::scale_step, "scale_step"},
    {Kind::noise_gain, "noise_gain"},
    {Kind::spikes, "spikes"},
    {Kind::saturation, "saturation"},
    {Kind::slow, "slow"},
    {Kind::intermittent, "intermittent"},
    {Kind::delayed, "delayed"},
    {Kind::plausible_drift, "plausible_drift"},
    {Kind::drop, "drop"},
    {Kind::duplicate, "duplicate"},
    {Kind::bad_checksum, "bad_checksum"},
    {Kind::bit_errors, "bit_errors"},
    {Kind::truncate, "truncate"},
    {Kind::bad_length, "bad_length"},
    {Kind::sequence_jump, "sequence_jump"},
    {Kind::sequence_reset, "sequence_reset"},
    {Kind::time_jump, "time_jump"},
    {Kind::time_freeze, "time_freeze"},
    {Kind::babble, "babble"},
    {Kind::silence, "silence"},
    {Kind::restart, "restart"},
    {Kind::can_wrong_id, "can_wrong_id"},
    {Kind::can_missing_frame, "can_missing_frame"},
}};

[[noreturn]] void refuse(const FaultSpec& spec, const std::string& field, const std::string& what) {
  throw std::invalid_argument("fault " + std::string(kind_name(spec.kind)) + ": " + field + ": " + what);
}

bool has_gyro(const FaultSpec& s) { return (static_cast<unsigned>(s.triad) & 1u) != 0; }
bool has_accel(const FaultSpec& s) { return (static_cast<unsigned>(s.triad) & 2u) != 0; }

// The per-packet probability of the link faults that take one.
bool takes_probability(Kind k) {
  switch (k) {
    case Kind::drop:
    case Kind::duplicate:
    case Kind::bad_checksum:
    case Kind::truncate:
    case Kind::bad_length:
    case Kind::can_wrong_id:
    case Kind::can_missing_frame:
      return true;
    default:
      return false;
  }
}

std::string number(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return buf;
}

std::string seconds(TimeNs ns) { return number(static_cast<double>(ns) * 1e-9) + " s"; }

}  // namespace

bool is_sensor_fault(Kind kind) { return static_cast<unsigned>(kind) <= static_cast<unsigned>(Kind::plausible_drift); }
bool is_link_fault(Kind kind) { return !is_sensor_fault(kind); }
bool is_can_only(Kind kind) { return kind == Kind::can_wrong_id || kind == Kind::can_missing_frame; }

std::string_view kind_name(Kind kind) {
  for (const KindInfo& k : kKinds)
    if (k.kind == kind) return k.name;
  return "unknown";
}

std::optional<Kind> kind_from_name(std::string_view name) {
  for (const KindInfo& k : kKinds)
    if (k.name == name) return k.kind;
  return std::nullopt;
}

std::vector<std::string_view> kind_names() {
  std::vector<std::string_view> out;
  for (const KindInfo& k : kKinds) out.push_back(k.name);
  return out;
}

FaultSpec default_spec(Kind kind) {
  FaultSpec s;
  s.kind = kind;
  if (takes_probability(kind)) s.probability = 1.0;
  switch (kind) {
    case Kind::plausible_drift:
      s.gyro_bias_rad_s = kPlausibleGyroBiasRadS;
      s.gyro_ramp_rad_s2 = kPlausibleGyroRampRadS2;
      s.accel_bias_m_s2 = kPlausibleAccelBiasMS2;
      s.accel_ramp_m_s3 = kPlausibleAccelRampMS3;
      break;
    case Kind::slow:
      s.divisor = 2;
      break;
    case Kind::babble:
      s.babble_factor = 2;
      break;
    default:
      break;
  }
  return s;
}

void validate(const FaultSpec& spec) {
  if (kind_name(spec.kind) == "unknown") throw std::invalid_argument("fault: kind: not a fault kind");
  const unsigned triad = static_cast<unsigned>(spec.triad);
  if (triad < 1 || triad > 3) refuse(spec, "sensor", "expected gyro, accel or both");
  if (spec.axes == 0 || spec.axes > 7) refuse(spec, "axes", "expected a non-empty subset of x, y, z");
  if (spec.clock != Clock::trajectory && spec.clock != Clock::since_start)
    refuse(spec, "clock", "expected trajectory or since_start");
  if (spec.clock == Clock::since_start && spec.start_ns < 0)
    refuse(spec, "start", "expected a time since the start >= 0");
  if (spec.duration_ns < 0) refuse(spec, "duration", "expected >= 0 (0: until cleared)");
  const std::array<std::pair<const char*, double>, 9> doubles{{{"gyro_bias_rad_s", spec.gyro_bias_rad_s},
                                                               {"accel_bias_m_s2", spec.accel_bias_m_s2},
                                                               {"gyro_ramp_rad_s2", spec.gyro_ramp_rad_s2},
                                                               {"accel_ramp_m_s3", spec.accel_ramp_m_s3},
                                                               {"scale_ppm", spec.scale_ppm},
                                                               {"noise_factor", spec.noise_factor},
                                                               {"rate_hz", spec.rate_hz},
                                                               {"probability", spec.probability},
                                                               {"bit_error_rate", spec.bit_error_rate}}};
  for (const auto& [name, v] : doubles)
    if (!std::isfinite(v)) refuse(spec, name, "expected a finite number");
  const bool gyro = has_gyro(spec), accel = has_accel(spec);
  auto need_some = [&](double g, double a, const char* gname, const char* aname, const char* what) {
    if ((gyro && g != 0.0) || (accel && a != 0.0)) return;
    refuse(spec, std::string(gyro ? gname : "") + (gyro && accel ? " or " : "") + (accel ? aname : ""),
           std::string("expected a nonzero ") + what + " for the faulted sensor");
  };
  switch (spec.kind) {
    case Kind::stuck:
    case Kind::dead:
    case Kind::garbage:
    case Kind::saturation:
      break;
    case Kind::bias_step:
      need_some(spec.gyro_bias_rad_s, spec.accel_bias_m_s2, "gyro_bias_rad_s", "accel_bias_m_s2", "bias");
      break;
    case Kind::bias_ramp:
      need_some(spec.gyro_ramp_rad_s2, spec.accel_ramp_m_s3, "gyro_ramp_rad_s2", "accel_ramp_m_s3", "ramp");
      break;
    case Kind::plausible_drift:
      need_some(spec.gyro_ramp_rad_s2, spec.accel_ramp_m_s3, "gyro_ramp_rad_s2", "accel_ramp_m_s3", "ramp");
      if (gyro && spec.gyro_ramp_rad_s2 != 0.0 && !(spec.gyro_bias_rad_s > 0.0))
        refuse(spec, "gyro_bias_rad_s", "expected the drift's final bias magnitude > 0");
      if (accel && spec.accel_ramp_m_s3 != 0.0 && !(spec.accel_bias_m_s2 > 0.0))
        refuse(spec, "accel_bias_m_s2", "expected the drift's final bias magnitude > 0");
      break;
    case Kind::scale_step:
      if (spec.scale_ppm == 0.0 || spec.scale_ppm < -1e6 || spec.scale_ppm > 1e7)
        refuse(spec, "scale_ppm", "expected a nonzero scale-factor change in [-1e6, 1e7] ppm");
      break;
    case Kind::noise_gain:
      if (!(spec.noise_factor >= 1.0 && spec.noise_factor <= kMaxNoiseFactor))
        refuse(spec, "noise_factor", "expected a factor k in [1, " + number(kMaxNoiseFactor) + "]");
      break;
    case Kind::spikes:
      if (!(spec.rate_hz > 0.0 && spec.rate_hz <= kMaxSpikeRateHz))
        refuse(spec, "rate_hz", "expected a spike rate in (0, " + number(kMaxSpikeRateHz) + "] per second");
      need_some(spec.gyro_bias_rad_s, spec.accel_bias_m_s2, "gyro_bias_rad_s", "accel_bias_m_s2", "spike amplitude");
      break;
    case Kind::slow:
      if (spec.divisor < 2 || spec.divisor > kMaxDivisor)
        refuse(spec, "divisor", "expected an integer in 2.." + std::to_string(kMaxDivisor));
      break;
    case Kind::intermittent:
      if (spec.on_ns <= 0) refuse(spec, "on", "expected an on time > 0");
      if (spec.off_ns <= 0) refuse(spec, "off", "expected an off time > 0");
      if (spec.on_ns > (TimeNs{1} << 62) || spec.off_ns > (TimeNs{1} << 62))
        refuse(spec, "on/off", "expected times below 2^62 ns");
      break;
    case Kind::delayed:
      if (spec.delay_ns <= 0 || spec.delay_ns > kMaxDelayNs)
        refuse(spec, "delay", "expected a delay in (0, " + seconds(kMaxDelayNs) + "]");
      break;
    case Kind::drop:
      if (spec.burst_samples > 0) {
        if (spec.burst_samples > kMaxBurstSamples)
          refuse(spec, "burst_samples", "expected 1.." + std::to_string(kMaxBurstSamples) + " (0: independent drops)");
        if (!(spec.rate_hz > 0.0 && spec.rate_hz <= kMaxSpikeRateHz))
          refuse(spec, "rate_hz", "expected the bursts' rate in (0, " + number(kMaxSpikeRateHz) + "] per second");
      } else if (!(spec.probability > 0.0 && spec.probability <= 1.0)) {
        refuse(spec, "probability", "expected a per-packet probability in (0, 1] (or burst_samples with rate_hz)");
      }
      break;
    case Kind::duplicate:
    case Kind::bad_checksum:
    case Kind::bad_length:
    case Kind::can_missing_frame:
      break;
    case Kind::truncate:
      if (spec.truncate_bytes < 1 || spec.truncate_bytes > 65535)
        refuse(spec, "truncate_bytes", "expected 1..65535 bytes");
      break;
    case Kind::can_wrong_id:
      if (spec.can_id > 0x1FFFFFFFu) refuse(spec, "can_id", "expected an 11- or 29-bit identifier (0..0x1FFFFFFF)");
      break;
    case Kind::bit_errors:
      if (!(spec.bit_error_rate > 0.0 && spec.bit_error_rate <= 0.5))
        refuse(spec, "bit_error_rate", "expected a per-bit error rate in (0, 0.5]");
      break;
    case Kind::sequence_jump:
      if (spec.sequence_step == 0) refuse(spec, "sequence_step", "expected a nonzero counter step");
      break;
    case Kind::sequence_reset:
    case Kind::time_freeze:
    case Kind::silence:
      break;
    case Kind::time_jump:
      if (spec.time_step_ns == 0) refuse(spec, "time_step", "expected a nonzero time step");
      break;
    case Kind::babble:
      if (spec.babble_factor < 2 || spec.babble_factor > kMaxBabbleFactor)
        refuse(spec, "babble_factor", "expected 2.." + std::to_string(kMaxBabbleFactor) + " frames per tick");
      break;
    case Kind::restart:
      if (spec.duration_ns <= 0) refuse(spec, "duration", "expected the off time > 0 (restart: silent, then start-up)");
      break;
  }
  if (takes_probability(spec.kind) && !(spec.kind == Kind::drop && spec.burst_samples > 0) &&
      !(spec.probability > 0.0 && spec.probability <= 1.0))
    refuse(spec, "probability", "expected a per-packet probability in (0, 1]");
}

std::string describe(const FaultSpec& s) {
  static const char* const kAxes[8] = {"", "x", "y", "xy", "z", "xz", "yz", "xyz"};
  std::string out(kind_name(s.kind));
  if (is_sensor_fault(s.kind)) {
    out += s.triad == Triad::gyro ? " gyro " : s.triad == Triad::accel ? " accel " : " gyro+accel ";
    out += kAxes[s.axes & 7u];
  }
  out += " at " + seconds(s.start_ns) + (s.clock == Clock::trajectory ? " trajectory time" : " since start");
  out += s.duration_ns > 0 ? " for " + seconds(s.duration_ns) : std::string(" until cleared");
  std::string p;
  auto add = [&](const std::string& text) { p += (p.empty() ? "" : ", ") + text; };
  const bool gyro = has_gyro(s), accel = has_accel(s);
  constexpr double kDeg = 180.0 / 3.14159265358979323846;
  switch (s.kind) {
    case Kind::bias_step:
    case Kind::spikes:
      if (s.kind == Kind::spikes) add("rate " + number(s.rate_hz) + " /s");
      if (gyro && s.gyro_bias_rad_s != 0.0) add("gyro " + number(s.gyro_bias_rad_s * kDeg) + " deg/s");
      if (accel && s.accel_bias_m_s2 != 0.0) add("accel " + number(s.accel_bias_m_s2 / 9.80665 * 1e3) + " mg");
      break;
    case Kind::bias_ramp:
    case Kind::plausible_drift:
      if (gyro && s.gyro_ramp_rad_s2 != 0.0) add("gyro " + number(s.gyro_ramp_rad_s2 * kDeg) + " deg/s per s");
      if (accel && s.accel_ramp_m_s3 != 0.0) add("accel " + number(s.accel_ramp_m_s3 / 9.80665 * 1e3) + " mg/s");
      if (s.kind == Kind::plausible_drift) {
        if (gyro && s.gyro_ramp_rad_s2 != 0.0) add("gyro up to " + number(s.gyro_bias_rad_s * kDeg) + " deg/s");
        if (accel && s.accel_ramp_m_s3 != 0.0) add("accel up to " + number(s.accel_bias_m_s2 / 9.80665 * 1e3) + " mg");
      }
      break;
    case Kind::scale_step: add(number(s.scale_ppm) + " ppm"); break;
    case Kind::noise_gain: add("noise x" + number(s.noise_factor)); break;
    case Kind::slow: add("every " + std::to_string(s.divisor) + " samples"); break;
    case Kind::intermittent: add("on " + seconds(s.on_ns) + ", off " + seconds(s.off_ns)); break;
    case Kind::delayed: add("delay " + seconds(s.delay_ns)); break;
    case Kind::drop:
      if (s.burst_samples > 0)
        add("bursts of " + std::to_string(s.burst_samples) + " samples at " + number(s.rate_hz) + " /s");
      else
        add("probability " + number(s.probability));
      break;
    case Kind::duplicate:
    case Kind::bad_checksum:
    case Kind::bad_length:
    case Kind::can_missing_frame: add("probability " + number(s.probability)); break;
    case Kind::truncate:
      add(std::to_string(s.truncate_bytes) + " bytes, probability " + number(s.probability));
      break;
    case Kind::can_wrong_id: add("id " + std::to_string(s.can_id) + ", probability " + number(s.probability)); break;
    case Kind::bit_errors: add("bit error rate " + number(s.bit_error_rate)); break;
    case Kind::sequence_jump: add("step " + std::to_string(s.sequence_step)); break;
    case Kind::time_jump: add("step " + seconds(s.time_step_ns)); break;
    case Kind::babble: add(std::to_string(s.babble_factor) + " frames per tick"); break;
    default: break;
  }
  if (!p.empty()) out += ": " + p;
  if (s.flag_status) out += "; status flagged";
  out += "; seed " + std::to_string(s.seed) + ", source " + s.source;
  return out;
}

}  // namespace imuemu::fault
