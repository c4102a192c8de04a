#include "daemon/batch_generation.hpp"

#include <memory>

#include "io/sample_writers.hpp"

namespace imuemu::cli {

SensorStage::SensorStage(const scene::ErrorModelConfig& model, const std::string& device, std::int64_t rate_hz,
                         TimeNs t0_ns)
    : rate_hz_(rate_hz), t0_ns_(t0_ns) {
  if (!model.ideal()) model_.emplace(model.spec, static_cast<double>(rate_hz), device);
}

void SensorStage::apply(ImuSample& sample) {
  if (!model_) return;  // the ideal sensor: no stage at all
  const sensor::Measurement r =
      model_->measure(scene::grid_index(t0_ns_, sample.t_ns, rate_hz_), sample.gyro_rad_s, sample.accel_m_s2);
  sample.gyro_rad_s = r.gyro_rad_s;
  sample.accel_m_s2 = r.accel_m_s2;
  if (r.saturated_axes != 0) ++saturated_;
}

BatchCounts generate_to_files(const std::vector<Pose>& knots, const PipelineOptions& options,
                              const scene::ErrorModelConfig& sensor_model, const std::string& device,
                              const BatchOutputs& outputs, const ProgressFn& progress) {
  // The whole-list checks (run_streaming's first step) before any file
  // exists, so a bad trajectory is reported as such.
  interp::check_knots(knots);
  SensorStage sensor(sensor_model, device, options.rate_hz, knots.front().t_ns);
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
        ImuSample measured = s.imu;
        sensor.apply(measured);
        imu.write(measured);
      },
      progress);
  // An empty IMU file is refused before the kinematics file replaces anything.
  if (imu.count() == 0) imu.commit();  // throws: no samples
  if (trajectory) trajectory->commit();
  imu.commit();
  return {imu.count(), sensor.saturated_samples()};
}

}  // namespace imuemu::cli
