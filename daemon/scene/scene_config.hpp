// The scene file of imuemud (TOML, docs/scene-format.md): where the poses come
// from, how they are smoothed, how the daemon runs, and one [[imu]] table per
// emulated device (mounting, protocol, transport, sync output, error model).
//
// Parsing is strict: an unknown key, a wrong type, a value out of range or a
// name that is not one of the allowed ones is a SceneError naming the file,
// the line and column, the dotted key (imu[1].transport.baud) and what is
// allowed. Nothing is silently ignored or defaulted past a typo.
#pragma once

#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "core/live_emitter.hpp"
#include "core/mounting.hpp"
#include "core/fault/fault.hpp"
#include "core/fault/timeline.hpp"
#include "core/pipeline.hpp"
#include "core/sensor/sensor_model.hpp"
#include "core/signal_chain/signal_chain.hpp"
#include "core/time_mapping.hpp"
#include "drivers/gpio_sync.hpp"
#include "drivers/protocols/can_protocols.hpp"
#include "drivers/protocols/stream_protocols.hpp"
#include "drivers/serial_transport.hpp"

namespace imuemu::scene {

// "FILE:LINE:COLUMN: KEY: what is wrong; what is allowed".
class SceneError : public std::runtime_error {
 public:
  SceneError(std::string file, std::uint32_t line, std::uint32_t column, std::string key, const std::string& what);
  const std::string& file() const noexcept { return file_; }
  std::uint32_t line() const noexcept { return line_; }      // 1-based; 0 when unknown
  std::uint32_t column() const noexcept { return column_; }  // 1-based; 0 when unknown
  const std::string& key() const noexcept { return key_; }   // dotted path; empty for the whole file

 private:
  std::string file_;
  std::uint32_t line_;
  std::uint32_t column_;
  std::string key_;
};

// ---- [trajectory] ----

enum class SourceKind { file, udp, tcp, stdin_lines, sample, mavlink_udp };
// Poses arrive while the daemon runs (udp, mavlink, tcp, stdin).
inline bool is_live(SourceKind kind) {
  return kind == SourceKind::udp || kind == SourceKind::mavlink_udp || kind == SourceKind::tcp ||
         kind == SourceKind::stdin_lines;
}
enum class SampleMotion { flight, circle, stationary };  // "flight" | "circle" | "static"
enum class StartAlignment { now, next_second };          // "now" | "next-second"

struct TrajectoryConfig {
  std::string source;  // as written: file:PATH | udp:ADDR:PORT | mavlink:ADDR:PORT | tcp:ADDR:PORT | stdin | sample:KIND
  SourceKind kind = SourceKind::sample;
  std::string file_path;     // file: resolved against the scene file's directory
  std::string address;       // udp/tcp: address to bind
  std::uint16_t port = 0;    // udp/tcp
  SampleMotion sample = SampleMotion::flight;  // sample:
  double duration_s = 600.0;                   // sample: length of the built-in motion
  live::SpeedFactor speed;                     // replay factor (file, sample)
  double knot_interval_s = 1.0;  // expected pose spacing (sample: the knot period)
  bool loop = false;             // file, sample: replay again from the start at the end
  double tcp_idle_timeout_s = 5.0;  // tcp: a client silent this long is closed (0: never; io/pose_source.hpp)
  // mavlink: the one vehicle taken (io/pose_source.hpp PoseSourceOptions);
  // empty: the first HIL_STATE_QUATERNION sender's.
  std::optional<std::uint8_t> mavlink_system_id, mavlink_component_id;
  StartAlignment start = StartAlignment::now;
};

// ---- [smoothing] ----

struct SmoothingConfig {
  interp::Method method = interp::Method::hermite;
  double sigma = 1.0, mu = 1.0;      // min-accel (Lemma 3.22)
  int spline_window_knots = 4;       // interp::Options::spline_window_knots
  // Window half-length: Delta in output samples of each IMU, or in seconds
  // (Delta = round(window_s * rate_hz)). Neither: one knot interval.
  std::optional<int> delta_samples;
  std::optional<double> window_s;
  int kernel_order = 4;
  smoothing::KernelWidth kernel = smoothing::KernelWidth::window;
  double kernel_half_width_s = 1.0;  // kernel = seconds
  Chart chart = Chart::local;
  Derivatives derivatives = Derivatives::kernel;
  Ends ends = Ends::extrapolate;
  GapPolicy gap_policy = GapPolicy::split;  // live: a gap starts a new run
  double max_gap_s = 10.0;
  bool closed_form_positions = true;
  int attitude_node_step = 0;
  int min_kernel_samples = 100;
};

// ---- [live] ----

struct LiveConfig {
  live::UnderrunPolicy underrun = live::UnderrunPolicy::extrapolate;
  double blend_s = 0.2;
  double margin_s = 0.1;  // delay beyond the engine's look-ahead (absorbs input jitter)
  // Live input: samples leave this long after their trajectory time (on the
  // mapping anchored at the first pose's arrival), replacing look-ahead +
  // margin_s. Below the smoothing method's look-ahead + the producer's 20 ms
  // lead the causal
  // Hermite method runs instead (core/causal_hermite.hpp, docs/streaming.md
  // "Low-latency live input"). Empty: look-ahead + margin_s, the smoothing method.
  std::optional<double> latency_budget_ms;
};

// ---- [daemon] ----

enum class DeviceMissingPolicy { fail, wait };

struct DaemonConfig {
  int realtime_priority = 0;        // SCHED_FIFO priority of the emission thread, 1..99; 0 = normal scheduling
  bool lock_memory = false;         // mlockall(MCL_CURRENT | MCL_FUTURE)
  bool require_realtime = false;    // refuse to start without the priority / lock that was asked for
  std::string control_socket;       // default /run/imuemu/<scene name>.sock
  std::string control_group;        // group owning the control socket; empty: the daemon's
  std::string fault_log;            // issue 18: append fault start/end events here (JSON lines); empty: none
  double status_interval_s = 1.0;   // status line / JSON every this many seconds
  bool watchdog = true;             // sd_notify WATCHDOG=1 when systemd set WatchdogSec=
  // A tick whose wake-up missed its deadline by more than one period: dropped
  // (the receiver sees the sample time jump, as from an IMU that skipped a
  // sample; a sequence gap only in native, docs/emission.md) or sent late.
  // emission::EngineOptions::drop_late_ticks.
  bool drop_late_ticks = true;      // late_ticks = "drop" | "send"
  DeviceMissingPolicy device_missing = DeviceMissingPolicy::fail;
  double device_retry_initial_s = 0.1;  // wait: first retry, doubling up to device_retry_max_s
  double device_retry_max_s = 2.0;
};

// ---- [[imu]] ----

enum class TransportType { pty, serial, can, udp, tcp_server, null };

struct PtyConfig {
  std::string link;            // absolute path of the published symlink
  unsigned mode = 0;           // slave permission bits (0: openpty's)
  std::size_t queue_bytes = 32 * 1024;
};

struct SerialConfig {
  std::string port;
  drivers::SerialSettings settings;
  std::size_t queue_bytes = 0;  // 0: 100 ms of line time
};

struct CanConfig {
  std::string interface;
  bool fd = false;
  bool bitrate_switch = true;
  std::int64_t bitrate = 1'000'000;  // arbitration (classic) bit rate, for the budget
  std::int64_t data_bitrate = 0;     // CAN FD data phase; 0: = bitrate
};

// type udp / tcp_server (drivers/net_transport.hpp).
struct NetConfig {
  std::string host;               // udp: where datagrams go; tcp_server: the address listened on
  std::uint16_t port = 0;         // udp: remote port; tcp_server: listening port
  std::uint16_t bind_port = 0;    // udp: the local port (0: the kernel's choice)
  std::size_t queue_bytes = 32 * 1024;
};

struct TransportConfig {
  TransportType type = TransportType::null;
  PtyConfig pty;
  SerialConfig serial;
  CanConfig can;
  NetConfig net;
};

struct SyncConfig {
  std::string chip;
  unsigned line = 0;
  std::uint64_t every_n_samples = 1;
  TimeNs width_ns = 100'000;
  bool active_low = false;
  std::optional<unsigned> pps_line;
  std::string pps_chip;  // empty: chip
  TimeNs pps_width_ns = 100'000'000;
  bool pps_active_low = false;
  int trailing_edge_priority = 0;
};

// [imu.error_model] (daemon/scene/error_model_config.hpp): ideal unless a preset or
// a term is given; its [signal_chain] table is the device's internal rate and
// filters (core/signal_chain/signal_chain.hpp), ideal unless given.
struct ErrorModelConfig {
  std::string preset = "ideal";   // the preset the terms start from
  sensor::SensorModelSpec spec;   // preset + overrides, SI units, with the seed
  signal_chain::ChainSpec chain;  // resolved against the device's rate when it is built
  bool ideal() const { return spec.is_ideal() && chain.is_ideal(); }
  // The sensor model to run, if any.
  std::optional<sensor::SensorModelSpec> sensor() const {
    return spec.is_ideal() ? std::nullopt : std::optional<sensor::SensorModelSpec>(spec);
  }
};

struct ImuConfig {
  std::string name;
  std::int64_t rate_hz = 400;
  Mounting mounting;
  std::string protocol;  // native | mavlink2 | mip (byte streams) | dronecan | j1939 (CAN)
  drivers::StreamEncoderOptions stream_options;  // nominal_sample_rate_hz = rate_hz
  drivers::CanEncoderOptions can_options;
  TransportConfig transport;
  std::optional<SyncConfig> sync;
  ErrorModelConfig error_model;
  // [[imu.fault]] and [imu.random_faults] (daemon/scene/fault_config.hpp,
  // docs/faults.md): the faults on this device's timeline; their seeds
  // default to the error model's.
  std::vector<fault::FaultSpec> faults;
  fault::RandomFaults random_faults;
  std::uint32_t line = 0;             // where its [[imu]] header is in the file
};

struct SceneConfig {
  std::string file;      // the scene file (or the name given to parse_scene_text)
  std::string name;
  SceneModel physics;    // flat | ecef, flat gravity
  TrajectoryConfig trajectory;
  SmoothingConfig smoothing;
  LiveConfig live;
  DaemonConfig daemon;
  std::vector<ImuConfig> imus;
};

// Protocol names by the link they need.
bool is_can_protocol(std::string_view protocol);

// Reads and validates a scene file; relative paths in it are resolved against
// its directory. Throws SceneError.
SceneConfig parse_scene_file(const std::string& path);
// The same for text already in memory: `file_name` appears in messages,
// `base_dir` resolves relative paths.
SceneConfig parse_scene_text(std::string_view toml_text, const std::string& file_name, const std::string& base_dir);

// The smoothing engine's options for one device of the scene (its rate and
// window); what imuemud hands to StreamPipeline.
PipelineOptions pipeline_options(const SceneConfig& scene, const ImuConfig& imu);

// How one device meets the scene's latency (live.latency_budget_ms).
struct LatencyPlan {
  bool causal = false;                 // the causal Hermite method instead of Eq. 3.68
  TimeNs smoothing_lookahead_ns = 0;   // the smoothing method's look-ahead for this scene
  TimeNs lookahead_ns = 0;             // of the method used
  TimeNs emission_delay_ns = 0;        // samples leave this long after their trajectory time
  TimeNs producer_lead_ns = 20'000'000;  // the producer computes a tick this long before it is due
  // Causal: a pose is used exactly (not extrapolated over) when it arrives
  // within this of its mapped time: emission delay - producer lead - one
  // pose interval (negative: every pose interval ends extrapolated).
  TimeNs arrival_slack_ns = 0;
};
LatencyPlan latency_plan(const SceneConfig& scene, const ImuConfig& imu);

}  // namespace imuemu::scene
