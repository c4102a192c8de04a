// GPS <-> UTC with the leap-second table; see gps_time.hpp.
#include "drivers/protocols/gps_time.hpp"

#include <array>

namespace imuemu::drivers::gps_time {

namespace {

constexpr std::int64_t kNsPerSecond64 = 1'000'000'000;

// IERS Bulletin C: the UTC days (00:00:00Z, POSIX seconds) from which
// GPS - UTC took each new value, one leap second at the end of the day
// before. GPS - UTC = index + 1 from that day on.
constexpr std::array<std::int64_t, 18> kLeapSecondStartsPosix = {
    362'793'600,    // 1981-07-01: 1 s
    394'329'600,    // 1982-07-01: 2
    425'865'600,    // 1983-07-01: 3
    489'024'000,    // 1985-07-01: 4
    567'993'600,    // 1988-01-01: 5
    631'152'000,    // 1990-01-01: 6
    662'688'000,    // 1991-01-01: 7
    709'948'800,    // 1992-07-01: 8
    741'484'800,    // 1993-07-01: 9
    773'020'800,    // 1994-07-01: 10
    820'454'400,    // 1996-01-01: 11
    867'715'200,    // 1997-07-01: 12
    915'148'800,    // 1999-01-01: 13
    1'136'073'600,  // 2006-01-01: 14
    1'230'768'000,  // 2009-01-01: 15
    1'341'100'800,  // 2012-07-01: 16
    1'435'708'800,  // 2015-07-01: 17
    1'483'228'800,  // 2017-01-01: 18
};

// GPS seconds at which each new value applies: the UTC day start, moved to
// the GPS scale with the new offset.
constexpr std::int64_t gps_start_s(std::size_t i) {
  return kLeapSecondStartsPosix[i] - kGpsEpochPosixSeconds + static_cast<std::int64_t>(i) + 1;
}

}  // namespace

int gps_minus_utc_s(TimeNs utc_posix_ns) {
  int leap = 0;
  for (std::size_t i = 0; i < kLeapSecondStartsPosix.size(); ++i) {
    // floor division: a time before the day start (even by 1 ns) is before it
    if (utc_posix_ns >= kLeapSecondStartsPosix[i] * kNsPerSecond64) leap = static_cast<int>(i) + 1;
  }
  return leap;
}

int latest_gps_minus_utc_s() { return static_cast<int>(kLeapSecondStartsPosix.size()); }

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

UtcCalendar calendar_from_posix_ns(TimeNs utc_posix_ns) {
  // Floor division into days and the time of day, then the civil date of a
  // day count (H. Hinnant, "chrono-Compatible Low-Level Date Algorithms",
  // civil_from_days: eras of 400 years starting 0000-03-01).
  constexpr std::int64_t kNsPerDay = 86'400LL * kNsPerSecond64;
  std::int64_t days = utc_posix_ns / kNsPerDay;
  std::int64_t of_day = utc_posix_ns % kNsPerDay;
  if (of_day < 0) {
    of_day += kNsPerDay;
    --days;
  }
  UtcCalendar c;
  c.nanosecond = of_day % kNsPerSecond64;
  const std::int64_t seconds = of_day / kNsPerSecond64;
  c.hour = static_cast<int>(seconds / 3600);
  c.minute = static_cast<int>(seconds / 60 % 60);
  c.second = static_cast<int>(seconds % 60);
  const std::int64_t z = days + 719'468;
  const std::int64_t era = (z >= 0 ? z : z - 146'096) / 146'097;
  const std::int64_t doe = z - era * 146'097;                                  // [0, 146096]
  const std::int64_t yoe = (doe - doe / 1460 + doe / 36'524 - doe / 146'096) / 365;  // [0, 399]
  const std::int64_t doy = doe - (365 * yoe + yoe / 4 - yoe / 100);              // [0, 365]
  const std::int64_t mp = (5 * doy + 2) / 153;                                  // [0, 11], March = 0
  c.day = static_cast<int>(doy - (153 * mp + 2) / 5 + 1);
  c.month = static_cast<int>(mp < 10 ? mp + 3 : mp - 9);
  c.year = static_cast<int>(yoe + era * 400 + (c.month <= 2 ? 1 : 0));
  return c;
}

}  // namespace imuemu::drivers::gps_time
