// The data that flows through the pipeline: poses in, kinematics in the
// middle, IMU samples out. All in the scene's navigation frame:
//   ecef scene: position x^e (m) in WGS84 ECEF, attitude R_b^e;
//   flat scene: position (m) in a fixed local North-East-Down frame, attitude R_b^n.
// Body axes are forward-right-down (FRD) everywhere (thesis §1.3).
#pragma once

#include <vector>

#include "core/types.hpp"

namespace imuemu {

// One knot of the input trajectory, already in the scene frame.
struct Pose {
  TimeNs t_ns = 0;
  Vec3 position_m = Vec3::Zero();
  Mat3 attitude = Mat3::Identity();  // R_b^frame
};

// A smoothed state with its time derivatives, as the IMU equations need it.
struct Kinematics {
  TimeNs t_ns = 0;
  Vec3 position_m = Vec3::Zero();
  Vec3 velocity_m_s = Vec3::Zero();          // d/dt position, frame axes
  Vec3 acceleration_m_s2 = Vec3::Zero();     // d2/dt2 position, frame axes
  Mat3 attitude = Mat3::Identity();          // R_b^frame
  Vec3 angular_rate_rad_s = Vec3::Zero();    // omega_{frame,b}^b: body rate relative to the frame
};

// What an ideal IMU measures (thesis Eq. 3.70), body FRD axes.
struct ImuSample {
  TimeNs t_ns = 0;
  Vec3 gyro_rad_s = Vec3::Zero();    // omega_ib^b
  Vec3 accel_m_s2 = Vec3::Zero();    // specific force f^b
};

enum class Physics {
  flat,  // non-rotating local NED frame, constant gravity vector, no Earth rate
  ecef,  // rotating WGS84 ECEF: Earth rate, Coriolis, normal gravity
};

}  // namespace imuemu
