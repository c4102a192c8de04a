// Ideal IMU output from kinematics (thesis Eq. 3.70). A scene computes only the
// physics it needs:
//   flat: f^b = R_b^n^T (a^n - g^n),            omega_ib^b = omega_nb^b
//   ecef: f^b = R_b^e^T (a^e + 2 omega_ie^e x v^e - g^e(x^e)),
//         omega_ib^b = omega_eb^b + R_b^e^T omega_ie^e.
#pragma once

#include "core/trajectory.hpp"

namespace imuemu {

struct SceneModel {
  Physics physics = Physics::flat;
  // Gravity vector of the flat scene in its NED frame (m/s^2); ignored by ecef.
  Vec3 flat_gravity_m_s2 = Vec3(0.0, 0.0, 9.80665);
};

ImuSample imu_from_kinematics(const SceneModel& scene, const Kinematics& k);

// Gravity the scene applies at a position of its frame (m/s^2).
Vec3 scene_gravity(const SceneModel& scene, const Vec3& position_m);
// Frame rotation rate relative to inertial space, frame axes (zero for flat).
Vec3 scene_rotation_rate(const SceneModel& scene);

}  // namespace imuemu
