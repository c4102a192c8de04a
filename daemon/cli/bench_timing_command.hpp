// `imuemu bench timing`: the emission path's wake-up lateness against the
// machine's floor (a bare clock_nanosleep loop at the same rate and priority).
#pragma once

#include <cstdint>
#include <string>

namespace CLI {
class App;
}

namespace imuemu::cli {

struct BenchTimingArgs {
  std::int64_t rate_hz = 1000;
  double seconds = 5.0;
  int devices = 1;
  int priority = 0;  // SCHED_FIFO for both loops; 0: normal scheduling
  std::string protocol = "native";
};

int bench_timing(const BenchTimingArgs& args);
// Registers `bench` (if not there yet) and its `timing` subcommand.
void add_bench_timing_command(CLI::App& app, int& exit_code);

}  // namespace imuemu::cli
