// Per-sample cost of the sensor model (issue 15, acceptance 5): one
// SensorModel::measure at 1 kHz with every term on, with each preset, and the
// ideal path (no stage: what generate/stream/imuemud do for an ideal sensor,
// i.e. nothing, measured as the copy they keep). Goal: all terms <= 0.5 us.
// Run: build/release/bench/bench_sensor --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
#include <benchmark/benchmark.h>

#include <cmath>
#include <string>

#include "core/sensor/datasheet.hpp"
#include "core/sensor/sensor_model.hpp"

using namespace imuemu;

namespace {

sensor::SensorModelSpec every_term() {
  using sensor::Triad;
  sensor::SensorModelSpec s;
  s.seed = 1;
  for (Triad t : {Triad::gyro, Triad::accel}) {
    const bool g = t == Triad::gyro;
    auto set = [&](const std::string& key, std::vector<double> v) { sensor::apply_key(s, t, key, v); };
    set(g ? "arw_deg_rt_h" : "vrw_m_s_rt_h", {0.15});
    set(g ? "bias_instability_deg_h" : "bias_instability_ug", {0.5});  // 1..1000 s: 12 processes per axis
    set(g ? "rrw_deg_h_rt_h" : "acceleration_random_walk_ug_rt_h", {0.1});
    set(g ? "rate_ramp_deg_h2" : "acceleration_ramp_ug_h", {0.01});
    set(g ? "gauss_markov_sigma_deg_h" : "gauss_markov_sigma_ug", {1.0});
    set("gauss_markov_tau_s", {300.0});
    set(g ? "turn_on_bias_sigma_deg_h" : "turn_on_bias_sigma_mg", {1.0});
    set("scale_factor_ppm", {300.0, -200.0, 100.0});
    set("scale_factor_asymmetry_ppm", {50.0});
    set("nonlinearity_ppm_fs", {25.0});
    set("misalignment_mrad", {1.0, -0.5, 0.2});
    set("non_orthogonality_mrad", {0.1, 0.2, 0.3});
    set(g ? "bias_temp_coeff_deg_h_per_c" : "bias_temp_coeff_ug_per_c", {0.1});
    set("scale_factor_temp_coeff_ppm_per_c", {5.0});
    set(g ? "lsb_dps" : "lsb_mg", {g ? 2000.0 / 32768.0 : 16000.0 / 32768.0});
    set(g ? "range_dps" : "range_g", {g ? 2000.0 : 16.0});
    if (g) set("g_sensitivity_deg_h_g", {1.0, 0.5, 0.2, 0.1, 1.0, 0.3, 0.2, 0.1, 1.0});
  }
  s.temperature = {.reference_c = 25.0, .start_c = 10.0, .end_c = 40.0, .warmup_tau_s = 600.0};
  return s;
}

void run(benchmark::State& state, const sensor::SensorModelSpec& spec) {
  sensor::SensorModel model(spec, 1000.0, "imu0");
  std::uint64_t k = 0;
  const Vec3 w(0.1, -0.2, 0.3), f(0.5, 0.1, -9.8);
  for (auto _ : state) {
    const sensor::Measurement m = model.measure(k++, w, f);
    benchmark::DoNotOptimize(m);
  }
  state.counters["ns_per_sample"] = benchmark::Counter(static_cast<double>(state.iterations()),
                                                       benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

}  // namespace

static void BM_sensor_all_terms_1kHz(benchmark::State& state) { run(state, every_term()); }
BENCHMARK(BM_sensor_all_terms_1kHz);

static void BM_sensor_white_only_1kHz(benchmark::State& state) {
  sensor::SensorModelSpec s;
  s.gyro.white_density = Vec3::Constant(1e-4);
  s.accel.white_density = Vec3::Constant(1e-3);
  run(state, s);
}
BENCHMARK(BM_sensor_white_only_1kHz);

static void BM_sensor_preset_1kHz(benchmark::State& state, const char* name) { run(state, sensor::preset_spec(name)); }
BENCHMARK_CAPTURE(BM_sensor_preset_1kHz, icm42688p, "icm42688p");
BENCHMARK_CAPTURE(BM_sensor_preset_1kHz, adis16470, "adis16470");
BENCHMARK_CAPTURE(BM_sensor_preset_1kHz, stim300, "stim300");
BENCHMARK_CAPTURE(BM_sensor_preset_1kHz, hg9900, "hg9900");

// The ideal sensor: the callers test is_ideal() once and never construct a
// model; per sample they pass the sample through unchanged.
static void BM_sensor_none_1kHz(benchmark::State& state) {
  const sensor::SensorModelSpec ideal;
  const bool skip = ideal.is_ideal();
  Vec3 w(0.1, -0.2, 0.3), f(0.5, 0.1, -9.8);
  for (auto _ : state) {
    if (!skip) w *= 2.0;
    benchmark::DoNotOptimize(w);
    benchmark::DoNotOptimize(f);
  }
  state.counters["ns_per_sample"] = benchmark::Counter(static_cast<double>(state.iterations()),
                                                       benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_sensor_none_1kHz);

// The Gaussian alone (ziggurat).
static void BM_sensor_gaussian(benchmark::State& state) {
  sensor::Stream s{12345};
  for (auto _ : state) benchmark::DoNotOptimize(s.gaussian());
}
BENCHMARK(BM_sensor_gaussian);

BENCHMARK_MAIN();
