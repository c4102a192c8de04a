#include "core/pipeline.hpp"

#include <algorithm>
#include <array>
#include <optional>
#include <cmath>
#include <stdexcept>
#include <string>

#include "core/limits.hpp"
#include "core/stream.hpp"

namespace imuemu {

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
