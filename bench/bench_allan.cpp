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

BENCHMARK_MAIN();
