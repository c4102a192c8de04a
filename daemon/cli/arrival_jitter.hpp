// Arrival-interval jitter of `imuemu listen` in bounded memory: |interval -
// nominal| percentiles and maximum over a run of any length, where the
// nominal interval (the mean interval, unless a rate is expected) is only
// known at the end.
//
// The first kExactIntervals intervals are kept as they are, and a run that
// short is summarised exactly (nearest rank of the sorted |d - nominal|).
// Beyond that they are folded into a fixed histogram of the deviation d - r
// from a reference r (the expected interval, or the mean of the exact
// intervals): signed, log-linear in |d - r| (one bucket below 1 ns; from 1 ns
// to 100 s each decade cut into 900 buckets of 0.1 % to 1 % relative width;
// one overflow bucket per sign). A percentile is then read as the upper
// bound of |d - nominal| over its bucket, so it is never below the exact
// value and above it by at most one bucket's width. The maximum is exact
// (|d - nominal| is largest at the shortest or longest interval).
// Memory: kExactIntervals * 8 bytes until the switch, then the histogram
// (kBuckets * 8 bytes) only: ~160 KB at most, however long the run
// (tests/cli/test_listen.cpp ArrivalJitter.*).
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <vector>

#include "core/types.hpp"

namespace imuemu::cli {

struct JitterSummary {
  double p50_us = 0.0, p99_us = 0.0, max_us = 0.0;
};

class ArrivalJitter {
 public:
  static constexpr std::size_t kExactIntervals = std::size_t{1} << 14;
  static constexpr int kDecades = 11;             // |d - r| from 1 ns to 100 s
  static constexpr int kBucketsPerDecade = 900;   // [n, n+1) x 10^(e-2) ns, n = 100..999
  static constexpr std::size_t kSideBuckets = static_cast<std::size_t>(kDecades) * kBucketsPerDecade + 1;  // + overflow
  static constexpr std::size_t kBuckets = 2 * kSideBuckets + 1;  // negative side, |d - r| < 1 ns, positive side

  // expected_interval_ns > 0: the nominal interval is known (listen
  // --expect-rate-hz) and is the histogram's reference; otherwise the mean
  // of the first kExactIntervals intervals is.
  explicit ArrivalJitter(double expected_interval_ns = 0.0);

  void record(TimeNs interval_ns);
  std::uint64_t count() const noexcept { return count_; }

  // Percentiles of |d - nominal_ns| (nearest rank) and its maximum, in
  // microseconds; empty before any interval.
  std::optional<JitterSummary> summary(double nominal_ns) const;

  // Bytes held for the intervals (exact store capacity + histogram): the
  // bound the header promises.
  std::size_t memory_bytes() const noexcept;
  bool exact() const noexcept { return histogram_.empty(); }

 private:
  void fold_exact_into_histogram();
  void add_to_histogram(TimeNs interval_ns);
  static std::size_t bucket_of(double deviation_ns) noexcept;
  // Signed deviation range [lo, hi] of bucket b (the overflow buckets end at
  // the largest deviation seen).
  void bucket_range(std::size_t b, double& lo, double& hi) const noexcept;

  double reference_ns_;
  bool reference_known_;
  std::uint64_t count_ = 0;
  TimeNs min_ns_ = 0, max_ns_ = 0;
  std::vector<TimeNs> exact_;
  std::vector<std::uint64_t> histogram_;  // empty while exact
};

}  // namespace imuemu::cli
