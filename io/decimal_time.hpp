// Exact text <-> number conversions for the file formats.
//
// Times are written in files as decimal seconds ("1700000000.123456789") but
// live in the program as int64 nanoseconds (core/types.hpp). A trip through
// double would lose the nanoseconds of an epoch time (2^53 ns is only 104
// days), so times are parsed digit by digit, exactly, and formatted back the
// same way. Other quantities are doubles, parsed with std::from_chars (exact
// round trip of std::to_chars' shortest form) and refused when not finite.
//
// Accepted time syntax (no exponent, no spaces, ASCII digits only):
//   [+|-] digits [ . [digits] ]   or   [+|-] . digits
// with at most 9 significant fraction digits: further fraction digits are
// accepted only if they are all '0' ("1.5000000000" is fine, "0.0000000005" is
// refused as finer than a nanosecond). The value must fit in int64 ns, i.e.
// [-9223372036.854775808, 9223372036.854775807] s.
#pragma once

#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <string_view>

#include "core/decimal_seconds.hpp"
#include "core/types.hpp"

namespace imuemu::io {

// Why a number field was refused. `ok` means the value is valid.
enum class NumberStatus {
  ok,
  empty,         // nothing (or only a sign) to parse
  malformed,     // not the accepted syntax (letters, exponent in a time, "1..2", ...)
  too_precise,   // a time with non-zero digits beyond the 9th decimal
  out_of_range,  // does not fit (int64 ns; a double beyond +-1.8e308 or underflowing)
  not_finite,    // "nan", "inf", "infinity" (any case)
};

// Short English phrase for a status, e.g. "more than nanosecond resolution".
std::string_view describe(NumberStatus status) noexcept;

struct TimeParse {
  TimeNs ns = 0;
  NumberStatus status = NumberStatus::empty;
};
struct DoubleParse {
  double value = 0.0;
  NumberStatus status = NumberStatus::empty;
};
struct Int64Parse {
  std::int64_t value = 0;
  NumberStatus status = NumberStatus::empty;
};

// Decimal seconds -> exact int64 nanoseconds (syntax above). Never throws.
TimeParse try_parse_decimal_seconds(std::string_view text) noexcept;

// Finite double from std::from_chars (general format: "1.5", "-2e-3", ".5", "5.").
// A single leading '+' is accepted; NaN/Inf, empty fields, leading/trailing
// spaces or garbage and hex are refused. Never throws.
DoubleParse try_parse_double(std::string_view text) noexcept;

// Decimal integer: [+|-] digits, within int64. Never throws.
Int64Parse try_parse_int64(std::string_view text) noexcept;

// Thrown by the throwing convenience forms below.
class NumberFormatError : public std::invalid_argument {
 public:
  NumberFormatError(std::string_view text, NumberStatus status, std::string_view what_expected);
  NumberStatus status() const noexcept { return status_; }

 private:
  NumberStatus status_;
};

TimeNs parse_decimal_seconds(std::string_view text);
double parse_double(std::string_view text);
std::int64_t parse_int64(std::string_view text);

// int64 ns -> the shortest exact decimal seconds: 12'500'000'000 -> "12.5",
// 0 -> "0", -1 -> "-0.000000001", 3'000'000'000 -> "3". Parsing the result with
// try_parse_decimal_seconds gives back t_ns exactly, for every int64.
// Implemented in core/decimal_seconds.hpp (core's messages name times
// exactly too); kMaxDecimalSecondsChars = 21 is its longest output.
using imuemu::format_decimal_seconds;
using imuemu::kMaxDecimalSecondsChars;
using imuemu::write_decimal_seconds;

}  // namespace imuemu::io
