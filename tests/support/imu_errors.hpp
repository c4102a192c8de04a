// Shared by the method tests: IMU error statistics of a method's output
// against an analytic reference motion, and bound checks.
#pragma once

#include <gtest/gtest.h>

#include <string>

#include "core/pipeline.hpp"
#include "core/reference_motion.hpp"

namespace imuemu::test_support {

// reference::compare_with_truth plus the per-run timing the tests print; a
// non-finite sample is a test failure.
struct ImuErrorStats : reference::ImuErrors {
  double ns_per_sample = 0.0;  // filled by callers that time the run
};

inline ImuErrorStats imu_errors_against_truth(const BatchResult& out, const reference::Motion& motion,
                                              const SceneModel& scene, TimeNs from_ns, TimeNs to_ns) {
  ImuErrorStats s;
  static_cast<reference::ImuErrors&>(s) = reference::compare_with_truth(out.imu, motion, scene, from_ns, to_ns);
  EXPECT_EQ(s.non_finite, 0u) << "NaN/Inf in the output";
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
