// Strapdown inertial integration of thesis Eq. 3.69 (the thesis used an
// external tool, NEXA): turns IMU samples back into a trajectory so the
// pipeline can be verified in closed loop.
#pragma once

#include <vector>

#include "core/imu_model.hpp"

namespace imuemu::strapdown {

struct NavState {
  TimeNs t_ns = 0;
  Vec3 position_m = Vec3::Zero();   // scene frame
  Vec3 velocity_m_s = Vec3::Zero(); // scene frame
  Mat3 attitude = Mat3::Identity(); // R_b^frame
};

struct Options {
  // The free-inertial vertical channel in the ecef scene is unstable (a height
  // error grows as exp(t/sqrt(r/2g)), ~10 min time constant). If set, the
  // vertical (along-local-down) position and velocity are reset to the aiding
  // reference at every step, as a perfect altimeter would.
  bool aid_vertical = false;
};

// Integrates uniformly spaced samples (constant period) from `initial` (whose
// t_ns equals samples.front().t_ns). Fourth order: classical Runge-Kutta over
// two sample periods with the middle sample as the half step. Returns the state
// at every sample time reached (samples.size() when odd; the last sample is
// used as an end point only). `vertical_reference` (same length as samples, or
// empty) supplies the aiding positions/velocities when aid_vertical is set.
std::vector<NavState> integrate(const SceneModel& scene, const NavState& initial,
                                const std::vector<ImuSample>& samples, const Options& options = {},
                                const std::vector<NavState>& vertical_reference = {});

}  // namespace imuemu::strapdown
