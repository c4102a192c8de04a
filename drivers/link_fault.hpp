// Link and protocol faults (issue 18) at the encoder/transport edge. The
// producer thread decides, per sample, what the active link faults do to it
// (LinkActions, from core/fault's timeline and the fault's seeded random
// stream) and puts that in the sample's ring slot; the emission thread only
// applies it here: no allocation once the buffers have grown, no blocking,
// no randomness of its own (bit positions come from actions.bit_error_seed).
#pragma once

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
// alone would. What each action does per protocol: docs/faults.md.
void encode_with_link_faults(const LinkActions& actions, StreamEncoder& encoder, const ImuFrameInput& sample,
                             std::vector<std::uint8_t>& out);
void encode_with_link_faults(const LinkActions& actions, CanEncoder& encoder, const ImuFrameInput& sample,
                             std::vector<CanFrame>& out);

}  // namespace imuemu::drivers
