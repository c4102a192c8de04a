// The civil calendar on POSIX time; see calendar.hpp.
#include "core/aiding/calendar.hpp"

#include <stdexcept>
#include <string>

#include "core/time_arith.hpp"

namespace imuemu::aiding {

namespace {

constexpr std::int64_t kNsPerDay = 86'400LL * kNsPerSecond;
constexpr std::int64_t kDaysPerEra = 146'097;       // 400 Gregorian years
constexpr std::int64_t kDaysTo1970FromMarch0 = 719'468;  // 0000-03-01 .. 1970-01-01

std::int64_t floor_div(std::int64_t a, std::int64_t b) noexcept {
  std::int64_t q = a / b;
  if ((a % b != 0) && ((a < 0) != (b < 0))) --q;
  return q;
}

int days_in_month(int year, int month) noexcept {
  static constexpr int kDays[] = {31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31};
  return month == 2 && is_leap_year(year) ? 29 : kDays[month - 1];
}

}  // namespace

bool is_leap_year(int year) noexcept { return (year % 4 == 0 && year % 100 != 0) || year % 400 == 0; }

std::int64_t days_from_civil(int year, int month, int day) noexcept {
  const std::int64_t y = std::int64_t{year} - (month <= 2 ? 1 : 0);  // years start in March
  const std::int64_t era = floor_div(y, 400);
  const std::int64_t yoe = y - era * 400;                                          // [0, 399]
  const std::int64_t mp = month > 2 ? month - 3 : month + 9;                       // March = 0
  const std::int64_t doy = (153 * mp + 2) / 5 + day - 1;                           // [0, 365]
  const std::int64_t doe = 365 * yoe + yoe / 4 - yoe / 100 + doy;                  // [0, 146096]
  return era * kDaysPerEra + doe - kDaysTo1970FromMarch0;
}

UtcCalendar calendar_from_posix_ns(TimeNs utc_posix_ns) noexcept {
  const std::int64_t days = floor_div(utc_posix_ns, kNsPerDay);
  const std::int64_t of_day = utc_posix_ns - days * kNsPerDay;  // [0, kNsPerDay): no overflow
  UtcCalendar c;
  c.nanosecond = of_day % kNsPerSecond;
  const std::int64_t s = of_day / kNsPerSecond;
  c.hour = static_cast<int>(s / 3600);
  c.minute = static_cast<int>(s / 60 % 60);
  c.second = static_cast<int>(s % 60);
  const std::int64_t z = days + kDaysTo1970FromMarch0;
  const std::int64_t era = floor_div(z, kDaysPerEra);
  const std::int64_t doe = z - era * kDaysPerEra;
  const std::int64_t yoe = (doe - doe / 1460 + doe / 36'524 - doe / 146'096) / 365;
  const std::int64_t doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
  const std::int64_t mp = (5 * doy + 2) / 153;
  c.day = static_cast<int>(doy - (153 * mp + 2) / 5 + 1);
  c.month = static_cast<int>(mp < 10 ? mp + 3 : mp - 9);
  c.year = static_cast<int>(yoe + era * 400 + (c.month <= 2 ? 1 : 0));
  return c;
}

TimeNs posix_ns_from_calendar(const UtcCalendar& c) {
  auto need = [](bool ok, const char* field, std::int64_t v) {
    if (!ok) throw std::invalid_argument(std::string("calendar: ") + field + " " + std::to_string(v) + " is out of range");
  };
  need(c.month >= 1 && c.month <= 12, "month", c.month);
  need(c.day >= 1 && c.day <= days_in_month(c.year, c.month), "day", c.day);
  need(c.hour >= 0 && c.hour <= 23, "hour", c.hour);
  need(c.minute >= 0 && c.minute <= 59, "minute", c.minute);
  need(c.second >= 0 && c.second <= 59, "second", c.second);
  need(c.nanosecond >= 0 && c.nanosecond < kNsPerSecond, "nanosecond", c.nanosecond);
  const std::int64_t s_of_day = std::int64_t{c.hour} * 3600 + std::int64_t{c.minute} * 60 + c.second;
  const auto day_ns = checked_mul_ns(days_from_civil(c.year, c.month, c.day), kNsPerDay);
  const auto with_s = day_ns ? checked_add_ns(*day_ns, s_of_day * kNsPerSecond) : std::nullopt;
  const auto t = with_s ? checked_add_ns(*with_s, c.nanosecond) : std::nullopt;
  if (!t) throw std::invalid_argument("calendar: year " + std::to_string(c.year) + " is beyond int64 ns of POSIX time");
  return *t;
}

double decimal_year_from_posix_ns(TimeNs utc_posix_ns) noexcept {
  const UtcCalendar c = calendar_from_posix_ns(utc_posix_ns);
  const std::int64_t start_day = days_from_civil(c.year, 1, 1);
  const std::int64_t length_days = is_leap_year(c.year) ? 366 : 365;
  // Within the year: whole days plus the time of day, in ns (< 2^55, exact enough in double).
  const std::int64_t into_ns =
      (floor_div(utc_posix_ns, kNsPerDay) - start_day) * kNsPerDay + (utc_posix_ns - floor_div(utc_posix_ns, kNsPerDay) * kNsPerDay);
  return static_cast<double>(c.year) + static_cast<double>(into_ns) / static_cast<double>(length_days * kNsPerDay);
}

}  // namespace imuemu::aiding
