// Trajectory CSV parsing speed: records/s for a 4-hour 100 Hz file (1.44 M
// lines). Run: build/release/bench/bench_io
#include <benchmark/benchmark.h>

#include <charconv>
#include <string>

#include "io/trajectory_csv.hpp"

static void BM_parse_trajectory_csv(benchmark::State& state) {
  const int records = static_cast<int>(state.range(0));
  std::string text = "time_s,lat_deg,lon_deg,h_m,heading_deg,pitch_deg,roll_deg\n";
  text.reserve(static_cast<std::size_t>(records) * 90);
  char buf[64];
  for (int i = 0; i < records; ++i) {
    text += std::to_string(i / 100) + "." + (i % 100 < 10 ? "0" : "") + std::to_string(i % 100);
    for (double v : {41.3 + i * 1e-7, 2.17 + i * 1e-7, 1000.0 + i * 1e-3, 15.0 + i * 1e-5, 1.5, -11.0}) {
      const auto r = std::to_chars(buf, buf + sizeof buf, v);
      text += ',';
      text.append(buf, r.ptr);
    }
    text += '\n';
  }
  for (auto _ : state) {
    const auto t = imuemu::io::parse_trajectory_csv(text, "bench.csv");
    benchmark::DoNotOptimize(t.records.data());
  }
  state.SetItemsProcessed(state.iterations() * records);
}
BENCHMARK(BM_parse_trajectory_csv)->Arg(1'440'000)->Unit(benchmark::kMillisecond)->Iterations(3);

BENCHMARK_MAIN();
