// Link and protocol faults (issue 18) at the encoder/transport edge. The
// producer thread decides, per sample, what the active link faults do to it
// (LinkActions, from core/fault's timeline and the fault's seeded random
// stream) and puts that in the sample's ring slot; the emission thread only
// applies it here: no allocation once the buffers have grown, no blocking,
// no randomness of its own (bit positions come from actions.bit_error_seed).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "drivers/protocol.hpp"

namespace imuemu::drivers {

struct LinkActions {
  bool silence = false;            // nothing on the wire for this tick (silence, restart's off time, dropped)
  bool drop = false;               // this sample's frames are not sent (periodic traffic still is)
  std::uint8_t copies = 1;         // 2: duplicated; N > 2: babbling (N frames in this tick)
  bool corrupt_checksum = false;   // the checksum / CRC of the sample's frame(s) is wrong
  std::uint32_t bit_flips = 0;     // bits flipped in the sample's frame(s)...
  std::uint64_t bit_error_seed = 0;  // ...at positions drawn from this seed
  std::uint32_t truncate_bytes = 0;  // the sample's frame cut short by this many bytes (never to nothing)
  bool bad_length = false;         // the length field disagrees with the payload
  std::int64_t sequence_step = 0;  // the protocol's counter jumps by this before this sample (once)
  bool sequence_reset = false;     // the protocol's counter restarts at 0 at this sample
  bool restart = false;            // the device restarts before this sample: start-up sequence, counters reset
  bool can_wrong_id = false;       // CAN: the sample's frames under can_id
  std::uint32_t can_id = 0;
  bool can_missing_frame = false;  // CAN: one frame (the second, or the only one) of the sample's transfer missing
  bool any() const {
    return silence || drop || copies != 1 || corrupt_checksum || bit_flips != 0 || truncate_bytes != 0 || bad_length ||
           sequence_step != 0 || sequence_reset || restart || can_wrong_id || can_missing_frame;
  }
};

// Encodes one sample (encode() then periodic()) with `actions` applied,
// appending to `out`; with no action it appends exactly what the encoder
// alone would. What each action does per protocol: docs/faults.md
// ("Link and protocol faults"). In order:
//   1. restart: encoder.restart(t_ns, out) (counters, uptime, power-up
//      traffic), then sequence_reset, then sequence_step;
//   2. the sample's frames: encode() once, or `copies` times when copies > 2
//      (babble: the same stale sample in N full frames, each with the
//      protocol's next packet counter where it has one); copies == 0 sends
//      none (as drop);
//   3. on those frames: corrupt_checksum (every checksum byte inverted),
//      bad_length (length field + 1 modulo its width), truncate_bytes (each
//      frame cut, never below 1 byte), then bit_flips distinct bit positions
//      over the bytes left (see link_fault_bit_position), can_wrong_id,
//      can_missing_frame;
//   4. copies == 2: the sample's frames (as corrupted) sent twice, byte for
//      byte; drop: the sample's frames removed;
//   5. periodic() traffic appended;
//   6. silence: everything of this call removed again.
// The encoder always runs (steps 1, 2, 5), so its state - counters,
// heartbeat schedule - moves on during drop and silence as if the frames had
// gone out: after the fault ends the output is byte-identical to a run that
// never had it. An action the protocol has no field for does nothing
// (link_fault_support says which; refuse those before the run).
//
// On the emission thread: no allocation once `out` has the capacity
// link_fault_reserve() gives (reserve it once per device), no exception for
// any action (the encoders' own refusals aside), no randomness except
// bit_error_seed. The only state is the encoder's own: one encoder per
// device, as without faults.
void encode_with_link_faults(const LinkActions& actions, StreamEncoder& encoder, const ImuFrameInput& sample,
                             std::vector<std::uint8_t>& out);
void encode_with_link_faults(const LinkActions& actions, CanEncoder& encoder, const ImuFrameInput& sample,
                             std::vector<CanFrame>& out);

// Which actions a protocol can show (the others do nothing).
struct LinkFaultSupport {
  bool sequence = false;       // sequence_step, sequence_reset
  bool checksum = false;       // corrupt_checksum
  bool length = false;         // bad_length
  bool bit_errors = false;     // bit_flips (not on CAN: the controller's CRC and retransmission hide them)
  bool can_id = false;         // can_wrong_id
  bool missing_frame = false;  // can_missing_frame
};
LinkFaultSupport link_fault_support(const StreamEncoder& encoder);
LinkFaultSupport link_fault_support(const CanEncoder& encoder);

// Capacity `out` needs so that encode_with_link_faults never grows it, for
// copies up to max_copies (babble_factor) - bytes for a stream encoder,
// frames for a CAN encoder.
std::size_t link_fault_reserve(const StreamEncoder& encoder, std::uint32_t max_copies);
std::size_t link_fault_reserve_can_frames(std::uint32_t max_copies);

// Bit flips: the k-th flipped bit (k = 0, 1, ...) of a sample is at bit
// position r mod n_bits of its frames' bytes (byte p / 8, bit
// p % 8 with 1 << (p % 8)), where r = splitmix64(bit_error_seed + (j + 1) *
// 0x9E3779B97F4A7C15) over draws j = 0, 1, ... skipping positions already
// drawn; at most kMaxBitFlipsPerSample (and n_bits) bits per sample.
inline constexpr std::uint32_t kMaxBitFlipsPerSample = 64;
std::uint64_t link_fault_bit_position(std::uint64_t bit_error_seed, std::uint64_t draw, std::uint64_t n_bits);

// CAN: can_id with this bit set is sent as an extended (29-bit) id even when
// it fits 11 bits (SocketCAN's CAN_EFF_FLAG); otherwise ids above 0x7FF are
// extended, the rest standard.
inline constexpr std::uint32_t kCanIdExtendedFlag = 0x80000000u;

}  // namespace imuemu::drivers
