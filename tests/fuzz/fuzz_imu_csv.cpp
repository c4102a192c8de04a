// libFuzzer target: the IMU CSV reader (used by `imuemu verify`) returns
// finite, strictly time-ordered samples or throws SampleFormatError.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "io/sample_writers.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  try {
    const auto samples = imuemu::io::parse_imu_csv(text, "fuzz.csv");
    for (std::size_t i = 0; i < samples.size(); ++i) {
      if (i > 0 && !(samples[i].t_ns > samples[i - 1].t_ns)) __builtin_trap();
      if (!samples[i].gyro_rad_s.allFinite() || !samples[i].accel_m_s2.allFinite()) __builtin_trap();
    }
  } catch (const imuemu::io::CsvFormatError&) {
  }
  return 0;
}
