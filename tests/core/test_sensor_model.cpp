// The sensor model (core/sensor/) against independent truth: sampling
// statistics with tolerances from their sampling distributions (seeded, so
// deterministic, but several standard errors wide so that they are genuine
// checks rather than tuned to one seed), an overlapping Allan deviation
// written here from IEEE Std 952 Annex C, and exact arithmetic for the
// deterministic terms.
#include <gtest/gtest.h>

#include <cmath>
#include <complex>
#include <numbers>
#include <numeric>
#include <vector>

#include "core/sensor/datasheet.hpp"
#include "core/sensor/sensor_model.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace imuemu::sensor {}
namespace unity_core_test_sensor_model {
namespace imuemu { using namespace ::imuemu; }
namespace imuemu::sensor { using namespace ::imuemu::sensor; }

namespace imuemu::sensor {
namespace {

// Overlapping Allan variance at cluster size m (IEEE Std 952-1997 Annex C,
// Eq. C.5 form via the integrated signal theta_k = sum of y * tau0).
double overlapping_avar(const std::vector<double>& y, double tau0_s, std::size_t m) {
  std::vector<double> theta(y.size() + 1, 0.0);
  for (std::size_t i = 0; i < y.size(); ++i) theta[i + 1] = theta[i] + y[i] * tau0_s;
  const std::size_t n = theta.size();
  if (n <= 2 * m) return std::nan("");
  const double tau = static_cast<double>(m) * tau0_s;
  double sum = 0.0;
  for (std::size_t k = 0; k + 2 * m < n; ++k) {
    const double d = theta[k + 2 * m] - 2.0 * theta[k + m] + theta[k];
    sum += d * d;
  }
  return sum / (2.0 * tau * tau * static_cast<double>(n - 2 * m));
}

double mean(const std::vector<double>& v) { return std::accumulate(v.begin(), v.end(), 0.0) / static_cast<double>(v.size()); }
double variance(const std::vector<double>& v) {
  const double m = mean(v);
  double s = 0.0;
  for (double x : v) s += (x - m) * (x - m);
  return s / static_cast<double>(v.size() - 1);
}
double correlation(const std::vector<double>& a, const std::vector<double>& b) {
  const double ma = mean(a), mb = mean(b);
  double sab = 0.0, saa = 0.0, sbb = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    sab += (a[i] - ma) * (b[i] - mb);
    saa += (a[i] - ma) * (a[i] - ma);
    sbb += (b[i] - mb) * (b[i] - mb);
  }
  return sab / std::sqrt(saa * sbb);
}

// Radix-2 FFT (in place), for the periodogram.
void fft(std::vector<std::complex<double>>& a) {
  const std::size_t n = a.size();
  for (std::size_t i = 1, j = 0; i < n; ++i) {
    std::size_t bit = n >> 1;
    for (; j & bit; bit >>= 1) j ^= bit;
    j ^= bit;
    if (i < j) std::swap(a[i], a[j]);
  }
  for (std::size_t len = 2; len <= n; len <<= 1) {
    const double ang = -2.0 * std::numbers::pi / static_cast<double>(len);
    const std::complex<double> wl(std::cos(ang), std::sin(ang));
    for (std::size_t i = 0; i < n; i += len) {
      std::complex<double> w(1.0);
      for (std::size_t j = 0; j < len / 2; ++j) {
        const std::complex<double> u = a[i + j], v = a[i + j + len / 2] * w;
        a[i + j] = u + v;
        a[i + j + len / 2] = u - v;
        w *= wl;
      }
    }
  }
}

// Gyro x output of a static run (zero input).
std::vector<double> run_axis(const SensorModelSpec& spec, double fs, std::size_t n, const std::string& device = "imu0",
                             int triad = 0, int axis = 0) {
  SensorModel model(spec, fs, device);
  std::vector<double> out(n);
  for (std::size_t k = 0; k < n; ++k) {
    const Measurement m = model.measure(k, Vec3::Zero(), Vec3::Zero());
    out[k] = triad == 0 ? m.gyro_rad_s[axis] : m.accel_m_s2[axis];
  }
  return out;
}

TEST(SensorModel, WhiteNoiseSigmaIsDensityTimesRootRate) {
  SensorModelSpec spec;
  spec.seed = 11;
  spec.gyro.white_density = Vec3::Constant(0.01);  // rad/s/sqrt(Hz)
  const double fs = 400.0;
  const std::size_t n = 200'000;
  const std::vector<double> y = run_axis(spec, fs, n);
  const double expected_var = 0.01 * 0.01 * fs;
  // Sample variance of n Gaussians: relative standard error sqrt(2/n) = 0.32 %; 5 of them.
  EXPECT_NEAR(variance(y) / expected_var, 1.0, 5.0 * std::sqrt(2.0 / static_cast<double>(n)));
  EXPECT_NEAR(mean(y), 0.0, 5.0 * std::sqrt(expected_var / static_cast<double>(n)));
  // Fourth moment of a Gaussian: kurtosis 3 (standard error sqrt(24/n) = 1.1 %).
  double m4 = 0.0;
  for (double v : y) m4 += v * v * v * v;
  m4 /= static_cast<double>(n);
  EXPECT_NEAR(m4 / (expected_var * expected_var), 3.0, 5.0 * std::sqrt(24.0 / static_cast<double>(n)));
}

TEST(SensorModel, WhiteNoisePeriodogramIsFlatAtTheDensity) {
  // Averaged periodogram, two-sided density |X_f|^2 / (L fs): N^2 at every
  // frequency for sigma = N sqrt(fs) (the one-sided density over [0, fs/2] is
  // twice that; docs/sensor-models.md). 8 bands of 32 bins x 390 segments: each
  // band's mean has a relative standard error 1/sqrt(12480) = 0.9 %; 6 %.
  SensorModelSpec spec;
  spec.seed = 12;
  spec.accel.white_density = Vec3::Constant(0.002);
  const double fs = 1000.0;
  const std::size_t len = 512, segments = 390;
  const std::vector<double> y = run_axis(spec, fs, len * segments, "imu0", 1, 2);
  std::vector<double> psd(len / 2, 0.0);
  for (std::size_t s = 0; s < segments; ++s) {
    std::vector<std::complex<double>> a(len);
    for (std::size_t i = 0; i < len; ++i) a[i] = y[s * len + i];
    fft(a);
    for (std::size_t f = 1; f < len / 2; ++f) psd[f] += std::norm(a[f]) / (static_cast<double>(len) * fs);
  }
  const double n2 = 0.002 * 0.002;
  for (std::size_t band = 0; band < 8; ++band) {
    double sum = 0.0;
    std::size_t bins = 0;
    for (std::size_t f = std::max<std::size_t>(1, band * 32); f < (band + 1) * 32; ++f, ++bins) sum += psd[f];
    EXPECT_NEAR(sum / static_cast<double>(bins * segments) / n2, 1.0, 0.06) << "band " << band;
  }
}

TEST(SensorModel, OneDensityGivesOneAllanArwAt100And400And2000Hz) {
  // Allan deviation of white noise at tau = 0.1 s is N / sqrt(0.1) at any rate.
  // 300 s: about 1.5 * 300 / 0.1 = 4500 equivalent degrees of freedom, a
  // relative standard error of 1.1 % in the deviation; 6 %.
  const double density = 0.005;  // rad/s/sqrt(Hz)
  for (double fs : {100.0, 400.0, 2000.0}) {
    SensorModelSpec spec;
    spec.seed = 13;
    spec.gyro.white_density = Vec3::Constant(density);
    const std::vector<double> y = run_axis(spec, fs, static_cast<std::size_t>(300.0 * fs));
    const auto m = static_cast<std::size_t>(std::lround(0.1 * fs));
    const double adev = std::sqrt(overlapping_avar(y, 1.0 / fs, m));
    EXPECT_NEAR(adev / (density / std::sqrt(0.1)), 1.0, 0.06) << fs << " Hz";
  }
}

TEST(SensorModel, GaussMarkovAutocorrelationIsPhiToTheLag) {
  SensorModelSpec spec;
  spec.seed = 14;
  spec.gyro.gauss_markov_sigma = Vec3::Constant(1.0);
  spec.gyro.gauss_markov_tau_s = Vec3::Constant(0.05);
  const double fs = 1000.0;
  const std::size_t n = 400'000;
  const std::vector<double> y = run_axis(spec, fs, n);
  const double phi = std::exp(-1.0 / (fs * 0.05));
  // AR(1) with phi = 0.98: about n (1 - phi) / (1 + phi) = 4000 independent
  // samples; the standard errors of the variance and of the autocorrelations
  // are about 0.02; tolerances 0.08 and 0.06.
  const double var = variance(y);
  EXPECT_NEAR(var, 1.0, 0.08);
  const double m = mean(y);
  for (std::size_t lag : {1u, 10u, 50u, 100u}) {
    double s = 0.0;
    for (std::size_t i = 0; i + lag < n; ++i) s += (y[i] - m) * (y[i + lag] - m);
    const double rho = s / static_cast<double>(n - lag) / var;
    EXPECT_NEAR(rho, std::pow(phi, static_cast<double>(lag)), 0.06) << "lag " << lag;
  }
}

TEST(SensorModel, RandomWalkVarianceGrowsLinearlyInTime) {
  // 600 independent walks (100 devices x 3 axes x 2 triads): the variance at t
  // is K^2 t with a relative standard error sqrt(2/600) = 5.8 %; 20 %.
  SensorModelSpec spec;
  spec.seed = 15;
  spec.gyro.random_walk = Vec3::Constant(0.3);
  spec.accel.random_walk = Vec3::Constant(0.3);
  const double fs = 100.0;
  const std::size_t checkpoints[] = {100, 400, 1000};
  std::vector<std::vector<double>> at(3);
  for (int d = 0; d < 100; ++d) {
    SensorModel model(spec, fs, "dev" + std::to_string(d));
    for (std::size_t k = 0; k <= 1000; ++k) {
      const Measurement m = model.measure(k, Vec3::Zero(), Vec3::Zero());
      for (int c = 0; c < 3; ++c)
        if (k == checkpoints[c])
          for (int a = 0; a < 3; ++a) {
            at[c].push_back(m.gyro_rad_s[a]);
            at[c].push_back(m.accel_m_s2[a]);
          }
    }
  }
  for (int c = 0; c < 3; ++c) {
    const double t = static_cast<double>(checkpoints[c]) / fs;
    double s = 0.0;
    for (double v : at[c]) s += v * v;  // the walk starts at 0: E[b^2] = K^2 t
    EXPECT_NEAR(s / static_cast<double>(at[c].size()) / (0.09 * t), 1.0, 0.2) << "t = " << t;
  }
}

TEST(SensorModel, FlickerAllanDeviationIsFlatAt0664BOverTheTauRange) {
  // Bias instability B over [0.1, 10] s at 100 Hz; the mean Allan variance of
  // 24 independent axes (4 devices x 6), 3000 s each, at 5 tau in the range is
  // within 10 % of (0.664 B)^2 in deviation (model ripple -2.3/+0.9 %,
  // sampling error about 2 % at tau = 10 s). A single Gauss-Markov process
  // spans a factor of 2 in deviation over these two decades.
  SensorModelSpec spec;
  spec.seed = 16;
  spec.gyro.bias_instability = Vec3::Constant(1.0);
  spec.accel.bias_instability = Vec3::Constant(1.0);
  for (TriadSpec* t : {&spec.gyro, &spec.accel}) {
    t->flicker_tau_min_s = 0.1;
    t->flicker_tau_max_s = 10.0;
  }
  const double fs = 100.0;
  const std::size_t n = 300'000;
  const double taus[] = {0.1, 0.3, 1.0, 3.0, 10.0};
  double avar_sum[5] = {};
  int count = 0;
  for (int d = 0; d < 4; ++d) {
    SensorModel model(spec, fs, "flicker" + std::to_string(d));
    std::vector<std::vector<double>> y(6, std::vector<double>(n));
    for (std::size_t k = 0; k < n; ++k) {
      const Measurement m = model.measure(k, Vec3::Zero(), Vec3::Zero());
      for (int a = 0; a < 3; ++a) {
        y[a][k] = m.gyro_rad_s[a];
        y[3 + a][k] = m.accel_m_s2[a];
      }
    }
    for (const auto& axis : y) {
      for (int i = 0; i < 5; ++i) avar_sum[i] += overlapping_avar(axis, 1.0 / fs, static_cast<std::size_t>(std::lround(taus[i] * fs)));
      ++count;
    }
  }
  const double floor_dev = std::sqrt(2.0 * std::numbers::ln2 / std::numbers::pi);  // 0.664
  EXPECT_NEAR(floor_dev, 0.664, 5e-4);
  for (int i = 0; i < 5; ++i)
    EXPECT_NEAR(std::sqrt(avar_sum[i] / count) / floor_dev, 1.0, 0.10) << "tau " << taus[i] << " s";
}

TEST(SensorModel, FlickerDecompositionTwoProcessesPerDecadeWithFoldedEnds) {
  // 1..1000 s: T_j = 10^(j/2 - 1.5), j = 0..11 (1.5 decades below, one above).
  // Far from dt (1 ms) every process has variance B^2 ln(sqrt 10) / pi, the
  // two end ones rho / (rho - 1) times that (the geometric tails beyond them).
  const FlickerProcesses p = flicker_processes(2.0, 1.0, 1000.0, 1e-3);
  ASSERT_EQ(p.count, 12);
  EXPECT_NEAR(p.tau_s[0], std::pow(10.0, -1.5), 1e-15);
  EXPECT_NEAR(p.tau_s[3], 1.0, 1e-12);
  EXPECT_NEAR(p.tau_s[11], 1e4, 1e-8);
  const double rho = std::sqrt(10.0), base = 2.0 * std::sqrt(std::log(rho) / std::numbers::pi);
  EXPECT_NEAR(p.sigma[5] / base, 1.0, 1e-6);   // T = 10 s: discrete correction (dt/T)^2/12 ~ 1e-9
  EXPECT_NEAR(p.sigma[11] / base, std::sqrt(rho / (rho - 1.0)), 1e-6);
  // The fastest (T = 31.6 dt): its discrete white-noise equivalent s^2 (1 + phi) / (1 - phi) dt
  // equals the continuous 2 T s_c^2.
  const double phi = std::exp(-1e-3 / p.tau_s[0]);
  const double s_c2 = base * base * rho / (rho - 1.0);
  EXPECT_NEAR(p.sigma[0] * p.sigma[0] * (1.0 + phi) / (1.0 - phi) * 1e-3 / (2.0 * p.tau_s[0] * s_c2), 1.0, 1e-12);
}

// The analytic Allan variance of the decomposition (the sum of each process'
// s^2 g(tau/T), g(x) = (2/x^2)(x - 3/2 + 2e^-x - e^-2x/2), the Allan
// variance of a first-order Gauss-Markov process) is flat at (0.664 B)^2
// within 0.1 % in deviation over [tau_min, tau_max], on 100 tau per decade.
TEST(SensorModel, FlickerAnalyticAllanDeviationIsFlatWithinAPerMilleOverTheRange) {
  const auto g = [](double x) {
    return x < 1e-4 ? 2.0 * x / 3.0 - x * x / 2.0 : 2.0 / (x * x) * (x - 1.5 + 2.0 * std::exp(-x) - 0.5 * std::exp(-2.0 * x));
  };
  const double floor2 = 2.0 * std::numbers::ln2 / std::numbers::pi;
  for (const auto& [lo, hi] : {std::pair{1.0, 1000.0}, std::pair{10.0, 1e4}, std::pair{100.0, 1e5}, std::pair{0.3, 2.0}}) {
    const FlickerProcesses p = flicker_processes(1.0, lo, hi, 1e-6);
    double worst = 0.0;
    for (double e = std::log10(lo); e <= std::log10(hi) + 1e-9; e += 0.01) {
      const double tau = std::pow(10.0, e);
      double avar = 0.0;
      for (int j = 0; j < p.count; ++j) avar += p.sigma[j] * p.sigma[j] * g(tau / p.tau_s[j]);
      worst = std::max(worst, std::abs(std::sqrt(avar / floor2) - 1.0));
    }
    EXPECT_LT(worst, 1e-3) << "[" << lo << ", " << hi << "] s";
  }
}

TEST(SensorModel, ScaleFactorAsymmetryMisalignmentGSensitivityExactWithNoiseOff) {
  SensorModelSpec spec;
  spec.gyro.scale_factor = Vec3(1000e-6, -500e-6, 0.0);
  spec.gyro.scale_factor_asymmetry = Vec3(0.0, 0.0, 200e-6);
  spec.accel.misalignment_rad = Vec3(1e-3, -2e-3, 0.5e-3);
  spec.gyro.g_sensitivity = Mat3::Zero();
  spec.gyro.g_sensitivity(0, 2) = 1e-4;  // x gyro sees 1e-4 rad/s per m/s^2 of z specific force
  SensorModel model(spec, 400.0, "imu0");
  const Vec3 w(0.1, -0.2, 0.3), f(0.0, 0.0, -9.8);
  const Measurement m = model.measure(0, w, f);
  EXPECT_DOUBLE_EQ(m.gyro_rad_s.x(), (1.0 + 1000e-6) * 0.1 + 1e-4 * -9.8);
  EXPECT_DOUBLE_EQ(m.gyro_rad_s.y(), (1.0 - 500e-6) * -0.2);
  EXPECT_DOUBLE_EQ(m.gyro_rad_s.z(), (1.0 + 100e-6) * 0.3);
  const Measurement neg = model.measure(1, -w, f);
  EXPECT_DOUBLE_EQ(neg.gyro_rad_s.z(), (1.0 - 100e-6) * -0.3);
  // Misalignment: the triad is rotated by the small rotation vector m against
  // the body; it measures R(m)^T f, to first order in |m| (error ~ |m|^2 |f|).
  const Mat3 r = Eigen::AngleAxisd(spec.accel.misalignment_rad.norm(), spec.accel.misalignment_rad.normalized()).toRotationMatrix();
  const Vec3 expected = r.transpose() * f;
  EXPECT_LT((m.accel_m_s2 - expected).norm(), 9.8 * 1e-5);
  EXPECT_GT((m.accel_m_s2 - f).norm(), 9.8 * 1e-3);  // and it is there
}

TEST(SensorModel, SaturatesExactlyAtTheRangeWithFlagsAndQuantisesToTheLsb) {
  SensorModelSpec spec = preset_spec("icm42688p");
  spec.gyro.white_density.setZero();
  spec.accel.white_density.setZero();
  SensorModel model(spec, 1000.0, "imu0");
  // The SI values the datasheet keys convert to: 2000 deg/s and 2000/32768 deg/s.
  const double deg = std::numbers::pi / 180.0;
  const double range = 2000.0 * deg, lsb = (2000.0 / 32768.0) * deg;
  const Measurement over = model.measure(0, Vec3(range * 1.5, -range * 3.0, 0.5), Vec3(0.0, 0.0, 200.0));
  EXPECT_EQ(over.gyro_rad_s.x(), range);
  EXPECT_EQ(over.gyro_rad_s.y(), -range);
  EXPECT_EQ(over.accel_m_s2.z(), 16.0 * 9.80665);  // range_g x g
  EXPECT_EQ(over.saturated_axes, kGyroX | kGyroY | kAccelZ);
  const Measurement at = model.measure(1, Vec3(range, 0.0, 0.0), Vec3::Zero());
  EXPECT_NEAR(at.gyro_rad_s.x(), range, 1e-12);  // the top code, not flagged
  EXPECT_LE(at.gyro_rad_s.x(), range);
  EXPECT_EQ(at.saturated_axes, 0);
  // Quantised values are exact multiples of the LSB, the nearest one.
  for (std::uint64_t k = 2; k < 2000; ++k) {
    const double v = 1.234567 * std::sin(0.01 * static_cast<double>(k));
    const Measurement q = model.measure(k, Vec3(v, -v, 0.0), Vec3(v, 0.0, 0.0));
    // q = n * lsb for an integer n (as a double product: what a decoder
    // computes from the integer code).
    const double n = std::nearbyint(q.gyro_rad_s.x() / lsb);
    ASSERT_EQ(q.gyro_rad_s.x(), n * lsb) << k;
    ASSERT_LE(std::abs(q.gyro_rad_s.x() - v), 0.5 * lsb * (1 + 1e-12));
    const double alsb = (16000.0 / 32768.0) * (1e-3 * 9.80665);
    ASSERT_EQ(q.accel_m_s2.x(), std::nearbyint(q.accel_m_s2.x() / alsb) * alsb);
  }
}

TEST(SensorModel, SeedsAxesAndDevicesAreUncorrelated) {
  // |r| of independent series of n = 100000 has standard error 1/sqrt(n) =
  // 0.0032; 5 of them.
  const std::size_t n = 100'000;
  SensorModelSpec spec;
  spec.gyro.white_density = Vec3::Constant(0.01);
  spec.accel.white_density = Vec3::Constant(0.01);
  spec.seed = 1;
  const auto x1 = run_axis(spec, 400.0, n, "imu0", 0, 0);
  const auto y1 = run_axis(spec, 400.0, n, "imu0", 0, 1);
  const auto a1 = run_axis(spec, 400.0, n, "imu0", 1, 0);
  const auto d1 = run_axis(spec, 400.0, n, "imu1", 0, 0);
  spec.seed = 2;
  const auto x2 = run_axis(spec, 400.0, n, "imu0", 0, 0);
  const double bound = 5.0 / std::sqrt(static_cast<double>(n));
  EXPECT_LT(std::abs(correlation(x1, y1)), bound);
  EXPECT_LT(std::abs(correlation(x1, a1)), bound);
  EXPECT_LT(std::abs(correlation(x1, d1)), bound);
  EXPECT_LT(std::abs(correlation(x1, x2)), bound);
  // Lag-1 autocorrelation of white noise: 0 within the same bound.
  std::vector<double> lagged(x1.begin() + 1, x1.end()), head(x1.begin(), x1.end() - 1);
  EXPECT_LT(std::abs(correlation(head, lagged)), bound);
}

TEST(SensorModel, AddingATermLeavesTheOtherNoiseBitIdentical) {
  SensorModelSpec a;
  a.seed = 7;
  a.gyro.white_density = Vec3::Constant(0.01);
  SensorModelSpec b = a;
  b.accel.bias_instability = Vec3::Constant(1e-3);
  b.accel.random_walk = Vec3::Constant(1e-3);
  b.gyro.turn_on_bias_sigma = Vec3(0.0, 0.0, 0.0);
  b.accel.white_density = Vec3::Constant(0.02);
  SensorModel ma(a, 400.0, "imu0"), mb(b, 400.0, "imu0");
  for (std::uint64_t k = 0; k < 1000; ++k) {
    const Measurement ra = ma.measure(k, Vec3(0.1, 0.2, 0.3), Vec3::Zero());
    const Measurement rb = mb.measure(k, Vec3(0.1, 0.2, 0.3), Vec3::Zero());
    ASSERT_EQ(ra.gyro_rad_s, rb.gyro_rad_s) << k;
  }
}

TEST(SensorModel, SkippedSamplesAreSimulatedSoSampleKIsTheSame) {
  SensorModelSpec spec = preset_spec("adis16470");
  spec.seed = 99;
  SensorModel every(spec, 400.0, "imu0"), some(spec, 400.0, "imu0");
  for (std::uint64_t k = 0; k < 2000; ++k) {
    const Vec3 w(0.01 * static_cast<double>(k), 0.0, 0.0), f(0.0, 0.0, -9.8);
    const Measurement e = every.measure(k, w, f);
    if (k % 7 == 0 || (k > 500 && k < 520)) continue;
    const Measurement s = some.measure(k, w, f);
    ASSERT_EQ(e.gyro_rad_s, s.gyro_rad_s) << k;
    ASSERT_EQ(e.accel_m_s2, s.accel_m_s2) << k;
  }
  EXPECT_THROW(some.measure(10, Vec3::Zero(), Vec3::Zero()), std::invalid_argument);
}

TEST(SensorModel, TurnOnBiasIsDrawnPerRunAndTemperatureWarmUpFollowsTheProfile) {
  SensorModelSpec spec;
  spec.seed = 3;
  spec.gyro.turn_on_bias = Vec3(1e-3, 0.0, 0.0);
  spec.gyro.turn_on_bias_sigma = Vec3(0.0, 1e-2, 0.0);
  spec.accel.bias_temperature_coeff = Vec3(0.0, 0.0, 1e-3);  // m/s^2 per K
  spec.temperature = {.reference_c = 25.0, .start_c = 5.0, .end_c = 45.0, .warmup_tau_s = 60.0};
  SensorModel model(spec, 100.0, "imu0");
  const Measurement m0 = model.measure(0, Vec3::Zero(), Vec3::Zero());
  EXPECT_DOUBLE_EQ(m0.gyro_rad_s.x(), 1e-3);
  EXPECT_NE(m0.gyro_rad_s.y(), 0.0);
  EXPECT_EQ(m0.gyro_rad_s.y(), model.gyro_turn_on_bias().y());
  EXPECT_DOUBLE_EQ(m0.temperature_c, 5.0);
  EXPECT_NEAR(m0.accel_m_s2.z(), 1e-3 * (5.0 - 25.0), 1e-15);
  const Measurement m60 = model.measure(6000, Vec3::Zero(), Vec3::Zero());
  const double t60 = 45.0 - 40.0 * std::exp(-1.0);
  EXPECT_NEAR(m60.temperature_c, t60, 1e-12);
  EXPECT_NEAR(m60.accel_m_s2.z(), 1e-3 * (t60 - 25.0), 1e-15);
  // Another seed draws another turn-on bias; the same seed the same.
  spec.seed = 4;
  EXPECT_NE(SensorModel(spec, 100.0, "imu0").gyro_turn_on_bias().y(), model.gyro_turn_on_bias().y());
  spec.seed = 3;
  EXPECT_EQ(SensorModel(spec, 100.0, "imu0").gyro_turn_on_bias().y(), model.gyro_turn_on_bias().y());
}

TEST(SensorModel, RampAndNonFiniteInputNeverLeaveNaN) {
  SensorModelSpec spec;
  spec.gyro.ramp = Vec3::Constant(1e-4);
  spec.gyro.range = 10.0;
  SensorModel model(spec, 100.0, "imu0");
  const Measurement m = model.measure(500, Vec3(std::nan(""), INFINITY, 0.0), Vec3::Zero());
  EXPECT_TRUE(m.gyro_rad_s.allFinite());
  EXPECT_NEAR(m.gyro_rad_s.z(), 1e-4 * 5.0, 1e-15);
}

TEST(SensorModel, IdealSpecIsIdealAndRefusedSpecsNameTheField) {
  EXPECT_TRUE(SensorModelSpec{}.is_ideal());
  for (const Preset& p : presets()) {
    const SensorModelSpec s = preset_spec(p.name);
    EXPECT_FALSE(s.is_ideal()) << p.name;
    EXPECT_NO_THROW(validate(s)) << p.name;
    EXPECT_FALSE(describe(s, 400.0).empty());
  }
  SensorModelSpec bad;
  bad.gyro.white_density = Vec3(-1.0, 0.0, 0.0);
  EXPECT_THROW(validate(bad), std::invalid_argument);
  SensorModelSpec nl;
  nl.accel.nonlinearity = Vec3::Constant(1e-4);
  EXPECT_THROW(validate(nl), std::invalid_argument);
  EXPECT_THROW(SensorModel(SensorModelSpec{}, 0.0, "x"), std::invalid_argument);
}

TEST(Datasheet, KeysConvertOnceToSiAndUnitlessKeysAreRefused) {
  SensorModelSpec s;
  apply_key(s, Triad::gyro, "arw_deg_rt_h", {0.15});
  EXPECT_NEAR(s.gyro.white_density.x(), 0.15 * std::numbers::pi / 180.0 / 60.0, 1e-18);
  apply_key(s, Triad::gyro, "noise_density_dps_rt_hz", {0.0025});
  EXPECT_NEAR(s.gyro.white_density.y(), 0.0025 * std::numbers::pi / 180.0, 1e-18);  // same term, per sqrt(Hz)
  apply_key(s, Triad::accel, "noise_density_ug_rt_hz", {70.0});
  EXPECT_NEAR(s.accel.white_density.z(), 70e-6 * 9.80665, 1e-18);
  apply_key(s, Triad::accel, "vrw_m_s_rt_h", {0.06});
  EXPECT_NEAR(s.accel.white_density.z(), 0.001, 1e-18);
  apply_key(s, Triad::gyro, "g_sensitivity_deg_h_g", {1.0, 2.0, 3.0});
  EXPECT_NEAR(s.gyro.g_sensitivity(2, 2), 3.0 * std::numbers::pi / 180.0 / 3600.0 / 9.80665, 1e-20);
  EXPECT_EQ(s.gyro.g_sensitivity(0, 1), 0.0);
  apply_key(s, Triad::gyro, "misalignment_mrad", {1.0, 2.0, 3.0});
  EXPECT_DOUBLE_EQ(s.gyro.misalignment_rad.y(), 2e-3);
  try {
    apply_key(s, Triad::gyro, "noise_density", {1.0});
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("noise_density_dps_rt_hz"), std::string::npos) << e.what();
  }
  EXPECT_THROW(apply_key(s, Triad::gyro, "range_g", {16.0}), std::invalid_argument);  // an accel key
  EXPECT_THROW(apply_key(s, Triad::gyro, "scale_factor_ppm", {1.0, 2.0}), std::invalid_argument);
  EXPECT_THROW(preset_spec("nope"), std::invalid_argument);
}

}  // namespace
}  // namespace imuemu::sensor
}  // namespace unity_core_test_sensor_model
