// GPS time from UTC and back, with the leap seconds explicit (internal to
// drivers/protocols: the MIP GPS timestamp field needs it).
//
// GPS time: ns since the GPS epoch 1980-01-06T00:00:00 UTC, a continuous
// scale without leap seconds (IS-GPS-200). UTC is taken as POSIX time: ns
// since 1970-01-01T00:00:00Z with every day 86400 s long, so a POSIX time
// repeats during a positive leap second (23:59:60 has no number of its own;
// the second after it is the first second of the new GPS-UTC offset).
//   gps_ns = utc_posix_ns - 315964800 s + (GPS - UTC)(utc)
// GPS - UTC is 0 s at the GPS epoch and one more second after each leap
// second (IERS Bulletin C): 18 s since 2017-01-01. The table below ends
// there; a leap second announced later must be added to it, or given
// explicitly with the gps_minus_utc_s option.
#pragma once

#include <cstdint>
#include <optional>

#include "core/aiding/calendar.hpp"
#include "core/aiding/gnss_time.hpp"
#include "core/types.hpp"

namespace imuemu::drivers::gps_time {

using aiding::kGpsEpochPosixSeconds;  // 1980-01-06T00:00:00Z

// GPS - UTC (s) at a UTC instant (POSIX ns): the table's value for the last
// leap second at or before it (0 before 1981-07-01).
int gps_minus_utc_s(TimeNs utc_posix_ns);
// The last entry of the table: 18 (2017-01-01).
int latest_gps_minus_utc_s();

// UTC (POSIX ns) -> GPS ns. GPS - UTC from the table, or `gps_minus_utc_s`
// when given (a fixed offset). Nothing for times before the GPS epoch or on
// overflow.
std::optional<std::int64_t> gps_from_utc_ns(TimeNs utc_posix_ns, std::optional<int> gps_minus_utc_s = std::nullopt);
// The inverse: GPS ns -> UTC (POSIX ns). During a leap second (GPS time
// that falls on 23:59:60) the result is the POSIX time of the second after
// it (00:00:00), which POSIX then repeats. Nothing on overflow.
std::optional<TimeNs> utc_from_gps_ns(std::int64_t gps_ns, std::optional<int> gps_minus_utc_s = std::nullopt);

// A POSIX UTC instant as a proleptic Gregorian date and time of day
// (NMEA RMC/ZDA, UBX NAV-PVT); every day 86400 s (a leap second shows as
// the next day's 00:00:00, as POSIX has it).
// (core/aiding/calendar.hpp: the one implementation.)
using aiding::UtcCalendar;
inline UtcCalendar calendar_from_posix_ns(TimeNs utc_posix_ns) { return aiding::calendar_from_posix_ns(utc_posix_ns); }

}  // namespace imuemu::drivers::gps_time
