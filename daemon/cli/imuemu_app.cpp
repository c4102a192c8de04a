// imuemu: offline trajectory-to-IMU generation and verification: its command
// line (every subcommand's options) and dispatch. main() is in imuemu_main.cpp,
// so this file compiles in the room's unity batch with the commands that
// already instantiate CLI11 (issue 25: one CLI11 instantiation fewer per flavour).
#include "daemon/cli/imuemu_app.hpp"

#include <iostream>
#include <CLI/CLI.hpp>

#include "daemon/cli/allan_command.hpp"
#include "daemon/cli/cli_options.hpp"
#include "daemon/cli/commands.hpp"
#include "daemon/cli/ports_command.hpp"
#include "daemon/cli/listen_command.hpp"
#include "daemon/cli/budget_command.hpp"
#include "daemon/cli/emit_command.hpp"
#include "daemon/cli/bench_timing_command.hpp"
#include "daemon/cli/status_command.hpp"
#include "daemon/cli/fault_command.hpp"
#include "daemon/cli/send_command.hpp"

int imuemu::cli::run_imuemu(int argc, char** argv, const char* version_text) {
  using namespace imuemu::cli;
  CLI::App app{
      "imuemu: turns a pose trajectory into what a real IMU would give - ideal or with its sensor errors, "
      "filters, vibration and faults - as files, or live on a device's wire (imuemu COMMAND --help; man imuemu; "
      "the docs/*.md the help names are under /usr/share/doc/imuemu when installed)"};
  app.set_version_flag("--version", std::string("imuemu ") + version_text);
  app.require_subcommand(1);

  GenerateArgs gen;
  auto* g = app.add_subcommand("generate", "Interpolate, smooth and differentiate a trajectory into IMU samples");
  auto* gen_in = g->add_option("--in", gen.in_path, "Trajectory CSV (docs/trajectory-format.md)");
  auto* gen_scene = g->add_option("--scene-file", gen.scene_file,
                                  "Instead of --in and the method options: what imuemud emits for one [[imu]] of this scene "
                                  "(its trajectory once, smoothing, physics, rate, mounting)");
  gen_in->excludes(gen_scene);
  g->add_option("--imu", gen.imu_name, "--scene-file: the [[imu]] name (default: the first)");
  g->add_option("--max-seconds", gen.max_seconds, "--scene-file: only the first seconds of output")->check(seconds_in(0.0, kMaxDurationS, true));
  g->add_option("--out", gen.out_path,
                "IMU CSV to write (time_ns, gyro rad/s, accel m/s^2): replaced atomically, through a symbolic link to "
                "the file it names; a FIFO, character device or /dev/stdout is written as a stream (not atomic); "
                "a directory is refused")->required();
  g->add_option("--trajectory-out", gen.trajectory_out_path, "Also write the smoothed trajectory CSV");
  auto* gen_gnss = g->add_option("--gnss-out", gen.gnss_out_path,
                "--scene-file (ecef scene): also write the device's GNSS fixes as it sends them (HIL_GPS of "
                "[imu.mavlink] hil_gps_rate_hz, or an nmea/ubx device's fixes), before the wire's rounding: CSV "
                "time_ns, gps_time_ns, latitude_rad, longitude_rad, height_m (ellipsoid), velocity_north/east/down_m_s, "
                "fix_type, satellites, hdop, vdop");
  auto* gen_baro = g->add_option("--baro-out", gen.baro_out_path,
                "--scene-file (ecef scene): also write the device's barometer ([imu.mavlink] baro) as it sends it, "
                "one row per sample: CSV time_ns, pressure_pa, temperature_k, pressure_altitude_m (empty outside "
                "the atmosphere's range)");
  gen_gnss->needs(gen_scene);
  gen_baro->needs(gen_scene);
  g->add_option("--rate", gen.rate_hz, "Output rate in Hz (integer)")->capture_default_str()->check(CLI::Range(1, 1000000));
  g->add_option("--delta", gen.delta, "Window half-length Delta of Eq. 3.68, in output samples (default: one median knot interval of output samples with --method hermite, the default, two with the other methods; 0 only with --derivatives finite-difference)")->check(CLI::Range(std::int64_t{0}, imuemu::limits::kMaxWindowSamples));
  g->add_option("--method", gen.method, "Base curve: hermite (C2 in local charts), geodesic (Eq. 3.44), min-accel (Lemma 3.22), park-ravani (3.6.1)")->capture_default_str()
      ->check(CLI::IsMember({"hermite", "geodesic", "min-accel", "park-ravani"}));
  g->add_option("--kernel-order", gen.kernel_order, "Bump kernel order: 4 (preserves cubic motion) or 2 (the thesis' positive bump)")
      ->capture_default_str()->check(CLI::IsMember({2, 4}));
  g->add_option("--sigma", gen.sigma, "min-accel: start speed factor (Lemma 3.22)")->capture_default_str()
      ->check(finite_in(imuemu::limits::kMinSpeedFactor, imuemu::limits::kMaxSpeedFactor));
  g->add_option("--mu", gen.mu, "min-accel: end speed factor (Lemma 3.22)")->capture_default_str()
      ->check(finite_in(imuemu::limits::kMinSpeedFactor, imuemu::limits::kMaxSpeedFactor));
  g->add_option("--kernel", gen.kernel, "Bump time axis: window (support = window), thesis (t in seconds, literal Eq. 3.68), seconds")
      ->capture_default_str()->check(CLI::IsMember({"window", "thesis", "seconds"}));
  g->add_option("--kernel-half-width-s", gen.kernel_half_width_s, "Bump half width for --kernel seconds")->capture_default_str()->check(seconds_in(0.0, kMaxIntervalS, true));
  g->add_option("--chart", gen.chart, "Where to smooth: local (default) or global (the thesis' log R)")->capture_default_str()
      ->check(CLI::IsMember({"local", "global"}));
  g->add_option("--derivatives", gen.derivatives, "kernel (exact, through the bump kernel) or finite-difference (thesis Eq. 3.71-3.74)")
      ->capture_default_str()->check(CLI::IsMember({"kernel", "finite-difference"}));
  g->add_option("--ends", gen.ends, "Beyond the first/last knot: extrapolate (continue the degree-6 polynomial through the seven end knots) or clip (the thesis' one-sided windows)")
      ->capture_default_str()->check(CLI::IsMember({"extrapolate", "clip"}));
  g->add_option("--gap-policy", gen.gap_policy, "Knot intervals longer than --max-gap-s: error, or split into independent segments")
      ->capture_default_str()->check(CLI::IsMember({"error", "split"}));
  g->add_option("--max-gap-s", gen.max_gap_s, "Longest knot interval interpolated across")->capture_default_str()->check(seconds_in(0.0, kMaxGapS, true));
  g->add_option("--scene", gen.scene, "Physics: ecef (Earth rate, Coriolis, normal gravity) or flat")->capture_default_str()
      ->check(CLI::IsMember({"ecef", "flat"}));
  g->add_option("--gravity", gen.gravity_m_s2, "flat scene: gravity magnitude (m/s^2), along NED down")->capture_default_str()->check(finite_in(0.0, kMaxGravityM_s2));
  g->add_flag("--quiet", gen.quiet, "No progress bar or summary");
  g->add_option("--sensor", gen.sensor, std::string(kSensorOptionHelp) + "; default: ideal, or the scene's [imu.error_model] with --scene-file");
  g->add_option("--seed", gen.seed, "Noise seed of the sensor model (integer >= 0; default: the model's)")->check(CLI::NonNegativeNumber);

  VerifyArgs ver;
  auto* v = app.add_subcommand("verify", "Integrate IMU samples (Eq. 3.69) and print drift against a trajectory");
  v->add_option("--imu", ver.imu_path, "IMU CSV written by generate")->required();
  v->add_option("--trajectory", ver.trajectory_path, "Smoothed trajectory CSV written by generate --trajectory-out")->required();
  v->add_option("--scene", ver.scene, "Physics the IMU was generated for")->capture_default_str()
      ->check(CLI::IsMember({"ecef", "flat"}));
  v->add_option("--gravity", ver.gravity_m_s2, "flat scene gravity (m/s^2)")->capture_default_str()->check(finite_in(0.0, kMaxGravityM_s2));
  v->add_flag("--aid-vertical", ver.aid_vertical, "Reset height and vertical speed from the trajectory every step (ecef's free-inertial vertical channel is unstable)");
  v->add_option("--report-every-s", ver.report_every_s, "Seconds between drift lines")->capture_default_str()->check(seconds_in(0.0, kMaxDurationS, true));
  v->add_option("--start-s", ver.start_s, "Start integrating this many seconds after the first sample (skip the one-sided window)")->capture_default_str()->check(seconds_in(0.0, kMaxDurationS));
  v->add_option("--max-position-error-m", ver.max_position_error_m, "Exit 6 if the position drift exceeds this")->check(finite_in(0.0, 1e300));
  v->add_option("--max-attitude-error-rad", ver.max_attitude_error_rad, "Exit 6 if the attitude drift exceeds this")->check(finite_in(0.0, 1e300));

  SampleArgs smp;
  auto* s = app.add_subcommand("sample-trajectory", "Write a built-in sample trajectory CSV (geodetic + heading/pitch/roll)");
  s->add_option("--out", smp.out_path, "CSV to write (as generate --out: atomic, or a stream to a FIFO or /dev/stdout)")->required();
  s->add_option("--kind", smp.kind, "flight (aircraft-like, Barcelona), circle, static")->capture_default_str()
      ->check(CLI::IsMember({"flight", "circle", "static"}));
  s->add_option("--duration-s", smp.duration_s, "Duration")->capture_default_str()->check(seconds_in(0.0, kMaxDurationS, true));
  s->add_option("--period-s", smp.period_s, "Knot period")->capture_default_str()->check(seconds_in(0.0, kMaxIntervalS, true));

  StreamArgs str;
  auto* st = app.add_subcommand("stream", "Live: poses from a file replay, UDP, TCP or stdin -> IMU CSV lines in real time");
  st->add_option("--source", str.source, "file:PATH | udp:ADDR:PORT (binary datagrams) | tcp:ADDR:PORT | stdin (text lines); docs/pose-wire-format.md")->required();
  st->add_option("--out", str.out_path, "IMU CSV with a status column (exact|extrapolated|blending); - for stdout")->capture_default_str();
  st->add_option("--speed", str.speed, "Replay speed factor (2.5, 1/3), or max for a file as fast as possible")->capture_default_str();
  st->add_option("--rate", str.rate_hz, "Output rate in Hz")->capture_default_str()->check(CLI::Range(1, 1000000));
  st->add_option("--knot-interval-s", str.knot_interval_s, "Expected pose spacing: default window and look-ahead")->capture_default_str()->check(seconds_in(0.0, kMaxIntervalS, true));
  st->add_option("--tcp-idle-timeout-s", str.tcp_idle_timeout_s, "tcp: close a client that sent nothing for this long (0: never); a new client replaces one idle for 1 s")->capture_default_str()->check(seconds_in(0.0, 86400.0));
  st->add_option("--delta", str.delta, "Window half-length Delta (samples); default one knot interval")->check(CLI::Range(std::int64_t{1}, imuemu::limits::kMaxWindowSamples));
  st->add_option("--scene", str.scene, "ecef or flat")->capture_default_str()->check(CLI::IsMember({"ecef", "flat"}));
  st->add_option("--gravity", str.gravity_m_s2, "flat scene gravity (m/s^2)")->capture_default_str()->check(finite_in(0.0, kMaxGravityM_s2));
  st->add_option("--max-gap-s", str.max_gap_s, "Longer pose gaps split the stream")->capture_default_str()->check(seconds_in(0.0, kMaxGapS, true));
  st->add_option("--underrun", str.underrun, "When a pose is late: extrapolate (flagged, then blended back) or pause")->capture_default_str()
      ->check(CLI::IsMember({"extrapolate", "pause"}));
  st->add_option("--blend-s", str.blend_s, "Rejoin blend after an extrapolation")->capture_default_str()->check(seconds_in(0.0, kMaxIntervalS));
  st->add_option("--margin-s", str.margin_s, "Extra delay beyond the engine's look-ahead")->capture_default_str()->check(seconds_in(0.0, kMaxIntervalS));
  st->add_option("--duration-s", str.duration_s, "Stop after this much trajectory time")->check(seconds_in(0.0, kMaxDurationS, true));
  st->add_option("--sensor", str.sensor, kSensorOptionHelp)->capture_default_str();
  st->add_option("--seed", str.seed, "Noise seed of the sensor model (integer >= 0; default: the model's)")->check(CLI::NonNegativeNumber);

  bool popts_markdown = false;
  auto* popts = app.add_subcommand(
      "protocol-options",
      "List every protocol option: the scene's [imu.PROTOCOL] keys and emit's --PROTOCOL-KEY options, with type, "
      "allowed values, default and meaning");
  popts->add_flag("--markdown", popts_markdown, "As the Markdown reference block of docs/scene-format.md");
  double sensors_rate_hz = 400.0;
  auto* sens = app.add_subcommand("sensors", "List the sensor-model presets: terms, discrete sigma at a rate, datasheet sources");
  sens->add_option("--rate", sensors_rate_hz, "Rate (Hz) for the discrete values")->capture_default_str()->check(finite_in(0.0, 1e6, true));

  std::string demo_dir = "out/demo";
  std::int64_t demo_rate = 400;
  auto* d = app.add_subcommand("demo", "Main job on the built-in sample: 10-min flight at 1 Hz -> 400 Hz IMU -> verify");
  d->add_option("--out-dir", demo_dir, "Directory for the demo's files")->capture_default_str();
  d->add_option("--rate", demo_rate, "Output rate in Hz")->capture_default_str()->check(CLI::Range(1, 100000));

  auto* ports_command = app.add_subcommand("ports", "List the serial ports libserialport finds (name, USB VID:PID, serial number, manufacturer)");

  int exit_code = kUsageError;  // set by the callbacks of the add_*_command subcommands
  add_listen_command(app, exit_code);
  add_budget_command(app, exit_code);
  add_emit_command(app, exit_code);
  add_bench_timing_command(app, exit_code);
  add_status_command(app, exit_code);
  add_fault_command(app, exit_code);
  add_allan_command(app, exit_code);
  add_send_command(app, exit_code);
  auto* completion = app.add_subcommand(
      "completion",
      "Print the bash completion script for imuemu's commands and options (the package installs it as "
      "/usr/share/bash-completion/completions/imuemu)");

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);
    return code == 0 ? kOk : kUsageError;
  }
  if (*g) {
    if (gen.in_path.empty() == gen.scene_file.empty()) {
      std::cerr << "imuemu generate: give --in TRAJECTORY or --scene-file SCENE\n";
      return kUsageError;
    }
    // Delta 0 is no smoothing at all: only finite differences work without a window.
    if (gen.delta == 0 && gen.derivatives == "kernel") {
      std::cerr << "imuemu generate: --delta 0 needs --derivatives finite-difference (kernel derivatives need a "
                   "window: --delta 1.." << imuemu::limits::kMaxWindowSamples << ")\n";
      return kUsageError;
    }
    return generate(gen);
  }
  if (*v) return verify(ver);
  if (*s) return sample_trajectory(smp);
  if (*d) return demo(demo_dir, demo_rate);
  if (*st) return stream(str);
  if (*sens) return sensors(sensors_rate_hz);
  if (*popts) return protocol_options(popts_markdown);
  if (*completion) {
    std::cout << bash_completion_script(app);
    return kOk;
  }
  if (*ports_command) return ports();
  return exit_code;
}
