#include "core/mounting.hpp"

#include <cmath>

namespace imuemu {

Pose sensor_pose(const Pose& body, const Mounting& mounting) {
  Pose sensor;
  sensor.t_ns = body.t_ns;
  sensor.position_m = body.position_m + body.attitude * mounting.lever_arm_b_m;
  sensor.attitude = body.attitude * mounting.sensor_to_body;
  return sensor;
}

bool is_rotation(const Mat3& C, double tolerance) {
  if (!C.allFinite()) return false;
  const double orthogonality = (C.transpose() * C - Mat3::Identity()).cwiseAbs().maxCoeff();
  return orthogonality <= tolerance && std::abs(C.determinant() - 1.0) <= tolerance;
}

}  // namespace imuemu
