// The sensor model (core/sensor/sensor_model.hpp).
#include "core/sensor/sensor_model.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <sstream>
#include <stdexcept>

#include "core/setting_error.hpp"

namespace imuemu::sensor {
namespace {

// ---- SplitMix64 (Steele, Lea, Flood 2014): state += gamma, then the mix.
constexpr std::uint64_t kGamma = 0x9E3779B97F4A7C15ULL;
constexpr std::uint64_t mix64(std::uint64_t z) noexcept {
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
  return z ^ (z >> 31);
}

// ---- Ziggurat for N(0,1): Marsaglia & Tsang (2000) with 256 layers; the
// double-precision tables and tests of Doornik, "An improved ziggurat method
// to generate normal random samples" (2005). Tables computed once from r and
// v (the paper's constants for C = 256), with the same binary's exp/log, so
// reproducible run to run.
constexpr int kLayers = 256;
constexpr double kZigR = 3.6541528853610088;
constexpr double kZigV = 0.00492867323399;

struct ZigguratTables {
  std::array<double, kLayers + 1> x{};
  std::array<double, kLayers> ratio{};
  ZigguratTables() {
    double f = std::exp(-0.5 * kZigR * kZigR);
    x[0] = kZigV / f;  // the base layer with the tail: V / f(R)
    x[1] = kZigR;
    x[kLayers] = 0.0;
    for (int i = 2; i < kLayers; ++i) {
      x[i] = std::sqrt(-2.0 * std::log(kZigV / x[i - 1] + f));
      f = std::exp(-0.5 * x[i] * x[i]);
    }
    for (int i = 0; i < kLayers; ++i) ratio[i] = x[i + 1] / x[i];
  }
};
const ZigguratTables& zig() {
  static const ZigguratTables t;
  return t;
}

constexpr double kDegToRad = std::numbers::pi / 180.0;

std::string fmt(double v) {
  std::ostringstream s;
  s.precision(6);
  s << v;
  return s.str();
}
std::string fmt3(const Vec3& v) {
  if (v.x() == v.y() && v.y() == v.z()) return fmt(v.x());
  std::string out = "[";
  out += fmt(v.x());
  out += ", ";
  out += fmt(v.y());
  out += ", ";
  out += fmt(v.z());
  out += "]";
  return out;
}


void validate_triad(const TriadSpec& s, bool gyro) {
  const std::string who = gyro ? "gyro" : "accel";
  auto need = [&](bool ok, const std::string& field, const std::string& what) {
    if (!ok) throw std::invalid_argument(who + "." + field + ": " + what);
  };
  for (const char* term : {"white noise", "bias instability", "flicker tau min", "flicker tau max", "random walk", "ramp",
                           "Gauss-Markov sigma", "Gauss-Markov tau", "turn-on bias", "turn-on bias sigma",
                           "scale factor", "scale factor asymmetry", "nonlinearity", "misalignment",
                           "non-orthogonality", "g-sensitivity", "bias temperature coefficient",
                           "scale factor temperature coefficient", "quantisation", "saturation"})
    validate_term(s, gyro, term);
  need(s.range == 0.0 || s.lsb <= s.range, "lsb", "is larger than the range");
  need(s.nonlinearity.isZero() || s.range > 0.0, "nonlinearity", "is a fraction of full scale: needs a range");
  if (!s.bias_instability.isZero()) {
    need(s.flicker_tau_min_s < s.flicker_tau_max_s, "bias instability tau range", "expected 0 < tau_min < tau_max");
    need(std::log10(s.flicker_tau_max_s / s.flicker_tau_min_s) <= kMaxFlickerDecades + 1e-9, "bias instability tau range",
         "spans more than " + std::to_string(kMaxFlickerDecades) + " decades");
  }
}

}  // namespace

double TemperatureSpec::at(double t_s) const {
  if (warmup_tau_s <= 0.0 || start_c == end_c) return end_c;
  return end_c - (end_c - start_c) * std::exp(-t_s / warmup_tau_s);
}

bool SensorModelSpec::is_ideal() const {
  const SensorModelSpec ideal;
  auto same = [](const TriadSpec& a, const TriadSpec& b) {
    return a.white_density == b.white_density && a.bias_instability == b.bias_instability &&
           a.random_walk == b.random_walk && a.ramp == b.ramp && a.gauss_markov_sigma == b.gauss_markov_sigma &&
           a.turn_on_bias == b.turn_on_bias && a.turn_on_bias_sigma == b.turn_on_bias_sigma &&
           a.scale_factor == b.scale_factor && a.scale_factor_asymmetry == b.scale_factor_asymmetry &&
           a.nonlinearity == b.nonlinearity && a.misalignment_rad == b.misalignment_rad &&
           a.non_orthogonality_rad == b.non_orthogonality_rad && a.g_sensitivity == b.g_sensitivity &&
           a.bias_temperature_coeff == b.bias_temperature_coeff &&
           a.scale_factor_temperature_coeff == b.scale_factor_temperature_coeff && a.lsb == b.lsb &&
           a.range == b.range;
  };
  return same(gyro, ideal.gyro) && same(accel, ideal.accel);
}

void validate_term(const TriadSpec& s, bool gyro, const std::string& term) {
  const TriadBounds& b = gyro ? kGyroBounds : kAccelBounds;
  const std::string key = std::string(gyro ? "gyro." : "accel.") + term;
  const char* unit = gyro ? "rad/s" : "m/s^2";
  // One bound per term: [0, hi] (a sigma or density) or |x| <= hi (signed).
  auto at_most = [&](const Vec3& v, double hi, const char* u, const char* why) {
    require_within(key, key, v, {0.0, hi, u, why});
  };
  auto signed_within = [&](const Vec3& v, double hi, const char* u, const char* why) {
    require_magnitude(key, key, v, {0.0, hi, u, why});
  };
  const char* full_scale_why = gyro ? "the widest gyro, ADXRS649, reads +-20,000 deg/s"
                                    : "the widest accelerometer, H3LIS331DL, reads +-400 g";
  const char* bias_why = gyro ? "within the widest gyro's full scale, +-20,000 deg/s"
                              : "within the widest accelerometer's full scale, +-400 g";
  if (term == "white noise") {
    at_most(s.white_density, b.white_density, gyro ? "rad/s/sqrt(Hz)" : "m/s^2/sqrt(Hz)",
            gyro ? "10 deg/s/sqrt(Hz): ~300x the noisiest consumer MEMS gyro"
                 : "100 mg/sqrt(Hz): ~300x the noisiest consumer MEMS accelerometer");
  } else if (term == "bias instability" || term == "Gauss-Markov sigma") {
    at_most(term == "bias instability" ? s.bias_instability : s.gauss_markov_sigma, b.bias, unit, bias_why);
  } else if (term == "random walk") {
    at_most(s.random_walk, b.bias, gyro ? "rad/s/sqrt(s)" : "m/s^2/sqrt(s)", bias_why);
  } else if (term == "ramp") {
    signed_within(s.ramp, b.ramp, gyro ? "rad/s^2" : "m/s^3", gyro ? "1 deg/s per s" : "10 mg per s");
  } else if (term == "flicker tau min" || term == "flicker tau max") {
    require_within(key, key, term == "flicker tau min" ? s.flicker_tau_min_s : s.flicker_tau_max_s,
                   {kMinTauS, kMaxTauS, "s", "Allan floors lie at 1..1e5 s"});
  } else if (term == "Gauss-Markov tau") {
    require_within(key, key, s.gauss_markov_tau_s, {kMinTauS, kMaxTauS, "s", "a bias process' correlation time"});
  } else if (term == "turn-on bias") {
    signed_within(s.turn_on_bias, b.full_scale, unit, full_scale_why);
  } else if (term == "turn-on bias sigma") {
    at_most(s.turn_on_bias_sigma, b.full_scale, unit, full_scale_why);
  } else if (term == "scale factor") {
    signed_within(s.scale_factor, kMaxScaleFactor, "", "+-100 %; MEMS parts: 0.5..3 %");
    if (!(s.scale_factor.array() > -1.0).all()) throw SettingError(key, key + ": must stay above -100 %");
  } else if (term == "scale factor asymmetry" || term == "nonlinearity") {
    signed_within(term == "nonlinearity" ? s.nonlinearity : s.scale_factor_asymmetry, kMaxScaleFactor, "",
                  "+-100 %");
  } else if (term == "misalignment" || term == "non-orthogonality") {
    signed_within(term == "misalignment" ? s.misalignment_rad : s.non_orthogonality_rad, kMaxMisalignmentRad, "rad",
                  "5.7 deg: datasheets give +-1 deg, and the model is first order in the angles");
  } else if (term == "g-sensitivity") {
    for (int r = 0; r < 3; ++r)
      signed_within(s.g_sensitivity.row(r).transpose(), kMaxGSensitivity, "rad/s per m/s^2",
                    "56 deg/s/g; MEMS gyros: 0.005..0.1 deg/s/g");
  } else if (term == "bias temperature coefficient") {
    signed_within(s.bias_temperature_coeff, b.bias_temperature_coeff, gyro ? "rad/s/K" : "m/s^2/K",
                  gyro ? "1 deg/s per K; MEMS: ~0.01" : "10 mg per K; MEMS: ~0.15 mg");
  } else if (term == "scale factor temperature coefficient") {
    signed_within(s.scale_factor_temperature_coeff, kMaxScaleFactorTemperatureCoeff, "1/K",
                  "10,000 ppm/K; MEMS: 100..300 ppm/K");
  } else if (term == "quantisation" || term == "saturation") {
    const double v = term == "quantisation" ? s.lsb : s.range;
    if (v != 0.0)
      require_within(key, key, v, {kMinLsb, b.full_scale, unit,
                                   term == "quantisation" ? "0 for none; from 1e-12 (the rounding stays exact) to the widest full scale"
                                                          : full_scale_why});
  }
}

void validate_temperature(const TemperatureSpec& t) {
  const SettingBound degrees{kMinTemperatureC, kMaxTemperatureC, "degC",
                             "above absolute zero, below solder reflow's 260 degC peak (J-STD-020)"};
  require_within("temperature.reference_c", "temperature: reference_c", t.reference_c, degrees);
  require_within("temperature.start_c", "temperature: start_c", t.start_c, degrees);
  require_within("temperature.end_c", "temperature: end_c", t.end_c, degrees);
  require_within("temperature.warmup_tau_s", "temperature: warmup_tau_s", t.warmup_tau_s,
                 {0.0, kMaxTauS, "s", "0 for a constant temperature"});
}

void validate(const SensorModelSpec& spec) {
  validate_triad(spec.gyro, true);
  validate_triad(spec.accel, false);
  if (!spec.accel.g_sensitivity.isZero()) throw std::invalid_argument("accel.g sensitivity: applies to the gyro only");
  validate_temperature(spec.temperature);
}

std::uint64_t Stream::next() noexcept { return mix64(state += kGamma); }

double Stream::uniform() noexcept { return static_cast<double>(next() >> 11) * 0x1.0p-53; }

double Stream::gaussian() noexcept {
  const ZigguratTables& t = zig();
  for (;;) {
    const std::uint64_t bits = next();
    const int i = static_cast<int>(bits & 0xFF);
    // u in (-1, 1) from the top 53 bits (independent of the layer bits).
    const double u = 2.0 * (static_cast<double>(bits >> 11) + 0.5) * 0x1.0p-53 - 1.0;
    if (std::abs(u) < t.ratio[i]) return u * t.x[i];  // inside the layer's rectangle
    if (i == 0) {  // the tail beyond R (Marsaglia 1964)
      double x = 0.0, y = 0.0;
      do {
        x = std::log(1.0 - uniform()) / kZigR;
        y = std::log(1.0 - uniform());
      } while (-2.0 * y < x * x);
      return u < 0.0 ? x - kZigR : kZigR - x;
    }
    const double x = u * t.x[i];
    const double f0 = std::exp(-0.5 * (t.x[i] * t.x[i] - x * x));
    const double f1 = std::exp(-0.5 * (t.x[i + 1] * t.x[i + 1] - x * x));
    if (f1 + uniform() * (f0 - f1) < 1.0) return x;
  }
}

std::uint64_t stream_key(std::uint64_t seed, std::uint64_t device_hash_value, unsigned sensor, unsigned axis,
                         unsigned term, unsigned sub) noexcept {
  std::uint64_t h = mix64(seed ^ 0x5EED5EED5EED5EEDULL);
  h = mix64(h ^ device_hash_value);
  h = mix64(h ^ ((static_cast<std::uint64_t>(sensor) << 48) | (static_cast<std::uint64_t>(axis) << 32) |
                 (static_cast<std::uint64_t>(term) << 16) | sub));
  return h;
}

std::uint64_t device_hash(const std::string& name) noexcept {
  std::uint64_t h = 0xCBF29CE484222325ULL;  // FNV-1a 64
  for (unsigned char c : name) {
    h ^= c;
    h *= 0x100000001B3ULL;
  }
  return h;
}

FlickerProcesses flicker_processes(double bias_instability, double tau_min_s, double tau_max_s, double dt_s) {
  FlickerProcesses p;
  if (!(bias_instability > 0.0)) return p;
  // The Allan variance of one Gauss-Markov process of variance s^2 and
  // correlation time T is s^2 g(tau/T), g(x) = (2/x^2)(x - 3/2 + 2e^-x -
  // e^-2x/2). Over T_j = T_0 rho^j (every j) with equal variances the sum is
  // periodic in log tau with mean s^2 (1/ln rho) Int_0^inf g(x) dx/x =
  // s^2 2 ln 2 / ln rho, the flicker floor (2 ln 2 / pi) B^2 for s^2 =
  // B^2 ln rho / pi; at rho = sqrt(10) its ripple is below 0.003 %
  // (docs/sensor-models.md). The sum is cut kFlickerBelow processes below
  // tau_min and kFlickerAbove above tau_max. The processes beyond the cut
  // would add, where tau is far from them, 2 T_j s^2 / tau each below
  // (white) and 2 tau s^2 / (3 T_j) each above (random walk): geometric
  // series in T_j, whose sums are 1/(rho - 1) times the end process' own
  // share, so the end processes carry rho / (rho - 1) times the variance.
  constexpr double kRho = 3.1622776601683795;  // 10^(1/kFlickerPerDecade)
  static_assert(kFlickerPerDecade == 2);
  const int steps = static_cast<int>(std::ceil(kFlickerPerDecade * std::log10(tau_max_s / tau_min_s) - 1e-9));
  p.count = std::min(steps + kFlickerBelow + kFlickerAbove + 1, kMaxFlickerProcesses);
  const double variance = bias_instability * bias_instability * std::log(kRho) / std::numbers::pi;
  for (int j = 0; j < p.count; ++j) {
    const double tau = tau_min_s * std::pow(kRho, j - kFlickerBelow);
    double v = variance;
    if (j == 0 || j == p.count - 1) v *= kRho / (kRho - 1.0);
    // In discrete time a process whose T is a few dt or less is white noise
    // of density^2 s^2 (1 + phi)/(1 - phi) dt (phi = e^(-dt/T)), against the
    // 2 T s^2 of the continuous process the floor is derived from: scale its
    // variance by the ratio (1 - O((dt/T)^2) for T >> dt).
    const double phi = std::exp(-dt_s / tau);
    v *= 2.0 * tau * -std::expm1(-dt_s / tau) / (dt_s * (1.0 + phi));
    p.tau_s[static_cast<std::size_t>(j)] = tau;
    p.sigma[static_cast<std::size_t>(j)] = std::sqrt(v);
  }
  return p;
}

std::uint32_t hold_period(double tau_s, double dt_s) {
  const double m = std::floor(tau_s / (kHoldRatio * dt_s));
  if (!(m >= 1.0)) return 1;
  return m > 1e6 ? 1'000'000u : static_cast<std::uint32_t>(m);
}


SensorModel::SensorModel(const SensorModelSpec& spec, double sample_rate_hz, const std::string& device)
    : spec_(spec), rate_hz_(sample_rate_hz) {
  if (!std::isfinite(sample_rate_hz) || sample_rate_hz <= 0.0)
    throw std::invalid_argument("sensor model: sample rate must be finite and > 0 Hz");
  validate(spec);
  dt_s_ = 1.0 / rate_hz_;
  const std::uint64_t dev = device_hash(device);
  init_triad(gyro_, spec.gyro, 0, dev);
  init_triad(accel_, spec.accel, 1, dev);
  const TemperatureSpec& t = spec.temperature;
  temperature_varies_ = t.warmup_tau_s > 0.0 && t.start_c != t.end_c;
  temperature_terms_ = !spec.gyro.bias_temperature_coeff.isZero() || !spec.gyro.scale_factor_temperature_coeff.isZero() ||
                       !spec.accel.bias_temperature_coeff.isZero() ||
                       !spec.accel.scale_factor_temperature_coeff.isZero();
}

void SensorModel::init_triad(Triad& tr, const TriadSpec& s, unsigned sensor, std::uint64_t dev) {
  tr.spec = s;
  const std::uint64_t seed = spec_.seed;
  const FlickerProcesses fp[3] = {flicker_processes(s.bias_instability.x(), s.flicker_tau_min_s, s.flicker_tau_max_s, dt_s_),
                                  flicker_processes(s.bias_instability.y(), s.flicker_tau_min_s, s.flicker_tau_max_s, dt_s_),
                                  flicker_processes(s.bias_instability.z(), s.flicker_tau_min_s, s.flicker_tau_max_s, dt_s_)};
  for (unsigned a = 0; a < 3; ++a) {
    Axis& ax = tr.axis[a];
    ax.white = s.white_density[a] > 0.0;
    ax.white_sigma = s.white_density[a] * std::sqrt(rate_hz_);  // sigma = N sqrt(fs), one-sided PSD
    ax.white_stream.state = stream_key(seed, dev, sensor, a, kTermWhite, 0);
    ax.flicker = fp[a].count > 0;
    ax.flicker_count = fp[a].count;
    for (int j = 0; j < fp[a].count; ++j) {
      const std::uint32_t period = hold_period(fp[a].tau_s[j], dt_s_);
      const double step_s = period * dt_s_;
      ax.flicker_period[j] = ax.flicker_countdown[j] = period;
      ax.flicker_phi[j] = std::exp(-step_s / fp[a].tau_s[j]);
      ax.flicker_drive[j] = fp[a].sigma[static_cast<std::size_t>(j)] * std::sqrt(-std::expm1(-2.0 * step_s / fp[a].tau_s[j]));  // sigma sqrt(1 - phi^2)
      ax.flicker_stream[j].state = stream_key(seed, dev, sensor, a, kTermFlicker, static_cast<unsigned>(j));
      // Starts at 0: the bias at switch-on is the turn-on bias; the flicker
      // is the in-run change from it (a stationary start would add a random
      // offset of about 2 B, counting the run-to-run bias twice). The Allan
      // variance does not see the difference: it is blind to offsets.
      ax.flicker_state[j] = 0.0;
    }
    // hold_period grows with tau and the processes are in increasing tau.
    ax.flicker_every = 0;
    while (ax.flicker_every < ax.flicker_count && ax.flicker_period[ax.flicker_every] == 1) ++ax.flicker_every;
    ax.flicker_span = ax.flicker_every < ax.flicker_count ? ax.flicker_period[ax.flicker_every] : 0;
    ax.flicker_wait = ax.flicker_span;
    ax.walk = s.random_walk[a] > 0.0;
    ax.walk_step = s.random_walk[a] * std::sqrt(dt_s_);
    ax.walk_stream.state = stream_key(seed, dev, sensor, a, kTermWalk, 0);
    ax.gm = s.gauss_markov_sigma[a] > 0.0;
    ax.gm_period = ax.gm_countdown = hold_period(s.gauss_markov_tau_s[a], dt_s_);
    const double gm_step_s = ax.gm_period * dt_s_;
    ax.gm_phi = std::exp(-gm_step_s / s.gauss_markov_tau_s[a]);
    ax.gm_drive = s.gauss_markov_sigma[a] * std::sqrt(-std::expm1(-2.0 * gm_step_s / s.gauss_markov_tau_s[a]));
    ax.gm_stream.state = stream_key(seed, dev, sensor, a, kTermGaussMarkov, 0);
    if (ax.gm) ax.gm_state = s.gauss_markov_sigma[a] * ax.gm_stream.gaussian();
    Stream turn_on{stream_key(seed, dev, sensor, a, kTermTurnOn, 0)};
    tr.turn_on[a] = s.turn_on_bias[a] + (s.turn_on_bias_sigma[a] > 0.0 ? s.turn_on_bias_sigma[a] * turn_on.gaussian() : 0.0);
    tr.stochastic = tr.stochastic || ax.flicker || ax.walk || ax.gm;
  }
  // Body -> sensor axes, first order in the small angles: a rotation by the
  // misalignment m (R = I - [m]x maps body vectors into the tilted triad) and
  // the non-orthogonality of the sensor axes (each axis leans toward the
  // previous ones: lower triangle).
  const Vec3& m = s.misalignment_rad;
  Mat3 rot;
  rot << 1.0, m.z(), -m.y(), -m.z(), 1.0, m.x(), m.y(), -m.x(), 1.0;
  Mat3 skew = Mat3::Identity();
  skew(1, 0) = s.non_orthogonality_rad.x();
  skew(2, 0) = s.non_orthogonality_rad.y();
  skew(2, 1) = s.non_orthogonality_rad.z();
  tr.axes = skew * rot;
  tr.deterministic_matrix = !m.isZero() || !s.non_orthogonality_rad.isZero();
  tr.g_sens = !s.g_sensitivity.isZero();
  tr.scale = !s.scale_factor.isZero() || !s.scale_factor_asymmetry.isZero() || !s.scale_factor_temperature_coeff.isZero();
  tr.nonlinear = !s.nonlinearity.isZero();
  if (tr.nonlinear) tr.nonlinear_k2 = s.nonlinearity / s.range;  // k2 x^2 = nl * range at x = range
  tr.saturation = s.range;
  if (s.range > 0.0 && s.lsb > 0.0) {
    // A range that is a whole number of LSBs (every preset) saturates at the
    // range itself; otherwise at the largest multiple of the LSB within it.
    const double codes = s.range / s.lsb;
    if (std::abs(codes - std::nearbyint(codes)) > 1e-9 * codes) tr.saturation = std::floor(codes) * s.lsb;
  }
}

void SensorModel::advance(Triad& tr) noexcept {
  for (Axis& ax : tr.axis) {
    if (ax.flicker) {
      for (int j = 0; j < ax.flicker_every; ++j)
        ax.flicker_state[j] = ax.flicker_phi[j] * ax.flicker_state[j] + ax.flicker_drive[j] * ax.flicker_stream[j].gaussian();
      if (ax.flicker_span > 0 && --ax.flicker_wait == 0) {
        // flicker_span samples since the last visit: every held countdown
        // moves by that much; those at 0 take their exact step over
        // flicker_period samples (held between), and the nearest next step
        // sets the next visit.
        std::uint32_t next = ~std::uint32_t{0};
        for (int j = ax.flicker_every; j < ax.flicker_count; ++j) {
          ax.flicker_countdown[j] -= ax.flicker_span;
          if (ax.flicker_countdown[j] == 0) {
            ax.flicker_countdown[j] = ax.flicker_period[j];
            ax.flicker_state[j] = ax.flicker_phi[j] * ax.flicker_state[j] + ax.flicker_drive[j] * ax.flicker_stream[j].gaussian();
          }
          next = std::min(next, ax.flicker_countdown[j]);
        }
        ax.flicker_span = ax.flicker_wait = next;
      }
    }
    if (ax.walk) ax.walk_state += ax.walk_step * ax.walk_stream.gaussian();
    if (ax.gm && --ax.gm_countdown == 0) {
      ax.gm_countdown = ax.gm_period;
      ax.gm_state = ax.gm_phi * ax.gm_state + ax.gm_drive * ax.gm_stream.gaussian();
    }
  }
}

Vec3 SensorModel::stochastic_bias(const Triad& tr) noexcept {
  Vec3 b = Vec3::Zero();
  for (int a = 0; a < 3; ++a) {
    const Axis& ax = tr.axis[a];
    double s = 0.0;
    for (int j = 0; j < ax.flicker_count; ++j) s += ax.flicker_state[j];
    b[a] = s + ax.walk_state + ax.gm_state;
  }
  return b;
}

Vec3 SensorModel::white(Triad& tr) noexcept {
  Vec3 w = Vec3::Zero();
  for (int a = 0; a < 3; ++a)
    if (tr.axis[a].white) w[a] = tr.axis[a].white_sigma * tr.axis[a].white_stream.gaussian();
  return w;
}

Vec3 SensorModel::finish(const Triad& tr, const Vec3& in_axes, const Vec3& bias, double dT, double t_s,
                         unsigned sat_shift, std::uint8_t& sat) const noexcept {
  const TriadSpec& s = tr.spec;
  Vec3 y = in_axes;
  if (tr.scale) {
    for (int a = 0; a < 3; ++a) {
      const double asym = in_axes[a] >= 0.0 ? 0.5 * s.scale_factor_asymmetry[a] : -0.5 * s.scale_factor_asymmetry[a];
      y[a] = (1.0 + s.scale_factor[a] + asym + s.scale_factor_temperature_coeff[a] * dT) * in_axes[a];
    }
  }
  if (tr.nonlinear) y += (tr.nonlinear_k2.array() * in_axes.array().square()).matrix();
  y += bias + tr.turn_on + s.ramp * t_s + s.bias_temperature_coeff * dT;
  for (int a = 0; a < 3; ++a) {
    if (!std::isfinite(y[a])) {
      // Every term is bounded (validate), so only a non-finite input gets
      // here: never NaN/Inf downstream, and never a silent 0 (issue 26, N5:
      // a level unit read 0 g with status 0): 0 with the axis flagged.
      sat = static_cast<std::uint8_t>(sat | (1u << (sat_shift + static_cast<unsigned>(a))));
      y[a] = 0.0;
      continue;
    }
    if (tr.saturation > 0.0 && std::abs(y[a]) > tr.saturation) {
      // Beyond the range: exactly the largest value the sensor can report
      // (the range, or its largest multiple of the LSB), flagged.
      sat = static_cast<std::uint8_t>(sat | (1u << (sat_shift + static_cast<unsigned>(a))));
      y[a] = std::copysign(tr.saturation, y[a]);
      continue;
    }
    if (s.lsb > 0.0) {
      y[a] = std::nearbyint(y[a] / s.lsb) * s.lsb;
      if (tr.saturation > 0.0 && std::abs(y[a]) > tr.saturation) y[a] = std::copysign(tr.saturation, y[a]);  // rounding at the top code
    }
  }
  return y;
}

Measurement SensorModel::measure(std::uint64_t k, const Vec3& gyro_rad_s, const Vec3& accel_m_s2) {
  if (k < next_k_)
    throw std::invalid_argument("sensor model: sample " + std::to_string(k) + " after sample " +
                                std::to_string(next_k_ - 1) + " (indices must not decrease)");
  // Skipped indices: the stochastic states and the white streams step as if
  // those samples had been measured, so sample k does not depend on which
  // samples were asked for.
  while (next_k_ < k) {
    (void)white(gyro_);
    (void)white(accel_);
    advance(gyro_);
    advance(accel_);
    ++next_k_;
  }
  const double t_s = static_cast<double>(k) * dt_s_;
  Measurement m;
  m.temperature_c = temperature_varies_ ? spec_.temperature.at(t_s) : spec_.temperature.at(0.0);
  const double dT = temperature_terms_ ? m.temperature_c - spec_.temperature.reference_c : 0.0;

  Vec3 g_axes = gyro_.deterministic_matrix ? Vec3(gyro_.axes * gyro_rad_s) : gyro_rad_s;
  Vec3 f_axes = accel_.deterministic_matrix ? Vec3(accel_.axes * accel_m_s2) : accel_m_s2;
  Vec3 g_bias = white(gyro_);
  Vec3 a_bias = white(accel_);
  if (gyro_.stochastic) g_bias += stochastic_bias(gyro_);
  if (accel_.stochastic) a_bias += stochastic_bias(accel_);
  if (gyro_.g_sens) g_bias += gyro_.spec.g_sensitivity * accel_m_s2;
  m.gyro_rad_s = finish(gyro_, g_axes, g_bias, dT, t_s, 0, m.saturated_axes);
  m.accel_m_s2 = finish(accel_, f_axes, a_bias, dT, t_s, 3, m.saturated_axes);
  advance(gyro_);
  advance(accel_);
  ++next_k_;
  return m;
}

std::vector<TermReport> describe(const SensorModelSpec& spec, double fs) {
  std::vector<TermReport> out;
  const double dt = 1.0 / fs;
  for (int which = 0; which < 2; ++which) {
    const TriadSpec& s = which == 0 ? spec.gyro : spec.accel;
    const std::string name = which == 0 ? "gyro" : "accel";
    const std::string u = which == 0 ? "rad/s" : "m/s^2";
    auto add = [&](const std::string& term, const std::string& value, const std::string& discrete) {
      out.push_back({name, term, value, discrete});
    };
    if (!s.white_density.isZero())
      add("white noise", "N = " + fmt3(s.white_density) + " " + u + "/sqrt(Hz) (IEEE 952 N)",
          "sigma = N sqrt(fs) = " + fmt3(s.white_density * std::sqrt(fs)) + " " + u + " per sample");
    if (!s.bias_instability.isZero()) {
      const FlickerProcesses p = flicker_processes(1.0, s.flicker_tau_min_s, s.flicker_tau_max_s, dt);
      std::string taus, sigmas;
      for (int j = 0; j < p.count; ++j) {
        if (j > 0) taus += ", ", sigmas += ", ";
        taus += fmt(p.tau_s[static_cast<std::size_t>(j)]);
        sigmas += fmt(p.sigma[static_cast<std::size_t>(j)]);
      }
      add("bias instability", "B = " + fmt3(s.bias_instability) + " " + u + ", Allan floor 0.664 B over [" +
                                  fmt(s.flicker_tau_min_s) + ", " + fmt(s.flicker_tau_max_s) + "] s",
          std::to_string(p.count) + " Gauss-Markov processes (two per decade), tau = {" + taus +
              "} s, sigma = B x {" + sigmas + "}");
    }
    if (!s.random_walk.isZero())
      add("random walk", "K = " + fmt3(s.random_walk) + " " + u + "/sqrt(s)",
          "step sigma = K sqrt(dt) = " + fmt3(s.random_walk * std::sqrt(dt)) + " " + u);
    if (!s.ramp.isZero()) add("ramp", "R = " + fmt3(s.ramp) + " " + u + "/s", "per sample " + fmt3(s.ramp * dt) + " " + u);
    if (!s.gauss_markov_sigma.isZero()) {
      Vec3 phi, drive;
      for (int a = 0; a < 3; ++a) {
        phi[a] = std::exp(-dt / s.gauss_markov_tau_s[a]);
        drive[a] = s.gauss_markov_sigma[a] * std::sqrt(-std::expm1(-2.0 * dt / s.gauss_markov_tau_s[a]));
      }
      Vec3 period;
      for (int a = 0; a < 3; ++a) period[a] = hold_period(s.gauss_markov_tau_s[a], dt);
      add("Gauss-Markov bias", "sigma = " + fmt3(s.gauss_markov_sigma) + " " + u + ", tau = " + fmt3(s.gauss_markov_tau_s) + " s",
          "per sample phi = " + fmt3(phi) + ", drive sigma = " + fmt3(drive) + " " + u + " (stepped exactly every " +
              fmt3(period) + " samples)");
    }
    if (!s.turn_on_bias.isZero() || !s.turn_on_bias_sigma.isZero())
      add("turn-on bias", "fixed " + fmt3(s.turn_on_bias) + " " + u + ", sigma " + fmt3(s.turn_on_bias_sigma) + " " + u,
          "drawn once per run");
    if (!s.scale_factor.isZero() || !s.scale_factor_asymmetry.isZero())
      add("scale factor", fmt3(s.scale_factor * 1e6) + " ppm, asymmetry " + fmt3(s.scale_factor_asymmetry * 1e6) + " ppm", "");
    if (!s.nonlinearity.isZero()) add("nonlinearity", fmt3(s.nonlinearity * 1e6) + " ppm of full scale", "quadratic");
    if (!s.misalignment_rad.isZero() || !s.non_orthogonality_rad.isZero())
      add("misalignment", fmt3(s.misalignment_rad * 1e3) + " mrad, non-orthogonality " +
                              fmt3(s.non_orthogonality_rad * 1e3) + " mrad", "");
    if (!s.g_sensitivity.isZero())
      add("g-sensitivity", "max |G| = " + fmt(s.g_sensitivity.cwiseAbs().maxCoeff() / kDegToRad * 3600.0 * 9.80665) + " deg/h/g", "");
    if (!s.bias_temperature_coeff.isZero() || !s.scale_factor_temperature_coeff.isZero())
      add("temperature", "bias " + fmt3(s.bias_temperature_coeff) + " " + u + "/K, scale factor " +
                             fmt3(s.scale_factor_temperature_coeff * 1e6) + " ppm/K", "");
    if (s.lsb > 0.0) add("quantisation", "LSB = " + fmt(s.lsb) + " " + u, "uniform error sigma = LSB/sqrt(12) = " + fmt(s.lsb / std::sqrt(12.0)));
    if (s.range > 0.0) add("saturation", "+-" + fmt(s.range) + " " + u, "");
  }
  return out;
}

}  // namespace imuemu::sensor
