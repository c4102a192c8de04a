// Fixed-bucket histogram of wake-up lateness (now - deadline when the emission
// thread wakes), written by the real-time thread without allocation or locks
// and read concurrently by the status reporting.
//
// Buckets are log-linear: below 1 us one bucket (on time, or early); from
// 1 us to 1 s, each decade [10^d, 10^(d+1)) us is cut into 90 equal buckets
// [n, n+1) x 10^(d-1) us for n = 10..99, i.e. a relative resolution of 1% to
// 10% (a percentile is reported as its bucket's upper edge, so it is never
// optimistic); at or above 1 s one overflow bucket. The maximum is exact.
#pragma once

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/types.hpp"

namespace imuemu::emission {

// One non-empty bucket: its values are below upper_ns (the overflow bucket,
// >= 1 s: at most upper_ns, the exact maximum), count of them.
struct LatenessBucket {
  TimeNs upper_ns = 0;
  std::uint64_t count = 0;
  bool operator==(const LatenessBucket&) const = default;
};

struct LatenessSummary {
  std::uint64_t count = 0;
  TimeNs p50_ns = 0;   // bucket upper edges (0: below 1 us)
  TimeNs p99_ns = 0;
  TimeNs p999_ns = 0;
  TimeNs max_ns = 0;   // exact
  double mean_ns = 0.0;
  // Filled only where asked (LatenessHistogram::buckets(): status
  // pose_latency.buckets); empty otherwise.
  std::vector<LatenessBucket> buckets;
};

class LatenessHistogram {
 public:
  static constexpr int kDecades = 6;             // 1 us .. 1 s
  static constexpr int kBucketsPerDecade = 90;   // n = 10..99
  static constexpr std::size_t kBuckets = 2 + kDecades * kBucketsPerDecade;

  // Real-time safe: a few integer operations and relaxed atomic increments.
  void record(TimeNs lateness_ns) noexcept;
  LatenessSummary summary() const noexcept;
  // The non-empty buckets in increasing order (allocates: not for the
  // real-time thread). Counts are read one by one while the histogram may
  // be written, so their sum may differ from summary().count by the values
  // recorded meanwhile.
  std::vector<LatenessBucket> buckets() const;
  // The value at quantile q in [0, 1] as its bucket's upper edge (ns).
  TimeNs quantile_ns(double q) const noexcept;

  static std::size_t bucket_of(TimeNs lateness_ns) noexcept;
  // Smallest lateness not in bucket i (the overflow bucket reports 1 s).
  static TimeNs upper_edge_ns(std::size_t bucket) noexcept;

 private:
  std::array<std::atomic<std::uint64_t>, kBuckets> counts_{};
  std::atomic<std::uint64_t> total_{0};
  std::atomic<TimeNs> max_ns_{0};
  std::atomic<std::int64_t> sum_ns_{0};  // wraps only after ~292 years of summed lateness
};

}  // namespace imuemu::emission
