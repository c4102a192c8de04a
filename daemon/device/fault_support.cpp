// Which link faults a device's protocol can show (drivers/link_fault.hpp
// link_fault_support): the check behind Device::check_supports and `imuemu
// check-config`, so that a fault is refused when it would do nothing on the
// wire while the fault log claims it acted.
#include <stdexcept>
#include <string>

#include "daemon/device/device.hpp"

namespace imuemu::device {

namespace {

void check(const std::string& imu, const std::string& protocol, const drivers::LinkFaultSupport& s, fault::Kind kind) {
  using fault::Kind;
  const char* missing = nullptr;
  switch (kind) {
    case Kind::sequence_jump:
    case Kind::sequence_reset: if (!s.sequence) missing = "no sequence counter"; break;
    case Kind::bad_checksum: if (!s.checksum) missing = "no checksum field"; break;
    case Kind::bad_length: if (!s.length) missing = "no length field"; break;
    case Kind::bit_errors: if (!s.bit_errors) missing = "no bit errors on this link (CAN's CRC and retransmission hide them)"; break;
    case Kind::can_wrong_id: if (!s.can_id) missing = "no CAN identifier"; break;
    case Kind::can_missing_frame: if (!s.missing_frame) missing = "no multi-frame transfers"; break;
    default: break;
  }
  if (missing != nullptr)
    throw std::invalid_argument("fault type " + std::string(fault::kind_name(kind)) + " on imu '" + imu + "' (" +
                                protocol + "): the protocol has " + missing + ", the fault would show nothing");
}

}  // namespace

void check_supports(const std::string& imu, const drivers::StreamEncoder& encoder, fault::Kind kind) {
  check(imu, encoder.name(), drivers::link_fault_support(encoder), kind);
}

void check_supports(const std::string& imu, const drivers::CanEncoder& encoder, fault::Kind kind) {
  check(imu, encoder.name(), drivers::link_fault_support(encoder), kind);
}

}  // namespace imuemu::device
