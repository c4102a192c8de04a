#include "daemon/device/frame_navigation.hpp"

#include "core/attitude.hpp"
#include "core/earth.hpp"

namespace imuemu::device {

void set_frame_navigation(const Kinematics& k, Physics physics, drivers::ImuFrameInput& frame) {
  if (physics != Physics::ecef) {
    frame.sensor_to_ned = k.attitude;
    return;
  }
  const earth::Geodetic g = earth::geodetic_from_ecef(k.position_m);
  frame.has_navigation = true;
  frame.latitude_rad = g.latitude_rad;
  frame.longitude_rad = g.longitude_rad;
  frame.height_m = g.height_m;
  const Mat3 R_n_e = attitude::ned_to_ecef(g.latitude_rad, g.longitude_rad);
  frame.velocity_ned_m_s = R_n_e.transpose() * k.velocity_m_s;
  frame.sensor_to_ned = R_n_e.transpose() * k.attitude;  // R_s^n = (R_n^e)^T R_s^e
}

}  // namespace imuemu::device
