// libFuzzer target: pose datagrams (docs/pose-wire-format.md §2) through the
// decoder and the UDP source's admission and loss statistics. A decoded
// datagram must satisfy the trajectory format's rules and encode back to a
// datagram that decodes to the same record; every datagram must end counted
// exactly once; the loss statistics must never count more late datagrams
// than gaps; accepted poses must be finite and strictly later.
// Input: byte 0 is flags (bit 0: recompute each datagram's CRC so the fuzzer
// reaches the checks behind it; bit 1: write magic and version 1; bit 2: the
// ecef scene); the rest is cut into datagrams of 84 bytes (the last may be
// shorter).
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <optional>
#include <vector>

#include "io/pose_admission.hpp"
#include "io/pose_wire.hpp"
#include "tests/fuzz/reseal_datagram.hpp"

namespace {

using namespace imuemu;
using namespace imuemu::io;

void check_record(const TrajectoryRecord& r) {
  if (!r.position.allFinite() || !r.attitude.allFinite()) __builtin_trap();
  if (r.position_kind == PositionKind::geodetic && std::abs(r.position[0]) > 90.0) __builtin_trap();
  if (r.attitude_kind == AttitudeKind::heading_pitch_roll) {
    if (std::abs(r.attitude[1]) > 90.0 || r.attitude[3] != 0.0) __builtin_trap();
  } else if (std::abs(r.attitude.norm() - 1.0) > 1e-15) {
    __builtin_trap();
  }
  if (!kinds_compatible(r.position_kind, r.attitude_kind)) __builtin_trap();
}

bool same(const TrajectoryRecord& a, const TrajectoryRecord& b) {
  return a.t_ns == b.t_ns && a.position_kind == b.position_kind && a.attitude_kind == b.attitude_kind &&
         std::memcmp(a.position.data(), b.position.data(), sizeof(double) * 3) == 0 &&
         (a.attitude - b.attitude).norm() <= 4e-16;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  const std::uint8_t flags = data[0];
  PoseSourceOptions options;
  options.physics = (flags & 4) != 0 ? Physics::ecef : Physics::flat;
  options.log = [](std::string_view) {};
  PoseAdmission admission(options);
  std::optional<Pose> previous;
  std::uint64_t accepted = 0;

  for (std::size_t at = 1; at < size; at += kPoseDatagramV1Size) {
    std::vector<std::uint8_t> d(data + at, data + std::min(size, at + kPoseDatagramV1Size));
    fuzz::reseal_datagram(d, flags);

    PoseDatagram decoded;
    DatagramDecodeError error;
    if (decode_pose_datagram(d, decoded, error)) {
      check_record(decoded.record);
      const auto again = encode_pose_datagram(decoded);
      PoseDatagram round;
      if (!decode_pose_datagram(again, round, error)) __builtin_trap();
      if (round.sequence != decoded.sequence || !same(round.record, decoded.record)) __builtin_trap();
    } else if (error.message.empty()) {
      __builtin_trap();
    }

    SourcedPose out;
    const auto check_released = [&](const SourcedPose& released) {
      const Pose& p = released.pose;
      if (!p.position_m.allFinite() || !p.attitude.allFinite()) __builtin_trap();
      if (previous && !(p.t_ns > previous->t_ns)) __builtin_trap();
      if (!released.sequence) __builtin_trap();
      previous = p;
      ++accepted;
    };
    if (admission.receive_datagram(d, static_cast<TimeNs>(at), "fuzz", out)) {
      check_released(out);
      // An acquisition also releases the poses held until it (resync_poses).
      while (admission.take_released(out)) check_released(out);
    }
    const PoseSourceCounters c = admission.counters();
    if (c.late > c.sequence_gaps) __builtin_trap();
  }
  const PoseSourceCounters c = admission.counters();
  if (c.accepted != accepted) __builtin_trap();
  // Every record is ignored, accepted, rejected, or still held: poses of a
  // stream not yet confirmed by resync_poses consistent ones (the live-time
  // rule, docs/pose-wire-format.md 3.1) when the input ended.
  if (c.received != c.ignored + c.accepted + c.rejected() + c.held) __builtin_trap();
  return 0;
}
