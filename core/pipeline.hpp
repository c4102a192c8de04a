// The batch trajectory-to-IMU pipeline of thesis §3.6.2 + §3.7:
//   knots --interpolate (Eq. 3.44 / Lemma 3.22 / §3.6.1)--> dense poses on the
//   output grid --r = log R (Eq. 3.13-3.17)--> smooth r and d (Eq. 3.68)
//   --> R~ = exp(r~) --> derivatives (Eq. 3.71-3.74) --> omega = W(r~) r~'
//   (Eq. 3.59), a = d~'' --> ideal IMU (Eq. 3.70) in the scene's physics.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "core/imu_model.hpp"
#include "core/interpolation.hpp"
#include "core/smoothing.hpp"

namespace imuemu {

// Where Eq. 3.68 smooths the attitude and the position.
enum class Chart {
  // The thesis' literal global chart: r = log R_j and the absolute positions
  // d_j. Breaks where log R jumps branch (rotation angle crossing pi), which
  // R_b^e does for ordinary vehicles; kept for comparison.
  global,
  // Blocks of output samples share a reference sample (R_ref, d_ref) at their
  // middle; the window's attitudes enter Eq. 3.68 as log(R_ref^T R_j) and the
  // positions as d_j - d_ref, and the results map back. No sample sits near a
  // log branch cut (blocks are split until every |log(R_ref^T R_j)| <=
  // kMaxChartAngleRad) and the position offsets are small numbers.
  local,
};

Chart chart_from_string(const std::string& name);  // global|local
std::string to_string(Chart c);

// Largest rotation (rad) allowed between a local chart's reference and any
// sample of its window; beyond it the block is split, and a single-sample block
// beyond it is an error (the window itself spans too much rotation).
inline constexpr double kMaxChartAngleRad = 3.0;

struct PipelineOptions {
  SceneModel scene;
  Chart chart = Chart::local;
  std::int64_t rate_hz = 400;  // output rate, integer Hz
  interp::Options interpolation;
  smoothing::KernelOptions kernel;
};

struct BatchResult {
  std::vector<Kinematics> trajectory;  // the smoothed trajectory with its derivatives
  std::vector<ImuSample> imu;          // ideal IMU samples at the same times
};

// Output times t_k = t_first + floor(k * 1e9 / rate_hz) ns for every t_k <=
// t_last: exact integers, no accumulated rounding, any integer rate.
std::vector<TimeNs> output_grid(TimeNs t_first_ns, TimeNs t_last_ns, std::int64_t rate_hz);

// Reports progress in [0, 1]; may be empty.
using ProgressFn = std::function<void(double)>;

// Runs the whole batch method. Throws interp::InterpolationError for knots the
// method cannot interpolate and std::invalid_argument for bad options (rate not
// positive or above 1 MHz, fewer than two output samples).
BatchResult run_batch(const std::vector<Pose>& knots, const PipelineOptions& options,
                      const ProgressFn& progress = {});

}  // namespace imuemu
