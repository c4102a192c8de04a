// libFuzzer target: exact decimal-seconds parsing. Whatever parses must format
// back to a string that parses to the same int64 nanoseconds.
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "io/decimal_time.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace imuemu::io;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  const TimeParse parsed = try_parse_decimal_seconds(text);
  if (parsed.status != NumberStatus::ok) return 0;
  const std::string formatted = format_decimal_seconds(parsed.ns);
  const TimeParse again = try_parse_decimal_seconds(formatted);
  if (again.status != NumberStatus::ok || again.ns != parsed.ns) __builtin_trap();
  return 0;
}
