// The built-in sample trajectories (`imuemu sample-trajectory`, the scenes'
// `source = "sample"`, `imuemu emit --sample`): a reference motion of
// core/reference_motion.hpp sampled into knots and written as the trajectory
// CSV of docs/trajectory-format.md. Every user of a sample takes the poses
// parsed back from that same text, so imuemud and emit see exactly the poses
// of `sample-trajectory` + `generate`, without a temporary file.
#pragma once

#include <string>
#include <vector>

#include "core/trajectory.hpp"

namespace imuemu::io {

// kind: flight (aircraft-like, near Barcelona, WGS84 geodetic), circle
// (radius 500 m at 50 m/s, local NED) or static; knots every period_s over
// duration_s. Throws limits::SizeLimitError beyond limits::kMaxKnots knots
// and std::invalid_argument for a duration or period that does not fit int64
// ns (both callers bound them first).
std::string sample_trajectory_csv(const std::string& kind, double duration_s, double period_s);

// The poses of that text in a scene's physics.
std::vector<Pose> sample_trajectory_poses(const std::string& kind, double duration_s, double period_s,
                                          Physics physics);

}  // namespace imuemu::io
