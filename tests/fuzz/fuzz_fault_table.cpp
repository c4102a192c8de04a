// libFuzzer target: the fault keys of one [[imu]] table ([[imu.fault]] and
// [imu.random_faults], daemon/scene/fault_config.hpp) through the parser
// and, when accepted, through the device's fault timeline (core/fault/).
// Whatever the bytes: a refusal is a SceneError with a message; an accepted
// table builds a timeline, and on inputs within the part's range every
// output sample is finite and within the range (issue 26, N11: bias steps
// summed to 7.7e6 rad/s on a +-2000 deg/s part), its increments within
// range x period, with the saturated flag wherever a fault took a value
// there.
// Input: byte 0 chooses the output rate (bits 0-1) and whether the device
// has the ICM-42688-P's ranges or the defaults (bit 2); the rest is the TOML
// text of the [[imu]] table's body.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <string_view>

#include "core/fault/timeline.hpp"
#include "core/sensor/datasheet.hpp"
#include "daemon/scene/fault_config.hpp"
#include "tests/fuzz/scene_input.hpp"

namespace {

using namespace imuemu;

constexpr std::int64_t kRates[4] = {10, 100, 400, 1000};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  const std::int64_t rate = kRates[data[0] & 3u];
  const bool icm = (data[0] & 4u) != 0;
  const std::string_view text(reinterpret_cast<const char*>(data + 1), size - 1);
  const std::optional<toml::table> root = fuzz::toml_of(text);
  if (!root) return 0;
  scene::DeviceFaults faults;
  try {
    faults = scene::parse_device_faults(*root, fuzz::kFile, "imu[0]", "a", rate, 7);
  } catch (const scene::SceneError& e) {
    fuzz::check_refusal(e);
    return 0;
  }
  fault::TimelineOptions o;
  o.context = fault::device_context("a", rate, icm ? std::optional(sensor::preset_spec("icm42688p")) : std::nullopt);
  o.faults = std::move(faults.faults);
  o.random = std::move(faults.random);
  std::optional<fault::FaultTimeline> timeline;
  try {
    timeline.emplace(std::move(o));
  } catch (const std::invalid_argument&) {
    __builtin_trap();  // the parser accepted what the timeline refuses: they disagree
  }
  const fault::DeviceContext& c = timeline->context();
  const TimeNs period = kNsPerSecond / rate;
  const double h = static_cast<double>(period) * 1e-9;
  for (std::uint64_t k = 0; k < 600; ++k) {
    fault::SampleValues v;
    const double x = std::sin(0.01 * static_cast<double>(k));
    v.gyro_rad_s = Vec3(0.5, -0.3, 0.2) * x * c.gyro_range_rad_s;
    v.accel_m_s2 = Vec3(0.1, 0.2, -0.9) * c.accel_range_m_s2 * (0.5 + 0.5 * x);
    v.delta_theta_rad = v.gyro_rad_s * h;
    v.delta_velocity_m_s = v.accel_m_s2 * h;
    v.period_ns = period;
    const fault::SampleFaults f = timeline->step(k, static_cast<TimeNs>(k) * period, v);
    const double ranges[2] = {c.gyro_range_rad_s, c.accel_range_m_s2};
    const Vec3* rates[2] = {&v.gyro_rad_s, &v.accel_m_s2};
    const Vec3* increments[2] = {&v.delta_theta_rad, &v.delta_velocity_m_s};
    for (int t = 0; t < 2; ++t)
      for (int a = 0; a < 3; ++a) {
        const double r = (*rates[t])[a], i = (*increments[t])[a];
        if (!std::isfinite(r) || !std::isfinite(i)) __builtin_trap();
        if (std::abs(r) > ranges[t] || std::abs(i) > ranges[t] * h * (1.0 + 1e-12)) __builtin_trap();
      }
    (void)f;
  }
  return 0;
}
