// Bound checks of the settings the core takes (core/setting_error.hpp).
#include "core/setting_error.hpp"

#include <cmath>
#include <cstdio>

namespace imuemu {

std::string setting_number(double value) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.6g", value);
  return buffer;
}

namespace {

// (Strings built by appending: GCC 12's -Wrestrict misfires on
// "literal" + std::string.)
[[noreturn]] void refuse(const std::string& key, const std::string& label, double value, const std::string& range,
                         const SettingBound& bound) {
  std::string what = label;
  what.append(1, ' ').append(setting_number(value));
  if (*bound.unit != '\0') what.append(1, ' ').append(bound.unit);
  what.append(" is not in ").append(range);
  if (*bound.unit != '\0') what.append(1, ' ').append(bound.unit);
  if (*bound.why != '\0') what.append(" (").append(bound.why).append(1, ')');
  throw SettingError(key, what);
}

std::string interval(double lo, double hi) {
  std::string s(1, '[');
  s.append(setting_number(lo)).append(", ").append(setting_number(hi)).append(1, ']');
  return s;
}

std::string closed(const SettingBound& b) { return interval(b.lo, b.hi); }

std::string axis(const std::string& label, int i) {
  std::string s = label;
  s.append(" (").append(1, "xyz"[i]).append(1, ')');
  return s;
}

}  // namespace

void require_within(const std::string& key, const std::string& label, double value, const SettingBound& bound) {
  if (!(value >= bound.lo && value <= bound.hi)) refuse(key, label, value, closed(bound), bound);
}

void require_within(const std::string& key, const std::string& label, const Vec3& v, const SettingBound& bound) {
  for (int i = 0; i < 3; ++i)
    if (!(v[i] >= bound.lo && v[i] <= bound.hi))
      refuse(key, axis(label, i), v[i], closed(bound), bound);
}

void require_magnitude(const std::string& key, const std::string& label, double value, const SettingBound& bound) {
  if (!(std::abs(value) <= bound.hi))
    refuse(key, label, value, interval(-bound.hi, bound.hi), bound);
}

void require_magnitude(const std::string& key, const std::string& label, const Vec3& v, const SettingBound& bound) {
  for (int i = 0; i < 3; ++i)
    if (!(std::abs(v[i]) <= bound.hi))
      refuse(key, axis(label, i), v[i], interval(-bound.hi, bound.hi), bound);
}

}  // namespace imuemu
