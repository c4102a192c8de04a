// imuemu native v1: the emulator's own lossless byte-stream frame. The
// specification (byte table, worked example) is docs/native-protocol.md.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>

#include "drivers/protocol.hpp"

namespace imuemu::drivers::native {

inline constexpr std::uint8_t kSync0 = 0xA5;
inline constexpr std::uint8_t kSync1 = 0x5A;
inline constexpr std::uint8_t kVersion = 1;
inline constexpr std::uint8_t kFlagDeltas = 0x01;        // delta block present
inline constexpr std::size_t kHeaderBytes = 6;           // sync(2) version flags length(2)
inline constexpr std::size_t kPayloadBytesBase = 68;     // seq, t, status, gyro, accel
inline constexpr std::size_t kPayloadBytesDeltas = 116;  // + delta-theta, delta-v
inline constexpr std::size_t kCrcBytes = 4;
inline constexpr std::size_t kFrameBytesBase = kHeaderBytes + kPayloadBytesBase + kCrcBytes;       // 78
inline constexpr std::size_t kFrameBytesDeltas = kHeaderBytes + kPayloadBytesDeltas + kCrcBytes;   // 126
// SampleStatus bits v1 defines; the rest are sent 0 and ignored on receipt.
inline constexpr std::uint32_t kStatusBitsV1 = kStatusExtrapolated | kStatusSaturated | kStatusFault;

// CRC-32C (Castagnoli; poly 0x1EDC6F41 reflected, init/xorout 0xFFFFFFFF),
// via Boost.CRC. Check value of "123456789" is 0xE3069283.
std::uint32_t crc32c(std::span<const std::uint8_t> bytes);

class Encoder final : public StreamEncoder {
 public:
  explicit Encoder(bool include_deltas) : include_deltas_(include_deltas) {}
  std::string name() const override { return "native"; }
  void encode(const ImuFrameInput& sample, std::vector<std::uint8_t>& out) override;
  std::size_t max_bytes_per_sample() const override {
    return include_deltas_ ? kFrameBytesDeltas : kFrameBytesBase;
  }

  // Link faults (docs/faults.md). The frame's sequence is the sample counter
  // plus an offset that sequence_step() moves and sequence_reset() / restart()
  // set so that the next frame carries 0 (section 6 item 5: a step backwards
  // is how a receiver sees a restart). Native v1 has no power-up frame.
  StreamFrameLayout frame_layout(std::span<const std::uint8_t> frame) const override;
  bool has_sequence_counter() const override { return true; }
  void sequence_step(std::int64_t step) override {
    (reset_pending_ ? step_after_reset_ : sequence_offset_) += static_cast<std::uint64_t>(step);
  }
  void sequence_reset() override {
    reset_pending_ = true;
    step_after_reset_ = 0;
  }
  void restart(TimeNs now_ns, std::vector<std::uint8_t>& out) override {
    (void)now_ns;
    (void)out;
    sequence_reset();
  }

 private:
  bool include_deltas_;
  std::uint64_t sequence_offset_ = 0;  // modulo 2^64, as the field wraps
  bool reset_pending_ = false;          // the next frame's sequence restarts at 0...
  std::uint64_t step_after_reset_ = 0;  // ...plus steps asked for after the reset
};

class Decoder final : public StreamDecoder {
 public:
  void feed(std::span<const std::uint8_t> bytes, const SampleCallback& on_sample) override;
  const DecoderCounters& counters() const override { return counters_; }

 private:
  std::vector<std::uint8_t> buffer_;
  DecoderCounters counters_;
  std::optional<std::uint64_t> last_sequence_;
};

}  // namespace imuemu::drivers::native
