// DroneCAN (UAVCAN v0) on classic CAN: uavcan.equipment.ahrs.RawIMU (data
// type id 1003) per sample, uavcan.protocol.NodeStatus (341) at 1 Hz.
//
// Sources (DroneCAN specification, dronecan.github.io/Specification):
//  - 4.1 "CAN bus transport layer": 29-bit id of a message frame =
//    priority(5) << 24 | message type id(16) << 8 | service_not_message(1)=0
//    << 7 | source node id(7); the last data byte is the tail byte
//    start(bit 7) | end(bit 6) | toggle(bit 5) | transfer id mod 32 (bits 4-0);
//    a transfer longer than 7 bytes is split over frames and prefixed by the
//    transfer CRC (CRC-16-CCITT-FALSE: poly 0x1021, init 0xFFFF, no reflection,
//    no final xor, check "123456789" = 0x29B1), seeded with the 64-bit data
//    type signature fed least significant byte first; the toggle bit is 0 in
//    the first frame (libcanard canard.c enqueueTxFrames/canardHandleRxFrame,
//    libuavcan uc_transfer_receiver.cpp "Toggle bit is not cleared").
//  - 3 "Data structure description language": little-endian bit-level
//    serialisation, tail array optimisation (the last dynamic array of the
//    top-level type has no length field).
//  - 5 "Application level conventions": body axes X forward, Y right, Z down,
//    i.e. exactly imuemu's body FRD: RawIMU axes need no conversion.
//  - Data type signatures: CRC-64-WE over the normalised DSDL definition,
//    extended with each nested compound type's signature (pydronecan
//    dsdl/parser.py CompoundType.get_data_type_signature); RawIMU's published
//    value 0x8280632C40E574B5 (DroneCAN dsdlc output, e.g. MissionPlanner
//    ExtLibs/DroneCAN uavcan.equipment.ahrs.RawIMU.cs) is recomputed from the
//    DSDL text in tests/engine/test_protocols_can.cpp.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "drivers/protocol.hpp"

namespace imuemu::drivers::dronecan {

inline constexpr std::uint16_t kRawImuDataTypeId = 1003;
inline constexpr std::uint64_t kRawImuSignature = 0x8280632C40E574B5ULL;
// timestamp(7) + integration_interval(4) + 3 float16 + 3 float32 + 3 float16 +
// 3 float32; the covariance float16[<=36] is sent empty (tail array
// optimisation: no length field, so zero bytes).
inline constexpr std::size_t kRawImuPayloadBytes = 47;
inline constexpr std::size_t kRawImuMaxCovariance = 36;

inline constexpr std::uint16_t kNodeStatusDataTypeId = 341;
// NodeStatus fits one frame, so its signature never enters a CRC; kept for the
// decoder's table (published value, libcanard/dronecan dsdlc headers).
inline constexpr std::uint64_t kNodeStatusSignature = 0x0F0868D0C1A7C6F1ULL;
inline constexpr std::size_t kNodeStatusPayloadBytes = 7;  // uint32 + 2+3+3 bits + uint16

// Services the node answers (DroneCAN DSDL, uavcan/protocol): data type id
// and signature (published values: libcanard / DroneCAN dsdlc headers, e.g.
// UAVCAN_PROTOCOL_GETNODEINFO_SIGNATURE). Request and response of a service
// share the signature; it seeds the CRC of their multi-frame transfers.
inline constexpr std::uint8_t kGetNodeInfoServiceId = 1;      // 1.GetNodeInfo.uavcan
inline constexpr std::uint64_t kGetNodeInfoSignature = 0xEE468A8121C46A9EULL;
inline constexpr std::uint8_t kRestartNodeServiceId = 5;      // 5.RestartNode.uavcan
inline constexpr std::uint64_t kRestartNodeSignature = 0x569E05394A3017F0ULL;
inline constexpr std::uint64_t kRestartNodeMagic = 0xACCE551B1EULL;  // uint40 MAGIC_NUMBER
inline constexpr std::uint8_t kParamGetSetServiceId = 11;     // param/11.GetSet.uavcan
inline constexpr std::uint64_t kParamGetSetSignature = 0xA7B622F939D1A4D5ULL;
inline constexpr std::size_t kNodeNameMaxBytes = 80;          // GetNodeInfo name uint8[<=80]

// uavcan.protocol.NodeStatus constants (DSDL 341.NodeStatus.uavcan).
enum class NodeHealth : std::uint8_t { kOk = 0, kWarning = 1, kError = 2, kCritical = 3 };
enum class NodeMode : std::uint8_t {
  kOperational = 0, kInitialization = 1, kMaintenance = 2, kSoftwareUpdate = 3, kOffline = 7
};

// ---- wire helpers (public for the tests' golden frames) ----

// CRC-16-CCITT-FALSE continued over `bytes` from `crc`.
std::uint16_t crc16_ccitt_false(std::uint16_t crc, std::span<const std::uint8_t> bytes);
// The transfer CRC of a multi-frame transfer: init 0xFFFF, the signature's 8
// bytes LSB first, then the payload.
std::uint16_t transfer_crc(std::uint64_t data_type_signature, std::span<const std::uint8_t> payload);
// 29-bit identifier of a (non-anonymous) message broadcast frame.
std::uint32_t message_can_id(std::uint8_t priority, std::uint16_t data_type_id, std::uint8_t source_node_id);

// float -> IEEE half exactly as libuavcan's IEEE754Converter::nativeNonIeeeToHalf
// (uc_float_spec.cpp, the algorithm of half.sourceforge.net) rounds: the
// magnitude is rounded to nearest with ties AWAY from zero (not to even);
// |v| >= 65520 (after rounding) gives infinity, NaN gives 0x7FFF | sign.
std::uint16_t float16_bits_libuavcan(float value);
// half -> double (exact). Infinity / NaN come back as such.
double float16_to_double(std::uint16_t bits);

enum class WireClip : std::uint8_t { kExact = 0, kSaturated, kNotFinite };
struct Float16Value {
  std::uint16_t bits = 0;
  WireClip clip = WireClip::kExact;
};
// A DSDL "saturated float16" field: libuavcan's FloatSpec<16, Saturate> first
// rounds the double to the float field type, clamps finite values to
// +-65504 (IEEE754Limits<16>::max), then converts. Never infinity or NaN on
// the wire: a non-finite input is sent as 0 and reported kNotFinite.
Float16Value float16_saturated(double value);

// ---- options ----

struct DroneCanOptions {
  std::uint8_t node_id = 42;              // 1..127 (0 = anonymous: cannot send multi-frame transfers)
  std::uint8_t raw_imu_priority = 8;      // 0..31, lower is more urgent; libcanard's PRIORITY_HIGH
  std::uint8_t node_status_priority = 24; // libcanard's PRIORITY_LOW, what nodes use for NodeStatus
  TimeNs node_status_period_ns = kNsPerSecond;  // NodeStatus MAX_BROADCASTING_PERIOD_MS = 1000
  // RawIMU timestamp.usec = (t_ns + timestamp_offset_ns) / 1000, truncated to
  // 56 bits; never 0, which the Timestamp DSDL defines as UNKNOWN: a sum
  // below 1 us (including negative) is sent as 1 us (raw_imu_timestamp_usec).
  TimeNs timestamp_offset_ns = 0;
  // Send delta_theta / delta_velocity as rate_gyro_integral (rad) and
  // accelerometer_integral (m/s) with integration_interval = period (s);
  // otherwise integration_interval = -1 ("non-positive: integrals not
  // available", RawIMU DSDL) and the integrals are 0.
  bool send_integrals = true;
  // Spec NodeStatus at power-up: mode INITIALIZATION for the first second
  // ("entered immediately after startup", NodeStatus DSDL), then
  // OPERATIONAL. Off by default: the first NodeStatus of existing scenes
  // stays OPERATIONAL (their frames are compared byte for byte).
  bool initialization_at_power_up = false;
  // Identity (GetNodeInfo): name "reverse internet domain", software and
  // hardware version, the 128-bit unique id.
  std::string name = "com.imuemu.imu";
  std::uint8_t software_major = 1;
  std::uint8_t software_minor = 0;
  std::uint32_t software_vcs_commit = 0;  // sent with optional_field_flags bit 0 when not 0
  std::uint8_t hardware_major = 1;
  std::uint8_t hardware_minor = 0;
  // Default: "imuemu" in ASCII, then zeros, the node id in the last byte.
  std::optional<std::array<std::uint8_t, 16>> unique_id;
};

// The unique id GetNodeInfo reports (options.unique_id or the default).
std::array<std::uint8_t, 16> unique_id_of(const DroneCanOptions& options);

// The emitted NodeStatus (7 payload bytes) and a restart request, shared by
// the encoder (emission thread) and its node (io thread) without a lock.
struct NodeShared {
  std::atomic<std::uint64_t> node_status_payload{0};  // LE bytes 0..6 of the last NodeStatus sent
  std::atomic<bool> restart_requested{false};
};

// The service side of the node (issue 27): receives the service requests
// addressed to node_id (the receive filters), reassembles single- and
// multi-frame request transfers (tail byte, toggle, transfer CRC), answers
//  - GetNodeInfo (1): status = the last NodeStatus sent, software_version,
//    hardware_version (unique_id, empty certificate), name;
//  - RestartNode (5): ok when magic_number = 0xACCE551B1E (then the encoder
//    restarts at its next sample: NodeStatus INITIALIZATION, uptime 0),
//    ok = false otherwise;
//  - param.GetSet (11): read-only; by name, or by index when the name is
//    empty; a set is refused by answering the current value; an unknown
//    parameter gets the empty answer (value empty, name empty).
// A response goes to the requester with the request's priority and transfer id.
class DroneCanNode final : public CanCommandResponder {
 public:
  DroneCanNode(const DroneCanOptions& options, NodeShared& shared);
  std::vector<CanReceiveFilter> receive_filters() const override;
  void on_frame(const CanFrame& frame, CanReplySink& replies) override;
  CommandCounters command_counters() const override;
  void set_log(std::function<void(std::string_view)> log) override;

 private:
  struct Rx {
    bool in_progress = false;
    std::uint8_t transfer_id = 0;
    bool next_toggle = false;
    std::uint16_t crc = 0;
    std::vector<std::uint8_t> payload;
  };
  void handle(std::uint8_t service, std::uint8_t priority, std::uint8_t source, std::uint8_t transfer_id,
              std::span<const std::uint8_t> payload, CanReplySink& replies);
  void respond(std::uint8_t service, std::uint64_t signature, std::uint8_t priority, std::uint8_t destination,
               std::uint8_t transfer_id, std::span<const std::uint8_t> payload, CanReplySink& replies);
  DroneCanOptions options_;
  NodeShared& shared_;
  std::map<std::uint16_t, Rx> rx_;  // key = service << 8 | source node
  std::atomic<std::uint64_t> received_{0}, answered_{0}, unsupported_{0}, bad_bytes_{0}, dropped_{0};
  std::mutex log_mutex_;
  std::function<void(std::string_view)> log_;
};

// Throws std::invalid_argument naming the option that is out of range.
void validate(const DroneCanOptions& options);

// ---- encoder ----

// The RawIMU payload of one sample (what the encoder splits into frames) and
// how many of its values had to be clipped on the way.
struct RawImuPayload {
  std::vector<std::uint8_t> bytes;
  unsigned saturated_values = 0;
  unsigned non_finite_values = 0;
};
RawImuPayload serialize_raw_imu(const ImuFrameInput& sample, const DroneCanOptions& options);

// The RawIMU timestamp.usec of a sample time: floor((t_ns + offset) / 1000),
// at least kRawImuEarliestKnownUsec, since 0 means UNKNOWN (uavcan.Timestamp
// DSDL) and the emulator always knows the sample time.
inline constexpr std::uint64_t kRawImuEarliestKnownUsec = 1;
std::uint64_t raw_imu_timestamp_usec(TimeNs t_ns, TimeNs timestamp_offset_ns);

// One RawIMU multi-frame transfer (7 frames of 8 bytes) per sample; a
// NodeStatus single-frame transfer from periodic() at start and every
// node_status_period_ns after.
//
// RawIMU has no status field, so the sample status surfaces in NodeStatus:
// health = ERROR if any sample since the previous NodeStatus had
// kStatusFault or a non-finite value, else WARNING if any was saturated
// (SampleStatus or a float16 clamped to +-65504: "a critical parameter went
// out of range", NodeStatus DSDL), else OK; vendor_specific_status_code = OR
// of those samples' SampleStatus bits.
class DroneCanEncoder final : public CanEncoder {
 public:
  explicit DroneCanEncoder(const DroneCanOptions& options = {});
  std::string name() const override { return "dronecan"; }
  CanCommandResponder* command_responder() override { return node_.get(); }
  void encode(const ImuFrameInput& sample, std::vector<CanFrame>& out) override;
  void periodic(TimeNs now_ns, std::vector<CanFrame>& out) override;

  std::uint64_t saturated_values() const { return saturated_values_; }
  std::uint64_t non_finite_values() const { return non_finite_values_; }

  // Link faults (docs/faults.md). The sequence is RawIMU's 5-bit transfer
  // id (spec 4.1). restart(): both transfer ids start again at 0, uptime
  // restarts at 0, and a NodeStatus with mode INITIALIZATION ("node is
  // initializing; this mode is entered immediately after startup",
  // NodeStatus DSDL) goes out at once; the next one, a period later, is
  // OPERATIONAL again.
  bool has_sequence_counter() const override { return true; }
  void sequence_step(std::int64_t step) override {
    raw_imu_transfer_id_ = static_cast<std::uint8_t>((raw_imu_transfer_id_ + static_cast<std::uint8_t>(step)) & 0x1F);
  }
  void sequence_reset() override { raw_imu_transfer_id_ = 0; }
  void restart(TimeNs now_ns, std::vector<CanFrame>& out) override;
  bool frames_have_tail_byte() const override { return true; }

 private:
  void note_time(TimeNs t_ns);
  void append_node_status(TimeNs now_ns, NodeMode mode, std::vector<CanFrame>& out);
  DroneCanOptions options_;
  std::uint8_t raw_imu_transfer_id_ = 0;
  std::uint8_t node_status_transfer_id_ = 0;
  bool started_ = false;
  TimeNs start_ns_ = 0;
  TimeNs next_node_status_ns_ = 0;
  std::uint32_t status_since_node_status_ = 0;
  bool saturated_since_node_status_ = false;
  bool fault_since_node_status_ = false;
  std::uint64_t saturated_values_ = 0;
  std::uint64_t non_finite_values_ = 0;
  std::unique_ptr<NodeShared> shared_ = std::make_unique<NodeShared>();
  std::unique_ptr<DroneCanNode> node_;
};

// ---- decoder ----

struct NodeStatusInfo {
  std::uint32_t uptime_sec = 0;
  NodeHealth health = NodeHealth::kOk;
  std::uint8_t mode = 0;
  std::uint8_t sub_mode = 0;
  std::uint16_t vendor_specific_status_code = 0;
};

// Where other_errors came from (their sum is counters().other_errors).
struct DroneCanErrorDetail {
  std::uint64_t not_dronecan_frame = 0;      // standard id, CAN FD, empty frame, service or anonymous frame
  std::uint64_t unknown_data_type = 0;       // a message type this decoder has no signature for
  std::uint64_t missed_start = 0;            // a continuation frame with no transfer in progress
  std::uint64_t bad_toggle = 0;              // toggle bit not the expected one (also: set in a first frame)
  std::uint64_t bad_transfer_id = 0;         // a continuation frame of another transfer id
  std::uint64_t interrupted_transfer = 0;    // a new start frame while a transfer was incomplete
  std::uint64_t bad_length = 0;              // short start frame, oversized transfer
  std::uint64_t bad_payload = 0;             // CRC fine but the payload does not parse (or Inf/NaN)
  std::uint64_t duplicate_transfer = 0;      // same transfer id as the last accepted one
  std::uint64_t stale_transfer = 0;          // transfer id behind the last accepted one (reordered)
};

// Reassembles transfers per (source node, data type), checks the tail byte,
// the transfer id sequence and the transfer CRC, and decodes RawIMU into a
// DecodedSample (gyro = rate_gyro_latest, accel = accelerometer_latest,
// delta_theta / delta_velocity = the integrals when integration_interval > 0,
// t_ns = timestamp.usec * 1000 - timestamp_offset_ns with has_time unless
// usec = 0 "UNKNOWN" (or the time does not fit int64 nanoseconds),
// sequence = the transfer id widened to 64 bits) and NodeStatus into
// last_node_status().
//
// Counting (counters()): frames = complete transfers accepted (messages, not
// CAN frames); checksum_errors = multi-frame transfers whose CRC failed;
// sequence_gaps = transfer ids skipped between accepted transfers of one
// (node, type) - only modulo 32, so whole multiples of 32 lost transfers are
// invisible; other_errors = one per rejected frame or broken transfer (the
// rest of a broken transfer's frames are then dropped silently), detailed in
// detail(). A transfer id 16..31 behind the last accepted one is stale
// (reordered) and dropped, unless two such transfers in a row are
// consecutive: then the sender has jumped (restart, or 16+ lost) and the
// decoder follows it without counting gaps.
class DroneCanDecoder final : public CanDecoder {
 public:
  explicit DroneCanDecoder(const DroneCanOptions& options = {});
  void feed(const CanFrame& frame, const SampleCallback& on_sample) override;
  const DecoderCounters& counters() const override { return counters_; }
  const DroneCanErrorDetail& detail() const { return detail_; }
  std::optional<NodeStatusInfo> last_node_status(std::uint8_t node_id) const;

 private:
  struct Reassembly {
    bool in_progress = false;
    bool discarding = false;        // dropping the rest of a broken transfer
    std::uint8_t transfer_id = 0;   // of the transfer in progress / being discarded
    bool next_toggle = false;
    std::uint16_t expected_crc = 0;
    std::uint16_t running_crc = 0;
    std::vector<std::uint8_t> payload;
    // transfer id sequence of accepted transfers
    bool have_last = false;
    std::uint8_t last_transfer_id = 0;
    std::uint64_t sequence = 0;
    bool have_stale = false;
    std::uint8_t stale_transfer_id = 0;
  };
  void reject(std::uint64_t DroneCanErrorDetail::*what);
  void break_transfer(Reassembly& state, std::uint64_t DroneCanErrorDetail::*what);
  void complete(Reassembly& state, std::uint8_t source, std::uint16_t data_type,
                std::uint8_t transfer_id, std::span<const std::uint8_t> payload,
                const SampleCallback& on_sample);

  DroneCanOptions options_;
  DecoderCounters counters_;
  DroneCanErrorDetail detail_;
  std::map<std::uint32_t, Reassembly> states_;  // key = data type << 8 | source node
  std::map<std::uint8_t, NodeStatusInfo> node_status_;
};

}  // namespace imuemu::drivers::dronecan
