// Vibration as rigid-body motion (issue 16, acceptance 2; first part):
// added to the smoothed trajectory after the smoothing (so the kernel cannot
// remove it), linear and angular, in body axes at the body's reference
// point, carried to the IMU through its lever arm, so that gyro, accelerometer
// and the increments agree and coning and sculling appear by construction.
//
// Sources in this first part: sinusoids (frequency, amplitude and phase per
// axis; linear as acceleration, angular as rate) and random linear vibration
// from a one-sided acceleration PSD table (g^2/Hz against Hz, interpolated
// log-log as test standards write it, e.g. MIL-STD-810H Method 514.8). The
// random part is a random-phase multisine: one component per `resolution_hz`
// bin at a frequency drawn uniformly inside the bin (incommensurate: the
// signal never repeats) and a uniform phase, its amplitude^2 / 2 the bin's
// power S(f) df, so that its PSD is the table's; Gaussian by the central
// limit theorem over the hundreds of components a profile spans. Rotor or
// engine harmonics: a shaft speed (constant or a piecewise-linear (time, rpm)
// profile, plus a smooth seeded jitter), harmonic orders k with amplitude and
// phase per axis; the shaft angle Phi(t) is the integral of the speed in
// closed form; the random part optionally scaled over time. Random angular
// vibration likewise, from a one-sided angular-acceleration PSD. Shocks:
// half-sine or terminal-peak sawtooth acceleration pulses (MIL-STD-810H
// Method 516.8 shapes), linear and/or angular, at given times, followed by a
// smooth return of the mount (below).
//
// Motion: the vibration displaces the body by d(t) and turns it by exp([th(t)])
// about the reference point (th, d in body axes, closed form with their first
// and second derivatives). A sensor at lever arm l (body axes) with axes
// sensor_to_body = M moves by p = d + (exp([th]) - I) l; in sensor axes the
// turn is exp([M^T th]) and the displacement q = M^T p. On top of the smoothed
// sensor trajectory (x_s, R_s, omega_s, alpha_s):
//   R = R_s exp([M^T th]),  omega = exp([M^T th])^T omega_s + W(M^T th) M^T th'
//   x = x_s + R_s q,  v = v_s + R_s (omega_s x q + q'),
//   a = a_s + R_s (alpha_s x q + omega_s x (omega_s x q) + 2 omega_s x q' + q'')
// (Eq. 3.59 and 3.61 for the turn's rate and acceleration).
#pragma once

#include <complex>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "core/signal_chain/increments.hpp"
#include "core/trajectory.hpp"

namespace imuemu::signal_chain {

struct Sinusoid {
  double frequency_hz = 0.0;
  Vec3 linear_m_s2 = Vec3::Zero();   // acceleration amplitude per body axis
  Vec3 angular_rad_s = Vec3::Zero(); // angular-rate amplitude per body axis
  Vec3 phase_rad = Vec3::Zero();     // per axis: a(t) = A sin(2 pi f t + phase)
};

struct PsdPoint {
  double frequency_hz = 0.0;
  double g2_per_hz = 0.0;  // one-sided acceleration PSD, g^2/Hz (g = 9.80665 m/s^2)
};

// Random angular vibration: the same random-phase multisine, from a
// one-sided PSD of angular acceleration ((rad/s^2)^2/Hz against Hz, log-log
// between points); each component turns the mount by
// theta = -(a / w^2) cos(w t + phase) about its axis, so the gyro sees
// theta' (Eq. 3.59 through W(theta)) and the lever arm carries it into the
// accelerometer.
struct AngularPsdPoint {
  double frequency_hz = 0.0;
  double rad2_s4_per_hz = 0.0;
};

// A point of the random profile's scale over time.
struct ScalePoint {
  double time_s = 0.0;
  double scale = 1.0;  // amplitude multiplier (the PSD scales by its square), >= 0
};

struct RandomVibration {
  std::vector<PsdPoint> psd;            // increasing frequencies, log-log interpolated between them
  Vec3 axis_scale = Vec3(1.0, 1.0, 1.0);  // PSD multiplier per body axis (0: none on that axis)
  double resolution_hz = 0.5;           // one component per bin of this width
  std::uint64_t seed = 0;
  // Amplitude scale over time (empty: 1). Between points the scale follows a
  // smootherstep (C2: its rate and curvature are zero at the points), not a
  // straight line: the random displacement is s(t) d(t), differentiated
  // exactly, and a kink in s would put a step into the mount's velocity. The
  // acceleration is s d'' + 2 s' d' + s'' d; the last two terms are of
  // relative size s' / (s w) and s'' / (s w^2), small for a ramp much slower
  // than the profile's lowest frequency. Constant before the first point and
  // after the last.
  std::vector<ScalePoint> amplitude_scale;
};

struct RandomAngularVibration {
  std::vector<AngularPsdPoint> psd;     // increasing frequencies
  Vec3 axis_scale = Vec3(1.0, 1.0, 1.0);  // PSD multiplier per body axis
  double resolution_hz = 0.5;
  std::uint64_t seed = 0;
  std::vector<ScalePoint> amplitude_scale;  // as RandomVibration's
};

// Rotor or engine harmonics. The shaft turns at Omega(t) = 2 pi rpm(t) / 60
// (rpm(t): linear between the profile's points, constant before the first and
// after the last; one point is a constant speed) plus a jitter: a sum of
// kJitterComponents sinusoids at frequencies drawn uniformly in
// (0, jitter_bandwidth_hz] with random phases, of total rms jitter_rpm (its
// own SplitMix64 stream from seed and the device name, so a run is
// reproducible bit for bit). The shaft angle Phi(t) = integral of Omega is in
// closed form (a quadratic per profile segment plus the jitter's sines).
// Harmonic k drives psi_k = k Phi + phase: angle theta = -A cos(psi)/(k Omega)
// and displacement d = -A sin(psi)/(k Omega)^2, differentiated exactly (with
// Omega' and Omega''), so theta' = A sin(psi) and d'' = A sin(psi) exactly at
// a constant speed, and up to terms of relative size Omega'/(k Omega^2) while
// the speed changes: the motion stays rigid and consistent (gyro, accel and
// increments are derivatives of one trajectory) and the amplitude is the
// datasheet's at the instantaneous speed.
struct RpmPoint {
  double time_s = 0.0;  // since the start of the run
  double rpm = 0.0;     // > 0
};

struct RotorHarmonic {
  double order = 1.0;                 // k: frequency k rpm / 60 Hz
  Vec3 linear_m_s2 = Vec3::Zero();    // acceleration amplitude per body axis
  Vec3 angular_rad_s = Vec3::Zero();  // angular-rate amplitude per body axis
  Vec3 phase_rad = Vec3::Zero();      // per axis: A sin(k Phi(t) + phase)
};

struct Rotor {
  std::vector<RpmPoint> speed;  // increasing times; one point: constant speed
  std::vector<RotorHarmonic> harmonics;
  double jitter_rpm = 0.0;            // rms of the speed jitter
  double jitter_bandwidth_hz = 1.0;   // the jitter's components lie in (0, this]
  std::uint64_t seed = 0;
};

// A shock: a linear acceleration pulse per body axis starting at time_s,
// peak_m_s2 [x, y, z] and duration T (one shape for the three axes):
//   half_sine:  a(tau) = P sin(pi tau / T), 0 <= tau < T
//   sawtooth:   a(tau) = P tau / T (terminal peak, then back to 0 at tau = T).
// As rigid-body motion the pulse leaves the mount with a velocity
// (2 P T / pi or P T / 2) and a displacement (P T^2 / pi or P T^2 / 6). The
// mount then returns over return_s: an acceleration R(x) = c1 x^2 (1 - x)^2 +
// c2 x^3 (1 - x)^2 (x = (tau - T) / return_s) with c1, c2 so that velocity and
// displacement are zero at the return's end (starting and ending at zero
// acceleration and jerk). Outside [time_s, time_s + T + return_s] the shock
// contributes nothing: the trajectory is the one without it.
enum class ShockShape { half_sine, sawtooth };

// An angular shock is the same pulse (and return) as an angular
// acceleration per body axis, angular_peak_rad_s2: the mount turns by the
// pulse's double integral and turns back over the return, so outside the
// event the attitude is the one without it.
struct Shock {
  double time_s = 0.0;
  ShockShape shape = ShockShape::half_sine;
  Vec3 peak_m_s2 = Vec3::Zero();
  Vec3 angular_peak_rad_s2 = Vec3::Zero();
  double duration_s = 0.011;
  double return_s = 0.2;
};

struct VibrationSpec {
  std::vector<Sinusoid> sinusoids;
  std::vector<Shock> shocks;
  std::optional<RandomVibration> random_linear;
  std::optional<RandomAngularVibration> random_angular;
  std::vector<Rotor> rotors;
  Vec3 lever_arm_m = Vec3::Zero();   // the sensor relative to the vibration's reference point, body axes
  Mat3 sensor_to_body = Mat3::Identity();
  bool empty() const {
    return sinusoids.empty() && !random_linear && !random_angular && rotors.empty() && shocks.empty();
  }
};

// Bounds of the vibration settings (issue 26, N5, N7/N8: a sinusoid at
// 1e-300 or 1e308 Hz, amplitudes of 1e308, a rotor at 1e-300 rpm made NaN;
// a crafted bin count wrapped at 2^64). Within them every value the
// vibration computes is finite, and each is beyond what a test standard or
// a datasheet asks for:
//  - frequencies (sinusoids, PSD points, rotor harmonics at top speed):
//    MIL-STD-810H Method 514.8 profiles span 5..2000 Hz, pyroshock (517.3)
//    reaches 10 kHz, MEMS gyros' drive resonances lie at 20..30 kHz. Below
//    0.01 Hz (a 100 s period) it is the trajectory's motion, not vibration.
inline constexpr double kMinVibrationHz = 0.01, kMaxVibrationHz = 1e5;
//  - linear acceleration amplitudes and shock peaks: 1e5 m/s^2, about 10^4 g
//    (pyroshock reaches thousands of g; the widest MEMS accelerometer,
//    ADXL375, reads +-200 g: beyond a part's range the sensor model saturates).
inline constexpr double kMaxVibrationAccelM_s2 = 1e5;
//  - angular-rate amplitudes: 1000 rad/s, 57,000 deg/s (the widest MEMS
//    gyro, ADXRS649, reads +-20,000 deg/s); angular shock peaks 1e6 rad/s^2
//    (a 1 ms half-sine then turns the mount at 640 rad/s).
inline constexpr double kMaxVibrationRateRad_s = 1e3, kMaxShockAngularRad_s2 = 1e6;
//  - PSD levels: MIL-STD-810H 514.8 profiles stay below about 1 g^2/Hz; 1e3
//    g^2/Hz over 100 kHz is 10^4 g rms. Above 0 for the log-log
//    interpolation, and at least 1e-15 (a seismically quiet floor is about
//    1e-13 g^2/Hz) so the ratio of two points cannot overflow. Angular:
//    1e4 (rad/s^2)^2/Hz, 2e5 times the example multirotor frame's.
inline constexpr double kMinPsd = 1e-15, kMaxPsdG2PerHz = 1e3, kMaxPsdRad2S4PerHz = 1e4;
//  - a PSD table of at most 10,000 points (test standards give 3..10
//    breakpoints; a measured Welch PSD at 0.25 Hz to 2 kHz has 8000), bins of
//    1e-3..1e4 Hz, and at most Vibration::kMaxComponents components in all.
inline constexpr std::size_t kMaxPsdPoints = 10'000;
inline constexpr double kMinResolutionHz = 1e-3, kMaxResolutionHz = 1e4;
//  - axis and amplitude scales 0..100 (40 dB above the profile).
inline constexpr double kMaxVibrationScale = 100.0;
//  - rotor speeds 1..1e6 rpm (turbomachinery turns at 1e5 rpm), harmonic
//    orders 0.01..1000, speed jitter bandwidth 1e-3..1000 Hz (a governor
//    loop wanders at a few Hz).
inline constexpr double kMinRpm = 1.0, kMaxRpm = 1e6, kMinHarmonicOrder = 0.01, kMaxHarmonicOrder = 1000.0;
inline constexpr double kMinJitterBandwidthHz = 1e-3, kMaxJitterBandwidthHz = 1e3;
//  - times (shocks, speed and scale profiles) within +-1e9 s (31 years), the
//    points of a profile at least 1 ms apart (a slope over less is a step:
//    the speed's rate and the scale's derivatives divide by the spacing).
inline constexpr double kMaxVibrationTimeS = 1e9, kMinProfileSpacingS = 1e-3;
//  - shock pulses of 10 us..10 s (MIL-STD-810H 516.8 pulses are 0.5..100 ms,
//    pyroshock rises in tens of us), returns of 1 ms..1000 s.
inline constexpr double kMinShockDurationS = 1e-5, kMaxShockDurationS = 10.0;
inline constexpr double kMinShockReturnS = 1e-3, kMaxShockReturnS = 1e3;
//  - the lever arm within +-1000 m, as the scene's [imu.mounting] takes it.
inline constexpr double kMaxLeverArmM = 1000.0;

// Throws SettingError (core/setting_error.hpp) for the first setting out of
// its bounds or out of order, its key the field's path in the spec:
// "sinusoid[i].frequency_hz", "random.psd[j]", "random.resolution_hz",
// "rotor[i].speed[j]", "rotor[i].harmonic[j].order", "shock[i].duration_s",
// "random_angular.amplitude_scale[j]", "lever_arm_m", ...; also for more
// random components than Vibration::kMaxComponents (key "random.resolution_hz"
// or "random_angular.resolution_hz"), counted without wrapping.
void validate(const VibrationSpec& spec);

// Bins per axis of a random profile from first_hz to last_hz:
// ceil((last - first) / resolution), as a double (never wraps).
double random_bins(double first_hz, double last_hz, double resolution_hz);

// th, d and their derivatives at one instant, body axes.
struct VibrationState {
  Vec3 theta = Vec3::Zero(), theta_dot = Vec3::Zero(), theta_ddot = Vec3::Zero();
  Vec3 d = Vec3::Zero(), d_dot = Vec3::Zero(), d_ddot = Vec3::Zero();
};

// Random components evaluated: advanced by one rotation on the internal grid
// (a complex product), or by a sine and a cosine (an instant off the grid,
// a resynchronisation every kResyncSteps steps, a start or a gap).
struct VibrationWork {
  std::uint64_t rotations = 0, direct = 0;
};

// A rotor's shaft: angle, speed and its derivatives at one instant.
struct ShaftState {
  double angle_rad = 0.0, speed_rad_s = 0.0, accel_rad_s2 = 0.0, jerk_rad_s3 = 0.0;
};

// One-sided PSD table value at f (log-log interpolation; 0 outside the table).
double psd_at(const std::vector<PsdPoint>& psd, double f_hz);

class Vibration {
 public:
  // Throws SettingError (validate()). device: the noise stream's name.
  Vibration(const VibrationSpec& spec, const std::string& device);
  // t_s: seconds since the start of the run. Not thread-safe (the random
  // part keeps its phasors between calls): one Vibration per device chain.
  VibrationState at(double t_s) const;
  // The internal sample period: a call one period after the previous grid
  // instant advances the random components' phasors by one rotation each
  // (a complex product) instead of a sine and a cosine; re-synchronised
  // exactly every kResyncSteps steps, and by any call off that sequence.
  void set_grid_step(double step_s);
  static constexpr int kResyncSteps = 4096;
  // The kinematics of the vibrating sensor on top of the smoothed ones.
  Kinematics apply(const Kinematics& base, const Vec3& base_angular_acceleration_rad_s2, double t_s) const;
  std::size_t random_components() const { return comps_.size(); }
  // The random components evaluated so far (issue 26, N9: what the CPU
  // estimate counts; daemon/scene/scene_check.hpp).
  const VibrationWork& work() const { return work_; }
  // Rotor r's shaft at t_s (for the tests and check-config).
  ShaftState shaft(std::size_t r, double t_s) const;

  static constexpr int kJitterComponents = 16;

  static constexpr std::size_t kMaxComponents = 200'000;

 private:
  struct Component {
    double w_rad_s, amplitude_m_s2, phase_rad;  // amplitude: m/s^2, or rad/s^2 when angular
    int axis;
    bool angular;
    double amplitude_over_w, amplitude_over_w2;  // velocity and displacement amplitudes
  };
  // e^{i phase} of every random component at t_s: the cache (valid at
  // t_cached_s) advanced by the per-step rotation e^{i w step}, or evaluated.
  const std::vector<std::complex<double>>& random_phasors(double t_s) const;
  // Adds one random profile's components (its PSD table times unit_si^2 is
  // in SI units squared per Hz); validate() has checked it.
  void add_random(const std::vector<PsdPoint>& psd, double unit_si, const Vec3& axis_scale, double resolution_hz,
                  std::uint64_t seed, std::uint64_t device_hash, unsigned stream, bool angular);
  struct JitterComponent {
    double w_rad_s, amplitude_rad_s, phase_rad;
  };
  struct RotorState {
    std::vector<double> angle_at_point_rad;  // Phi at each profile point (without jitter)
    std::vector<JitterComponent> jitter;
  };
  VibrationSpec spec_;
  std::vector<Component> comps_;
  std::vector<RotorState> rotors_;
  // Per shock, per unit peak: the pulse's end velocity and displacement and
  // the return's coefficients c1, c2.
  struct ShockState {
    double v_end, d_end, c1, c2;
  };
  std::vector<ShockState> shocks_;
  void add_shock(double t, VibrationState& v) const;
  double step_s_ = 0.0;
  std::vector<std::complex<double>> rotation_;
  mutable std::vector<std::complex<double>> phasor_;
  mutable std::vector<std::complex<double>> off_grid_;  // an instant between grid instants
  mutable VibrationWork work_;
  mutable bool cached_ = false;
  mutable double t_cached_s_ = 0.0;
  mutable int steps_since_exact_ = 0;
};

// The interval's motion with the vibration on top; positions (for the ecef
// gravitation integral only) stay the base's: the vibration's displacement,
// micrometres to millimetres, moves gravity by less than 1e-8 m/s^2.
class VibratingInterval final : public IntervalMotion {
 public:
  VibratingInterval(const IntervalMotion& base, const Vibration& vibration, double t0_s, double h_s)
      : base_(base), vibration_(vibration), t0_s_(t0_s), h_s_(h_s) {}
  Kinematics at(double s) const override;
  Vec3 position_at(double s) const override { return base_.position_at(s); }

 private:
  const IntervalMotion& base_;
  const Vibration& vibration_;
  double t0_s_, h_s_;
};

}  // namespace imuemu::signal_chain
