// MAVLink 2 over a byte stream: HIL_SENSOR (#107), optionally HIGHRES_IMU
// (#105), and HEARTBEAT (#0) at 1 Hz. Written from the MAVLink developer guide
// ("Packet Serialization") and common.xml/minimal.xml; no generated headers.
#pragma once

#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <span>

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

// fields_updated bits (common.xml HIL_SENSOR_UPDATED_FLAGS and
// HIGHRES_IMU_UPDATED_FLAGS share the layout): xacc..zgyro = bits 0..5,
// temperature = bit 12.
inline constexpr std::uint32_t kUpdatedAccelGyro = 0x3F;
inline constexpr std::uint32_t kUpdatedTemperature = 1u << 12;

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

  StreamEncoderOptions options_;
  std::unique_ptr<Device> device_;
  std::uint8_t sequence_ = 0;  // one counter for every packet this component sends
  std::optional<TimeNs> next_heartbeat_ns_;
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
