// SAE J1939 inertial PGNs: Angular Rate Information (ARI, PGN 61482 =
// 0xF02A), Acceleration Sensor (ACCS, 61485 = 0xF02D), Slope Sensor
// Information 2 (SSI2, 61481 = 0xF029). Single 8-byte frames, PDU2 broadcast.
//
// Layouts, scalings, signs and codes: SAE J1939 Digital Annex (J1939DA,
// the SPN/PGN table, 2018 edition as published in the canscope repository's
// thirdparty/j1939da_2018.xlsx; read, nothing copied), cross-checked against
// device manuals that reproduce it:
//  ARI  (PGN 61482, "Z-Down axis system as referenced in SAE J670", default
//       priority 3) bytes 1-2 Pitch Rate (Extended Range) SPN 4983, 3-4 Roll
//       Rate 4984, 5-6 Yaw Rate 4985: 1/128 deg/s per bit, offset -250 deg/s;
//       byte 7 bits 1-2 / 3-4 / 5-6 figures of merit SPN 4986 / 4987 / 4988
//       (00 fully functional, 01 degraded, 10 error, 11 not available), bits
//       7-8 not defined (sent 11); byte 8 Angular Rate Measurement Latency SPN
//       4989, 0.5 ms/bit, 0..125 ms.
//       (Honeywell TARS user manual 7.4 example 0x0CF02AE2 00 7D 00 7D 00 7D =
//       0 deg/s on all axes at priority 3, SA 0xE2.)
//  ACCS (PGN 61485, "Z-Up axis system as referenced in SAE J670", default
//       priority 2) bytes 1-2 Lateral Acceleration (Extended Range) SPN 5347,
//       3-4 Longitudinal 5348, 5-6 Vertical 5349: 0.01 m/s^2 per bit, offset
//       -320 m/s^2; byte 7 bits 1-2 / 3-4 / 5-6 figures of merit SPN 5350 /
//       5351 / 5352, bits 7-8 SPN 5353 "Support Variable Transmission
//       Repetition Rate" (sent 11: only the standard 10 ms); byte 8 not
//       defined (0xFF). (Honeywell TARS 7.5 example 00 7D 00 7D D5 80 = 0, 0,
//       +9.81 m/s^2.)
//  SSI2 (PGN 61481, Z-Down as ARI, default priority 3) bytes 1-3 Pitch Angle
//       (Extended Range) SPN 4976, 4-6 Roll Angle 4977: 1/32768 deg per bit,
//       offset -250 deg; byte 7 bits 1-2 Pitch Angle Compensation SPN 4978,
//       3-4 Pitch Angle Figure of Merit 4979, 5-6 Roll Angle Compensation
//       4980, 7-8 Roll Angle Figure of Merit 4981; compensation codes "00b =
//       On, 01b = Off, 10b = Error, 11b = Not Available" (J1939DA; the ifm JD
//       manual 8.3 agrees). The older SSI (61459) SPN 3326 "Pitch and Roll
//       Compensated" codes them the other way round (00 off, 01 on), which
//       is what the Axiomatic UMAX0608xx manual prints; byte 8 Roll and Pitch
//       Measurement Latency SPN 4982, 0.5 ms/bit.
//  Transmitted ranges (J1939-71 parameter ranges): a 1-byte value is valid in
//  0..0xFA, 2 bytes 0..0xFAFF, 3 bytes 0..0xFAFFFF; above that the most
//  significant byte 0xFB-0xFD is reserved, 0xFE "error indicator", 0xFF "not
//  available". So ARI spans -250..+251.9921875 deg/s and ACCS -320..+322.55
//  m/s^2 (the LORD and Honeywell figures), SSI2 -250..+251.99997 deg.
//  29-bit identifier: priority(3) << 26 | PGN(18: EDP, DP, PF, PS) << 8 |
//  source address; PF >= 240 (all three) means PDU2, PS is part of the PGN.
//  One `priority` option serves the three PGNs (default 3; J1939DA gives
//  ACCS priority 2 by default, receivers filter on the PGN, not on it).
//
// Axes and signs (default VehicleAxes::kJ1939da, the SPN definitions):
//  ARI, SSI2 in SAE J670 Z-Down axes (x forward, y right, z down = body FRD),
//  signs by the right-hand rule: SPN 4983 pitch rate positive for
//  "increasing ascent" (nose rising: +w_y), SPN 4984 roll rate positive for
//  "increasing roll to the right" (+w_x), SPN 4985 yaw rate positive "when
//  the object turns clockwise" seen from above (+w_z); SPN 4976 pitch angle
//  positive for ascent (the aerospace pitch theta), SPN 4977 roll angle
//  positive rolled right (the aerospace roll phi):
//    pitch rate = w_y, roll rate = w_x, yaw rate = w_z; pitch = theta, roll = phi
//  ACCS in SAE J670 Z-Up axes (x forward, y LEFT, z UP): SPN 5347 lateral
//  positive "accelerated to the left", SPN 5348 longitudinal positive
//  speeding up forward, SPN 5349 vertical "+1 gravity when stationary on a
//  horizontal surface" (specific force):
//    lateral = -f_y, longitudinal = f_x, vertical = -f_z
//  Two alternatives for receivers that deviate from the DA: kIso8855ZUp puts
//  all three PGNs in Z-Up axes (pitch rate = -w_y, yaw rate = -w_z, pitch =
//  -theta: imuemu's choice before it followed the DA), kSaeJ670eZDown all in
//  Z-Down (lateral = f_y, vertical = f_z).
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "drivers/protocol.hpp"

namespace imuemu::drivers::j1939 {

inline constexpr std::uint32_t kPgnSlopeSensorInformation2 = 61481;   // 0xF029 SSI2
inline constexpr std::uint32_t kPgnAngularRateInformation = 61482;    // 0xF02A ARI
inline constexpr std::uint32_t kPgnAccelerationSensor = 61485;        // 0xF02D ACCS
inline constexpr std::uint8_t kDefaultPriority = 3;
// Address Claimed (J1939-81; linux/can/j1939.h J1939_PGN_ADDRESS_CLAIMED):
// PDU1 PGN 0xEE00 sent to the global address 0xFF, data = the 64-bit NAME
// little-endian (bits 0-20 identity number, 21-31 manufacturer code, 32-34
// ECU instance, 35-39 function instance, 40-47 function, 48 reserved,
// 49-55 vehicle system, 56-59 its instance, 60-62 industry group, 63
// arbitrary address capable: linux/can/j1939.h "J1939 NAME"). A node
// claims its address at power-up before it sends anything else.
inline constexpr std::uint32_t kPgnAddressClaimed = 0xEE00;
inline constexpr std::uint8_t kGlobalAddress = 0xFF;
inline constexpr std::uint8_t kAddressClaimedPriority = 6;
inline constexpr std::uint8_t kNullAddress = 0xFE;  // source of Cannot Claim (J1939-81)
// J1939-21: Request (PDU1 0xEA00, data = the requested PGN, 3 bytes LE),
// Acknowledgement (0xE800), transport protocol connection management
// (TP.CM 0xEC00; BAM control byte 32) and data transfer (TP.DT 0xEB00).
inline constexpr std::uint32_t kPgnRequest = 0xEA00;              // 59904
inline constexpr std::uint32_t kPgnAcknowledgement = 0xE800;      // 59392
inline constexpr std::uint32_t kPgnTpCm = 0xEC00;                 // 60416
inline constexpr std::uint32_t kPgnTpDt = 0xEB00;                 // 60160
inline constexpr std::uint8_t kTpCmBam = 32;
inline constexpr std::uint8_t kTpPriority = 7;
// J1939-71 identification PGNs (PDU2, default priority 6): fields of ASCII
// each ended by '*'.
inline constexpr std::uint32_t kPgnComponentIdentification = 0xFEEB;  // 65259: make*model*serial*unit*
inline constexpr std::uint32_t kPgnSoftwareIdentification = 0xFEDA;   // 65242: count, then id*...
inline constexpr std::uint8_t kIdentificationPriority = 6;

// One SPN's linear scaling: physical = raw * resolution + offset, raw valid in
// 0..max_valid_raw.
struct Scaling {
  double resolution;
  double offset;
  std::uint32_t max_valid_raw;
  unsigned bytes;
  double min_value() const { return offset; }
  double max_value() const { return static_cast<double>(max_valid_raw) * resolution + offset; }
};
inline constexpr Scaling kAngularRateScaling{1.0 / 128.0, -250.0, 0xFAFF, 2};      // deg/s
inline constexpr Scaling kAccelerationScaling{0.01, -320.0, 0xFAFF, 2};            // m/s^2
inline constexpr Scaling kSlopeAngleScaling{1.0 / 32768.0, -250.0, 0xFAFFFF, 3};   // deg
inline constexpr Scaling kLatencyScaling{0.5, 0.0, 0xFA, 1};                        // ms

// Figure of merit / 2-bit status states.
enum class FigureOfMerit : std::uint8_t { kFullyFunctional = 0, kDegraded = 1, kError = 2, kNotAvailable = 3 };

std::uint32_t can_id(std::uint8_t priority, std::uint32_t pgn, std::uint8_t source_address);
struct IdFields {
  std::uint8_t priority;
  std::uint32_t pgn;             // destination-specific PDU1 PGNs with PS cleared
  std::uint8_t source_address;
};
IdFields parse_can_id(std::uint32_t id);

// What became of one value: raw is always a valid (or, for non-finite input,
// the error-indicator) code, never a reserved one.
struct Encoded {
  std::uint32_t raw = 0;
  bool clamped = false;      // out of range: clamped to the nearest valid end
  bool error = false;        // non-finite input: error indicator sent
};
Encoded encode_value(double value, const Scaling& scaling);
// The not-available code (all 0xFF) for the width of `scaling`.
std::uint32_t not_available_raw(const Scaling& scaling);

enum class VehicleAxes : std::uint8_t { kJ1939da, kIso8855ZUp, kSaeJ670eZDown };

// Aerospace Euler angles of the sensor (FRD) relative to the local level
// frame (NED): pitch positive nose up, roll positive right side down.
struct PitchRoll {
  double pitch_rad = 0.0;
  double roll_rad = 0.0;
};

struct J1939Options {
  std::uint8_t source_address = 0x80;   // 0..253 (254 = null address, 255 = global)
  std::uint8_t priority = kDefaultPriority;  // 0..7
  bool send_angular_rate = true;        // ARI
  bool send_acceleration = true;        // ACCS
  // SSI2: pitch and roll from the sample's level attitude
  // (ImuFrameInput::has_level_attitude, which the emission engine fills
  // because needs_level_attitude() says so); a sample without one sends both
  // angles "not available" (0xFFFFFF, compensation and figures of merit 11).
  bool send_slope = false;
  // ARI byte 8 and SSI2 byte 8 (0.5 ms/bit, 0..125 ms); not available when unset.
  std::optional<double> measurement_latency_ms;
  VehicleAxes axes = VehicleAxes::kJ1939da;
  // The NAME the Address Claimed message of a restart (link fault) carries.
  // Default: identity number 1, every other field 0 (manufacturer codes and
  // functions are SAE-assigned; 0 is J1939_NO_NAME, so not that).
  std::uint64_t name = 1;
  // Component Identification (65259) fields: SPN 586 make (up to 5
  // characters), 587 model, 588 serial number, 233 unit number.
  std::string make = "IMUEM";
  std::string model = "imuemu-j1939";
  std::string serial_number = "00000001";
  std::string unit_number;
  // Software Identification (65242) fields (SPN 234), each '*'-terminated.
  std::vector<std::string> software_ids{"imuemu 1.0"};
};

// The address the node holds now, shared by the encoder (emission thread)
// and its node (io thread) without a lock; kNullAddress after it lost
// address-claim arbitration without an address to move to.
struct NodeShared {
  std::atomic<std::uint8_t> address{0x80};
};

// The request side of the node (issue 27):
//  - Request (59904) to its address or global for Address Claimed (60928):
//    its claim to global (Cannot Claim from 254 when it has no address);
//    for Component Identification (65259) / Software Identification (65242):
//    the data, one frame when it fits 8 bytes, else a BAM (TP.CM + TP.DT to
//    global, J1939-21); another PGN requested to its own address: NACK
//    (Acknowledgement 59392, control 1) to global; to global: nothing.
//  - Address Claimed (J1939-81) from another node for its address: a lower
//    (higher-priority) NAME wins: the node moves to a free address in
//    128..247 when its NAME is arbitrary-address capable (bit 63), else
//    sends Cannot Claim and falls silent; a higher NAME gets the node's
//    claim again.
class J1939Node final : public CanCommandResponder {
 public:
  J1939Node(const J1939Options& options, NodeShared& shared);
  std::vector<CanReceiveFilter> receive_filters() const override;
  void on_frame(const CanFrame& frame, CanReplySink& replies) override;
  CommandCounters command_counters() const override;
  void set_log(std::function<void(std::string_view)> log) override;
  // The payloads of the identification PGNs.
  static std::vector<std::uint8_t> component_identification(const J1939Options& options);
  static std::vector<std::uint8_t> software_identification(const J1939Options& options);

 private:
  bool send(const CanFrame& frame, CanReplySink& replies);
  bool send_claim(std::uint8_t source, CanReplySink& replies);
  bool send_pgn(std::uint32_t pgn, const std::vector<std::uint8_t>& data, CanReplySink& replies);
  void log(const std::string& line);
  J1939Options options_;
  NodeShared& shared_;
  std::map<std::uint8_t, std::uint64_t> others_;  // address -> NAME claimed by another node
  std::atomic<std::uint64_t> received_{0}, answered_{0}, nacked_{0}, bad_bytes_{0}, dropped_{0};
  std::mutex log_mutex_;
  std::function<void(std::string_view)> log_;
};

// Throws std::invalid_argument naming the option that is out of range.
void validate(const J1939Options& options);

// Per sample: ARI, then ACCS, then SSI2 (those enabled), one frame each.
// Figures of merit: error when the sample has kStatusFault or the value is
// not finite (the value then carries the error indicator); degraded when the
// value was clamped to the PGN's range, or the sample is extrapolated or
// flagged saturated by the sensor model; else fully functional.
class J1939Encoder final : public CanEncoder {
 public:
  explicit J1939Encoder(const J1939Options& options = {});
  std::string name() const override { return "j1939"; }
  CanCommandResponder* command_responder() override { return node_.get(); }
  void encode(const ImuFrameInput& sample, std::vector<CanFrame>& out) override;
  bool needs_level_attitude() const override { return options_.send_slope; }
  std::uint64_t clamped_values() const { return clamped_values_; }
  // Link faults (docs/faults.md): J1939 PGNs carry no counter (the default
  // sequence hooks do nothing); restart() sends Address Claimed.
  void restart(TimeNs now_ns, std::vector<CanFrame>& out) override;

 private:
  void encode_frames(const ImuFrameInput& sample, std::vector<CanFrame>& out);
  J1939Options options_;
  std::uint64_t clamped_values_ = 0;
  std::unique_ptr<NodeShared> shared_ = std::make_unique<NodeShared>();
  std::unique_ptr<J1939Node> node_;
};

struct J1939ErrorDetail {
  std::uint64_t not_j1939_frame = 0;   // standard id, CAN FD, not 8 bytes
  std::uint64_t unknown_pgn = 0;       // a PGN this decoder does not read
  std::uint64_t reserved_value = 0;    // a value in the reserved 0xFB..0xFD range
};

// Reassembles one DecodedSample per ARI + ACCS pair from a source address
// (the encoder sends ARI then ACCS): an ACCS completes the pending ARI; an
// ARI that finds another ARI still pending emits that one alone (gyro only);
// an ACCS with no ARI pending is emitted alone (accel only). SSI2 angles go
// to last_slope(), Address Claimed NAMEs to claimed_name(). Not-available values decode as 0; error indicators and
// figure of merit "error" set kStatusFault; "degraded" sets kStatusSaturated
// when the value sits at its range limit, else kStatusExtrapolated. J1939
// has no sequence counter or time field: has_sequence / has_time are false
// and sequence_gaps stays 0. frames counts accepted PGN frames.
class J1939Decoder final : public CanDecoder {
 public:
  explicit J1939Decoder(const J1939Options& options = {});
  void feed(const CanFrame& frame, const SampleCallback& on_sample) override;
  const DecoderCounters& counters() const override { return counters_; }
  const J1939ErrorDetail& detail() const { return detail_; }

  struct Slope {
    std::optional<PitchRoll> angles;   // nothing when not available
    bool fault = false;
  };
  std::optional<Slope> last_slope(std::uint8_t source_address) const;
  // The NAME of the last Address Claimed from a source address.
  std::optional<std::uint64_t> claimed_name(std::uint8_t source_address) const;

 private:
  struct Pending {
    bool has_rates = false;
    DecodedSample sample;
  };
  void emit(DecodedSample& sample, const SampleCallback& on_sample);
  J1939Options options_;
  DecoderCounters counters_;
  J1939ErrorDetail detail_;
  std::map<std::uint8_t, Pending> pending_;
  std::map<std::uint8_t, Slope> slope_;
  std::map<std::uint8_t, std::uint64_t> claimed_names_;
};

}  // namespace imuemu::drivers::j1939
