// Shared by the method tests: IMU error statistics of a method's output
// against an analytic reference motion, and bound checks.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "core/pipeline.hpp"
#include "core/reference_motion.hpp"

namespace imuemu::test_support {

struct ImuErrorStats {
  double gyro_rms_rad_s = 0.0, gyro_max_rad_s = 0.0;
  double accel_rms_m_s2 = 0.0, accel_max_m_s2 = 0.0;
  // Samples before from_ns or after to_ns count here only.
  double end_gyro_max_rad_s = 0.0, end_accel_max_m_s2 = 0.0;
  double ns_per_sample = 0.0;  // filled by callers that time the run
  std::size_t samples = 0;     // samples inside [from_ns, to_ns]
};

// Compares every output sample with reference::truth_imu at the same t_ns.
inline ImuErrorStats imu_errors_against_truth(const BatchResult& out, const reference::Motion& motion,
                                              const SceneModel& scene, TimeNs from_ns, TimeNs to_ns) {
  ImuErrorStats s;
  double g2 = 0.0, a2 = 0.0;
  for (const ImuSample& e : out.imu) {
    const ImuSample t = reference::truth_imu(motion, scene, e.t_ns);
    const double g = (e.gyro_rad_s - t.gyro_rad_s).norm(), a = (e.accel_m_s2 - t.accel_m_s2).norm();
    EXPECT_TRUE(std::isfinite(g) && std::isfinite(a)) << "sample at " << e.t_ns << " ns";
    if (e.t_ns < from_ns || e.t_ns > to_ns) {
      s.end_gyro_max_rad_s = std::max(s.end_gyro_max_rad_s, g);
      s.end_accel_max_m_s2 = std::max(s.end_accel_max_m_s2, a);
      continue;
    }
    ++s.samples;
    g2 += g * g;
    a2 += a * a;
    s.gyro_max_rad_s = std::max(s.gyro_max_rad_s, g);
    s.accel_max_m_s2 = std::max(s.accel_max_m_s2, a);
  }
  s.gyro_rms_rad_s = std::sqrt(g2 / static_cast<double>(std::max<std::size_t>(1, s.samples)));
  s.accel_rms_m_s2 = std::sqrt(a2 / static_cast<double>(std::max<std::size_t>(1, s.samples)));
  return s;
}

struct ErrorBounds {
  double gyro_rms, gyro_max, accel_rms, accel_max;
};

inline void expect_within(const ImuErrorStats& s, const ErrorBounds& b, const std::string& what) {
  EXPECT_LT(s.gyro_rms_rad_s, b.gyro_rms) << what;
  EXPECT_LT(s.gyro_max_rad_s, b.gyro_max) << what;
  EXPECT_LT(s.accel_rms_m_s2, b.accel_rms) << what;
  EXPECT_LT(s.accel_max_m_s2, b.accel_max) << what;
}

// 4th-order central difference of f at 0 with step h: exact for quartics.
template <typename F>
Vec3 central_difference(const F& f, double h) {
  const Vec3 near = f(h) - f(-h), far = f(2.0 * h) - f(-2.0 * h);
  return (8.0 * near - far) / (12.0 * h);
}

}  // namespace imuemu::test_support
