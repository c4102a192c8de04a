// Issue 15, acceptance 1: for each sensor preset a long static run (hours of
// emulated time) through the batch sensor stage of `imuemu generate`
// (scene::error_model_from_option + scene::apply_error_model, the code
// `generate --sensor PRESET --seed N` runs), analysed by the command's own
// path (cli::allan_options + cli::analyse_allan_input, what `imuemu allan`
// runs between reading the CSV and printing). The truth is the preset's
// configured figures (core/sensor/datasheet.cpp), not anything the analysis
// computes. The CSV round trip itself is tested in tests/cli/test_allan_command.cpp
// (and a multi-hour CSV would be gigabytes). docs/allan.md "The presets"
// explains the durations and what a static Allan analysis cannot see.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <cstdio>
#include <string>
#include <vector>

#include "core/allan/allan.hpp"
#include "core/pipeline.hpp"
#include "core/reference_motion.hpp"
#include "core/sensor/datasheet.hpp"
#include "core/sensor/sensor_model.hpp"
#include "daemon/cli/allan_command.hpp"
#include "daemon/scene/error_model_config.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_cli_test_allan_presets {
namespace imuemu { using namespace ::imuemu; }

namespace cli = imuemu::cli;
namespace allan = imuemu::allan;
using imuemu::ImuSample;
using imuemu::TimeNs;

namespace {

struct StaticRun {
  cli::AllanInput input;
  std::uint64_t saturated = 0;
};

// `imuemu generate --in static.csv --sensor PRESET --seed SEED --rate RATE`
// without the CSV: the static body of `imuemu sample-trajectory --kind
// static` (reference::Static near Barcelona, ECEF physics: Earth rate and
// normal gravity, both constant in the body frame), its ideal IMU sample on
// the output grid t_k = floor(k 1e9 / rate), then the sensor stage of
// generate. That stage (scene::apply_error_model) is one SensorModel built
// from the device's spec at the rate, measuring sample k = grid_index(t0,
// t_k) = k; it is called here the same way, one sample at a time, so that a
// record of 14 M samples keeps 6 doubles per sample, not a whole ImuSample
// (generate's bits equal this stage's: tests/scene/test_sensor_integration.cpp).
StaticRun static_run(const std::string& preset, std::int64_t rate_hz, double hours, std::int64_t seed) {
  const auto count = static_cast<std::size_t>(std::llround(hours * 3600.0 * static_cast<double>(rate_hz)));
  const imuemu::reference::Static body(imuemu::reference::AircraftFlight::default_origin(),
                                       imuemu::attitude::HeadingPitchRoll{0.5, 0.02, -0.01}, imuemu::Physics::ecef, 0,
                                       static_cast<TimeNs>(hours * 3600e9) + 1'000'000'000);
  const imuemu::SceneModel scene{imuemu::Physics::ecef};
  const ImuSample ideal = imuemu::reference::truth_imu(body, scene, 0);
  const imuemu::scene::ErrorModelConfig model = imuemu::scene::error_model_from_option(preset, seed);
  imuemu::sensor::SensorModel stage(model.spec, static_cast<double>(rate_hz), "imu0");
  StaticRun run;
  run.input.format = "imu";
  run.input.rows = count;
  run.input.tau0_s = 1.0 / static_cast<double>(rate_hz);
  static constexpr const char* kNames[] = {"gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"};
  run.input.series.resize(6);
  for (int a = 0; a < 6; ++a) {
    run.input.series[a].name = kNames[a];
    run.input.series[a].kind = a < 3 ? allan::SensorKind::gyro : allan::SensorKind::accel;
    run.input.series[a].values.resize(count);
  }
  for (std::size_t k = 0; k < count; ++k) {
    const imuemu::sensor::Measurement m = stage.measure(k, ideal.gyro_rad_s, ideal.accel_m_s2);
    if (m.saturated_axes != 0) ++run.saturated;
    for (int a = 0; a < 3; ++a) {
      run.input.series[a].values[k] = m.gyro_rad_s[a];
      run.input.series[3 + a].values[k] = m.accel_m_s2[a];
    }
  }
  return run;
}

// What one triad's analysis must show. `configured`: the preset's
// coefficients (SI, one per Allan term, 0 = not configured).
struct Expectation {
  std::array<double, allan::kTermCount> configured{};
  // The white-noise deviation the emitted series really has when the
  // preset quantises the rate: N_eff^2 = N^2 + LSB^2 / (12 fs) (the rounding
  // error of a rate sample is white, variance LSB^2/12 when the noise spans
  // about an LSB or more: Widrow & Kollar, "Quantization Noise", 2008, ch. 4).
  // 0: N itself.
  double white_effective = 0.0;
};

Expectation expectation(const imuemu::sensor::TriadSpec& t, double rate_hz) {
  Expectation e;
  e.configured[allan::white] = t.white_density.x();
  e.configured[allan::bias_instability] = t.bias_instability.x();
  e.configured[allan::rate_random_walk] = t.random_walk.x();
  e.configured[allan::rate_ramp] = t.ramp.x();
  if (t.lsb > 0.0 && t.white_density.x() > 0.0)
    e.white_effective = std::sqrt(t.white_density.x() * t.white_density.x() + t.lsb * t.lsb / (12.0 * rate_hz));
  return e;
}

struct Tally {
  int checks = 0, inside = 0;
  // Sum of squared normalised errors (fitted - truth) / reported sigma over
  // the `normalised` checks whose term was fitted (sigma > 0); their RMS is 1
  // when the reported sigma is honest.
  double sum_z2 = 0.0;
  int normalised = 0;
  void add(const Tally& o) {
    checks += o.checks;
    inside += o.inside;
    sum_z2 += o.sum_z2;
    normalised += o.normalised;
  }
};

// Every configured term within 10 % (rate random walk 20 %) and within 4
// reported sigma on each axis; the truth inside the reported 90 % interval is
// tallied (run_preset bounds the misses); an
// unconfigured term the fit reports must stay below the configured noise at
// every tau of the grid (it never dominates: the fit found nothing of its own).
void check_triad(const std::string& preset, const cli::AllanInput& in, const std::vector<allan::Analysis>& analyses,
                 const Expectation& e, Tally& tally) {
  for (std::size_t s = 0; s < analyses.size(); ++s) {
    const allan::Analysis& a = analyses[s];
    const std::string axis = preset + " " + in.series[s].name;
    std::array<allan::FittedTerm, allan::kTermCount> truth{};
    for (int k = 0; k < allan::kTermCount; ++k) {
      truth[static_cast<std::size_t>(k)].enabled = true;
      truth[static_cast<std::size_t>(k)].value = e.configured[static_cast<std::size_t>(k)];
    }
    for (int k = 0; k < allan::kTermCount; ++k) {
      const auto ku = static_cast<std::size_t>(k);
      const allan::FittedTerm& f = a.terms[ku];
      const double configured = e.configured[ku];
      if (configured > 0.0) {
        const double tolerance = k == allan::rate_random_walk ? 0.20 : 0.10;
        EXPECT_NEAR(f.value / configured, 1.0, tolerance) << axis << " " << allan::term_name(k);
        const double ci_truth = k == allan::white && e.white_effective > 0.0 ? e.white_effective : configured;
        const bool inside = f.low <= ci_truth && ci_truth <= f.high;
        ++tally.checks;
        tally.inside += inside ? 1 : 0;
        if (f.sigma > 0.0) {
          const double z = (f.value - ci_truth) / f.sigma;
          tally.sum_z2 += z * z;
          ++tally.normalised;
          // No term 4 reported sigma off (a normal variable is, once in
          // 16 000): a bias or an interval far too narrow, which the count
          // of misses below would let through as one of its few.
          EXPECT_LE(std::abs(z), 4.0) << axis << " " << allan::term_name(k) << ": fitted " << f.value << " truth "
                                      << ci_truth << " sigma " << f.sigma;
        } else {
          ADD_FAILURE() << axis << " " << allan::term_name(k) << ": configured but not fitted";
        }
        std::printf("  %-20s %-16s configured %.5g fitted %.5g (%+.2f %%) 90 %% interval [%.5g, %.5g]%s\n", axis.c_str(),
                    allan::term_name(k).c_str(), configured, f.value, 100.0 * (f.value / configured - 1.0), f.low,
                    f.high, inside ? "" : "  truth outside");
      } else if (f.value > 0.0) {
        std::printf("  %-20s %-16s not configured, fitted %.5g (sigma %.3g)\n", axis.c_str(), allan::term_name(k).c_str(),
                    f.value, f.sigma);
      }
      if (configured <= 0.0 && f.value > 0.0 && f.sigma > 0.0 && f.value / (2.0 * f.sigma) > 3.0) {
        // A term the preset does not have, fitted significantly: its squared
        // coefficient c = value^2 more than 3 sigma_c = 3 x 2 value sigma
        // above 0 (a null term gets there by chance 0.13 % of the time; the
        // 90 % interval excluding 0, as once here, happens by chance on some
        // of the 18 unconfigured (term, axis) pairs of a preset once the
        // intervals are honest). It must stay below the configured noise over
        // the fitted tau (a minor share the fit moved around, not a noise of
        // its own).
        for (const allan::Point& p : a.points) {
          if (!p.in_fit) continue;
          const double spurious = std::sqrt(f.value * f.value * allan::term_basis(k, p.tau_s));
          EXPECT_LT(spurious, allan::model_adev(truth, p.tau_s))
              << axis << ": the unconfigured " << allan::term_name(k) << " (" << f.value << ", 90 % interval ["
              << f.low << ", " << f.high << "]) dominates at tau " << p.tau_s << " s; measured " << p.adev << " ["
              << p.ci_low << ", " << p.ci_high << "]";
        }
      }
    }
  }
}

struct PresetCase {
  std::string preset;
  std::int64_t rate_hz;
  double hours;
  std::int64_t seed;
  double accel_fit_min_tau_s = 0.0;  // --fit-min-tau-s of the accelerometer analysis
  bool assert_coverage = true;
  std::string terms = "q,n,b,k,r";  // EXPERIMENT
};

const PresetCase kIcm42688p{"icm42688p", 1000, 1.0, 1};
const PresetCase kAdis16470{"adis16470", 25, 24.0, 1};
const PresetCase kStim300{"stim300", 20, 192.0, 1};
const PresetCase kHg9900{"hg9900", 1, 700.0, 1, 100.0};

// Honest 90 % intervals miss their truth once in 10 checks, independently
// across axes (separate noise streams): the misses among n checks are
// Binomial(n, 0.1). The smallest x with P(misses > x) < `tail`: with tail 1 %,
// 3 for 6 or 9 checks, 4 for 12. (Every term inside its 90 % interval at
// once happens with probability 0.9^n only, 28 % for 12 checks, so it cannot
// be asserted of honest intervals.)
int binomial_misses_bound(int n, double p, double tail) {
  double pmf = std::pow(1.0 - p, n), cdf = 0.0;
  for (int x = 0; x <= n; ++x) {
    cdf += pmf;
    if (1.0 - cdf < tail) return x;
    pmf *= static_cast<double>(n - x) / static_cast<double>(x + 1) * p / (1.0 - p);
  }
  return n;
}

Tally run_preset(const PresetCase& c) {
  StaticRun run = static_run(c.preset, c.rate_hz, c.hours, c.seed);
  EXPECT_EQ(run.saturated, 0u);  // at rest nothing reaches a range
  const imuemu::sensor::SensorModelSpec spec = imuemu::sensor::preset_spec(c.preset);
  // `imuemu allan FILE --axes gyro` and `--axes accel [--fit-min-tau-s T]`.
  // The axes are moved, not copied (a 14 M-sample record is 110 MB per axis).
  cli::AllanInput gyro, accel;
  for (cli::AllanInput* in : {&gyro, &accel}) {
    in->format = run.input.format;
    in->rows = run.input.rows;
    in->tau0_s = run.input.tau0_s;
  }
  for (int a = 0; a < 6; ++a) (a < 3 ? gyro : accel).series.push_back(std::move(run.input.series[static_cast<std::size_t>(a)]));
  run.input.series.clear();
  cli::AllanArgs gyro_args, accel_args;
  accel_args.fit_min_tau_s = c.accel_fit_min_tau_s;
  gyro_args.terms = accel_args.terms = c.terms;
  std::printf("%s: %.0f h at %lld Hz, seed %lld\n", c.preset.c_str(), c.hours, static_cast<long long>(c.rate_hz),
              static_cast<long long>(c.seed));
  Tally tally;
  const auto g = cli::analyse_allan_input(gyro, cli::allan_options(gyro_args));
  check_triad(c.preset, gyro, g, expectation(spec.gyro, static_cast<double>(c.rate_hz)), tally);
  const auto a = cli::analyse_allan_input(accel, cli::allan_options(accel_args));
  check_triad(c.preset, accel, a, expectation(spec.accel, static_cast<double>(c.rate_hz)), tally);
  std::printf("%s: truth inside the 90 %% interval in %d of %d\n", c.preset.c_str(), tally.inside, tally.checks);
  if (c.assert_coverage) {
    const int allowed = binomial_misses_bound(tally.checks, 0.10, 0.01);
    EXPECT_LE(tally.checks - tally.inside, allowed)
        << c.preset << ": more terms outside their 90 % interval than honest intervals miss in 99 % of runs";
  }
  return tally;
}

// Durations: each preset's slowest configured term must be dominant over a
// decade or more of tau below T/4 (docs/allan.md "The presets"), and the
// record long enough that the bias instability's own scatter is well inside
// the 10 % the test asserts: its 1-sigma scatter goes as sqrt(crossover / T)
// (the flicker's degrees of freedom at tau are about T / tau), 3-4 % at the
// durations below, 5-6 % at a quarter of them (STIM300 and HG9900 gyros,
// 90 % interval +-9-10 %: one B in 13 came out beyond 10 % over 8 seeds). Rates
// are chosen for cost: the density convention makes the Allan white noise
// independent of the rate (tests/core/test_sensor_model.cpp), so a long record at
// a low rate holds the same information about the slow terms, as long as the
// flicker's fastest processes stay a few samples long (docs/sensor-models.md).

// White noise only (plus the 16-bit LSB): 1 h at 1 kHz, where the rate's
// rounding adds 2 % to the gyro's white deviation (N_eff above).
TEST(AllanPresets, Icm42688pOneHourAt1kHz) { run_preset(kIcm42688p); }

// Gyro white/flicker crossover (0.008 deg/s/sqrt(Hz) / (0.664 x 8 deg/h))^2 = 29 s,
// accel 53 s; flicker configured over 1..1000 s.
TEST(AllanPresets, Adis16470OneDayAt25Hz) { run_preset(kAdis16470); }

// Gyro crossover (0.15 deg/sqrt(h) / (0.664 x 0.5 deg/h))^2 = 735 s: eight
// days put T/4 = 48 h, 2.4 decades above it. 20 Hz: the accelerometer's
// flicker starts at 1 s, 20 samples (at 5 Hz its fastest processes, a few
// samples long, would read the accelerometer's N 0.4 % high).
TEST(AllanPresets, Stim300EightDaysAt20Hz) { run_preset(kStim300); }

// Gyro crossover (0.002 deg/sqrt(h) / (0.664 x 0.0035 deg/h))^2 = 2670 s:
// 700 h (scripts/plot_presets_allan.sh makes the same record, and
// sample-trajectory stops at 720 h) put T/4 = 175 h = 6.3e5 s, 2.4 decades
// above it. The accelerometer has
// only bias instability (the brochure gives no VRW): below the flicker's
// configured tau_min = 100 s the sum of Gauss-Markov processes falls (it is
// flicker only over its range), which the five-term model would read as a
// rate random walk; the analysis is therefore `--fit-min-tau-s 100`.
TEST(AllanPresets, Hg9900SevenHundredHoursAt1Hz) { run_preset(kHg9900); }

// Not run by ctest (DISABLED_): the calibration of the fitted terms' 90 %
// intervals over seeds, for docs/allan.md. For experiments, COV_PRESET,
// COV_SEED, COV_HOURS, COV_RATE and COV_TERMS (imuemu allan --terms) narrow
// or change the cases. Prints, per preset and in all,
// how often the truth is inside the interval and the RMS of
// (fitted - truth) / reported sigma (1 when the sigma is honest):
//   build/release/tests/cli_tests --gtest_also_run_disabled_tests
//     --gtest_filter='AllanPresets.*Coverage*' | grep coverage
TEST(AllanPresets, DISABLED_CoverageOverSeeds) {
  const std::vector<PresetCase> cases = {kIcm42688p, kAdis16470, kStim300, kHg9900};
  constexpr int kSeeds = 8;
  Tally all;
  for (PresetCase base : cases) {
    if (const char* e = std::getenv("COV_PRESET"); e && base.preset != e) continue;
    if (const char* e = std::getenv("COV_HOURS")) base.hours = std::atof(e);
    if (const char* e = std::getenv("COV_RATE")) base.rate_hz = std::atoll(e);
    if (const char* e = std::getenv("COV_TERMS")) base.terms = e;
    Tally preset;
    for (int seed = 1; seed <= kSeeds; ++seed) {
      if (const char* e = std::getenv("COV_SEED"); e && std::atoi(e) != seed) continue;
      PresetCase c = base;
      c.seed = seed;
      c.assert_coverage = false;  // measured here, not asserted
      const Tally t = run_preset(c);
      std::printf("coverage %s seed %d: %d of %d inside\n", base.preset.c_str(), seed, t.inside, t.checks);
      preset.add(t);
    }
    std::printf("coverage %s: %d of %d inside, RMS of normalised error %.3f over %d\n", base.preset.c_str(),
                preset.inside, preset.checks, std::sqrt(preset.sum_z2 / std::max(1, preset.normalised)),
                preset.normalised);
    all.add(preset);
  }
  std::printf("coverage all: %d of %d inside (%.1f %%), RMS of normalised error %.3f over %d\n", all.inside, all.checks,
              100.0 * all.inside / std::max(1, all.checks), std::sqrt(all.sum_z2 / std::max(1, all.normalised)),
              all.normalised);
  // Pooled over every (term, axis, seed), honest 90 % intervals miss as
  // Binomial(n, 0.1): no more misses than that exceeds in 1 % of studies
  // (44 of 312; main before the two-per-decade flicker had 58, now 33).
  EXPECT_LE(all.checks - all.inside, binomial_misses_bound(all.checks, 0.10, 0.01));
}

}  // namespace
}  // namespace unity_cli_test_allan_presets
