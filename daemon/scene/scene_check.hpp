// `imuemud --check-config FILE`: what a valid scene will cost before it runs.
// Per device: the engine's look-ahead (how far behind the poses it emits),
// the link budget (drivers/link_budget.hpp: UART line time, CAN bus time with
// worst-case stuffing) and a CPU estimate; then the totals.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "core/signal_chain/signal_chain.hpp"
#include "daemon/scene/scene_config.hpp"
#include "drivers/link_budget.hpp"

namespace imuemu::scene {

// Measured cost of one output sample of one device (smoothing, IMU equations,
// encoding) on the development machine: bench/bench_stream.cpp, ~1 us per
// sample at the default window. An estimate, not a guarantee: a wider window
// or finite-difference derivatives cost more.
inline constexpr double kCpuSecondsPerSample = 1e-6;
// The signal chain's share, per unit of its work (core/signal_chain/
// signal_chain.hpp ChainWork, predict_work; bench/bench_signal_chain.cpp,
// docs/signal-chain.md "Cost"): per internal sample of a non-ideal chain
// (the icm42688p chain at 8x: 2546 ns per output sample, / 8), per node of
// the increments' quadrature (raw increments: 1331 ns per output sample for
// 4 nodes), and per random-vibration component advanced by a rotation
// (2883 components at 8x, compensated increments: 142 us per output sample)
// or evaluated by a sine and a cosine (between grid instants: the raw
// increments' 4 nodes; SettingBounds.N9CpuEstimateOfHeavyChainsFollowsTheirMeasuredCost
// measured 36 ns for it beside 7.1 ns per rotation on the shared 2-core
// build machine at a load of 9, so 31 ns beside the bench's 6.2 ns, and a
// raw-increment chain of 6000 components 3.4-3.6 times the compensated
// one's cost). Issue 26, N9: the estimate counted the components
// per internal sample only, as if every one were a rotation, and put a
// 100,000-row PSD on a native (raw increments) device at 12 % of a core; it
// fell behind. SettingBounds.CpuEstimateOfHeavyChainsFollowsTheirMeasuredCost
// (tests/scene/test_setting_bounds.cpp) checks the units against a measured run.
inline constexpr double kCpuSecondsPerInternalSample = 0.32e-6;
inline constexpr double kCpuSecondsPerIncrementNode = 0.33e-6;
inline constexpr double kCpuSecondsPerVibrationRotation = 6.2e-9;
inline constexpr double kCpuSecondsPerVibrationDirect = 31e-9;
// CPU seconds of that work on the development machine.
double chain_cpu_seconds(const signal_chain::ChainWork& work);

struct ImuCheck {
  std::string name;
  std::string protocol;
  std::string transport;                 // "pty /run/imuemu/ttyIMU0", "serial /dev/ttyUSB0 921600 8N1, flow none", ...
  std::int64_t rate_hz = 0;
  int delta_samples = 0;                 // Delta of Eq. 3.68 at this rate
  TimeNs lookahead_ns = 0;               // StreamPipeline::lookahead_ns for the scene's knot interval
  TimeNs emission_delay_ns = 0;          // lookahead + live.margin_s, or live.latency_budget_ms: samples go out this long after their pose
  bool causal = false;                   // the causal Hermite method (live.latency_budget_ms below the smoothing look-ahead)
  TimeNs smoothing_lookahead_ns = 0;     // what the smoothing method would need
  TimeNs producer_lead_ns = 0;           // live: the producer computes a tick this long before it is due
  TimeNs arrival_slack_ns = 0;           // causal: a pose arriving this late after its mapped time is still used exactly
  // Causal: relative acceleration error bound of the Hermite cubic for a
  // motion at 1 Hz, (2 pi f h)^2 / 12 with the poses' rates (cubic Hermite
  // bound |p'' - H''| <= h^2/12 |p''''|), and 2 (2 pi f h)^2 with slopes
  // estimated from the poses (tests/core/test_causal_hermite.cpp).
  double accel_error_1hz_with_rates = 0.0, accel_error_1hz_estimated = 0.0;
  std::optional<double> bytes_per_second;     // byte-stream protocols: the outputs as configured at power-up (the verdict's)
  std::optional<double> worst_case_bytes_per_second;  // byte-stream protocols: max_bytes_per_sample x rate (every output)
  std::optional<double> can_frames_per_second;
  std::optional<drivers::LinkBudget> link;    // serial and can transports (pty and null have no line rate)
  double cpu_fraction = 0.0;             // of one core: rate x (kCpuSecondsPerSample + the chain's share)
  int oversampling = 1;                  // the signal chain's internal rate / rate_hz
  std::size_t vibration_components = 0;  // random vibration components (linear and angular)
  bool compensated_increments = false;   // the encoder's convention (raw: 4 quadrature nodes per sample)
  signal_chain::ChainWork work;          // the chain's work per output sample (predict_work)
  std::vector<std::string> error_model;  // each term with its discrete sigma at rate_hz (daemon/scene/error_model_config.hpp)
  std::vector<std::string> faults;       // [[imu.fault]] and [imu.random_faults], one line each (daemon/scene/fault_config.hpp)
};

struct SceneCheck {
  std::string file;
  std::string scene;
  std::string physics;       // flat | ecef
  std::string source;
  double knot_interval_s = 0.0;
  std::vector<ImuCheck> imus;
  double total_cpu_fraction = 0.0;
  TimeNs max_emission_delay_ns = 0;
  // Link budgets per shared link: devices on one CAN interface share its bus.
  struct SharedLink {
    std::string link;        // "can vcan0"
    std::vector<std::string> devices;
    drivers::LinkBudget budget;
  };
  std::vector<SharedLink> shared_links;
  bool refused = false;      // a link over 100 % or a fault the protocol cannot show: a start would refuse it
  std::vector<std::string> refusals;  // why, one line each (issue 26 N17: not always a link)
  std::vector<std::string> warnings;
};

struct RunnerOptions;  // daemon/scene/scene_runner.hpp

// What a start would refuse that the parser cannot see, checked without
// opening a device, by the functions the start path itself runs:
//  - the trajectory (file or built-in sample): loaded by scene_trajectory()
//    (a malformed file: io::CsvFormatError naming file:line), its knot count
//    and output size against core/limits.hpp, and every device's knots
//    through StreamPipeline::check_trajectory (the engine's own knot rules:
//    antipodal steps, gaps, end padding, the chart span);
//  - the published paths (check_start_paths).
// Throws std::invalid_argument (or CsvFormatError) naming the scene file, the
// device and what is wrong.
void check_startable(const SceneConfig& scene, const RunnerOptions& options);

// The paths a start creates: every pty link as published (pty_link_path, so
// --pty-link-dir included) must name a file (not "/", not a directory), fit
// PATH_MAX/NAME_MAX, and be distinct from the others and from the control
// socket after normalisation ("./x", "//x", "a/../x"); the control socket's
// directory must exist or be creatable. imuemud runs this before it starts.
// The outputs (issue 26 N15), before anything is opened or created: the fault
// log and --stats-json are distinct from each other, from the control socket,
// from every pty link and its "<link>.lock"; neither names a directory or a
// terminal (a path under /dev/pts, /dev/ptmx, /dev/tty*, or a symbolic link
// to /dev/pts/N: another imuemud's pty link); --stats-json's directory exists
// and is writable (it is written at exit, when nothing can be done about it).
struct OutputPaths {
  std::string fault_log;   // empty: none
  std::string stats_json;  // empty: none
};
void check_start_paths(const SceneConfig& scene, const RunnerOptions& options, const std::string& control_socket,
                       const OutputPaths& outputs = {});

// Computes the figures; throws std::invalid_argument only for a scene that
// parse_scene_* would not have produced.
SceneCheck check_scene(const SceneConfig& scene);
// "refused: REASON[; REASON...]" from check.refusals (the refusal's own words).
std::string refusal_text(const SceneCheck& check);
std::string to_text(const SceneCheck& check);
std::string to_json(const SceneCheck& check);  // one JSON object, 2-space indented

}  // namespace imuemu::scene
