// Generated from config/default.toml; keep identical (tests/scene/test_scene_config.cpp
// compares them). To regenerate after editing config/default.toml, paste its
// text between the raw-string delimiters.
#include "daemon/scene/default_scene.hpp"

namespace imuemu::scene {

std::string_view default_scene_toml() {
  static constexpr std::string_view kText = R"imuemu_default(# imuemud's built-in scene: `imuemud` with no arguments runs exactly this
# text (embedded in the binary, daemon/scene/default_scene.cpp; a test keeps the two
# identical). No hardware and no root needed: the built-in aircraft-like
# flight near Barcelona (thesis Appendix C style, WGS84 ECEF physics) becomes
# a 400 Hz ideal IMU in imuemu's native protocol on a pseudo-terminal.
# Open /tmp/imuemu/ttyIMU0 like a serial port (e.g. with `imuemu listen`).
# Format: docs/scene-format.md.

[scene]
name = "default"
physics = "ecef"

[trajectory]
source = "sample:flight"
duration_s = 3600
knot_interval_s = 1.0
loop = true

[daemon]
control_socket = "/tmp/imuemu/default.sock"

[[imu]]
name = "imu0"
rate_hz = 400
protocol = "native"

[imu.transport]
type = "pty"
link = "/tmp/imuemu/ttyIMU0"
mode = 0o660
)imuemu_default";
  return kText;
}

SceneConfig default_scene() { return parse_scene_text(default_scene_toml(), std::string(kDefaultSceneName), "/"); }

}  // namespace imuemu::scene
