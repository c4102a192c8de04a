// Turns trajectory records, as read from a file, into poses in a scene's frame.
#pragma once

#include <vector>

#include "core/imu_model.hpp"
#include "io/trajectory_csv.hpp"

namespace imuemu::io {

// ecef scene: geodetic positions go through Eq. 1.1, attitudes R_b^l become
//   R_b^e = R_l^e(lat, lon) R_b^l (Eq. 1.4, 1.5) at each record's own position.
// flat scene: local NED positions are used as they are (attitude R_b^n = R_b^l);
//   geodetic/ECEF positions are expressed in the NED tangent frame of the
//   first record, and attitudes rotated into that fixed frame.
// Throws TrajectoryFormatError (naming the file and line) for combinations
// that have no meaning, e.g. local NED positions in the ecef scene.
std::vector<Pose> poses_in_scene(const Trajectory& trajectory, Physics physics);

}  // namespace imuemu::io
