// MicroStrain (HBK) MIP packets over a byte stream: the IMU data set 0x80
// with scaled accelerometer, scaled gyro, delta theta, delta velocity, GPS
// timestamp and overrange status fields. Written from the 3DM-GX5/3DM-CV7 DCP
// manuals; no MIP SDK code.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <vector>
#include <span>

#include "drivers/protocol.hpp"
#include "drivers/protocols/mip_device.hpp"
#include "drivers/protocols/stream_protocols.hpp"

namespace imuemu::drivers::mip {

inline constexpr std::uint8_t kSync1 = 0x75;  // 'u'
inline constexpr std::uint8_t kSync2 = 0x65;  // 'e'
inline constexpr std::size_t kHeaderBytes = 4;   // sync1 sync2 descriptor-set payload-length
inline constexpr std::size_t kChecksumBytes = 2;

inline constexpr std::uint8_t kSensorDataSet = 0x80;
inline constexpr std::uint8_t kScaledAccel = 0x04;    // float x3, g
inline constexpr std::uint8_t kScaledGyro = 0x05;     // float x3, rad/s
inline constexpr std::uint8_t kDeltaTheta = 0x07;     // float x3, rad
inline constexpr std::uint8_t kDeltaVelocity = 0x08;  // float x3, g*s
inline constexpr std::uint8_t kGpsTimestamp = 0x12;   // double tow s, u16 week, u16 flags
inline constexpr std::uint8_t kOverrangeStatus = 0x18;  // u16 per-axis bits

// GPS timestamp valid flags (0x80,0x12).
inline constexpr std::uint16_t kTimeInitialized = 0x0004;
inline constexpr std::uint16_t kTowValid = 0x0008;
inline constexpr std::uint16_t kWeekNumberValid = 0x0010;
// Overrange status bits (0x80,0x18).
inline constexpr std::uint16_t kOverrangeAccelX = 0x0001;  // Y 0x0002, Z 0x0004
inline constexpr std::uint16_t kOverrangeGyroX = 0x0010;   // Y 0x0020, Z 0x0040
inline constexpr std::uint16_t kOverrangeAccelGyroAll = 0x0077;

// 1 g as the MIP manuals define it (m/s^2).
inline constexpr double kStandardGravity_m_s2 = 9.80665;
inline constexpr std::int64_t kNsPerGpsWeek = 604'800LL * 1'000'000'000LL;
inline constexpr std::uint16_t kGpsTimeValid = kTimeInitialized | kTowValid | kWeekNumberValid;

// 16-bit Fletcher checksum of the MIP manuals (3DM-GX5 DCP manual 6.4): two
// running 8-bit sums over every byte from sync1 to the end of the payload,
// sum1 in the high byte (sent first).
std::uint16_t fletcher_checksum(std::span<const std::uint8_t> bytes);

class Device;
class NavEncoder;
struct FieldRate;

class Encoder final : public StreamEncoder {
 public:
  // With options.mip_device.answers_commands, the encoder carries the
  // device's command side (drivers/protocols/mip_device.hpp): what it streams
  // then follows the mode and message format its driver set.
  explicit Encoder(const StreamEncoderOptions& options);
  // A copy is the same device model powered up again: the options, and a
  // command side in its power-up state (not the original's settings).
  Encoder(const Encoder& other) : Encoder(other.options_) {}
  Encoder& operator=(const Encoder& other);
  ~Encoder() override;
  std::string name() const override { return "mip"; }
  CommandResponder* command_responder() override;
  // The 0x80 fields this encoder sends at power-up, in order.
  std::vector<std::uint8_t> sensor_fields() const;
  void encode(const ImuFrameInput& sample, std::vector<std::uint8_t>& out) override;
  std::size_t max_bytes_per_sample() const override;
  // Delta theta / delta velocity (0x80,0x07 / 0x80,0x08) as the device sends
  // them with its coning and sculling compensation (MIP 3DM command
  // 0x0C,0x51) on: an INS integrates them without corrections of its own.
  bool compensated_increments() const override { return true; }
  // The GNSS (0x81) and filter (0x82) sets take the trajectory's position,
  // velocity and attitude (issue 28, mip_nav.hpp).
  bool needs_navigation() const override { return options_.mip_nav.any(); }

  // Link faults (docs/faults.md): payload length byte and Fletcher
  // checksum [P 6.3, 6.4]. The IMU data set carries no packet counter and
  // the emulated device sends no power-up packet, so the sequence hooks keep
  // their defaults; a restart shows on the wire as the silence before it
  // and, for a device whose driver changed its settings, as the startup
  // settings (saved, power-up mode) after it (docs/mip-device.md).
  StreamFrameLayout frame_layout(std::span<const std::uint8_t> frame) const override;
  void restart(TimeNs now_ns, std::vector<std::uint8_t>& out) override;

 private:
  // A format the driver set: the fields due at this sample's counter (a
  // field with decimation d goes out on counters that are multiples of d).
  void encode_format(const ImuFrameInput& sample, std::span<const FieldRate> fields,
                     std::vector<std::uint8_t>& out);
  void encode_imu(const ImuFrameInput& sample, const StreamConfig* c, std::vector<std::uint8_t>& out);
  StreamEncoderOptions options_;
  std::unique_ptr<Device> device_;
  std::unique_ptr<NavEncoder> nav_;     // GNSS / filter sets (null when both are off)
  StreamConfig nav_power_up_;           // their power-up formats, for an encoder without command side
  std::uint64_t restarts_ = 0;  // restart faults seen (emission thread)
};

// The GPS timestamp field (0x80,0x12) of a sample at trajectory time t_ns,
// as the options' time base makes it (stream_protocols.hpp mip_time_base).
struct GpsTimestamp {
  double tow_s = 0.0;
  std::uint16_t week = 0;
  std::uint16_t valid_flags = 0;
};
GpsTimestamp gps_timestamp_of(TimeNs t_ns, const StreamEncoderOptions& options);
// Trajectory time from a received field, by the same options: valid GPS time
// (tow and week flagged valid) through the time base; an unflagged field is
// the device's internal clock, which is trajectory time when the base is
// unknown (and no time otherwise: the encoder clears the flags only when the
// time cannot be represented).
std::optional<TimeNs> trajectory_time_of(double tow_s, std::uint16_t week, std::uint16_t valid_flags,
                                         const StreamEncoderOptions& options);

class Decoder final : public StreamDecoder {
 public:
  explicit Decoder(const StreamEncoderOptions& options) : options_(options) {}
  void feed(std::span<const std::uint8_t> bytes, const SampleCallback& on_sample) override;
  const DecoderCounters& counters() const override { return counters_; }

 private:
  StreamEncoderOptions options_;
  std::vector<std::uint8_t> buffer_;
  DecoderCounters counters_;
};

}  // namespace imuemu::drivers::mip
