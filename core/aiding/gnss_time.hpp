// GPS time, UTC with its leap seconds, GPS week / time of week, from the
// trajectory's epoch (issue 28). Pure integer arithmetic on int64 ns
// through core/time_arith.hpp; core's counterpart of the drivers' MIP
// helper (drivers/protocols/gps_time.hpp, same definitions and table), so
// the GNSS models below the protocol room can use it.
//
// GPS time: ns since the GPS epoch 1980-01-06T00:00:00 UTC, continuous, no
// leap seconds (IS-GPS-200N §3.3.4: the week number counts weeks from that
// epoch, the time of week seconds from Saturday/Sunday midnight; the
// legacy navigation message carries the week modulo 1024, which rolled
// over on 1999-08-22 and 2019-04-07). UTC is POSIX time (ns since 1970,
// 86400 s a day), so it repeats a number across a positive leap second:
//     gps_ns = utc_posix_ns - 315964800 s + (GPS - UTC)(utc)
// GPS - UTC: 0 s at the GPS epoch, one more after each leap second (IERS
// Bulletin C), 18 s since 2017-01-01 (IERS Bulletin C 52..70: no leap
// second announced since). A later one must be added to the table, or given
// as a fixed gps_minus_utc_s.
//
// The trajectory's clock is a uniform scale (its t_ns are physical
// seconds), so it maps onto GPS time by one offset: gps(t) = gps(t0) + t,
// with gps(t0) from the UTC of the trajectory's epoch; UTC then follows
// from the table, and a leap second inside a run shows as 23:59:60.
#pragma once

#include <array>
#include <cstdint>
#include <optional>

#include "core/aiding/calendar.hpp"
#include "core/types.hpp"

namespace imuemu::aiding {

inline constexpr std::int64_t kGpsEpochPosixSeconds = 315'964'800;  // 1980-01-06T00:00:00Z

// The one leap-second table of the project (drivers/protocols/gps_time.hpp
// reads it too). IERS Bulletin C: the UTC days (00:00:00Z, POSIX seconds) from which
// GPS - UTC took each new value, after a leap second at the end of the day
// before: GPS - UTC = index + 1 from that day on.
inline constexpr std::array<std::int64_t, 18> kLeapSecondStartsPosix = {
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
inline constexpr std::int64_t kSecondsPerWeek = 604'800;
inline constexpr TimeNs kNsPerWeek = kSecondsPerWeek * kNsPerSecond;

// GPS - UTC (s) at a UTC instant (POSIX ns): the table's value for the last
// leap second at or before it (0 before 1981-07-01).
int gps_minus_utc_s(TimeNs utc_posix_ns) noexcept;
// GPS - UTC (s) at a GPS instant; during a leap second (23:59:60) the
// offset before it.
int gps_minus_utc_at_gps_s(TimeNs gps_ns) noexcept;
// The table's last entry: 18 (2017-01-01).
int latest_gps_minus_utc_s() noexcept;

// UTC (POSIX ns) -> GPS ns, with the table's offset or a fixed one. Throws
// std::invalid_argument for a time before the GPS epoch or beyond int64.
TimeNs gps_from_utc_ns(TimeNs utc_posix_ns, std::optional<int> gps_minus_utc_s = std::nullopt);
// GPS ns -> UTC (POSIX ns); during a leap second the POSIX time of the
// second after it (which POSIX then repeats). Throws for a negative GPS
// time or overflow.
TimeNs utc_from_gps_ns(TimeNs gps_ns, std::optional<int> gps_minus_utc_s = std::nullopt);
// The civil UTC date and time of a GPS instant, second = 60 during a leap
// second (what NMEA ZDA/RMC and UBX NAV-PVT show). Throws as utc_from_gps_ns.
UtcCalendar utc_calendar_from_gps_ns(TimeNs gps_ns);

struct GpsWeekTime {
  std::int64_t week = 0;      // full week number since 1980-01-06
  TimeNs time_of_week_ns = 0; // [0, 604800 s)
  int week_mod_1024 = 0;      // the legacy navigation message's 10-bit week
};
// Throws std::invalid_argument for a negative GPS time.
GpsWeekTime gps_week_time(TimeNs gps_ns);
// week * 604800 s + time of week; throws for a negative week, a time of
// week outside [0, 604800 s) or overflow.
TimeNs gps_ns_from_week_time(std::int64_t week, TimeNs time_of_week_ns);

// GPS time at trajectory time t_ns when t = 0 is the UTC instant
// epoch_utc_posix_ns: gps_from_utc_ns(epoch) + t. Throws as gps_from_utc_ns
// and for a sum beyond int64 or before the GPS epoch.
TimeNs gps_ns_at(TimeNs t_ns, TimeNs epoch_utc_posix_ns, std::optional<int> gps_minus_utc_s = std::nullopt);

}  // namespace imuemu::aiding
