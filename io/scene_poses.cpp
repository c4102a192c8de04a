#include "io/scene_poses.hpp"

#include <numbers>
#include <optional>

#include "core/attitude.hpp"
#include "core/earth.hpp"
#include "core/so3.hpp"

namespace imuemu::io {
namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;

struct EcefPose {
  Vec3 x_e;
  Mat3 R_b_e;
};

earth::Geodetic geodetic_of(const TrajectoryRecord& rec, const Vec3& x_e) {
  if (rec.position_kind == PositionKind::geodetic)
    return {rec.position.x() * kDegToRad, rec.position.y() * kDegToRad, rec.position.z()};
  return earth::geodetic_from_ecef(x_e);
}

Mat3 body_to_local(const TrajectoryRecord& rec) {
  if (rec.attitude_kind == AttitudeKind::heading_pitch_roll)
    return attitude::rotation_from_hpr(
        {rec.attitude[0] * kDegToRad, rec.attitude[1] * kDegToRad, rec.attitude[2] * kDegToRad});
  return attitude::rotation_from_quaternion(rec.attitude[0], rec.attitude[1], rec.attitude[2], rec.attitude[3]);
}

EcefPose to_ecef(const TrajectoryRecord& rec) {
  const Vec3 x_e = rec.position_kind == PositionKind::geodetic
                       ? earth::ecef_from_geodetic(geodetic_of(rec, Vec3::Zero()))
                       : rec.position;
  if (rec.attitude_kind == AttitudeKind::quaternion_ecef) return {x_e, body_to_local(rec)};
  const earth::Geodetic g = geodetic_of(rec, x_e);
  return {x_e, attitude::ned_to_ecef(g.latitude_rad, g.longitude_rad) * body_to_local(rec)};
}

}  // namespace

std::vector<Pose> poses_in_scene(const Trajectory& trajectory, Physics physics) {
  std::vector<Pose> poses;
  poses.reserve(trajectory.records.size());
  if (trajectory.position_kind == PositionKind::local_ned) {
    if (physics == Physics::ecef) {
      const auto& rec = trajectory.records.front();
      throw TrajectoryFormatError({trajectory.source, rec.line, "north_m", 0},
                                  "geodetic (lat_deg,lon_deg,h_m) or ECEF (x_m,y_m,z_m) positions for the ecef scene",
                                  "local north/east/down positions have no Earth origin");
    }
    for (const auto& rec : trajectory.records) {
      if (rec.attitude_kind == AttitudeKind::quaternion_ecef)
        throw TrajectoryFormatError({trajectory.source, rec.line, "qw", 0},
                                    "a body-to-NED attitude with local positions", "an ECEF attitude");
      poses.push_back({rec.t_ns, rec.position, body_to_local(rec)});
    }
    return poses;
  }
  std::optional<earth::LocalNed> tangent;
  for (const auto& rec : trajectory.records) {
    const EcefPose p = to_ecef(rec);
    if (physics == Physics::ecef) {
      poses.push_back({rec.t_ns, p.x_e, p.R_b_e});
      continue;
    }
    if (!tangent) tangent.emplace(geodetic_of(rec, p.x_e));
    poses.push_back({rec.t_ns, tangent->ned_from_ecef(p.x_e), tangent->R_n_to_e().transpose() * p.R_b_e});
  }
  return poses;
}

}  // namespace imuemu::io
