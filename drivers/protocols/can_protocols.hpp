// The CAN protocols by name, with the options that shape what they send. A
// decoder made with the same options accepts exactly what the matching
// encoder sends.
//
//   "dronecan"  DroneCAN / UAVCAN v0: uavcan.equipment.ahrs.RawIMU (1003) per
//               sample + uavcan.protocol.NodeStatus (341) at 1 Hz
//               (drivers/protocols/dronecan.hpp)
//   "j1939"     SAE J1939: Angular Rate Information (PGN 61482), Acceleration
//               Sensor (61485) [+ Slope Sensor Information 2 (61481)]
//               (drivers/protocols/j1939.hpp)
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "drivers/protocol.hpp"
#include "drivers/protocols/dronecan.hpp"
#include "drivers/protocols/j1939.hpp"

namespace imuemu::drivers {

struct CanEncoderOptions {
  dronecan::DroneCanOptions dronecan;
  j1939::J1939Options j1939;
};

// The protocol names make_can_encoder/make_can_decoder accept.
std::vector<std::string> can_protocol_names();

// Throws std::invalid_argument naming the protocol or option that is wrong.
std::unique_ptr<CanEncoder> make_can_encoder(const std::string& protocol, const CanEncoderOptions& options = {});
std::unique_ptr<CanDecoder> make_can_decoder(const std::string& protocol, const CanEncoderOptions& options = {});

}  // namespace imuemu::drivers
