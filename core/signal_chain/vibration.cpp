#include "core/signal_chain/vibration.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>

#include "core/sensor/sensor_model.hpp"
#include "core/setting_error.hpp"
#include "core/so3.hpp"

namespace imuemu::signal_chain {

namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;
constexpr double kG_m_s2 = 9.80665;
// The random vibration's noise stream: its own "sensor" index in the keys of
// core/sensor (0 gyro, 1 accel), so no sensor-model stream is shared.
constexpr unsigned kVibrationStream = 7;
// The rotors' speed jitter: stream 8, axis = the rotor's index.
constexpr unsigned kRotorJitterStream = 8;
// The random angular vibration: stream 9.
constexpr unsigned kAngularVibrationStream = 9;

// The smootherstep amplitude scale s(t) of a random profile and its first
// two derivatives (RandomVibration::amplitude_scale).
struct Scale {
  double s0 = 1.0, s1 = 0.0, s2 = 0.0;
};
Scale scale_at(const std::vector<ScalePoint>& sc, double t) {
  Scale s;
  if (sc.empty()) return s;
  const auto next = std::upper_bound(sc.begin(), sc.end(), t, [](double x, const ScalePoint& q) { return x < q.time_s; });
  if (next == sc.begin()) {
    s.s0 = sc.front().scale;
  } else if (next == sc.end()) {
    s.s0 = sc.back().scale;
  } else {
    const ScalePoint& a = *(next - 1);
    const double span = next->time_s - a.time_s, u = (t - a.time_s) / span, ds = next->scale - a.scale;
    // Smootherstep S(u) = 6u^5 - 15u^4 + 10u^3: S', S'' vanish at both ends.
    s.s0 = a.scale + ds * u * u * u * (10.0 + u * (-15.0 + 6.0 * u));
    s.s1 = ds / span * 30.0 * u * u * (1.0 - u) * (1.0 - u);
    s.s2 = ds / (span * span) * 60.0 * u * (1.0 - u) * (1.0 - 2.0 * u);
  }
  return s;
}
constexpr double kRpmToRad_s = kTwoPi / 60.0;

// "name[i]": an entry of a list in a SettingError key.
std::string item(const std::string& name, std::size_t i) { return name + "[" + std::to_string(i) + "]"; }

// A profile's times (speed points, scale points): finite, within
// +-kMaxVibrationTimeS, increasing by at least kMinProfileSpacingS.
template <class Point>
void check_profile_times(const std::vector<Point>& points, double Point::*time, const std::string& key,
                         const std::string& label) {
  for (std::size_t i = 0; i < points.size(); ++i) {
    const double t = points[i].*time;
    require_magnitude(item(key, i), label + " point " + std::to_string(i + 1) + ": time_s", t,
                      {0.0, kMaxVibrationTimeS, "s", "31 years"});
    if (i > 0 && !(t >= points[i - 1].*time + kMinProfileSpacingS))
      throw SettingError(item(key, i), label + " point " + std::to_string(i + 1) +
                                                   " must have a time after the previous one (by at least 1 ms: "
                                                   "the profile's slope divides by the spacing)");
  }
}

constexpr SettingBound kFrequencyBound{kMinVibrationHz, kMaxVibrationHz, "Hz",
                                       "vibration from 0.01 Hz (slower is the trajectory's motion) to 100 kHz "
                                       "(above MIL-STD-810H pyroshock and MEMS drive resonances)"};
constexpr SettingBound kAccelBound{0.0, kMaxVibrationAccelM_s2, "m/s^2",
                                   "about 10^4 g; the widest MEMS accelerometer reads +-200 g"};
constexpr SettingBound kRateBound{0.0, kMaxVibrationRateRad_s, "rad/s",
                                  "57,000 deg/s; the widest MEMS gyro reads +-20,000 deg/s"};
constexpr SettingBound kPhaseBound{0.0, 1e6, "rad", "a phase"};
constexpr SettingBound kScaleBound{0.0, kMaxVibrationScale, "", "at most 40 dB above the profile"};

// An oscillation's amplitudes and phases (sinusoid, rotor harmonic).
void check_oscillation(const std::string& key, const std::string& label, const Vec3& linear, const Vec3& angular,
                       const Vec3& phase) {
  require_magnitude(key + ".linear_m_s2", label + ": linear_m_s2", linear, kAccelBound);
  require_magnitude(key + ".angular_rad_s", label + ": angular_rad_s", angular, kRateBound);
  require_magnitude(key + ".phase_rad", label + ": phase_rad", phase, kPhaseBound);
}

void check_rotor(const Rotor& r, std::size_t index) {
  const std::string key = item("rotor", index);
  const std::string where = "rotor " + std::to_string(index + 1);
  if (r.speed.empty())
    throw SettingError(key + ".speed", where + ": the speed profile needs at least one (time_s, rpm) point");
  check_profile_times(r.speed, &RpmPoint::time_s, key + ".speed", where + ": speed");
  double min_rpm = r.speed.front().rpm, max_rpm = min_rpm;
  for (std::size_t i = 0; i < r.speed.size(); ++i) {
    require_within(item(key + ".speed", i), where + ": speed point " + std::to_string(i + 1) + ": rpm",
                   r.speed[i].rpm, {kMinRpm, kMaxRpm, "rpm", "turbomachinery turns at 1e5 rpm"});
    min_rpm = std::min(min_rpm, r.speed[i].rpm);
    max_rpm = std::max(max_rpm, r.speed[i].rpm);
  }
  require_within(key + ".jitter_bandwidth_hz", where + ": jitter_bandwidth_hz", r.jitter_bandwidth_hz,
                 {kMinJitterBandwidthHz, kMaxJitterBandwidthHz, "Hz", "a governor loop wanders at a few Hz"});
  if (!(r.jitter_rpm >= 0.0))
    throw SettingError(key + ".jitter_rpm", where + ": jitter_rpm must be >= 0");
  // The jitter's peak (every component in phase) stays below half the lowest
  // speed, so the shaft never stops and 1/Omega stays bounded.
  const double peak = r.jitter_rpm * std::sqrt(2.0 * Vibration::kJitterComponents);
  if (!(peak < 0.5 * min_rpm))
    throw SettingError(key + ".jitter_rpm", where + ": jitter_rpm " + setting_number(r.jitter_rpm) + " may reach " +
                                                setting_number(peak) +
                                                " rpm; it must stay below half the lowest speed (" +
                                                setting_number(min_rpm) + " rpm)");
  for (std::size_t i = 0; i < r.harmonics.size(); ++i) {
    const RotorHarmonic& h = r.harmonics[i];
    const std::string hk = key + "." + item("harmonic", i);
    const std::string hw = where + ": harmonic " + std::to_string(i + 1);
    require_within(hk + ".order", hw + ": order", h.order,
                   {kMinHarmonicOrder, kMaxHarmonicOrder, "", "a shaft's harmonics and blade passes"});
    // At the top speed plus the jitter's peak.
    const double top_hz = h.order * (max_rpm + peak) / 60.0;
    if (!(top_hz <= kMaxVibrationHz))
      throw SettingError(hk + ".order", hw + ": order " + setting_number(h.order) + " reaches " +
                                            setting_number(top_hz) + " Hz at " + setting_number(max_rpm + peak) +
                                            " rpm; at most " + setting_number(kMaxVibrationHz) + " Hz");
    check_oscillation(hk, hw, h.linear_m_s2, h.angular_rad_s, h.phase_rad);
  }
}

// One random profile: its table (density: the point's level), bins, scales.
template <class Point>
void check_random(const std::string& key, const std::string& label, const std::vector<Point>& psd,
                  double Point::*density, const SettingBound& level, const Vec3& axis_scale, double resolution_hz,
                  const std::vector<ScalePoint>& amplitude_scale) {
  if (psd.size() < 2) throw SettingError(key + ".psd", label + ": the PSD table needs at least two points");
  if (psd.size() > kMaxPsdPoints)
    throw SettingError(key + ".psd", label + ": " + std::to_string(psd.size()) + " PSD points; at most " +
                                         std::to_string(kMaxPsdPoints) +
                                         " (test standards give 3..10 breakpoints; a measured PSD can be resampled)");
  for (std::size_t i = 0; i < psd.size(); ++i) {
    const std::string pk = item(key + ".psd", i);
    const std::string pw = label + ": PSD point " + std::to_string(i + 1);
    if (i > 0 && !(psd[i].frequency_hz > psd[i - 1].frequency_hz))
      throw SettingError(pk, pw + " must have a frequency above the previous one");
    require_within(pk, pw + ": frequency", psd[i].frequency_hz, kFrequencyBound);
    require_within(pk, pw + ": density", psd[i].*density, level);
  }
  require_within(key + ".resolution_hz", label + ": resolution_hz", resolution_hz,
                 {kMinResolutionHz, kMaxResolutionHz, "Hz", "one component per bin of this width"});
  const double bins = random_bins(psd.front().frequency_hz, psd.back().frequency_hz, resolution_hz);
  if (!(bins <= static_cast<double>(Vibration::kMaxComponents / 3)))
    throw SettingError(key + ".resolution_hz",
                       label + ": " + setting_number(bins) + " bins per axis of " + setting_number(resolution_hz) +
                           " Hz over " + setting_number(psd.front().frequency_hz) + ".." +
                           setting_number(psd.back().frequency_hz) + " Hz; at most " +
                           std::to_string(Vibration::kMaxComponents / 3) +
                           " per axis (raise resolution_hz): each costs work on every internal sample");
  require_within(key + ".axis_scale", label + ": axis_scale", axis_scale, kScaleBound);
  check_profile_times(amplitude_scale, &ScalePoint::time_s, key + ".amplitude_scale", label + ": amplitude_scale");
  for (std::size_t i = 0; i < amplitude_scale.size(); ++i)
    require_within(item(key + ".amplitude_scale", i),
                   label + ": amplitude_scale point " + std::to_string(i + 1) + ": scale", amplitude_scale[i].scale,
                   kScaleBound);
}

}  // namespace

double psd_at(const std::vector<PsdPoint>& psd, double f) {
  if (psd.empty() || f < psd.front().frequency_hz || f > psd.back().frequency_hz) return 0.0;
  // The first point at or above f (a binary search: a table may have
  // kMaxPsdPoints points and every component reads it once).
  const auto b = std::lower_bound(psd.begin(), psd.end(), f,
                                  [](const PsdPoint& p, double x) { return p.frequency_hz < x; });
  if (b == psd.begin()) return b->g2_per_hz;
  const PsdPoint& lo = *(b - 1);
  // Straight line in log S against log f (dB/octave slopes of the standards).
  const double x = std::log(f / lo.frequency_hz) / std::log(b->frequency_hz / lo.frequency_hz);
  return lo.g2_per_hz * std::pow(b->g2_per_hz / lo.g2_per_hz, x);
}

double random_bins(double first_hz, double last_hz, double resolution_hz) {
  return std::ceil((last_hz - first_hz) / resolution_hz);
}

void validate(const VibrationSpec& spec) {
  for (std::size_t i = 0; i < spec.sinusoids.size(); ++i) {
    const Sinusoid& s = spec.sinusoids[i];
    const std::string key = item("sinusoid", i);
    const std::string where = "vibration sinusoid " + std::to_string(i + 1);
    require_within(key + ".frequency_hz", where + ": frequency_hz", s.frequency_hz, kFrequencyBound);
    check_oscillation(key, where, s.linear_m_s2, s.angular_rad_s, s.phase_rad);
  }
  for (std::size_t i = 0; i < spec.rotors.size(); ++i) check_rotor(spec.rotors[i], i);
  for (std::size_t i = 0; i < spec.shocks.size(); ++i) {
    const Shock& k = spec.shocks[i];
    const std::string key = item("shock", i);
    const std::string where = "shock " + std::to_string(i + 1);
    require_within(key + ".time_s", where + ": time_s", k.time_s, {0.0, kMaxVibrationTimeS, "s", "since the start"});
    require_within(key + ".duration_s", where + ": duration_s", k.duration_s,
                   {kMinShockDurationS, kMaxShockDurationS, "s",
                    "MIL-STD-810H 516.8 pulses last 0.5..100 ms, pyroshock rises in tens of us"});
    require_within(key + ".return_s", where + ": return_s", k.return_s,
                   {kMinShockReturnS, kMaxShockReturnS, "s", "the mount's return after the pulse"});
    require_magnitude(key + ".peak_m_s2", where + ": peak_m_s2", k.peak_m_s2, kAccelBound);
    require_magnitude(key + ".angular_peak_rad_s2", where + ": angular_peak_rad_s2", k.angular_peak_rad_s2,
                      {0.0, kMaxShockAngularRad_s2, "rad/s^2", "a 1 ms half-sine then turns the mount at 640 rad/s"});
  }
  std::size_t components = 0;  // per axis
  if (spec.random_linear) {
    const RandomVibration& r = *spec.random_linear;
    check_random("random", "random vibration", r.psd, &PsdPoint::g2_per_hz,
                 {kMinPsd, kMaxPsdG2PerHz, "g^2/Hz", "MIL-STD-810H 514.8 profiles stay below about 1 g^2/Hz"},
                 r.axis_scale, r.resolution_hz, r.amplitude_scale);
    components = static_cast<std::size_t>(
        random_bins(r.psd.front().frequency_hz, r.psd.back().frequency_hz, r.resolution_hz));
  }
  if (spec.random_angular) {
    const RandomAngularVibration& r = *spec.random_angular;
    check_random("random_angular", "random angular vibration", r.psd, &AngularPsdPoint::rad2_s4_per_hz,
                 {kMinPsd, kMaxPsdRad2S4PerHz, "(rad/s^2)^2/Hz", "2e5 times a multirotor frame's"}, r.axis_scale,
                 r.resolution_hz, r.amplitude_scale);
    const double bins = random_bins(r.psd.front().frequency_hz, r.psd.back().frequency_hz, r.resolution_hz);
    if (static_cast<double>(components) + bins > static_cast<double>(Vibration::kMaxComponents / 3))
      throw SettingError("random_angular.resolution_hz",
                         "random angular vibration: " + setting_number(bins) + " bins per axis; at most " +
                             std::to_string(Vibration::kMaxComponents / 3 - components) +
                             " beside the linear profile's (raise resolution_hz)");
  }
  require_magnitude("lever_arm_m", "vibration: lever_arm_m", spec.lever_arm_m,
                    {0.0, kMaxLeverArmM, "m", "the scene's [imu.mounting] bound"});
  if (!spec.sensor_to_body.allFinite())
    throw SettingError("sensor_to_body", "vibration: sensor_to_body must be finite");
}

Vibration::Vibration(const VibrationSpec& spec, const std::string& device) : spec_(spec) {
  validate(spec);
  const std::uint64_t dev = sensor::device_hash(device);
  for (std::size_t i = 0; i < spec.rotors.size(); ++i) {
    const Rotor& r = spec.rotors[i];
    RotorState st;
    // Phi at each profile point: Omega_0 t before the first, trapezoids
    // (exact: the speed is linear) between points.
    st.angle_at_point_rad.push_back(r.speed[0].rpm * kRpmToRad_s * r.speed[0].time_s);
    for (std::size_t j = 1; j < r.speed.size(); ++j)
      st.angle_at_point_rad.push_back(st.angle_at_point_rad.back() + 0.5 * (r.speed[j - 1].rpm + r.speed[j].rpm) *
                                                                        kRpmToRad_s *
                                                                        (r.speed[j].time_s - r.speed[j - 1].time_s));
    if (r.jitter_rpm > 0.0) {
      sensor::Stream stream;
      stream.state = sensor::stream_key(r.seed, dev, kRotorJitterStream, static_cast<unsigned>(i), 0, 0);
      // Sum of a^2 / 2 over the components = jitter_rpm^2.
      const double a = r.jitter_rpm * kRpmToRad_s * std::sqrt(2.0 / kJitterComponents);
      for (int c = 0; c < kJitterComponents; ++c) {
        const double f = (1.0 - stream.uniform()) * r.jitter_bandwidth_hz;  // (0, bandwidth]
        st.jitter.push_back({kTwoPi * f, a, kTwoPi * stream.uniform()});
      }
    }
    rotors_.push_back(std::move(st));
  }
  for (std::size_t i = 0; i < spec.shocks.size(); ++i) {
    const Shock& k = spec.shocks[i];
    const double T = k.duration_s, R = k.return_s;
    // The unit pulse's velocity and displacement at its end.
    const double v_end = k.shape == ShockShape::half_sine ? 2.0 * T / std::numbers::pi : 0.5 * T;
    const double d_end = k.shape == ShockShape::half_sine ? T * T / std::numbers::pi : T * T / 6.0;
    // Return: v_end + R (c1/30 + c2/60) = 0 and
    // d_end + v_end R + R^2 (c1/60 + c2/140) = 0 (the moments of
    // x^2 (1-x)^2 and x^3 (1-x)^2 and of (1 - x) times them over [0, 1]).
    const double b1 = -v_end / R, b2 = -(d_end + v_end * R) / (R * R);
    const double det = (1.0 / 30.0) * (1.0 / 140.0) - (1.0 / 60.0) * (1.0 / 60.0);
    shocks_.push_back({v_end, d_end, (b1 / 140.0 - b2 / 60.0) / det, (b2 / 30.0 - b1 / 60.0) / det});
  }
  if (spec.random_linear) {
    const RandomVibration& r = *spec.random_linear;
    add_random(r.psd, kG_m_s2, r.axis_scale, r.resolution_hz, r.seed, dev, kVibrationStream, false);
  }
  if (spec.random_angular) {
    const RandomAngularVibration& r = *spec.random_angular;
    std::vector<PsdPoint> psd;  // the same log-log table, its values in (rad/s^2)^2/Hz
    for (const AngularPsdPoint& p : r.psd) psd.push_back({p.frequency_hz, p.rad2_s4_per_hz});
    add_random(psd, 1.0, r.axis_scale, r.resolution_hz, r.seed, dev, kAngularVibrationStream, true);
  }
  // Sized once: evaluating allocates nothing.
  phasor_.resize(comps_.size());
  off_grid_.resize(comps_.size());
}

void Vibration::add_random(const std::vector<PsdPoint>& psd, double unit_si, const Vec3& axis_scale,
                           double resolution_hz, std::uint64_t seed, std::uint64_t dev, unsigned stream_index,
                           bool angular) {
  const double f0 = psd.front().frequency_hz, f1 = psd.back().frequency_hz;
  // validate() has bounded the count (as a double: no wrap) by kMaxComponents.
  const auto bins = static_cast<std::size_t>(random_bins(f0, f1, resolution_hz));
  comps_.reserve(comps_.size() + 3 * bins);
  for (int axis = 0; axis < 3; ++axis) {
    if (axis_scale[axis] == 0.0) continue;
    sensor::Stream stream;
    stream.state = sensor::stream_key(seed, dev, stream_index, static_cast<unsigned>(axis), 0, 0);
    for (std::size_t b = 0; b < bins; ++b) {
      const double lo = f0 + static_cast<double>(b) * resolution_hz;
      const double width = std::min(resolution_hz, f1 - lo);
      if (!(width > 0.0)) break;  // a last bin the rounding of (f1 - f0) / resolution made empty
      const double f = lo + stream.uniform() * width;
      const double phase = kTwoPi * stream.uniform();
      // The bin's power S(f) df as a sinusoid's amplitude^2 / 2.
      const double power = psd_at(psd, f) * axis_scale[axis] * unit_si * unit_si * width;
      const double w = kTwoPi * f, a = std::sqrt(2.0 * power);
      comps_.push_back({w, a, phase, axis, angular, a / w, a / (w * w)});
    }
  }
}

ShaftState Vibration::shaft(std::size_t index, double t) const {
  const Rotor& r = spec_.rotors[index];
  const RotorState& st = rotors_[index];
  ShaftState s;
  const std::vector<RpmPoint>& p = r.speed;
  // The first point after t: before the first point and after the last the
  // speed is constant.
  const auto next = std::upper_bound(p.begin(), p.end(), t, [](double x, const RpmPoint& q) { return x < q.time_s; });
  if (next == p.begin()) {
    s.speed_rad_s = p.front().rpm * kRpmToRad_s;
    s.angle_rad = s.speed_rad_s * t;
  } else {
    const std::size_t j = static_cast<std::size_t>(next - p.begin()) - 1;
    const double tau = t - p[j].time_s, w0 = p[j].rpm * kRpmToRad_s;
    const double slope = next == p.end() ? 0.0 : (next->rpm - p[j].rpm) * kRpmToRad_s / (next->time_s - p[j].time_s);
    // Phi = Phi_j + Omega_j tau + slope tau^2 / 2: the integral of a linear speed.
    s.angle_rad = st.angle_at_point_rad[j] + w0 * tau + 0.5 * slope * tau * tau;
    s.speed_rad_s = w0 + slope * tau;
    s.accel_rad_s2 = slope;
  }
  for (const JitterComponent& c : st.jitter) {
    const double ph = c.w_rad_s * t + c.phase_rad, sn = std::sin(ph), cs = std::cos(ph);
    // d Omega = a sin(ph), integrated from t = 0.
    s.angle_rad -= c.amplitude_rad_s / c.w_rad_s * (cs - std::cos(c.phase_rad));
    s.speed_rad_s += c.amplitude_rad_s * sn;
    s.accel_rad_s2 += c.amplitude_rad_s * c.w_rad_s * cs;
    s.jerk_rad_s3 -= c.amplitude_rad_s * c.w_rad_s * c.w_rad_s * sn;
  }
  return s;
}

void Vibration::add_shock(double t, VibrationState& v) const {
  for (std::size_t i = 0; i < shocks_.size(); ++i) {
    const Shock& k = spec_.shocks[i];
    const ShockState& st = shocks_[i];
    const double tau = t - k.time_s, T = k.duration_s, R = k.return_s;
    if (!(tau >= 0.0) || !(tau < T + R)) continue;  // outside the event: nothing
    double a, vel, d;  // per unit peak
    if (tau < T) {
      if (k.shape == ShockShape::half_sine) {
        const double w = std::numbers::pi / T;
        a = std::sin(w * tau);
        vel = (1.0 - std::cos(w * tau)) / w;
        d = (tau - std::sin(w * tau) / w) / w;
      } else {
        a = tau / T;
        vel = tau * tau / (2.0 * T);
        d = tau * tau * tau / (6.0 * T);
      }
    } else {
      // The return's polynomial in x and its integrals (R x^{n+1}/(n+1), R^2 x^{n+2}/((n+1)(n+2))).
      const double x = (tau - T) / R, x2 = x * x, x3 = x2 * x, x4 = x3 * x, x5 = x4 * x, x6 = x5 * x, x7 = x6 * x;
      const double c1 = st.c1, c2 = st.c2;
      // c1 (x^2 - 2x^3 + x^4) + c2 (x^3 - 2x^4 + x^5)
      a = c1 * (x2 - 2.0 * x3 + x4) + c2 * (x3 - 2.0 * x4 + x5);
      vel = st.v_end + R * (c1 * (x3 / 3.0 - x4 / 2.0 + x5 / 5.0) + c2 * (x4 / 4.0 - 2.0 * x5 / 5.0 + x6 / 6.0));
      d = st.d_end + st.v_end * (tau - T) +
          R * R * (c1 * (x4 / 12.0 - x5 / 10.0 + x6 / 30.0) + c2 * (x5 / 20.0 - x6 / 15.0 + x7 / 42.0));
    }
    v.d += d * k.peak_m_s2;
    v.d_dot += vel * k.peak_m_s2;
    v.d_ddot += a * k.peak_m_s2;
    v.theta += d * k.angular_peak_rad_s2;
    v.theta_dot += vel * k.angular_peak_rad_s2;
    v.theta_ddot += a * k.angular_peak_rad_s2;
  }
}

VibrationState Vibration::at(double t) const {
  VibrationState v;
  add_shock(t, v);
  for (std::size_t r = 0; r < spec_.rotors.size(); ++r) {
    const ShaftState sh = shaft(r, t);
    const double W = sh.speed_rad_s, W1 = sh.accel_rad_s2, W2 = sh.jerk_rad_s3;
    for (const RotorHarmonic& h : spec_.rotors[r].harmonics) {
      const double k = h.order, kW = k * W;
      for (int i = 0; i < 3; ++i) {
        const double psi = k * sh.angle_rad + h.phase_rad[i];
        const double sn = std::sin(psi), cs = std::cos(psi);
        // d = u sin(psi), u = -A / (k Omega)^2; psi' = k Omega, psi'' = k Omega'.
        const double A = h.linear_m_s2[i];
        if (A != 0.0) {
          const double u = -A / (kW * kW);
          const double u1 = 2.0 * A * W1 / (k * k * W * W * W);
          const double u2 = 2.0 * A / (k * k) * (W2 / (W * W * W) - 3.0 * W1 * W1 / (W * W * W * W));
          v.d[i] += u * sn;
          v.d_dot[i] += u1 * sn + u * kW * cs;
          v.d_ddot[i] += u2 * sn + 2.0 * u1 * kW * cs + u * k * W1 * cs - u * kW * kW * sn;
        }
        // theta = q cos(psi), q = -B / (k Omega).
        const double B = h.angular_rad_s[i];
        if (B != 0.0) {
          const double q = -B / kW;
          const double q1 = B * W1 / (k * W * W);
          const double q2 = B / k * (W2 / (W * W) - 2.0 * W1 * W1 / (W * W * W));
          v.theta[i] += q * cs;
          v.theta_dot[i] += q1 * cs - q * kW * sn;
          v.theta_ddot[i] += q2 * cs - 2.0 * q1 * kW * sn - q * k * W1 * sn - q * kW * kW * cs;
        }
      }
    }
  }
  for (const Sinusoid& s : spec_.sinusoids) {
    const double w = kTwoPi * s.frequency_hz;
    for (int i = 0; i < 3; ++i) {
      const double ph = w * t + s.phase_rad[i];
      const double sn = std::sin(ph), cs = std::cos(ph);
      // Zero-mean displacement and angle whose second / first derivative is
      // the given amplitude times sin(ph).
      v.d[i] += -s.linear_m_s2[i] * sn / (w * w);
      v.d_dot[i] += -s.linear_m_s2[i] * cs / w;
      v.d_ddot[i] += s.linear_m_s2[i] * sn;
      v.theta[i] += -s.angular_rad_s[i] * cs / w;
      v.theta_dot[i] += s.angular_rad_s[i] * sn;
      v.theta_ddot[i] += s.angular_rad_s[i] * w * cs;
    }
  }
  if (comps_.empty()) return v;
  const std::vector<std::complex<double>>& phasor = random_phasors(t);
  // Linear (d) and angular (theta) sums, each with its profile's scale.
  Vec3 x[2] = {Vec3::Zero(), Vec3::Zero()}, x_dot[2] = {Vec3::Zero(), Vec3::Zero()},
       x_ddot[2] = {Vec3::Zero(), Vec3::Zero()};
  for (std::size_t i = 0; i < comps_.size(); ++i) {
    const Component& c = comps_[i];
    const double cs = phasor[i].real(), sn = phasor[i].imag();
    const int j = c.angular ? 1 : 0;
    x[j][c.axis] -= c.amplitude_over_w2 * cs;
    x_dot[j][c.axis] += c.amplitude_over_w * sn;
    x_ddot[j][c.axis] += c.amplitude_m_s2 * cs;
  }
  // The scaled motion s(t) x(t), differentiated exactly (product rule).
  const Scale sl = spec_.random_linear ? scale_at(spec_.random_linear->amplitude_scale, t) : Scale{};
  const Scale sa = spec_.random_angular ? scale_at(spec_.random_angular->amplitude_scale, t) : Scale{};
  v.d += sl.s0 * x[0];
  v.d_dot += sl.s0 * x_dot[0] + sl.s1 * x[0];
  v.d_ddot += sl.s0 * x_ddot[0] + 2.0 * sl.s1 * x_dot[0] + sl.s2 * x[0];
  v.theta += sa.s0 * x[1];
  v.theta_dot += sa.s0 * x_dot[1] + sa.s1 * x[1];
  v.theta_ddot += sa.s0 * x_ddot[1] + 2.0 * sa.s1 * x_dot[1] + sa.s2 * x[1];
  return v;
}

void Vibration::set_grid_step(double step_s) {
  step_s_ = step_s;
  rotation_.resize(comps_.size());
  for (std::size_t i = 0; i < comps_.size(); ++i) rotation_[i] = std::polar(1.0, comps_[i].w_rad_s * step_s);
  cached_ = false;
}

const std::vector<std::complex<double>>& Vibration::random_phasors(double t) const {
  const std::size_t n = comps_.size();
  // The cached grid instant itself (to the rounding of the caller's t: the
  // end of one interval is the start of the next, t_k = k h against
  // t_{k+1} - h).
  // (Below a quarter step, so neither test can take one instant for the other.)
  double tolerance = 1e-12 * std::max(1.0, std::abs(t));
  if (step_s_ > 0.0) tolerance = std::min(tolerance, 0.25 * step_s_);
  if (cached_ && std::abs(t - t_cached_s_) <= tolerance) return phasor_;
  // One grid step after the cached instant, to the rounding of the caller's
  // t = t0 + s h (agreeing to ~1e-15 relative; 1e-12 is allowed).
  const bool next_step = cached_ && step_s_ > 0.0 && std::abs(t - (t_cached_s_ + step_s_)) <= tolerance &&
                         steps_since_exact_ < kResyncSteps;
  if (next_step) {
    for (std::size_t i = 0; i < n; ++i) phasor_[i] *= rotation_[i];
    t_cached_s_ = t;
    ++steps_since_exact_;
    work_.rotations += n;
    return phasor_;
  }
  work_.direct += n;
  // Only grid instants become the cache; an instant between them (the raw
  // increments' Gauss-Legendre nodes) is computed into its own buffer and
  // forgotten, so the grid goes on by rotations after it.
  const bool on_grid = step_s_ > 0.0 && std::abs(t / step_s_ - std::round(t / step_s_)) < 1e-6;
  std::vector<std::complex<double>>& out = on_grid || step_s_ <= 0.0 ? phasor_ : off_grid_;
  for (std::size_t i = 0; i < n; ++i) out[i] = std::polar(1.0, comps_[i].w_rad_s * t + comps_[i].phase_rad);
  if (&out == &phasor_) {
    cached_ = on_grid;
    t_cached_s_ = t;
    steps_since_exact_ = 0;
  }
  return out;
}

Kinematics Vibration::apply(const Kinematics& base, const Vec3& alpha_s, double t) const {
  const VibrationState v = at(t);
  const Mat3& M = spec_.sensor_to_body;
  const Vec3& l = spec_.lever_arm_m;
  // The sensor point's displacement p = d + (exp([th]) - I) l and its
  // derivatives, with the turn's body rate w_v = W(th) th' and acceleration
  // a_v (Eq. 3.59, 3.61): d/dt exp([th]) l = exp([th]) (w_v x l).
  const Mat3 E = so3::exp(v.theta);
  const Vec3 w_v = so3::W(v.theta) * v.theta_dot;
  const Vec3 a_v = so3::angular_acceleration(v.theta, v.theta_dot, v.theta_ddot);
  const Vec3 p = v.d + E * l - l;
  const Vec3 p_dot = v.d_dot + E * w_v.cross(l);
  const Vec3 p_ddot = v.d_ddot + E * (a_v.cross(l) + w_v.cross(w_v.cross(l)));
  // In sensor axes.
  const Vec3 th_s = M.transpose() * v.theta, th_s_dot = M.transpose() * v.theta_dot;
  const Vec3 q = M.transpose() * p, q_dot = M.transpose() * p_dot, q_ddot = M.transpose() * p_ddot;
  const Mat3 Es = so3::exp(th_s);
  const Vec3& w_s = base.angular_rate_rad_s;
  Kinematics k = base;
  k.attitude = base.attitude * Es;
  k.angular_rate_rad_s = Es.transpose() * w_s + so3::W(th_s) * th_s_dot;
  k.position_m = base.position_m + base.attitude * q;
  k.velocity_m_s = base.velocity_m_s + base.attitude * (w_s.cross(q) + q_dot);
  k.acceleration_m_s2 = base.acceleration_m_s2 + base.attitude * (alpha_s.cross(q) + w_s.cross(w_s.cross(q)) +
                                                                  2.0 * w_s.cross(q_dot) + q_ddot);
  return k;
}

Kinematics VibratingInterval::at(double s) const {
  return vibration_.apply(base_.at(s), base_.angular_acceleration_at(s), t0_s_ + s * h_s_);
}

}  // namespace imuemu::signal_chain
