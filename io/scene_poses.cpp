#include "io/scene_poses.hpp"

#include <numbers>

#include "core/attitude.hpp"
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

Pose ScenePoseConverter::convert(const TrajectoryRecord& rec, const std::string& source) {
  if (rec.position_kind == PositionKind::local_ned) {
    if (physics_ == Physics::ecef) {
      throw TrajectoryFormatError({source, rec.line, "north_m", 0},
                                  "geodetic (lat_deg,lon_deg,h_m) or ECEF (x_m,y_m,z_m) positions for the ecef scene",
                                  "local north/east/down positions have no Earth origin");
    }
    if (rec.attitude_kind == AttitudeKind::quaternion_ecef)
      throw TrajectoryFormatError({source, rec.line, "qw", 0}, "a body-to-NED attitude with local positions",
                                  "an ECEF attitude");
    if (input_frame_ == InputFrame::earth_fixed)
      throw TrajectoryFormatError({source, rec.line, "north_m", 0},
                                  "Earth-fixed positions like the records before",
                                  "a local north/east/down position after Earth-fixed (geodetic or ECEF) ones: "
                                  "the two have no common frame");
    input_frame_ = InputFrame::local_ned;
    return {rec.t_ns, rec.position, body_to_local(rec)};
  }
  if (physics_ == Physics::flat && input_frame_ == InputFrame::local_ned)
    throw TrajectoryFormatError({source, rec.line, "", 0}, "local north/east/down positions like the records before",
                                "an Earth-fixed (geodetic or ECEF) position after local north/east/down ones: "
                                "the two have no common frame");
  const EcefPose p = to_ecef(rec);
  if (physics_ == Physics::ecef) return {rec.t_ns, p.x_e, p.R_b_e};
  input_frame_ = InputFrame::earth_fixed;
  if (!tangent_) tangent_.emplace(geodetic_of(rec, p.x_e));
  return {rec.t_ns, tangent_->ned_from_ecef(p.x_e), tangent_->R_n_to_e().transpose() * p.R_b_e};
}

std::vector<Pose> poses_in_scene(const Trajectory& trajectory, Physics physics) {
  std::vector<Pose> poses;
  poses.reserve(trajectory.records.size());
  ScenePoseConverter converter(physics);
  for (const auto& rec : trajectory.records) poses.push_back(converter.convert(rec, trajectory.source));
  return poses;
}

}  // namespace imuemu::io
