// The accuracy report: every trajectory-to-IMU method over the reference set
// (analytic aircraft-like flight, knots at 1 Hz; output at 100, 400, 1000 and
// 2000 Hz; flat and ecef scenes), against analytic truth.
//
//   accuracy_report OUT_DIR [--quick]
//
// writes OUT_DIR/accuracy.csv and OUT_DIR/accuracy.md; scripts/accuracy_report.sh
// runs it and plots docs/accuracy_speed_vs_error.png. Columns:
//  - gyro/accel RMS and max error against truth (first/last 5 s excluded:
//    methods differ in how far they reach past the ends, reported separately),
//  - self-consistency: emitted IMU integrated (Eq. 3.69, RK4) for 10 s from
//    each emitted state and compared with the emitted trajectory 10 s later,
//    expressed as the equivalent constant gyro (|dtheta|/T) and accelerometer
//    (2|dp|/T^2) error; max over the run,
//  - closed-loop drift after one hour at 100 Hz (ecef: vertical channel aided),
//  - look-ahead latency: how far past an output time the method needs poses,
//  - throughput: output samples per CPU second, one core.
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <string>
#include <vector>

#include "core/bspline.hpp"
#include "core/naive_spline.hpp"
#include "core/pipeline.hpp"
#include "core/reference_motion.hpp"
#include "core/so3.hpp"
#include "core/strapdown.hpp"
#include "core/stream.hpp"

using namespace imuemu;

namespace {

struct Method {
  std::string name;
  std::string description;
  // Runs the method on knots (1 Hz) at rate_hz.
  std::function<BatchResult(const std::vector<Pose>&, const SceneModel&, std::int64_t)> run;
  // Look-ahead in seconds for 1 s knots at rate_hz.
  std::function<double(std::int64_t)> lookahead_s;
};

PipelineOptions thesis_options(const SceneModel& scene, std::int64_t rate) {
  // Appendix C: geodesic, literal kernel (t in seconds), Delta = +-1 s,
  // global chart, finite differences, one-sided end windows.
  PipelineOptions o;
  o.scene = scene;
  o.rate_hz = rate;
  o.chart = Chart::global;
  o.derivatives = Derivatives::finite_difference;
  o.ends = Ends::clip;
  o.interpolation.method = interp::Method::geodesic;
  o.kernel = {static_cast<int>(rate), smoothing::KernelWidth::thesis, 1.0, 2};
  return o;
}

// The product default (and the CLI's): C2 Hermite base, fourth-order bump
// over +-1 knot interval, local chart, kernel derivatives, extrapolated ends.
PipelineOptions default_options(const SceneModel& scene, std::int64_t rate) {
  PipelineOptions o;
  o.scene = scene;
  o.rate_hz = rate;
  o.kernel.delta = static_cast<int>(rate);
  return o;
}

// What the streaming engine (which run_batch loops over) needs beyond an
// output time for 1 s knots: window, chart blocks, spline look-ahead.
double engine_lookahead_s(const PipelineOptions& o) {
  return static_cast<double>(StreamPipeline::lookahead_ns(o, kNsPerSecond)) * 1e-9;
}

std::vector<Method> methods() {
  std::vector<Method> m;
  m.push_back({"thesis", "geodesic + literal Eq. 3.68 (+-1 s) on log R + Eq. 3.71-3.74 (Appendix C)",
               [](const auto& k, const auto& s, auto r) { return run_batch(k, thesis_options(s, r)); },
               [](std::int64_t r) { return engine_lookahead_s(thesis_options({}, r)); }});
  m.push_back({"thesis-window", "as thesis, window kernel +-2 s",
               [](const auto& k, const auto& s, auto r) {
                 PipelineOptions o = thesis_options(s, r);
                 o.kernel = {static_cast<int>(2 * r), smoothing::KernelWidth::window, 0.0, 2};
                 return run_batch(k, o);
               },
               [](std::int64_t r) {
                 PipelineOptions o = thesis_options({}, r);
                 o.kernel = {static_cast<int>(2 * r), smoothing::KernelWidth::window, 0.0, 2};
                 return engine_lookahead_s(o);
               }});
  m.push_back({"imuemu-fd", "default but finite differences (Eq. 3.71-3.74)",
               [](const auto& k, const auto& s, auto r) {
                 PipelineOptions o = default_options(s, r);
                 o.derivatives = Derivatives::finite_difference;
                 return run_batch(k, o);
               },
               [](std::int64_t r) {
                 PipelineOptions o = default_options({}, r);
                 o.derivatives = Derivatives::finite_difference;
                 return engine_lookahead_s(o);
               }});
  m.push_back({"geodesic-local", "geodesic + bump +-2 s, local chart, kernel derivatives, extrapolated ends",
               [](const auto& k, const auto& s, auto r) {
                 PipelineOptions o = default_options(s, r);
                 o.interpolation.method = interp::Method::geodesic;
                 o.kernel = {static_cast<int>(2 * r), smoothing::KernelWidth::window, 0.0, 2};
                 return run_batch(k, o);
               },
               [](std::int64_t r) {
                 PipelineOptions o = default_options({}, r);
                 o.interpolation.method = interp::Method::geodesic;
                 o.kernel = {static_cast<int>(2 * r), smoothing::KernelWidth::window, 0.0, 2};
                 return engine_lookahead_s(o);
               }});
  m.push_back({"imuemu", "default: C2 Hermite in local charts, 4th-order bump +-1 s, kernel derivatives",
               [](const auto& k, const auto& s, auto r) { return run_batch(k, default_options(s, r)); },
               // +-1 s window, the chart blocks and the spline's +-4 knots.
               [](std::int64_t r) { return engine_lookahead_s(default_options({}, r)); }});
  m.push_back({"bspline", "cumulative cubic B-spline on SO(3) x R3 (Sommer et al. 2020)",
               [](const auto& k, const auto& s, auto r) { return bspline::run(k, s, r); },
               [](std::int64_t) { return 2.0; }});
  m.push_back({"naive", "natural cubic splines on heading/pitch/roll and position",
               [](const auto& k, const auto& s, auto r) { return naive::run(k, s, r); },
               [](std::int64_t) { return std::numeric_limits<double>::infinity(); }});
  return m;
}

// Integrates the emitted IMU from emitted states over windows of `window`
// samples; returns {equivalent gyro error, equivalent accel error}.
std::pair<double, double> self_consistency(const BatchResult& out, const SceneModel& scene, std::size_t window,
                                           std::size_t skip) {
  double gyro = 0, accel = 0;
  if (window % 2) ++window;  // RK4 over two periods: states at even offsets
  for (std::size_t start = skip; start + window + skip < out.imu.size(); start += window) {
    const Kinematics& k0 = out.trajectory[start];
    std::vector<ImuSample> samples(out.imu.begin() + static_cast<std::ptrdiff_t>(start),
                                   out.imu.begin() + static_cast<std::ptrdiff_t>(start + window + 1));
    const auto states = strapdown::integrate(scene, {k0.t_ns, k0.position_m, k0.velocity_m_s, k0.attitude}, samples);
    const Kinematics& k1 = out.trajectory[start + window];
    const strapdown::NavState& s1 = states.back();
    const double T = seconds_between(k0.t_ns, k1.t_ns);
    gyro = std::max(gyro, so3::angle(k1.attitude.transpose() * s1.attitude) / T);
    accel = std::max(accel, 2.0 * (s1.position_m - k1.position_m).norm() / (T * T));
  }
  return {gyro, accel};
}

std::pair<double, double> closed_loop_one_hour(const Method& m, Physics physics) {
  const reference::AircraftFlight flight(physics);
  SceneModel scene;
  scene.physics = physics;
  const BatchResult out = m.run(reference::sample_knots(flight, kNsPerSecond), scene, 100);
  // Start past the ends' reach (5 s), like `imuemu verify --start-s`.
  const std::size_t start = 500;
  const Kinematics& k0 = out.trajectory[start];
  std::vector<ImuSample> samples(out.imu.begin() + static_cast<std::ptrdiff_t>(start), out.imu.end() - 500);
  if (samples.size() % 2 == 0) samples.pop_back();
  std::vector<strapdown::NavState> reference;
  for (std::size_t i = start; i < start + samples.size(); ++i)
    reference.push_back({out.trajectory[i].t_ns, out.trajectory[i].position_m, out.trajectory[i].velocity_m_s,
                         out.trajectory[i].attitude});
  strapdown::Options opt;
  opt.aid_vertical = physics == Physics::ecef;
  const auto states =
      strapdown::integrate(scene, {k0.t_ns, k0.position_m, k0.velocity_m_s, k0.attitude}, samples, opt, reference);
  double pos = 0, att = 0;
  for (std::size_t j = 0; j < states.size(); ++j) {
    const strapdown::NavState& r = reference[2 * j];
    pos = std::max(pos, (states[j].position_m - r.position_m).norm());
    att = std::max(att, so3::angle(r.attitude.transpose() * states[j].attitude));
  }
  return {pos, att};
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::cerr << "usage: accuracy_report OUT_DIR [--quick]\n";
    return 2;
  }
  const std::filesystem::path dir = argv[1];
  const bool quick = argc > 2 && std::string(argv[2]) == "--quick";
  std::filesystem::create_directories(dir);
  const TimeNs duration = (quick ? 120 : 600) * kNsPerSecond;
  const std::vector<std::int64_t> rates = quick ? std::vector<std::int64_t>{100, 400}
                                                : std::vector<std::int64_t>{100, 400, 1000, 2000};
  std::ofstream csv(dir / "accuracy.csv");
  csv << "method,scene,rate_hz,gyro_rms_rad_s,gyro_max_rad_s,accel_rms_m_s2,accel_max_m_s2,self_gyro_rad_s,"
         "self_accel_m_s2,lookahead_s,samples_per_cpu_s\n";
  std::ofstream md(dir / "accuracy.md");
  md << "| method | scene | rate Hz | gyro RMS rad/s | gyro max | accel RMS m/s² | accel max | self-consistency gyro | "
        "self-consistency accel | look-ahead s | samples/s (1 core) |\n|---|---|---|---|---|---|---|---|---|---|---|\n";
  char line[1024];
  for (const Method& m : methods()) {
    for (Physics physics : {Physics::flat, Physics::ecef}) {
      const reference::AircraftFlight flight(physics, reference::AircraftFlight::default_origin(), 0, duration);
      SceneModel scene;
      scene.physics = physics;
      const std::vector<Pose> knots = reference::sample_knots(flight, kNsPerSecond);
      for (std::int64_t rate : rates) {
        const std::clock_t c0 = std::clock();
        const BatchResult out = m.run(knots, scene, rate);
        const double cpu_s = static_cast<double>(std::clock() - c0) / CLOCKS_PER_SEC;
        const reference::ImuErrors e = reference::compare_with_truth(
            out.imu, flight, scene, flight.start_ns() + 5 * kNsPerSecond, flight.end_ns() - 5 * kNsPerSecond);
        const auto [self_g, self_a] =
            self_consistency(out, scene, static_cast<std::size_t>(10 * rate), static_cast<std::size_t>(5 * rate));
        const double throughput = static_cast<double>(out.imu.size()) / std::max(cpu_s, 1e-9);
        const char* scene_name = physics == Physics::flat ? "flat" : "ecef";
        std::snprintf(line, sizeof line, "%s,%s,%lld,%.3e,%.3e,%.3e,%.3e,%.3e,%.3e,%.1f,%.4g\n", m.name.c_str(),
                      scene_name, static_cast<long long>(rate), e.gyro_rms_rad_s, e.gyro_max_rad_s, e.accel_rms_m_s2, e.accel_max_m_s2,
                      self_g, self_a, m.lookahead_s(rate), throughput);
        csv << line;
        std::snprintf(line, sizeof line, "| %s | %s | %lld | %.2e | %.2e | %.2e | %.2e | %.2e | %.2e | %.1f | %.3g |\n",
                      m.name.c_str(), scene_name, static_cast<long long>(rate), e.gyro_rms_rad_s, e.gyro_max_rad_s, e.accel_rms_m_s2,
                      e.accel_max_m_s2, self_g, self_a, m.lookahead_s(rate), throughput);
        md << line;
        std::cout << line << std::flush;
      }
    }
  }
  md << "\nClosed loop, one hour at 100 Hz (ideal IMU integrated back with RK4, Eq. 3.69; ecef vertical aided):\n\n"
        "| method | scene | max position drift m | max attitude drift rad |\n|---|---|---|---|\n";
  for (const Method& m : methods()) {
    if (quick) break;
    for (Physics physics : {Physics::flat, Physics::ecef}) {
      const auto [pos, att] = closed_loop_one_hour(m, physics);
      std::snprintf(line, sizeof line, "| %s | %s | %.2e | %.2e |\n", m.name.c_str(),
                    physics == Physics::flat ? "flat" : "ecef", pos, att);
      md << line;
      std::cout << line << std::flush;
    }
  }
  return 0;
}
