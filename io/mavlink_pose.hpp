// MAVLink 2 HIL_STATE_QUATERNION (#115) as a live pose input: what simulator
// bridges (PX4/ArduPilot HITL, Gazebo, JSBSim, X-Plane) send to a flight
// controller, read from UDP datagrams (docs/pose-wire-format.md §4).
//
// Written from the MAVLink developer guide ("Packet Serialization":
// MAVLink 2 packet layout, field reordering by type size, CRC_EXTRA, payload
// truncation, incompatibility flags) and message_definitions/v1.0/common.xml
// (HIL_STATE_QUATERNION); no generated headers, nothing copied. The
// independent reference for the golden bytes and CRC_EXTRA is
// tests/support/protocol_reference.py.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <map>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "io/pose_wire.hpp"
#include "io/trajectory_csv.hpp"

namespace imuemu::io::mavlink {

inline constexpr std::uint8_t kMagicV2 = 0xFD;  // MAVLink 2 STX
inline constexpr std::uint8_t kMagicV1 = 0xFE;  // MAVLink 1 STX: refused (no message id above 255, no flags)
inline constexpr std::size_t kHeaderBytes = 10;  // STX .. msgid
inline constexpr std::size_t kChecksumBytes = 2;
inline constexpr std::size_t kSignatureBytes = 13;
inline constexpr std::uint8_t kIncompatSigned = 0x01;

// common.xml HIL_STATE_QUATERNION: id 115, 64 payload bytes, no extension
// fields; CRC_EXTRA 4 (recomputed from the field list in the test).
inline constexpr std::uint32_t kHilStateQuaternionId = 115;
inline constexpr std::uint8_t kHilStateQuaternionCrcExtra = 4;
inline constexpr std::size_t kHilStateQuaternionPayloadBytes = 64;

// The message's fields in common.xml units (wire order = XML order here:
// already sorted by type size).
struct HilStateQuaternion {
  std::uint64_t time_usec = 0;                  // us: since the UNIX epoch or since the simulator's boot
  std::array<float, 4> attitude_quaternion{};  // w, x, y, z: body FRD to local NED (1 0 0 0 = level, north)
  float rollspeed_rad_s = 0, pitchspeed_rad_s = 0, yawspeed_rad_s = 0;  // body-frame angular rate
  std::int32_t lat_degE7 = 0, lon_degE7 = 0;   // 1e-7 deg
  std::int32_t alt_mm = 0;                     // mm
  std::int16_t vx_cm_s = 0, vy_cm_s = 0, vz_cm_s = 0;  // ground velocity, NED
  std::uint16_t ind_airspeed_cm_s = 0, true_airspeed_cm_s = 0;
  std::int16_t xacc_mG = 0, yacc_mG = 0, zacc_mG = 0;  // body-frame acceleration, milli-g
};

// Header fields of a received packet.
struct PacketInfo {
  std::uint8_t sequence = 0;
  std::uint8_t system_id = 0;
  std::uint8_t component_id = 0;
};

// One MAVLink 2 HIL_STATE_QUATERNION packet (unsigned, payload truncated of
// trailing zero bytes as the guide requires). For the test simulator, the
// bench and golden tests; does not validate.
std::vector<std::uint8_t> encode_hil_state_quaternion(const HilStateQuaternion& message, const PacketInfo& header);

// X.25 CRC (CRC-16/MCRF4XX), as drivers/protocols/mavlink2 computes it.
std::uint16_t crc16_mcrf4xx(std::span<const std::uint8_t> bytes) noexcept;

enum class Outcome {
  hil_state,  // `message` and `info` hold the datagram's HIL_STATE_QUATERNION
  other,      // only whole packets of other messages (HEARTBEAT, HIL_SENSOR, ...): ignored
  refused,    // `error` says why (DatagramError reasons, docs/pose-wire-format.md §4.3)
};

// A datagram holding whole MAVLink 2 packets, one of which may be a
// HIL_STATE_QUATERNION. Packets of other ids are skipped by their length
// (their CRC_EXTRA is not known here, so they are neither checked nor used).
Outcome decode_datagram(std::span<const std::uint8_t> bytes, HilStateQuaternion& message, PacketInfo& info,
                        DatagramDecodeError& error);

// The pose it carries as a trajectory record (geodetic position, q_b^l, the
// rates of docs/pose-wire-format.md §4.2). time_usec becomes t_ns. False (with
// error.intact set) for values a pose cannot have: non-unit or non-finite
// quaternion, latitude beyond +-90 deg, longitude beyond +-180 deg,
// non-finite rates or rates beyond the physical bounds of io/pose_wire.hpp
// (check_live_rates), time beyond int64 ns.
bool to_record(const HilStateQuaternion& message, TrajectoryRecord& record, DatagramDecodeError& error);

// Which sender a live source takes (issue 26 N4): one vehicle. Every
// (sysid, compid) on the port sends its own pose stream; merged, two
// vehicles 1 km apart became a 1-km jump every packet. The configured
// system and component ids (either may be left free), else the first intact
// HIL_STATE_QUATERNION's sender, is taken for the source's lifetime (a
// reload builds a new source); every other sender's packet is `other`.
class SenderFilter {
 public:
  SenderFilter(std::optional<std::uint8_t> system_id, std::optional<std::uint8_t> component_id);
  enum class Verdict {
    taken_now,  // the first packet of the sender taken from now on
    taken,      // the taken sender's
    other,      // another sender's (or, before one is taken, one the configuration does not match)
  };
  // For an intact packet (its checksum matched: a corrupted header must not choose).
  Verdict judge(const PacketInfo& info) noexcept;
  // The sender taken (sequence unused), if any yet.
  const std::optional<PacketInfo>& taken() const noexcept { return taken_; }
  bool configured() const noexcept { return system_id_ || component_id_; }

 private:
  std::optional<std::uint8_t> system_id_, component_id_;
  std::optional<PacketInfo> taken_;
};

// Widens MAVLink's 8-bit sequence to the 64-bit numbering the loss
// statistics use (io::SequenceTracker), one counter per (system, component):
// a step of k (mod 256) counts as k.
class SequenceWidener {
 public:
  std::uint64_t widen(const PacketInfo& info);

 private:
  struct State {
    std::uint8_t last = 0;
    std::uint64_t widened = 0;
  };
  std::map<std::uint16_t, State> senders_;
};

}  // namespace imuemu::io::mavlink
