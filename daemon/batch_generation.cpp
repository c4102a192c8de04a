#include "daemon/batch_generation.hpp"

#include <memory>

#include "core/time_arith.hpp"

#include "io/sample_writers.hpp"

namespace imuemu::cli {

SensorStage::SensorStage(const scene::ErrorModelConfig& model, const std::string& device, std::int64_t rate_hz,
                         TimeNs t0_ns, const SceneModel& scene)
    : rate_hz_(rate_hz), t0_ns_(t0_ns) {
  if (!model.ideal()) chain_.emplace(scene, model.sensor(), model.chain, rate_hz, device);
}

ImuSample SensorStage::apply(const StreamSample& sample) {
  if (!chain_) return sample.imu;  // the ideal sensor and chain: no stage at all
  const std::uint64_t k = scene::grid_index(t0_ns_, sample.imu.t_ns, rate_hz_);
  const Kinematics* previous = previous_ && previous_->first + 1 == k ? &previous_->second : nullptr;
  const signal_chain::ChainOutput r = chain_->step(k, sample.kinematics, sample.imu, previous, std::nullopt);
  previous_.emplace(k, sample.kinematics);
  ImuSample out = sample.imu;
  out.gyro_rad_s = r.gyro_rad_s;
  out.accel_m_s2 = r.accel_m_s2;
  out.t_ns = saturating_sub_ns(out.t_ns, r.stamp_shift_ns);
  if (r.saturated_axes != 0) ++saturated_;
  return out;
}

BatchCounts generate_to_files(const std::vector<Pose>& knots, const PipelineOptions& options,
                              const scene::ErrorModelConfig& sensor_model, const std::string& device,
                              const BatchOutputs& outputs, const ProgressFn& progress) {
  // The whole-list checks (run_streaming's first step) before any file
  // exists, so a bad trajectory is reported as such.
  interp::check_knots(knots);
  SensorStage sensor(sensor_model, device, options.rate_hz, knots.front().t_ns, options.scene);
  io::ImuCsvWriter imu(outputs.imu_csv_path);
  std::unique_ptr<io::KinematicsCsvWriter> trajectory;
  if (!outputs.trajectory_csv_path.empty())
    trajectory = std::make_unique<io::KinematicsCsvWriter>(outputs.trajectory_csv_path, outputs.physics);
  run_streaming(
      knots, options,
      [&](const StreamSample& s) {
        // The kinematics file holds the whole smoothed trajectory (as before
        // --max-seconds cut only the IMU samples).
        if (trajectory) trajectory->write(s.kinematics);
        if (s.imu.t_ns >= outputs.end_ns) return;
        imu.write(sensor.apply(s));
      },
      progress);
  // An empty IMU file is refused before the kinematics file replaces anything.
  if (imu.count() == 0) imu.commit();  // throws: no samples
  if (trajectory) trajectory->commit();
  imu.commit();
  return {imu.count(), sensor.saturated_samples()};
}

}  // namespace imuemu::cli
