#include "daemon/engine/lateness_histogram.hpp"

#include <algorithm>
#include <cmath>

namespace imuemu::emission {

std::size_t LatenessHistogram::bucket_of(TimeNs lateness_ns) noexcept {
  if (lateness_ns < 1000) return 0;
  TimeNs decade_start_ns = 1000;  // 10^d us
  for (int d = 0; d < kDecades; ++d, decade_start_ns *= 10) {
    if (lateness_ns < decade_start_ns * 10) {
      // n in 10..99: lateness in [n, n+1) x decade_start / 10.
      const auto n = static_cast<std::size_t>(lateness_ns / (decade_start_ns / 10));
      return 1 + static_cast<std::size_t>(d) * kBucketsPerDecade + (n - 10);
    }
  }
  return kBuckets - 1;
}

TimeNs LatenessHistogram::upper_edge_ns(std::size_t bucket) noexcept {
  if (bucket == 0) return 1000;
  if (bucket >= kBuckets - 1) return kNsPerSecond;
  const std::size_t i = bucket - 1;
  TimeNs decade_start_ns = 1000;
  for (std::size_t d = 0; d < i / kBucketsPerDecade; ++d) decade_start_ns *= 10;
  const auto n = static_cast<TimeNs>(i % kBucketsPerDecade) + 10;
  return (n + 1) * (decade_start_ns / 10);
}

void LatenessHistogram::record(TimeNs lateness_ns) noexcept {
  counts_[bucket_of(lateness_ns)].fetch_add(1, std::memory_order_relaxed);
  total_.fetch_add(1, std::memory_order_relaxed);
  sum_ns_.fetch_add(lateness_ns, std::memory_order_relaxed);
  TimeNs seen = max_ns_.load(std::memory_order_relaxed);
  while (lateness_ns > seen && !max_ns_.compare_exchange_weak(seen, lateness_ns, std::memory_order_relaxed)) {
  }
}

TimeNs LatenessHistogram::quantile_ns(double q) const noexcept {
  std::uint64_t total = 0;
  std::array<std::uint64_t, kBuckets> c{};
  for (std::size_t i = 0; i < kBuckets; ++i) total += (c[i] = counts_[i].load(std::memory_order_relaxed));
  if (total == 0) return 0;
  // Smallest bucket whose cumulative count reaches ceil(q * total).
  const auto rank = std::max<std::uint64_t>(
      1, static_cast<std::uint64_t>(std::ceil(std::clamp(q, 0.0, 1.0) * static_cast<double>(total))));
  std::uint64_t cumulative = 0;
  for (std::size_t i = 0; i < kBuckets; ++i) {
    cumulative += c[i];
    if (cumulative >= rank) {
      // The exact maximum is a tighter bound than the bucket edge when it lies inside.
      if (i == kBuckets - 1) return max_ns_.load(std::memory_order_relaxed);
      return i == 0 ? 0 : std::min(upper_edge_ns(i), std::max<TimeNs>(max_ns_.load(std::memory_order_relaxed), 0));
    }
  }
  return max_ns_.load(std::memory_order_relaxed);
}

LatenessSummary LatenessHistogram::summary() const noexcept {
  LatenessSummary s;
  s.count = total_.load(std::memory_order_relaxed);
  s.p50_ns = quantile_ns(0.5);
  s.p99_ns = quantile_ns(0.99);
  s.p999_ns = quantile_ns(0.999);
  s.max_ns = max_ns_.load(std::memory_order_relaxed);
  s.mean_ns = s.count == 0 ? 0.0 : static_cast<double>(sum_ns_.load(std::memory_order_relaxed)) / static_cast<double>(s.count);
  return s;
}

std::vector<LatenessBucket> LatenessHistogram::buckets() const {
  std::vector<LatenessBucket> out;
  for (std::size_t i = 0; i < kBuckets; ++i) {
    const std::uint64_t n = counts_[i].load(std::memory_order_relaxed);
    if (n == 0) continue;
    const TimeNs upper = i == kBuckets - 1 ? std::max(max_ns_.load(std::memory_order_relaxed), kNsPerSecond)
                                           : upper_edge_ns(i);
    out.push_back({upper, n});
  }
  return out;
}

}  // namespace imuemu::emission
