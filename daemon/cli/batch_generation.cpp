#include "daemon/cli/batch_generation.hpp"

#include <charconv>
#include <filesystem>
#include <memory>
#include <sstream>

#include "core/time_arith.hpp"
#include "daemon/device/frame_navigation.hpp"
#include "drivers/gnss_fix.hpp"
#include "drivers/protocols/mavlink2.hpp"
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

namespace {

// Shortest decimal that reads back as the same double.
void append_number(std::string& line, double v) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  line.append(buf, r.ptr);
}

// The aiding sensors' CSV files (BatchOutputs::gnss_csv_path,
// baro_csv_path): the device's own encoder (or fix source) stepped on every
// sample with the navigation fields imuemud's producer gives it
// (daemon/engine/producer.cpp set_navigation: geodetic position, NED
// velocity and R_s^n of the sample's kinematics, Eq. 1.1 and 1.5).
class AidingFiles {
 public:
  AidingFiles(const BatchOutputs& o, Physics physics, std::int64_t rate_hz) : rate_hz_(rate_hz) {
    if (o.gnss_csv_path.empty() && o.baro_csv_path.empty()) return;
    if (physics != Physics::ecef)
      throw std::invalid_argument("--gnss-out/--baro-out need an ecef scene (a flat scene has no geodetic position)");
    const bool mavlink = o.aiding_protocol == "mavlink2";
    const bool receiver = o.aiding_protocol == "nmea" || o.aiding_protocol == "ubx";
    if (!o.gnss_csv_path.empty() && !(receiver || (mavlink && o.aiding_options.mavlink_hil_gps_rate_hz > 0)))
      throw std::invalid_argument("--gnss-out: the device sends no GNSS fix (protocol " + o.aiding_protocol +
                                  "; give [imu.mavlink] hil_gps_rate_hz, or an nmea/ubx device)");
    if (!o.baro_csv_path.empty() && !(mavlink && o.aiding_options.mavlink_baro))
      throw std::invalid_argument("--baro-out: the device sends no barometer (protocol " + o.aiding_protocol +
                                  "; give [imu.mavlink] baro = true)");
    drivers::StreamEncoderOptions so = o.aiding_options;
    so.mavlink_answers_commands = false;  // no command side: nobody talks to a batch run
    if (mavlink) mavlink_.emplace(so);
    else receiver_.emplace(so.gnss, so.nominal_sample_rate_hz, so.device_name);
    if (!o.gnss_csv_path.empty()) {
      gnss_ = std::make_unique<io::AtomicFileWriter>(o.gnss_csv_path);
      gnss_->write(
          "time_ns,gps_time_ns,latitude_rad,longitude_rad,height_m,velocity_north_m_s,velocity_east_m_s,"
          "velocity_down_m_s,fix_type,satellites,hdop,vdop\n");
    }
    if (!o.baro_csv_path.empty()) {
      baro_ = std::make_unique<io::AtomicFileWriter>(o.baro_csv_path);
      baro_->write("time_ns,pressure_pa,temperature_k,pressure_altitude_m\n");
    }
  }
  bool any() const { return gnss_ || baro_; }

  void step(const StreamSample& s, TimeNs t0_ns) {
    if (!any()) return;
    drivers::ImuFrameInput f;
    f.sample_counter = scene::grid_index(t0_ns, s.imu.t_ns, rate_hz_);
    f.t_ns = s.imu.t_ns;
    f.period_ns = kNsPerSecond / rate_hz_;
    device::set_frame_navigation(s.kinematics, Physics::ecef, f);  // the fixes of an ecef scene
    if (mavlink_) {
      // encode()'s order: the sample's readings, then HIL_GPS.
      const drivers::mavlink2::Encoder::AidingReading& r = mavlink_->aiding_of(f);
      if (baro_ && r.has_pressure) {
        line_.clear();
        line_ += std::to_string(f.t_ns);
        line_ += ',';
        append_number(line_, r.pressure_pa);
        line_ += ',';
        append_number(line_, r.temperature_k);
        line_ += ',';
        if (r.has_pressure_altitude) append_number(line_, r.pressure_altitude_m);
        line_ += '\n';
        baro_->write(line_);
      }
      if (gnss_)
        if (const std::optional<drivers::GnssFix> fix = mavlink_->hil_gps_fix(f)) write_fix(f.t_ns, *fix);
    } else if (receiver_ && gnss_) {
      const drivers::GnssFix fix = receiver_->fix(f);
      if (fix.fix_type != drivers::GnssFixType::none) write_fix(f.t_ns, fix);
    }
  }

  void commit() {
    if (gnss_) gnss_->commit();
    if (baro_) baro_->commit();
  }

 private:
  void write_fix(TimeNs t_ns, const drivers::GnssFix& fix) {
    line_.clear();
    line_ += std::to_string(t_ns);
    line_ += ',';
    if (fix.time_valid) line_ += std::to_string(fix.gps_time_ns);
    for (double v : {fix.latitude_rad, fix.longitude_rad, fix.height_m, fix.velocity_ned_m_s.x(),
                     fix.velocity_ned_m_s.y(), fix.velocity_ned_m_s.z()}) {
      line_ += ',';
      append_number(line_, v);
    }
    line_ += ',';
    line_ += fix.fix_type == drivers::GnssFixType::fix_3d ? "3" : fix.fix_type == drivers::GnssFixType::fix_2d ? "2" : "0";
    line_ += ',';
    line_ += std::to_string(fix.satellites);
    line_ += ',';
    append_number(line_, fix.hdop);
    line_ += ',';
    append_number(line_, fix.vdop);
    line_ += '\n';
    gnss_->write(line_);
  }

  std::int64_t rate_hz_;
  std::optional<drivers::mavlink2::Encoder> mavlink_;
  std::optional<drivers::GnssFixSource> receiver_;
  std::unique_ptr<io::AtomicFileWriter> gnss_, baro_;
  std::string line_;
};

}  // namespace

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
  AidingFiles aiding(outputs, options.scene.physics, options.rate_hz);
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
        aiding.step(s, knots.front().t_ns);
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
  aiding.commit();
  imu.commit();
  return {imu.count(), sensor.saturated_samples(), sensor.faulted_samples(), event_lines, fault_log_path};
}

}  // namespace imuemu::cli
