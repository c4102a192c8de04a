// The MAVLink component's command side (issue 27): what a ground station or
// autopilot sends to a new component at connection - COMMAND_LONG /
// COMMAND_INT (REQUEST_MESSAGE, SET_MESSAGE_INTERVAL, anything else
// UNSUPPORTED) and the parameter protocol (PARAM_REQUEST_LIST / _READ /
// PARAM_SET on a small read-only set). docs/mavlink-device.md.
//
// Why replies do NOT go through ReplySink (as MIP's do): a MAVLink
// component has ONE 8-bit seq for every packet it sends [G], and receivers
// count lost packets from its steps. A reply numbered on the io thread and
// queued by the transport between frames could leave before a stream frame
// numbered earlier but still queued, and the receiver would count ~255 lost
// packets. So the io thread only parses and decides; it hands each reply
// (a small POD) to the emission thread through a wait-free SPSC ring, and
// the encoder serialises it after the sample's own messages with the next
// seq: replies are whole packets between frames, in seq order, at most one
// sample period late.
#pragma once

#include <array>
#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <mutex>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <boost/lockfree/spsc_queue.hpp>

#include "drivers/protocol.hpp"
#include "drivers/protocols/mavlink2.hpp"
#include "drivers/protocols/responder_status.hpp"

namespace imuemu::drivers::mavlink2 {

// Messages the device reads or answers with ([X] common.xml; CRC_EXTRA by
// the [G] algorithm; payload length with extensions).
inline constexpr MessageSpec kParamRequestRead{20, 214, 20};
inline constexpr MessageSpec kParamRequestList{21, 159, 2};
inline constexpr MessageSpec kParamValue{22, 220, 25};
inline constexpr MessageSpec kParamSet{23, 168, 23};
inline constexpr MessageSpec kCommandInt{75, 158, 35};
inline constexpr MessageSpec kCommandLong{76, 152, 33};
inline constexpr MessageSpec kCommandAck{77, 143, 10};

// The inbound messages whose CRC_EXTRA a device's parser knows: the ones it
// acts on, and HEARTBEAT (what every peer sends; read, not a command).
inline constexpr std::array<const MessageSpec*, 6> kDeviceInbound{&kHeartbeat,   &kParamRequestRead, &kParamRequestList,
                                                                  &kParamSet,    &kCommandInt,       &kCommandLong};

inline constexpr std::uint8_t kMagicV1 = 0xFE;  // MAVLink 1 STX
inline constexpr std::size_t kHeaderBytesV1 = 6;

// [X] MAV_CMD / MAV_RESULT / MAV_PARAM_TYPE values used.
inline constexpr std::uint16_t kCmdSetMessageInterval = 511;
inline constexpr std::uint16_t kCmdRequestMessage = 512;
inline constexpr std::uint8_t kResultAccepted = 0;
inline constexpr std::uint8_t kResultDenied = 2;
inline constexpr std::uint8_t kResultUnsupported = 3;
inline constexpr std::uint8_t kParamTypeReal32 = 9;

// One valid packet read from the driver (payload zero-extended to the
// message's full length, [G] truncation).
struct InboundPacket {
  std::uint8_t version = 2;  // 1: 0xFE frame, 2: 0xFD frame
  std::uint8_t seq = 0, system_id = 0, component_id = 0;
  std::uint32_t message_id = 0;
  std::span<const std::uint8_t> payload;
  std::size_t frame_bytes = 0;
};

// MAVLink 1 and 2 framing of the bytes a driver writes [G]: finds 0xFD /
// 0xFE, waits for the whole packet (split across reads), checks the CRC with
// the message's CRC_EXTRA. A packet whose id has no CRC_EXTRA here cannot be
// checked, so like a bad CRC or an unknown incompat flag it costs ONE byte
// and the scan goes on (a real packet that starts inside it is still found);
// those bytes count as not_command_bytes. A partial candidate older than
// kStaleAfter when more bytes arrive is given up the same way (a stray 0xFD
// with a large length byte would otherwise hold real requests behind it), as
// the MIP device's parser does.
class FrameParser {
 public:
  static constexpr std::chrono::milliseconds kStaleAfter{100};
  // The messages whose CRC_EXTRA the parser knows (the table must outlive
  // the parser): by default what a device reads from its driver; a ground
  // station's side (drivers/protocols/handshake.cpp) passes its own.
  explicit FrameParser(std::span<const MessageSpec* const> known = kDeviceInbound) : known_(known) {}
  void feed(std::span<const std::uint8_t> bytes, std::chrono::steady_clock::time_point now,
            const std::function<void(const InboundPacket&)>& on_packet);
  std::uint64_t skipped_bytes() const noexcept { return skipped_; }
  std::uint64_t packets() const noexcept { return packets_; }

 private:
  const MessageSpec* spec_of(std::uint32_t id) const;

  std::span<const MessageSpec* const> known_;
  std::vector<std::uint8_t> buffer_;
  std::chrono::steady_clock::time_point candidate_since_{};
  std::uint64_t skipped_ = 0, packets_ = 0;
};

// What the io thread asks the emission thread to send (one ring slot).
struct ReplyItem {
  enum class Kind : std::uint8_t { ack, heartbeat, imu_message, param_value };
  Kind kind = Kind::ack;
  std::uint8_t result = 0;           // ack
  std::uint16_t command = 0;         // ack
  std::uint8_t target_system = 0;    // ack: the requester
  std::uint8_t target_component = 0;
  std::uint16_t param_index = 0;     // param_value
};

// The device's read-only parameters (PARAM_VALUE, REAL32).
struct DeviceParam {
  char id[17];  // at most 16 characters, [X] param_id
  float value;
};

class Device final : public CommandResponder {
 public:
  static constexpr std::size_t kRingSlots = 64;
  // Replies serialised per sample at most (each at most one ACK + one IMU
  // message, ~100 bytes): inside StreamDevice's 4096-byte reserve.
  static constexpr int kMaxRepliesPerSample = 1;

  explicit Device(const StreamEncoderOptions& options);

  // --- io thread ---
  void on_input(std::span<const std::uint8_t> bytes, ReplySink& replies) override;
  // As on_input, at a given time (tests of the stale-candidate rule).
  void on_input_at(std::span<const std::uint8_t> bytes, std::chrono::steady_clock::time_point now);
  // --- any thread but the emission thread ---
  CommandCounters command_counters() const override;
  void set_log(std::function<void(std::string_view)> log) override;
  // --- emission thread ---
  bool next_reply(ReplyItem& item) noexcept { return ring_.pop(item); }
  // The streamed IMU message goes out on sample counters that are
  // multiples of this (0: off); 1 at power-up.
  std::uint32_t decimation() const noexcept { return decimation_.load(std::memory_order_acquire); }
  void note_period(TimeNs period_ns) noexcept { period_ns_.store(period_ns, std::memory_order_relaxed); }

  std::span<const DeviceParam> params() const noexcept { return params_; }
  std::uint32_t streamed_message_id() const noexcept { return imu_id_; }

 private:
  void handle(const InboundPacket& p);
  void command(std::uint16_t cmd, const float* param, std::uint8_t target_system, std::uint8_t target_component,
               const InboundPacket& p);
  bool addressed_to_us(std::uint8_t target_system, std::uint8_t target_component) const noexcept;
  bool queue(const ReplyItem& item);
  void ack(std::uint16_t cmd, std::uint8_t result, const InboundPacket& p);
  void log(const std::string& line) const { status_.log(line); }
  int param_by_id(std::span<const std::uint8_t> id16) const;

  StreamEncoderOptions options_;
  std::uint32_t imu_id_;
  std::vector<DeviceParam> params_;
  FrameParser parser_;
  boost::lockfree::spsc_queue<ReplyItem, boost::lockfree::capacity<kRingSlots>> ring_;
  std::atomic<std::uint32_t> decimation_{1};
  std::atomic<TimeNs> period_ns_{0};
  ResponderStatus status_{"mavlink device: "};
};

}  // namespace imuemu::drivers::mavlink2
