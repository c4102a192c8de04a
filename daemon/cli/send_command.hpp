// `imuemu send`: a trajectory (a file `imuemu generate` reads, or a built-in
// sample) sent to a live pose source in real time: UDP pose datagrams v1 or
// v2, or TCP pose lines (docs/pose-wire-format.md). The sender every live
// scene needs (config/live-udp.toml, `imuemu stream --source udp:|tcp:`).
#pragma once

#include <string>

namespace CLI {
class App;
}

namespace imuemu::cli {

struct SendArgs {
  // Input: exactly one of these.
  std::string in_path;      // trajectory CSV (docs/trajectory-format.md)
  std::string sample_kind;  // flight | circle | static (imuemu sample-trajectory)
  double sample_duration_s = 60.0;
  double sample_period_s = 1.0;

  std::string to;                  // udp:HOST:PORT | tcp:HOST:PORT
  int datagram_version = 1;        // udp: 1 (84 bytes) or 2 (156 bytes, no rates: mask 0)
  std::string speed = "1";         // trajectory seconds per wall second ("2.5", "1/3"), or "max" (no pacing)
  bool loop = false;               // send again, times shifted by the span plus the last interval, until killed
  double connect_timeout_s = 5.0;  // tcp: keep trying to connect this long (the receiver may start later)
  bool quiet = false;
};

int send(const SendArgs& args);
void add_send_command(CLI::App& app, int& exit_code);

}  // namespace imuemu::cli
