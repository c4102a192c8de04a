// The navigation fields of a device's frame (drivers::ImuFrameInput: WGS84
// position, NED velocity, attitude relative to NED) from a sample's
// kinematics. One function for the engine's producer and the batch outputs
// of `imuemu generate` (--gnss-out, --baro-out), so the fixes a file holds are
// the ones the device would have sent.
#pragma once

#include "core/trajectory.hpp"
#include "core/types.hpp"
#include "drivers/protocol.hpp"

namespace imuemu::device {

// In an ecef scene: Eq. 1.1 inverse for the geodetic position, v^n = R_l^e^T v^e
// and R_s^n = R_l^e^T R_s^e with Eq. 1.5 at the sample's own position; the
// frame's has_navigation is set. A flat scene's positions have no geodetic
// anchor: the position fields stay unset (has_navigation false), and its
// attitude is already R_s^n (a VectorNav's attitude outputs, issue 29).
void set_frame_navigation(const Kinematics& k, Physics physics, drivers::ImuFrameInput& frame);

}  // namespace imuemu::device
