// `imuemu sensors`: the sensor-model presets (core/sensor/datasheet.hpp), each
// term with its discrete sigma at a rate, and the datasheet it comes from.
#include <cstdio>
#include <iostream>

#include "core/sensor/datasheet.hpp"
#include "daemon/cli/commands.hpp"
#include "daemon/scene/error_model_config.hpp"

namespace imuemu::cli {

const char* const kSensorOptionHelp =
    "Sensor error model: ideal, a preset (icm42688p, adis16470, stim300, hg9900; `imuemu sensors` lists them) or a "
    "TOML file (docs/sensor-models.md). White noise density N is IEEE Std 952's: Allan deviation N/sqrt(tau), "
    "discrete sigma = N*sqrt(fs) at the rate the noise is generated (1 deg/sqrt(h) = 1/60 deg/s/sqrt(Hz))";

int sensors(double rate_hz) {
  std::cout << "# Sensor-model presets (docs/sensor-models.md). Convention: white noise density N as IEEE Std 952\n"
               "# defines it (Allan deviation N/sqrt(tau)); discrete sigma = N sqrt(fs) at the rate the noise is\n"
               "# generated. Bias instability B: Allan floor 0.664 B over the configured tau range.\n"
               "# Discrete values below at "
            << rate_hz << " Hz (--rate).\n";
  for (const sensor::Preset& p : sensor::presets()) {
    std::cout << "\n" << p.name << ": " << p.description << "\n  source: " << p.source << "\n  keys:";
    for (const sensor::PresetEntry& e : p.entries) {
      std::cout << " " << (e.triad == sensor::Triad::gyro ? "gyro." : "accel.") << e.key << "=";
      for (std::size_t i = 0; i < e.values.size(); ++i) std::cout << (i ? "," : "") << e.values[i];
    }
    std::cout << "\n";
    scene::ErrorModelConfig m;
    m.preset = p.name;
    m.spec = sensor::preset_spec(p.name);
    for (const std::string& line : scene::error_model_lines(m, rate_hz)) std::cout << "  " << line << "\n";
  }
  return kOk;
}

}  // namespace imuemu::cli
