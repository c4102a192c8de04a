// `imuemud --check-config FILE`: what a valid scene will cost before it runs.
// Per device: the engine's look-ahead (how far behind the poses it emits),
// the link budget (drivers/link_budget.hpp: UART line time, CAN bus time with
// worst-case stuffing) and a CPU estimate; then the totals.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "daemon/scene_config.hpp"
#include "drivers/link_budget.hpp"

namespace imuemu::scene {

// Measured cost of one output sample of one device (smoothing, IMU equations,
// encoding) on the development machine: bench/bench_stream.cpp, ~1 us per
// sample at the default window. An estimate, not a guarantee: a wider window
// or finite-difference derivatives cost more.
inline constexpr double kCpuSecondsPerSample = 1e-6;

struct ImuCheck {
  std::string name;
  std::string protocol;
  std::string transport;                 // "pty /run/imuemu/ttyIMU0", "serial /dev/ttyUSB0 921600 8N1, flow none", ...
  std::int64_t rate_hz = 0;
  int delta_samples = 0;                 // Delta of Eq. 3.68 at this rate
  TimeNs lookahead_ns = 0;               // StreamPipeline::lookahead_ns for the scene's knot interval
  TimeNs emission_delay_ns = 0;          // lookahead + live.margin_s: samples go out this long after their pose
  std::optional<double> bytes_per_second;     // byte-stream protocols: max_bytes_per_sample x rate
  std::optional<double> can_frames_per_second;
  std::optional<drivers::LinkBudget> link;    // serial and can transports (pty and null have no line rate)
  double cpu_fraction = 0.0;             // of one core: rate x kCpuSecondsPerSample
  std::vector<std::string> error_model;  // each term with its discrete sigma at rate_hz (daemon/error_model_config.hpp)
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
  bool refused = false;      // a link over 100 %: the scene cannot keep its schedule
  std::vector<std::string> warnings;
};

// Computes the figures; throws std::invalid_argument only for a scene that
// parse_scene_* would not have produced.
SceneCheck check_scene(const SceneConfig& scene);
std::string to_text(const SceneCheck& check);
std::string to_json(const SceneCheck& check);  // one JSON object, 2-space indented

}  // namespace imuemu::scene
