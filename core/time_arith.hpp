// Overflow-safe arithmetic on int64 nanoseconds (core/types.hpp TimeNs).
//
// Time is int64 ns end to end; a sum, difference or product of two times can
// leave int64 (signed overflow is undefined behaviour in C++), e.g. a pose
// stamped near INT64_MAX plus the end extrapolation's padding, or a
// difference INT64_MAX - INT64_MIN. Every such combination in core/ and io/
// goes through one of these, whose names say what happens at the limit:
//   checked_*_ns     std::nullopt when the exact result does not fit int64
//                    (the caller refuses the input and says why);
//   saturating_*_ns  the exact result clamped to [INT64_MIN, INT64_MAX]
//                    (for bounds and comparisons where "beyond" is enough);
//   ns_between       the exact distance of two ordered instants as uint64.
// Pure, constexpr, noexcept.
#pragma once

#include <cstdint>
#include <limits>
#include <optional>

#include "core/types.hpp"

namespace imuemu {

inline constexpr TimeNs kMaxTimeNs = std::numeric_limits<TimeNs>::max();
inline constexpr TimeNs kMinTimeNs = std::numeric_limits<TimeNs>::min();

constexpr std::optional<TimeNs> checked_add_ns(TimeNs a, TimeNs b) noexcept {
  TimeNs r = 0;
  if (__builtin_add_overflow(a, b, &r)) return std::nullopt;
  return r;
}

constexpr std::optional<TimeNs> checked_sub_ns(TimeNs a, TimeNs b) noexcept {
  TimeNs r = 0;
  if (__builtin_sub_overflow(a, b, &r)) return std::nullopt;
  return r;
}

// a * factor (a count of periods, a number of seconds times kNsPerSecond).
constexpr std::optional<TimeNs> checked_mul_ns(TimeNs a, std::int64_t factor) noexcept {
  TimeNs r = 0;
  if (__builtin_mul_overflow(a, factor, &r)) return std::nullopt;
  return r;
}

constexpr TimeNs saturating_add_ns(TimeNs a, TimeNs b) noexcept {
  TimeNs r = 0;
  if (__builtin_add_overflow(a, b, &r)) return b > 0 ? kMaxTimeNs : kMinTimeNs;
  return r;
}

constexpr TimeNs saturating_sub_ns(TimeNs a, TimeNs b) noexcept {
  TimeNs r = 0;
  if (__builtin_sub_overflow(a, b, &r)) return b < 0 ? kMaxTimeNs : kMinTimeNs;
  return r;
}

constexpr TimeNs saturating_mul_ns(TimeNs a, std::int64_t factor) noexcept {
  TimeNs r = 0;
  if (__builtin_mul_overflow(a, factor, &r)) return (a < 0) != (factor < 0) ? kMinTimeNs : kMaxTimeNs;
  return r;
}

// to - from for from <= to, exactly (it lies in [0, 2^64)), where the signed
// difference could overflow.
constexpr std::uint64_t ns_between(TimeNs from_ns, TimeNs to_ns) noexcept {
  return static_cast<std::uint64_t>(to_ns) - static_cast<std::uint64_t>(from_ns);
}

}  // namespace imuemu
