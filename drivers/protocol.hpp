// What a wire protocol encoder sees and produces. One direction of data:
// source -> smoother -> physics -> sensor model -> ENCODER -> transport.
// An encoder turns one IMU sample (body FRD axes, SI units, as the sensor
// model emits it) into the bytes or CAN frames of a real device protocol, and
// converts units and axes explicitly; a decoder (for `imuemu listen` and the
// tests) does the reverse and counts what it could not accept.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <functional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "drivers/sync_pulse.hpp"
#include "core/types.hpp"
#include "drivers/transport.hpp"

namespace imuemu::drivers {

// Status bits every encoder maps onto its protocol's own fields where it has
// them (the native frame carries them all).
enum SampleStatus : std::uint32_t {
  kStatusExtrapolated = 1u << 0,  // not the smoother's own sample (underrun extrapolation or rejoin blend)
  kStatusSaturated = 1u << 1,     // a value was clipped to the sensor's range
  kStatusFault = 1u << 2,         // the emulated sensor reports a fault
};

// One emulated IMU sample, as the sensor model hands it to an encoder.
struct ImuFrameInput {
  std::uint64_t sample_counter = 0;      // 0, 1, 2, ... per device (sync pulses refer to it)
  TimeNs t_ns = 0;                       // sample instant, trajectory time
  Vec3 gyro_rad_s = Vec3::Zero();        // angular rate omega_ib^b, body FRD
  Vec3 accel_m_s2 = Vec3::Zero();        // specific force f^b, body FRD
  // Increments over the sample period ending at t_ns, exact for the
  // emulated motion (core/signal_chain/increments.hpp), in the convention
  // the encoder asks for (compensated_increments(); docs/emission.md): raw
  // integrals of rate and specific force, or coning/sculling-compensated
  // (rotation vector of the attitude change, velocity change in the body
  // frame at the period's start).
  Vec3 delta_theta_rad = Vec3::Zero();
  Vec3 delta_velocity_m_s = Vec3::Zero();
  TimeNs period_ns = 0;                  // the output period
  std::uint32_t status = 0;              // SampleStatus bits
  // The sensor model's temperature at t_ns (core/sensor: constant or warm-up
  // profile), for the protocols that carry one (MAVLink HIL_SENSOR /
  // HIGHRES_IMU `temperature`); false for the ideal sensor.
  bool has_temperature = false;
  double temperature_c = 0.0;
  // Inclination of the sensor axes at t_ns: aerospace pitch (nose up
  // positive) and roll (right side down positive) of the sensor FRD axes
  // relative to the local level frame (NED), Eq. 1.2. Filled only for an
  // encoder whose needs_level_attitude() is true (J1939 SSI2).
  bool has_level_attitude = false;
  double pitch_rad = 0.0;
  double roll_rad = 0.0;
  // The sensor's (a GNSS device: its antenna's) position and velocity at
  // t_ns from the smoothed trajectory: WGS84 latitude, longitude, height
  // above the ellipsoid and the velocity in local NED axes. Filled only for
  // an encoder whose needs_navigation() is true, in an ecef scene (a flat
  // scene has no geodetic position: left false).
  bool has_navigation = false;
  double latitude_rad = 0.0;
  double longitude_rad = 0.0;
  double height_m = 0.0;
  Vec3 velocity_ned_m_s = Vec3::Zero();
  // The sensor axes' attitude relative to local NED at t_ns, R_s^n (a
  // vector in sensor axes to NED), with the navigation fields: what a
  // magnetometer in those axes turns the Earth's field by (MAVLink
  // HIL_SENSOR x/y/zmag).
  Mat3 sensor_to_ned = Mat3::Identity();
};

// A classic CAN or CAN FD frame (SocketCAN's struct can_frame / canfd_frame
// without the kernel header, so encoders stay testable anywhere).
struct CanFrame {
  std::uint32_t id = 0;    // 11-bit or 29-bit identifier
  bool extended = false;   // 29-bit
  bool fd = false;         // CAN FD frame (len up to 64)
  std::uint8_t len = 0;    // data length in bytes
  std::array<std::uint8_t, 64> data{};
};

// Where the fields a link fault touches (drivers/link_fault.hpp) sit in one
// frame an encoder sent, offsets from the frame's first byte.
struct StreamFrameLayout {
  std::size_t frame_bytes = 0;        // the whole frame (0: not a frame of this protocol)
  std::size_t length_offset = 0;      // the length field...
  std::uint8_t length_bytes = 0;      // ...its width (0: the protocol has none)
  bool length_big_endian = false;
  std::size_t checksum_offset = 0;    // the checksum / CRC...
  std::uint8_t checksum_bytes = 0;    // ...its width (0: none)
};

// Byte-stream protocols (UART, pty): frames appended to `out`.
// What a device that answers its driver counted, and its settings now
// (daemon/device maps it to the status JSON's "commands").
struct CommandCounters {
  std::uint64_t received = 0;           // whole commands (valid framing and checksum)
  std::uint64_t answered = 0;           // acknowledged (ACK, with its reply data if any)
  std::uint64_t nacked = 0;             // refused with the protocol's error code
  std::uint64_t not_command_bytes = 0;  // input bytes that were not part of a valid command
  std::uint64_t replies_dropped = 0;    // replies the reply queue could not take
  std::string mode;                     // "streaming" / "idle"
  std::string format;                   // what it streams: messages, fields, decimation
  std::uint32_t baud = 0;               // the rate its driver last set (or the power-up one)
};

// The command side of a device (the bytes its driver writes), handed to the
// transport (Transport::set_input_handler): on_input runs on the transport's
// io thread. Whatever it changes reaches the encoder (the emission thread)
// without a lock or a wait.
class CommandResponder : public InputHandler {
 public:
  virtual CommandCounters command_counters() const = 0;
  // Log lines about changes the driver made (mode, format, baud); empty: none.
  virtual void set_log(std::function<void(std::string_view)> log) = 0;
};

class StreamEncoder {
 public:
  virtual ~StreamEncoder() = default;
  // A device that answers its driver's commands: its responder (owned by
  // the encoder, alive as long as it); nullptr for a device that only sends.
  virtual CommandResponder* command_responder() { return nullptr; }
  virtual std::string name() const = 0;
  // Appends the frame(s) of one sample.
  virtual void encode(const ImuFrameInput& sample, std::vector<std::uint8_t>& out) = 0;
  // Appends whatever the protocol sends on its own schedule (heartbeats,
  // status) due at or before now_ns; called once per sample.
  virtual void periodic(TimeNs now_ns, std::vector<std::uint8_t>& out) { (void)now_ns; (void)out; }
  // Largest number of bytes one sample (plus periodic traffic, averaged per
  // sample) puts on the wire, whatever the device is configured to send:
  // what sizes the emission buffers, and the link budget's worst case.
  virtual std::size_t max_bytes_per_sample() const = 0;
  // Bytes per second the device sends as it is configured now (its
  // power-up outputs, or what its driver has commanded since, periodic
  // traffic included) in a scene at sample_rate_hz: the link budget's
  // verdict. Default: the worst case, max_bytes_per_sample() per sample (a
  // protocol whose traffic no configuration changes). Call it where
  // encode() runs, or before emission starts (it reads the configuration
  // the emission thread reads).
  virtual double configured_bytes_per_second(double sample_rate_hz) const {
    return static_cast<double>(max_bytes_per_sample()) * sample_rate_hz;
  }
  // The frame's delta_theta / delta_velocity are coning/sculling-compensated
  // increments (true) or raw integrals (false, the default).
  virtual bool compensated_increments() const { return false; }
  // The encoder reports a navigation fix (a GNSS receiver, issue 28): the
  // producer fills ImuFrameInput's navigation fields only then.
  virtual bool needs_navigation() const { return false; }
  // The GPIO sync line as the device's own sync-out setting drives it for
  // the sample just encoded (drivers/sync_pulse.hpp); nothing when the
  // device has no such setting or it is off: the scene's [imu.sync] pulse
  // then applies. Called on the emission thread after encode(); never
  // allocates or blocks.
  virtual std::optional<DeviceSyncPulse> device_sync_pulse() const noexcept { return std::nullopt; }

  // ---- link-fault hooks (issue 18; applied by drivers/link_fault.cpp,
  // effects per protocol in docs/faults.md). Defaults: a protocol without
  // the field does nothing. None allocates, throws or blocks.
  //
  // The layout of the frame that starts at frame[0], which this encoder sent
  // (encode() or periodic() output). Default: the whole span is one frame
  // with no length or checksum field known.
  virtual StreamFrameLayout frame_layout(std::span<const std::uint8_t> frame) const {
    return StreamFrameLayout{frame.size()};
  }
  // The protocol has a packet / sample counter sequence_step() and
  // sequence_reset() move (false: they do nothing).
  virtual bool has_sequence_counter() const { return false; }
  // The counter the next frame carries moves by `step` (modulo its width;
  // negative steps back), once: later frames count on from there.
  virtual void sequence_step(std::int64_t step) { (void)step; }
  // The next frame carries counter 0, later ones 1, 2, ...
  virtual void sequence_reset() {}
  // The device powers up again at now_ns: counters and uptime restart, and
  // whatever the device sends at power-up is appended to `out` (before the
  // sample the caller encodes next).
  virtual void restart(TimeNs now_ns, std::vector<std::uint8_t>& out) { (void)now_ns; (void)out; }
};

// CAN protocols: frames appended to `out`.
// ---- the command side of a CAN device (issue 27) ----
//
// Where a CAN device's replies go: the transport queues each frame and
// writes it between the device's own frames, never blocking the emission
// thread. Called on the transport's io thread only (inside on_frame).
class CanReplySink {
 public:
  virtual ~CanReplySink() = default;
  // Queues one frame; false (counted) when the bounded reply queue is full.
  virtual bool reply(const CanFrame& frame) = 0;
};

// One kernel receive filter (SocketCAN struct can_filter): a frame matches
// when (frame id & mask) == (id & mask) and its id width is `extended`.
struct CanReceiveFilter {
  std::uint32_t id = 0;
  std::uint32_t mask = 0;
  bool extended = true;
};

// What a CAN device does with the frames addressed to it (requests). on_frame
// runs on the transport's io thread, never on the emission thread; it may
// allocate and lock. Whatever it changes reaches the encoder without a lock.
class CanCommandResponder {
 public:
  virtual ~CanCommandResponder() = default;
  // The requests the protocol defines for this node (the transport installs
  // exactly these filters; nothing else reaches on_frame).
  virtual std::vector<CanReceiveFilter> receive_filters() const = 0;
  virtual void on_frame(const CanFrame& frame, CanReplySink& replies) = 0;
  virtual CommandCounters command_counters() const = 0;
  virtual void set_log(std::function<void(std::string_view)> log) = 0;
};

class CanEncoder {
 public:
  virtual ~CanEncoder() = default;
  // A device that answers requests addressed to it: its responder (owned by
  // the encoder, alive as long as it); nullptr for a device that only sends.
  virtual CanCommandResponder* command_responder() { return nullptr; }
  virtual std::string name() const = 0;
  virtual void encode(const ImuFrameInput& sample, std::vector<CanFrame>& out) = 0;
  virtual void periodic(TimeNs now_ns, std::vector<CanFrame>& out) { (void)now_ns; (void)out; }
  // The encoder sends the attitude (ImuFrameInput::pitch_rad / roll_rad):
  // the producer computes it only then.
  virtual bool needs_level_attitude() const { return false; }
  // As StreamEncoder::compensated_increments.
  virtual bool compensated_increments() const { return false; }

  // ---- link-fault hooks, as StreamEncoder's.
  virtual bool has_sequence_counter() const { return false; }
  virtual void sequence_step(std::int64_t step) { (void)step; }
  virtual void sequence_reset() {}
  virtual void restart(TimeNs now_ns, std::vector<CanFrame>& out) { (void)now_ns; (void)out; }
  // The sample's frames form one transfer whose data carry a tail byte
  // (DroneCAN: start / end / toggle / transfer id in the last data byte);
  // false: each frame is a message of its own (J1939).
  virtual bool frames_have_tail_byte() const { return false; }
};

// What a decoder recovered from a frame: the fields the protocol carries
// (others left at zero), in the same SI units and body FRD axes.
struct DecodedSample {
  std::uint64_t sequence = 0;  // the protocol's own counter (widened), if it has one
  bool has_sequence = false;
  TimeNs t_ns = 0;             // the protocol's time field converted to ns, if it has one
  bool has_time = false;
  Vec3 gyro_rad_s = Vec3::Zero();
  Vec3 accel_m_s2 = Vec3::Zero();
  Vec3 delta_theta_rad = Vec3::Zero();
  Vec3 delta_velocity_m_s = Vec3::Zero();
  std::uint32_t status = 0;
};

struct DecoderCounters {
  std::uint64_t frames = 0;            // valid frames decoded (any message)
  std::uint64_t samples = 0;           // IMU samples among them
  std::uint64_t checksum_errors = 0;   // framed but the checksum/CRC failed
  std::uint64_t resync_bytes = 0;      // bytes skipped looking for the next frame start
  std::uint64_t sequence_gaps = 0;     // missing sequence numbers
  std::uint64_t other_errors = 0;      // malformed frames (bad length, unknown id, ...)
};

using SampleCallback = std::function<void(const DecodedSample&)>;

// Byte-stream decoder: feed any chunking of the stream; resynchronises on the
// next valid frame after corruption, counting what it skipped.
class StreamDecoder {
 public:
  virtual ~StreamDecoder() = default;
  virtual void feed(std::span<const std::uint8_t> bytes, const SampleCallback& on_sample) = 0;
  virtual const DecoderCounters& counters() const = 0;
};

class CanDecoder {
 public:
  virtual ~CanDecoder() = default;
  virtual void feed(const CanFrame& frame, const SampleCallback& on_sample) = 0;
  virtual const DecoderCounters& counters() const = 0;
};

}  // namespace imuemu::drivers
