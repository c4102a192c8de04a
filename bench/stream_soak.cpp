// Long streaming runs of the engine (core/stream.hpp) in the ecef scene: the
// aircraft flight with 1 Hz knots, pushed knot by knot and every sample
// pulled, as the daemon does. For each output rate it prints
//  - resident memory (VmRSS) after 1, 2 and 4 hours of input: O(window) means
//    the three are equal,
//  - self-consistency over the whole run: every `every_s` seconds the emitted
//    IMU is integrated (Eq. 3.69, RK4, core/strapdown) for 10 s from the
//    emitted state and compared with the emitted trajectory 10 s later, as
//    the equivalent constant gyro (|dtheta|/T) and accelerometer (2|dp|/T^2)
//    error; max over the run,
//  - CPU per emitted sample (engine only) and the look-ahead it ran at.
//
//   stream_soak [HOURS=4] [RATE_HZ...]   (default rates 50 100 400 1000 2000 4000 10000)
#include <sys/resource.h>

#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <deque>
#include <fstream>
#include <string>
#include <vector>

#include "core/reference_motion.hpp"
#include "core/so3.hpp"
#include "core/strapdown.hpp"
#include "core/stream.hpp"

using namespace imuemu;

namespace {

long rss_kib() {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line))
    if (line.rfind("VmRSS:", 0) == 0) return std::strtol(line.c_str() + 6, nullptr, 10);
  return -1;
}

double cpu_s() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

}  // namespace

int main(int argc, char** argv) {
  const double hours = argc > 1 ? std::atof(argv[1]) : 4.0;
  std::vector<std::int64_t> rates;
  for (int a = 2; a < argc; ++a) rates.push_back(std::atoll(argv[a]));
  if (rates.empty()) rates = {50, 100, 400, 1000, 2000, 4000, 10000};
  const auto duration_ns = static_cast<TimeNs>(hours * 3600.0) * kNsPerSecond;
  const reference::AircraftFlight flight(Physics::ecef, reference::AircraftFlight::default_origin(), 0, duration_ns);
  const std::vector<Pose> knots = reference::sample_knots(flight, kNsPerSecond);
  std::printf("%.1f h flight, %zu knots at 1 Hz, ecef scene, default method (hermite, order-4 bump, Delta = one knot interval)\n",
              hours, knots.size());
  std::printf("| rate Hz | Delta | samples | RSS 1 h / 2 h / 4 h (KiB) | engine buffer (samples) | self-consistency gyro rad/s | accel m/s² | windows | CPU/sample | look-ahead s (max seen / bound) |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|\n");
  for (const std::int64_t rate : rates) {
    PipelineOptions o;
    o.scene.physics = Physics::ecef;
    o.rate_hz = rate;
    o.kernel.delta = static_cast<int>(rate);
    StreamPipeline engine(o);
    const std::size_t window = static_cast<std::size_t>(10 * rate) + (10 * rate) % 2;  // even: RK4 over two periods
    const auto every = static_cast<std::size_t>(60 * rate);                            // one window a minute
    std::vector<StreamSample> held;  // the current 10 s window, when one is open
    held.reserve(window + 1);
    std::size_t count = 0, windows = 0, max_buffered = 0;
    double gyro = 0.0, accel = 0.0, engine_cpu = 0.0;
    TimeNs max_lag = 0;
    long rss[3] = {-1, -1, -1};
    StreamSample s;
    auto take = [&] {
      while (engine.pop(s)) {
        // Skip the first and last minute: the ends are a different question.
        if (count % every == 0 && count >= every && held.empty()) held.push_back(s);
        else if (!held.empty()) held.push_back(s);
        ++count;
        if (held.size() == window + 1) {
          std::vector<ImuSample> imu;
          imu.reserve(held.size());
          for (const StreamSample& h : held) imu.push_back(h.imu);
          const Kinematics& k0 = held.front().kinematics;
          const Kinematics& k1 = held.back().kinematics;
          const auto states = strapdown::integrate(o.scene, {k0.t_ns, k0.position_m, k0.velocity_m_s, k0.attitude}, imu);
          const double T = seconds_between(k0.t_ns, k1.t_ns);
          gyro = std::max(gyro, so3::angle(k1.attitude.transpose() * states.back().attitude) / T);
          accel = std::max(accel, 2.0 * (states.back().position_m - k1.position_m).norm() / (T * T));
          ++windows;
          held.clear();
        }
      }
    };
    for (std::size_t k = 0; k < knots.size(); ++k) {
      const double c0 = cpu_s();
      engine.push(knots[k]);
      engine_cpu += cpu_s() - c0;
      max_buffered = std::max(max_buffered, engine.buffered_samples());
      max_lag = std::max(max_lag, engine.current_lag_ns());
      take();
      for (int h : {1, 2, 4})
        if (k == static_cast<std::size_t>(h) * 3600) rss[h == 4 ? 2 : h - 1] = rss_kib();
    }
    engine.finish();
    take();
    // Engine CPU: push() does all the work; pop() only moves samples out.
    std::printf("| %lld | %d | %zu | %ld / %ld / %ld | %zu | %.2e | %.2e | %zu | %.0f ns | %.2f / %.2f |\n",
                static_cast<long long>(rate), o.kernel.delta, count, rss[0], rss[1], rss[2], max_buffered, gyro, accel,
                windows, engine_cpu / static_cast<double>(count) * 1e9, static_cast<double>(max_lag) * 1e-9,
                static_cast<double>(StreamPipeline::lookahead_ns(o, kNsPerSecond)) * 1e-9);
    std::fflush(stdout);
  }
  return 0;
}
