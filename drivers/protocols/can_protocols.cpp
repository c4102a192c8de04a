#include "drivers/protocols/can_protocols.hpp"

#include <stdexcept>

namespace imuemu::drivers {

namespace {

[[noreturn]] void unknown_protocol(const std::string& protocol) {
  std::string known;
  for (const std::string& name : can_protocol_names()) known += (known.empty() ? "" : ", ") + name;
  throw std::invalid_argument("unknown CAN protocol '" + protocol + "' (known: " + known + ")");
}

}  // namespace

std::vector<std::string> can_protocol_names() { return {"dronecan", "j1939"}; }

std::unique_ptr<CanEncoder> make_can_encoder(const std::string& protocol, const CanEncoderOptions& options) {
  if (protocol == "dronecan") return std::make_unique<dronecan::DroneCanEncoder>(options.dronecan);
  if (protocol == "j1939") return std::make_unique<j1939::J1939Encoder>(options.j1939);
  unknown_protocol(protocol);
}

std::unique_ptr<CanDecoder> make_can_decoder(const std::string& protocol, const CanEncoderOptions& options) {
  if (protocol == "dronecan") {
    dronecan::validate(options.dronecan);
    return std::make_unique<dronecan::DroneCanDecoder>(options.dronecan);
  }
  if (protocol == "j1939") {
    j1939::validate(options.j1939);
    return std::make_unique<j1939::J1939Decoder>(options.j1939);
  }
  unknown_protocol(protocol);
}

}  // namespace imuemu::drivers
