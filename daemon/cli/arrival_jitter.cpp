#include "daemon/cli/arrival_jitter.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <utility>

namespace imuemu::cli {
namespace {

// 10^(e-2) ns for decade e = 0..kDecades-1: the bucket width in decade e.
constexpr std::array<double, ArrivalJitter::kDecades> kStepNs{1e-2, 1e-1, 1e0, 1e1, 1e2, 1e3,
                                                              1e4,  1e5,  1e6, 1e7, 1e8};
constexpr double kOverflowNs = 1e11;  // 100 s: the start of the overflow buckets

// Nearest rank (p in (0, 1]) of n values: 1..n.
std::uint64_t nearest_rank(double p, std::uint64_t n) {
  const auto rank = static_cast<std::uint64_t>(std::ceil(p * static_cast<double>(n)));
  return std::clamp<std::uint64_t>(rank, 1, n);
}

}  // namespace

ArrivalJitter::ArrivalJitter(double expected_interval_ns)
    : reference_ns_(expected_interval_ns > 0.0 ? expected_interval_ns : 0.0),
      reference_known_(expected_interval_ns > 0.0) {
  exact_.reserve(kExactIntervals);
}

void ArrivalJitter::record(TimeNs interval_ns) {
  if (count_ == 0) min_ns_ = max_ns_ = interval_ns;
  min_ns_ = std::min(min_ns_, interval_ns);
  max_ns_ = std::max(max_ns_, interval_ns);
  ++count_;
  if (histogram_.empty()) {
    if (exact_.size() < kExactIntervals) {
      exact_.push_back(interval_ns);
      return;
    }
    fold_exact_into_histogram();
  }
  add_to_histogram(interval_ns);
}

void ArrivalJitter::fold_exact_into_histogram() {
  if (!reference_known_) {
    long double sum = 0.0L;
    for (const TimeNs d : exact_) sum += static_cast<long double>(d);
    reference_ns_ = static_cast<double>(sum / static_cast<long double>(exact_.size()));
  }
  histogram_.assign(kBuckets, 0);
  for (const TimeNs d : exact_) add_to_histogram(d);
  std::vector<TimeNs>().swap(exact_);  // give the memory back
}

void ArrivalJitter::add_to_histogram(TimeNs interval_ns) {
  ++histogram_[bucket_of(static_cast<double>(interval_ns) - reference_ns_)];
}

std::size_t ArrivalJitter::bucket_of(double deviation_ns) noexcept {
  const double a = std::abs(deviation_ns);
  if (!(a >= 1.0)) return kSideBuckets;  // |d - r| < 1 ns (the centre)
  std::size_t side = kSideBuckets - 1;    // overflow
  if (a < kOverflowNs) {
    int e = 0;
    while (e + 1 < kDecades && a >= kStepNs[static_cast<std::size_t>(e)] * 1000.0) ++e;
    // n in [100, 999]; clamped against rounding at the decade edges.
    const double n = std::clamp(std::floor(a / kStepNs[static_cast<std::size_t>(e)]), 100.0, 999.0);
    side = static_cast<std::size_t>(e) * kBucketsPerDecade + static_cast<std::size_t>(n) - 100;
  }
  return deviation_ns > 0.0 ? kSideBuckets + 1 + side : kSideBuckets - 1 - side;
}

void ArrivalJitter::bucket_range(std::size_t b, double& lo, double& hi) const noexcept {
  if (b == kSideBuckets) {
    lo = -1.0;
    hi = 1.0;
    return;
  }
  const bool positive = b > kSideBuckets;
  const std::size_t side = positive ? b - kSideBuckets - 1 : kSideBuckets - 1 - b;
  double m_lo = 0.0, m_hi = 0.0;
  if (side == kSideBuckets - 1) {
    m_lo = kOverflowNs;
    m_hi = positive ? static_cast<double>(max_ns_) - reference_ns_ : reference_ns_ - static_cast<double>(min_ns_);
    m_hi = std::max(m_hi, m_lo);
  } else {
    const std::size_t e = side / kBucketsPerDecade;
    const auto n = static_cast<double>(100 + side % kBucketsPerDecade);
    m_lo = n * kStepNs[e];
    m_hi = (n + 1.0) * kStepNs[e];
  }
  lo = positive ? m_lo : -m_hi;
  hi = positive ? m_hi : -m_lo;
}

std::optional<JitterSummary> ArrivalJitter::summary(double nominal_ns) const {
  if (count_ == 0) return std::nullopt;
  JitterSummary out;
  const double max_ns = std::max(std::abs(static_cast<double>(min_ns_) - nominal_ns),
                                 std::abs(static_cast<double>(max_ns_) - nominal_ns));
  out.max_us = max_ns * 1e-3;
  if (exact()) {
    std::vector<double> jitter_us;
    jitter_us.reserve(exact_.size());
    for (const TimeNs d : exact_) jitter_us.push_back(std::abs(static_cast<double>(d) - nominal_ns) * 1e-3);
    std::sort(jitter_us.begin(), jitter_us.end());
    out.p50_us = jitter_us[nearest_rank(0.50, jitter_us.size()) - 1];
    out.p99_us = jitter_us[nearest_rank(0.99, jitter_us.size()) - 1];
    out.max_us = jitter_us.back();
    return out;
  }
  // Each bucket's largest |d - nominal|, with d - nominal = (d - r) - shift.
  const double shift_ns = nominal_ns - reference_ns_;
  std::vector<std::pair<double, std::uint64_t>> upper;  // (bound ns, count)
  for (std::size_t b = 0; b < kBuckets; ++b) {
    if (histogram_[b] == 0) continue;
    double lo = 0.0, hi = 0.0;
    bucket_range(b, lo, hi);
    const double bound = std::min(max_ns, std::max(std::abs(lo - shift_ns), std::abs(hi - shift_ns)));
    upper.emplace_back(bound, histogram_[b]);
  }
  std::sort(upper.begin(), upper.end());
  const auto at_rank = [&](double p) {
    const std::uint64_t rank = nearest_rank(p, count_);
    std::uint64_t seen = 0;
    for (const auto& [bound, n] : upper) {
      seen += n;
      if (seen >= rank) return bound * 1e-3;
    }
    return max_ns * 1e-3;
  };
  out.p50_us = at_rank(0.50);
  out.p99_us = at_rank(0.99);
  return out;
}

std::size_t ArrivalJitter::memory_bytes() const noexcept {
  return exact_.capacity() * sizeof(TimeNs) + histogram_.capacity() * sizeof(std::uint64_t);
}

}  // namespace imuemu::cli
