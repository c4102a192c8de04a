// libFuzzer target: a pose line stream (docs/pose-wire-format.md §1) through
// the decoder and the sources' admission, as the TCP and stdin sources run
// it. Whatever the bytes, every line must end counted exactly once, every
// decoded record must satisfy the trajectory format's rules and every
// accepted pose must be finite, strictly later than the one before and
// within the attitude step limit; nothing may throw or crash.
// Input: byte 0 chooses the scene (bit 0) and the read size (bits 1-7); the
// rest is the stream.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string_view>

#include "core/so3.hpp"
#include "io/pose_admission.hpp"
#include "io/pose_wire.hpp"

namespace {

using namespace imuemu;
using namespace imuemu::io;

void check_record(const TrajectoryRecord& r) {
  for (int k = 0; k < 3; ++k)
    if (!std::isfinite(r.position[k])) __builtin_trap();
  for (int k = 0; k < 4; ++k)
    if (!std::isfinite(r.attitude[k])) __builtin_trap();
  if (r.position_kind == PositionKind::geodetic && std::abs(r.position[0]) > 90.0) __builtin_trap();
  if (r.attitude_kind == AttitudeKind::heading_pitch_roll) {
    if (std::abs(r.attitude[1]) > 90.0 || r.attitude[3] != 0.0) __builtin_trap();
  } else if (std::abs(r.attitude.norm() - 1.0) > 1e-15) {
    __builtin_trap();
  }
  if (!kinds_compatible(r.position_kind, r.attitude_kind)) __builtin_trap();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  const std::string_view text(reinterpret_cast<const char*>(data + 1), size - 1);

  // 1. The decoder alone, line by line.
  PoseLineDecoder decoder("fuzz");
  std::size_t begin = 0;
  while (begin < text.size()) {
    std::size_t end = text.find('\n', begin);
    if (end == std::string_view::npos) end = text.size();
    TrajectoryRecord record;
    LineError error = LineError::bad_record;
    std::string message;
    const auto outcome = decoder.decode(text.substr(begin, end - begin), record, error, message);
    if (outcome == PoseLineDecoder::Outcome::record) check_record(record);
    if (outcome == PoseLineDecoder::Outcome::error && message.empty()) __builtin_trap();
    begin = end + 1;
  }

  // 2. The stream as a source runs it: reads of 1..128 bytes, admission.
  PoseSourceOptions options;
  options.physics = (data[0] & 1) != 0 ? Physics::ecef : Physics::flat;
  options.log = [](std::string_view) {};
  PoseAdmission admission(options);
  PoseLineStream stream(admission, "fuzz");
  const std::size_t read_size = static_cast<std::size_t>(data[0] >> 1) + 1;
  std::optional<Pose> previous;
  std::uint64_t accepted = 0;
  auto take = [&] {
    SourcedPose out;
    while (stream.next(out)) {
      const Pose& p = out.pose;
      if (!p.position_m.allFinite() || !p.attitude.allFinite()) __builtin_trap();
      if (previous) {
        if (!(p.t_ns > previous->t_ns)) __builtin_trap();
        // Within one stream the attitude step rule holds between released
        // poses. A re-acquired stream (the live-time rule) is placed more than
        // max_gap_ns (default: max_time_step_ns) after the last pose, where the
        // engine starts a new segment, so no attitude step is implied across it.
        const bool same_stream = p.t_ns - previous->t_ns <= options.max_time_step_ns;
        if (same_stream && !(so3::angle(previous->attitude.transpose() * p.attitude) < options.max_attitude_step_rad))
          __builtin_trap();
      }
      previous = p;
      ++accepted;
    }
  };
  for (std::size_t at = 0; at < text.size(); at += read_size) {
    const std::size_t n = std::min(read_size, text.size() - at);
    stream.append(text.data() + at, n, static_cast<TimeNs>(at));
    take();
  }
  stream.finish();
  const PoseSourceCounters c = admission.counters();
  if (c.accepted != accepted) __builtin_trap();
  // Every record is ignored, accepted, rejected, or still held: poses of a
  // stream not yet confirmed by resync_poses consistent ones (the live-time
  // rule, docs/pose-wire-format.md 3.1) when the input ended.
  if (c.received != c.ignored + c.accepted + c.rejected() + c.held) __builtin_trap();
  return 0;
}
