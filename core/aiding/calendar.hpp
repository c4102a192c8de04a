// The proleptic Gregorian calendar on POSIX time (issue 28): the civil date
// of an instant and back, and the decimal year the World Magnetic Model
// takes. POSIX time: ns since 1970-01-01T00:00:00Z, every day 86400 s (a
// leap second has no number of its own; core/aiding/gnss_time.hpp says how
// GPS time shows it). Pure integer arithmetic.
//
// Days from a civil date: count from 0000-03-01 so that the leap day ends
// each year, in eras of 400 years (146097 days): a year of era yoe starts
// 365 yoe + yoe/4 - yoe/100 days in, a month mp (March = 0) 153 mp + 2 / 5
// days into its year (the 31/30-day months repeat every 5 months = 153
// days). The same derivation as H. Hinnant, "chrono-Compatible Low-Level
// Date Algorithms" (days_from_civil / civil_from_days).
#pragma once

#include <cstdint>

#include "core/types.hpp"

namespace imuemu::aiding {

struct UtcCalendar {
  int year = 1970, month = 1, day = 1;  // month 1..12, day 1..31
  int hour = 0, minute = 0, second = 0; // second 0..59, or 60 during a leap second (gnss_time.hpp)
  std::int64_t nanosecond = 0;          // 0..999'999'999
};

// Days since 1970-01-01 of a civil date (no range check: any int year).
std::int64_t days_from_civil(int year, int month, int day) noexcept;
// The civil date and time of day of a POSIX instant (every int64 ns has one).
UtcCalendar calendar_from_posix_ns(TimeNs utc_posix_ns) noexcept;
// The POSIX instant of a civil date and time (second 0..59). Throws
// std::invalid_argument for a field out of its range (month 13, day 31 of
// a 30-day month, February 29 of a common year) or a result beyond int64 ns.
TimeNs posix_ns_from_calendar(const UtcCalendar& c);
// year + (t - start of year) / (length of that year), the WMM's time
// argument (its software: year + day of year / days in year).
double decimal_year_from_posix_ns(TimeNs utc_posix_ns) noexcept;
bool is_leap_year(int year) noexcept;

}  // namespace imuemu::aiding
