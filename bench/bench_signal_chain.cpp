// CPU per output sample of a device's signal chain (core/signal_chain/,
// issue 16): DeviceChain::step at 1 kHz on 2 s of the aircraft flight (ecef),
// for the ideal chain (with and without the exact increments), the sensor
// model alone, filter chains at 8x oversampling (8 kHz internal) and
// everything together, sinusoidal and random vibration; then 16 devices at 1 kHz at 8x on one thread, each
// with its own streaming pipeline (core/stream.hpp), over 20 s of the flight:
// the share of one core that takes (real time if below 1).
//   build/release/bench/bench_signal_chain --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
#include <benchmark/benchmark.h>

#include <time.h>

#include <optional>
#include <string>
#include <vector>

#include "core/reference_motion.hpp"
#include "core/sensor/datasheet.hpp"
#include "core/signal_chain/signal_chain.hpp"
#include "core/stream.hpp"

using namespace imuemu;

namespace {

PipelineOptions flight_options(std::int64_t rate) {
  PipelineOptions o;
  o.scene.physics = Physics::ecef;
  o.rate_hz = rate;
  o.kernel.delta = static_cast<int>(rate);  // the product's default for 1 Hz knots
  return o;
}

std::vector<Pose> flight_knots(int seconds) {
  const reference::AircraftFlight flight(Physics::ecef, reference::AircraftFlight::default_origin(), 0,
                                         seconds * kNsPerSecond);
  return reference::sample_knots(flight, kNsPerSecond);
}

const std::vector<StreamSample>& flight_samples() {
  static const std::vector<StreamSample> samples = [] {
    std::vector<StreamSample> out;
    run_streaming(flight_knots(20), flight_options(1000), [&](const StreamSample& s) {
      if (out.size() < 2000) out.push_back(s);
    });
    return out;
  }();
  return samples;
}

struct Config {
  bool sensor = false;
  std::string preset = "ideal";
  std::optional<int> oversampling;
  std::optional<signal_chain::IncrementConvention> increments;
  signal_chain::VibrationSpec vibration;
};

// Three sinusoids (linear and angular) on a lever arm.
signal_chain::VibrationSpec sinusoids() {
  signal_chain::VibrationSpec v;
  signal_chain::Sinusoid a, b, c;
  a.frequency_hz = 120.0;
  a.linear_m_s2 = Vec3(2.0, 0.0, 1.0);
  b.frequency_hz = 77.0;
  b.linear_m_s2 = Vec3(0.0, 0.5, 0.0);
  c.frequency_hz = 90.0;
  c.angular_rad_s = Vec3(0.0, 0.3, 0.0);
  v.sinusoids = {a, b, c};
  v.lever_arm_m = Vec3(0.1, 0.05, -0.02);
  return v;
}

// A random profile of 20-500 Hz on three axes at 0.5 Hz resolution (2883 components).
signal_chain::VibrationSpec random_profile() {
  signal_chain::VibrationSpec v;
  signal_chain::RandomVibration r;
  r.psd = {{20.0, 0.002}, {80.0, 0.04}, {350.0, 0.04}, {500.0, 0.01}};
  v.random_linear = r;
  return v;
}

Config make_config(bool sensor, const std::string& preset, std::optional<int> oversampling,
                   std::optional<signal_chain::IncrementConvention> increments) {
  Config c;
  c.sensor = sensor;
  c.preset = preset;
  c.oversampling = oversampling;
  c.increments = increments;
  return c;
}

Config config(int i) {
  using C = signal_chain::IncrementConvention;
  switch (i) {
    case 1: return make_config(false, "ideal", std::nullopt, C::raw);          // ideal + raw increments (native)
    case 2: return make_config(false, "ideal", std::nullopt, C::compensated);  // ideal + compensated (MIP)
    case 3: return make_config(true, "ideal", std::nullopt, std::nullopt);     // icm42688p sensor model at 1 kHz
    case 4: return make_config(false, "stim300", 8, std::nullopt);             // 4th-order Butterworth at 8 kHz
    case 5: return make_config(false, "icm42688p", 8, std::nullopt);           // AAF + UI filter at 8 kHz
    case 6: return make_config(true, "icm42688p", 8, C::compensated);          // all of it
    case 7: {                                                                  // sinusoidal vibration, no chain
      Config c = make_config(false, "ideal", std::nullopt, C::compensated);
      c.vibration = sinusoids();
      return c;
    }
    case 8: {                                                                  // random vibration at 8x
      Config c = make_config(false, "ideal", 8, C::compensated);
      c.vibration = random_profile();
      return c;
    }
    default: return Config{};                                                  // ideal, no increments (generate)
  }
}

signal_chain::DeviceChain make_chain(const Config& c, const std::string& device) {
  signal_chain::ChainSpec spec;
  spec.preset = c.preset;
  spec.oversampling = c.oversampling;
  spec.vibration = c.vibration;
  std::optional<sensor::SensorModelSpec> s;
  if (c.sensor) {
    s = sensor::preset_spec("icm42688p");
    s->seed = 1;
  }
  return signal_chain::DeviceChain(flight_options(1000).scene, s, spec, 1000, device);
}

void BM_chain_step(benchmark::State& state) {
  const Config c = config(static_cast<int>(state.range(0)));
  const std::vector<StreamSample>& samples = flight_samples();
  std::uint64_t k = 0, steps = 0;
  std::optional<signal_chain::DeviceChain> chain;
  chain.emplace(make_chain(c, "imu0"));
  for (auto _ : state) {
    const std::size_t i = k % samples.size();
    if (i == 0 && k > 0) {
      state.PauseTiming();
      chain.emplace(make_chain(c, "imu0"));
      k = 0;
      state.ResumeTiming();
    }
    const Kinematics* prev = i > 0 ? &samples[i - 1].kinematics : nullptr;
    const signal_chain::ChainOutput o = chain->step(k, samples[i].kinematics, samples[i].imu, prev, c.increments);
    benchmark::DoNotOptimize(o);
    ++k;
    ++steps;
  }
  state.counters["ns_per_sample"] =
      benchmark::Counter(static_cast<double>(steps) * 1e-9, benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

double thread_cpu_s() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

// 16 devices at 1 kHz, each its own pipeline and chain, 20 s of flight pushed
// knot by knot on this one thread; core_share = CPU seconds / emulated seconds.
void sixteen_devices(benchmark::State& state, const Config& c) {
  const std::vector<Pose> knots = flight_knots(26);
  double cpu = 0.0;
  std::uint64_t outputs = 0;
  for (auto _ : state) {
    const double t0 = thread_cpu_s();
    std::vector<std::unique_ptr<StreamPipeline>> engines;
    std::vector<signal_chain::DeviceChain> chains;
    std::vector<std::optional<Kinematics>> previous(16);
    std::vector<std::uint64_t> next_k(16, 0);
    for (int d = 0; d < 16; ++d) {
      engines.push_back(std::make_unique<StreamPipeline>(flight_options(1000)));
      chains.push_back(make_chain(c, "imu" + std::to_string(d)));
    }
    StreamSample s;
    for (const Pose& p : knots) {
      for (int d = 0; d < 16; ++d) {
        engines[d]->push(p);
        while (engines[d]->pop(s) && next_k[d] < 20'000) {
          const Kinematics* prev = previous[d] ? &*previous[d] : nullptr;
          const signal_chain::ChainOutput o = chains[d].step(next_k[d], s.kinematics, s.imu, prev, c.increments);
          benchmark::DoNotOptimize(o);
          previous[d] = s.kinematics;
          ++next_k[d];
          ++outputs;
        }
      }
    }
    cpu += thread_cpu_s() - t0;
  }
  const double iterations = static_cast<double>(state.iterations());
  const double emulated_s = static_cast<double>(outputs) / iterations / 16.0 / 1000.0;  // per device
  state.counters["core_share"] = cpu / iterations / emulated_s;
  state.counters["outputs"] = static_cast<double>(outputs) / iterations;
}

void BM_sixteen_devices_1khz_ideal(benchmark::State& state) {
  sixteen_devices(state, config(2));
}
void BM_sixteen_devices_1khz_8x_chain(benchmark::State& state) { sixteen_devices(state, config(6)); }

}  // namespace

BENCHMARK(BM_chain_step)->DenseRange(0, 8)->Unit(benchmark::kNanosecond);
BENCHMARK(BM_sixteen_devices_1khz_ideal)->Unit(benchmark::kMillisecond)->Iterations(1);
BENCHMARK(BM_sixteen_devices_1khz_8x_chain)->Unit(benchmark::kMillisecond)->Iterations(1);

BENCHMARK_MAIN();
