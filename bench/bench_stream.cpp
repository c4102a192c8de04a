// CPU per emitted sample of the streaming engine (core/stream.hpp) at 100,
// 400, 1000 and 4000 Hz: a 60 s stretch of the aircraft flight (1 Hz knots,
// ecef scene) is pushed knot by knot and every sample pulled, as the daemon
// does. Two windows: 1 s in total (Delta = rate/2, support +-0.5 s) and the
// product's default for 1 Hz knots (Delta = rate, +-1 s).
//   build/release/bench/bench_stream --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
// cpu_per_sample is CPU time per emitted sample; look-ahead is
// StreamPipeline::lookahead_ns for 1 s knot spacing.
#include <benchmark/benchmark.h>

#include "core/reference_motion.hpp"
#include "core/stream.hpp"

using namespace imuemu;

namespace {

const std::vector<Pose>& flight_knots() {
  static const std::vector<Pose> knots = [] {
    const reference::AircraftFlight flight(Physics::ecef, reference::AircraftFlight::default_origin(), 0,
                                           60 * kNsPerSecond);
    return reference::sample_knots(flight, kNsPerSecond);
  }();
  return knots;
}

void stream_flight(benchmark::State& state, bool one_second_window) {
  const std::int64_t rate = state.range(0);
  PipelineOptions o;
  o.scene.physics = Physics::ecef;
  o.rate_hz = rate;
  o.kernel.delta = static_cast<int>(one_second_window ? rate / 2 : rate);
  const std::vector<Pose>& knots = flight_knots();
  std::size_t samples = 0;
  for (auto _ : state) {
    StreamPipeline engine(o);
    StreamSample s;
    for (const Pose& k : knots) {
      engine.push(k);
      while (engine.pop(s)) ++samples;
    }
    engine.finish();
    while (engine.pop(s)) ++samples;
    benchmark::DoNotOptimize(s);
  }
  // Seconds of CPU per emitted sample (printed with an SI prefix: "812n" = 812 ns).
  state.counters["cpu_per_sample"] =
      benchmark::Counter(static_cast<double>(samples), benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
  state.counters["lookahead_s"] = static_cast<double>(StreamPipeline::lookahead_ns(o, kNsPerSecond)) * 1e-9;
  state.counters["delta"] = o.kernel.delta;
}

void BM_stream_window_1s(benchmark::State& state) { stream_flight(state, true); }
void BM_stream_default_window(benchmark::State& state) { stream_flight(state, false); }

}  // namespace

BENCHMARK(BM_stream_window_1s)->Arg(100)->Arg(400)->Arg(1000)->Arg(4000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_stream_default_window)->Arg(100)->Arg(400)->Arg(1000)->Arg(4000)->Unit(benchmark::kMillisecond);

BENCHMARK_MAIN();
