// Stated limits of imuemu's inputs, in one place: the caps on every size that
// is derived from an input (a knot count, a window, a sample count, a
// reservation) and the ranges of the options the command line and the scene
// parser share. Each is checked before anything is allocated for it, and a
// value beyond it is refused with SizeLimitError (exit 4, README.md) naming
// the cause, never left to bad_alloc, an int overflow or a 10 GB process.
// Pure, no I/O.
#pragma once

#include <cmath>
#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>

#include "core/time_arith.hpp"
#include "core/types.hpp"

namespace imuemu::limits {

// A derived size beyond its cap. An std::invalid_argument, so every caller
// that maps "valid input the method cannot process" to exit 4 already does.
class SizeLimitError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

// Knots of one trajectory (a file, a built-in sample, a loop of either): 10
// million knots are ~2 GB of poses and segments; a longer file is a unit
// mistake or wants splitting.
inline constexpr std::size_t kMaxKnots = 10'000'000;

// Knots of a looped trajectory ([trajectory] loop = true: copies for up to
// 24 h, daemon/scene/scene_runner.hpp looped()). The copies are held in memory
// (~100 B a pose), so 24 h of a dense file (100 k knots 1 ms apart: 86 M
// knots, 9 GB) is capped to the copies that fit here; the run then restarts
// after them instead of after 24 h.
inline constexpr std::size_t kMaxLoopKnots = 1'000'000;

// The smoothing half-window Delta of Eq. 3.68, in output samples: beyond a
// million it is a unit mistake (window seconds x rate), and the engine would
// allocate its kernel tables (~100 B per sample) before anything else.
inline constexpr std::int64_t kMaxWindowSamples = 1'000'000;

// Output samples of one batch run (`imuemu generate`): 1e9 samples are 28 h
// at 10 kHz, ~100 GB of CSV.
inline constexpr std::uint64_t kMaxBatchSamples = 1'000'000'000;

// Virtual knots the end extrapolation (Ends::extrapolate) places beyond each
// end of a run to cover its padding (whole seconds): knots 1 us apart would
// need a million per end (500 MB), 1 ns apart a billion. Beyond this count
// the virtual knots are spread over the padding at pad / kMaxPaddingKnots
// (still on the extrapolated curve), so their number never exceeds it.
inline constexpr std::int64_t kMaxPaddingKnots = 4096;

// Position coordinates (m) of a trajectory (heights, ECEF, local NED): a
// million km. Beyond it the physics squares them into inf (h_m = 1e300 ended
// as a NaN sample at the writer); within it a double still resolves 0.1 um.
inline constexpr double kMaxPositionM = 1e9;

// Speed factors sigma and mu of the minimum-acceleration warp (Lemma 3.22):
// p'(0) = sigma, p'(1) = mu. Beyond 3 the cubic p(tau) leaves [0, 1] (it runs
// backwards along the geodesic), below 0 it does at once.
inline constexpr double kMinSpeedFactor = 0.0;
inline constexpr double kMaxSpeedFactor = 3.0;

// Seconds that fit int64 nanoseconds with room for the sums made of them
// (a time plus a padding plus a window): +-2^62 ns, ~146 years.
inline constexpr double kMaxSecondsMagnitude = 4.611686018427387904e9;

// s seconds as int64 ns (rounded to nearest), or nullopt when s is not finite
// or |s| exceeds kMaxSecondsMagnitude: the one checked seconds -> ns step of
// every option and scene value given in seconds.
inline std::optional<TimeNs> checked_ns_from_seconds(double s) noexcept {
  if (!std::isfinite(s) || std::abs(s) > kMaxSecondsMagnitude) return std::nullopt;
  return static_cast<TimeNs>(std::llround(s * 1e9));
}

// round(seconds x rate_hz) as a sample count, or nullopt when it is not
// finite or beyond `cap` (a window, a duration in samples).
inline std::optional<std::int64_t> checked_samples(double seconds, double rate_hz, std::int64_t cap) noexcept {
  const double n = std::round(seconds * rate_hz);
  if (!std::isfinite(n) || n < 0.0 || n > static_cast<double>(cap)) return std::nullopt;
  return static_cast<std::int64_t>(n);
}

// Output samples of the grid first_ns + floor(k * 1e9 / rate_hz) that lie in
// [first_ns, last_ns] (first_ns <= last_ns): exact, no overflow.
constexpr std::uint64_t grid_sample_count(TimeNs first_ns, TimeNs last_ns, std::int64_t rate_hz) noexcept {
  const std::uint64_t span_ns = ns_between(first_ns, last_ns);
  const auto rate = static_cast<std::uint64_t>(rate_hz);
  const std::uint64_t ns = static_cast<std::uint64_t>(kNsPerSecond);
  // floor(span * rate / 1e9) + 1, split so no product leaves 64 bits
  // (span < 2^64, rate <= 1e6: whole seconds x rate < 2^64 / 1e9 x 1e6).
  return (span_ns / ns) * rate + (span_ns % ns) * rate / ns + 1;
}

}  // namespace imuemu::limits
