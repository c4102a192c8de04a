// The engine's grid arithmetic (internal to daemon/engine/): where sample k
// of a device at an integer rate falls in trajectory time, how many samples
// a span holds, and where a run-time fault's first sample is. Exact in
// 128-bit integers (no accumulated drift over a long run), saturated at the
// int64 limit where a time could leave it (core/time_arith.hpp).
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <limits>

#include "core/time_arith.hpp"
#include "core/types.hpp"

namespace imuemu::emission {

__extension__ typedef __int128 Int128;  // exact products of int64 times (GCC/Clang)

// Grid time k of a stream starting at t0: t0 + floor(k * 1e9 / rate), in
// 128 bits (core/pipeline.hpp output_grid), saturated at the int64 limit
// (core/time_arith.hpp): a grid reaching beyond int64 ns (a stream stamped
// near the limit, issue 13 C1) ends there instead of wrapping.
inline TimeNs grid_ns(TimeNs t0_ns, std::uint64_t k, std::int64_t rate_hz) noexcept {
  const Int128 offset = static_cast<Int128>(k) * kNsPerSecond / rate_hz;
  if (offset > static_cast<Int128>(kMaxTimeNs)) return kMaxTimeNs;
  return saturating_add_ns(t0_ns, static_cast<TimeNs>(offset));
}

// Number of grid ticks with t_k <= t0 + span_ns: the k with k * 1e9 < (span + 1) * rate.
inline std::uint64_t ticks_within(TimeNs span_ns, std::int64_t rate_hz) noexcept {
  const Int128 bound = (static_cast<Int128>(span_ns) + 1) * rate_hz;
  const Int128 ticks = (bound + kNsPerSecond - 1) / kNsPerSecond;
  return ticks > static_cast<Int128>(std::numeric_limits<std::uint64_t>::max()) ? std::numeric_limits<std::uint64_t>::max()
                                                                                : static_cast<std::uint64_t>(ticks);
}

// The first tick at or after `since_t0_ns` on the grid (t_k - t0 >= since):
// the first k with floor(k 1e9 / rate) >= since, i.e. ceil(since rate / 1e9).
inline std::uint64_t first_tick_at_or_after(TimeNs since_t0_ns, std::int64_t rate_hz) noexcept {
  const Int128 first = (static_cast<Int128>(since_t0_ns) * rate_hz + kNsPerSecond - 1) / kNsPerSecond;
  return static_cast<std::uint64_t>(first);
}

// Ring slots for span_ns of samples at rate_hz: the ticks in the span, two
// more, at least 16.
inline std::size_t ring_capacity_for(TimeNs span_ns, std::int64_t rate_hz) noexcept {
  return static_cast<std::size_t>(std::max<Int128>(16, static_cast<Int128>(span_ns) * rate_hz / kNsPerSecond + 2));
}

}  // namespace imuemu::emission
