#include <gtest/gtest.h>

#include <array>

#include "drivers/transport.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_drivers_test_drivers {
namespace imuemu { using namespace ::imuemu; }

TEST(NullTransport, CountsFramesAndBytes) {
  imuemu::drivers::NullTransport t;
  std::array<std::byte, 7> a{};
  std::array<std::byte, 5> b{};
  EXPECT_TRUE(t.write_frame(a));
  EXPECT_TRUE(t.write_frame(b));
  EXPECT_EQ(t.counters().frames, 2u);
  EXPECT_EQ(t.counters().bytes, 12u);
  EXPECT_EQ(t.counters().write_errors, 0u);
  EXPECT_EQ(t.describe(), "null");
}
}  // namespace unity_drivers_test_drivers
