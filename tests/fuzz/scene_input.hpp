// What the fuzz targets of the scene's table parsers share (fuzz_error_model,
// fuzz_fault_table, fuzz_scene): the input as a TOML table, and the rule
// every refusal must follow (a SceneError naming the file, with a message).
#pragma once

#include <optional>
#include <string>
#include <string_view>

#include <toml++/toml.h>

#include "daemon/scene/scene_config.hpp"

namespace imuemu::fuzz {

inline constexpr const char* kFile = "fuzz.toml";

// nullopt: not TOML (toml++'s own refusal, not the parser under test).
inline std::optional<toml::table> toml_of(std::string_view text) {
  try {
    return toml::parse(text, std::string_view(kFile));
  } catch (const toml::parse_error&) {
    return std::nullopt;
  }
}

inline void check_refusal(const scene::SceneError& e) {
  if (std::string(e.what()).empty() || e.file() != kFile) __builtin_trap();
}

}  // namespace imuemu::fuzz
