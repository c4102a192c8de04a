// libFuzzer target: a whole scene file (docs/scene-format.md) through the
// parser and, when accepted, through check-config's figures (no device is
// opened). Whatever the bytes: a refusal is a SceneError with a message; an
// accepted scene is one check_scene() computes (it throws only for a scene
// the parser would not have produced) with a finite CPU estimate.
// Input: the TOML text.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "daemon/scene/scene_check.hpp"
#include "daemon/scene/scene_config.hpp"
#include "tests/fuzz/scene_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace imuemu::scene;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  SceneConfig scene;
  try {
    scene = parse_scene_text(text, imuemu::fuzz::kFile, "/nonexistent-imuemu-fuzz");
  } catch (const SceneError& e) {
    imuemu::fuzz::check_refusal(e);
    return 0;
  }
  SceneCheck check;
  try {
    check = check_scene(scene);
  } catch (...) {
    __builtin_trap();  // accepted by the parser, refused by check-config: they disagree
  }
  if (!std::isfinite(check.total_cpu_fraction) || check.total_cpu_fraction < 0.0) __builtin_trap();
  (void)to_text(check);
  (void)to_json(check);
  return 0;
}
