// `imuemu generate`'s engine: the pipeline run as the sliding window it is
// (core/stream.hpp run_streaming), the sensor model applied to each sample as
// it comes out, and each sample written straight to the output files
// (io/sample_writers.hpp). Nothing proportional to the output is held: memory
// is the input knots plus the engine's O(window) buffers and the writers'
// 1 MiB buffers, whatever the duration (tests/test_cli.cpp
// Cli.GenerateFourHoursAtOneKilohertzInBoundedMemory).
#pragma once

#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "core/sensor/sensor_model.hpp"
#include "core/signal_chain/signal_chain.hpp"
#include "core/stream.hpp"
#include "daemon/error_model_config.hpp"

namespace imuemu::cli {

// The sensor stage of one device, one sample at a time: the device's signal
// chain (core/signal_chain/signal_chain.hpp: internal rate, sensor model,
// filters, decimation) on tick k of the grid t_k = t0 + floor(k 1e9 / rate)
// (scene::grid_index), exactly as imuemud's producer and `imuemu stream` run
// it on tick k, so all give the same bits. An ideal model and chain leave
// samples untouched.
class SensorStage {
 public:
  // Throws std::invalid_argument for a spec the model or the chain refuses.
  SensorStage(const scene::ErrorModelConfig& model, const std::string& device, std::int64_t rate_hz, TimeNs t0_ns,
              const SceneModel& scene);
  // Samples in increasing time (SensorModel::measure throws otherwise); the
  // measured sample (stamped t_k minus the group delay when the chain
  // compensates it).
  ImuSample apply(const StreamSample& sample);
  std::uint64_t saturated_samples() const noexcept { return saturated_; }

 private:
  std::optional<signal_chain::DeviceChain> chain_;
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
};

struct BatchCounts {
  std::size_t samples = 0;            // IMU rows written
  std::uint64_t saturated_samples = 0;
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
