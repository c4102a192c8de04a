// WGS84 Earth for the ecef scene: geodetic <-> ECEF (Eq. 1.1 and its inverse),
// normal gravity including the centrifugal term, and the Earth rotation rate,
// all through GeographicLib (its constants are the WGS84 defining ones).
#pragma once

#include "core/types.hpp"

namespace imuemu::earth {

// WGS84 angular velocity of the Earth, omega_ie (rad/s).
inline constexpr double kRotationRate_rad_s = 7.292115e-5;
// omega_ie^e = (0, 0, omega_ie).
inline Vec3 rotation_rate_ecef() { return Vec3(0.0, 0.0, kRotationRate_rad_s); }

struct Geodetic {
  double latitude_rad = 0.0;
  double longitude_rad = 0.0;
  double height_m = 0.0;  // above the ellipsoid
};

// Eq. 1.1.
Vec3 ecef_from_geodetic(const Geodetic& g);
// Inverse of Eq. 1.1 (GeographicLib's closed-form solution, accurate to a few
// nm everywhere including the poles and the Earth's centre region).
Geodetic geodetic_from_ecef(const Vec3& x_e_m);

// Normal gravity g^e(x^e) of the WGS84 ellipsoid in the rotating ECEF frame:
// gravitation plus the centrifugal acceleration (GeographicLib NormalGravity),
// i.e. what a plumb line feels. Units m/s^2.
Vec3 normal_gravity_ecef(const Vec3& x_e_m);

// Conventional standard gravity, for the flat scene's default vector.
inline constexpr double kStandardGravity_m_s2 = 9.80665;

// A local North-East-Down tangent frame anchored at a geodetic origin, for the
// flat scene when the input is geodetic or ECEF: position in the tangent frame
// and the fixed rotation R_e^n at the origin.
class LocalNed {
 public:
  explicit LocalNed(const Geodetic& origin);
  Vec3 ned_from_ecef(const Vec3& x_e_m) const;
  Vec3 ecef_from_ned(const Vec3& ned_m) const;
  const Mat3& R_n_to_e() const { return R_n_e_; }  // R_l^e at the origin
  const Vec3& origin_ecef_m() const { return origin_e_; }

 private:
  Vec3 origin_e_;
  Mat3 R_n_e_;
};

}  // namespace imuemu::earth
