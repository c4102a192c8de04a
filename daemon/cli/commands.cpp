#include "daemon/cli/commands.hpp"

#include <unistd.h>

#include <algorithm>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <numbers>
#include <unordered_map>

#include "core/attitude.hpp"
#include "core/limits.hpp"
#include "core/time_arith.hpp"
#include "daemon/cli/cli_options.hpp"
#include "core/mounting.hpp"
#include "core/stream.hpp"
#include "daemon/cli/batch_generation.hpp"
#include "daemon/scene/error_model_config.hpp"
#include "daemon/scene/fault_config.hpp"
#include "daemon/scene/scene_runner.hpp"
#include "core/earth.hpp"
#include "core/pipeline.hpp"
#include "core/reference_motion.hpp"
#include "core/so3.hpp"
#include "core/strapdown.hpp"
#include "io/atomic_file.hpp"
#include "io/decimal_time.hpp"
#include "io/sample_trajectory.hpp"
#include "io/sample_writers.hpp"
#include "io/scene_poses.hpp"
#include "io/trajectory_csv.hpp"

namespace imuemu::cli {
namespace {

constexpr double kRadToDeg = 180.0 / std::numbers::pi;

// A one-line progress bar on stderr, shown only on a terminal and only once a
// run has taken longer than a second (short runs stay silent).
class ProgressBar {
 public:
  explicit ProgressBar(bool enabled) : enabled_(enabled && ::isatty(STDERR_FILENO) == 1) {}
  ~ProgressBar() {
    if (shown_) std::fputs("\n", stderr);
  }
  void update(double fraction) {
    if (!enabled_) return;
    const auto elapsed = std::chrono::steady_clock::now() - start_;
    if (elapsed < std::chrono::seconds(1)) return;
    shown_ = true;
    constexpr int kWidth = 40;
    const int filled = static_cast<int>(std::clamp(fraction, 0.0, 1.0) * kWidth);
    std::fprintf(stderr, "\r[%.*s%*s] %3d%%", filled, "########################################",
                 kWidth - filled, "", static_cast<int>(fraction * 100.0));
    std::fflush(stderr);
  }

 private:
  bool enabled_;
  bool shown_ = false;
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
};

std::string number(double v) {
  char buf[64];
  const auto res = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, res.ptr);
}

// Default window in median knot intervals: the C2 Hermite base curve needs
// only +-1; the two-point methods' chord polygon has impulsive acceleration at
// the knots, and a bump one interval wide leaves an 18% ripple at the knot
// rate, two intervals 0.7% (tests/core/test_pipeline.cpp, circle).
// The window is capped where every window is (limits::kMaxWindowSamples):
// two knots an hour apart at 4 kHz asked for 14.4 million samples.
int auto_delta(const std::vector<Pose>& knots, std::int64_t rate_hz, double intervals) {
  if (knots.size() < 2) return 0;
  std::vector<TimeNs> steps;
  for (std::size_t i = 1; i < knots.size(); ++i) steps.push_back(knots[i].t_ns - knots[i - 1].t_ns);
  std::nth_element(steps.begin(), steps.begin() + static_cast<std::ptrdiff_t>(steps.size() / 2), steps.end());
  const double median_s = static_cast<double>(steps[steps.size() / 2]) * 1e-9;
  const std::optional<int> delta = window_samples(intervals * median_s, rate_hz);
  if (!delta)
    throw limits::SizeLimitError("the automatic window (" + number(intervals) + " median knot interval(s) of " +
                                 number(median_s) + " s at " + std::to_string(rate_hz) + " Hz) is more than " +
                                 std::to_string(limits::kMaxWindowSamples) +
                                 " samples; give --delta or a lower --rate, or add knots");
  return *delta;
}

Physics physics_from(const std::string& scene) { return scene == "flat" ? Physics::flat : Physics::ecef; }

SceneModel scene_model(const std::string& scene, double gravity_m_s2) {
  SceneModel m;
  m.physics = physics_from(scene);
  m.flat_gravity_m_s2 = Vec3(0.0, 0.0, gravity_m_s2);
  return m;
}

// Errors from files become messages with the file:line:column the reader put
// in them, and a meaningful exit code.
template <typename Fn>
int run_guarded(Fn&& fn) {
  try {
    return fn();
  } catch (const UsageError& e) {
    std::cerr << "imuemu: " << e.what() << "\n";
    return kUsageError;
  } catch (const io::CsvFormatError& e) {
    std::cerr << "imuemu: " << e.what() << "\n";
    return kBadInput;
  } catch (const scene::SceneError& e) {
    std::cerr << "imuemu: " << e.what() << "\n";
    return kBadInput;
  } catch (const interp::InterpolationError& e) {
    std::cerr << "imuemu: cannot interpolate: " << e.what() << "\n";
    return kCannotProcess;
  } catch (const std::invalid_argument& e) {
    std::cerr << "imuemu: " << e.what() << "\n";
    return kCannotProcess;
  } catch (const std::system_error& e) {
    std::cerr << "imuemu: " << e.what() << "\n";
    return kOutputError;
  } catch (const std::exception& e) {
    std::cerr << "imuemu: internal error: " << e.what() << "\n";
    return kInternalError;
  }
}

// The sensor stage of `generate` (daemon/cli/batch_generation.hpp SensorStage):
// the same SensorModel::measure on sample k as imuemud's producer on tick k.
void describe_sensor_stage(const scene::ErrorModelConfig& model, const std::string& device, std::int64_t rate_hz,
                           bool quiet) {
  if (model.ideal() || quiet) return;
  for (const std::string& line : scene::error_model_lines(model, static_cast<double>(rate_hz)))
    std::cerr << "imuemu: sensor " << device << ": " << line << "\n";
}

void report_saturation(const std::string& device, std::uint64_t saturated, bool quiet) {
  if (!quiet && saturated > 0)
    std::cerr << "imuemu: sensor " << device << ": " << saturated << " samples saturated (clipped to the range)\n";
}

}  // namespace

namespace {

// generate --scene-file: the batch pipeline over exactly what imuemud feeds
// one device (scene_runner.hpp), so the two can be compared sample by sample.
int generate_for_scene(const GenerateArgs& args) {
  const scene::SceneConfig sc = scene::parse_scene_file(args.scene_file);
  const scene::ImuConfig* imu = nullptr;
  for (const scene::ImuConfig& i : sc.imus)
    if (args.imu_name.empty() ? imu == nullptr : i.name == args.imu_name) imu = &i;
  if (imu == nullptr)
    throw std::invalid_argument("scene " + args.scene_file + " has no [[imu]] named '" + args.imu_name + "'");
  const PipelineOptions opt = scene::pipeline_options(sc, *imu);
  std::vector<Pose> knots;
  for (const Pose& p : scene::scene_trajectory(sc)) knots.push_back(sensor_pose(p, imu->mounting));
  TimeNs end_ns = std::numeric_limits<TimeNs>::max();
  if (args.max_seconds > 0 && knots.size() >= 2) {
    end_ns = saturating_add_ns(knots.front().t_ns, option_ns("--max-seconds", args.max_seconds));
    // A sample sees knots up to its look-ahead: beyond it (plus a margin of
    // knots) nothing changes the samples kept.
    const TimeNs interval_ns = option_ns("knot_interval_s", sc.trajectory.knot_interval_s);
    const TimeNs keep_ns = saturating_add_ns(
        saturating_add_ns(end_ns, StreamPipeline::lookahead_ns(opt, interval_ns)), saturating_mul_ns(interval_ns, 10));
    while (knots.size() > 2 && knots.back().t_ns > keep_ns) knots.pop_back();
  }
  const scene::ErrorModelConfig model =
      args.sensor.empty() ? imu->error_model : scene::error_model_from_option(args.sensor, args.seed);
  scene::ErrorModelConfig seeded = model;
  if (args.seed >= 0) seeded.spec.seed = static_cast<std::uint64_t>(args.seed);
  describe_sensor_stage(seeded, imu->name, imu->rate_hz, args.quiet);
  // Faults ([[imu.fault]], [imu.random_faults]; docs/faults.md): on the
  // samples as imuemud's producer applies them, logged beside the output.
  BatchOutputs outputs;
  outputs.imu_csv_path = args.out_path;
  outputs.trajectory_csv_path = args.trajectory_out_path;
  outputs.physics = opt.scene.physics;
  outputs.end_ns = end_ns;
  // Issue 28: the device's GNSS and barometer as its encoder sends them,
  // seeded as imuemud seeds them (scene_config.cpp: aiding_seed = the error
  // model's seed; here --seed's when given) at the device's rate
  // (scene_runner.cpp: nominal_sample_rate_hz).
  outputs.gnss_csv_path = args.gnss_out_path;
  outputs.baro_csv_path = args.baro_out_path;
  outputs.aiding_protocol = imu->protocol;
  outputs.aiding_options = imu->stream_options;
  outputs.aiding_options.nominal_sample_rate_hz = static_cast<double>(imu->rate_hz);
  outputs.aiding_options.aiding_seed = seeded.spec.seed;
  outputs.faults.faults = imu->faults;
  outputs.faults.random = imu->random_faults;
  if (!args.quiet)
    for (const std::string& line : scene::fault_lines(imu->faults, imu->random_faults))
      std::cerr << "imuemu: " << imu->name << ": " << line << "\n";
  // Streamed to the file sample by sample: O(window) memory (batch_generation.hpp).
  const BatchCounts counts = generate_to_files(knots, opt, seeded, imu->name, outputs);
  report_saturation(imu->name, counts.saturated_samples, args.quiet);
  if (!args.quiet && !counts.fault_log_path.empty())
    std::cerr << "imuemu: " << imu->name << ": " << counts.faulted_samples << " samples faulted, " << counts.fault_events
              << " fault events -> " << counts.fault_log_path
              << " (link faults are logged; they act on the wire only: imuemud, emit)\n";
  if (!args.quiet)
    std::cerr << "imuemu: scene " << sc.name << ", imu " << imu->name << ": " << knots.size() << " knots -> "
              << counts.samples << " samples at " << imu->rate_hz << " Hz (Delta " << opt.kernel.delta << ") -> "
              << args.out_path << "\n";
  return static_cast<int>(kOk);
}

}  // namespace

int generate(const GenerateArgs& args) {
  if (!args.scene_file.empty()) return run_guarded([&] { return generate_for_scene(args); });
  return run_guarded([&] {
    const auto wall_start = std::chrono::steady_clock::now();
    io::Trajectory trajectory = io::read_trajectory_csv(args.in_path);
    PipelineOptions opt;
    opt.scene = scene_model(args.scene, args.gravity_m_s2);
    opt.rate_hz = args.rate_hz;
    opt.chart = chart_from_string(args.chart);
    opt.derivatives = derivatives_from_string(args.derivatives);
    opt.ends = ends_from_string(args.ends);
    opt.gap_policy = gap_policy_from_string(args.gap_policy);
    opt.max_gap_s = args.max_gap_s;
    opt.interpolation.method = interp::method_from_string(args.method);
    opt.interpolation.sigma = args.sigma;
    opt.interpolation.mu = args.mu;
    opt.kernel.delta = args.delta;
    opt.kernel.width = smoothing::kernel_width_from_string(args.kernel);
    opt.kernel.half_width_s = args.kernel_half_width_s;
    opt.kernel.order = args.kernel_order;
    // Input-convention traps (docs/trajectory-format.md): warnings with their
    // numbers, printed even with --quiet (which silences progress, not doubts
    // about the input).
    for (const auto& warning : {io::attitude_frame_warning(trajectory), io::flat_scene_warning(trajectory, opt.scene.physics)})
      if (warning) std::cerr << "imuemu: warning: " << *warning << "\n";
    const std::vector<Pose> knots = io::poses_in_scene(trajectory, opt.scene.physics);
    // Each knot's file line, for the messages that name knots (gaps).
    std::vector<std::size_t> knot_lines;
    knot_lines.reserve(trajectory.records.size());
    for (const io::TrajectoryRecord& rec : trajectory.records) knot_lines.push_back(rec.line);
    trajectory = io::Trajectory{};  // the parsed file is dropped once it is poses: only the knots (and lines) are held
    if (args.delta < 0)
      opt.kernel.delta = auto_delta(knots, args.rate_hz, opt.interpolation.method == interp::Method::hermite ? 1.0 : 2.0);
    const scene::ErrorModelConfig model = scene::error_model_from_option(args.sensor.empty() ? "ideal" : args.sensor, args.seed);
    describe_sensor_stage(model, "imu0", args.rate_hz, args.quiet);
    BatchCounts counts;
    {
      // Streamed to both files sample by sample: O(window) memory
      // (batch_generation.hpp); neither file is replaced unless both are written.
      ProgressBar bar(!args.quiet);
      try {
        BatchOutputs outputs;
        outputs.imu_csv_path = args.out_path;
        outputs.trajectory_csv_path = args.trajectory_out_path;
        outputs.physics = opt.scene.physics;
        counts = generate_to_files(knots, opt, model, "imu0", outputs,
                                   [&](double f) { bar.update(f); });
      } catch (const GapError& e) {
        // Named by file line (knot k is the record at knot_lines[k]), not by
        // the 0-based knot index the core knows.
        throw interp::InterpolationError(e.describe([&](std::size_t k) {
          return k < knot_lines.size() ? "the knot at " + args.in_path + ":" + std::to_string(knot_lines[k])
                                       : "knot " + std::to_string(k);
        }));
      }
    }
    report_saturation("imu0", counts.saturated_samples, args.quiet);
    if (!args.quiet) {
      const double wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count();
      std::cerr << "imuemu: " << knots.size() << " knots -> " << counts.samples << " samples at " << args.rate_hz
                << " Hz (" << args.scene << ", " << args.method << ", Delta " << opt.kernel.delta << ", " << args.kernel
                << " order-" << args.kernel_order << " kernel, " << args.chart << " chart, " << args.derivatives << " derivatives) in " << number(std::round(wall_s * 1000) / 1000)
                << " s -> " << args.out_path << "\n";
    }
    return static_cast<int>(kOk);
  });
}

int verify(const VerifyArgs& args) {
  return run_guarded([&] {
    std::vector<ImuSample> imu = io::read_imu_csv(args.imu_path);
    if (args.start_s > 0.0 && !imu.empty()) {
      const TimeNs start_ns = saturating_add_ns(imu.front().t_ns, option_ns("--start-s", args.start_s));
      imu.erase(imu.begin(), std::lower_bound(imu.begin(), imu.end(), start_ns,
                                              [](const ImuSample& s, TimeNs t) { return s.t_ns < t; }));
    }
    const io::KinematicsTrajectory ref = io::read_kinematics_csv(args.trajectory_path);
    const SceneModel scene = scene_model(args.scene, args.gravity_m_s2);
    if (ref.physics != scene.physics)
      throw std::invalid_argument("trajectory file " + args.trajectory_path + " is in the " +
                                  (ref.physics == Physics::flat ? "flat" : "ecef") + " scene, not " + args.scene);
    if (imu.size() < 3 || ref.states.empty()) throw std::invalid_argument("verify needs at least three IMU samples");
    std::unordered_map<TimeNs, std::size_t> index_of;
    index_of.reserve(ref.states.size());
    for (std::size_t i = 0; i < ref.states.size(); ++i) index_of.emplace(ref.states[i].t_ns, i);
    const auto first = index_of.find(imu.front().t_ns);
    if (first == index_of.end())
      throw std::invalid_argument("the trajectory file has no state at the first IMU time " +
                                  io::format_decimal_seconds(imu.front().t_ns) + " s");
    const Kinematics& k0 = ref.states[first->second];
    const strapdown::NavState initial{k0.t_ns, k0.position_m, k0.velocity_m_s, k0.attitude};
    std::vector<strapdown::NavState> aiding;
    if (args.aid_vertical) {
      aiding.reserve(imu.size());
      for (const ImuSample& s : imu) {
        const auto it = index_of.find(s.t_ns);
        if (it == index_of.end())
          throw std::invalid_argument("--aid-vertical: no trajectory state at IMU time " + io::format_decimal_seconds(s.t_ns));
        const Kinematics& k = ref.states[it->second];
        aiding.push_back({k.t_ns, k.position_m, k.velocity_m_s, k.attitude});
      }
    }
    strapdown::Options sopt;
    sopt.aid_vertical = args.aid_vertical;
    const auto states = strapdown::integrate(scene, initial, imu, sopt, aiding);

    std::printf("# closed loop: %zu IMU samples integrated (Eq. 3.69, %s scene%s) against %s\n", imu.size(),
                args.scene.c_str(), args.aid_vertical ? ", vertical aided" : "", args.trajectory_path.c_str());
    std::printf("%12s %14s %14s %14s %14s\n", "time_s", "pos_err_m", "horiz_err_m", "vert_err_m", "att_err_rad");
    double max_pos = 0.0, max_h = 0.0, max_v = 0.0, max_att = 0.0;
    TimeNs next_report = imu.front().t_ns;
    const TimeNs report_step = option_ns("--report-every-s", std::max(args.report_every_s, 1e-3));
    for (std::size_t i = 0; i < states.size(); ++i) {
      const auto it = index_of.find(states[i].t_ns);
      if (it == index_of.end()) continue;
      const Kinematics& k = ref.states[it->second];
      const Vec3 dp = states[i].position_m - k.position_m;
      Vec3 down = Vec3::UnitZ();
      if (scene.physics == Physics::ecef) {
        const earth::Geodetic g = earth::geodetic_from_ecef(k.position_m);
        down = attitude::ned_to_ecef(g.latitude_rad, g.longitude_rad).col(2);
      }
      const double vert = std::abs(dp.dot(down));
      const double horiz = (dp - dp.dot(down) * down).norm();
      const double att = so3::angle(k.attitude.transpose() * states[i].attitude);
      max_pos = std::max(max_pos, dp.norm());
      max_h = std::max(max_h, horiz);
      max_v = std::max(max_v, vert);
      max_att = std::max(max_att, att);
      if (states[i].t_ns >= next_report || i + 1 == states.size()) {
        std::printf("%12s %14.6e %14.6e %14.6e %14.6e\n",
                    io::format_decimal_seconds(states[i].t_ns - imu.front().t_ns).c_str(), dp.norm(), horiz, vert, att);
        while (next_report <= states[i].t_ns && next_report < kMaxTimeNs) next_report = saturating_add_ns(next_report, report_step);
      }
    }
    std::printf("# max: position %.6e m (horizontal %.6e, vertical %.6e), attitude %.6e rad\n", max_pos, max_h,
                max_v, max_att);
    const bool pos_bad = args.max_position_error_m >= 0.0 && !(max_pos <= args.max_position_error_m);
    const bool att_bad = args.max_attitude_error_rad >= 0.0 && !(max_att <= args.max_attitude_error_rad);
    if (pos_bad || att_bad) {
      std::fprintf(stderr, "imuemu verify: drift above the requested bound\n");
      return static_cast<int>(kVerifyFailed);
    }
    return static_cast<int>(kOk);
  });
}

int sample_trajectory(const SampleArgs& args) {
  return run_guarded([&] {
    (void)option_ns("duration", args.duration_s);  // UsageError (exit 2) naming the option
    (void)option_ns("period", args.period_s);
    io::write_file_atomically(args.out_path, io::sample_trajectory_csv(args.kind, args.duration_s, args.period_s));
    return static_cast<int>(kOk);
  });
}

int demo(const std::string& out_dir, std::int64_t rate_hz) {
  std::error_code ec;
  std::filesystem::create_directories(out_dir, ec);
  if (ec) {
    std::cerr << "imuemu demo: cannot create " << out_dir << ": " << ec.message() << "\n";
    return kOutputError;
  }
  const std::string traj = out_dir + "/trajectory.csv", imu = out_dir + "/imu.csv", smooth = out_dir + "/smoothed.csv";
  std::cout << "imuemu demo: built-in 10-minute aircraft-like flight near Barcelona, knots at 1 Hz\n";
  if (int rc = sample_trajectory({traj, "flight", 600.0, 1.0}); rc != kOk) return rc;
  GenerateArgs gen;
  gen.in_path = traj;
  gen.out_path = imu;
  gen.trajectory_out_path = smooth;
  gen.rate_hz = rate_hz;
  gen.scene = "ecef";
  if (int rc = generate(gen); rc != kOk) return rc;
  std::cout << "  " << traj << "  (input knots)\n  " << imu << "  (ideal IMU, ecef scene: Earth rate, Coriolis, normal gravity)\n  "
            << smooth << "  (smoothed trajectory)\n\nClosed loop (vertical channel aided):\n";
  std::cout.flush();
  VerifyArgs ver;
  ver.imu_path = imu;
  ver.trajectory_path = smooth;
  ver.scene = "ecef";
  ver.aid_vertical = true;
  ver.report_every_s = 60.0;
  ver.start_s = 1.0;  // past the one-sided window at the start
  return verify(ver);
}

}  // namespace imuemu::cli
