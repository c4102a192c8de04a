// The imuemu command-line tool's subcommands. Each returns a process exit code.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "io/pose_source.hpp"

namespace CLI {
class App;
}

namespace imuemu::cli {

// Exit codes (documented in README.md).
enum ExitCode : int {
  kOk = 0,
  kInternalError = 1,
  kUsageError = 2,       // bad command line (CLI11 also uses 2..)
  kBadInput = 3,         // an input file is malformed (file:line:column in the message)
  kCannotProcess = 4,    // valid file the method cannot handle (antipodal knots, too short, ...)
  kOutputError = 5,      // an output file could not be written
  kVerifyFailed = 6,     // verify: drift above the requested bound
};

struct GenerateArgs {
  std::string in_path, out_path, trajectory_out_path;
  std::int64_t rate_hz = 400;
  int delta = -1;  // < 0: one knot interval (hermite) or two (others) of output samples
  std::string method = "hermite";
  int kernel_order = 4;
  double sigma = 1.0, mu = 1.0;
  std::string kernel = "window";
  double kernel_half_width_s = 1.0;
  std::string chart = "local";
  std::string derivatives = "kernel";
  std::string ends = "extrapolate";
  std::string gap_policy = "error";
  double max_gap_s = 10.0;
  std::string scene = "ecef";
  double gravity_m_s2 = 9.80665;
  bool quiet = false;
  // Instead of --in and the method options: one [[imu]] of a scene file, as
  // imuemud emits it (the scene's trajectory without looping, smoothing,
  // physics, the IMU's rate and mounting): the batch reference for the
  // daemon's output. max_seconds > 0: only the first seconds of output (the
  // knots beyond what those samples can see are not read).
  std::string scene_file, imu_name;
  double max_seconds = -1.0;
  // Sensor error model (docs/sensor-models.md): a preset, a TOML file, or
  // "ideal"; empty: the scene's [imu.error_model] with --scene-file, else ideal.
  std::string sensor;
  std::int64_t seed = -1;  // >= 0: replaces the model's seed
  // --scene-file (an ecef scene): the device's aiding sensors as it sends
  // them (issue 28), one CSV each: the HIL_GPS fixes ([imu.mavlink]
  // hil_gps_rate_hz; an nmea/ubx device: its fix of every sample) and the
  // barometer ([imu.mavlink] baro). Empty: not written.
  std::string gnss_out_path, baro_out_path;
};
int generate(const GenerateArgs& args);

struct VerifyArgs {
  std::string imu_path, trajectory_path;
  std::string scene = "ecef";
  double gravity_m_s2 = 9.80665;
  bool aid_vertical = false;
  double report_every_s = 300.0;
  // Seconds after the first IMU sample at which integration starts: the
  // one-sided windows of Eq. 3.68 at a file's ends bias the first Delta
  // samples (thesis §3.6.2), so a closed loop usually starts past them.
  double start_s = 0.0;
  double max_position_error_m = -1.0;  // < 0: no bound
  double max_attitude_error_rad = -1.0;
};
int verify(const VerifyArgs& args);

struct SampleArgs {
  std::string out_path;
  std::string kind = "flight";  // flight | circle | static
  double duration_s = 600.0;
  double period_s = 1.0;
};
int sample_trajectory(const SampleArgs& args);
// Its text: io/sample_trajectory.hpp (shared with the scenes and emit).

// Live streaming (docs/streaming.md): poses from a source, IMU CSV lines out
// (with a status column) in real time on the monotonic clock.
struct StreamArgs {
  std::string source;           // file:PATH | udp:ADDR:PORT | tcp:ADDR:PORT | stdin
  std::string out_path = "-";   // '-' = stdout
  std::string speed = "1";      // replay speed factor ("2.5", "1/3"), or "max" (file: as fast as possible)
  std::int64_t rate_hz = 400;
  double knot_interval_s = 1.0;  // expected pose spacing: sets the default window and the look-ahead
  double tcp_idle_timeout_s = 5.0;  // tcp: a client silent this long is closed (0: never)
  int delta = -1;               // < 0: one knot interval of output samples
  std::string scene = "ecef";
  double gravity_m_s2 = 9.80665;
  double max_gap_s = 10.0;      // longer gaps split the stream (each side its own end windows)
  std::string underrun = "extrapolate";  // extrapolate | pause
  double blend_s = 0.2;
  double margin_s = 0.1;        // extra delay beyond the engine's look-ahead: absorbs input jitter
  double duration_s = -1.0;     // < 0: until the input ends (or SIGINT/SIGTERM)
  std::string sensor = "ideal"; // sensor error model: preset or TOML file (docs/sensor-models.md)
  std::int64_t seed = -1;
};
int stream(const StreamArgs& args);

// "udp:127.0.0.1:5005" (scheme "udp") -> address and port; std::invalid_argument
// naming the option value otherwise. Used by `stream` and `emit` --source.
io::NetEndpoint endpoint_of(const std::string& spec, const std::string& scheme);

// The sensor models' --help text: the presets and the one noise convention.
extern const char* const kSensorOptionHelp;

// `imuemu sensors`: the presets, their terms with the discrete sigma at
// rate_hz, and their sources.
int sensors(double rate_hz);

// `imuemu protocol-options`: every [imu.<protocol>] key (type, allowed
// values, default, meaning); markdown: the reference block of
// docs/scene-format.md.
int protocol_options(bool markdown);

// `imuemu completion`: the bash completion script of `app` (every command
// path with its subcommands and options).
std::string bash_completion_script(const CLI::App& app);

// The README's main job: sample flight -> generate -> verify, in out_dir.
int demo(const std::string& out_dir, std::int64_t rate_hz);

}  // namespace imuemu::cli
