#include "core/imu_model.hpp"

#include <Eigen/Geometry>

#include "core/earth.hpp"

namespace imuemu {

ImuSample imu_from_kinematics(const SceneModel& scene, const Kinematics& k) {
  ImuSample s;
  s.t_ns = k.t_ns;
  const Mat3& R = k.attitude;  // R_b^frame
  if (scene.physics == Physics::flat) {
    // Non-rotating frame: the accelerometer measures a - g and the gyro the
    // body rate itself.
    s.accel_m_s2 = R.transpose() * (k.acceleration_m_s2 - scene.flat_gravity_m_s2);
    s.gyro_rad_s = k.angular_rate_rad_s;
    return s;
  }
  // Eq. 3.70: f^b = R_e^b (a^e + 2 w_ie^e x v^e - g^e(x^e)),
  //           w_ib^b = w_eb^b + R_e^b w_ie^e.
  const Vec3 w_ie = earth::rotation_rate_ecef();
  s.accel_m_s2 = R.transpose() * (k.acceleration_m_s2 + 2.0 * w_ie.cross(k.velocity_m_s) -
                                  earth::normal_gravity_ecef(k.position_m));
  s.gyro_rad_s = k.angular_rate_rad_s + R.transpose() * w_ie;
  return s;
}

Vec3 scene_gravity(const SceneModel& scene, const Vec3& position_m) {
  if (scene.physics == Physics::flat) return scene.flat_gravity_m_s2;
  return earth::normal_gravity_ecef(position_m);
}

Vec3 scene_rotation_rate(const SceneModel& scene) {
  if (scene.physics == Physics::flat) return Vec3::Zero();
  return earth::rotation_rate_ecef();
}

}  // namespace imuemu
