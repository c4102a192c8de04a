// libFuzzer target: the trajectory CSV reader must either return records that
// satisfy its documented invariants or throw TrajectoryFormatError; anything
// else (another exception, a crash, UB, a NaN that got through) is a bug.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "io/trajectory_csv.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  imuemu::io::TrajectoryReadOptions options;
  options.allow_extra_columns = (data[0] & 1) != 0;
  const std::string_view text(reinterpret_cast<const char*>(data + 1), size - 1);
  try {
    const imuemu::io::Trajectory t = imuemu::io::parse_trajectory_csv(text, "fuzz.csv", options);
    if (t.records.empty()) __builtin_trap();
    for (std::size_t i = 0; i < t.records.size(); ++i) {
      const auto& r = t.records[i];
      if (i > 0 && !(r.t_ns > t.records[i - 1].t_ns)) __builtin_trap();
      for (int k = 0; k < 3; ++k)
        if (!std::isfinite(r.position[k])) __builtin_trap();
      for (int k = 0; k < 4; ++k)
        if (!std::isfinite(r.attitude[k])) __builtin_trap();
    }
  } catch (const imuemu::io::TrajectoryFormatError&) {
  }
  return 0;
}
