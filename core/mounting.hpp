// Where a sensor sits on the body whose trajectory the scene gives.
//
// The trajectory describes a reference point of the body (its origin) with
// body axes forward-right-down (core/trajectory.hpp). An IMU mounted at lever
// arm l^b from that point, its own axes rotated by C_s^b (sensor axes -> body
// axes) from the body's, has the pose
//   p_s = p + R_b l^b,        R_s = R_b C_s^b,
// at every instant (a rigid body). Each emulated device smooths and
// differentiates THIS pose sequence, so its IMU output is the exact derivative
// of what the sensor point itself does: the centripetal and tangential terms
// of the lever arm (w x (w x l), w' x l) and the axis permutation of the
// mounting rotation come out of the same Eq. 3.68 / Eq. 3.70 path as the body
// motion, with no separate lever-arm formula that could disagree with it.
#pragma once

#include "core/trajectory.hpp"

namespace imuemu {

struct Mounting {
  // C_s^b: sensor axes expressed in body axes (v^b = C_s^b v^s). Identity:
  // the sensor's axes are the body's FRD axes.
  Mat3 sensor_to_body = Mat3::Identity();
  // Sensor point relative to the trajectory reference point, body FRD (m).
  Vec3 lever_arm_b_m = Vec3::Zero();
};

// The sensor's pose for a body pose: p + R_b l^b, R_b C_s^b (same time).
Pose sensor_pose(const Pose& body, const Mounting& mounting);

// Whether a matrix is a proper rotation to within tolerance
// (|C^T C - I| and |det C - 1| below it, max-norm).
bool is_rotation(const Mat3& C, double tolerance = 1e-9);

}  // namespace imuemu
