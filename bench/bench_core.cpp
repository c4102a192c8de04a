// Speed of the core maths (acceptance item 6 of the foundation issue):
// ns per call for exp and log, smoothing cost per output sample at
// Delta = 10, 50, 500, and whole-pipeline samples/s for a one-hour 1 Hz
// trajectory at 400 Hz. Run: build/release/bench/bench_core
#include <benchmark/benchmark.h>

#include <random>
#include <vector>

#include "core/pipeline.hpp"
#include "core/reference_motion.hpp"
#include "core/smoothing.hpp"
#include "core/so3.hpp"

using namespace imuemu;

namespace {
std::vector<Vec3> random_rotation_vectors(std::size_t n, double max_angle) {
  std::mt19937_64 rng(7);
  std::normal_distribution<double> n01;
  std::uniform_real_distribution<double> u(0.0, max_angle);
  std::vector<Vec3> v(n);
  for (Vec3& r : v) r = Vec3(n01(rng), n01(rng), n01(rng)).normalized() * u(rng);
  return v;
}
}  // namespace

static void BM_so3_exp(benchmark::State& state) {
  const auto rs = random_rotation_vectors(1024, 3.14);
  std::size_t i = 0;
  for (auto _ : state) benchmark::DoNotOptimize(so3::exp(rs[i++ & 1023]));
}
BENCHMARK(BM_so3_exp);

static void BM_so3_log(benchmark::State& state) {
  std::vector<Mat3> Rs;
  for (const Vec3& r : random_rotation_vectors(1024, 3.14)) Rs.push_back(so3::exp(r));
  std::size_t i = 0;
  for (auto _ : state) benchmark::DoNotOptimize(so3::log(Rs[i++ & 1023]));
}
BENCHMARK(BM_so3_log);

static void BM_so3_W(benchmark::State& state) {
  const auto rs = random_rotation_vectors(1024, 3.14);
  std::size_t i = 0;
  for (auto _ : state) benchmark::DoNotOptimize(so3::W(rs[i++ & 1023]));
}
BENCHMARK(BM_so3_W);

// Eq. 3.68 for one output sample (one Vec3 channel), window +-Delta.
static void BM_smooth_per_sample(benchmark::State& state) {
  const int delta = static_cast<int>(state.range(0));
  const auto f = random_rotation_vectors(4096 + 2 * static_cast<std::size_t>(delta), 1.0);
  const smoothing::UniformKernel kernel({delta, smoothing::KernelWidth::window, 0.0}, 1.0 / 400);
  std::size_t i = static_cast<std::size_t>(delta);
  for (auto _ : state) {
    benchmark::DoNotOptimize(smoothing::smooth_at(kernel, f, i));
    if (++i == f.size() - static_cast<std::size_t>(delta)) i = static_cast<std::size_t>(delta);
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_smooth_per_sample)->Arg(10)->Arg(50)->Arg(500);

// The whole batch pipeline: one hour of 1 Hz knots (ecef flight) -> 400 Hz.
// config 0: the product default (Hermite base, 4th-order kernel, local chart,
// kernel derivatives, extrapolated ends); config 1: the thesis baseline
// (geodesic, literal Eq. 3.68 kernel, global chart, Eq. 3.71-3.74, clipped
// ends) at the same window.
static void BM_pipeline_one_hour_400Hz(benchmark::State& state) {
  const reference::AircraftFlight flight(Physics::ecef);
  const std::vector<Pose> knots = reference::sample_knots(flight, kNsPerSecond);
  PipelineOptions opt;
  opt.scene.physics = Physics::ecef;
  opt.rate_hz = 400;
  opt.kernel.delta = static_cast<int>(state.range(0));
  if (state.range(1) == 1) {
    opt.interpolation.method = interp::Method::geodesic;
    opt.kernel.width = smoothing::KernelWidth::thesis;
    opt.kernel.order = 2;
    opt.chart = Chart::global;
    opt.derivatives = Derivatives::finite_difference;
    opt.ends = Ends::clip;
  }
  std::size_t samples = 0;
  for (auto _ : state) {
    const BatchResult r = run_batch(knots, opt);
    samples += r.imu.size();
    benchmark::DoNotOptimize(r.imu.back());
  }
  state.counters["samples_per_s"] = benchmark::Counter(static_cast<double>(samples), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_pipeline_one_hour_400Hz)
    ->ArgNames({"delta", "thesis"})
    ->Args({400, 0})
    ->Args({400, 1})
    ->Args({50, 0})
    ->Args({50, 1})
    ->Unit(benchmark::kMillisecond)
    ->Iterations(2);

BENCHMARK_MAIN();
