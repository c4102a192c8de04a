#include "core/earth.hpp"

#include <GeographicLib/Geocentric.hpp>
#include <GeographicLib/NormalGravity.hpp>
#include <algorithm>
#include <numbers>

#include "core/attitude.hpp"

namespace imuemu::earth {

namespace {

constexpr double kDegPerRad = 180.0 / std::numbers::pi;
constexpr double kRadPerDeg = std::numbers::pi / 180.0;

}  // namespace

Vec3 ecef_from_geodetic(const Geodetic& g) {
  // Eq. 1.1 via GeographicLib (degrees). pi/2 in radians may convert to
  // 90.00000000000001 deg, which GeographicLib rejects (NaN): clamp to the
  // pole, a change below 1e-16 rad.
  const double lat_deg = std::clamp(g.latitude_rad * kDegPerRad, -90.0, 90.0);
  const double lon_deg = g.longitude_rad * kDegPerRad;
  Vec3 x;
  GeographicLib::Geocentric::WGS84().Forward(lat_deg, lon_deg, g.height_m, x.x(), x.y(), x.z());
  return x;
}

Geodetic geodetic_from_ecef(const Vec3& x_e_m) {
  // The inverse of Eq. 1.1 has no closed form in the thesis ("has to be
  // computed numerically"); GeographicLib's solution is exact to rounding.
  double lat_deg = 0.0, lon_deg = 0.0, h_m = 0.0;
  GeographicLib::Geocentric::WGS84().Reverse(x_e_m.x(), x_e_m.y(), x_e_m.z(), lat_deg, lon_deg,
                                             h_m);
  return Geodetic{lat_deg * kRadPerDeg, lon_deg * kRadPerDeg, h_m};
}

Vec3 normal_gravity_ecef(const Vec3& x_e_m) {
  // NormalGravity::U returns the gradient of gravitational + centrifugal
  // potential of the level ellipsoid, in the rotating ECEF frame.
  Vec3 g;
  GeographicLib::NormalGravity::WGS84().U(x_e_m.x(), x_e_m.y(), x_e_m.z(), g.x(), g.y(), g.z());
  return g;
}

LocalNed::LocalNed(const Geodetic& origin)
    : origin_e_(ecef_from_geodetic(origin)),
      R_n_e_(attitude::ned_to_ecef(origin.latitude_rad, origin.longitude_rad)) {}

Vec3 LocalNed::ned_from_ecef(const Vec3& x_e_m) const {
  // R_e^n = (R_l^e)^T at the origin (Eq. 1.5 is orthonormal).
  return R_n_e_.transpose() * (x_e_m - origin_e_);
}

Vec3 LocalNed::ecef_from_ned(const Vec3& ned_m) const { return origin_e_ + R_n_e_ * ned_m; }

}  // namespace imuemu::earth
