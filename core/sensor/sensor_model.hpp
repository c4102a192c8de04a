// The sensor model: what a real IMU adds to the ideal angular rate and
// specific force (issue 15). Pure maths, deterministic, no I/O; sits between
// the physics (core/imu_model.hpp) and the encoders (drivers/protocol.hpp):
//   ideal (omega_ib^b, f^b) --SensorModel::measure--> measured values + flags.
//
// Conventions (docs/sensor-models.md):
//  * White noise is given as a ONE-SIDED power spectral density N (the
//    square root of it: rad/s/sqrt(Hz), m/s^2/sqrt(Hz)). At the rate fs the
//    model runs at, each sample carries independent Gaussian noise of
//        sigma = N * sqrt(fs)
//    (the Allan deviation of that sequence is N / sqrt(tau), IEEE Std 952
//    Annex C, whatever fs is). Angle / velocity random walk in deg/sqrt(h)
//    and m/s/sqrt(h) are the same N: 1 deg/sqrt(h) = (pi/180)/60 rad/s/sqrt(Hz).
//  * Rate / acceleration random walk K: the bias steps by K * sqrt(dt) each
//    sample (variance grows as K^2 t; Allan deviation K * sqrt(tau / 3)).
//  * Bias instability B (flicker, 1/f): a sum of first-order Gauss-Markov
//    processes, two per decade (ratio rho = sqrt(10)), correlation times
//    from tau_min / 10^1.5 to tau_max * 10, each of variance
//    B^2 ln(rho) / pi, the two end ones times rho / (rho - 1) (the sum of
//    the geometric tail of processes beyond each end, whose Allan variance
//    has that end's shape), each scaled by 2T(1 - phi)/(dt(1 + phi)),
//    phi = e^(-dt/T), so that its white-noise equivalent in discrete time is
//    the continuous 2 T sigma^2 (matters only for T of a few dt), started at
//    0 (the in-run change from the turn-on bias). Its Allan deviation is
//    0.664 B (= B sqrt(2 ln 2 / pi)) within -0.07 % / +0.01 % over
//    [tau_min, tau_max] (-0.3 % at tau_max over a record of 20 tau_max, from
//    the zero start); derivation in docs/sensor-models.md.
//  * Gauss-Markov bias: exact discretisation phi = exp(-dt/tau),
//    x[k+1] = phi x[k] + sigma sqrt(1 - phi^2) w[k], started stationary.
//    A slow process (tau >= kHoldRatio * dt, the flicker's and most bias
//    processes) is stepped exactly over M = floor(tau / (kHoldRatio dt))
//    samples and held between steps: exact at every step, its Allan curve
//    unchanged (the hold moves less than sqrt(2/kHoldRatio) sigma), at 1/M
//    of the cost (docs/sensor-models.md).
//
// The model runs at the sample interval it is constructed with (not baked to
// an output rate): the signal chain of the next issue runs it at an internal
// rate above the output rate before anti-alias filtering and decimation.
//
// Randomness: every (seed, device, sensor, axis, term, sub-process) has its
// own SplitMix64 stream (Steele, Lea, Flood, "Fast splittable pseudorandom
// number generators", OOPSLA 2014) keyed by a hash of those, so adding a term
// or a device leaves the other streams' noise unchanged. Gaussians by the
// ziggurat method (Marsaglia & Tsang, J. Stat. Softw. 5(8), 2000, with
// Doornik's 2005 double-precision layout): bit-reproducible for one binary.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "core/types.hpp"

namespace imuemu::sensor {

// One triad (gyro or accelerometer), SI units: rad/s for the gyro, m/s^2 for
// the accelerometer ("unit" below). Per-axis values are Vec3 (x, y, z of the
// sensor's axes). Zero means "term off".
struct TriadSpec {
  Vec3 white_density = Vec3::Zero();      // N: unit/sqrt(Hz), one-sided PSD
  Vec3 bias_instability = Vec3::Zero();   // B: unit (Allan floor 0.664 B)
  double flicker_tau_min_s = 1.0;         // Allan deviation flat at 0.664 B over [tau_min, tau_max]
  double flicker_tau_max_s = 1000.0;
  Vec3 random_walk = Vec3::Zero();        // K: unit/sqrt(s) (RRW / acceleration random walk)
  Vec3 ramp = Vec3::Zero();               // R: unit/s (rate ramp)
  Vec3 gauss_markov_sigma = Vec3::Zero(); // stationary sigma, unit
  Vec3 gauss_markov_tau_s = Vec3::Constant(100.0);
  Vec3 turn_on_bias = Vec3::Zero();       // fixed part, unit
  Vec3 turn_on_bias_sigma = Vec3::Zero(); // drawn once per run from N(0, sigma^2), unit
  Vec3 scale_factor = Vec3::Zero();       // dimensionless (1e-6 per ppm)
  Vec3 scale_factor_asymmetry = Vec3::Zero();  // dimensionless: +a/2 for positive input, -a/2 negative
  Vec3 nonlinearity = Vec3::Zero();       // dimensionless fraction of full scale at full scale (needs range)
  Vec3 misalignment_rad = Vec3::Zero();   // small rotation of the triad against the body axes
  Vec3 non_orthogonality_rad = Vec3::Zero();  // (y toward x, z toward x, z toward y)
  Mat3 g_sensitivity = Mat3::Zero();      // gyro only: rad/s per m/s^2 of specific force
  Vec3 bias_temperature_coeff = Vec3::Zero();  // unit per kelvin about the reference temperature
  Vec3 scale_factor_temperature_coeff = Vec3::Zero();  // 1/K
  double lsb = 0.0;                       // quantisation step, unit; 0: none
  double range = 0.0;                     // saturation at +-range (unit); 0: none
};

// T(t) = end - (end - start) exp(-t / warmup_tau) (constant when tau = 0 or start = end).
struct TemperatureSpec {
  double reference_c = 25.0;  // the temperature the datasheet biases refer to
  double start_c = 25.0;
  double end_c = 25.0;
  double warmup_tau_s = 0.0;
  double at(double t_s) const;
};

struct SensorModelSpec {
  TriadSpec gyro, accel;
  TemperatureSpec temperature;
  std::uint64_t seed = 0;
  bool is_ideal() const;  // no term on: callers skip the stage entirely
};

// Bounds of the terms (issue 26, N12: a bias instability of 1e308 deg/s or a
// temperature of 1e308 degC made every output non-finite, then zero; a noise
// density of 1e308 was accepted). Each is far beyond any datasheet, so it
// refuses only what no part is, and within them every term the model
// computes is finite (docs/sensor-models.md "Bounds"). Per triad, SI:
struct TriadBounds {
  // The widest full scale of any part: ADXRS649 +-20,000 deg/s (349 rad/s),
  // H3LIS331DL +-400 g. Range, turn-on bias and its sigma stay within it.
  double full_scale;
  // White noise density: ~300x the noisiest consumer MEMS (gyro ~0.03
  // deg/s/sqrt(Hz), MPU-6050 accel 400 ug/sqrt(Hz); the ICM-42688-P has
  // 2.8 mdps/sqrt(Hz), 70 ug/sqrt(Hz)): 10 deg/s/sqrt(Hz), 100 mg/sqrt(Hz).
  double white_density;
  // Bias instability, Gauss-Markov sigma and random walk (per sqrt(s)):
  // within the widest full scale (a bias process beyond it reads nothing
  // but saturation; a consumer MEMS's in-run stability is ~1e-5 of it).
  double bias;
  // Rate ramp: 1 deg/s per s, 10 mg per s.
  double ramp;
  // Bias temperature coefficient: 1 deg/s per K, 10 mg per K (MEMS: ~0.01
  // deg/s/K, ~0.15 mg/K).
  double bias_temperature_coeff;
};
inline constexpr TriadBounds kGyroBounds{20000.0 * 3.14159265358979323846 / 180.0, 10.0 * 3.14159265358979323846 / 180.0,
                                         20000.0 * 3.14159265358979323846 / 180.0, 3.14159265358979323846 / 180.0,
                                         3.14159265358979323846 / 180.0};
inline constexpr TriadBounds kAccelBounds{400.0 * 9.80665, 0.1 * 9.80665, 400.0 * 9.80665, 0.01 * 9.80665, 0.01 * 9.80665};
// Dimensionless terms: scale factor in (-1, 1] and its asymmetry and the
// nonlinearity within +-1 (100 %; MEMS: 0.5..3 %); scale factor temperature
// coefficient within +-1e-2 per K (MEMS: 100..300 ppm/K); misalignment and
// non-orthogonality within +-0.1 rad (5.7 deg; datasheets give +-1 deg, and
// the first-order model of the axes holds for small angles only); the
// gyro's g-sensitivity within +-0.1 rad/s per m/s^2 (56 deg/s/g; MEMS: 0.005..0.1 deg/s/g).
inline constexpr double kMaxScaleFactor = 1.0, kMaxScaleFactorTemperatureCoeff = 1e-2, kMaxMisalignmentRad = 0.1,
                        kMaxGSensitivity = 0.1;
// Time constants: flicker range and Gauss-Markov tau in [1e-3, 1e8] s (Allan
// floors lie at 1..1e5 s; the HG9900 preset's reaches 1e5 s).
inline constexpr double kMinTauS = 1e-3, kMaxTauS = 1e8;
// Quantisation step: at least 1e-12 unit, so y / lsb stays below 2^53 (the
// rounding exact) for any value within full_scale.
inline constexpr double kMinLsb = 1e-12;
// Temperatures: above absolute zero and below 300 degC (solder reflow peaks
// at 260 degC, J-STD-020; parts operate within -40..+125 degC).
inline constexpr double kMinTemperatureC = -273.15, kMaxTemperatureC = 300.0;

// Throws std::invalid_argument naming the field for a spec the model refuses
// (a term outside its bounds above, negative sigma, tau_min >= tau_max, a
// flicker range of more than kMaxFlickerDecades decades, nonlinearity
// without a range, non-finite values, lsb > range).
void validate(const SensorModelSpec& spec);
// One term of one triad against its bounds (term as core/sensor/datasheet.hpp
// names them: "white noise", "bias instability", "flicker tau min", ...,
// "saturation"; an unknown term is not checked): the check validate() makes,
// so a parser can report it at the key that set the term. Throws
// SettingError (core/setting_error.hpp), key "gyro.<term>" or "accel.<term>".
void validate_term(const TriadSpec& spec, bool gyro, const std::string& term);
// The temperature profile against its bounds (what validate() checks).
void validate_temperature(const TemperatureSpec& spec);

// Flicker: kFlickerPerDecade processes per decade over the range plus
// kFlickerBelow below tau_min and kFlickerAbove above tau_max.
inline constexpr int kFlickerPerDecade = 2, kFlickerBelow = 3, kFlickerAbove = 2;
inline constexpr int kMaxFlickerDecades = 9;
inline constexpr int kMaxFlickerProcesses = kFlickerPerDecade * kMaxFlickerDecades + kFlickerBelow + kFlickerAbove + 1;
// A Gauss-Markov process is stepped at most every tau / kHoldRatio.
inline constexpr double kHoldRatio = 64.0;
// Samples between steps of a process of correlation time tau at interval dt.
std::uint32_t hold_period(double tau_s, double dt_s);

// Per-axis saturation flags of Measurement::saturated_axes.
enum SaturatedAxis : std::uint8_t {
  kGyroX = 1u << 0, kGyroY = 1u << 1, kGyroZ = 1u << 2,
  kAccelX = 1u << 3, kAccelY = 1u << 4, kAccelZ = 1u << 5,
};

struct Measurement {
  Vec3 gyro_rad_s = Vec3::Zero();
  Vec3 accel_m_s2 = Vec3::Zero();
  std::uint8_t saturated_axes = 0;  // SaturatedAxis bits
  double temperature_c = 25.0;
};

// SplitMix64: one 64-bit state per stream.
struct Stream {
  std::uint64_t state = 0;
  std::uint64_t next() noexcept;
  double gaussian() noexcept;  // N(0, 1), ziggurat
  double uniform() noexcept;   // [0, 1), 53 bits
};

// The `term` of a stream key: which random process of a sensor axis draws
// from the stream. One list for every model (the IMU's, and the barometer,
// magnetometer and GNSS of core/aiding); never renumber: it would change the
// noise every seed gives.
enum NoiseTerm : unsigned {
  kTermWhite = 1,
  kTermFlicker = 2,
  kTermWalk = 3,
  kTermGaussMarkov = 4,
  kTermTurnOn = 5,
  kTermVelocity = 6,  // GNSS velocity noise
};

// The key of one noise stream: a hash of everything that names it.
std::uint64_t stream_key(std::uint64_t seed, std::uint64_t device_hash, unsigned sensor, unsigned axis,
                         unsigned term, unsigned sub) noexcept;
// FNV-1a of a device name (the [[imu]] name), for stream_key.
std::uint64_t device_hash(const std::string& name) noexcept;

// Flicker decomposition for one axis at the sample interval dt_s:
// correlation times and each process' stationary sigma (docs/sensor-models.md).
struct FlickerProcesses {
  int count = 0;
  std::array<double, kMaxFlickerProcesses> tau_s{};
  std::array<double, kMaxFlickerProcesses> sigma{};
};
FlickerProcesses flicker_processes(double bias_instability, double tau_min_s, double tau_max_s, double dt_s);

class SensorModel {
 public:
  // sample_rate_hz: the rate measure() is called at (sample k at t = k / fs
  // since the start of the run). device: the device's name (its own noise).
  // Throws std::invalid_argument (validate, rate not positive/finite).
  SensorModel(const SensorModelSpec& spec, double sample_rate_hz, const std::string& device);

  // Sample k (k never decreases; indices skipped since the last call are
  // simulated, so sample k is the same whichever samples were asked for).
  // Throws std::invalid_argument for a k below the next expected one.
  Measurement measure(std::uint64_t k, const Vec3& gyro_rad_s, const Vec3& accel_m_s2);

  double sample_rate_hz() const { return rate_hz_; }
  std::uint64_t next_index() const { return next_k_; }
  // Turn-on bias drawn for this run (fixed + random part), per triad.
  const Vec3& gyro_turn_on_bias() const { return gyro_.turn_on; }
  const Vec3& accel_turn_on_bias() const { return accel_.turn_on; }

 private:
  struct Axis {
    bool white = false, flicker = false, walk = false, gm = false;
    double white_sigma = 0.0;
    Stream white_stream;
    int flicker_count = 0;
    // Processes [0, flicker_every) step every sample; the held ones are
    // visited only when the nearest of their steps is due: flicker_wait
    // samples from now, flicker_span after the last visit.
    int flicker_every = 0;
    std::uint32_t flicker_wait = 0, flicker_span = 0;
    std::array<double, kMaxFlickerProcesses> flicker_phi{}, flicker_drive{}, flicker_state{};
    std::array<std::uint32_t, kMaxFlickerProcesses> flicker_period{}, flicker_countdown{};
    std::array<Stream, kMaxFlickerProcesses> flicker_stream{};
    double walk_step = 0.0, walk_state = 0.0;
    Stream walk_stream;
    double gm_phi = 0.0, gm_drive = 0.0, gm_state = 0.0;
    std::uint32_t gm_period = 1, gm_countdown = 1;
    Stream gm_stream;
  };
  struct Triad {
    TriadSpec spec;
    std::array<Axis, 3> axis;
    bool stochastic = false, deterministic_matrix = false, g_sens = false, scale = false, nonlinear = false;
    Mat3 axes = Mat3::Identity();  // body -> sensor axes (misalignment, non-orthogonality)
    Vec3 turn_on = Vec3::Zero();
    Vec3 nonlinear_k2 = Vec3::Zero();  // unit^-1
    double saturation = 0.0;           // largest multiple of lsb within range (or range)
  };
  void init_triad(Triad& tr, const TriadSpec& spec, unsigned sensor, std::uint64_t dev);
  static void advance(Triad& tr) noexcept;              // one step of the stochastic states
  static Vec3 stochastic_bias(const Triad& tr) noexcept;  // sum of the states at the current step
  Vec3 white(Triad& tr) noexcept;
  Vec3 finish(const Triad& tr, const Vec3& in_axes, const Vec3& bias, double dT, double t_s, unsigned sat_shift,
              std::uint8_t& sat) const noexcept;

  SensorModelSpec spec_;
  double rate_hz_ = 0.0, dt_s_ = 0.0;
  std::uint64_t next_k_ = 0;
  bool temperature_varies_ = false, temperature_terms_ = false;
  Triad gyro_, accel_;
};

// What a term becomes at a given rate: one line per term and triad, for
// `imuemu sensors`, check-config and generate.
struct TermReport {
  std::string sensor;   // gyro | accel
  std::string term;     // white, bias instability, ...
  std::string value;    // as configured, SI
  std::string discrete; // per sample at the rate (sigma, phi, ...)
};
std::vector<TermReport> describe(const SensorModelSpec& spec, double sample_rate_hz);

}  // namespace imuemu::sensor
