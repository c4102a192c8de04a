// Acceptance test of the streaming issue, end to end over real UDP loopback:
// a sender replays a trajectory as binary pose datagrams (docs/pose-wire-
// format.md) in real time x20, with 1% of the datagrams dropped at random and
// 1% sent after their successor. The receiver (io::make_udp_pose_source)
// feeds the streaming engine (core/stream.hpp) whose samples the live emitter
// (core/live_emitter.hpp) sends at every tick of the output grid, each tick
// seeing exactly the poses due by its deadline on the sender's clock
// (core/time_mapping.hpp), extrapolating through underruns.
//
// Asserted: the emitted stream is continuous at the exact rate (one sample per
// grid tick from the first to the last), exactly the samples flagged exact
// are the smoother's own (identical to the batch result over the poses the
// receiver accepted), nothing is NaN/Inf, and the receiver's counters match
// the injected faults.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <deque>
#include <limits>
#include <optional>
#include <iostream>
#include <random>
#include <set>
#include <thread>

#include "core/live_emitter.hpp"
#include "core/reference_motion.hpp"
#include "core/so3.hpp"
#include "core/stream.hpp"
#include "core/time_mapping.hpp"
#include "io/pose_source.hpp"
#include "io/pose_wire.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_io_test_live_udp {
namespace imuemu { using namespace ::imuemu; }

using namespace imuemu;

namespace {

void sleep_until_monotonic(TimeNs due_ns) {
  timespec ts{static_cast<time_t>(due_ns / kNsPerSecond), static_cast<long>(due_ns % kNsPerSecond)};
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

bool identical(const live::Emission& e, const StreamSample& r) {
  return e.kinematics.t_ns == r.kinematics.t_ns && e.kinematics.position_m == r.kinematics.position_m &&
         e.kinematics.velocity_m_s == r.kinematics.velocity_m_s &&
         e.kinematics.acceleration_m_s2 == r.kinematics.acceleration_m_s2 &&
         e.kinematics.attitude == r.kinematics.attitude &&
         e.kinematics.angular_rate_rad_s == r.kinematics.angular_rate_rad_s && e.imu.gyro_rad_s == r.imu.gyro_rad_s &&
         e.imu.accel_m_s2 == r.imu.accel_m_s2;
}

}  // namespace

TEST(LiveUdp, DroppedAndReorderedDatagramsGiveAContinuousFlaggedStream) {
  // 120 s of a 20 m/s circle of radius 50 m (0.4 rad/s, heading through all
  // angles) with knots at 10 Hz, in the flat scene.
  const reference::Circle circle(50.0, 20.0, 0, 120 * kNsPerSecond);
  const std::vector<Pose> knots = reference::sample_knots(circle, kNsPerSecond / 10);
  const std::size_t n = knots.size();

  // 1% dropped, 1% swapped with their successor (never touching a dropped
  // one, nor the first or last three: the run's ends are not the question).
  std::mt19937_64 rng(20261122);
  std::set<std::size_t> dropped, reordered;
  const std::size_t faults = n / 100;
  std::uniform_int_distribution<std::size_t> pick(3, n - 5);
  while (dropped.size() < faults) dropped.insert(pick(rng));
  while (reordered.size() < faults) {
    const std::size_t i = pick(rng);
    bool clear = true;
    for (std::size_t j = i - 1; j <= i + 2; ++j) clear = clear && !dropped.count(j) && !reordered.count(j);
    if (clear) reordered.insert(i);
  }
  std::vector<std::size_t> send_order;
  for (std::size_t i = 0; i < n; ++i) {
    if (dropped.count(i)) continue;
    if (reordered.count(i)) {
      send_order.push_back(i + 1);
      send_order.push_back(i);
      ++i;
      continue;
    }
    send_order.push_back(i);
  }

  // Receiver.
  io::PoseSourceOptions so;
  so.physics = Physics::flat;
  so.queue_capacity = 4096;
  so.log = [](std::string_view) {};
  io::NetEndpoint ep;
  ep.address = "127.0.0.1";
  ep.receive_buffer_bytes = 1 << 20;
  std::unique_ptr<io::PoseSource> source = io::make_udp_pose_source(ep, so);
  source->start();
  const std::uint16_t port = source->local_port();
  ASSERT_NE(port, 0);

  // Engine and emitter: 400 Hz, a window of one knot interval (Delta = 40).
  PipelineOptions po;
  po.scene.physics = Physics::flat;
  po.rate_hz = 400;
  po.kernel.delta = 40;
  StreamPipeline engine(po);
  live::StreamSampleSource samples(engine);
  live::LiveEmitterOptions lo;
  lo.scene = po.scene;
  lo.underrun = live::UnderrunPolicy::extrapolate;
  lo.blend_ns = 100'000'000;
  live::LiveEmitter emitter(lo);

  // The sender replays in real time x20 (pose t leaves at T(t)). The emission
  // loop does not race it on the wall clock: for each tick it releases to the
  // engine exactly the poses a punctual receiver would have had by the tick's
  // deadline T(tick + look-ahead), the engine's worst-case look-ahead with no
  // margin, and waits for the datagrams themselves, not for a time. So a lost
  // knot (one more knot interval to wait) is an underrun whatever the host's
  // speed (ASan, a loaded machine): the verdict asserts what the engine
  // guarantees, not what a fast machine happens to produce. Delivery at the
  // exact rate in real time is the loopback tests' job (tests/loopback/).
  const live::SpeedFactor speed = live::make_speed_factor(20, 1);
  const TimeNs lookahead_ns = StreamPipeline::lookahead_ns(po, kNsPerSecond / 10);
  const live::TimeMapping sender_clock =
      live::TimeMapping::start_now(knots.front().t_ns, io::monotonic_now_ns() + 50'000'000, speed);
  std::atomic<bool> sender_done{false};
  std::thread sender([&] {
    const int fd = socket(AF_INET, SOCK_DGRAM, 0);
    sockaddr_in to{};
    to.sin_family = AF_INET;
    to.sin_port = htons(port);
    to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    for (std::size_t i : send_order) {
      // Each pose leaves when it is due; the earlier half of a swapped pair
      // right after the later one.
      sleep_until_monotonic(sender_clock.monotonic_at(knots[i].t_ns));
      io::PoseDatagram d;
      d.sequence = i;  // the pose's own number: a drop is a gap, a swap is late
      d.record.t_ns = knots[i].t_ns;
      d.record.position_kind = io::PositionKind::local_ned;
      d.record.position = knots[i].position_m;
      d.record.attitude_kind = io::AttitudeKind::quaternion;
      d.record.attitude = so3::quaternion_from_matrix(knots[i].attitude);
      const auto bytes = io::encode_pose_datagram(d);
      (void)sendto(fd, bytes.data(), bytes.size(), 0, reinterpret_cast<const sockaddr*>(&to), sizeof to);
    }
    close(fd);
    sender_done = true;
  });

  // The emission loop (the daemon's emission thread, with the hand-off inline).
  std::vector<Pose> accepted;
  std::vector<live::Emission> emitted;
  std::vector<TimeNs> ticks;
  const std::vector<TimeNs> grid = output_grid(knots.front().t_ns, knots.back().t_ns, po.rate_hz);
  bool finished = false;
  std::vector<io::SourcedPose> batch;
  std::deque<io::SourcedPose> received;  // arrived, not yet due at the engine
  TimeNs newest_received_ns = std::numeric_limits<TimeNs>::min();
  const auto all_accounted = [&] {
    const io::PoseSourceCounters c = source->counters();
    return sender_done && c.accepted + c.out_of_order == send_order.size() && source->queue().size() == 0;
  };
  const TimeNs give_up_at_ns = io::monotonic_now_ns() + 120 * kNsPerSecond;  // a broken receiver fails, not hangs
  std::optional<TimeNs> timed_out_at_tick;
  for (const TimeNs tick : grid) {
    const TimeNs due_ns = tick + lookahead_ns;
    // Wait until every datagram due by this tick's deadline has arrived: one
    // newer than the deadline was received, or the sender is done.
    for (;;) {
      batch.clear();
      source->queue().drain(batch);
      for (const io::SourcedPose& p : batch) {
        newest_received_ns = std::max(newest_received_ns, p.pose.t_ns);
        received.push_back(p);
      }
      if (newest_received_ns > due_ns || all_accounted()) break;
      if (io::monotonic_now_ns() > give_up_at_ns) break;
      std::this_thread::sleep_for(std::chrono::microseconds(200));
    }
    if (io::monotonic_now_ns() > give_up_at_ns) {
      timed_out_at_tick = tick;
      break;
    }
    while (!received.empty() && received.front().pose.t_ns <= due_ns) {
      engine.push(received.front().pose);  // the source already refused duplicates and out-of-order poses
      accepted.push_back(received.front().pose);
      received.pop_front();
    }
    if (!finished && received.empty() && all_accounted()) {
      engine.finish();  // end of input: the last look-ahead's worth comes out
      finished = true;
    }
    const live::Emission e = emitter.emit(tick, samples);
    if (e.has_sample()) {
      emitted.push_back(e);
      ticks.push_back(tick);
    }
  }
  sender.join();
  source->stop();
  ASSERT_FALSE(timed_out_at_tick) << "the datagrams due by tick " << *timed_out_at_tick << " ns never arrived";

  // Reference: the batch result over exactly the poses the engine accepted.
  const BatchResult reference = run_batch(accepted, po);
  const io::PoseSourceCounters c = source->counters();
  const live::LiveCounters& lc = emitter.counters();
  std::size_t exact = 0, flagged = 0, mismatched_flags = 0, non_finite = 0;
  for (std::size_t i = 0; i < emitted.size(); ++i) {
    const live::Emission& e = emitted[i];
    const auto k = static_cast<std::size_t>(std::lower_bound(reference.trajectory.begin(), reference.trajectory.end(), e.kinematics.t_ns,
                                                             [](const Kinematics& a, TimeNs t) { return a.t_ns < t; }) -
                                            reference.trajectory.begin());
    ASSERT_LT(k, reference.trajectory.size());
    const bool same = identical(e, {reference.trajectory[k], reference.imu[k]});
    if (e.exact()) ++exact;
    else ++flagged;
    if (e.exact() != same) ++mismatched_flags;
    if (!e.kinematics.position_m.allFinite() || !e.imu.gyro_rad_s.allFinite() || !e.imu.accel_m_s2.allFinite())
      ++non_finite;
  }
  std::cout << n << " poses, " << dropped.size() << " dropped, " << reordered.size() << " reordered; receiver: "
            << c.accepted << " accepted, " << c.out_of_order << " out of order, " << c.lost() << " lost; emitted "
            << emitted.size() << " of " << grid.size() << " ticks: " << exact << " exact, " << lc.extrapolated
            << " extrapolated, " << lc.blending << " blending (" << lc.underrun_events << " underruns), "
            << lc.waiting << " waiting before the first sample\n";
  // Counters match the injected faults.
  EXPECT_EQ(c.lost(), dropped.size());
  EXPECT_EQ(c.out_of_order, reordered.size());
  EXPECT_EQ(c.accepted, n - dropped.size() - reordered.size());
  EXPECT_EQ(c.rejected(), reordered.size());  // the late half of each swap, nothing else
  EXPECT_EQ(accepted.size(), c.accepted);
  // Continuous at the exact rate: every tick from the first sample on.
  ASSERT_FALSE(ticks.empty());
  const auto first = static_cast<std::size_t>(std::find(grid.begin(), grid.end(), ticks.front()) - grid.begin());
  EXPECT_EQ(ticks.size(), grid.size() - first);
  for (std::size_t i = 0; i < ticks.size(); ++i) {
    ASSERT_EQ(ticks[i], grid[first + i]);
    ASSERT_EQ(emitted[i].imu.t_ns, grid[first + i]);
  }
  EXPECT_EQ(ticks.back(), knots.back().t_ns);
  // The flags mark exactly the samples that are not the smoother's own.
  EXPECT_EQ(mismatched_flags, 0u);
  EXPECT_EQ(flagged, lc.extrapolated + lc.blending);
  EXPECT_GT(lc.underrun_events, 0u);  // the drops did starve the window
  EXPECT_EQ(non_finite, 0u);
}
}  // namespace unity_io_test_live_udp
