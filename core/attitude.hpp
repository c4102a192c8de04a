// Attitude parametrizations of thesis §1.3: heading-pitch-roll (Eq. 1.2,
// Tait-Bryan z-y-x, body FRD to local NED), quaternions (Eq. 1.3) and the
// local-level to ECEF rotation R_l^e (Eq. 1.5).
#pragma once

#include "core/types.hpp"

namespace imuemu::attitude {

struct HeadingPitchRoll {
  double heading_rad = 0.0;  // psi, about down; in (-pi, pi]
  double pitch_rad = 0.0;    // theta, about the once-rotated y; in [-pi/2, pi/2]
  double roll_rad = 0.0;     // gamma, about forward; in (-pi, pi]
};

// R_b^l = R_z(psi) R_y(theta) R_x(gamma)   (Eq. 1.2).
Mat3 rotation_from_hpr(const HeadingPitchRoll& hpr);

// Inverse of Eq. 1.2. At pitch = +-90 deg (gimbal lock) heading and roll are
// not separable; the whole rotation about the vertical is put into heading and
// roll is returned as 0, so rotation_from_hpr(hpr_from_rotation(R)) == R
// holds everywhere. Near the singularity the pitch comes from atan2 of the
// full column norm, so it is accurate even when |R(2,0)| rounds to 1.
HeadingPitchRoll hpr_from_rotation(const Mat3& R_b_l);

// R_b^l from a unit quaternion q = (q0, q1, q2, q3) = (w, x, y, z) of the
// thesis' Eq. 1.3 (which prints the transpose, R_l^b).
Mat3 rotation_from_quaternion(double q0, double q1, double q2, double q3);

// R_l^e (Eq. 1.5): local NED axes expressed in ECEF, at geodetic latitude and
// longitude. Well defined at the poles (north then depends on longitude).
Mat3 ned_to_ecef(double latitude_rad, double longitude_rad);

}  // namespace imuemu::attitude
