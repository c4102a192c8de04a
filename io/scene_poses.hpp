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

}  // namespace imuemu::io
