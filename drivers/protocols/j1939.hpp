// SAE J1939 inertial PGNs: Angular Rate Information (ARI, PGN 61482 =
// 0xF02A), Acceleration Sensor (ACCS, 61485 = 0xF02D), Slope Sensor
// Information 2 (SSI2, 61481 = 0xF029). Single 8-byte frames, PDU2 broadcast.
//
// Layouts and scalings (SAE J1939-71 / J1939DA; quoted from device manuals and
// firmware that reproduce them, since the SAE text is not public):
//  ARI  bytes 1-2 pitch rate, 3-4 roll rate, 5-6 yaw rate ("Extended Range"),
//       1/128 deg/s per bit, offset -250 deg/s; byte 7 bits 1-2 / 3-4 / 5-6
//       pitch / roll / yaw rate figure of merit (00 fully functional, 01
//       degraded, 10 error, 11 not available), bits 7-8 not defined (11);
//       byte 8 angular rate measurement latency, 0.5 ms/bit.
//       (FORKWORKS ARI_canmsg.h; tcan_can_j1939_devices AngularRateInformation;
//       Honeywell TARS user manual section 7.4, example 0x0CF02AE2
//       00 7D 00 7D 00 7D = 0 deg/s on all axes at priority 3, SA 0xE2.)
//  ACCS bytes 1-2 lateral, 3-4 longitudinal, 5-6 vertical acceleration
//       ("Extended Range"), 0.01 m/s^2 per bit, offset -320 m/s^2, range -320
//       to +322.55; byte 7 bits 1-2 / 3-4 / 5-6 their figures of merit, bits
//       7-8 "support variable transmission repetition rate" (sent 11, not
//       available); byte 8 not defined (0xFF).
//       (FORKWORKS ACCS_canmsg.h; LORD MV5-AR user manual 4.2.3; Honeywell
//       TARS 7.5, example 00 7D 00 7D D5 80 = 0, 0, +9.81 m/s^2.)
//  SSI2 bytes 1-3 pitch angle (SPN 4976), 4-6 roll angle (SPN 4977), 1/32768
//       deg per bit, offset -250 deg; byte 7 bits 1-2 pitch compensation (SPN
//       4978: 00 off, 01 on, 10 error, 11 n/a), 3-4 pitch figure of merit
//       (4979), 5-6 roll compensation (4980), 7-8 roll figure of merit (4981);
//       byte 8 measurement latency (4982), 0.5 ms/bit.
//       (Axiomatic UMAX0608xx Tri-Axial J1939 manual 2.5.1.2; ifm JD-series
//       manual 8.3, which lists the compensation codes the other way round,
//       00 on / 01 off: this encoder follows Axiomatic's 01 = on.) Default
//       priority 3 for all three.
//  Transmitted ranges (J1939-71 parameter ranges): a 1-byte value is valid in
//  0..0xFA, 2 bytes 0..0xFAFF, 3 bytes 0..0xFAFFFF; above that the most
//  significant byte 0xFB-0xFD is reserved, 0xFE "error indicator", 0xFF "not
//  available". So ARI spans -250..+251.9921875 deg/s and ACCS -320..+322.55
//  m/s^2 (the LORD and Honeywell figures), SSI2 -250..+251.99997 deg.
//  29-bit identifier: priority(3) << 26 | PGN(18: EDP, DP, PF, PS) << 8 |
//  source address; PF >= 240 (all three) means PDU2, PS is part of the PGN.
//
// Axes. These PGNs are in vehicle axes, not the sensor's: the encoder takes
// body FRD (x forward, y right, z down) and converts explicitly. Default
// kIso8855ZUp: x forward, y LEFT, z UP, right-handed (the ISO 8855 vehicle
// axes), as the LORD MV5-AR manual states for ACCS ("Right-handed axis
// system, Z axis points up", lateral = Y, longitudinal = X) and as the
// Honeywell TARS example sends +1 g vertical for a sensor at rest:
//   longitudinal =  f_x,  lateral = -f_y,  vertical = -f_z     (specific force)
//   roll rate    =  w_x,  pitch rate = -w_y, yaw rate = -w_z  (right-hand rule
//   about x fwd / y left / z up: yaw rate positive turning left)
//   roll angle   =  phi,  pitch angle = -theta  (so that d(pitch)/dt = pitch
//   rate for level flight; phi/theta are the aerospace Euler angles)
// kSaeJ670eZDown (SAE J670e: x forward, y right, z down) is the identity map,
// for receivers that follow the older SAE axes (the ifm JD manual offers
// "SAE J670" and "opposite" directions per angle). The J1939DA definitions
// of these SPNs' signs were not available to check this against; the choice
// is an option so a real receiver decides.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "drivers/protocol.hpp"

namespace imuemu::drivers::j1939 {

inline constexpr std::uint32_t kPgnSlopeSensorInformation2 = 61481;   // 0xF029 SSI2
inline constexpr std::uint32_t kPgnAngularRateInformation = 61482;    // 0xF02A ARI
inline constexpr std::uint32_t kPgnAccelerationSensor = 61485;        // 0xF02D ACCS
inline constexpr std::uint8_t kDefaultPriority = 3;

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

enum class VehicleAxes : std::uint8_t { kIso8855ZUp, kSaeJ670eZDown };

// Aerospace Euler angles of the body (FRD) relative to the local level
// frame (NED): pitch positive nose up, roll positive right side down.
struct PitchRoll {
  double pitch_rad = 0.0;
  double roll_rad = 0.0;
};
// Attitude at a sample time, or nothing when unknown.
using AttitudeSource = std::function<std::optional<PitchRoll>(TimeNs t_ns)>;

struct J1939Options {
  std::uint8_t source_address = 0x80;   // 0..253 (254 = null address, 255 = global)
  std::uint8_t priority = kDefaultPriority;  // 0..7
  bool send_angular_rate = true;        // ARI
  bool send_acceleration = true;        // ACCS
  // SSI2 needs pitch and roll, which ImuFrameInput does not carry: taken from
  // attitude_source when set and when it returns a value; otherwise SSI2 is
  // sent with both angles "not available" (0xFFFFFF, figures of merit 11).
  bool send_slope = false;
  AttitudeSource attitude_source;
  // ARI byte 8 and SSI2 byte 8 (0.5 ms/bit, 0..125 ms); not available when unset.
  std::optional<double> measurement_latency_ms;
  VehicleAxes axes = VehicleAxes::kIso8855ZUp;
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
  void encode(const ImuFrameInput& sample, std::vector<CanFrame>& out) override;
  std::uint64_t clamped_values() const { return clamped_values_; }

 private:
  J1939Options options_;
  std::uint64_t clamped_values_ = 0;
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
// to last_slope(). Not-available values decode as 0; error indicators and
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
};

}  // namespace imuemu::drivers::j1939
