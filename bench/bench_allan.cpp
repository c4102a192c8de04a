// Speed of the Allan analysis (core/allan): samples/s of the overlapping
// Allan variance over the whole log grid (10 per decade up to N/4; every
// start, or strided at m/64 as analyse() does) and of the
// complete analysis (grid + EDF + intervals + five-term fit), for one axis of
// 1 h and 24 h at 200 Hz. `imuemu allan` on a 24-hour 200 Hz file does this
// for six axes plus the parsing (docs/allan.md, "Speed").
// Run: build/release/bench/bench_allan
#include <benchmark/benchmark.h>

#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "core/allan/allan.hpp"

namespace {

std::vector<double> white_plus_walk(std::size_t n) {
  std::mt19937_64 rng(1);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::vector<double> y(n);
  double walk = 0.0;
  for (double& v : y) {
    walk += 1e-4 * normal(rng);
    v = 1e-3 * normal(rng) + walk;
  }
  return y;
}

}  // namespace

static void BM_allan_variance_grid(benchmark::State& state) {
  const auto n = static_cast<std::size_t>(state.range(0));
  const std::vector<double> y = white_plus_walk(n);
  const std::vector<std::int64_t> factors = imuemu::allan::log_spaced_factors(static_cast<std::int64_t>(n));
  for (auto _ : state) {
    const std::vector<double> theta = imuemu::allan::integrate_rate(y, 0.0);
    double sum = 0.0;
    for (std::int64_t m : factors)
      sum += imuemu::allan::overlapping_allan_variance(theta, m, imuemu::allan::stride_for(m, state.range(1)));
    benchmark::DoNotOptimize(sum);
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(n));
  state.counters["tau_points"] = static_cast<double>(factors.size());
}
// Second argument: the overlap ratio (0: every start; 64: analyse()'s default).
BENCHMARK(BM_allan_variance_grid)->Args({720'000, 0})->Args({720'000, 64})->Args({17'280'000, 0})->Args({17'280'000, 64})
    ->Unit(benchmark::kMillisecond)->Iterations(2);

static void BM_allan_analysis(benchmark::State& state) {
  const auto n = static_cast<std::size_t>(state.range(0));
  const std::vector<double> y = white_plus_walk(n);
  for (auto _ : state) {
    const imuemu::allan::Analysis a = imuemu::allan::analyse(y, 0.005);
    benchmark::DoNotOptimize(a.terms[0].value);
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(n));
}
BENCHMARK(BM_allan_analysis)->Arg(720'000)->Arg(17'280'000)->Unit(benchmark::kMillisecond)->Iterations(2);

// Not a timing: how the fit's reported uncertainty compares with the actual
// scatter of the fitted coefficients over 40 seeds of 4 h at 50 Hz with
// quantisation, white noise and rate random walk (each dominant over a decade
// or more). Counters: <term>_scatter_over_formal and _over_reported (the
// reported sigma is the sandwich covariance over the correlated tau), and the
// mean fitted value over the configured one.
static void BM_allan_fit_scatter(benchmark::State& state) {
  const double tau0 = 0.02, white_n = 1e-3, rrw_k = 2e-5, quant_q = 2e-4;
  const std::size_t n = 720'000;
  constexpr int kSeeds = 40;
  const int terms[] = {imuemu::allan::quantization, imuemu::allan::white, imuemu::allan::rate_random_walk};
  const double truth[] = {quant_q, white_n, rrw_k};
  for (auto _ : state) {
    double sum[3] = {}, sum2[3] = {}, formal[3] = {}, reported[3] = {};
    for (int s = 0; s < kSeeds; ++s) {
      std::mt19937_64 rng(1000 + static_cast<std::uint64_t>(s));
      std::normal_distribution<double> normal(0.0, 1.0);
      std::vector<double> y(n);
      double walk = 0.0, previous_e = quant_q * normal(rng);
      for (double& v : y) {
        walk += rrw_k * std::sqrt(tau0) * normal(rng);
        const double e = quant_q * normal(rng);
        v = white_n / std::sqrt(tau0) * normal(rng) + walk + (e - previous_e) / tau0;
        previous_e = e;
      }
      const imuemu::allan::Analysis a = imuemu::allan::analyse(y, tau0);
      for (int i = 0; i < 3; ++i) {
        const imuemu::allan::FittedTerm& t = a.terms[static_cast<std::size_t>(terms[i])];
        sum[i] += t.value;
        sum2[i] += t.value * t.value;
        formal[i] += t.formal_sigma / kSeeds;
        reported[i] += t.sigma / kSeeds;
      }
    }
    for (int i = 0; i < 3; ++i) {
      const double mean = sum[i] / kSeeds;
      const double sd = std::sqrt(std::max(0.0, sum2[i] / kSeeds - mean * mean));
      const std::string name = imuemu::allan::term_name(terms[i]);
      state.counters[name + "_scatter_over_formal"] = sd / formal[i];
      state.counters[name + "_scatter_over_reported"] = sd / reported[i];
      state.counters[name + "_mean_over_truth"] = mean / truth[i];
    }
  }
}
BENCHMARK(BM_allan_fit_scatter)->Unit(benchmark::kSecond)->Iterations(1);

BENCHMARK_MAIN();
