#include "core/pipeline.hpp"

#include <algorithm>
#include <charconv>
#include <array>
#include <optional>
#include <cmath>
#include <stdexcept>
#include <string>

#include "core/decimal_seconds.hpp"
#include "core/limits.hpp"
#include "core/time_arith.hpp"
#include "core/stream.hpp"

namespace imuemu {

namespace {
std::string default_knot_label(std::size_t index) { return "knot " + std::to_string(index); }

std::string shortest(double v) {
  char buf[32];
  return std::string(buf, std::to_chars(buf, buf + sizeof buf, v).ptr);
}

// The one wording of every gap message (GapError::what() and describe()).
std::string gap_message(GapError::Kind kind, const std::vector<std::size_t>& knots, const std::vector<TimeNs>& times_ns,
                        double max_gap_s, const KnotLabel& label) {
  const auto at = [&](std::size_t k) {
    return label(knots[k]) + " (t=" + format_decimal_seconds(times_ns[k]) + " s)";
  };
  if (kind == GapError::Kind::isolated)
    return at(0) + " is isolated between two gaps: a segment needs at least two knots";
  // The interval exactly, as a time: two ordered times' distance fits uint64
  // (ns_between); beyond int64 it is shown saturated.
  const std::uint64_t step_ns = ns_between(times_ns[0], times_ns[1]);
  const TimeNs shown_ns = step_ns > static_cast<std::uint64_t>(kMaxTimeNs) ? kMaxTimeNs : static_cast<TimeNs>(step_ns);
  return at(0) + " and " + at(1) + " are " + format_decimal_seconds(shown_ns) + " s apart, more than the " +
         shortest(max_gap_s) + " s gap limit: raise the limit or split the trajectory at gaps";
}
}  // namespace

GapError::GapError(Kind kind_, std::vector<std::size_t> knots_, std::vector<TimeNs> times_ns_, double max_gap_s_)
    : interp::InterpolationError(gap_message(kind_, knots_, times_ns_, max_gap_s_, default_knot_label)),
      kind(kind_),
      knots(std::move(knots_)),
      times_ns(std::move(times_ns_)),
      max_gap_s(max_gap_s_) {}

std::string GapError::describe(const KnotLabel& label) const {
  return gap_message(kind, knots, times_ns, max_gap_s, label);
}

Chart chart_from_string(const std::string& name) {
  if (name == "global") return Chart::global;
  if (name == "local") return Chart::local;
  throw std::invalid_argument("chart '" + name + "': expected global or local");
}

std::string to_string(Chart c) { return c == Chart::global ? "global" : "local"; }

Derivatives derivatives_from_string(const std::string& name) {
  if (name == "kernel") return Derivatives::kernel;
  if (name == "finite-difference") return Derivatives::finite_difference;
  throw std::invalid_argument("derivatives '" + name + "': expected kernel or finite-difference");
}

std::string to_string(Derivatives d) { return d == Derivatives::kernel ? "kernel" : "finite-difference"; }

Ends ends_from_string(const std::string& name) {
  if (name == "clip") return Ends::clip;
  if (name == "extrapolate") return Ends::extrapolate;
  throw std::invalid_argument("ends '" + name + "': expected clip or extrapolate");
}

GapPolicy gap_policy_from_string(const std::string& name) {
  if (name == "error") return GapPolicy::error;
  if (name == "split") return GapPolicy::split;
  throw std::invalid_argument("gap policy '" + name + "': expected error or split");
}

std::vector<TimeNs> output_grid(TimeNs t_first_ns, TimeNs t_last_ns, std::int64_t rate_hz) {
  if (rate_hz <= 0 || rate_hz > 1'000'000)
    throw std::invalid_argument("output rate " + std::to_string(rate_hz) + " Hz: expected 1..1000000");
  if (t_last_ns < t_first_ns) throw std::invalid_argument("output grid: end before start");
  // Exact floor arithmetic without 128-bit types: split into whole seconds and
  // a remainder so no product exceeds ~1e15.
  const TimeNs span_ns = t_last_ns - t_first_ns;
  const std::int64_t whole_s = span_ns / kNsPerSecond, rem_ns = span_ns % kNsPerSecond;
  const auto count = static_cast<std::size_t>(whole_s * rate_hz + rem_ns * rate_hz / kNsPerSecond) + 1;
  std::vector<TimeNs> times(count);
  for (std::size_t k = 0; k < count; ++k) {
    const auto ks = static_cast<std::int64_t>(k);
    times[k] = t_first_ns + (ks / rate_hz) * kNsPerSecond + (ks % rate_hz) * kNsPerSecond / rate_hz;
  }
  return times;
}

double output_grid_fraction_ns(std::size_t k, std::int64_t rate_hz) {
  const auto ks = static_cast<std::int64_t>(k);
  return static_cast<double>(((ks % rate_hz) * kNsPerSecond) % rate_hz) / static_cast<double>(rate_hz);
}

std::uint64_t batch_sample_count(const std::vector<Pose>& knots, std::int64_t rate_hz) {
  if (knots.size() > limits::kMaxKnots)
    throw limits::SizeLimitError(std::to_string(knots.size()) + " knots: more than the " +
                                 std::to_string(limits::kMaxKnots) + " a trajectory may hold (split it)");
  if (knots.size() < 2)
    throw std::invalid_argument("interpolation needs at least 2 knots, got " + std::to_string(knots.size()));
  const std::uint64_t samples = limits::grid_sample_count(knots.front().t_ns, knots.back().t_ns, rate_hz);
  const std::string span = "the trajectory spans " +
                           std::to_string(seconds_between(knots.front().t_ns, knots.back().t_ns)) + " s (knots 0 to " +
                           std::to_string(knots.size() - 1) + ")";
  if (samples < 2)
    throw limits::SizeLimitError(span + ": shorter than two output samples at " + std::to_string(rate_hz) + " Hz");
  if (samples > limits::kMaxBatchSamples)
    throw limits::SizeLimitError(span + ": " + std::to_string(samples) + " output samples at " +
                                 std::to_string(rate_hz) + " Hz, more than the " +
                                 std::to_string(limits::kMaxBatchSamples) + " of one batch run");
  return samples;
}

BatchResult run_batch(const std::vector<Pose>& knots, const PipelineOptions& options,
                      const ProgressFn& progress) {
  // The batch path is a loop over the streaming engine: one implementation.
  // The knots' own rules first (their message names the knots), then the
  // derived sizes before anything is allocated for them (core/limits.hpp).
  interp::check_knots(knots);
  const std::uint64_t expected = batch_sample_count(knots, options.rate_hz);
  BatchResult result;
  // A bounded first reservation: the vectors grow with what the run really
  // produces, and a large count is never reserved before any work.
  constexpr std::uint64_t kMaxReservedSamples = std::uint64_t{1} << 22;
  result.trajectory.reserve(static_cast<std::size_t>(std::min(expected, kMaxReservedSamples)));
  result.imu.reserve(static_cast<std::size_t>(std::min(expected, kMaxReservedSamples)));
  run_streaming(
      knots, options,
      [&](const StreamSample& sample) {
        result.trajectory.push_back(sample.kinematics);
        result.imu.push_back(sample.imu);
      },
      progress);
  return result;
}

}  // namespace imuemu
