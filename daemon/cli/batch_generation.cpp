#include "daemon/cli/batch_generation.hpp"

#include <filesystem>
#include <memory>
#include <sstream>

#include "core/time_arith.hpp"
#include "io/fault_log.hpp"
#include "io/atomic_file.hpp"
#include "io/sample_writers.hpp"

namespace imuemu::cli {

std::string fault_log_path_for(const std::string& output_path) {
  std::filesystem::path p(output_path);
  p.replace_extension(".faults.jsonl");
  return p.string();
}

SensorStage::SensorStage(const scene::ErrorModelConfig& model, const std::string& device, std::int64_t rate_hz,
                         TimeNs t0_ns, const SceneModel& scene, const BatchFaults* faults)
    : rate_hz_(rate_hz), t0_ns_(t0_ns) {
  if (!model.ideal()) chain_.emplace(scene, model.sensor(), model.chain, rate_hz, device);
  if (faults != nullptr && faults->any()) {
    fault::TimelineOptions o;
    o.context = fault::device_context(device, rate_hz, model.sensor());
    o.faults = faults->faults;
    o.random = faults->random;
    faults_.emplace(std::move(o));
  }
}

ImuSample SensorStage::apply(const StreamSample& sample) {
  if (!chain_ && !faults_) return sample.imu;  // the ideal sensor and chain, no fault: no stage at all
  const std::uint64_t k = scene::grid_index(t0_ns_, sample.imu.t_ns, rate_hz_);
  ImuSample out = sample.imu;
  if (chain_) {
    const Kinematics* previous = previous_ && previous_->first + 1 == k ? &previous_->second : nullptr;
    const signal_chain::ChainOutput r = chain_->step(k, sample.kinematics, sample.imu, previous, std::nullopt);
    previous_.emplace(k, sample.kinematics);
    out.gyro_rad_s = r.gyro_rad_s;
    out.accel_m_s2 = r.accel_m_s2;
    out.t_ns = saturating_sub_ns(out.t_ns, r.stamp_shift_ns);
    if (r.saturated_axes != 0) ++saturated_;
  }
  if (faults_) {
    // At the tick's grid time t_k (the timeline's clock), on the chain's
    // output; generate writes no increments (they stay zero here).
    fault::SampleValues v;
    v.gyro_rad_s = out.gyro_rad_s;
    v.accel_m_s2 = out.accel_m_s2;
    const fault::SampleFaults f = faults_->step(k, sample.imu.t_ns, v);
    out.gyro_rad_s = v.gyro_rad_s;
    out.accel_m_s2 = v.accel_m_s2;
    if (f.active != 0) ++faulted_;
  }
  return out;
}

BatchCounts generate_to_files(const std::vector<Pose>& knots, const PipelineOptions& options,
                              const scene::ErrorModelConfig& sensor_model, const std::string& device,
                              const BatchOutputs& outputs, const ProgressFn& progress) {
  // The whole-list checks (run_streaming's first step) before any file
  // exists, so a bad trajectory is reported as such.
  interp::check_knots(knots);
  SensorStage sensor(sensor_model, device, options.rate_hz, knots.front().t_ns, options.scene, &outputs.faults);
  // The fault log: JSON lines as the events come (bounded memory), committed with the IMU file.
  std::unique_ptr<io::AtomicFileWriter> fault_log;
  std::string fault_log_path;
  if (sensor.faults() != nullptr) {
    fault_log_path =
        outputs.faults.log_path.empty() ? fault_log_path_for(outputs.imu_csv_path) : outputs.faults.log_path;
    fault_log = std::make_unique<io::AtomicFileWriter>(fault_log_path);
  }
  std::vector<fault::FaultEvent> events;
  std::uint64_t event_lines = 0;
  auto write_events = [&] {
    if (!fault_log) return;
    events.clear();
    sensor.faults()->drain_events(events);
    for (const fault::FaultEvent& e : events) {
      std::ostringstream line;
      fault_log::write_fault_event_json_line(line, e);
      fault_log->write(line.str());
      ++event_lines;
    }
  };
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
        write_events();
      },
      progress);
  // An empty IMU file is refused before the kinematics file replaces anything.
  if (imu.count() == 0) imu.commit();  // throws: no samples
  if (sensor.faults() != nullptr) {
    sensor.faults()->finish();  // faults still acting end at the last sample
    write_events();
    if (sensor.faults()->counters().events_overflowed != 0)  // drained every sample: cannot happen
      throw std::logic_error("fault log: events lost");
  }
  if (trajectory) trajectory->commit();
  if (fault_log) fault_log->commit();
  imu.commit();
  return {imu.count(), sensor.saturated_samples(), sensor.faulted_samples(), event_lines, fault_log_path};
}

}  // namespace imuemu::cli
