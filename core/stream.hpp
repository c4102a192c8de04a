// The streaming form of the pipeline (core/pipeline.hpp): poses are pushed in
// as they arrive, IMU samples are pulled out as soon as every input their
// smoothing window of Eq. 3.68 reads has arrived. run_batch() is a loop over
// this class, so the stream emits exactly (bit for bit) what batch emits,
// including the one-sided or extrapolated windows at both ends.
//
// Memory is O(window): knots, dense samples and segments are dropped as soon
// as no future output reads them.
#pragma once

#include <cstddef>
#include <deque>
#include <functional>
#include <memory>
#include <vector>

#include "core/causal_hermite.hpp"
#include "core/pipeline.hpp"
#include "core/pose_rates.hpp"

namespace imuemu {

struct StreamSample {
  Kinematics kinematics;  // smoothed trajectory and its exact derivatives
  ImuSample imu;          // ideal IMU (Eq. 3.70) at the same instant
};

class StreamPipeline {
 public:
  // Throws std::invalid_argument for options the pipeline refuses (rate,
  // window, spline window).
  explicit StreamPipeline(const PipelineOptions& options);
  ~StreamPipeline();
  StreamPipeline(const StreamPipeline&) = delete;
  StreamPipeline& operator=(const StreamPipeline&) = delete;

  // Appends a knot (a pose in the scene frame). Throws
  // interp::InterpolationError for a knot that cannot follow the previous one
  // (not later, not finite, antipodal step) or whose end extrapolation
  // (Ends::extrapolate) would leave the int64 ns range, and GapError for a gap
  // the policy refuses; std::invalid_argument for a knot whose attitude is
  // more than kMaxChartAngleRad from a knot within one smoothing half-window
  // (Chart::local), or if a smoothing window spans more rotation than a chart
  // holds. Strong guarantee: a refused knot changes nothing (no output, no
  // counter), so a live caller may count it and go on.
  void push(const Pose& knot);
  // The same with the knot's own derivatives (live input): the causal method
  // (PipelineOptions::causal) uses them as its Hermite slopes; the smoothing
  // method ignores them.
  void push(const Pose& knot, const PoseRates& rates);
  // End of input: computes the end of the trajectory (Ends policy). Throws
  // GapError for a last run of a single knot, std::invalid_argument for a
  // run shorter than two output samples (Ends::clip).
  void finish();

  // Takes the oldest ready sample; false if none is ready.
  bool pop(StreamSample& out);
  std::size_t ready() const { return out_.size(); }

  std::size_t knots_pushed() const { return knots_pushed_; }
  // The output grid is first_knot_ns() + floor(k * 1e9 / rate) ns, for every
  // run of a stream split at gaps (GapPolicy::split).
  TimeNs first_knot_ns() const { return first_knot_ns_; }
  TimeNs last_knot_ns() const { return last_knot_.t_ns; }
  // Output samples held inside the engine (dense samples, pending attitudes,
  // ready queue): the memory that must stay O(window).
  std::size_t buffered_samples() const;
  // Newest knot time minus the time of the newest sample made ready so far:
  // the look-ahead the engine is actually running at (0 before any output).
  TimeNs current_lag_ns() const;

  // Upper bound of current_lag_ns() once the first outputs flow, for knots
  // spaced knot_interval_ns apart: the window (Delta samples), the chart
  // blocks' own reach, the time to the next knot and the spline look-ahead
  // (interp::Options::spline_window_knots).
  static TimeNs lookahead_ns(const PipelineOptions& options, TimeNs knot_interval_ns);

  // Every knot-level rule push() and finish() apply (finite, strictly
  // increasing, not antipodal, gaps, end padding within int64, the chart
  // span), over a whole trajectory, without computing a sample: throws what
  // push() or finish() would throw for the first knot they would refuse.
  // imuemud --check-config uses it to say what a start would refuse.
  static void check_trajectory(const std::vector<Pose>& knots, const PipelineOptions& options);

 private:
  class Run;  // one gap-free stretch of knots
  // The knot-level rules of push (nothing changes); true if the knot starts
  // a new run after a gap (GapPolicy::split).
  bool check_knot(const Pose& knot) const;
  // Commits an accepted knot to the bookkeeping the rules read.
  void record(const Pose& knot, bool new_run);
  void check_last_run() const;
  std::size_t knots_in_run() const { return knots_pushed_ - run_first_knot_; }
  void check_padding(const Pose& knot, bool new_run) const;
  void check_chart_span(const Pose& knot, bool new_run) const;
  PipelineOptions options_;
  std::unique_ptr<Run> run_;
  std::unique_ptr<CausalHermite> causal_;  // PipelineOptions::causal
  std::deque<StreamSample> out_;
  std::size_t knots_pushed_ = 0;
  std::size_t run_first_knot_ = 0;
  TimeNs first_knot_ns_ = 0;
  Pose last_knot_;
  std::deque<Pose> recent_;  // this run's knots within one smoothing half-window of the newest
  TimeNs newest_output_ns_ = 0;
  bool any_output_ = false;
  bool finished_ = false;
};

// Receives each output sample, in time order, as soon as it is final.
using StreamSampleSink = std::function<void(const StreamSample&)>;

// The batch method (run_batch) without its result vectors: the whole-list
// checks of run_batch, then every knot pushed through one StreamPipeline and
// every sample handed to `sink` as soon as it is ready, so memory is the
// knots plus O(window), whatever the duration. run_batch is this with a sink
// that appends, so both give the same bits. Throws what run_batch throws, and
// whatever `sink` throws (after some samples may have been delivered).
void run_streaming(const std::vector<Pose>& knots, const PipelineOptions& options, const StreamSampleSink& sink,
                   const ProgressFn& progress = {});

}  // namespace imuemu
