// Optional time derivatives a live pose input may carry beside the pose
// (a vehicle simulator knows its own velocity and body rate exactly): the
// pose datagram v2 (docs/pose-wire-format.md §2.5) and MAVLink
// HIL_STATE_QUATERNION (§4). In the scene frame once converted
// (io::ScenePoseConverter::convert_rates); the causal live method
// (core/causal_hermite.hpp) uses them as the end slopes of its Hermite cubics
// instead of estimating them from neighbouring poses.
#pragma once

#include <optional>

#include "core/types.hpp"

namespace imuemu {

struct PoseRates {
  std::optional<Vec3> velocity_m_s;        // d/dt position, frame axes
  std::optional<Vec3> angular_rate_rad_s;  // omega_{frame,b}^b: body rate relative to the frame, body axes
  std::optional<Vec3> acceleration_m_s2;   // d2/dt2 position, frame axes
  bool any() const noexcept { return velocity_m_s || angular_rate_rad_s || acceleration_m_s2; }
};

}  // namespace imuemu
