// A setting the core refuses (issue 26): a std::invalid_argument whose
// message says which setting, its value, the bound and why the bound is
// there, and whose key() says where the setting is inside the spec, as a
// dotted path of its fields ("sinusoid[0].frequency_hz", "stage[1].q",
// "random.psd[3]"). A parser that built the spec from a table (the scene's
// TOML, daemon/scene/) catches it, finds the table entry that key names
// and reports the core's message at that entry's file:line:column, so the
// scene parser, check-config and the core refuse with one message.
#pragma once

#include <stdexcept>
#include <string>
#include <utility>

#include "core/types.hpp"

namespace imuemu {

class SettingError : public std::invalid_argument {
 public:
  SettingError(std::string key, const std::string& message) : std::invalid_argument(message), key_(std::move(key)) {}
  const std::string& key() const noexcept { return key_; }

 private:
  std::string key_;
};

// A closed range [lo, hi] of one setting, in the unit the core holds it in,
// and the reason for it (the datasheet or physical limit it comes from).
struct SettingBound {
  double lo = 0.0, hi = 0.0;
  const char* unit = "";
  const char* why = "";
};

// Throws SettingError(key, "<label> <value> <unit> is not in [lo, hi] <unit>
// (<why>)") unless lo <= value <= hi (a NaN is never within).
void require_within(const std::string& key, const std::string& label, double value, const SettingBound& bound);
// The same for each component of v (label names the component: "label (y)").
void require_within(const std::string& key, const std::string& label, const Vec3& v, const SettingBound& bound);
// |v_i| <= bound.hi for each component (a signed amplitude or coefficient).
void require_magnitude(const std::string& key, const std::string& label, double value, const SettingBound& bound);
void require_magnitude(const std::string& key, const std::string& label, const Vec3& v, const SettingBound& bound);
// "%.6g" of a value, as the bound messages write numbers.
std::string setting_number(double value);

}  // namespace imuemu
