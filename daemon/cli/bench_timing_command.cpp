// `imuemu bench timing`: see bench_timing_command.hpp.
//
// Two runs in one process, one after the other (run together they would
// disturb each other's timing):
//  1. the floor: a bare loop sleeping to absolute CLOCK_MONOTONIC deadlines
//     t0 + floor(k * 1e9 / rate) with clock_nanosleep(TIMER_ABSTIME), at the
//     same priority, doing nothing else; its lateness is what the machine
//     (kernel timer slack, scheduler, virtualisation) gives any thread;
//  2. the emission engine with N devices at that rate, native encoder into
//     NullTransport, on a flat circle.
// The ratio of their percentiles is what the emission path itself costs in
// timing; CPU % is the emission thread's CLOCK_THREAD_CPUTIME_ID over wall time.
#include "daemon/cli/bench_timing_command.hpp"

#include <pthread.h>
#include <sched.h>
#include <time.h>

#include <CLI/CLI.hpp>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <iostream>
#include <string>
#include <thread>
#include <vector>

#include "core/reference_motion.hpp"
#include "daemon/cli/cli_options.hpp"
#include "daemon/cli/commands.hpp"
#include "daemon/device/device.hpp"
#include "daemon/engine/emission.hpp"
#include "drivers/protocols/stream_protocols.hpp"

namespace imuemu::cli {
namespace {

struct FloorResult {
  emission::LatenessSummary lateness;
  std::uint64_t ticks = 0, misses = 0;
  TimeNs cpu_ns = 0, wall_ns = 0;
  std::string note;  // why SCHED_FIFO was refused
};

TimeNs thread_cpu_ns() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<TimeNs>(ts.tv_sec) * kNsPerSecond + ts.tv_nsec;
}

FloorResult bare_sleep_loop(std::int64_t rate_hz, std::uint64_t ticks, int priority) {
  FloorResult r;
  emission::LatenessHistogram histogram;
  std::thread t([&] {
    if (priority > 0) {
      sched_param sp{};
      sp.sched_priority = priority;
      if (const int rc = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp); rc != 0) r.note = std::strerror(rc);
    }
    const TimeNs period_ns = kNsPerSecond / rate_hz;
    const TimeNs cpu0 = thread_cpu_ns();
    const TimeNs t0 = emission::monotonic_now_ns() + 20'000'000;
    for (std::uint64_t k = 0; k < ticks; ++k) {
      const TimeNs due = t0 + static_cast<TimeNs>((k / static_cast<std::uint64_t>(rate_hz)) * kNsPerSecond) +
                         static_cast<TimeNs>(k % static_cast<std::uint64_t>(rate_hz)) * kNsPerSecond / rate_hz;
      timespec ts{static_cast<time_t>(due / kNsPerSecond), static_cast<long>(due % kNsPerSecond)};
      while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
      }
      const TimeNs lateness = emission::monotonic_now_ns() - due;
      histogram.record(lateness);
      if (lateness > period_ns) ++r.misses;
    }
    r.cpu_ns = thread_cpu_ns() - cpu0;
    r.wall_ns = emission::monotonic_now_ns() - t0;
  });
  t.join();
  r.ticks = ticks;
  r.lateness = histogram.summary();
  return r;
}

void print_row(const char* label, const emission::LatenessSummary& l, std::uint64_t misses) {
  std::printf("%-22s %10.1f %10.1f %10.1f %10.1f %10llu\n", label, static_cast<double>(l.p50_ns) / 1e3,
              static_cast<double>(l.p99_ns) / 1e3, static_cast<double>(l.p999_ns) / 1e3,
              static_cast<double>(l.max_ns) / 1e3, static_cast<unsigned long long>(misses));
}

double ratio(TimeNs a, TimeNs b) { return b > 0 ? static_cast<double>(a) / static_cast<double>(b) : NAN; }

}  // namespace

int bench_timing(const BenchTimingArgs& a) {
  const auto ticks = static_cast<std::uint64_t>(std::llround(a.seconds * static_cast<double>(a.rate_hz)));
  if (ticks == 0) {
    std::cerr << "imuemu bench timing: --seconds x --rate gives no tick\n";
    return kUsageError;
  }
  const FloorResult floor = bare_sleep_loop(a.rate_hz, ticks, a.priority);

  const reference::Circle circle(200.0, 20.0, 0, static_cast<TimeNs>(std::ceil(a.seconds + 3.0)) * kNsPerSecond);
  emission::EngineOptions eo;
  eo.trajectory = reference::sample_knots(circle, kNsPerSecond);
  eo.max_ticks_per_device = ticks;
  eo.realtime.priority = a.priority;
  std::vector<emission::DeviceOptions> devices;
  for (int i = 0; i < a.devices; ++i) {
    emission::DeviceOptions d;
    d.name = "imu" + std::to_string(i);
    d.rate_hz = a.rate_hz;
    d.pipeline.scene.physics = Physics::flat;
    d.pipeline.kernel.delta = static_cast<int>(a.rate_hz);  // one knot interval
    drivers::StreamEncoderOptions so;
    so.nominal_sample_rate_hz = static_cast<double>(a.rate_hz);
    d.device = device::make_stream_device(drivers::make_stream_encoder(a.protocol, so),
                                          std::make_unique<drivers::NullTransport>());
    devices.push_back(std::move(d));
  }
  emission::EngineStats s;
  try {
    emission::EmissionEngine engine(std::move(eo), std::move(devices));
    engine.start();
    engine.wait();
    engine.stop();
    s = engine.stats();
  } catch (const std::exception& e) {
    std::cerr << "imuemu bench timing: " << e.what() << "\n";
    return kCannotProcess;
  }

  std::uint64_t dropped = 0, late = 0;
  for (const auto& d : s.devices) {
    dropped += d.dropped_late;
    late += d.producer_late;
  }
  std::printf("imuemu bench timing: %lld Hz x %g s, %d device(s) (%s -> null), %s\n",
              static_cast<long long>(a.rate_hz), a.seconds, a.devices, a.protocol.c_str(),
              a.priority == 0 ? "normal scheduling"
                              : (s.realtime_priority ? ("SCHED_FIFO " + std::to_string(a.priority)).c_str()
                                                     : ("SCHED_FIFO refused (" + s.realtime_note + ")").c_str()));
  std::printf("%-22s %10s %10s %10s %10s %10s\n", "lateness (us)", "p50", "p99", "p99.9", "max", "misses");
  print_row("bare clock_nanosleep", floor.lateness, floor.misses);
  print_row("emission path", s.lateness, s.deadline_misses);
  std::printf("%-22s %10.2f %10.2f %10.2f %10.2f\n", "ratio (emission/bare)", ratio(s.lateness.p50_ns, floor.lateness.p50_ns),
              ratio(s.lateness.p99_ns, floor.lateness.p99_ns), ratio(s.lateness.p999_ns, floor.lateness.p999_ns),
              ratio(s.lateness.max_ns, floor.lateness.max_ns));
  const std::uint64_t expected = ticks * static_cast<std::uint64_t>(a.devices);
  std::printf("emitted %llu of %llu expected (rate x seconds x devices); not sent: %llu after a deadline miss, %llu producer late\n",
              static_cast<unsigned long long>(s.emitted), static_cast<unsigned long long>(expected),
              static_cast<unsigned long long>(dropped), static_cast<unsigned long long>(late));
  const double wall_s = static_cast<double>(s.emission_wall_ns) * 1e-9;
  std::printf("CPU of one core: emission thread %.3f%% (%.1f ms in %.2f s, %.2f us per sample), producer %.2f%%, bare loop %.3f%%\n",
              wall_s > 0 ? 100.0 * static_cast<double>(s.emission_cpu_ns) * 1e-9 / wall_s : 0.0,
              static_cast<double>(s.emission_cpu_ns) * 1e-6, wall_s,
              s.emitted > 0 ? static_cast<double>(s.emission_cpu_ns) * 1e-3 / static_cast<double>(s.emitted) : 0.0,
              wall_s > 0 ? 100.0 * static_cast<double>(s.producer_cpu_ns) * 1e-9 / wall_s : 0.0,
              floor.wall_ns > 0 ? 100.0 * static_cast<double>(floor.cpu_ns) / static_cast<double>(floor.wall_ns) : 0.0);
  return kOk;
}

void add_bench_timing_command(CLI::App& app, int& exit_code) {
  CLI::App* bench = nullptr;
  try {
    bench = app.get_subcommand("bench");
  } catch (const CLI::OptionNotFound&) {
    bench = app.add_subcommand("bench", "Measurements of this machine and build");
    bench->require_subcommand(1);
  }
  auto args = std::make_shared<BenchTimingArgs>();
  auto* c = bench->add_subcommand("timing", "Emission lateness and CPU against a bare clock_nanosleep loop at the same rate");
  c->add_option("--rate", args->rate_hz, "Output rate (Hz)")->capture_default_str()->check(CLI::Range(1, 1000000));
  c->add_option("--seconds", args->seconds, "Duration of each run")->capture_default_str()->check(seconds_in(0.0, kMaxDurationS, true));
  c->add_option("--devices", args->devices, "Devices on the emission thread")->capture_default_str()->check(CLI::Range(1, 64));
  c->add_option("--priority", args->priority, "SCHED_FIFO priority (1..99; 0: normal)")->capture_default_str()->check(CLI::Range(0, 99));
  c->add_option("--protocol", args->protocol, "Stream encoder")->capture_default_str()
      ->check(CLI::IsMember(drivers::stream_protocol_names()));
  c->callback([args, &exit_code] { exit_code = bench_timing(*args); });
}

}  // namespace imuemu::cli
