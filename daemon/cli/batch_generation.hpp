// `imuemu generate`'s engine: the pipeline run as the sliding window it is
// (core/stream.hpp run_streaming), the sensor model applied to each sample as
// it comes out, and each sample written straight to the output files
// (io/sample_writers.hpp). Nothing proportional to the output is held: memory
// is the input knots plus the engine's O(window) buffers and the writers'
// 1 MiB buffers, whatever the duration (tests/cli/test_cli.cpp
// Cli.GenerateFourHoursAtOneKilohertzInBoundedMemory).
#pragma once

#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "core/fault/fault.hpp"
#include "core/fault/timeline.hpp"
#include "core/sensor/sensor_model.hpp"
#include "core/signal_chain/signal_chain.hpp"
#include "core/stream.hpp"
#include "daemon/scene/error_model_config.hpp"
#include "drivers/protocols/stream_protocols.hpp"

namespace imuemu::cli {

// The sensor stage of one device, one sample at a time: the device's signal
// chain (core/signal_chain/signal_chain.hpp: internal rate, sensor model,
// filters, decimation) on tick k of the grid t_k = t0 + floor(k 1e9 / rate)
// (scene::grid_index), exactly as imuemud's producer and `imuemu stream` run
// it on tick k, so all give the same bits. An ideal model and chain leave
// samples untouched.
//
// Faults (issue 18, core/fault/timeline.hpp): the device's FaultTimeline
// acts on the chain's output of tick k at its grid time t_k, as imuemud's
// producer does, so generate is the batch reference for the faulted output
// too. Link faults are decided (and logged) but act on the wire only.
struct BatchFaults {
  std::vector<fault::FaultSpec> faults;  // the scene's [[imu.fault]]
  fault::RandomFaults random;            // [imu.random_faults]
  std::string log_path;                  // JSON lines (io/fault_log.hpp); empty: beside the IMU file
  bool any() const { return !faults.empty() || random.per_hour > 0.0; }
};

// The fault log beside an output file: "dir/imu.csv" -> "dir/imu.faults.jsonl".
std::string fault_log_path_for(const std::string& output_path);

class SensorStage {
 public:
  // Throws std::invalid_argument for a spec the model, the chain or the
  // fault timeline refuses. faults: none when null or empty.
  SensorStage(const scene::ErrorModelConfig& model, const std::string& device, std::int64_t rate_hz, TimeNs t0_ns,
              const SceneModel& scene, const BatchFaults* faults = nullptr);
  // Samples in increasing time (SensorModel::measure throws otherwise); the
  // measured sample (stamped t_k minus the group delay when the chain
  // compensates it), with the active sensor faults applied.
  ImuSample apply(const StreamSample& sample);
  std::uint64_t saturated_samples() const noexcept { return saturated_; }
  std::uint64_t faulted_samples() const noexcept { return faulted_; }
  // The timeline (null without faults): events to drain, finish().
  fault::FaultTimeline* faults() noexcept { return faults_ ? &*faults_ : nullptr; }

 private:
  std::optional<signal_chain::DeviceChain> chain_;
  std::optional<fault::FaultTimeline> faults_;
  std::uint64_t faulted_ = 0;
  std::int64_t rate_hz_;
  TimeNs t0_ns_;
  std::optional<std::pair<std::uint64_t, Kinematics>> previous_;  // tick k - 1
  std::uint64_t saturated_ = 0;
};

struct BatchOutputs {
  std::string imu_csv_path;         // required
  std::string trajectory_csv_path;  // empty: no kinematics file
  Physics physics = Physics::flat;  // the kinematics file's columns
  // Only samples before this time are kept (generate --max-seconds).
  TimeNs end_ns = std::numeric_limits<TimeNs>::max();
  // Faults on the samples and their log (written, like the other outputs,
  // only when the whole run succeeded; only when there are faults).
  BatchFaults faults;
  // Issue 28: the device's aiding sensors, as its encoder computes them for
  // the wire (an ecef scene: they need the samples' geodetic position).
  // gnss_csv_path: protocol mavlink2, the HIL_GPS fixes
  // (mavlink2::Encoder::hil_gps_fix, at hil_gps_rate_hz); nmea / ubx, the
  // receiver's fix of every sample (GnssFixSource::fix(sample), as their
  // encoders). baro_csv_path: mavlink2 with baro, each sample's reading
  // (mavlink2::Encoder::aiding_of). The encoder is built from
  // aiding_options (the device's StreamEncoderOptions with its nominal rate
  // and seed) and stepped on every sample before end_ns, as encode() is.
  // Empty paths: nothing built, nothing written.
  std::string gnss_csv_path, baro_csv_path;
  std::string aiding_protocol;
  drivers::StreamEncoderOptions aiding_options;
};

struct BatchCounts {
  std::size_t samples = 0;            // IMU rows written
  std::uint64_t saturated_samples = 0;
  std::uint64_t faulted_samples = 0;  // samples with at least one fault acting
  std::uint64_t fault_events = 0;     // lines in the fault log
  std::string fault_log_path;         // empty: no faults, no log
};

// Runs the pipeline over `knots` and writes every sample as it is made. Both
// output files are created (as temporaries) before the first knot is pushed
// and committed only once every sample was written, the kinematics file
// first: a run refused half way (bad knot, non-finite value, I/O error)
// replaces neither file. Throws what run_streaming and the writers throw.
BatchCounts generate_to_files(const std::vector<Pose>& knots, const PipelineOptions& options,
                              const scene::ErrorModelConfig& sensor_model, const std::string& device,
                              const BatchOutputs& outputs, const ProgressFn& progress = {});

}  // namespace imuemu::cli
