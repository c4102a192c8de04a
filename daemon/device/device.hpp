// The emulated device: what a navigation computer sees on one port. The
// emission engine (daemon/engine/) computes each sample on its grid and
// decides its link faults; everything from there to the wire is the device's:
// the protocol encoder with its link-fault hooks (drivers/link_fault.hpp), the
// output (a byte-stream transport or a CAN interface) and the optional GPIO
// sync pulse. The engine talks to a device through this one interface only:
// at construction it asks what the producer must compute for it
// (SampleNeeds) and which faults it can show (check_supports); on each tick
// the emission thread makes one call, emit(); the controlling thread starts
// and stops it and reads its counters.
//
// Why a seam here: the devices to come answer their driver's commands (ping,
// idle, message format, baud rate: a reader on the same port, replies queued
// between frames) and send more than IMU samples (GNSS, baro, magnetometer,
// a navigation solution, each at its own decimation). Those live behind this
// interface: the device keeps its own mode and per-message schedule inside
// emit(), owns its reader thread between start() and stop(), and says in
// SampleNeeds what more the producer must compute; the engine's tick loop
// stays as it is. Today's two devices: a byte-stream device (native,
// mavlink2, mip: drivers::StreamEncoder + drivers::Transport) and a CAN
// device (dronecan, j1939: drivers::CanEncoder + CanOutput), each with an
// optional drivers::GpioSyncOutput.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "core/fault/fault.hpp"
#include "core/signal_chain/increments.hpp"
#include "core/types.hpp"
#include "drivers/gpio_sync.hpp"
#include "drivers/link_fault.hpp"
#include "drivers/protocol.hpp"
#include "drivers/transport.hpp"

namespace imuemu::drivers {
class CanTransport;
}

namespace imuemu::device {

// What the producer must compute for each of the device's samples, beyond
// the IMU sample itself (fixed for the device's life; asked once).
struct SampleNeeds {
  // The increments' convention (core/signal_chain/increments.hpp): raw
  // integrals, or coning/sculling-compensated (the encoder's
  // compensated_increments()).
  signal_chain::IncrementConvention increments = signal_chain::IncrementConvention::raw;
  // Pitch and roll of the sensor axes relative to local level (Eq. 1.2) in
  // ImuFrameInput's level-attitude fields (J1939 SSI2).
  bool level_attitude = false;
  // The sensor's geodetic position and NED velocity in ImuFrameInput's
  // navigation fields (a GNSS receiver, issue 28).
  bool navigation = false;
};

// What one emit() did on the wire.
struct EmitOutcome {
  // Frames the output refused while its link was up (queue full, bad frame,
  // the kernel), plus one when the encoder refused the sample.
  std::uint64_t refused = 0;
  // Frames the output refused because its link was down (no process reading
  // the pty, the device gone): not write errors (issue 26).
  std::uint64_t refused_link_down = 0;
  // CLOCK_MONOTONIC when the output accepted the sample's frames (for the
  // live pose latency: arrival -> handed to the output); 0: nothing accepted.
  TimeNs accepted_ns = 0;
};

// What a device that answers its driver counted, and its current settings
// (status JSON "commands", `imuemu status --summary`).
struct CommandStatus {
  std::uint64_t received = 0;        // whole commands taken (valid framing and checksum)
  std::uint64_t answered = 0;        // acknowledged / replied to with data
  std::uint64_t nacked = 0;          // refused with the protocol's own error code
  std::uint64_t not_command_bytes = 0;  // input bytes that were not part of a valid command
  std::uint64_t replies_dropped = 0; // replies the output could not take
  std::string mode;                  // e.g. "streaming", "idle"
  std::string format;                // what it streams: messages, fields, decimation
  std::uint32_t baud = 0;            // the serial rate it was told to use (0: not a UART setting)
};

// The status of a device whose responder counted `c`, its output having
// dropped `output_replies_dropped` queued replies (queue full, link lost
// before they left): one mapping for the byte-stream and the CAN devices.
inline CommandStatus command_status_of(const drivers::CommandCounters& c, std::uint64_t output_replies_dropped) {
  CommandStatus s;
  s.received = c.received;
  s.answered = c.answered;
  s.nacked = c.nacked;
  s.not_command_bytes = c.not_command_bytes;
  s.replies_dropped = c.replies_dropped + output_replies_dropped;
  s.mode = c.mode;
  s.format = c.format;
  s.baud = c.baud;
  return s;
}

class Device {
 public:
  virtual ~Device() = default;

  // --- Construction time (any thread, before start) ---
  virtual SampleNeeds needs() const = 0;
  // The largest frame a byte-stream device writes for one sample (bit-error
  // faults draw their flips over this many bytes); 0 for a CAN device (bit
  // errors never reach a CAN receiver: the controller's CRC and retransmission).
  virtual std::size_t max_bytes_per_sample() const = 0;
  // A link fault the device's protocol has no field for would do nothing on
  // the wire while the fault log claims it acted: throws
  // std::invalid_argument naming the imu and the protocol.
  virtual void check_supports(const std::string& imu, fault::Kind kind) const = 0;

  // --- Control side (the engine's controlling thread) ---
  // Before the first emit(): a device that reads its port starts its reader here.
  virtual void start() {}
  // After the last emit(). The output drained for up to drain_timeout, then
  // stopped (what is left counted dropped_at_stop); keep_transport: a
  // byte-stream transport only flushed (bounded the same way) and left open
  // for take_transport(). The GPIO lines are released (inactive) either way;
  // describe() and the counters keep reporting.
  virtual void stop(std::chrono::milliseconds drain_timeout, bool keep_transport) = 0;
  // After stop(..., true): the byte-stream transport, moved out for the next
  // engine (imuemud's reload keeps a pty's reader connected); nullptr for a
  // device without one (CAN). describe() and counters() keep reporting it
  // as it was when taken.
  virtual std::unique_ptr<drivers::Transport> take_transport() = 0;

  // --- Any thread but the emission thread ---
  // "protocol -> output", e.g. "native -> pty /tmp/imu0 (/dev/pts/3)".
  virtual std::string describe() const = 0;
  // The output's counters since this device got it (a transport reused
  // across a reload counts from its baseline).
  virtual drivers::TransportCounters counters() const = 0;
  // The sync pulses' counters; empty without GPIO sync.
  virtual std::optional<drivers::GpioSyncCounters> gpio_counters() const = 0;
  // A device that reads its port (its driver's commands): what it took and
  // answered, and the settings its driver left it in; empty for a device
  // that only sends. Never called on the emission thread.
  virtual std::optional<CommandStatus> command_status() const { return std::nullopt; }

  // --- The emission thread, once per tick with a sample to send ---
  // Encodes the sample with its link faults applied (encode() then
  // periodic(); no action: the encoder's own bytes, byte for byte), hands the
  // frames to the output, then raises the sync pulse for sample
  // frame.sample_counter at pulse_t_ns. Under link.silence the encoder still
  // runs (its counters move on) but nothing is written and no pulse raised.
  // Never allocates (buffers reserved at construction), locks or blocks.
  // An encoder's refusal is counted in the outcome; the only exception that
  // leaves is a GPIO line writer's own (a test's writer: libgpiod's do not
  // throw), which the engine records as its emission thread's fault.
  virtual EmitOutcome emit(const drivers::ImuFrameInput& frame, const drivers::LinkActions& link,
                           TimeNs pulse_t_ns) = 0;
};

// Where a CAN device's frames go: drivers::CanTransport (can_transport_output)
// or a test double. send() is called from the emission thread and must not block.
class CanOutput {
 public:
  virtual ~CanOutput() = default;
  virtual bool send(const drivers::CanFrame& frame) = 0;
  virtual std::string describe() const = 0;
  virtual drivers::TransportCounters counters() const = 0;
  virtual bool flush(std::chrono::milliseconds timeout) { (void)timeout; return true; }
  // Bounded drain, then discard counted (drivers::Transport::stop).
  virtual void stop(std::chrono::milliseconds drain_timeout) { flush(drain_timeout); }
  // Hands received requests to `responder` on the output's io thread
  // (drivers::CanTransport::set_command_responder); nullptr: stop. False:
  // this output receives nothing.
  virtual bool set_command_responder(drivers::CanCommandResponder* responder) {
    (void)responder;
    return false;
  }
};
std::unique_ptr<CanOutput> can_transport_output(std::unique_ptr<drivers::CanTransport> transport);

// A byte-stream device (daemon/device/stream_device.cpp). baseline: the
// transport's counters when this device got it (a transport reused from a
// previous engine); counters() count from there. Throws
// std::invalid_argument when the encoder or the transport is missing.
std::unique_ptr<Device> make_stream_device(std::unique_ptr<drivers::StreamEncoder> encoder,
                                           std::unique_ptr<drivers::Transport> transport,
                                           std::unique_ptr<drivers::GpioSyncOutput> gpio = nullptr,
                                           drivers::TransportCounters baseline = {});
// A CAN device (daemon/device/can_device.cpp). Throws std::invalid_argument
// when the encoder or the output is missing.
std::unique_ptr<Device> make_can_device(std::unique_ptr<drivers::CanEncoder> encoder, std::unique_ptr<CanOutput> output,
                                        std::unique_ptr<drivers::GpioSyncOutput> gpio = nullptr);

// The same check as Device::check_supports from the encoder alone, for
// `imuemu check-config` (daemon/scene/scene_check.cpp): what a start would
// refuse, without opening any port.
void check_supports(const std::string& imu, const drivers::StreamEncoder& encoder, fault::Kind kind);
void check_supports(const std::string& imu, const drivers::CanEncoder& encoder, fault::Kind kind);

}  // namespace imuemu::device
