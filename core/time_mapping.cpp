#include "core/time_mapping.hpp"

#include <algorithm>
#include <limits>
#include <stdexcept>

namespace imuemu::live {

namespace {

// GCC/Clang 128-bit integer; __extension__ keeps -Wpedantic quiet (ISO C++ has
// no 128-bit type). Every product below is (difference of two int64, < 2^64)
// times (a speed term <= 10^12 < 2^40), so < 2^104: no overflow.
__extension__ typedef __int128 Int128;

Int128 gcd(Int128 a, Int128 b) {
  while (b != 0) {
    const Int128 r = a % b;
    a = b;
    b = r;
  }
  return a;
}

// floor(a / b) and ceil(a / b) for b > 0 (C++ division truncates towards 0).
Int128 floor_div(Int128 a, Int128 b) {
  const Int128 q = a / b;
  return (a % b != 0 && a < 0) ? q - 1 : q;
}
Int128 ceil_div(Int128 a, Int128 b) {
  const Int128 q = a / b;
  return (a % b != 0 && a > 0) ? q + 1 : q;
}

TimeNs to_time_or_throw(Int128 value, const char* what, TimeNs input) {
  if (value > std::numeric_limits<TimeNs>::max() || value < std::numeric_limits<TimeNs>::min()) {
    throw std::overflow_error(std::string("time mapping: ") + what + " of " + std::to_string(input) +
                              " ns does not fit int64 nanoseconds");
  }
  return static_cast<TimeNs>(value);
}

SpeedFactor reduced_or_throw(Int128 p, Int128 q, std::string_view text) {
  const Int128 g = gcd(p, q);
  p /= g;
  q /= g;
  if (p < 1 || q < 1 || p > kMaxSpeedTerm || q > kMaxSpeedTerm) {
    throw std::invalid_argument("speed factor '" + std::string(text) +
                                "': expected a positive speed whose reduced fraction p/q has p, q <= " +
                                std::to_string(kMaxSpeedTerm));
  }
  return SpeedFactor{static_cast<std::int64_t>(p), static_cast<std::int64_t>(q)};
}

// Digits only, 1..25 of them (so the value fits Int128 with room to scale).
bool parse_digits(std::string_view digits, Int128& value) {
  if (digits.empty() || digits.size() > 25) return false;
  value = 0;
  for (const char c : digits) {
    if (c < '0' || c > '9') return false;
    value = value * 10 + (c - '0');
  }
  return true;
}

}  // namespace

SpeedFactor make_speed_factor(std::int64_t numerator, std::int64_t denominator) {
  const std::string text = std::to_string(numerator) + "/" + std::to_string(denominator);
  if (numerator < 1 || denominator < 1) {
    throw std::invalid_argument("speed factor '" + text + "': expected numerator and denominator >= 1");
  }
  return reduced_or_throw(numerator, denominator, text);
}

SpeedFactor parse_speed_factor(std::string_view text) {
  const auto fail = [&]() -> SpeedFactor {
    throw std::invalid_argument("speed factor '" + std::string(text) +
                                "': expected a positive decimal (e.g. 2.5, at most 12 fraction digits) or a "
                                "fraction p/q of positive integers (e.g. 1/3)");
  };
  Int128 p = 0, q = 1;
  if (const auto slash = text.find('/'); slash != std::string_view::npos) {
    if (!parse_digits(text.substr(0, slash), p) || !parse_digits(text.substr(slash + 1), q)) return fail();
  } else if (const auto dot = text.find('.'); dot != std::string_view::npos) {
    const std::string_view whole = text.substr(0, dot), fraction = text.substr(dot + 1);
    if (fraction.empty() || fraction.size() > 12) return fail();
    Int128 w = 0, f = 0;
    if (!(whole.empty() || parse_digits(whole, w)) || !parse_digits(fraction, f)) return fail();
    for (std::size_t i = 0; i < fraction.size(); ++i) q *= 10;
    p = w * q + f;  // w < 10^25, q <= 10^12: fits Int128
  } else if (!parse_digits(text, p)) {
    return fail();
  }
  if (p == 0 || q == 0) return fail();
  return reduced_or_throw(p, q, text);
}

std::string to_string(const SpeedFactor& speed) {
  if (speed.denominator == 1) return std::to_string(speed.numerator);
  return std::to_string(speed.numerator) + "/" + std::to_string(speed.denominator);
}

TimeMapping::TimeMapping(TimeNs anchor_trajectory_ns, TimeNs anchor_monotonic_ns, SpeedFactor speed)
    : anchor_trajectory_ns_(anchor_trajectory_ns),
      anchor_monotonic_ns_(anchor_monotonic_ns),
      // Re-validates and reduces a hand-built SpeedFactor.
      speed_(make_speed_factor(speed.numerator, speed.denominator)) {}

TimeMapping TimeMapping::start_now(TimeNs start_trajectory_ns, TimeNs monotonic_now_ns, SpeedFactor speed) {
  return TimeMapping(start_trajectory_ns, monotonic_now_ns, speed);
}

TimeMapping TimeMapping::start_at_next_realtime_second(TimeNs start_trajectory_ns, TimeNs monotonic_now_ns,
                                                       TimeNs realtime_now_ns, TimeNs min_lead_ns,
                                                       SpeedFactor speed) {
  if (min_lead_ns < 0) {
    throw std::invalid_argument("next-second alignment: min_lead_ns " + std::to_string(min_lead_ns) +
                                ": expected >= 0");
  }
  // Floor/ceil division, so a (pre-1970) negative realtime also lands on the
  // right whole second.
  const Int128 after_now = (floor_div(realtime_now_ns, kNsPerSecond) + 1) * kNsPerSecond;
  const Int128 after_lead = ceil_div(static_cast<Int128>(realtime_now_ns) + min_lead_ns, kNsPerSecond) * kNsPerSecond;
  const Int128 next_second = std::max(after_now, after_lead);
  const Int128 anchor = static_cast<Int128>(monotonic_now_ns) + (next_second - realtime_now_ns);
  return TimeMapping(start_trajectory_ns, to_time_or_throw(anchor, "next-second anchor for realtime", realtime_now_ns),
                     speed);
}

TimeNs TimeMapping::monotonic_at(TimeNs trajectory_ns) const {
  const Int128 elapsed_trajectory = static_cast<Int128>(trajectory_ns) - anchor_trajectory_ns_;
  const Int128 m = anchor_monotonic_ns_ + ceil_div(elapsed_trajectory * speed_.denominator, speed_.numerator);
  return to_time_or_throw(m, "monotonic instant of trajectory time", trajectory_ns);
}

TimeNs TimeMapping::trajectory_at(TimeNs monotonic_ns) const {
  const Int128 elapsed_monotonic = static_cast<Int128>(monotonic_ns) - anchor_monotonic_ns_;
  const Int128 t = anchor_trajectory_ns_ + floor_div(elapsed_monotonic * speed_.numerator, speed_.denominator);
  return to_time_or_throw(t, "trajectory time of monotonic instant", monotonic_ns);
}

}  // namespace imuemu::live
