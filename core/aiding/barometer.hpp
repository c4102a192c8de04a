// The barometer: what a pressure sensor reads given the true static
// pressure and air temperature (issue 28). Pure maths, seeded, no I/O; the
// true values come from the standard atmosphere (core/aiding/atmosphere.hpp)
// at the trajectory's height.
//
// Terms, in the units pressure-sensor datasheets state (Bosch BMP280/BMP388,
// TE MS5611, Infineon DPS310):
//  * noise_rms_pa: per-sample RMS noise at the output rate, as datasheets
//    quote it for an oversampling setting (MS5611 OSR 4096: 1.2 Pa; BMP388
//    "ultra high resolution": 0.9 Pa... 0.03 Pa with the IIR filter on).
//  * noise_density_pa_rt_hz: the same as a one-sided PSD N (Pa/sqrt(Hz)),
//    the IMU's convention (core/sensor/sensor_model.hpp): per-sample sigma
//    = N sqrt(fs). Both may be given; their variances add.
//  * bias_pa: fixed offset ("absolute accuracy"), bias_sigma_pa: a turn-on
//    offset drawn once per run from N(0, sigma^2).
//  * drift_pa_per_year: linear drift ("long-term stability", BMP280: +-100
//    Pa per 12 months), a Julian year of 365.25 d.
//  * gauss_markov_sigma_pa / _tau_s: a first-order Gauss-Markov offset
//    (the slowly wandering bias an EKF's baro-bias state models), exact
//    discretisation phi = exp(-dt/tau), started stationary.
//  * lag_s: first-order lag of the pressure (port, filter, IIR setting):
//    y' = (u - y) / tau, discretised exactly with the input held over each
//    sample interval (t_{k-1}, t_k]: y[k] = phi y[k-1] + (1 - phi) u[k],
//    phi = exp(-dt/tau); so a step of the input at sample k0 reads
//    y[k0 + n] = u1 - (u1 - u0) exp(-(n + 1) dt / tau), the continuous step
//    response of a step at t_{k0-1}. Starts settled (y[0] = u[0]).
//  * resolution_pa: quantisation step; range_min_pa / range_max_pa:
//    the operating range (BMP280 30000..110000 Pa), clipped; 0/0: none.
//  * temperature_noise_rms_k, temperature_bias_k, temperature_lag_s: the
//    same for the die-temperature output (lag: the package's thermal time
//    constant).
// The order: lag (the physics) -> + offsets and noise -> quantise -> clip.
// Every random term has its own stream keyed by (seed, device, sensor 16,
// axis, term), as the IMU's (core/sensor/sensor_model.hpp), so the same seed
// gives the same bits.
#pragma once

#include <cstdint>
#include <string>

#include "core/sensor/sensor_model.hpp"

namespace imuemu::aiding {

struct BarometerSpec {
  double noise_rms_pa = 0.0;
  double noise_density_pa_rt_hz = 0.0;
  double bias_pa = 0.0;
  double bias_sigma_pa = 0.0;
  double drift_pa_per_year = 0.0;
  double gauss_markov_sigma_pa = 0.0;
  double gauss_markov_tau_s = 100.0;
  double lag_s = 0.0;
  double resolution_pa = 0.0;
  double range_min_pa = 0.0;
  double range_max_pa = 0.0;
  double temperature_noise_rms_k = 0.0;
  double temperature_bias_k = 0.0;
  double temperature_lag_s = 0.0;
  std::uint64_t seed = 0;
};

// Bounds (SI), each far beyond any datasheet; within them every output is finite.
inline constexpr double kBaroMaxNoisePa = 1000.0;       // 10 hPa RMS (MS5611 at OSR 256: 6.5 Pa)
inline constexpr double kBaroMaxOffsetPa = 10000.0;     // 100 hPa (datasheets: +-100 Pa absolute)
inline constexpr double kBaroMaxDriftPaPerYear = 1e5;   // 1000 hPa/year
inline constexpr double kBaroMaxPressurePa = 200000.0;  // 2 bar: above any sensor's range
inline constexpr double kBaroMaxLagS = 1e4;
inline constexpr double kBaroMaxTemperatureK = 1000.0;
inline constexpr double kBaroMaxTemperatureErrorK = 100.0;
inline constexpr double kBaroMaxRateHz = 1e6;

// Throws SettingError (key: the field's name) for a spec outside the bounds.
void validate(const BarometerSpec& spec);

struct BarometerSample {
  double pressure_pa = 0.0;
  double temperature_k = 0.0;
  bool clipped = false;  // the pressure hit the range
};

class Barometer {
 public:
  // Sample k at t = k / rate since the start of the run. Throws as validate,
  // and for a rate outside (0, 1 MHz].
  Barometer(const BarometerSpec& spec, double rate_hz, const std::string& device);

  // Sample k (k >= next_index(); skipped samples are simulated with the
  // given input held, so the noise of sample k does not depend on which
  // samples were asked for). Throws std::invalid_argument for a k below
  // next_index() or more than 2^28 after it (sample_index.hpp), or a true
  // value outside [0, 2e5] Pa / (0, 1000] K or NaN; a refused call changes
  // nothing.
  BarometerSample measure(std::uint64_t k, double true_pressure_pa, double true_temperature_k);

  std::uint64_t next_index() const { return next_k_; }
  double turn_on_bias_pa() const { return turn_on_pa_; }

 private:
  BarometerSample step(std::uint64_t k, double p_pa, double t_k) noexcept;

  BarometerSpec spec_;
  double rate_hz_ = 0.0, dt_s_ = 0.0;
  double sigma_pa_ = 0.0, turn_on_pa_ = 0.0;
  double lag_phi_ = 0.0, temperature_lag_phi_ = 0.0;
  double gm_phi_ = 0.0, gm_drive_ = 0.0, gm_state_ = 0.0;
  double lag_state_pa_ = 0.0, lag_state_k_ = 0.0;
  std::uint64_t next_k_ = 0;
  sensor::Stream white_, gm_, temperature_white_;
};

}  // namespace imuemu::aiding
