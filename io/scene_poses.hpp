// Turns trajectory records, as read from a file or a pose stream, into poses
// in a scene's frame.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "core/earth.hpp"
#include "core/imu_model.hpp"
#include "io/trajectory_csv.hpp"

namespace imuemu::io {

// One record at a time (pose streams convert as records arrive):
// ecef scene: geodetic positions go through Eq. 1.1, attitudes R_b^l become
//   R_b^e = R_l^e(lat, lon) R_b^l (Eq. 1.4, 1.5) at each record's own position.
// flat scene: local NED positions are used as they are (attitude R_b^n = R_b^l);
//   geodetic/ECEF positions are expressed in the NED tangent frame of the
//   first record converted, and attitudes rotated into that fixed frame.
// Records without a meaning in the scene are refused with a
// TrajectoryFormatError naming the source and the record's line: local NED
// positions in the ecef scene, an ECEF attitude with a local NED position,
// and (flat scene) a local NED record after Earth-fixed ones or the other way
// round (a datagram stream may change kinds from one pose to the next; the
// two have no common frame). A refused record changes nothing.
class ScenePoseConverter {
 public:
  explicit ScenePoseConverter(Physics physics) noexcept : physics_(physics) {}

  Pose convert(const TrajectoryRecord& record, const std::string& source = {});
  // The record's rates (TrajectoryRecord::rates) in the scene frame, after
  // convert() accepted the same record: velocity and acceleration rotated
  // into the scene's axes (ecef: R_l^e; flat with Earth-fixed input: R_e^n0
  // R_l^e), the body rate made relative to the scene frame by adding the
  // transport rate R_b^l^T omega_el^l when it is relative to local NED
  // (omega_el^l = (v_E/(R_N+h), -v_N/(R_M+h), -v_E tan(lat)/(R_N+h)), WGS84
  // radii; left out without a velocity). Absent rates stay absent.
  PoseRates convert_rates(const TrajectoryRecord& record) const;

  Physics physics() const noexcept { return physics_; }
  // Flat scene with Earth-fixed input: the tangent frame's origin, once the
  // first record has been converted.
  const std::optional<earth::LocalNed>& tangent_frame() const noexcept { return tangent_; }

 private:
  enum class InputFrame { none, local_ned, earth_fixed };
  Physics physics_;
  InputFrame input_frame_ = InputFrame::none;  // of the records converted so far (flat scene)
  std::optional<earth::LocalNed> tangent_;
};

// All records of a file through one ScenePoseConverter. Throws
// TrajectoryFormatError (naming the file and line) as convert() does.
std::vector<Pose> poses_in_scene(const Trajectory& trajectory, Physics physics);

// Plausibility checks of a whole file against the input-convention traps
// (docs/trajectory-format.md "Plausibility warnings"). Each returns a warning
// sentence with the numbers that show the trap, or nothing; they never refuse
// (the file may be what it says) and read at most kPlausibilitySamples knots.
inline constexpr std::size_t kPlausibilitySamples = 64;

// qw,qx,qy,qz holding q_b^e (or qw_ecef.. holding q_b^l) with an Earth-fixed
// position: at sampled knots, the specific force the positions imply
// (thesis Eq. 3.70 in ECEF: a + 2 omega_ie x v - g, from knots 2-10 s apart)
// is compared with the body's up axis under the columns' reading and under
// the other one. A vehicle's specific force points near its up axis (gravity
// when level or static, lift in a coordinated turn); a median angle above
// 45 deg under the columns' reading and below 15 deg under the other says the
// columns were named for the wrong frame.
std::optional<std::string> attitude_frame_warning(const Trajectory& trajectory);

// Flat physics (constant gravity along the fixed down axis, no Earth rate)
// on Earth-scale coordinates: Earth-fixed positions, which the flat scene
// puts in the tangent frame of the first record (what that leaves out, in
// numbers: Earth rate, Coriolis at the fastest speed, gravity's turn across
// the trajectory's extent), or local NED positions at the Earth's radius
// from their origin with a down_m beyond 100 km (ECEF values in the
// north_m,east_m,down_m columns).
std::optional<std::string> flat_scene_warning(const Trajectory& trajectory, Physics physics);

}  // namespace imuemu::io
