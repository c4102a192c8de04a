// libFuzzer target: an error-model table (`imuemu generate --sensor
// FILE.toml`, a scene's [imu.error_model]: sensor terms, temperature, the
// signal chain and its vibration; daemon/scene/error_model_config.hpp)
// through the parser and, when it is accepted, through the chain it makes
// (issue 26: settings the parser called OK overflowed into NaN, zeros,
// INT64_MAX or huge allocations). Whatever the bytes: a refusal is a
// SceneError with a message, or, for a chain the output rate cannot run, an
// std::invalid_argument from resolve() or DeviceChain naming it; an accepted
// model at an accepted rate computes finite samples, increments and
// temperatures for every tick, and a stamp shift within
// kMaxCompensatedDelayS.
// Input: byte 0 chooses the output rate (bits 0-2) and the increment
// convention (bit 3); the rest is the TOML text.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <string_view>

#include "core/signal_chain/signal_chain.hpp"
#include "daemon/scene/error_model_config.hpp"
#include "tests/fuzz/scene_input.hpp"

namespace {

using namespace imuemu;

constexpr std::int64_t kRates[8] = {1, 10, 100, 200, 400, 1000, 2000, 8000};

bool finite(const Vec3& v) { return v.allFinite(); }

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  const std::int64_t rate = kRates[data[0] & 7u];
  const auto convention =
      (data[0] & 8u) != 0 ? signal_chain::IncrementConvention::compensated : signal_chain::IncrementConvention::raw;
  const std::string_view text(reinterpret_cast<const char*>(data + 1), size - 1);
  const std::optional<toml::table> root = fuzz::toml_of(text);
  if (!root) return 0;
  scene::ErrorModelConfig model;
  try {
    model = scene::parse_error_model_table(*root, fuzz::kFile, "");
  } catch (const scene::SceneError& e) {
    fuzz::check_refusal(e);
    return 0;
  }
  std::optional<signal_chain::DeviceChain> chain;
  try {
    chain.emplace(SceneModel{}, model.sensor(), model.chain, rate, "fuzz");
  } catch (const std::invalid_argument& e) {  // a chain this rate cannot run: refused at start, by name
    if (std::string(e.what()).empty()) __builtin_trap();
    return 0;
  }
  const signal_chain::ResolvedChain& c = chain->chain();
  if (c.compensate_delay && !(std::abs(c.group_delay_s) <= signal_chain::kMaxCompensatedDelayS)) __builtin_trap();
  // A level body turning slowly, at rest: every tick's output finite. The
  // heaviest accepted chains (200,000 components at 1024x) are built, not run.
  if (static_cast<double>(chain->random_components()) * c.oversampling > 2e6) return 0;
  Kinematics k;
  k.angular_rate_rad_s = Vec3(0.01, -0.02, 0.03);
  const ImuSample ideal = imu_from_kinematics(SceneModel{}, k);
  for (std::uint64_t tick = 0; tick < 4; ++tick) {
    const signal_chain::ChainOutput o = chain->step(tick, k, ideal, tick > 0 ? &k : nullptr, convention);
    if (!finite(o.gyro_rad_s) || !finite(o.accel_m_s2) || !finite(o.delta_theta_rad) ||
        !finite(o.delta_velocity_m_s) || !std::isfinite(o.temperature_c))
      __builtin_trap();
  }
  return 0;
}
