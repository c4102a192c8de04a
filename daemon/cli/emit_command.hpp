// `imuemu emit`: one emulated IMU on a pty, UART or CAN interface, driven in
// real time by the emission engine (daemon/engine/emission.hpp).
#pragma once

#include <cstdint>
#include <map>
#include <string>

namespace CLI {
class App;
}

namespace imuemu::cli {

struct EmitArgs {
  // Input: exactly one of these.
  std::string trajectory_path;  // trajectory CSV (docs/trajectory-format.md)
  std::string sample_kind;      // flight | circle | static (imuemu sample-trajectory)
  double sample_duration_s = 60.0;
  double sample_period_s = 1.0;
  std::string source;           // udp:ADDR:PORT | tcp:ADDR:PORT | stdin
  double knot_interval_s = 1.0; // live source: expected pose spacing (window, look-ahead)
  double tcp_idle_timeout_s = 5.0;  // tcp source: a client silent this long is closed (0: never)
  double margin_s = 0.1;        // live source: extra delay beyond the engine's look-ahead

  std::string scene = "ecef";
  double gravity_m_s2 = 9.80665;
  std::int64_t rate_hz = 400;
  int delta = -1;               // < 0: one median knot interval of output samples (as generate)
  std::string protocol = "native";
  std::string device;           // pty:LINK | serial:PATH[,baud=N] | can:IFACE
  bool can_fd = false;
  double seconds = -1.0;        // < 0: to the end of the input
  std::string gpio;             // CHIP:LINE
  std::uint64_t sync_every = 1;
  double sync_width_us = 100.0;
  bool sync_active_low = false;
  int priority = 0;
  bool lock_memory = false;
  bool require_realtime = false;
  std::string stats_json_path;
  std::string late_ticks = "drop"; // drop | send: a tick woken more than a period late (EngineOptions::drop_late_ticks)
  std::string start = "now";    // now | next-second
  // Trajectory time per wall time (a trajectory or --sample only): "1", "2.5",
  // "30", "1/3" (core/time_mapping.hpp parse_speed_factor).
  std::string speed = "1";
  // Protocol options as given on the command line: flag (--mavlink-system-id,
  // from drivers/protocols/protocol_options.hpp) -> its text.
  std::map<std::string, std::string> protocol_options;
  std::string sensor = "ideal";  // sensor error model: a preset or a TOML file (docs/sensor-models.md)
  std::int64_t seed = -1;        // < 0: the file's seed (0 for a preset)
};

int emit(const EmitArgs& args);
void add_emit_command(CLI::App& app, int& exit_code);

}  // namespace imuemu::cli
