// The batch trajectory-to-IMU pipeline: thesis §3.6.2 + §3.7 and what the
// product does beyond it (each step selectable back to the thesis' form):
//   knots --interpolate (hermite default | Eq. 3.44 | Lemma 3.22 | §3.6.1)-->
//   dense poses on the output grid (exact rational instants) --> per block,
//   in a local chart (or the thesis' global r = log R): smooth with Eq. 3.68
//   (bump of Eq. 3.66, order 2 or 4) and differentiate through the kernel
//   (or Eq. 3.71-3.74) --> omega = W(r~) r~' (Eq. 3.59-3.60), a = d~'' -->
//   ideal IMU (Eq. 3.70) in the scene's physics.
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

// How the smoothed trajectory is differentiated.
enum class Derivatives {
  // The thesis' stencils (Eq. 3.71-3.74): forward/backward/centred at the
  // ends, five-point inside; velocity differentiated again for acceleration.
  // Their error grows as rounding/h^2: at ECEF magnitudes and kHz rates the
  // accelerometer error reaches 1e-3 m/s^2 and more.
  finite_difference,
  // Exact derivatives of the smoothed signal of Eq. 3.68 as a function of
  // time: the bump kernel is C-infinity, so d/dt and d2/dt2 go through the
  // kernel weights (smoothing::smooth_with_derivatives). No cancellation.
  kernel,
};

Derivatives derivatives_from_string(const std::string& name);  // finite-difference|kernel
std::string to_string(Derivatives d);

// What to do when consecutive knots are further apart than max_gap_s.
enum class GapPolicy {
  error,  // refuse, naming the two knots
  split,  // process each side as its own trajectory (own one-sided windows);
          // the output has the same gap
};
GapPolicy gap_policy_from_string(const std::string& name);  // error|split

// What Eq. 3.68 sees beyond the first and last knot.
enum class Ends {
  // The thesis: the window is clipped and renormalised (one-sided windows).
  // Biased: a constant-rate motion shows a rate error of up to ~50% there.
  clip,
  // Virtual knots continue the trajectory beyond its ends, so every output
  // sample sees a full window: the position as the degree-6 polynomial in
  // time through the seven end knots, the body rate as the degree-5
  // polynomial through their intervals' mean body rates, over the padding
  // plus the spline's window (core/stream.cpp, extend()). Exact for a
  // constant body rate and for polynomial positions up to degree 6; amplifies
  // knot noise at the ends (README, docs/accuracy.md).
  extrapolate,
};
Ends ends_from_string(const std::string& name);  // clip|extrapolate

struct PipelineOptions {
  SceneModel scene;
  Ends ends = Ends::extrapolate;
  Chart chart = Chart::local;
  Derivatives derivatives = Derivatives::kernel;
  GapPolicy gap_policy = GapPolicy::error;
  double max_gap_s = 10.0;  // longest knot interval interpolated across
  // With kernel derivatives: integrate the kernel against each knot segment's
  // position cubic in closed form (O(knots in window) per sample) instead of
  // summing over the 2*Delta+1 dense samples. Same result to rounding; the
  // dense sum is kept for comparison (tests/core/test_pipeline.cpp).
  bool closed_form_positions = true;
  // With kernel derivatives and KernelWidth::window: the attitude's Eq. 3.68
  // sum (O(Delta) per sample) is evaluated with its exact first and second
  // derivatives only at every attitude_node_step-th sample, and the samples
  // between take the quintic Hermite interpolant of those (value, rate and
  // acceleration matched at both nodes); the body rate is that curve's own
  // derivative, so attitude and gyro stay exactly consistent. The smoothed
  // signal is C-infinity and band-limited by the kernel: with nodes Delta/32
  // samples apart the interpolant differs from the per-sample sum by < 1e-13
  // rad and < 1e-11 rad/s (tests/core/test_stream.cpp). 0: Delta/32 (so every
  // sample below Delta = 64); 1: every sample.
  int attitude_node_step = 0;
  // With kernel derivatives and KernelWidth::window: if Delta is below this,
  // the pipeline runs internally at m = ceil(min_kernel_samples / Delta)
  // times the output rate with m * Delta (the same window in seconds) and
  // emits every m-th sample (the output grid is a subset of the internal
  // one, exactly). A discrete kernel over few samples carries a ripple at the
  // sample rate in its derivatives, which an integrating receiver aliases:
  // at 50 Hz with Delta = 50 the emitted accelerometer is inconsistent with
  // the emitted trajectory by 3.8e-6 m/s^2, with m = 2 by 1.4e-8
  // (tests/core/test_stream.cpp). 0 turns it off.
  int min_kernel_samples = 100;
  std::int64_t rate_hz = 400;  // output rate, integer Hz
  // Default: the C2 Hermite base curve (the thesis' geodesic polygon needs a
  // wide positive kernel to hide its knot kinks, which then attenuates the
  // motion itself; see docs/accuracy.md) smoothed by the fourth-order bump.
  interp::Options interpolation{.method = interp::Method::hermite};
  smoothing::KernelOptions kernel{.delta = 10, .width = smoothing::KernelWidth::window, .half_width_s = 1.0, .order = 4};
  // Live input under a latency budget below the smoothing look-ahead (issue
  // 17): StreamPipeline runs the causal cubic Hermite of
  // core/causal_hermite.hpp instead of Eq. 3.68 (look-ahead one knot
  // interval; interpolation, kernel, chart, derivatives and ends unused).
  bool causal = false;
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

// Sub-nanosecond part of grid time k: (k * 1e9 mod rate) / rate ns. The
// pipeline evaluates the physics at the exact instant t_first + k/rate s and
// stamps the sample with the integer floor (timestamps are int64 ns).
double output_grid_fraction_ns(std::size_t k, std::int64_t rate_hz);

// Names a knot in a message from its 0-based index: "knot 15" by default;
// a caller that knows where the knots came from names the file line instead
// (daemon: "traj.csv:17").
using KnotLabel = std::function<std::string(std::size_t knot_index)>;

// Thrown for knot spacings the gap policy refuses. Names the knots (label)
// and their times in exact decimal seconds (never rounded: epoch times keep
// their nanoseconds).
struct GapError : interp::InterpolationError {
  enum class Kind {
    too_long,  // knots[0], knots[1]: an interval longer than max_gap_s
    isolated,  // knots[0]: a knot alone between two gaps (GapPolicy::split)
  };
  GapError(Kind kind, std::vector<std::size_t> knots, std::vector<TimeNs> times_ns, double max_gap_s);
  // The message with each knot named by `label` (what() uses "knot N").
  std::string describe(const KnotLabel& label) const;

  Kind kind;
  std::vector<std::size_t> knots;  // 0-based indices, in time order
  std::vector<TimeNs> times_ns;    // their times
  double max_gap_s;
};

// Output samples a batch run over `knots` makes (the grid from the first to
// the last knot), checked against core/limits.hpp before any work: throws
// limits::SizeLimitError for more than kMaxKnots knots, fewer than two or
// more than kMaxBatchSamples samples (README: exit 4).
std::uint64_t batch_sample_count(const std::vector<Pose>& knots, std::int64_t rate_hz);

// Runs the whole batch method. Throws interp::InterpolationError for knots the
// method cannot interpolate (GapError for gaps) and std::invalid_argument for
// bad options (rate not positive or above 1 MHz, fewer than two output
// samples, a window spanning more rotation than a chart holds).
BatchResult run_batch(const std::vector<Pose>& knots, const PipelineOptions& options,
                      const ProgressFn& progress = {});

}  // namespace imuemu
