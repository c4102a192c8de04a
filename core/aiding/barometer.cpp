// The barometer error model; see barometer.hpp.
#include "core/aiding/barometer.hpp"

#include <cmath>
#include <stdexcept>

#include "core/aiding/sample_index.hpp"
#include "core/setting_error.hpp"

namespace imuemu::aiding {

namespace {

constexpr unsigned kSensorBarometer = 16;  // beside the IMU's gyro 0 / accel 1
constexpr double kSecondsPerJulianYear = 365.25 * 86400.0;

}  // namespace

void validate(const BarometerSpec& s) {
  const char* noise_why = "10 hPa RMS; the noisiest MEMS barometer setting (MS5611 OSR 256) is 6.5 Pa";
  require_within("noise_rms_pa", "barometer noise", s.noise_rms_pa, {0.0, kBaroMaxNoisePa, "Pa", noise_why});
  require_within("noise_density_pa_rt_hz", "barometer noise density", s.noise_density_pa_rt_hz,
                 {0.0, kBaroMaxNoisePa, "Pa/sqrt(Hz)", noise_why});
  const char* offset_why = "100 hPa; datasheets give +-1 hPa absolute accuracy";
  require_within("bias_pa", "barometer bias", s.bias_pa, {-kBaroMaxOffsetPa, kBaroMaxOffsetPa, "Pa", offset_why});
  require_within("bias_sigma_pa", "barometer bias sigma", s.bias_sigma_pa, {0.0, kBaroMaxOffsetPa, "Pa", offset_why});
  require_within("gauss_markov_sigma_pa", "barometer Gauss-Markov sigma", s.gauss_markov_sigma_pa,
                 {0.0, kBaroMaxOffsetPa, "Pa", offset_why});
  require_within("gauss_markov_tau_s", "barometer Gauss-Markov tau", s.gauss_markov_tau_s,
                 {sensor::kMinTauS, sensor::kMaxTauS, "s", "as the IMU's Gauss-Markov tau"});
  require_within("drift_pa_per_year", "barometer drift", s.drift_pa_per_year,
                 {-kBaroMaxDriftPaPerYear, kBaroMaxDriftPaPerYear, "Pa/year", "BMP280: +-100 Pa per 12 months"});
  require_within("lag_s", "barometer lag", s.lag_s, {0.0, kBaroMaxLagS, "s", "0 for none"});
  require_within("temperature_lag_s", "barometer temperature lag", s.temperature_lag_s,
                 {0.0, kBaroMaxLagS, "s", "0 for none"});
  require_within("resolution_pa", "barometer resolution", s.resolution_pa,
                 {0.0, kBaroMaxNoisePa, "Pa", "0 for none; BMP388: 0.016 Pa"});
  require_within("range_min_pa", "barometer range minimum", s.range_min_pa,
                 {0.0, kBaroMaxPressurePa, "Pa", "BMP280: 30000 Pa"});
  require_within("range_max_pa", "barometer range maximum", s.range_max_pa,
                 {0.0, kBaroMaxPressurePa, "Pa", "0 for none; BMP280: 110000 Pa"});
  if (s.range_max_pa != 0.0 && !(s.range_min_pa < s.range_max_pa))
    throw SettingError("range_min_pa", "barometer range minimum " + setting_number(s.range_min_pa) +
                                           " Pa is not below the maximum " + setting_number(s.range_max_pa) + " Pa");
  require_within("temperature_noise_rms_k", "barometer temperature noise", s.temperature_noise_rms_k,
                 {0.0, kBaroMaxTemperatureErrorK, "K", "datasheets: 0.005 K"});
  require_within("temperature_bias_k", "barometer temperature bias", s.temperature_bias_k,
                 {-kBaroMaxTemperatureErrorK, kBaroMaxTemperatureErrorK, "K", "datasheets: +-1 K"});
}

Barometer::Barometer(const BarometerSpec& spec, double rate_hz, const std::string& device) : spec_(spec) {
  validate(spec);
  require_within("rate_hz", "barometer rate", rate_hz, {1e-9, kBaroMaxRateHz, "Hz", "positive, at most 1 MHz"});
  rate_hz_ = rate_hz;
  dt_s_ = 1.0 / rate_hz;
  sigma_pa_ = std::sqrt(spec.noise_rms_pa * spec.noise_rms_pa +
                        spec.noise_density_pa_rt_hz * spec.noise_density_pa_rt_hz * rate_hz);
  const std::uint64_t dev = sensor::device_hash(device);
  white_.state = sensor::stream_key(spec.seed, dev, kSensorBarometer, 0, sensor::kTermWhite, 0);
  temperature_white_.state = sensor::stream_key(spec.seed, dev, kSensorBarometer, 1, sensor::kTermWhite, 0);
  gm_.state = sensor::stream_key(spec.seed, dev, kSensorBarometer, 0, sensor::kTermGaussMarkov, 0);
  sensor::Stream turn_on{sensor::stream_key(spec.seed, dev, kSensorBarometer, 0, sensor::kTermTurnOn, 0)};
  turn_on_pa_ = spec.bias_pa + spec.bias_sigma_pa * turn_on.gaussian();
  lag_phi_ = spec.lag_s > 0.0 ? std::exp(-dt_s_ / spec.lag_s) : 0.0;
  temperature_lag_phi_ = spec.temperature_lag_s > 0.0 ? std::exp(-dt_s_ / spec.temperature_lag_s) : 0.0;
  if (spec.gauss_markov_sigma_pa > 0.0) {
    gm_phi_ = std::exp(-dt_s_ / spec.gauss_markov_tau_s);
    gm_drive_ = spec.gauss_markov_sigma_pa * std::sqrt(1.0 - gm_phi_ * gm_phi_);
    gm_state_ = spec.gauss_markov_sigma_pa * gm_.gaussian();  // stationary start
  }
}

BarometerSample Barometer::step(std::uint64_t k, double p_pa, double t_k) noexcept {
  if (k == 0) {
    lag_state_pa_ = p_pa;
    lag_state_k_ = t_k;
  } else {
    lag_state_pa_ = lag_phi_ * lag_state_pa_ + (1.0 - lag_phi_) * p_pa;
    lag_state_k_ = temperature_lag_phi_ * lag_state_k_ + (1.0 - temperature_lag_phi_) * t_k;
    if (spec_.gauss_markov_sigma_pa > 0.0) gm_state_ = gm_phi_ * gm_state_ + gm_drive_ * gm_.gaussian();
  }
  BarometerSample out;
  const double t_s = static_cast<double>(k) * dt_s_;
  double p = lag_state_pa_ + turn_on_pa_ + spec_.drift_pa_per_year * (t_s / kSecondsPerJulianYear) + gm_state_;
  if (sigma_pa_ > 0.0) p += sigma_pa_ * white_.gaussian();
  // Quantise, then clip: the converter's extreme codes are the range's
  // ends. A sensor reads no negative absolute pressure (reachable only with
  // offsets above the ISA's 0.37 Pa at its top), nor one beyond the bounds.
  if (spec_.resolution_pa > 0.0) p = std::round(p / spec_.resolution_pa) * spec_.resolution_pa;
  double lo = 0.0, hi = kBaroMaxPressurePa + kBaroMaxOffsetPa * 2.0 + kBaroMaxDriftPaPerYear;
  if (spec_.range_max_pa != 0.0) {
    lo = spec_.range_min_pa;
    hi = spec_.range_max_pa;
  }
  if (p <= lo || p >= hi) {
    out.clipped = spec_.range_max_pa != 0.0;
    p = p <= lo ? lo : hi;
  }
  out.pressure_pa = p;
  double t = lag_state_k_ + spec_.temperature_bias_k;
  if (spec_.temperature_noise_rms_k > 0.0) t += spec_.temperature_noise_rms_k * temperature_white_.gaussian();
  out.temperature_k = t > 0.0 ? t : 0.0;
  return out;
}

BarometerSample Barometer::measure(std::uint64_t k, double true_pressure_pa, double true_temperature_k) {
  check_sample_index("barometer", k, next_k_);
  require_within("pressure_pa", "true pressure", true_pressure_pa,
                 {0.0, kBaroMaxPressurePa, "Pa", "absolute pressure up to 2 bar"});
  require_within("temperature_k", "true temperature", true_temperature_k,
                 {1e-3, kBaroMaxTemperatureK, "K", "above absolute zero"});
  // Drift time t = k dt is a double: exact for k below 2^53.
  while (next_k_ < k) step(next_k_++, true_pressure_pa, true_temperature_k);
  ++next_k_;
  return step(k, true_pressure_pa, true_temperature_k);
}

}  // namespace imuemu::aiding
