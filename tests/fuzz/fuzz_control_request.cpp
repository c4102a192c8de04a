// libFuzzer target: the arguments of imuemud's fault commands on the control
// socket (daemon/service/fault_control.hpp: fault-inject, fault-clear,
// fault-list), as the socket hands them over: any bytes that parse as JSON.
// Whatever the bytes: a refusal is a std::invalid_argument with a message
// (issue 26, N17: `after_s: 1e400` answered a raw nlohmann exception), and
// an accepted request is one the engine can take: a start within int64
// nanoseconds and not negative, a duration not negative, every parameter
// finite, a fault id that was a non-negative integer (`--id -5` went out as
// 18446744073709551611).
// Input: byte 0 chooses the command (bits 0-1); the rest is the JSON text
// of its arguments.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string_view>

#include <nlohmann/json.hpp>

#include "daemon/service/fault_control.hpp"

namespace {

using namespace imuemu;

void check_refusal(const std::invalid_argument& e) {
  if (std::string_view(e.what()).empty()) __builtin_trap();  // a refusal must say why
}

bool finite_spec(const fault::FaultSpec& s) {
  for (const double v : {s.gyro_bias_rad_s, s.accel_bias_m_s2, s.gyro_ramp_rad_s2, s.accel_ramp_m_s3, s.scale_ppm,
                         s.noise_factor, s.rate_hz, s.probability, s.bit_error_rate})
    if (!std::isfinite(v)) return false;
  return s.duration_ns >= 0 && s.on_ns >= 0 && s.off_ns >= 0 && s.delay_ns >= 0 && s.probability >= 0.0 &&
         s.probability <= 1.0;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  const unsigned command = data[0] & 3u;
  const nlohmann::json args =
      nlohmann::json::parse(reinterpret_cast<const char*>(data + 1), reinterpret_cast<const char*>(data + size),
                            nullptr, /*allow_exceptions=*/false);
  if (args.is_discarded()) return 0;  // the socket refuses a line that is not JSON before this
  try {
    switch (command) {
      case 0:
      case 3: {
        const service::FaultInjectRequest r = service::parse_fault_inject(args);
        if (r.after_ns < 0 || !finite_spec(r.spec)) __builtin_trap();
        break;
      }
      case 1: {
        const service::FaultClearRequest r = service::parse_fault_clear(args);
        if (r.id) {
          // An id the socket took is an integer it was given, never a wrapped negative.
          const auto given = args.find("id");
          if (given == args.end() || given->is_number_integer() == false) __builtin_trap();
          if (given->is_number_unsigned() ? given->get<std::uint64_t>() != *r.id
                                          : given->get<std::int64_t>() < 0 ||
                                                static_cast<std::uint64_t>(given->get<std::int64_t>()) != *r.id)
            __builtin_trap();
        }
        break;
      }
      case 2:
        (void)service::parse_fault_list(args);
        break;
    }
  } catch (const std::invalid_argument& e) {
    check_refusal(e);
  }
  // Any other exception escapes and libFuzzer reports it: the socket would
  // have answered a raw library message.
  return 0;
}
