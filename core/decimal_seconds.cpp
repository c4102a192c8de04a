#include "core/decimal_seconds.hpp"

#include <cstdint>

namespace imuemu {

char* write_decimal_seconds(char* out, TimeNs t_ns) noexcept {
  const bool negative = t_ns < 0;
  // Unsigned negation is well defined, including for INT64_MIN.
  const std::uint64_t magnitude =
      negative ? std::uint64_t{0} - static_cast<std::uint64_t>(t_ns) : static_cast<std::uint64_t>(t_ns);
  std::uint64_t seconds = magnitude / 1'000'000'000u;
  std::uint64_t frac = magnitude % 1'000'000'000u;
  if (negative) *out++ = '-';
  char digits[20];
  int count = 0;
  do {
    digits[count++] = static_cast<char>('0' + seconds % 10);
    seconds /= 10;
  } while (seconds != 0);
  while (count > 0) *out++ = digits[--count];
  if (frac != 0) {
    *out++ = '.';
    int width = 9;
    while (frac % 10 == 0) {  // shortest: drop trailing zeros
      frac /= 10;
      --width;
    }
    for (int pos = width - 1; pos >= 0; --pos) {
      digits[pos] = static_cast<char>('0' + frac % 10);
      frac /= 10;
    }
    for (int pos = 0; pos < width; ++pos) *out++ = digits[pos];
  }
  return out;
}

std::string format_decimal_seconds(TimeNs t_ns) {
  char buffer[kMaxDecimalSecondsChars];
  char* const end = write_decimal_seconds(buffer, t_ns);
  return std::string(buffer, end);
}

}  // namespace imuemu
