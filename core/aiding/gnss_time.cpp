// GPS time, UTC and the leap-second table; see gnss_time.hpp.
#include "core/aiding/gnss_time.hpp"

#include <array>
#include <stdexcept>
#include <string>

#include "core/time_arith.hpp"

namespace imuemu::aiding {

namespace {


// The GPS second at which value i + 1 applies (the UTC day start with the new offset).
constexpr std::int64_t gps_start_s(std::size_t i) {
  return kLeapSecondStartsPosix[i] - kGpsEpochPosixSeconds + static_cast<std::int64_t>(i) + 1;
}

[[noreturn]] void refuse(const std::string& what) { throw std::invalid_argument("GPS time: " + what); }

}  // namespace

int gps_minus_utc_s(TimeNs utc_posix_ns) noexcept {
  int leap = 0;
  for (std::size_t i = 0; i < kLeapSecondStartsPosix.size(); ++i)
    if (utc_posix_ns / kNsPerSecond >= kLeapSecondStartsPosix[i] && utc_posix_ns >= 0) leap = static_cast<int>(i) + 1;
  return leap;
}

int gps_minus_utc_at_gps_s(TimeNs gps_ns) noexcept {
  int leap = 0;
  for (std::size_t i = 0; i < kLeapSecondStartsPosix.size(); ++i)
    if (gps_ns >= 0 && gps_ns / kNsPerSecond >= gps_start_s(i)) leap = static_cast<int>(i) + 1;
  return leap;
}

int latest_gps_minus_utc_s() noexcept { return static_cast<int>(kLeapSecondStartsPosix.size()); }

TimeNs gps_from_utc_ns(TimeNs utc_posix_ns, std::optional<int> fixed) {
  const int leap = fixed.value_or(gps_minus_utc_s(utc_posix_ns));
  const auto since = checked_sub_ns(utc_posix_ns, kGpsEpochPosixSeconds * kNsPerSecond);
  const auto gps = since ? checked_add_ns(*since, std::int64_t{leap} * kNsPerSecond) : std::nullopt;
  if (!gps || *gps < 0) refuse("UTC " + std::to_string(utc_posix_ns) + " ns is before the GPS epoch 1980-01-06");
  return *gps;
}

TimeNs utc_from_gps_ns(TimeNs gps_ns, std::optional<int> fixed) {
  if (gps_ns < 0) refuse("a GPS time before 1980-01-06 (" + std::to_string(gps_ns) + " ns)");
  const int leap = fixed.value_or(gps_minus_utc_at_gps_s(gps_ns));
  const auto posix = checked_add_ns(gps_ns, kGpsEpochPosixSeconds * kNsPerSecond);
  const auto utc = posix ? checked_sub_ns(*posix, std::int64_t{leap} * kNsPerSecond) : std::nullopt;
  if (!utc) refuse("GPS time " + std::to_string(gps_ns) + " ns is beyond int64 ns of UTC");
  return *utc;
}

UtcCalendar utc_calendar_from_gps_ns(TimeNs gps_ns) {
  const TimeNs utc = utc_from_gps_ns(gps_ns);
  // Inside a leap second (the GPS second before gps_start_s(i)) UTC reads
  // 23:59:60 of the day before the new offset.
  for (std::size_t i = 0; i < kLeapSecondStartsPosix.size(); ++i) {
    if (gps_ns / kNsPerSecond == gps_start_s(i) - 1) {
      UtcCalendar c = calendar_from_posix_ns(utc - kNsPerSecond);
      c.second = 60;
      return c;
    }
  }
  return calendar_from_posix_ns(utc);
}

GpsWeekTime gps_week_time(TimeNs gps_ns) {
  if (gps_ns < 0) refuse("a GPS time before 1980-01-06 has no week (" + std::to_string(gps_ns) + " ns)");
  GpsWeekTime w;
  w.week = gps_ns / kNsPerWeek;
  w.time_of_week_ns = gps_ns % kNsPerWeek;
  w.week_mod_1024 = static_cast<int>(w.week % 1024);
  return w;
}

TimeNs gps_ns_from_week_time(std::int64_t week, TimeNs time_of_week_ns) {
  if (week < 0) refuse("negative week " + std::to_string(week));
  if (time_of_week_ns < 0 || time_of_week_ns >= kNsPerWeek)
    refuse("time of week " + std::to_string(time_of_week_ns) + " ns is not in [0, 604800 s)");
  const auto w = checked_mul_ns(week, kNsPerWeek);
  const auto t = w ? checked_add_ns(*w, time_of_week_ns) : std::nullopt;
  if (!t) refuse("week " + std::to_string(week) + " is beyond int64 ns");
  return *t;
}

TimeNs gps_ns_at(TimeNs t_ns, TimeNs epoch_utc_posix_ns, std::optional<int> fixed) {
  const auto t = checked_add_ns(gps_from_utc_ns(epoch_utc_posix_ns, fixed), t_ns);
  if (!t || *t < 0) refuse("trajectory time " + std::to_string(t_ns) + " ns is outside GPS time from the epoch");
  return *t;
}

}  // namespace imuemu::aiding
