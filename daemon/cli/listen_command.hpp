// `imuemu listen --protocol P --device D`: the project's own decoder of a live
// stream. Reads what an emulated (or real) IMU sends, decodes it with the
// protocol's decoder (drivers/protocols), checks sequence continuity and
// timing, and reports per sample and in a summary. The tests call listen()
// directly; the command line wraps it (run_listen).
//
//  - byte-stream protocols (native, mavlink2, mip): the device is a path read
//    through drivers::ByteStreamReader (pty or its published symlink, serial
//    port with the given settings, FIFO or file);
//  - CAN protocols (dronecan, j1939): the device is a SocketCAN interface,
//    "can:IFACE" or just "IFACE", read with drivers::CanReader.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <iosfwd>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "core/types.hpp"
#include "drivers/protocol.hpp"
#include "drivers/protocols/can_protocols.hpp"
#include "drivers/protocols/handshake.hpp"
#include "drivers/protocols/stream_protocols.hpp"
#include "drivers/serial_transport.hpp"

namespace CLI {
class App;
}

namespace imuemu::cli {

struct ListenArgs {
  std::string protocol;  // native | mavlink2 | mip | dronecan | j1939
  std::string device;    // path, or can:IFACE / IFACE for the CAN protocols
  drivers::SerialSettings serial;                // serial ports only
  drivers::StreamEncoderOptions stream_options;  // what the encoder was configured with
  drivers::CanEncoderOptions can_options;
  // CAN: only frames from this source (DroneCAN node id: the id's low 7 bits;
  // J1939 source address: its low 8 bits); others are counted and skipped.
  std::optional<std::uint8_t> can_source;
  double duration_s = 0.0;      // > 0: stop after this much wall time
  std::uint64_t count = 0;      // > 0: stop after this many samples
  bool json = false;            // NDJSON: one object per sample line, then the summary object
  bool quiet = false;           // no per-sample lines, the summary only
  std::uint64_t every = 1;      // print every Nth sample
  std::string out_path;         // CSV of every decoded sample (empty: none)
  double expect_rate_hz = 0.0;  // > 0: the summary says whether the measured rate matches
  double rate_tolerance = 0.01; // relative tolerance of that match
  // Before listening, act as the device's driver: write the start-up
  // sequence a common driver sends (drivers/protocols/handshake.hpp; mip and
  // mavlink2) and report each reply, waiting at most handshake_timeout_ms
  // for each.
  bool handshake = false;
  int handshake_timeout_ms = 1000;
};

struct ListenSummary {
  std::string protocol, device, device_description;
  std::string end_reason;      // count | duration | end of stream | stopped | device error: ...
  double wall_time_s = 0.0;
  std::uint64_t bytes_received = 0;       // byte streams
  std::uint64_t can_frames_received = 0;  // CAN
  std::uint64_t can_frames_other_source = 0;
  std::uint64_t can_kernel_drops = 0;
  // Decoder counters (drivers/protocol.hpp DecoderCounters).
  std::uint64_t frames = 0, checksum_errors = 0, resync_bytes = 0, sequence_gaps = 0, other_errors = 0;
  std::uint64_t samples = 0;  // samples taken (at most --count)
  // Own continuity check of the samples' sequence numbers: missing numbers
  // and backward steps (sender restarted, reordering). Empty when the
  // protocol has no per-sample counter (mip, j1939).
  std::optional<std::uint64_t> own_sequence_gaps;
  std::uint64_t sequence_backward_steps = 0;
  std::optional<TimeNs> first_sample_t_ns, last_sample_t_ns;  // the protocol's time field
  std::optional<double> rate_from_sample_time_hz;  // (n - 1) / (t_last - t_first)
  std::optional<double> rate_from_arrival_hz;      // same over CLOCK_MONOTONIC arrival times
  // |arrival interval - nominal interval| (nominal: 1 / expect_rate_hz, else
  // the mean arrival interval), microseconds; exact up to 16384 intervals,
  // then from a fixed histogram, never below the exact value and within 1 %
  // of |interval - reference| above it (daemon/cli/arrival_jitter.hpp).
  std::optional<double> jitter_p50_us, jitter_p99_us, jitter_max_us;
  std::optional<double> expected_rate_hz;
  // With expect_rate_hz and sample times: the rate of the sample-time grid,
  // (t_last - t_first) over the number of periods it spans, each time step
  // rounded to whole periods; and the samples skipped on that grid (a step of
  // k periods skips k - 1). A device that skips samples keeps its rate; one
  // whose period is off by more than half a period per step does not.
  std::optional<double> rate_of_sample_time_grid_hz;
  std::optional<std::uint64_t> missing_samples;
  std::optional<bool> rate_ok;  // with expect_rate_hz: the grid rate (else the arrival rate) within tolerance
  std::vector<drivers::handshake::StepResult> handshake;  // --handshake: each step as it ended
};

// A decoded sample and when it arrived (CLOCK_MONOTONIC ns).
using ListenSampleHook = std::function<void(const drivers::DecodedSample&, TimeNs arrival_monotonic_ns)>;

// The listening loop. Validates the options (std::invalid_argument naming
// the option), opens the device (drivers::TransportError naming it), then
// reads and decodes until --count samples, --duration-s, the end of the
// stream, a device error (reported in end_reason) or `stop`. Per-sample
// lines (human or JSON, unless quiet) go to `out`; the CSV to args.out_path
// (std::runtime_error naming it if it cannot be written). The summary is
// returned, not printed.
ListenSummary listen(const ListenArgs& args, std::ostream& out, const std::atomic<bool>& stop,
                     const ListenSampleHook& on_sample = {});

nlohmann::json summary_json(const ListenSummary& summary);  // {"type": "summary", ...}
std::string summary_text(const ListenSummary& summary);     // human, several lines

// The command: SIGINT/SIGTERM stop the loop (the summary is still printed);
// messages to stderr. Returns an exit code (daemon/cli/commands.hpp): 0 when it
// ran, kUsageError for bad options, kCannotProcess for a device that cannot
// be opened, kOutputError for an unwritable --out.
int run_listen(const ListenArgs& args);

void add_listen_command(CLI::App& app, int& exit_code);

}  // namespace imuemu::cli
