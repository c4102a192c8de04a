// GPS <-> UTC with the leap-second table; see gps_time.hpp.
#include "drivers/protocols/gps_time.hpp"

#include <array>

namespace imuemu::drivers::gps_time {

namespace {

constexpr std::int64_t kNsPerSecond64 = 1'000'000'000;

using aiding::kLeapSecondStartsPosix;  // core/aiding/gnss_time.hpp: the one table

// GPS seconds at which each new value applies: the UTC day start, moved to
// the GPS scale with the new offset.
constexpr std::int64_t gps_start_s(std::size_t i) {
  return kLeapSecondStartsPosix[i] - kGpsEpochPosixSeconds + static_cast<std::int64_t>(i) + 1;
}

}  // namespace

int gps_minus_utc_s(TimeNs utc_posix_ns) { return aiding::gps_minus_utc_s(utc_posix_ns); }

int latest_gps_minus_utc_s() { return aiding::latest_gps_minus_utc_s(); }

std::optional<std::int64_t> gps_from_utc_ns(TimeNs utc_posix_ns, std::optional<int> gps_minus_utc) {
  const std::int64_t leap_ns = std::int64_t{gps_minus_utc.value_or(gps_minus_utc_s(utc_posix_ns))} * kNsPerSecond64;
  std::int64_t gps_ns = 0;
  if (__builtin_sub_overflow(utc_posix_ns, kGpsEpochPosixSeconds * kNsPerSecond64, &gps_ns) ||
      __builtin_add_overflow(gps_ns, leap_ns, &gps_ns) || gps_ns < 0)
    return std::nullopt;
  return gps_ns;
}

std::optional<TimeNs> utc_from_gps_ns(std::int64_t gps_ns, std::optional<int> gps_minus_utc) {
  int leap = 0;
  if (gps_minus_utc) {
    leap = *gps_minus_utc;
  } else {
    for (std::size_t i = 0; i < kLeapSecondStartsPosix.size(); ++i) {
      // The leap second itself (GPS second gps_start_s(i) - 1) still takes
      // the old offset: it maps onto the new day's 00:00:00, which the
      // first second of the new offset then maps onto again (POSIX repeats
      // a number across a leap second). Every POSIX time round-trips.
      if (gps_ns >= gps_start_s(i) * kNsPerSecond64) leap = static_cast<int>(i) + 1;
    }
  }
  TimeNs utc_ns = 0;
  if (__builtin_add_overflow(gps_ns, kGpsEpochPosixSeconds * kNsPerSecond64, &utc_ns) ||
      __builtin_sub_overflow(utc_ns, std::int64_t{leap} * kNsPerSecond64, &utc_ns))
    return std::nullopt;
  return utc_ns;
}


}  // namespace imuemu::drivers::gps_time
