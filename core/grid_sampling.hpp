// The baselines' common last step (naive, bspline, so3spline): evaluate a
// curve on run_batch's output grid and turn every sample into an ideal IMU
// sample (Eq. 3.70).
#pragma once

#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/imu_model.hpp"
#include "core/pipeline.hpp"

namespace imuemu {

// `curve` has start_ns(), end_ns() and evaluate_in_segment(s, t_ns, Kinematics&);
// segment s covers times up to segment_end_ns[s]. Output times ascend, so the
// segment only moves forward; a time on a segment end goes to the next
// segment, except past the last.
template <typename Curve>
BatchResult sample_on_output_grid(const Curve& curve, const std::vector<TimeNs>& segment_end_ns,
                                  const SceneModel& scene, std::int64_t rate_hz, const std::string& name) {
  const std::vector<TimeNs> times = output_grid(curve.start_ns(), curve.end_ns(), rate_hz);
  if (times.size() < 2) throw std::invalid_argument(name + " output shorter than two samples");
  BatchResult result;
  result.trajectory.resize(times.size());
  result.imu.resize(times.size());
  std::size_t segment = 0;
  const std::size_t last = segment_end_ns.size() - 1;
  for (std::size_t i = 0; i < times.size(); ++i) {
    while (segment < last && segment_end_ns[segment] <= times[i]) ++segment;
    Kinematics& kin = result.trajectory[i];
    curve.evaluate_in_segment(segment, times[i], kin);
    result.imu[i] = imu_from_kinematics(scene, kin);
  }
  return result;
}

}  // namespace imuemu
