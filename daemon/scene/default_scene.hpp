// The scene imuemud runs when started without a scene file: config/default.toml,
// embedded in the binary (tests/scene/test_scene_config.cpp checks the two are
// byte for byte the same).
#pragma once

#include <string_view>

#include "daemon/scene/scene_config.hpp"

namespace imuemu::scene {

// The TOML text of config/default.toml.
std::string_view default_scene_toml();
// Name used for the embedded scene in messages.
inline constexpr std::string_view kDefaultSceneName = "<built-in config/default.toml>";
// The parsed default scene (it has no relative paths, so no base directory).
SceneConfig default_scene();

}  // namespace imuemu::scene
