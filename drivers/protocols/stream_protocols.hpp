// The byte-stream protocols (UART, pty) by name, with the options that shape
// what they send. A decoder made with the same options accepts exactly what
// the matching encoder sends.
//
//   "native"   imuemu native v1 (docs/native-protocol.md): f64, CRC-32C
//   "mavlink2" MAVLink 2 HIL_SENSOR (#107) [+ HIGHRES_IMU (#105)] + HEARTBEAT
//   "mip"      MicroStrain MIP, IMU data set 0x80
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "drivers/protocol.hpp"

namespace imuemu::drivers {

struct StreamEncoderOptions {
  // native and mip: send delta-theta / delta-velocity as well as the rates.
  bool include_deltas = true;

  // mavlink2. Source address (MAVLink guide, packet format: 0 is not a valid
  // source for either). 200 = MAV_COMP_ID_IMU (common.xml MAV_COMPONENT).
  std::uint8_t mavlink_system_id = 1;
  std::uint8_t mavlink_component_id = 200;
  bool mavlink_heartbeat = true;       // HEARTBEAT at 1 Hz from periodic()
  bool mavlink_hil_sensor = true;      // HIL_SENSOR (#107), what PX4 takes in HIL mode
  bool mavlink_highres_imu = false;    // HIGHRES_IMU (#105)
  std::uint8_t mavlink_sensor_id = 0;  // the messages' `id` extension field
  // HIL_SENSOR/HIGHRES_IMU `temperature` (degC, fields_updated bit 12) when
  // set; otherwise not sent (bit clear, field zero).
  std::optional<double> mavlink_temperature_degC;

  // mip. GPS time (ns since the GPS epoch 1980-01-06T00:00:00, GPS time
  // scale, no leap seconds) that trajectory time t_ns = 0 corresponds to; the
  // GPS timestamp field (0x80,0x12) carries gps = this + t_ns as week and
  // time of week.
  std::int64_t mip_gps_time_at_t0_ns = 0;
  // Overrange status field (0x80,0x18): where the saturated bit goes.
  bool mip_overrange_status = true;

  // The sample rate the encoder will run at, only to spread periodic traffic
  // (heartbeats) over samples in max_bytes_per_sample(); 0 = unknown (then
  // one whole heartbeat is charged to every sample, an upper bound).
  double nominal_sample_rate_hz = 0.0;
};

// The protocol names make_stream_encoder/make_stream_decoder accept.
std::vector<std::string> stream_protocol_names();

// Throws std::invalid_argument naming the protocol or option that is wrong.
std::unique_ptr<StreamEncoder> make_stream_encoder(const std::string& protocol,
                                                   const StreamEncoderOptions& options = {});
std::unique_ptr<StreamDecoder> make_stream_decoder(const std::string& protocol,
                                                   const StreamEncoderOptions& options = {});

}  // namespace imuemu::drivers
