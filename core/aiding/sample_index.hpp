// The sample (or fix) index the aiding models take (issue 28): it never
// decreases, and indices skipped since the last call are simulated (their
// noise drawn), so sample k is the same whichever samples were asked for.
// A skip is bounded: simulating 2^28 samples takes seconds (days at 1 kHz,
// 8.5 years of 1-Hz fixes); a longer jump is a caller's mistake (a time
// base mixed up), refused rather than run for minutes or, at 2^64, forever.
#pragma once

#include <cstdint>
#include <stdexcept>
#include <string>

namespace imuemu::aiding {

inline constexpr std::uint64_t kMaxSkippedSamples = std::uint64_t{1} << 28;

// Throws std::invalid_argument for k < next or k - next > kMaxSkippedSamples.
inline void check_sample_index(const char* who, std::uint64_t k, std::uint64_t next) {
  if (k < next)
    throw std::invalid_argument(std::string(who) + ": sample " + std::to_string(k) + " is before the next one, " +
                                std::to_string(next));
  if (k - next > kMaxSkippedSamples)
    throw std::invalid_argument(std::string(who) + ": sample " + std::to_string(k) + " skips " +
                                std::to_string(k - next) + " samples after " + std::to_string(next) +
                                ", more than 2^28 (simulated one by one)");
}

}  // namespace imuemu::aiding
