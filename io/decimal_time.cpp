#include "io/decimal_time.hpp"

#include <charconv>
#include <cmath>
#include <limits>
#include <system_error>

namespace imuemu::io {
namespace {

constexpr bool is_digit(char c) noexcept { return c >= '0' && c <= '9'; }

// Largest magnitude of a negative / non-negative int64, as unsigned.
constexpr std::uint64_t kMaxNegativeMagnitude = std::uint64_t{1} << 63;
constexpr std::uint64_t kMaxPositiveMagnitude = kMaxNegativeMagnitude - 1;

// -magnitude or +magnitude as int64; magnitude is within the matching limit.
constexpr std::int64_t apply_sign(std::uint64_t magnitude, bool negative) noexcept {
  if (!negative || magnitude == 0) return static_cast<std::int64_t>(magnitude);
  // -(m - 1) - 1 avoids forming +2^63 for INT64_MIN.
  return -static_cast<std::int64_t>(magnitude - 1) - 1;
}

}  // namespace

std::string_view describe(NumberStatus status) noexcept {
  switch (status) {
    case NumberStatus::ok: return "ok";
    case NumberStatus::empty: return "empty field";
    case NumberStatus::malformed: return "not a number in the accepted syntax";
    case NumberStatus::too_precise: return "more than nanosecond resolution";
    case NumberStatus::out_of_range: return "out of range";
    case NumberStatus::not_finite: return "not finite (NaN or infinity)";
  }
  return "unknown";
}

TimeParse try_parse_decimal_seconds(std::string_view text) noexcept {
  const std::size_t n = text.size();
  std::size_t i = 0;
  bool negative = false;
  if (i < n && (text[i] == '+' || text[i] == '-')) {
    negative = text[i] == '-';
    ++i;
  }
  // Syntax pass first, so a malformed field is reported as malformed even if
  // it is also huge.
  const std::size_t int_begin = i;
  while (i < n && is_digit(text[i])) ++i;
  const std::size_t int_end = i;
  std::size_t frac_begin = i;
  std::size_t frac_end = i;
  if (i < n && text[i] == '.') {
    frac_begin = ++i;
    while (i < n && is_digit(text[i])) ++i;
    frac_end = i;
  }
  if (int_end == int_begin && frac_end == frac_begin) {
    // No digit at all: "", "+" and "-" are empty; ".", "-." or "abc" malformed.
    return {0, int_begin == n ? NumberStatus::empty : NumberStatus::malformed};
  }
  if (i != n) return {0, NumberStatus::malformed};

  // Fraction: the first 9 digits are nanoseconds; any further digit must be 0.
  std::uint64_t frac_ns = 0;
  std::size_t k = 0;
  for (; k < 9; ++k) {
    const std::size_t pos = frac_begin + k;
    const unsigned digit = pos < frac_end ? static_cast<unsigned>(text[pos] - '0') : 0u;
    frac_ns = frac_ns * 10 + digit;
  }
  for (std::size_t pos = frac_begin + 9; pos < frac_end; ++pos) {
    if (text[pos] != '0') return {0, NumberStatus::too_precise};
  }

  // Integer seconds: int64 ns holds at most 9'223'372'036 s (10 digits), so
  // more than 10 significant digits overflow; with at most 10 digits,
  // seconds * 1e9 + frac < 1e19 < 2^64 cannot wrap in uint64.
  std::size_t first_significant = int_begin;
  while (first_significant < int_end && text[first_significant] == '0') ++first_significant;
  if (int_end - first_significant > 10) return {0, NumberStatus::out_of_range};
  std::uint64_t seconds = 0;
  for (std::size_t pos = first_significant; pos < int_end; ++pos) {
    seconds = seconds * 10 + static_cast<unsigned>(text[pos] - '0');
  }
  const std::uint64_t magnitude = seconds * 1'000'000'000u + frac_ns;
  if (magnitude > (negative ? kMaxNegativeMagnitude : kMaxPositiveMagnitude)) {
    return {0, NumberStatus::out_of_range};
  }
  return {apply_sign(magnitude, negative), NumberStatus::ok};
}

DoubleParse try_parse_double(std::string_view text) noexcept {
  if (text.empty()) return {0.0, NumberStatus::empty};
  const char* first = text.data();
  const char* const last = text.data() + text.size();
  if (*first == '+') {
    ++first;
    // from_chars takes a '-' itself; "+-1" and "++1" are not numbers.
    if (first == last) return {0.0, NumberStatus::empty};
    if (*first == '-' || *first == '+') return {0.0, NumberStatus::malformed};
  }
  double value = 0.0;
  const auto [end, ec] = std::from_chars(first, last, value, std::chars_format::general);
  if (ec == std::errc::invalid_argument) return {0.0, NumberStatus::malformed};
  if (end != last) return {0.0, NumberStatus::malformed};
  if (ec == std::errc::result_out_of_range) return {0.0, NumberStatus::out_of_range};
  if (ec != std::errc{}) return {0.0, NumberStatus::malformed};
  if (!std::isfinite(value)) return {0.0, NumberStatus::not_finite};
  return {value, NumberStatus::ok};
}

Int64Parse try_parse_int64(std::string_view text) noexcept {
  if (text.empty()) return {0, NumberStatus::empty};
  const char* first = text.data();
  const char* const last = text.data() + text.size();
  if (*first == '+') {
    ++first;
    if (first == last) return {0, NumberStatus::empty};
    if (*first == '-' || *first == '+') return {0, NumberStatus::malformed};
  }
  std::int64_t value = 0;
  const auto [end, ec] = std::from_chars(first, last, value, 10);
  if (ec == std::errc::invalid_argument) return {0, NumberStatus::malformed};
  if (end != last) return {0, NumberStatus::malformed};
  if (ec == std::errc::result_out_of_range) return {0, NumberStatus::out_of_range};
  if (ec != std::errc{}) return {0, NumberStatus::malformed};
  return {value, NumberStatus::ok};
}

NumberFormatError::NumberFormatError(std::string_view text, NumberStatus status,
                                     std::string_view what_expected)
    : std::invalid_argument("expected " + std::string(what_expected) + ", got '" +
                            std::string(text.substr(0, 64)) + (text.size() > 64 ? "...'" : "'") +
                            " (" + std::string(describe(status)) + ")"),
      status_(status) {}

TimeNs parse_decimal_seconds(std::string_view text) {
  const TimeParse r = try_parse_decimal_seconds(text);
  if (r.status != NumberStatus::ok) {
    throw NumberFormatError(text, r.status, "a time in decimal seconds");
  }
  return r.ns;
}

double parse_double(std::string_view text) {
  const DoubleParse r = try_parse_double(text);
  if (r.status != NumberStatus::ok) throw NumberFormatError(text, r.status, "a finite number");
  return r.value;
}

std::int64_t parse_int64(std::string_view text) {
  const Int64Parse r = try_parse_int64(text);
  if (r.status != NumberStatus::ok) throw NumberFormatError(text, r.status, "a 64-bit integer");
  return r.value;
}

}  // namespace imuemu::io
