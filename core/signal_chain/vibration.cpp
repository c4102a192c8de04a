#include "core/signal_chain/vibration.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>

#include "core/sensor/sensor_model.hpp"
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

void check_rotor(const Rotor& r, std::size_t index) {
  const std::string where = "rotor " + std::to_string(index + 1) + ": ";
  if (r.speed.empty()) throw std::invalid_argument(where + "the speed profile needs at least one (time_s, rpm) point");
  double min_rpm = r.speed.front().rpm;
  for (std::size_t i = 0; i < r.speed.size(); ++i) {
    const RpmPoint& p = r.speed[i];
    if (!std::isfinite(p.time_s) || !std::isfinite(p.rpm) || !(p.rpm > 0.0) ||
        (i > 0 && !(p.time_s > r.speed[i - 1].time_s)))
      throw std::invalid_argument(where + "speed point " + std::to_string(i + 1) +
                                  " must have a time after the previous one and an rpm > 0");
    min_rpm = std::min(min_rpm, p.rpm);
  }
  for (std::size_t i = 0; i < r.harmonics.size(); ++i) {
    const RotorHarmonic& h = r.harmonics[i];
    if (!(h.order > 0.0) || !std::isfinite(h.order) || !h.linear_m_s2.allFinite() || !h.angular_rad_s.allFinite() ||
        !h.phase_rad.allFinite())
      throw std::invalid_argument(where + "harmonic " + std::to_string(i + 1) +
                                  ": order must be > 0 and every amplitude and phase finite");
  }
  if (!(r.jitter_rpm >= 0.0) || !std::isfinite(r.jitter_rpm) || !(r.jitter_bandwidth_hz > 0.0) ||
      !std::isfinite(r.jitter_bandwidth_hz))
    throw std::invalid_argument(where + "jitter_rpm must be >= 0 and jitter_bandwidth_hz > 0");
  // The jitter's peak (every component in phase) stays below half the lowest
  // speed, so the shaft never stops and 1/Omega stays bounded.
  const double peak = r.jitter_rpm * std::sqrt(2.0 * Vibration::kJitterComponents);
  if (!(peak < 0.5 * min_rpm))
    throw std::invalid_argument(where + "jitter_rpm " + std::to_string(r.jitter_rpm) + " may reach " +
                                std::to_string(peak) + " rpm; it must stay below half the lowest speed (" +
                                std::to_string(min_rpm) + " rpm)");
}

}  // namespace

double psd_at(const std::vector<PsdPoint>& psd, double f) {
  if (psd.empty() || f < psd.front().frequency_hz || f > psd.back().frequency_hz) return 0.0;
  for (std::size_t i = 1; i < psd.size(); ++i) {
    const PsdPoint& a = psd[i - 1];
    const PsdPoint& b = psd[i];
    if (f <= b.frequency_hz) {
      // Straight line in log S against log f (dB/octave slopes of the standards).
      const double x = std::log(f / a.frequency_hz) / std::log(b.frequency_hz / a.frequency_hz);
      return a.g2_per_hz * std::pow(b.g2_per_hz / a.g2_per_hz, x);
    }
  }
  return psd.back().g2_per_hz;
}

Vibration::Vibration(const VibrationSpec& spec, const std::string& device) : spec_(spec) {
  for (std::size_t i = 0; i < spec.sinusoids.size(); ++i) {
    const Sinusoid& s = spec.sinusoids[i];
    if (!(s.frequency_hz > 0.0) || !std::isfinite(s.frequency_hz) || !s.linear_m_s2.allFinite() ||
        !s.angular_rad_s.allFinite() || !s.phase_rad.allFinite())
      throw std::invalid_argument("vibration sinusoid " + std::to_string(i + 1) +
                                  ": frequency_hz must be > 0 and every amplitude and phase finite");
  }
  const std::uint64_t dev = sensor::device_hash(device);
  for (std::size_t i = 0; i < spec.rotors.size(); ++i) {
    const Rotor& r = spec.rotors[i];
    check_rotor(r, i);
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
    if (!std::isfinite(k.time_s) || !(k.time_s >= 0.0) || !(k.duration_s > 0.0) || !std::isfinite(k.duration_s) ||
        !(k.return_s > 0.0) || !std::isfinite(k.return_s) || !k.peak_m_s2.allFinite() ||
        !k.angular_peak_rad_s2.allFinite())
      throw std::invalid_argument("shock " + std::to_string(i + 1) +
                                  ": time_s must be >= 0, duration and return > 0 and the peaks finite");
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
    add_random("random vibration", r.psd, kG_m_s2, r.axis_scale, r.resolution_hz, r.amplitude_scale, r.seed,
               dev, kVibrationStream, false);
  }
  if (spec.random_angular) {
    const RandomAngularVibration& r = *spec.random_angular;
    std::vector<PsdPoint> psd;  // the same log-log table, its values in (rad/s^2)^2/Hz
    for (const AngularPsdPoint& p : r.psd) psd.push_back({p.frequency_hz, p.rad2_s4_per_hz});
    add_random("random angular vibration", psd, 1.0, r.axis_scale, r.resolution_hz, r.amplitude_scale, r.seed, dev,
               kAngularVibrationStream, true);
  }
}

void Vibration::add_random(const std::string& label, const std::vector<PsdPoint>& psd, double unit_si,
                           const Vec3& axis_scale,
                           double resolution_hz, const std::vector<ScalePoint>& amplitude_scale, std::uint64_t seed,
                           std::uint64_t dev, unsigned stream_index, bool angular) {
  if (psd.size() < 2) throw std::invalid_argument(label + ": the PSD table needs at least two points");
  for (std::size_t i = 0; i < psd.size(); ++i) {
    if (!(psd[i].frequency_hz > 0.0) || !(psd[i].g2_per_hz > 0.0) || !std::isfinite(psd[i].g2_per_hz) ||
        !std::isfinite(psd[i].frequency_hz) || (i > 0 && !(psd[i].frequency_hz > psd[i - 1].frequency_hz)))
      throw std::invalid_argument(label + ": PSD point " + std::to_string(i + 1) +
                                  " must have a frequency above the previous one and a positive, finite density");
  }
  if (!(resolution_hz > 0.0) || !std::isfinite(resolution_hz))
    throw std::invalid_argument(label + ": resolution_hz must be > 0");
  for (std::size_t i = 0; i < amplitude_scale.size(); ++i) {
    const ScalePoint& p = amplitude_scale[i];
    if (!std::isfinite(p.time_s) || !std::isfinite(p.scale) || !(p.scale >= 0.0) ||
        (i > 0 && !(p.time_s > amplitude_scale[i - 1].time_s)))
      throw std::invalid_argument(label + ": amplitude_scale point " + std::to_string(i + 1) +
                                  " must have a time after the previous one and a scale >= 0");
  }
  if (!axis_scale.allFinite() || (axis_scale.array() < 0.0).any())
    throw std::invalid_argument(label + ": axis_scale must be finite and >= 0");
  const double f0 = psd.front().frequency_hz, f1 = psd.back().frequency_hz;
  const std::size_t bins = static_cast<std::size_t>(std::ceil((f1 - f0) / resolution_hz));
  if (comps_.size() + bins * 3 > kMaxComponents)
    throw std::invalid_argument(label + ": " + std::to_string(bins) + " bins per axis of " +
                                std::to_string(resolution_hz) + " Hz; at most " +
                                std::to_string((kMaxComponents - comps_.size()) / 3) + " (raise resolution_hz)");
  for (int axis = 0; axis < 3; ++axis) {
    if (axis_scale[axis] == 0.0) continue;
    sensor::Stream stream;
    stream.state = sensor::stream_key(seed, dev, stream_index, static_cast<unsigned>(axis), 0, 0);
    for (std::size_t b = 0; b < bins; ++b) {
      const double lo = f0 + static_cast<double>(b) * resolution_hz;
      const double width = std::min(resolution_hz, f1 - lo);
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
  random_phasors(t);
  // Linear (d) and angular (theta) sums, each with its profile's scale.
  Vec3 x[2] = {Vec3::Zero(), Vec3::Zero()}, x_dot[2] = {Vec3::Zero(), Vec3::Zero()},
       x_ddot[2] = {Vec3::Zero(), Vec3::Zero()};
  for (std::size_t i = 0; i < comps_.size(); ++i) {
    const Component& c = comps_[i];
    const double cs = phasor_[i].real(), sn = phasor_[i].imag();
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

void Vibration::random_phasors(double t) const {
  phasor_.resize(comps_.size());
  if (cached_ && t == t_cached_s_) return;
  // One grid step after the cached instant, to the rounding of the caller's
  // t = t0 + s h (agreeing to ~1e-15 relative; 1e-12 is allowed).
  const bool next_step = cached_ && step_s_ > 0.0 && std::abs(t - (t_cached_s_ + step_s_)) <= 1e-12 * std::max(1.0, t) &&
                         steps_since_exact_ < kResyncSteps;
  if (next_step) {
    for (std::size_t i = 0; i < comps_.size(); ++i) phasor_[i] *= rotation_[i];
    t_cached_s_ = t;
    ++steps_since_exact_;
    return;
  }
  for (std::size_t i = 0; i < comps_.size(); ++i) phasor_[i] = std::polar(1.0, comps_[i].w_rad_s * t + comps_[i].phase_rad);
  // Only grid instants become the cache (the raw increments' Gauss-Legendre
  // nodes between them are computed and forgotten).
  const bool on_grid = step_s_ > 0.0 && std::abs(t / step_s_ - std::round(t / step_s_)) < 1e-6;
  cached_ = on_grid;
  t_cached_s_ = t;
  steps_since_exact_ = 0;
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
