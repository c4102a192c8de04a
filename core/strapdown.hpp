// Strapdown inertial integration of thesis Eq. 3.69 (the thesis used an
// external tool, NEXA): turns IMU samples back into a trajectory so the
// pipeline can be verified in closed loop.
//
// Scene-frame equations (ecef; flat drops the Earth-rate terms and uses the
// scene's constant gravity vector):
//   x' = v,   v' = R f^b + g(x) - 2 w_ie x v,   R' = R [w_ib^b] - [w_ie] R.
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
  // vertical position and velocity components (along the ellipsoid normal at
  // the current position for ecef, along the down axis for flat) are replaced
  // by the aiding reference's after every integration step, as a perfect
  // altimeter would do.
  bool aid_vertical = false;
};

// Integrates sampled IMU data from `initial` (whose t_ns must equal
// samples.front().t_ns). One step spans two sample periods, k -> k+2, with the
// middle sample k+1 as the half step (samples are instantaneous, so a step
// needs the rates at its start, middle and end):
//   attitude: exact Earth-rotation factor times a fourth-order Magnus
//             (Simpson + coning commutator) body increment, orthogonal by
//             construction and exact for a constant body rate;
//   position/velocity: classical fourth-order Runge-Kutta.
// Global error O(dt^4).
//
// Returns the states at the even-indexed samples only: result[j] is the state
// at samples[2 j].t_ns, result.size() == (samples.size() - 1) / 2 + 1 and
// result[0] == initial. With an even number of samples the last one is unused.
//
// Samples must be (nearly) uniformly spaced: within each step the middle sample
// must lie within 2 ns of the midpoint (integer-ns rounding of rates such as
// 300 Hz is tolerated); otherwise std::invalid_argument is thrown.
// `vertical_reference` (same length as samples, or empty when aid_vertical is
// off) supplies the aiding positions/velocities; only its entries at
// even-indexed samples are used. Throws std::invalid_argument on mismatched
// lengths or times.
std::vector<NavState> integrate(const SceneModel& scene, const NavState& initial,
                                const std::vector<ImuSample>& samples, const Options& options = {},
                                const std::vector<NavState>& vertical_reference = {});

}  // namespace imuemu::strapdown
