// Byte-level helpers shared by the byte-stream protocols (internal to
// drivers/protocols): explicit-endian field packing, the float clamping every
// encoder applies before a value goes on the wire, and the resynchronising
// frame scanner every stream decoder runs.
#pragma once

#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>
#include <span>
#include <type_traits>
#include <vector>

#include "drivers/protocol.hpp"

namespace imuemu::drivers::wire {

// ---- explicit-endian packing (never memcpy of host structs: the wire order
// is the protocol's, not the compiler's) ----

template <class T>
using UnsignedOf = std::conditional_t<sizeof(T) == 1, std::uint8_t,
                   std::conditional_t<sizeof(T) == 2, std::uint16_t,
                   std::conditional_t<sizeof(T) == 4, std::uint32_t, std::uint64_t>>>;

template <class T>
void put_le(std::uint8_t* at, T value) {
  auto bits = std::bit_cast<UnsignedOf<T>>(value);
  for (std::size_t i = 0; i < sizeof(T); ++i) at[i] = static_cast<std::uint8_t>(bits >> (8 * i));
}

template <class T>
void put_be(std::uint8_t* at, T value) {
  auto bits = std::bit_cast<UnsignedOf<T>>(value);
  for (std::size_t i = 0; i < sizeof(T); ++i)
    at[sizeof(T) - 1 - i] = static_cast<std::uint8_t>(bits >> (8 * i));
}

template <class T>
T get_le(const std::uint8_t* at) {
  UnsignedOf<T> bits = 0;
  for (std::size_t i = 0; i < sizeof(T); ++i) bits |= static_cast<UnsignedOf<T>>(UnsignedOf<T>{at[i]} << (8 * i));
  return std::bit_cast<T>(bits);
}

template <class T>
T get_be(const std::uint8_t* at) {
  UnsignedOf<T> bits = 0;
  for (std::size_t i = 0; i < sizeof(T); ++i)
    bits |= static_cast<UnsignedOf<T>>(UnsignedOf<T>{at[sizeof(T) - 1 - i]} << (8 * i));
  return std::bit_cast<T>(bits);
}

// ---- values onto the wire: never NaN or infinity ----

// What became of one value on its way to the wire.
struct WireValue {
  double value = 0.0;     // finite and representable in the wire type
  bool clamped = false;   // was outside the wire type's range (incl. +-inf)
  bool was_nan = false;   // NaN: sent as 0, the protocol marks it its own way
};

// A value for a wire field of floating type Wire: NaN -> 0, beyond the type's
// finite range (or infinite) -> the largest finite value of that sign.
template <class Wire>
WireValue to_wire_float(double v) {
  constexpr double kMax = static_cast<double>(std::numeric_limits<Wire>::max());
  if (std::isnan(v)) return {0.0, false, true};
  if (v > kMax) return {kMax, true, false};
  if (v < -kMax) return {-kMax, true, false};
  return {v, false, false};
}

// ---- resynchronising frame scanner ----

// A candidate frame starting at a sync position, as the protocol judges it.
enum class Candidate {
  kNeedMore,     // not enough bytes yet to judge
  kBadChecksum,  // framed, checksum/CRC failed
  kMalformed,    // header impossible (bad version, length, unknown id, ...)
  kAccepted,     // a valid frame of `length` bytes (the protocol handled it)
};
struct CandidateResult {
  Candidate verdict = Candidate::kNeedMore;
  std::size_t length = 0;  // only for kAccepted
};

// Runs `judge(span starting at a sync position)` over the buffered stream.
// Every byte fed ends up either in an accepted frame or counted in
// resync_bytes (or is still buffered waiting for more): a rejected candidate
// gives up only its first byte, so a real frame that starts inside a false or
// damaged one is still found.
//
// `sync` is the protocol's start-of-frame pattern (1 or 2 bytes). A trailing
// partial sync is kept buffered.
template <class Judge>
void scan_frames(std::vector<std::uint8_t>& buffer, std::span<const std::uint8_t> sync,
                 DecoderCounters& counters, Judge&& judge) {
  std::size_t pos = 0;
  const std::size_t n = buffer.size();
  while (pos < n) {
    // Next position where the sync pattern starts (or could start, if cut
    // off by the end of the buffer).
    std::size_t start = pos;
    for (; start < n; ++start) {
      bool match = true;
      for (std::size_t k = 0; k < sync.size() && start + k < n; ++k) {
        if (buffer[start + k] != sync[k]) {
          match = false;
          break;
        }
      }
      if (match) break;
    }
    counters.resync_bytes += start - pos;
    pos = start;
    if (pos >= n) break;

    const CandidateResult r = judge(std::span<const std::uint8_t>(buffer.data() + pos, n - pos));
    if (r.verdict == Candidate::kNeedMore) break;
    if (r.verdict == Candidate::kAccepted) {
      pos += r.length;
      continue;
    }
    if (r.verdict == Candidate::kBadChecksum) ++counters.checksum_errors;
    else ++counters.other_errors;
    ++counters.resync_bytes;
    ++pos;
  }
  buffer.erase(buffer.begin(), buffer.begin() + static_cast<std::ptrdiff_t>(pos));
}

}  // namespace imuemu::drivers::wire
