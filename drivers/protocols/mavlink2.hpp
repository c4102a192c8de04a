// MAVLink 2 over a byte stream: HIL_SENSOR (#107), optionally HIGHRES_IMU
// (#105) and HIL_GPS (#113), and HEARTBEAT (#0) at 1 Hz. Written from the MAVLink developer guide
// ("Packet Serialization") and common.xml/minimal.xml; no generated headers.
#pragma once

#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <span>

#include "core/aiding/barometer.hpp"
#include "core/aiding/magnetometer.hpp"
#include "drivers/gnss_fix.hpp"
#include "drivers/protocol.hpp"
#include "drivers/protocols/stream_protocols.hpp"

namespace imuemu::drivers::mavlink2 {

inline constexpr std::uint8_t kMagic = 0xFD;          // MAVLink 2 STX
inline constexpr std::size_t kHeaderBytes = 10;       // magic..msgid
inline constexpr std::size_t kChecksumBytes = 2;
inline constexpr std::size_t kSignatureBytes = 13;
inline constexpr std::uint8_t kIncompatSigned = 0x01;  // MAVLINK_IFLAG_SIGNED

// Message id, CRC_EXTRA (guide "CRC_EXTRA Calculation", checked against an
// independent derivation in tests/support/protocol_reference.py) and full
// payload length including extension fields.
struct MessageSpec {
  std::uint32_t id;
  std::uint8_t crc_extra;
  std::uint8_t payload_bytes;
};
inline constexpr MessageSpec kHeartbeat{0, 50, 9};
inline constexpr MessageSpec kHighresImu{105, 93, 63};
inline constexpr MessageSpec kHilSensor{107, 108, 65};
inline constexpr MessageSpec kHilGps{113, 124, 39};

// fields_updated bits (common.xml HIL_SENSOR_UPDATED_FLAGS and
// HIGHRES_IMU_UPDATED_FLAGS share the layout): xacc..zgyro = bits 0..5,
// temperature = bit 12.
inline constexpr std::uint32_t kUpdatedAccelGyro = 0x3F;
inline constexpr std::uint32_t kUpdatedTemperature = 1u << 12;
// xmag, ymag, zmag = bits 6..8; abs_pressure 9, diff_pressure 10,
// pressure_alt 11. PX4 takes a group only with all its bits: mag 0x1C0,
// baro 0x1A00 (abs_pressure, pressure_alt, temperature); accel + gyro + mag
// + baro = 7167 (0x1BFF), diff_pressure (airspeed) not sent.
inline constexpr std::uint32_t kUpdatedMag = 0x1C0;
inline constexpr std::uint32_t kUpdatedAbsPressure = 1u << 9;
inline constexpr std::uint32_t kUpdatedPressureAlt = 1u << 11;

// CRC-16/MCRF4XX ("X.25"; poly 0x1021 reflected, init 0xFFFF, no xorout) via
// Boost.CRC. Check value of "123456789" is 0x6F91.
std::uint16_t crc16_mcrf4xx(std::span<const std::uint8_t> bytes);

class Device;   // drivers/protocols/mavlink_device.hpp
struct ReplyItem;

class Encoder final : public StreamEncoder {
 public:
  // With options.mavlink_answers_commands the encoder carries the
  // component's command side (mavlink_device.hpp, docs/mavlink-device.md):
  // its replies go out after a sample's messages, numbered by the one seq.
  explicit Encoder(const StreamEncoderOptions& options);
  // A copy keeps the stream state (seq, heartbeat schedule) and gets a
  // command side in its power-up state.
  Encoder(const Encoder& other);
  Encoder& operator=(const Encoder& other);
  ~Encoder() override;
  CommandResponder* command_responder() override;
  std::string name() const override { return "mavlink2"; }
  void encode(const ImuFrameInput& sample, std::vector<std::uint8_t>& out) override;
  void periodic(TimeNs now_ns, std::vector<std::uint8_t>& out) override;
  std::size_t max_bytes_per_sample() const override;

  // Link faults (docs/faults.md): seq is the one 8-bit counter of every
  // packet this component sends [G]; restart() sends a HEARTBEAT with
  // system_status MAV_STATE_BOOT at once (the next one, a period later, is
  // MAV_STATE_ACTIVE again) and seq restarts at 0.
  StreamFrameLayout frame_layout(std::span<const std::uint8_t> frame) const override;
  bool has_sequence_counter() const override { return true; }
  void sequence_step(std::int64_t step) override {
    sequence_ = static_cast<std::uint8_t>(sequence_ + static_cast<std::uint8_t>(step));
  }
  void sequence_reset() override { sequence_ = 0; }
  void restart(TimeNs now_ns, std::vector<std::uint8_t>& out) override;

 private:
  void append_heartbeat(std::uint8_t system_status, std::vector<std::uint8_t>& out);
  void append_packet(const MessageSpec& message, std::span<const std::uint8_t> payload,
                     std::vector<std::uint8_t>& out);
  void append_imu(const ImuFrameInput& sample, std::vector<std::uint8_t>& out);
  void append_reply(const ReplyItem& item, const ImuFrameInput& sample, std::vector<std::uint8_t>& out);
  void append_hil_gps(const ImuFrameInput& sample, std::vector<std::uint8_t>& out);

 public:
  // The barometer and magnetometer readings of one sample (measured once per
  // sample whichever messages carry them).
  struct AidingReading {
    bool has_pressure = false;
    double pressure_pa = 0.0;
    double temperature_k = 0.0;
    bool has_pressure_altitude = false;  // within the atmosphere's range
    double pressure_altitude_m = 0.0;
    bool has_field = false;
    Vec3 field_ut = Vec3::Zero();  // sensor axes
  };
  bool needs_navigation() const override {
    return options_.mavlink_baro || options_.mavlink_mag || options_.mavlink_hil_gps_rate_hz > 0;
  }
  // What encode() puts on the wire of one sample, before the wire's
  // rounding, for batch outputs (imuemu generate --baro-out / --gnss-out,
  // issue 28): call once per sample, in sample order, instead of encode()
  // (each steps the models exactly as encode() does, so the same samples
  // give the same readings and fixes as the stream).
  //  aiding_of: the barometer and magnetometer readings of the sample.
  //  hil_gps_fix: the HIL_GPS fix due at this sample (nullopt: none due, no
  //  HIL_GPS configured, no navigation fields or a non-finite fix).
  const AidingReading& aiding_of(const ImuFrameInput& sample) { return aiding_reading(sample); }
  std::optional<GnssFix> hil_gps_fix(const ImuFrameInput& sample);

 private:
  const AidingReading& aiding_reading(const ImuFrameInput& sample);

  StreamEncoderOptions options_;
  std::unique_ptr<Device> device_;
  std::uint8_t sequence_ = 0;  // one counter for every packet this component sends
  std::optional<TimeNs> next_heartbeat_ns_;
  std::optional<aiding::Barometer> barometer_;
  std::optional<aiding::Magnetometer> magnetometer_;
  std::optional<std::uint64_t> reading_counter_;  // the sample `reading_` is of
  AidingReading reading_;
  std::optional<TimeNs> next_gps_ns_;
  // HIL_GPS: the GNSS receivers' fix source at the HIL_GPS rate, and the
  // grid index of the stream's first fix (fix j = index - this).
  std::optional<GnssFixSource> gps_source_;
  std::int64_t gps_first_index_ = 0;
  // The ISA pressures at the top and the bottom of the model's range
  // (pressure_altitude_m's domain).
  double pressure_min_pa_ = 0.0, pressure_max_pa_ = 0.0;
};

class Decoder final : public StreamDecoder {
 public:
  // Samples come from HIL_SENSOR, or from HIGHRES_IMU when the options say
  // HIL_SENSOR is not sent (one sample per encoded sample either way).
  explicit Decoder(const StreamEncoderOptions& options)
      : sample_message_id_(options.mavlink_hil_sensor ? kHilSensor.id : kHighresImu.id) {}
  void feed(std::span<const std::uint8_t> bytes, const SampleCallback& on_sample) override;
  const DecoderCounters& counters() const override { return counters_; }

 private:
  struct SequenceState {
    std::uint8_t last = 0;
    std::uint64_t widened = 0;
  };
  std::uint32_t sample_message_id_;
  std::vector<std::uint8_t> buffer_;
  DecoderCounters counters_;
  std::map<std::uint16_t, SequenceState> sequences_;  // by sysid << 8 | compid
};

}  // namespace imuemu::drivers::mavlink2
