// int64 nanoseconds -> the shortest exact decimal seconds, for messages in
// core/ and for the files io/ writes (io/decimal_time.hpp forwards here).
// A double holds only ~16 significant digits, so an epoch time printed
// through one loses its microseconds: this is digit by digit, never rounded.
#pragma once

#include <cstddef>
#include <string>

#include "core/types.hpp"

namespace imuemu {

// Longest output of format_decimal_seconds: "-9223372036.854775808".
inline constexpr std::size_t kMaxDecimalSecondsChars = 21;

// 12'500'000'000 -> "12.5", 0 -> "0", -1 -> "-0.000000001",
// 3'000'000'000 -> "3"; every int64, exactly.
std::string format_decimal_seconds(TimeNs t_ns);
// Same, written at `out` (room for kMaxDecimalSecondsChars chars); returns the
// end of what was written. No terminating NUL.
char* write_decimal_seconds(char* out, TimeNs t_ns) noexcept;

}  // namespace imuemu
