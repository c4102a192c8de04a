// Basic vocabulary shared by every room: vectors, rotations and integer time.
#pragma once

#include <Eigen/Dense>
#include <cstdint>

namespace imuemu {

using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;

// Time is integer nanoseconds end to end. Only *differences* of times are ever
// turned into double seconds, never absolute epochs.
using TimeNs = std::int64_t;

inline constexpr TimeNs kNsPerSecond = 1'000'000'000;

// A (small) time difference in seconds. Safe because differences of int64 ns
// within a window are far below 2^53 ns (104 days).
inline constexpr double seconds_between(TimeNs from_ns, TimeNs to_ns) {
  return static_cast<double>(to_ns - from_ns) * 1e-9;
}

}  // namespace imuemu
