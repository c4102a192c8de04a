// Link and protocol faults at the encoder/transport edge (issue 18). The
// order of the steps and what each does: link_fault.hpp; per protocol:
// docs/faults.md. Runs on the emission thread: index arithmetic on `out`
// only (resize down, in-place copies and erases never reallocate once the
// capacity is there), no exceptions of its own, no randomness but the seed.
#include "drivers/link_fault.hpp"

#include <algorithm>
#include <array>
#include <span>

namespace imuemu::drivers {

namespace {

constexpr std::uint64_t kGoldenGamma = 0x9E3779B97F4A7C15ULL;
constexpr std::uint32_t kStandardIdMax = 0x7FF;
constexpr std::uint32_t kExtendedIdMask = 0x1FFFFFFFu;
// DroneCAN tail byte (specification 4.1): start, end, toggle, transfer id.
constexpr std::uint8_t kTailStart = 0x80;
constexpr std::uint8_t kTailEnd = 0x40;
constexpr std::uint8_t kTailToggle = 0x20;

// splitmix64's output function (Steele, Lea, Flood 2014, "Fast splittable
// pseudorandom number generators"; the constants of Vigna's reference).
std::uint64_t splitmix64_mix(std::uint64_t z) {
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
  return z ^ (z >> 31);
}

unsigned encodes_of(const LinkActions& actions) { return actions.copies > 2 ? actions.copies : 1u; }

// The sample's frames sent twice: [begin, end) copied after itself.
template <class T>
void duplicate_range(std::vector<T>& out, std::size_t begin, std::size_t end) {
  const std::size_t n = end - begin;
  out.resize(end + n);  // within capacity after warm-up; indices, not iterators, across it
  std::copy_n(out.begin() + static_cast<std::ptrdiff_t>(begin), n, out.begin() + static_cast<std::ptrdiff_t>(end));
}

template <class T>
void erase_range(std::vector<T>& out, std::size_t begin, std::size_t end) {
  out.erase(out.begin() + static_cast<std::ptrdiff_t>(begin), out.begin() + static_cast<std::ptrdiff_t>(end));
}

void flip_bits(std::uint8_t* bytes, std::size_t n_bytes, std::uint32_t flips, std::uint64_t seed) {
  const std::uint64_t n_bits = std::uint64_t{n_bytes} * 8;
  const std::uint64_t wanted = std::min<std::uint64_t>({flips, kMaxBitFlipsPerSample, n_bits});
  std::array<std::uint64_t, kMaxBitFlipsPerSample> drawn{};
  std::size_t count = 0;
  // Distinct positions (a bit flipped twice would be no flip). The draw
  // limit bounds the loop whatever the seed; it matters only when nearly
  // every bit of a tiny frame is asked for.
  constexpr std::uint64_t kMaxDraws = 64ULL * kMaxBitFlipsPerSample;
  for (std::uint64_t draw = 0; count < wanted && draw < kMaxDraws; ++draw) {
    const std::uint64_t position = link_fault_bit_position(seed, draw, n_bits);
    if (std::find(drawn.begin(), drawn.begin() + static_cast<std::ptrdiff_t>(count), position) !=
        drawn.begin() + static_cast<std::ptrdiff_t>(count))
      continue;
    drawn[count++] = position;
    bytes[position / 8] = static_cast<std::uint8_t>(bytes[position / 8] ^ (1u << (position % 8)));
  }
}

// Adds 1 to an unsigned field of `width` bytes, modulo 2^(8 width).
void increment_field(std::uint8_t* at, std::uint8_t width, bool big_endian) {
  for (std::uint8_t i = 0; i < width; ++i) {
    std::uint8_t& byte = at[big_endian ? width - 1 - i : i];
    byte = static_cast<std::uint8_t>(byte + 1);
    if (byte != 0) break;  // no carry
  }
}

// Step 3 on a byte stream: checksum, length, truncation per frame of
// [begin, end); returns the new end.
std::size_t corrupt_stream_frames(const LinkActions& actions, const StreamEncoder& encoder,
                                  std::vector<std::uint8_t>& out, std::size_t begin, std::size_t end) {
  if (!actions.corrupt_checksum && !actions.bad_length && actions.truncate_bytes == 0) return end;
  std::size_t pos = begin;
  while (pos < end) {
    const StreamFrameLayout layout =
        encoder.frame_layout(std::span<const std::uint8_t>(out.data() + pos, end - pos));
    const std::size_t frame_bytes = std::clamp<std::size_t>(layout.frame_bytes, 1, end - pos);
    std::uint8_t* frame = out.data() + pos;
    if (actions.corrupt_checksum && layout.checksum_bytes > 0 &&
        layout.checksum_offset + layout.checksum_bytes <= frame_bytes) {
      for (std::size_t i = 0; i < layout.checksum_bytes; ++i)
        frame[layout.checksum_offset + i] = static_cast<std::uint8_t>(~frame[layout.checksum_offset + i]);
    }
    if (actions.bad_length && layout.length_bytes > 0 && layout.length_offset + layout.length_bytes <= frame_bytes)
      increment_field(frame + layout.length_offset, layout.length_bytes, layout.length_big_endian);
    std::size_t kept = frame_bytes;
    if (actions.truncate_bytes > 0) {
      kept = frame_bytes - std::min<std::size_t>(actions.truncate_bytes, frame_bytes - 1);
      erase_range(out, pos + kept, pos + frame_bytes);
      end -= frame_bytes - kept;
    }
    pos += kept;
  }
  return end;
}

// The frames of a DroneCAN-style transfer starting at out[first]: up to and
// including the frame whose tail byte has the end bit (or the range's end).
std::size_t transfer_end(const std::vector<CanFrame>& out, std::size_t first, std::size_t end) {
  for (std::size_t i = first; i < end; ++i) {
    const CanFrame& f = out[i];
    if (f.len > 0 && (f.data[f.len - 1] & kTailEnd) != 0) return i + 1;
  }
  return end;
}

// A frame shortened by `cut` data bytes, never below 1 byte; with a tail
// byte the cut bytes are the ones before it (the transfer framing survives,
// its CRC shows the loss).
void cut_frame(CanFrame& f, std::uint32_t cut, bool keep_tail) {
  if (f.len <= 1) return;
  const auto n = static_cast<std::uint8_t>(std::min<std::uint32_t>(cut, f.len - 1u));
  if (keep_tail) f.data[f.len - 1 - n] = f.data[f.len - 1];
  std::fill(f.data.begin() + (f.len - n), f.data.begin() + f.len, std::uint8_t{0});
  f.len = static_cast<std::uint8_t>(f.len - n);
}

}  // namespace

std::uint64_t link_fault_bit_position(std::uint64_t bit_error_seed, std::uint64_t draw, std::uint64_t n_bits) {
  const std::uint64_t r = splitmix64_mix(bit_error_seed + (draw + 1) * kGoldenGamma);
  return n_bits == 0 ? 0 : r % n_bits;
}

void encode_with_link_faults(const LinkActions& actions, StreamEncoder& encoder, const ImuFrameInput& sample,
                             std::vector<std::uint8_t>& out) {
  const std::size_t start = out.size();
  if (actions.restart) encoder.restart(sample.t_ns, out);
  if (actions.sequence_reset) encoder.sequence_reset();
  if (actions.sequence_step != 0) encoder.sequence_step(actions.sequence_step);

  const std::size_t begin = out.size();
  for (unsigned i = 0; i < encodes_of(actions); ++i) encoder.encode(sample, out);
  std::size_t end = corrupt_stream_frames(actions, encoder, out, begin, out.size());
  if (actions.bit_flips > 0 && end > begin)
    flip_bits(out.data() + begin, end - begin, actions.bit_flips, actions.bit_error_seed);
  if (actions.drop || actions.copies == 0) {
    out.resize(begin);
  } else if (actions.copies == 2) {
    duplicate_range(out, begin, end);
  }

  encoder.periodic(sample.t_ns, out);
  if (actions.silence) out.resize(start);
}

void encode_with_link_faults(const LinkActions& actions, CanEncoder& encoder, const ImuFrameInput& sample,
                             std::vector<CanFrame>& out) {
  const std::size_t start = out.size();
  if (actions.restart) encoder.restart(sample.t_ns, out);
  if (actions.sequence_reset) encoder.sequence_reset();
  if (actions.sequence_step != 0) encoder.sequence_step(actions.sequence_step);

  const std::size_t begin = out.size();
  for (unsigned i = 0; i < encodes_of(actions); ++i) encoder.encode(sample, out);
  std::size_t end = out.size();
  const bool tail = encoder.frames_have_tail_byte();

  if (actions.corrupt_checksum && tail) {
    // Multi-frame transfer: its CRC (the first two bytes of the first
    // frame, specification 4.1) inverted. A single-frame transfer has none:
    // its tail byte's toggle bit is set instead, which a first frame must
    // never have.
    for (std::size_t first = begin; first < end;) {
      const std::size_t last = transfer_end(out, first, end);
      CanFrame& f = out[first];
      if (last - first >= 2 && f.len >= 3) {
        f.data[0] = static_cast<std::uint8_t>(~f.data[0]);
        f.data[1] = static_cast<std::uint8_t>(~f.data[1]);
      } else if (f.len > 0) {
        f.data[f.len - 1] = static_cast<std::uint8_t>(f.data[f.len - 1] ^ kTailToggle);
      }
      first = last;
    }
  }
  // The DLC is CAN's only length field, and the controller sends exactly
  // DLC bytes: a wrong length is a frame one byte short.
  const std::uint32_t cut = std::max<std::uint32_t>(actions.truncate_bytes, actions.bad_length ? 1u : 0u);
  if (cut > 0) {
    if (tail) {  // the last frame of each transfer
      for (std::size_t first = begin; first < end;) {
        const std::size_t last = transfer_end(out, first, end);
        cut_frame(out[last - 1], cut, true);
        first = last;
      }
    } else {
      for (std::size_t i = begin; i < end; ++i) cut_frame(out[i], cut, false);
    }
  }
  if (actions.can_wrong_id) {
    const std::uint32_t id = actions.can_id & kExtendedIdMask;
    const bool extended = (actions.can_id & kCanIdExtendedFlag) != 0 || id > kStandardIdMax;
    for (std::size_t i = begin; i < end; ++i) {
      out[i].id = id;
      out[i].extended = extended;
    }
  }
  if (actions.can_missing_frame && end > begin) {
    const std::size_t lost = end - begin >= 2 ? begin + 1 : begin;
    erase_range(out, lost, lost + 1);
    --end;
  }
  if (actions.drop || actions.copies == 0) {
    out.resize(begin);
  } else if (actions.copies == 2) {
    duplicate_range(out, begin, end);
  }

  encoder.periodic(sample.t_ns, out);
  if (actions.silence) out.resize(start);
}

LinkFaultSupport link_fault_support(const StreamEncoder& encoder) {
  LinkFaultSupport s;
  s.sequence = encoder.has_sequence_counter();
  // native, mavlink2 and mip all frame with a length and a checksum and
  // say where (frame_layout).
  s.checksum = true;
  s.length = true;
  s.bit_errors = true;
  return s;
}

LinkFaultSupport link_fault_support(const CanEncoder& encoder) {
  LinkFaultSupport s;
  s.sequence = encoder.has_sequence_counter();
  s.checksum = encoder.frames_have_tail_byte();
  s.length = true;  // as a DLC one short
  s.bit_errors = false;
  s.can_id = true;
  s.missing_frame = true;
  return s;
}

std::size_t link_fault_reserve(const StreamEncoder& encoder, std::uint32_t max_copies) {
  // The sample's frames up to max(copies, 2) times, the periodic traffic
  // and the power-up traffic: each at most max_bytes_per_sample().
  const std::size_t copies = std::max<std::uint32_t>(max_copies, 2);
  return (copies + 2) * encoder.max_bytes_per_sample();
}

std::size_t link_fault_reserve_can_frames(std::uint32_t max_copies) {
  // DroneCAN: a RawIMU transfer is at most 7 frames at 47 bytes (16 with a
  // full covariance), NodeStatus 1; J1939: 3 frames + 1 address claim.
  constexpr std::size_t kFramesPerSampleMax = 16;
  const std::size_t copies = std::max<std::uint32_t>(max_copies, 2);
  return (copies + 2) * kFramesPerSampleMax;
}

}  // namespace imuemu::drivers
