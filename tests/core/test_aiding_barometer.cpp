// The standard atmosphere and the barometer (core/aiding/, issue 28) against
// independent truth: the published tables of the U.S. Standard Atmosphere
// 1976 (NOAA-S/T 76-1562; Table 4 base pressures by geopotential altitude,
// Table I by geometric altitude, printed to 5 significant digits), which
// ICAO Doc 7488/3 equals below 32 km; the closed-form step response of a
// first-order lag; sampling statistics with tolerances from their sampling
// distributions.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <vector>

#include "core/aiding/atmosphere.hpp"
#include "core/aiding/barometer.hpp"
#include "core/setting_error.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace imuemu::aiding {}
namespace unity_core_test_aiding_barometer {
namespace imuemu { using namespace ::imuemu; }
namespace imuemu::aiding { using namespace ::imuemu::aiding; }

namespace imuemu::aiding {
namespace {

// Half a unit of the last printed digit of a value printed with `digits`
// significant digits: how far the exact value can lie from the table's.
double half_ulp_of_print(double printed, int digits) {
  const double exponent = std::floor(std::log10(std::abs(printed)));
  return 0.5 * std::pow(10.0, exponent - (digits - 1));
}

TEST(IsaAtmosphere, LayerBasesMatchUsStandardAtmosphere1976Table4) {
  // US 1976 Table 4: H_b (m'), T_M,b (K), P_b (Pa) as printed.
  struct Row { double h_m, t_k, p_pa; int digits; };
  const Row rows[] = {{0.0, 288.15, 101325.0, 6},     {11000.0, 216.65, 22632.06, 7},
                      {20000.0, 216.65, 5474.889, 7}, {32000.0, 228.65, 868.0187, 7},
                      {47000.0, 270.65, 110.9063, 7}, {51000.0, 270.65, 66.93887, 7},
                      {71000.0, 214.65, 3.956420, 7}};
  for (const Row& r : rows) {
    const IsaState s = isa_at_geopotential(r.h_m);
    EXPECT_NEAR(s.temperature_k, r.t_k, 1e-9) << r.h_m;
    // The table is computed with these constants; 7 digits plus one unit
    // for the table's own rounding chain.
    EXPECT_NEAR(s.pressure_pa, r.p_pa, 2.0 * half_ulp_of_print(r.p_pa, r.digits)) << r.h_m;
  }
  EXPECT_NEAR(isa_at_geopotential(0.0).density_kg_m3, 1.225, 0.0005);  // Table I: 1.2250 kg/m3
}

TEST(IsaAtmosphere, GeometricAltitudesMatchUsStandardAtmosphere1976TableI) {
  // US 1976 Table I (geometric altitude Z): T (K) to 3 decimals, P (Pa) to 5 digits.
  struct Row { double z_m, t_k, p_pa; };
  const Row rows[] = {{-1000.0, 294.651, 1.1393e5}, {0.0, 288.150, 1.01325e5}, {1000.0, 281.651, 8.9876e4},
                      {5000.0, 255.676, 5.4048e4},  {10000.0, 223.252, 2.6500e4}, {11000.0, 216.774, 2.2700e4},
                      {20000.0, 216.650, 5.5293e3}, {30000.0, 226.509, 1.1970e3}};
  for (const Row& r : rows) {
    const IsaState s = isa_at_geopotential(geopotential_from_geometric_m(r.z_m));
    EXPECT_NEAR(s.temperature_k, r.t_k, 0.0005 + 1e-9) << r.z_m;
    EXPECT_NEAR(s.pressure_pa, r.p_pa, half_ulp_of_print(r.p_pa, 5) + 1e-9) << r.z_m;
  }
  // ICAO Doc 7488 tabulates by geopotential altitude: 1000 m -> 898.746 hPa, 281.65 K.
  EXPECT_NEAR(isa_at_geopotential(1000.0).pressure_pa, 89874.6, 0.05);
  EXPECT_NEAR(isa_at_geopotential(1000.0).temperature_k, 281.65, 1e-9);
}

TEST(IsaAtmosphere, EllipsoidalHeightIsOrthometricThroughTheGeoidUndulation) {
  // h = 1030 m above the ellipsoid where the geoid lies 30 m above it: 1000 m geometric.
  const IsaState a = isa_at_ellipsoidal_height(1030.0, 30.0);
  EXPECT_NEAR(a.pressure_pa, 8.9876e4, half_ulp_of_print(8.9876e4, 5));
  EXPECT_NEAR(geopotential_from_geometric_m(geometric_from_geopotential_m(12345.0)), 12345.0, 1e-8);
}

TEST(IsaAtmosphere, PressureAltitudeInvertsThePressureInEveryLayer) {
  for (double h = -5000.0; h <= 84852.0; h += 250.0)
    EXPECT_NEAR(pressure_altitude_m(isa_at_geopotential(h).pressure_pa), h, 1e-6 * (1.0 + std::abs(h) / 1000.0)) << h;
}

TEST(IsaAtmosphere, RefusesNanAndAltitudesOutsideTheModel) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(isa_at_geopotential(nan), SettingError);
  EXPECT_THROW(isa_at_geopotential(-5001.0), SettingError);
  EXPECT_THROW(isa_at_geopotential(84853.0), SettingError);
  EXPECT_THROW(isa_at_ellipsoidal_height(100.0, nan), SettingError);
  EXPECT_THROW(isa_at_ellipsoidal_height(100.0, 500.0), SettingError);
  EXPECT_THROW(isa_at_ellipsoidal_height(std::numeric_limits<double>::infinity()), SettingError);
  EXPECT_THROW(geopotential_from_geometric_m(-7e6), SettingError);
  EXPECT_THROW(pressure_altitude_m(0.0), SettingError);
  EXPECT_THROW(pressure_altitude_m(nan), SettingError);
}

TEST(Barometer, LagFollowsTheFirstOrderStepResponse) {
  BarometerSpec spec;
  spec.lag_s = 0.5;
  spec.temperature_lag_s = 2.0;
  const double rate_hz = 100.0, dt = 1.0 / rate_hz;
  Barometer baro(spec, rate_hz, "baro");
  const double p0 = 101325.0, p1 = 101205.0;  // a 10-m climb's step
  const double t0 = 288.15, t1 = 278.15;
  const std::uint64_t k0 = 200;
  for (std::uint64_t k = 0; k < k0; ++k) {
    const BarometerSample s = baro.measure(k, p0, t0);
    ASSERT_DOUBLE_EQ(s.pressure_pa, p0);  // settled from the start
  }
  for (std::uint64_t n = 0; n < 500; ++n) {
    const BarometerSample s = baro.measure(k0 + n, p1, t1);
    const double elapsed = static_cast<double>(n + 1) * dt;
    EXPECT_NEAR(s.pressure_pa, p1 + (p0 - p1) * std::exp(-elapsed / 0.5), 1e-8) << n;
    EXPECT_NEAR(s.temperature_k, t1 + (t0 - t1) * std::exp(-elapsed / 2.0), 1e-10) << n;
    // One time constant after the step: 1 - 1/e = 63.2 % of the way.
    if (n + 1 == 50) {
      EXPECT_NEAR((p0 - s.pressure_pa) / (p0 - p1), 1.0 - std::exp(-1.0), 1e-12);
    }
  }
}

TEST(Barometer, NoiseBiasAndDriftHaveTheirDatasheetValues) {
  BarometerSpec spec;
  spec.noise_rms_pa = 1.2;              // MS5611 OSR 4096
  spec.noise_density_pa_rt_hz = 0.1;    // adds 0.1^2 * 50 Pa^2 at 50 Hz
  spec.bias_pa = 25.0;
  spec.drift_pa_per_year = 10.0 * 365.25 * 86400.0 / 4000.0;  // 10 Pa per 4000 s (exaggerated to see it)
  spec.seed = 7;
  const double rate_hz = 50.0;
  Barometer baro(spec, rate_hz, "baro");
  const std::size_t n = 200000;  // 4000 s
  const double sigma2 = 1.2 * 1.2 + 0.01 * rate_hz;
  double sum = 0.0, sum2 = 0.0;
  for (std::size_t k = 0; k < n; ++k) {
    const double t_s = static_cast<double>(k) / rate_hz;
    const double e = baro.measure(k, 90000.0, 280.0).pressure_pa - 90000.0 - 25.0 - 10.0 * t_s / 4000.0;
    sum += e;
    sum2 += e * e;
  }
  const double mean = sum / static_cast<double>(n);
  const double var = sum2 / static_cast<double>(n) - mean * mean;
  EXPECT_NEAR(mean, 0.0, 5.0 * std::sqrt(sigma2 / static_cast<double>(n)));
  EXPECT_NEAR(var, sigma2, 5.0 * sigma2 * std::sqrt(2.0 / static_cast<double>(n)));
}

TEST(Barometer, SameSeedSameBitsAndSkippedSamplesAreSimulated) {
  BarometerSpec spec;
  spec.noise_rms_pa = 2.0;
  spec.bias_sigma_pa = 50.0;
  spec.gauss_markov_sigma_pa = 10.0;
  spec.gauss_markov_tau_s = 30.0;
  spec.lag_s = 0.1;
  spec.temperature_noise_rms_k = 0.01;
  spec.seed = 42;
  Barometer a(spec, 25.0, "baro"), b(spec, 25.0, "baro"), other(spec, 25.0, "baro2");
  for (std::uint64_t k = 0; k < 100; ++k) {
    const BarometerSample x = a.measure(k, 95000.0, 285.0);
    if (k % 10 != 9) continue;
    const BarometerSample y = b.measure(k, 95000.0, 285.0);  // b skips 9 of every 10
    EXPECT_EQ(x.pressure_pa, y.pressure_pa) << k;
    EXPECT_EQ(x.temperature_k, y.temperature_k) << k;
  }
  EXPECT_EQ(a.turn_on_bias_pa(), b.turn_on_bias_pa());
  EXPECT_NE(a.turn_on_bias_pa(), other.turn_on_bias_pa());
}

TEST(Barometer, RangeClipsAndResolutionQuantises) {
  BarometerSpec spec;
  spec.range_min_pa = 30000.0;
  spec.range_max_pa = 110000.0;
  spec.resolution_pa = 0.16;
  Barometer baro(spec, 10.0, "baro");
  EXPECT_NEAR(baro.measure(0, 20000.0, 250.0).pressure_pa, 30000.0, 1e-9);  // 30000 = 187500 x 0.16
  EXPECT_TRUE(baro.measure(1, 20000.0, 250.0).clipped);
  const BarometerSample s = baro.measure(2, 101325.0, 288.15);
  EXPECT_FALSE(s.clipped);
  EXPECT_NEAR(s.pressure_pa, 101325.0, 0.08 + 1e-9);
  EXPECT_NEAR(std::remainder(s.pressure_pa, 0.16), 0.0, 1e-9);
}

TEST(Barometer, RefusesBadSpecsAndInputsAndARefusedCallChangesNothing) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  BarometerSpec bad;
  bad.noise_rms_pa = -1.0;
  EXPECT_THROW(Barometer(bad, 10.0, "b"), SettingError);
  bad = {};
  bad.lag_s = nan;
  EXPECT_THROW(Barometer(bad, 10.0, "b"), SettingError);
  bad = {};
  bad.range_min_pa = 50000.0;
  bad.range_max_pa = 40000.0;
  EXPECT_THROW(Barometer(bad, 10.0, "b"), SettingError);
  EXPECT_THROW(Barometer(BarometerSpec{}, 0.0, "b"), SettingError);
  EXPECT_THROW(Barometer(BarometerSpec{}, nan, "b"), SettingError);

  BarometerSpec spec;
  spec.noise_rms_pa = 1.0;
  spec.seed = 3;
  Barometer a(spec, 10.0, "b"), b(spec, 10.0, "b");
  a.measure(0, 100000.0, 288.0);
  b.measure(0, 100000.0, 288.0);
  EXPECT_THROW(a.measure(1, nan, 288.0), SettingError);
  EXPECT_THROW(a.measure(1, 100000.0, -1.0), SettingError);
  EXPECT_THROW(a.measure(1, -5.0, 288.0), SettingError);
  EXPECT_EQ(a.next_index(), 1u);
  EXPECT_EQ(a.measure(1, 100000.0, 288.0).pressure_pa, b.measure(1, 100000.0, 288.0).pressure_pa);
  EXPECT_THROW(a.measure(0, 100000.0, 288.0), std::invalid_argument);
  EXPECT_THROW(a.measure(std::numeric_limits<std::uint64_t>::max(), 100000.0, 288.0), std::invalid_argument);
  EXPECT_EQ(a.next_index(), 2u);
}

}  // namespace
}  // namespace imuemu::aiding
}  // namespace unity_core_test_aiding_barometer
