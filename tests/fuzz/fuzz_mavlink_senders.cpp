// libFuzzer target: MAVLink 2 HIL_STATE_QUATERNION datagrams of two (or
// more) senders through the live source's admission (io/pose_admission.hpp,
// docs/pose-wire-format.md §4; issue 26 N4 and N10). Checked on every input:
//  - one vehicle: no datagram of a sender other than the one taken (the
//    configured ids, else the first intact HIL_STATE_QUATERNION's sender,
//    worked out here from an independent decode) ever yields a pose, and
//    other_sender counts exactly those senders' intact packets;
//  - every snapshot of the counters adds up (received == ignored + accepted +
//    rejected() + held), after every datagram;
//  - released poses are finite, strictly later, and their rates within the
//    physical bounds (io/pose_wire.hpp kMaxLive*, plus the transport rate).
// Input: byte 0 flags (bit 0: configure sysid = byte 1; bit 1: configure
// compid = byte 2; bit 2: the ecef scene), then chunks of 68 bytes: [ctrl]
// [sysid selector] [compid selector] [seq] [64 payload bytes]. ctrl bit 0:
// the chunk's bytes are the datagram as they are (garbage, truncations);
// otherwise a packet is built with a valid checksum; ctrl bit 1 also makes
// its pose plausible (unit quaternion, time 20 ms after the previous, small
// position offsets) so the fuzzer reaches the admission rules behind.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <optional>
#include <vector>

#include "io/mavlink_pose.hpp"
#include "io/pose_admission.hpp"
#include "io/pose_wire.hpp"

namespace {

using namespace imuemu;
using namespace imuemu::io;

constexpr std::size_t kChunk = 68;

template <class T>
T read(const std::uint8_t* at) {
  T v;
  std::memcpy(&v, at, sizeof v);
  return v;
}

mavlink::HilStateQuaternion message_from(const std::uint8_t* p, bool plausible, std::uint64_t index) {
  mavlink::HilStateQuaternion m;
  m.time_usec = read<std::uint64_t>(p);
  for (std::size_t i = 0; i < 4; ++i) m.attitude_quaternion[i] = read<float>(p + 8 + 4 * i);
  m.rollspeed_rad_s = read<float>(p + 24);
  m.pitchspeed_rad_s = read<float>(p + 28);
  m.yawspeed_rad_s = read<float>(p + 32);
  m.lat_degE7 = read<std::int32_t>(p + 36);
  m.lon_degE7 = read<std::int32_t>(p + 40);
  m.alt_mm = read<std::int32_t>(p + 44);
  m.vx_cm_s = read<std::int16_t>(p + 48);
  m.vy_cm_s = read<std::int16_t>(p + 50);
  m.vz_cm_s = read<std::int16_t>(p + 52);
  if (plausible) {
    m.time_usec = 1'000'000 + 20'000 * index + (m.time_usec % 20'000);
    double n = 0;
    for (float q : m.attitude_quaternion) n += std::isfinite(q) ? double{q} * q : 0.0;
    if (n < 1e-6) m.attitude_quaternion = {1, 0, 0, 0};
    else
      for (float& q : m.attitude_quaternion) q = std::isfinite(q) ? static_cast<float>(q / std::sqrt(n)) : 0.0f;
    m.lat_degE7 = 415'000'000 + m.lat_degE7 % 100'000;
    m.lon_degE7 = 22'500'000 + m.lon_degE7 % 100'000;
    m.alt_mm %= 1'000'000;
  }
  return m;
}

void check_pose(const SourcedPose& s) {
  const Pose& p = s.pose;
  if (!p.position_m.allFinite() || !p.attitude.allFinite()) __builtin_trap();
  if (s.rates.angular_rate_rad_s &&
      !(s.rates.angular_rate_rad_s->norm() <= kMaxLiveAngularRate_rad_s * (1 + 1e-12) + 1e-3))
    __builtin_trap();
  if (s.rates.velocity_m_s && !(s.rates.velocity_m_s->norm() <= kMaxLiveSpeed_m_s * (1 + 1e-12))) __builtin_trap();
}

bool adds_up(const PoseSourceCounters& c) { return c.received == c.ignored + c.accepted + c.rejected() + c.held; }

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 3) return 0;
  const std::uint8_t flags = data[0];
  PoseSourceOptions options;
  options.physics = (flags & 4) != 0 ? Physics::ecef : Physics::flat;
  options.log = [](std::string_view) {};
  if ((flags & 1) != 0) options.mavlink_system_id = static_cast<std::uint8_t>(data[1] | 1);
  if ((flags & 2) != 0) options.mavlink_component_id = static_cast<std::uint8_t>(data[2] | 1);
  PoseAdmission admission(options);

  std::optional<mavlink::PacketInfo> taken;  // worked out here, independently of the admission
  std::uint64_t other = 0, accepted = 0, index = 0;
  std::optional<TimeNs> previous_t_ns;
  for (std::size_t at = 3; at < size; at += kChunk, ++index) {
    const std::size_t n = std::min(kChunk, size - at);
    const std::uint8_t* chunk = data + at;
    std::vector<std::uint8_t> datagram;
    if ((chunk[0] & 1) != 0 || n < kChunk) {
      datagram.assign(chunk, chunk + n);
    } else {
      // Two senders mostly (selector bit 0), now and then a third.
      const auto sysid = static_cast<std::uint8_t>(1 + (chunk[1] & 1) + ((chunk[1] & 0x80) != 0 ? 5 : 0));
      const auto compid = static_cast<std::uint8_t>(1 + (chunk[2] & 1));
      datagram = mavlink::encode_hil_state_quaternion(message_from(chunk + 4, (chunk[0] & 2) != 0, index),
                                                      {chunk[3], sysid, compid});
    }
    // The independent verdict: an intact HIL_STATE_QUATERNION chooses or is another's.
    bool from_other = false;
    {
      mavlink::HilStateQuaternion m;
      mavlink::PacketInfo info;
      DatagramDecodeError error;
      if (mavlink::decode_datagram(datagram, m, info, error) == mavlink::Outcome::hil_state) {
        const bool matches = (!options.mavlink_system_id || info.system_id == *options.mavlink_system_id) &&
                             (!options.mavlink_component_id || info.component_id == *options.mavlink_component_id);
        if (!taken && matches) taken = info;
        from_other = !taken || info.system_id != taken->system_id || info.component_id != taken->component_id;
        other += from_other;
      }
    }
    SourcedPose out;
    bool any = admission.receive_mavlink_datagram(datagram, static_cast<TimeNs>(at) * 1000, "fuzz", out);
    std::vector<SourcedPose> released;
    if (any) released.push_back(out);
    while (admission.take_released(out)) released.push_back(out);
    if (from_other && !released.empty()) __builtin_trap();  // another sender's datagram made a pose
    for (const SourcedPose& p : released) {
      check_pose(p);
      if (previous_t_ns && !(p.pose.t_ns > *previous_t_ns)) __builtin_trap();
      previous_t_ns = p.pose.t_ns;
      ++accepted;
    }
    const PoseSourceCounters c = admission.counters();
    if (!adds_up(c) || c.other_sender != other || c.accepted != accepted) __builtin_trap();
  }
  return 0;
}
