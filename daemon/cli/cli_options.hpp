// The numeric options of every imuemu subcommand: one validator for a finite
// number in a range, and the one checked step from seconds (or seconds x Hz)
// to int64 ns and sample counts. CLI11's Range, PositiveNumber and
// NonNegativeNumber let NaN through (every comparison with NaN is false) and
// ranges of 1e300 seconds later overflowed int64 ns; these refuse both with
// exit 2, naming the option and the allowed range.
#pragma once

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>

#include "core/limits.hpp"
#include "core/types.hpp"

namespace imuemu::cli {

// A command line the command refuses after parsing (a combination of options
// out of range): exit 2 (kUsageError), the message names the options.
class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Shortest decimal of a bound, for messages ("0", "3600", "1e+06").
inline std::string bound_text(double v) {
  std::ostringstream out;
  out << v;
  return out.str();
}

// A finite number in [lo, hi] (lo_open: (lo, hi]).
inline CLI::Validator finite_in(double lo, double hi, bool lo_open = false) {
  const std::string range = (lo_open ? "(" : "[") + bound_text(lo) + ", " + bound_text(hi) + "]";
  return CLI::Validator(
      [lo, hi, lo_open, range](std::string& text) -> std::string {
        double v = 0.0;
        if (!CLI::detail::lexical_cast(text, v)) return "'" + text + "' is not a number; expected one in " + range;
        if (!std::isfinite(v) || (lo_open ? !(v > lo) : !(v >= lo)) || !(v <= hi))
          return text + " is out of range; expected a finite number in " + range;
        return {};
      },
      "FINITE in " + range, "finite_in");
}

// Seconds in [lo, hi] (lo_open: (lo, hi]); hi at most
// limits::kMaxSecondsMagnitude, so the value always fits int64 ns.
inline CLI::Validator seconds_in(double lo, double hi, bool lo_open = false) {
  if (!(hi <= limits::kMaxSecondsMagnitude)) throw std::logic_error("seconds_in: bound beyond int64 ns");
  return finite_in(lo, hi, lo_open);
}

// Upper bounds of the duration-like options (seconds): 30 days of trajectory
// or of emission, as the scene's built-in samples; pose spacing, windows,
// blends and margins: one hour, as the scene's knot_interval_s.
inline constexpr double kMaxDurationS = 30.0 * 86400.0;
inline constexpr double kMaxIntervalS = 3600.0;
inline constexpr double kMaxGapS = 86400.0;
// Flat-scene gravity magnitude (m/s^2), as the scene's gravity_m_s2.
inline constexpr double kMaxGravityM_s2 = 100.0;

// The one checked conversion of an option given in seconds to int64 ns:
// UsageError naming the option when it does not fit (after seconds_in it
// always does; this keeps the conversion defined whoever calls it).
inline TimeNs option_ns(const std::string& option, double seconds) {
  if (const auto ns = limits::checked_ns_from_seconds(seconds)) return *ns;
  throw UsageError(option + " " + bound_text(seconds) + ": does not fit int64 nanoseconds (|s| <= " +
                   bound_text(limits::kMaxSecondsMagnitude) + ")");
}

// The smoothing window Delta (samples) of `seconds` at rate_hz, at least 1:
// nullopt when it exceeds limits::kMaxWindowSamples (the engine's one cap).
inline std::optional<int> window_samples(double seconds, std::int64_t rate_hz) {
  const auto n = limits::checked_samples(seconds, static_cast<double>(rate_hz), limits::kMaxWindowSamples);
  if (!n) return std::nullopt;
  return static_cast<int>(std::max<std::int64_t>(1, *n));
}

}  // namespace imuemu::cli
