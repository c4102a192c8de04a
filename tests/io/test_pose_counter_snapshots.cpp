// Counters a reader sees together are consistent (issue 26, the
// UdpPoseSource test race): a datagram was counted `received` before it was
// classified, so a reader (the status socket, a test waiting for received ==
// 15) could see `accepted` one short, and the sum rule of
// docs/pose-wire-format.md §3.2 broken. Now the source's thread publishes one
// snapshot per unit, after the unit is classified (and, for UDP, after its
// pose is queued): every snapshot satisfies
//   received == ignored + accepted + rejected() + held
// and a UDP source showing `received == n` has queued every accepted pose.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <string>
#include <thread>
#include <vector>

#include "io/pose_admission.hpp"
#include "io/pose_source.hpp"
#include "io/pose_wire.hpp"
#include "tests/support/udp_sender.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace imuemu::io {}
namespace unity_io_test_pose_counter_snapshots {
namespace imuemu { using namespace ::imuemu; }
namespace imuemu::io { using namespace ::imuemu::io; }

namespace imuemu::io {
namespace {

using namespace std::chrono_literals;

std::vector<std::uint8_t> datagram(std::uint64_t sequence, TimeNs t_ns) {
  PoseDatagram d;
  d.sequence = sequence;
  d.record.t_ns = t_ns;
  d.record.position_kind = PositionKind::local_ned;
  d.record.position = Vec3(static_cast<double>(sequence), 0.5, -2.0);
  d.record.attitude_kind = AttitudeKind::quaternion;
  d.record.attitude = Eigen::Vector4d(1, 0, 0, 0);
  const auto bytes = encode_pose_datagram(d);
  return {bytes.begin(), bytes.end()};
}

bool adds_up(const PoseSourceCounters& c) {
  return c.received == c.ignored + c.accepted + c.rejected() + c.held && c.late <= c.sequence_gaps;
}

// One thread feeds an admission datagrams of every kind (good, duplicate,
// reordered, corrupted, garbage, time jumps); another reads snapshots the
// whole time. Old code: the first broken snapshot came within milliseconds.
TEST(PoseCounterSnapshots, EverySnapshotAddsUpWhileTheSourceThreadCounts) {
  PoseSourceOptions options;
  options.log = [](std::string_view) {};
  PoseAdmission admission(options);
  constexpr std::uint64_t kUnits = 200'000;
  std::atomic<bool> done{false};
  std::uint64_t snapshots = 0, broken = 0;
  PoseSourceCounters first_broken;
  std::thread reader([&] {
    while (!done.load(std::memory_order_acquire)) {
      const PoseSourceCounters c = admission.counters();
      ++snapshots;
      if (!adds_up(c) && broken++ == 0) first_broken = c;
    }
  });
  const std::vector<std::uint8_t> garbage = {'h', 'e', 'l', 'l', 'o'};
  TimeNs t_ns = 1'000'000'000;
  std::uint64_t sequence = 0;
  for (std::uint64_t k = 0; k < kUnits; ++k) {
    std::vector<std::uint8_t> d;
    switch (k % 8) {
      case 3: d = datagram(sequence - 1, t_ns - 10'000'000); break;  // duplicate
      case 5: d = garbage; break;
      case 6:
        d = datagram(sequence, t_ns);
        d[30] ^= 0x10;  // corrupted
        break;
      case 7: d = datagram(sequence + 5000, t_ns + 3600 * kNsPerSecond); break;  // a stray an hour ahead
      default:
        d = datagram(sequence++, t_ns);
        t_ns += 10'000'000;
    }
    SourcedPose out;
    if (admission.receive_datagram(d, t_ns, "test", out))
      while (admission.take_released(out)) {
      }
  }
  done.store(true, std::memory_order_release);
  reader.join();
  const PoseSourceCounters c = admission.counters();
  EXPECT_EQ(c.received, kUnits);
  EXPECT_TRUE(adds_up(c));
  EXPECT_GT(snapshots, 100u);
  EXPECT_EQ(broken, 0u) << "of " << snapshots << " snapshots; the first: received " << first_broken.received
                        << ", accepted " << first_broken.accepted << ", rejected " << first_broken.rejected()
                        << ", held " << first_broken.held << ", ignored " << first_broken.ignored;
}

// The UDP source: once a snapshot says received == n, the accepted poses are
// in the queue (counted after the push, in the same snapshot).
TEST(PoseCounterSnapshots, AUdpSourceShowingReceivedHasQueuedWhatItAccepted) {
  PoseSourceOptions options;
  options.log = [](std::string_view) {};
  options.queue_capacity = 4096;
  auto source = make_udp_pose_source({"127.0.0.1", 0}, options);
  source->start();
  const test::LoopbackUdpSender sender(source->local_port());
  // Batches of 50 (a loaded host's socket buffer holds them all), read while
  // the source works on them: every snapshot's accepted poses are queued.
  std::uint64_t sent = 0, snapshots = 0, mismatches = 0, queued_seen = 0, accepted_seen = 0;
  const auto deadline = std::chrono::steady_clock::now() + 20s;
  while (sent < 300) {
    for (std::uint64_t k = 0; k < 50; ++k, ++sent) {
      const auto d = datagram(sent, 1'000'000'000 + static_cast<TimeNs>(sent) * 10'000'000);
      ASSERT_TRUE(sender.send(d));
    }
    for (;;) {
      const PoseSourceCounters c = source->counters();
      const std::size_t queued = source->queue().size();  // read after the snapshot: can only be larger
      ++snapshots;
      if (queued < c.accepted && mismatches++ == 0) {
        queued_seen = queued;
        accepted_seen = c.accepted;
      }
      if (c.received == sent || std::chrono::steady_clock::now() > deadline) break;
    }
  }
  const PoseSourceCounters c = source->counters();
  EXPECT_EQ(c.received, 300u);
  EXPECT_EQ(c.accepted, 300u);
  EXPECT_EQ(source->queue().size(), 300u);
  EXPECT_EQ(mismatches, 0u) << "of " << snapshots << " snapshots; the first: " << accepted_seen << " accepted, "
                            << queued_seen << " queued";
  source->stop();
}

}  // namespace
}  // namespace imuemu::io
}  // namespace unity_io_test_pose_counter_snapshots
