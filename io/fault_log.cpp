// The fault log's JSON lines (io/fault_log.hpp).
#include "io/fault_log.hpp"

namespace imuemu::fault_log {

nlohmann::json fault_parameters_json(const fault::FaultSpec& s) {
  using fault::Kind;
  nlohmann::json p = nlohmann::json::object();
  const bool gyro = (static_cast<unsigned>(s.triad) & 1u) != 0, accel = (static_cast<unsigned>(s.triad) & 2u) != 0;
  switch (s.kind) {
    case Kind::bias_step:
    case Kind::spikes:
      if (s.kind == Kind::spikes) p["rate_hz"] = s.rate_hz;
      if (gyro) p["gyro_bias_rad_s"] = s.gyro_bias_rad_s;
      if (accel) p["accel_bias_m_s2"] = s.accel_bias_m_s2;
      break;
    case Kind::bias_ramp:
      if (gyro) p["gyro_ramp_rad_s2"] = s.gyro_ramp_rad_s2;
      if (accel) p["accel_ramp_m_s3"] = s.accel_ramp_m_s3;
      break;
    case Kind::plausible_drift:
      if (gyro) {
        p["gyro_ramp_rad_s2"] = s.gyro_ramp_rad_s2;
        p["gyro_bias_rad_s"] = s.gyro_bias_rad_s;
      }
      if (accel) {
        p["accel_ramp_m_s3"] = s.accel_ramp_m_s3;
        p["accel_bias_m_s2"] = s.accel_bias_m_s2;
      }
      break;
    case Kind::scale_step: p["scale_ppm"] = s.scale_ppm; break;
    case Kind::noise_gain: p["noise_factor"] = s.noise_factor; break;
    case Kind::slow: p["divisor"] = s.divisor; break;
    case Kind::intermittent:
      p["on_ns"] = s.on_ns;
      p["off_ns"] = s.off_ns;
      break;
    case Kind::delayed: p["delay_ns"] = s.delay_ns; break;
    case Kind::drop:
      if (s.burst_samples > 0) {
        p["burst_samples"] = s.burst_samples;
        p["rate_hz"] = s.rate_hz;
      } else {
        p["probability"] = s.probability;
      }
      break;
    case Kind::duplicate:
    case Kind::bad_checksum:
    case Kind::bad_length:
    case Kind::can_missing_frame: p["probability"] = s.probability; break;
    case Kind::truncate:
      p["truncate_bytes"] = s.truncate_bytes;
      p["probability"] = s.probability;
      break;
    case Kind::can_wrong_id:
      p["can_id"] = s.can_id;
      p["probability"] = s.probability;
      break;
    case Kind::bit_errors: p["bit_error_rate"] = s.bit_error_rate; break;
    case Kind::sequence_jump: p["sequence_step"] = s.sequence_step; break;
    case Kind::time_jump: p["time_step_ns"] = s.time_step_ns; break;
    case Kind::babble: p["babble_factor"] = s.babble_factor; break;
    default: break;
  }
  return p;
}

nlohmann::json fault_event_json(const fault::FaultEvent& e) {
  static const char* const kAxes[8] = {"", "x", "y", "xy", "z", "xz", "yz", "xyz"};
  const fault::FaultSpec& s = e.spec;
  nlohmann::json j;
  j["device"] = s.device;
  j["phase"] = e.phase == fault::FaultEvent::Phase::start ? "start" : "end";
  j["fault_id"] = e.fault_id;
  j["type"] = std::string(fault::kind_name(s.kind));
  j["source"] = s.source;
  j["sample_counter"] = e.sample_counter;
  j["t_ns"] = e.t_ns;
  if (fault::is_sensor_fault(s.kind)) {
    j["sensor"] = s.triad == fault::Triad::gyro ? "gyro" : s.triad == fault::Triad::accel ? "accel" : "both";
    j["axes"] = kAxes[s.axes & 7u];
  }
  j["clock"] = s.clock == fault::Clock::trajectory ? "trajectory" : "since_start";
  j["start_ns"] = s.start_ns;
  j["duration_ns"] = s.duration_ns;
  j["flag_status"] = s.flag_status;
  j["seed"] = s.seed;
  j["parameters"] = fault_parameters_json(s);
  return j;
}

std::ostream& write_fault_event_json_line(std::ostream& out, const fault::FaultEvent& event) {
  // Non-finite numbers cannot occur (validate refuses them); dump() would
  // write them as null.
  out << fault_event_json(event).dump() << '\n';
  return out;
}

}  // namespace imuemu::fault_log
