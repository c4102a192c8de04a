// The real-time emission engine (daemon/engine/emission.hpp): counts, grid, order and
// values against the batch pipeline, several devices on one thread, stopping
// at a packet boundary, the watchdog heartbeat and a starved producer.
// Timing on this shared machine is not asserted beyond "it was recorded":
// the assertions are on counts, order and values.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <mutex>
#include <nlohmann/json.hpp>
#include <thread>
#include <vector>

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <fstream>
#include <numbers>
#include <sstream>

#include "tests/support/spawn.hpp"
#include "core/attitude.hpp"
#include "core/fault/fault.hpp"
#include "core/mounting.hpp"
#include "core/signal_chain/increments.hpp"
#include "core/pipeline.hpp"
#include "core/reference_motion.hpp"
#include "daemon/device/device.hpp"
#include "daemon/engine/emission.hpp"
#include "drivers/byte_stream_reader.hpp"
#include "drivers/link_fault.hpp"
#include "drivers/protocols/can_protocols.hpp"
#include "drivers/protocols/stream_protocols.hpp"
#include "drivers/queued_writer.hpp"
#include "io/pose_source.hpp"
#include "io/scene_poses.hpp"
#include "io/trajectory_csv.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace imuemu::emission {}
namespace imuemu::drivers {}
namespace unity_engine_test_emission {
namespace imuemu { using namespace ::imuemu; }
namespace imuemu::emission { using namespace ::imuemu::emission; }
namespace imuemu::drivers { using namespace ::imuemu::drivers; }

namespace imuemu::emission {
namespace {

using namespace std::chrono_literals;

// Records every frame whole, with the device tag and the frame's order among
// all recording transports (a shared sequence), so tests can check the
// emission thread's merged order.
struct SharedLog {
  std::mutex mutex;
  std::vector<std::pair<int, std::size_t>> order;  // (device tag, frame index on that device)
};

class RecordingTransport final : public drivers::Transport {
 public:
  explicit RecordingTransport(int tag = 0, SharedLog* log = nullptr) : tag_(tag), log_(log) {}
  bool write_frame(std::span<const std::byte> frame) override {
    std::lock_guard lock(mutex_);
    const auto* p = reinterpret_cast<const std::uint8_t*>(frame.data());
    frames_.emplace_back(p, p + frame.size());
    ++counters_.frames;
    ++counters_.frames_sent;
    counters_.bytes += frame.size();
    counters_.bytes_sent += frame.size();
    if (log_ != nullptr) {
      std::lock_guard l(log_->mutex);
      log_->order.emplace_back(tag_, frames_.size() - 1);
    }
    return true;
  }
  std::string describe() const override { return "recording"; }
  drivers::TransportCounters counters() const override {
    std::lock_guard lock(mutex_);
    return counters_;
  }
  bool flush(std::chrono::milliseconds) override {
    flushes_.fetch_add(1);
    return true;
  }
  std::vector<std::vector<std::uint8_t>> frames() const {
    std::lock_guard lock(mutex_);
    return frames_;
  }
  int flushes() const { return flushes_.load(); }

 private:
  int tag_;
  SharedLog* log_;
  mutable std::mutex mutex_;
  std::vector<std::vector<std::uint8_t>> frames_;
  drivers::TransportCounters counters_;
  std::atomic<int> flushes_{0};
};

std::vector<Pose> circle_knots(double duration_s) {
  const reference::Circle circle(200.0, 20.0, 0, static_cast<TimeNs>(duration_s * 1e9));
  return reference::sample_knots(circle, kNsPerSecond);
}

PipelineOptions flat_pipeline(std::int64_t rate_hz) {
  PipelineOptions po;
  po.scene.physics = Physics::flat;
  po.rate_hz = rate_hz;
  po.kernel.delta = static_cast<int>(rate_hz);  // one knot interval, as generate's default
  return po;
}

// A device on a recording transport (not owned by the test: the engine owns it).
DeviceOptions native_device(const std::string& name, std::int64_t rate_hz, RecordingTransport** transport,
                            int tag = 0, SharedLog* log = nullptr,
                            std::unique_ptr<drivers::GpioSyncOutput> gpio = nullptr) {
  DeviceOptions d;
  d.name = name;
  d.rate_hz = rate_hz;
  d.pipeline = flat_pipeline(rate_hz);
  auto t = std::make_unique<RecordingTransport>(tag, log);
  *transport = t.get();
  d.device = device::make_stream_device(drivers::make_stream_encoder("native"), std::move(t), std::move(gpio));
  return d;
}

std::vector<drivers::DecodedSample> decode_native(const std::vector<std::vector<std::uint8_t>>& frames,
                                                  drivers::DecoderCounters* counters = nullptr) {
  auto decoder = drivers::make_stream_decoder("native");
  std::vector<drivers::DecodedSample> out;
  for (const auto& f : frames) decoder->feed(f, [&](const drivers::DecodedSample& s) { out.push_back(s); });
  if (counters != nullptr) *counters = decoder->counters();
  return out;
}

__extension__ typedef __int128 Int128;

TimeNs grid(TimeNs t0, std::uint64_t k, std::int64_t rate) {
  // Independent of the engine's split form: 128-bit floor(k * 1e9 / rate).
  return t0 + static_cast<TimeNs>(static_cast<Int128>(k) * kNsPerSecond / rate);
}

bool finite(const Vec3& v) { return std::isfinite(v.x()) && std::isfinite(v.y()) && std::isfinite(v.z()); }

TEST(LatenessHistogram, BucketsAreLogLinearFromOneMicrosecondToOneSecond) {
  EXPECT_EQ(LatenessHistogram::bucket_of(-5), 0u);
  EXPECT_EQ(LatenessHistogram::bucket_of(999), 0u);
  EXPECT_EQ(LatenessHistogram::bucket_of(1000), 1u);
  EXPECT_EQ(LatenessHistogram::bucket_of(1099), 1u);
  EXPECT_EQ(LatenessHistogram::bucket_of(1100), 2u);
  EXPECT_EQ(LatenessHistogram::bucket_of(kNsPerSecond), LatenessHistogram::kBuckets - 1);
  // Every value lies below its bucket's upper edge and at or above the previous edge.
  for (TimeNs v : {1'000LL, 1'234LL, 9'999LL, 10'000LL, 123'456LL, 5'000'000LL, 999'999'999LL}) {
    const std::size_t b = LatenessHistogram::bucket_of(v);
    EXPECT_LT(v, LatenessHistogram::upper_edge_ns(b)) << v;
    EXPECT_GE(v, LatenessHistogram::upper_edge_ns(b - 1)) << v;
    EXPECT_LE(LatenessHistogram::upper_edge_ns(b), v + v / 10 + 1) << "resolution 10% at worst, " << v;
  }
  LatenessHistogram h;
  for (int i = 0; i < 1000; ++i) h.record(i < 990 ? 2'000 : 500'000);  // 99% at 2 us, 1% at 500 us
  const LatenessSummary s = h.summary();
  EXPECT_EQ(s.count, 1000u);
  EXPECT_EQ(s.p50_ns, 2'100);
  EXPECT_EQ(s.p99_ns, 2'100);
  EXPECT_EQ(s.p999_ns, 500'000);  // bucket [500, 510) us capped by the exact maximum
  EXPECT_EQ(s.max_ns, 500'000);
}

// Issue 17: status pose_latency.buckets (the histogram against the goal):
// the non-empty buckets, in order, with their upper bounds in us, from
// values whose buckets follow from the definition (1 us..1 s, 90 per decade).
TEST(LatenessHistogram, NonEmptyBucketsGoToTheStatusJsonOfPoseLatencyOnly) {
  LatenessHistogram h;
  EXPECT_TRUE(h.buckets().empty());
  for (int i = 0; i < 7; ++i) h.record(4'050'000);  // [4.0, 4.1) ms
  for (int i = 0; i < 3; ++i) h.record(2'500'000);  // [2.5, 2.6) ms
  h.record(500);                                    // below 1 us
  h.record(12'345'678);                             // [12, 13) ms
  h.record(3 * kNsPerSecond);                       // overflow: bounded by the exact maximum
  const std::vector<LatenessBucket> b = h.buckets();
  const std::vector<LatenessBucket> expected{
      {1'000, 1}, {2'600'000, 3}, {4'100'000, 7}, {13'000'000, 1}, {3 * kNsPerSecond, 1}};
  EXPECT_EQ(b, expected);

  EngineStats s;
  DeviceStats d;
  d.name = "imu0";
  d.pose_latency = h.summary();
  d.pose_latency.buckets = b;
  d.lateness = h.summary();  // no buckets asked for
  s.devices.push_back(d);
  const nlohmann::json j = to_json(s);
  const nlohmann::json& pl = j["devices"][0]["pose_latency"];
  ASSERT_TRUE(pl.contains("buckets")) << pl.dump();
  ASSERT_EQ(pl["buckets"].size(), 5u);
  EXPECT_EQ(pl["buckets"][1]["upper_us"], 2600.0);
  EXPECT_EQ(pl["buckets"][1]["count"], 3u);
  EXPECT_EQ(pl["buckets"][2]["upper_us"], 4100.0);
  EXPECT_EQ(pl["buckets"][2]["count"], 7u);
  EXPECT_EQ(pl["buckets"][0]["upper_us"], 1.0);
  EXPECT_EQ(pl["buckets"][4]["upper_us"], 3e6);
  EXPECT_EQ(pl["count"], 13u);
  EXPECT_FALSE(j["devices"][0]["lateness"].contains("buckets"));
}

TEST(Emission, ExactCountOnTheGridAndBitIdenticalToBatch) {
  const std::vector<Pose> knots = circle_knots(10.0);
  RecordingTransport* rec = nullptr;
  std::vector<DeviceOptions> devices;
  devices.push_back(native_device("imu0", 400, &rec));
  EngineOptions eo;
  eo.trajectory = knots;
  eo.drop_late_ticks = false;  // a late wake-up on this shared machine still sends: counts stay exact
  eo.max_ticks_per_device = 800;  // 400 Hz x 2 s
  eo.ring_capacity = 1024;        // the whole run computed before the clock starts: counts do not depend on load
  EmissionEngine engine(std::move(eo), std::move(devices));
  engine.start();
  ASSERT_TRUE(engine.wait(10s));
  engine.stop();

  const BatchResult batch = run_batch(knots, flat_pipeline(400));
  drivers::DecoderCounters dc;
  const auto samples = decode_native(rec->frames(), &dc);
  ASSERT_EQ(samples.size(), 800u);
  EXPECT_EQ(dc.checksum_errors + dc.resync_bytes + dc.other_errors, 0u);
  for (std::size_t k = 0; k < samples.size(); ++k) {
    const drivers::DecodedSample& s = samples[k];
    ASSERT_TRUE(s.has_sequence && s.has_time);
    EXPECT_EQ(s.sequence, k);  // no gaps, in order
    EXPECT_EQ(s.t_ns, grid(knots.front().t_ns, k, 400));
    EXPECT_EQ(s.t_ns, batch.imu[k].t_ns);
    // The stream is the batch's loop: bit-identical for exact samples.
    EXPECT_EQ(s.gyro_rad_s, batch.imu[k].gyro_rad_s) << k;
    EXPECT_EQ(s.accel_m_s2, batch.imu[k].accel_m_s2) << k;
    EXPECT_EQ(s.status & drivers::kStatusExtrapolated, 0u);
    if (k > 0) {
      // The native frame carries the raw integrals over the period ending at
      // t_k (docs/emission.md), of the batch trajectory between its samples
      // k - 1 and k: bit-identical to the batch's own interval.
      const double dt = 1.0 / 400.0;
      const signal_chain::HermiteInterval interval(batch.trajectory[k - 1], batch.trajectory[k], dt);
      const signal_chain::Increment raw = signal_chain::raw_increment(flat_pipeline(400).scene, interval, dt);
      EXPECT_EQ(s.delta_theta_rad, raw.delta_theta_rad) << k;
      EXPECT_EQ(s.delta_velocity_m_s, raw.delta_velocity_m_s) << k;
      // And within the trapezoid's own error (h^3/12 |omega''|, far below
      // 1e-9 for this slow circle) of the trapezoid of the samples.
      EXPECT_NEAR((s.delta_theta_rad - 0.5 * dt * (batch.imu[k - 1].gyro_rad_s + batch.imu[k].gyro_rad_s)).norm(), 0.0, 1e-9);
      EXPECT_NEAR((s.delta_velocity_m_s - 0.5 * dt * (batch.imu[k - 1].accel_m_s2 + batch.imu[k].accel_m_s2)).norm(), 0.0, 1e-9);
    }
  }
  const EngineStats st = engine.stats();
  ASSERT_EQ(st.devices.size(), 1u);
  const DeviceStats& d = st.devices[0];
  EXPECT_TRUE(st.finished);
  EXPECT_EQ(d.ticks, 800u);
  EXPECT_EQ(d.emitted, 800u);
  EXPECT_EQ(d.exact, 800u);
  EXPECT_EQ(d.producer_late, 0u);
  EXPECT_EQ(d.packets, 800u);
  EXPECT_EQ(d.lateness.count, 800u);  // every wake-up recorded
  EXPECT_GE(d.lateness.max_ns, d.lateness.p50_ns);
  EXPECT_EQ(d.last_sample_counter, 799u);
  EXPECT_EQ(rec->flushes(), 1);
  const nlohmann::json j = to_json(st);
  EXPECT_EQ(j["devices"][0]["emitted"], 800u);
  EXPECT_TRUE(j["devices"][0]["lateness"].contains("p99_9_ns"));
}

// A device mounted off the reference point and rotated: it must emit what a
// rigid body's sensor there measures. Independent truth: the body IMU
// (batch) carried over by the rigid-body formulas, omega_s = C^T omega_b and
// f_s = C^T (f_b + omega_b' x l + omega_b x (omega_b x l)) (the circle's
// omega_b is constant, so omega_b' = 0), which the engine never evaluates:
// it smooths and differentiates the sensor's own poses (core/mounting.hpp).
TEST(Emission, MountedDeviceMeasuresTheLeverArmAndTheAxisRotation) {
  const std::vector<Pose> knots = circle_knots(12.0);
  RecordingTransport* rec = nullptr;
  std::vector<DeviceOptions> devices;
  devices.push_back(native_device("imu0", 200, &rec));
  Mounting m;
  m.lever_arm_b_m = Vec3(1.2, -0.3, -0.4);
  m.sensor_to_body = attitude::rotation_from_hpr({std::numbers::pi / 2, 0.0, std::numbers::pi});  // x right, upside down
  devices.front().mounting = m;
  EngineOptions eo;
  eo.trajectory = knots;
  eo.drop_late_ticks = false;
  eo.max_ticks_per_device = 2000;  // 10 s at 200 Hz
  eo.ring_capacity = 4096;
  EmissionEngine engine(std::move(eo), std::move(devices));
  engine.start();
  ASSERT_TRUE(engine.wait(20s));
  engine.stop();
  const auto samples = decode_native(rec->frames());
  ASSERT_EQ(samples.size(), 2000u);

  const BatchResult body = run_batch(knots, flat_pipeline(200));
  std::vector<Pose> sensor_knots;
  for (const Pose& p : knots) sensor_knots.push_back(sensor_pose(p, m));
  const BatchResult sensor = run_batch(sensor_knots, flat_pipeline(200));
  const Mat3 Ct = m.sensor_to_body.transpose();
  double worst_gyro = 0.0, worst_accel = 0.0;
  for (std::size_t k = 400; k < 1600; ++k) {  // away from the one-sided ends
    const Vec3 w = body.imu[k].gyro_rad_s;
    const Vec3 f_rigid = body.imu[k].accel_m_s2 + w.cross(w.cross(m.lever_arm_b_m));
    worst_gyro = std::max(worst_gyro, (samples[k].gyro_rad_s - Ct * w).norm());
    worst_accel = std::max(worst_accel, (samples[k].accel_m_s2 - Ct * f_rigid).norm());
    // And it is exactly the pipeline over the sensor's poses.
    EXPECT_EQ(samples[k].gyro_rad_s, sensor.imu[k].gyro_rad_s) << k;
    EXPECT_EQ(samples[k].accel_m_s2, sensor.imu[k].accel_m_s2) << k;
  }
  std::printf("mounted device vs rigid-body formulas: worst gyro %.3e rad/s, accel %.3e m/s^2 "
              "(centripetal term %.3f m/s^2)\n",
              worst_gyro, worst_accel, (body.imu[1000].gyro_rad_s.cross(body.imu[1000].gyro_rad_s.cross(m.lever_arm_b_m))).norm());
  EXPECT_LT(worst_gyro, 1e-9);
  // The sensor point's own path is a circle of radius |l| about the body
  // point, interpolated from the 1 Hz knots like any other: a cubic on an arc
  // of theta = omega x 1 s errs in acceleration by ~ |l| omega^2 theta^2
  // (1.3e-4 m/s^2 here), the price of smoothing the sensor's poses rather
  // than adding the lever-arm terms afterwards (which would not integrate
  // back to the sensor's trajectory). Ignoring the lever arm errs by the
  // centripetal term, 0.012 m/s^2, ninety times the bound.
  const double omega = 20.0 / 200.0, theta = omega * 1.0;
  const double bound = m.lever_arm_b_m.norm() * omega * omega * theta * theta;
  EXPECT_LT(worst_accel, bound);
  EXPECT_GT((body.imu[1000].gyro_rad_s.cross(body.imu[1000].gyro_rad_s.cross(m.lever_arm_b_m))).norm(), 50 * bound);
}

TEST(Emission, WithoutALimitEmitsTheWholeTrajectoryGrid) {
  const std::vector<Pose> knots = circle_knots(2.0);  // knots at 0, 1, 2 s
  RecordingTransport* rec = nullptr;
  std::vector<DeviceOptions> devices;
  devices.push_back(native_device("imu0", 100, &rec));
  EngineOptions eo;
  eo.trajectory = knots;
  eo.drop_late_ticks = false;  // a late wake-up on this shared machine still sends: counts stay exact
  eo.ring_capacity = 256;      // the whole run computed before the clock starts: counts do not depend on load
  EmissionEngine engine(std::move(eo), std::move(devices));
  engine.start();
  ASSERT_TRUE(engine.wait(10s));
  engine.stop();
  const auto samples = decode_native(rec->frames());
  const auto batch_grid = output_grid(knots.front().t_ns, knots.back().t_ns, 100);
  ASSERT_EQ(samples.size(), batch_grid.size());  // 201: both ends included
  EXPECT_EQ(samples.back().t_ns, batch_grid.back());
}

TEST(Emission, TwoDevicesAtDifferentRatesOnOneThread) {
  const std::vector<Pose> knots = circle_knots(10.0);
  SharedLog log;
  RecordingTransport* slow = nullptr;
  RecordingTransport* fast = nullptr;
  std::vector<DeviceOptions> devices;
  devices.push_back(native_device("slow", 400, &slow, 0, &log));
  devices.push_back(native_device("fast", 1000, &fast, 1, &log));
  EngineOptions eo;
  eo.trajectory = knots;
  eo.drop_late_ticks = false;  // a late wake-up on this shared machine still sends: counts stay exact
  eo.ring_capacity = 2048;  // all computed before the clock starts
  EmissionEngine engine(std::move(eo), std::move(devices));
  engine.start();
  std::this_thread::sleep_for(1200ms);
  engine.stop();
  const auto slow_samples = decode_native(slow->frames());
  const auto fast_samples = decode_native(fast->frames());
  ASSERT_GT(slow_samples.size(), 100u);
  ASSERT_GT(fast_samples.size(), 250u);
  // Each device on its own grid with no gaps.
  for (std::size_t k = 0; k < slow_samples.size(); ++k) {
    EXPECT_EQ(slow_samples[k].sequence, k);
    EXPECT_EQ(slow_samples[k].t_ns, grid(0, k, 400));
  }
  for (std::size_t k = 0; k < fast_samples.size(); ++k) {
    EXPECT_EQ(fast_samples[k].sequence, k);
    EXPECT_EQ(fast_samples[k].t_ns, grid(0, k, 1000));
  }
  // One timeline: the merged write order is the order of the sample times.
  TimeNs previous = -1;
  for (const auto& [tag, index] : log.order) {
    const TimeNs t = tag == 0 ? slow_samples.at(index).t_ns : fast_samples.at(index).t_ns;
    EXPECT_GE(t, previous);
    previous = t;
  }
  // Rates in the ratio 2:5 (both stopped at the same instant: within one tick).
  const double ratio = static_cast<double>(fast_samples.size()) / static_cast<double>(slow_samples.size());
  EXPECT_NEAR(ratio, 2.5, 5.0 / static_cast<double>(slow_samples.size()));
}

TEST(Emission, TwoDevicesEachWithItsExactCount) {
  const std::vector<Pose> knots = circle_knots(10.0);
  RecordingTransport* slow = nullptr;
  std::vector<DeviceOptions> devices;
  devices.push_back(native_device("slow", 400, &slow));
  DeviceOptions null_dev;
  null_dev.name = "fast";
  null_dev.rate_hz = 1000;
  null_dev.pipeline = flat_pipeline(1000);
  null_dev.device = device::make_stream_device(drivers::make_stream_encoder("mavlink2"),
                                               std::make_unique<drivers::NullTransport>());
  devices.push_back(std::move(null_dev));
  EngineOptions eo;
  eo.trajectory = knots;
  eo.drop_late_ticks = false;  // a late wake-up on this shared machine still sends: counts stay exact
  eo.max_ticks_per_device = 1000;  // 2.5 s at 400 Hz, 1 s at 1000 Hz
  eo.ring_capacity = 1024;
  EmissionEngine engine(std::move(eo), std::move(devices));
  engine.start();
  ASSERT_TRUE(engine.wait(10s));
  engine.stop();
  const EngineStats st = engine.stats();
  ASSERT_EQ(st.devices.size(), 2u);
  EXPECT_EQ(st.devices[0].emitted, 1000u);
  EXPECT_EQ(st.devices[1].emitted, 1000u);
  EXPECT_EQ(st.devices[1].packets, 1000u);
  EXPECT_EQ(st.emitted, 2000u);
  EXPECT_EQ(st.lateness.count, 2000u);
  EXPECT_EQ(decode_native(slow->frames()).size(), 1000u);
}

TEST(Emission, StopsAtAPacketBoundaryFlushesAndReleasesGpio) {
  const std::vector<Pose> knots = circle_knots(30.0);
  RecordingTransport* rec = nullptr;
  std::mutex gpio_mutex;
  std::vector<bool> levels;
  drivers::GpioSyncOptions go;
  go.every_n_samples = 4;
  go.pulse_width_ns = 200'000;
  go.sample_period_ns = kNsPerSecond / 400;
  std::vector<DeviceOptions> devices;
  devices.push_back(native_device("imu0", 400, &rec, 0, nullptr,
                                  std::make_unique<drivers::GpioSyncOutput>(
                                      go,
                                      [&](bool active) {
                                        std::lock_guard lock(gpio_mutex);
                                        levels.push_back(active);
                                        return true;
                                      },
                                      drivers::GpioSyncOutput::LineWriter{})));
  EngineOptions eo;
  eo.trajectory = knots;
  eo.drop_late_ticks = false;  // a late wake-up on this shared machine still sends: counts stay exact
  EmissionEngine engine(std::move(eo), std::move(devices));
  engine.start();
  std::this_thread::sleep_for(300ms);
  engine.request_stop();
  engine.stop();
  const std::uint64_t emitted_at_stop = engine.stats().devices[0].emitted;
  std::this_thread::sleep_for(50ms);
  const EngineStats st = engine.stats();
  EXPECT_EQ(st.devices[0].emitted, emitted_at_stop);  // nothing after stop
  EXPECT_FALSE(st.finished);
  drivers::DecoderCounters dc;
  const auto frames = rec->frames();
  const auto samples = decode_native(frames, &dc);
  ASSERT_GT(samples.size(), 10u);
  EXPECT_EQ(samples.size(), frames.size());  // every frame whole: no partial packet
  EXPECT_EQ(samples.size(), st.devices[0].emitted);
  EXPECT_EQ(dc.checksum_errors + dc.resync_bytes + dc.other_errors, 0u);
  for (std::size_t k = 0; k < samples.size(); ++k) EXPECT_EQ(samples[k].sequence, k);
  EXPECT_EQ(rec->flushes(), 1);
  ASSERT_TRUE(st.devices[0].gpio.has_value());
  // A pulse on samples 0, 4, 8, ... (one due while the previous had not ended,
  // the trailing-edge thread being late on this shared machine, is skipped and counted).
  EXPECT_EQ(st.devices[0].gpio->pulses + st.devices[0].gpio->skipped_pulses, (samples.size() + 3) / 4);
  std::lock_guard lock(gpio_mutex);
  ASSERT_FALSE(levels.empty());
  EXPECT_FALSE(levels.back());  // released inactive
}

TEST(Emission, StalledEmissionThreadStopsTheHeartbeat) {
  const std::vector<Pose> knots = circle_knots(30.0);
  std::vector<DeviceOptions> devices;
  DeviceOptions d;
  d.rate_hz = 200;
  d.pipeline = flat_pipeline(200);
  d.device = device::make_stream_device(drivers::make_stream_encoder("native"), std::make_unique<drivers::NullTransport>());
  devices.push_back(std::move(d));
  EngineOptions eo;
  eo.trajectory = knots;
  EmissionEngine engine(std::move(eo), std::move(devices));
  EXPECT_EQ(engine.last_progress_ns(), 0);
  EXPECT_FALSE(engine.healthy(monotonic_now_ns(), kNsPerSecond));
  engine.start();
  std::this_thread::sleep_for(200ms);
  EXPECT_TRUE(engine.healthy(monotonic_now_ns(), kNsPerSecond));
  engine.set_emission_stall_for_test(true);
  std::this_thread::sleep_for(100ms);  // the tick in progress finishes
  const TimeNs stalled_at = engine.last_progress_ns();
  const std::uint64_t emitted_stalled = engine.stats().devices[0].emitted;
  std::this_thread::sleep_for(400ms);
  EXPECT_EQ(engine.last_progress_ns(), stalled_at);
  EXPECT_EQ(engine.stats().devices[0].emitted, emitted_stalled);
  EXPECT_FALSE(engine.healthy(monotonic_now_ns(), 300'000'000));
  engine.set_emission_stall_for_test(false);
  std::this_thread::sleep_for(200ms);
  EXPECT_GT(engine.last_progress_ns(), stalled_at);
  EXPECT_TRUE(engine.healthy(monotonic_now_ns(), 300'000'000));
  engine.stop();
  // The ticks whose deadlines passed during the stall are late, not sent late in a burst beyond one period.
  EXPECT_GT(engine.stats().devices[0].deadline_misses, 0u);
}

TEST(Emission, StarvedProducerCountsLateTicksAndSendsNothingNonFinite) {
  const std::vector<Pose> knots = circle_knots(10.0);
  RecordingTransport* rec = nullptr;
  std::vector<DeviceOptions> devices;
  devices.push_back(native_device("imu0", 400, &rec));
  EngineOptions eo;
  eo.trajectory = knots;
  eo.ring_capacity = 16;            // 40 ms computed ahead
  eo.max_ticks_per_device = 400;    // 1 s
  EmissionEngine engine(std::move(eo), std::move(devices));
  engine.set_producer_stall_for_test(true);  // the prefill of start() still happens
  engine.start();
  std::this_thread::sleep_for(300ms);
  engine.set_producer_stall_for_test(false);
  ASSERT_TRUE(engine.wait(10s));
  engine.stop();
  const DeviceStats st = engine.stats().devices[0];
  EXPECT_EQ(st.ticks, 400u);
  // >= 260 ms of 2.5 ms ticks starved. On a loaded host the emitter thread
  // itself can wake more than a period late for some of them, which counts
  // them as dropped_late instead: either way they are counted, never sent.
  EXPECT_GT(st.producer_late + st.dropped_late, 50u);
  EXPECT_EQ(st.emitted + st.producer_late + st.dropped_late, 400u);
  const auto samples = decode_native(rec->frames());
  ASSERT_EQ(samples.size(), st.emitted);
  const BatchResult batch = run_batch(knots, flat_pipeline(400));
  std::uint64_t previous = 0;
  for (std::size_t i = 0; i < samples.size(); ++i) {
    const drivers::DecodedSample& s = samples[i];
    if (i > 0) {
      EXPECT_GT(s.sequence, previous);  // gaps allowed, never out of order
    }
    previous = s.sequence;
    EXPECT_EQ(s.t_ns, grid(0, s.sequence, 400));
    EXPECT_TRUE(finite(s.gyro_rad_s) && finite(s.accel_m_s2) && finite(s.delta_theta_rad) && finite(s.delta_velocity_m_s));
    EXPECT_EQ(s.gyro_rad_s, batch.imu[s.sequence].gyro_rad_s);  // late ticks skipped, the others still exact
  }
  // The first ticks had prefilled samples (ring of 16); on a loaded host the
  // emitter itself may wake late for the very first and count it dropped_late
  // (CI's ASan run: first sent sequence 1), so any of those may be first.
  EXPECT_LT(samples.front().sequence, 16u);
  // Caught up after the starvation (ticks 16.. ~120 had nothing): later ticks go out again.
  EXPECT_GT(samples.back().sequence, 200u);
}

// Pose lines (docs/pose-wire-format.md) of a local NED trajectory.
std::string pose_lines(const std::vector<Pose>& knots) {
  std::string text = "time_s,north_m,east_m,down_m,heading_deg,pitch_deg,roll_deg\n";
  char line[256];
  for (const Pose& p : knots) {
    const attitude::HeadingPitchRoll hpr = attitude::hpr_from_rotation(p.attitude);
    const double deg = 180.0 / std::numbers::pi;
    std::snprintf(line, sizeof line, "%lld.%09lld,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g\n",
                  static_cast<long long>(p.t_ns / kNsPerSecond), static_cast<long long>(p.t_ns % kNsPerSecond),
                  p.position_m.x(), p.position_m.y(), p.position_m.z(), hpr.heading_rad * deg, hpr.pitch_rad * deg,
                  hpr.roll_rad * deg);
    text += line;
  }
  return text;
}

TEST(Emission, LivePoseSourceEmitsToTheEndOfTheInputAsTheBatchDoes) {
  const std::string text = pose_lines(circle_knots(3.0));
  // The reference: the same lines read as a file, through the batch pipeline.
  const std::string path = ::testing::TempDir() + "emission_live_poses.csv";
  std::ofstream(path) << text;
  const std::vector<Pose> parsed = io::poses_in_scene(io::read_trajectory_csv(path), Physics::flat);
  std::remove(path.c_str());
  ASSERT_EQ(parsed.size(), 4u);
  int fds[2];
  ASSERT_EQ(::pipe(fds), 0);
  ASSERT_EQ(::write(fds[1], text.data(), text.size()), static_cast<ssize_t>(text.size()));
  ::close(fds[1]);  // end of input after the four poses
  io::PoseSourceOptions so;
  so.physics = Physics::flat;
  so.log = [](std::string_view) {};
  auto source = io::make_fd_pose_source(fds[0], so);

  RecordingTransport* rec = nullptr;
  std::vector<DeviceOptions> devices;
  devices.push_back(native_device("imu0", 100, &rec));
  EngineOptions eo;
  eo.source = source.get();
  eo.emit_delay_ns = 300'000'000;  // every pose is there at once: a short delay suffices
  eo.drop_late_ticks = false;
  EmissionEngine engine(std::move(eo), std::move(devices));
  engine.start();
  ASSERT_TRUE(engine.wait(20s));  // ends by itself at the end of the input
  engine.stop();
  ::close(fds[0]);

  const BatchResult batch = run_batch(parsed, flat_pipeline(100));
  const EngineStats st = engine.stats();
  const DeviceStats& d = st.devices[0];
  EXPECT_EQ(d.ticks, batch.imu.size());  // 301: the grid from the first to the last pose
  EXPECT_EQ(d.ticks, d.emitted + d.producer_late + d.not_sent);
  EXPECT_EQ(d.extrapolated + d.blending, 0u);
  ASSERT_TRUE(st.pose_source.has_value());
  EXPECT_EQ(st.pose_source->accepted, 4u);
  EXPECT_EQ(st.poses_pushed, 4u);
  const auto samples = decode_native(rec->frames());
  ASSERT_EQ(samples.size(), d.emitted);
  ASSERT_GT(samples.size(), 250u);
  for (const drivers::DecodedSample& s : samples) {
    ASSERT_LT(s.sequence, batch.imu.size());
    EXPECT_EQ(s.t_ns, batch.imu[s.sequence].t_ns);
    EXPECT_EQ(s.gyro_rad_s, batch.imu[s.sequence].gyro_rad_s);
    EXPECT_EQ(s.accel_m_s2, batch.imu[s.sequence].accel_m_s2);
  }
}

// Issue 17: with live input the producer sleeps on the pose queue until a
// pose arrives or its next tick may be computed; it no longer polls the
// queue every 1 ms. The queue counts how each of its waits ended. Nothing
// here depends on the host being fast: load makes waits end later, hence
// fewer, never more; and a push can end a sleep early only if it notifies.
TEST(Emission, LiveProducerSleepsOnThePoseQueueUntilAPoseArrivesOrItsNextTick) {
  const std::vector<Pose> knots = circle_knots(8.0);  // 9 poses, 1 s apart
  std::vector<std::string> lines;
  {
    std::istringstream in(pose_lines(knots));
    for (std::string line; std::getline(in, line);) lines.push_back(line + "\n");
  }
  ASSERT_EQ(lines.size(), 10u);  // header + 9
  int fds[2];
  ASSERT_EQ(::pipe(fds), 0);
  auto write_line = [&](std::size_t i) {
    ASSERT_EQ(::write(fds[1], lines[i].data(), lines[i].size()), static_cast<ssize_t>(lines[i].size()));
  };
  io::PoseSourceOptions so;
  so.physics = Physics::flat;
  so.log = [](std::string_view) {};
  auto source = io::make_fd_pose_source(fds[0], so);
  RecordingTransport* rec = nullptr;
  std::vector<DeviceOptions> devices;
  devices.push_back(native_device("imu0", 10, &rec));
  EngineOptions eo;
  eo.source = source.get();
  eo.emit_delay_ns = 120 * kNsPerSecond;  // no tick comes due during the test: the producer's deadline is far
  EmissionEngine engine(std::move(eo), std::move(devices));
  engine.start();
  auto wait_for_poses = [&](std::uint64_t n) {
    for (int i = 0; i < 2000 && engine.stats().poses_pushed < n; ++i) std::this_thread::sleep_for(10ms);
    return engine.stats().poses_pushed;
  };
  write_line(0);
  write_line(1);
  write_line(2);  // the stream is acquired at its second pose
  ASSERT_EQ(wait_for_poses(2), 2u);

  // Idle for 1 s: polling every 1 ms woke the producer ~1000 times; sleeping
  // to its next tick (2 min away), bounded by the 50 ms stop/stall check, ~20.
  const io::PoseQueue::WaitCounters before = source->queue().wait_counters();
  std::this_thread::sleep_for(1s);
  const io::PoseQueue::WaitCounters idle = source->queue().wait_counters();
  EXPECT_LE(idle.total() - before.total(), 60u);
  EXPECT_GE(idle.deadline - before.deadline, 1u);  // it does sleep on the queue
  EXPECT_EQ(idle.woken_by_push + idle.items_on_entry, before.woken_by_push + before.items_on_entry);

  // Five more poses, one at a time: each is taken (counted by the engine),
  // and pushes end the producer's sleep before its deadline. Each sleep is
  // at most 50 ms, so a host that wakes the producer that late may see its
  // deadline first: at least one of five must be a push's wake-up (none
  // without the notification).
  for (std::size_t i = 3; i < 8; ++i) {
    write_line(i);
    ASSERT_EQ(wait_for_poses(i), i);
  }
  const io::PoseQueue::WaitCounters fed = source->queue().wait_counters();
  EXPECT_GE(fed.woken_by_push - idle.woken_by_push, 1u);
  EXPECT_LE(fed.woken_by_push - idle.woken_by_push, 5u);
  EXPECT_EQ(engine.stats().devices[0].emitted, 0u);  // nothing was due

  engine.stop();
  ::close(fds[1]);
  ::close(fds[0]);
}

class RecordingCanOutput final : public device::CanOutput {
 public:
  bool send(const drivers::CanFrame& frame) override {
    std::lock_guard lock(mutex_);
    frames_.push_back(frame);
    ++counters_.frames;
    ++counters_.frames_sent;
    counters_.bytes += frame.len;
    return true;
  }
  std::string describe() const override { return "recording can"; }
  drivers::TransportCounters counters() const override {
    std::lock_guard lock(mutex_);
    return counters_;
  }
  std::vector<drivers::CanFrame> frames() const {
    std::lock_guard lock(mutex_);
    return frames_;
  }

 private:
  mutable std::mutex mutex_;
  std::vector<drivers::CanFrame> frames_;
  drivers::TransportCounters counters_;
};

TEST(Emission, CanDeviceSendsEveryTickAsDroneCanFrames) {
  const std::vector<Pose> knots = circle_knots(5.0);
  std::vector<DeviceOptions> devices;
  DeviceOptions d;
  d.name = "can0";
  d.rate_hz = 100;
  d.pipeline = flat_pipeline(100);
  auto out = std::make_unique<RecordingCanOutput>();
  RecordingCanOutput* rec = out.get();
  d.device = device::make_can_device(drivers::make_can_encoder("dronecan"), std::move(out));
  devices.push_back(std::move(d));
  EngineOptions eo;
  eo.trajectory = knots;
  eo.max_ticks_per_device = 200;
  eo.drop_late_ticks = false;
  eo.ring_capacity = 256;
  EmissionEngine engine(std::move(eo), std::move(devices));
  engine.start();
  ASSERT_TRUE(engine.wait(10s));
  engine.stop();
  auto decoder = drivers::make_can_decoder("dronecan");
  std::vector<drivers::DecodedSample> samples;
  for (const drivers::CanFrame& f : rec->frames())
    decoder->feed(f, [&](const drivers::DecodedSample& s) { samples.push_back(s); });
  const BatchResult batch = run_batch(knots, flat_pipeline(100));
  ASSERT_EQ(samples.size(), 200u);
  EXPECT_EQ(engine.stats().devices[0].emitted, 200u);
  for (std::size_t k = 0; k < samples.size(); ++k) {
    if (k > 0) {
      EXPECT_EQ(samples[k].sequence, samples[k - 1].sequence + 1);
      EXPECT_EQ(samples[k].t_ns, batch.imu[k].t_ns - batch.imu[k].t_ns % 1000);  // microsecond timestamps
    }
    // float16 on the wire: 2^-11 relative.
    EXPECT_NEAR(samples[k].gyro_rad_s.z(), batch.imu[k].gyro_rad_s.z(), 1e-3 * std::abs(batch.imu[k].gyro_rad_s.z()) + 1e-4);
    EXPECT_NEAR(samples[k].accel_m_s2.y(), batch.imu[k].accel_m_s2.y(), 1e-3 * std::abs(batch.imu[k].accel_m_s2.y()) + 1e-3);
  }
}

TEST(Emission, RejectsBadConfigurationNamingTheDevice) {
  std::vector<DeviceOptions> devices;
  DeviceOptions d;
  d.name = "left";
  d.rate_hz = 0;
  d.device = device::make_stream_device(drivers::make_stream_encoder("native"), std::make_unique<drivers::NullTransport>());
  devices.push_back(std::move(d));
  EngineOptions eo;
  eo.trajectory = circle_knots(3.0);
  try {
    EmissionEngine engine(std::move(eo), std::move(devices));
    FAIL() << "rate 0 accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("'left'"), std::string::npos) << e.what();
  }
  std::vector<DeviceOptions> no_output(1);
  EngineOptions eo2;
  eo2.trajectory = circle_knots(3.0);
  EXPECT_THROW(EmissionEngine(std::move(eo2), std::move(no_output)), std::invalid_argument);
}

// `imuemu emit` end to end: a pty read by this test, decoded, compared with the
// batch pipeline on the same file (what `imuemu generate` writes).
class EmitCommand : public ::testing::Test {
 protected:
  void SetUp() override {
    char tmpl[] = "/tmp/imuemu-test-emit-XXXXXX";
    ASSERT_NE(::mkdtemp(tmpl), nullptr);
    dir_ = tmpl;
    const std::string cmd = std::string(IMUEMU_CLI_PATH) + " sample-trajectory --kind circle --duration-s 30 --out " +
                            dir_ + "/traj.csv";
    ASSERT_EQ(std::system(cmd.c_str()), 0);
  }
  void TearDown() override { std::system(("rm -rf " + dir_).c_str()); }

  pid_t spawn(const std::vector<std::string>& args) {
    return ::imuemu::test::spawn_logged(IMUEMU_CLI_PATH, args, dir_ + "/emit.log");
  }
  static int exit_status(pid_t pid) {
    int status = 0;
    ::waitpid(pid, &status, 0);
    return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  }
  nlohmann::json stats() const {
    std::ifstream in(dir_ + "/stats.json");
    return nlohmann::json::parse(in);
  }
  std::string dir_;
};

TEST_F(EmitCommand, PtySamplesEqualTheBatchAndSigtermStopsWithASummary) {
  const pid_t pid = spawn({"emit", "--trajectory", dir_ + "/traj.csv", "--scene", "flat", "--rate", "200", "--device",
                           "pty:" + dir_ + "/tty", "--stats-json", dir_ + "/stats.json"});
  ASSERT_GT(pid, 0);
  for (int i = 0; i < 500 && ::access((dir_ + "/tty").c_str(), F_OK) != 0; ++i) std::this_thread::sleep_for(10ms);
  std::vector<drivers::DecodedSample> samples;
  {
    drivers::ByteStreamReader reader(dir_ + "/tty");
    auto decoder = drivers::make_stream_decoder("native");
    std::vector<std::uint8_t> buffer(4096);
    // Until 300 samples (1.5 s at 200 Hz) are in, however slow the host is
    // to start the emitter; the 60-s bound only turns a hang into a failure.
    const auto until = std::chrono::steady_clock::now() + 60s;
    while (samples.size() < 300 && std::chrono::steady_clock::now() < until) {
      const drivers::ReadResult r = reader.read_some(buffer, 100ms);
      if (r.end_of_stream) break;
      decoder->feed(std::span<const std::uint8_t>(buffer.data(), r.bytes),
                    [&](const drivers::DecodedSample& s) { samples.push_back(s); });
    }
    EXPECT_EQ(decoder->counters().checksum_errors, 0u);
  }
  ASSERT_EQ(::kill(pid, SIGTERM), 0);
  EXPECT_EQ(exit_status(pid), 0);
  const nlohmann::json j = stats();
  EXPECT_FALSE(j["finished"].get<bool>());
  EXPECT_GE(j["devices"][0]["emitted"].get<std::uint64_t>(), samples.size());

  const std::vector<Pose> knots = io::poses_in_scene(io::read_trajectory_csv(dir_ + "/traj.csv"), Physics::flat);
  const BatchResult batch = run_batch(knots, flat_pipeline(200));
  ASSERT_GT(samples.size(), 50u);
  for (std::size_t i = 0; i < samples.size(); ++i) {
    const drivers::DecodedSample& s = samples[i];
    if (i > 0) {
      EXPECT_GT(s.sequence, samples[i - 1].sequence);  // a tick dropped after a deadline miss leaves a gap
    }
    ASSERT_LT(s.sequence, batch.imu.size());
    EXPECT_EQ(s.t_ns, batch.imu[s.sequence].t_ns);
    EXPECT_EQ(s.gyro_rad_s, batch.imu[s.sequence].gyro_rad_s);
    EXPECT_EQ(s.accel_m_s2, batch.imu[s.sequence].accel_m_s2);
  }
}

TEST_F(EmitCommand, SecondsLimitsTheTicksToRateTimesSeconds) {
  const pid_t pid = spawn({"emit", "--sample", "static", "--duration-s", "10", "--rate", "250", "--seconds", "1.5",
                           "--device", "pty:" + dir_ + "/tty", "--stats-json", dir_ + "/stats.json"});
  EXPECT_EQ(exit_status(pid), 0);
  const nlohmann::json d = stats()["devices"][0];
  EXPECT_EQ(d["ticks"].get<std::uint64_t>(), 375u);
  EXPECT_EQ(d["emitted"].get<std::uint64_t>() + d["dropped_late"].get<std::uint64_t>() +
                d["underruns"].get<std::uint64_t>(),
            375u);
  EXPECT_TRUE(stats()["finished"].get<bool>());
}

TEST_F(EmitCommand, RefusesAMismatchedProtocolAndDevice) {
  EXPECT_EQ(exit_status(spawn({"emit", "--sample", "static", "--protocol", "dronecan", "--device", "pty:" + dir_ + "/x"})), 2);
  EXPECT_EQ(exit_status(spawn({"emit", "--trajectory", dir_ + "/missing.csv", "--device", "pty:" + dir_ + "/x"})), 3);
}

// The device seam (daemon/device/device.hpp): what emit() puts on the wire
// is what drivers::encode_with_link_faults gives for the sample and its link
// actions (an independent encoder instance run beside it), one frame per
// sample; silence writes nothing and raises no pulse; refusals are counted;
// the counters run from the baseline and survive take_transport().
drivers::ImuFrameInput seam_sample(std::uint64_t k) {
  drivers::ImuFrameInput f;
  f.sample_counter = k;
  f.t_ns = static_cast<TimeNs>(k) * 5'000'000;
  f.period_ns = 5'000'000;
  f.gyro_rad_s = Vec3(0.01 * static_cast<double>(k), -0.02, 0.03);
  f.accel_m_s2 = Vec3(0.1, 0.2, -9.8);
  f.delta_theta_rad = f.gyro_rad_s * 0.005;
  f.delta_velocity_m_s = f.accel_m_s2 * 0.005;
  return f;
}

class RefusingTransport final : public drivers::Transport {
 public:
  bool write_frame(std::span<const std::byte>) override { return false; }
  std::string describe() const override { return "refusing"; }
  drivers::TransportCounters counters() const override {
    drivers::TransportCounters c;
    c.frames = 7;
    c.dropped_link_down = 7;
    return c;
  }
};

TEST(DeviceSeam, StreamDeviceWritesWhatTheEncoderWithItsLinkFaultsWrites) {
  std::mutex gpio_mutex;
  std::vector<bool> levels;
  drivers::GpioSyncOptions go;
  go.pulse_width_ns = 1'000;
  auto gpio = std::make_unique<drivers::GpioSyncOutput>(
      go,
      [&](bool active) {
        std::lock_guard lock(gpio_mutex);
        levels.push_back(active);
        return true;
      },
      drivers::GpioSyncOutput::LineWriter{});
  auto t = std::make_unique<RecordingTransport>();
  RecordingTransport* rec = t.get();
  const std::unique_ptr<device::Device> dev =
      device::make_stream_device(drivers::make_stream_encoder("mavlink2"), std::move(t), std::move(gpio));
  EXPECT_EQ(dev->describe(), "mavlink2 -> recording");
  EXPECT_EQ(dev->needs().increments, signal_chain::IncrementConvention::raw);
  EXPECT_FALSE(dev->needs().level_attitude);
  auto reference = drivers::make_stream_encoder("mavlink2");
  EXPECT_EQ(dev->max_bytes_per_sample(), reference->max_bytes_per_sample());

  std::vector<drivers::LinkActions> actions(4);
  actions[1].silence = true;  // the encoder runs (MAVLink's seq moves on), nothing is written
  actions[2].copies = 2;      // the sample's packets twice
  std::vector<std::vector<std::uint8_t>> expected;
  for (std::uint64_t k = 0; k < actions.size(); ++k) {
    std::vector<std::uint8_t> bytes;
    drivers::encode_with_link_faults(actions[k], *reference, seam_sample(k), bytes);
    if (!bytes.empty()) expected.push_back(bytes);
    const TimeNs before = monotonic_now_ns();
    const device::EmitOutcome out = dev->emit(seam_sample(k), actions[k], seam_sample(k).t_ns);
    EXPECT_EQ(out.refused, 0u) << k;
    if (k == 1) EXPECT_EQ(out.accepted_ns, 0) << "silenced: nothing handed over";
    else EXPECT_GE(out.accepted_ns, before) << k;
  }
  EXPECT_EQ(expected.size(), 3u);
  EXPECT_EQ(rec->frames(), expected);
  ASSERT_TRUE(dev->gpio_counters().has_value());
  const drivers::GpioSyncCounters g = *dev->gpio_counters();
  EXPECT_EQ(g.pulses + g.skipped_pulses, 3u) << "no pulse for the silenced sample";
  dev->stop(100ms, false);
  EXPECT_EQ(rec->flushes(), 1);
  ASSERT_TRUE(dev->gpio_counters().has_value()) << "the counters stay after the lines are released";
  EXPECT_EQ(dev->gpio_counters()->pulses, g.pulses);
  std::lock_guard lock(gpio_mutex);
  ASSERT_FALSE(levels.empty());
  EXPECT_FALSE(levels.back());  // released inactive
}

TEST(DeviceSeam, StreamDeviceCountsRefusalsFromItsBaselineAndHandsItsTransportOver) {
  drivers::TransportCounters baseline;
  baseline.frames = 3;
  baseline.dropped_link_down = 3;
  const std::unique_ptr<device::Device> dev = device::make_stream_device(
      drivers::make_stream_encoder("native"), std::make_unique<RefusingTransport>(), nullptr, baseline);
  const device::EmitOutcome out = dev->emit(seam_sample(0), {}, 0);
  EXPECT_EQ(out.refused, 1u);
  EXPECT_EQ(out.accepted_ns, 0);
  EXPECT_EQ(dev->counters().frames, 4u);
  EXPECT_EQ(dev->counters().dropped_link_down, 4u);
  EXPECT_FALSE(dev->gpio_counters().has_value());
  dev->stop(100ms, true);
  std::unique_ptr<drivers::Transport> taken = dev->take_transport();
  ASSERT_NE(taken, nullptr);
  EXPECT_EQ(taken->describe(), "refusing");
  EXPECT_EQ(dev->describe(), "native -> refusing") << "reported as it was when taken";
  EXPECT_EQ(dev->counters().frames, 4u);
  EXPECT_EQ(dev->take_transport(), nullptr);
  EXPECT_THROW(device::make_stream_device(drivers::make_stream_encoder("native"), nullptr), std::invalid_argument);
  // The compensated increments and the largest frame are the encoder's.
  const auto mip = device::make_stream_device(drivers::make_stream_encoder("mip"), std::make_unique<drivers::NullTransport>());
  EXPECT_EQ(mip->needs().increments, signal_chain::IncrementConvention::compensated);
  EXPECT_EQ(mip->max_bytes_per_sample(), drivers::make_stream_encoder("mip")->max_bytes_per_sample());
}

TEST(DeviceSeam, CanDeviceSendsEveryFrameOfTheSample) {
  auto out = std::make_unique<RecordingCanOutput>();
  RecordingCanOutput* rec = out.get();
  const std::unique_ptr<device::Device> dev = device::make_can_device(drivers::make_can_encoder("dronecan"), std::move(out));
  auto reference = drivers::make_can_encoder("dronecan");
  std::vector<drivers::CanFrame> expected;
  drivers::LinkActions missing;
  missing.can_missing_frame = true;
  for (std::uint64_t k = 0; k < 3; ++k) {
    const drivers::LinkActions a = k == 1 ? missing : drivers::LinkActions{};
    drivers::encode_with_link_faults(a, *reference, seam_sample(k), expected);
    const device::EmitOutcome o = dev->emit(seam_sample(k), a, seam_sample(k).t_ns);
    EXPECT_EQ(o.refused, 0u);
    EXPECT_GT(o.accepted_ns, 0) << "CAN hands over too (the pose latency counts it)";
  }
  const std::vector<drivers::CanFrame> sent = rec->frames();
  ASSERT_EQ(sent.size(), expected.size());
  for (std::size_t i = 0; i < sent.size(); ++i) {
    EXPECT_EQ(sent[i].id, expected[i].id) << i;
    ASSERT_EQ(sent[i].len, expected[i].len) << i;
    EXPECT_TRUE(std::equal(sent[i].data.begin(), sent[i].data.begin() + sent[i].len, expected[i].data.begin())) << i;
  }
  EXPECT_EQ(dev->describe(), "dronecan -> recording can");
  EXPECT_EQ(dev->max_bytes_per_sample(), 0u) << "bit errors never reach a CAN receiver";
  try {
    dev->check_supports("can0", fault::Kind::bit_errors);
    ADD_FAILURE() << "bit_errors accepted on CAN";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("fault type bit_errors on imu 'can0' (dronecan)"), std::string::npos) << e.what();
  }
  EXPECT_NO_THROW(dev->check_supports("can0", fault::Kind::can_wrong_id));
  drivers::CanEncoderOptions slope;
  slope.j1939.send_slope = true;
  EXPECT_TRUE(device::make_can_device(drivers::make_can_encoder("j1939", slope), std::make_unique<RecordingCanOutput>())
                  ->needs()
                  .level_attitude);
  EXPECT_FALSE(device::make_can_device(drivers::make_can_encoder("j1939"), std::make_unique<RecordingCanOutput>())
                   ->needs()
                   .level_attitude);
  dev->stop(100ms, true);
  EXPECT_EQ(dev->take_transport(), nullptr) << "a CAN interface is not handed to the next engine";
}

}  // namespace
}  // namespace imuemu::emission

// QueuedWriter::stop (issue 13): it discarded whatever was still queued,
// uncounted (frames neither sent nor dropped: `queued` stayed > 0 forever in
// the final statistics). Now stop() drains for a bounded time and counts
// what is left as dropped_at_stop.
namespace imuemu::drivers {
namespace {

// A datagram device taking one frame per write, `write_delay` each (a slow
// link), or none at all when `stalled` (would_block with nothing to poll:
// the writer waits until it is woken).
class SlowDevice final : public WriterDevice {
 public:
  SlowDevice(std::chrono::milliseconds write_delay, bool stalled, std::atomic<std::uint64_t>& written)
      : write_delay_(write_delay), stalled_(stalled), written_(written) {}
  bool datagrams() const override { return true; }
  int poll_fd() const override { return -1; }
  DeviceWrite write(std::span<const std::byte> bytes) override {
    if (stalled_) return {DeviceWrite::Outcome::would_block, 0, {}};
    std::this_thread::sleep_for(write_delay_);
    written_.fetch_add(1);
    return {DeviceWrite::Outcome::written, bytes.size(), {}};
  }
  std::optional<std::string> service(short, std::uint64_t*) override { return std::nullopt; }
  void on_link_lost() override {}
  bool try_restore(std::string&) override { return true; }
  bool initially_up() const override { return true; }

 private:
  std::chrono::milliseconds write_delay_;
  bool stalled_;
  std::atomic<std::uint64_t>& written_;
};

// Every frame offered ends in exactly one counter once the writer stopped.
void expect_every_frame_accounted(const TransportCounters& c) {
  EXPECT_EQ(c.queued, 0u);
  EXPECT_EQ(c.frames, c.frames_sent + c.dropped_queue_full + c.dropped_link_down + c.write_errors + c.dropped_at_stop);
}

QueuedWriterOptions quiet_options() {
  QueuedWriterOptions o;
  o.name = "test";
  o.log = [](std::string_view) {};
  return o;
}

TEST(QueuedWriterStop, DrainsWhatTheDeviceTakesWithinTheBound) {
  std::atomic<std::uint64_t> written{0};
  QueuedWriter writer(std::make_unique<SlowDevice>(std::chrono::milliseconds(5), false, written), quiet_options());
  const std::vector<std::byte> frame(32, std::byte{0x5a});
  for (int i = 0; i < 20; ++i) ASSERT_TRUE(writer.offer(frame));
  // 20 frames at 5 ms: about 100 ms; the bound is far beyond on any host.
  writer.stop(std::chrono::seconds(20));
  const TransportCounters c = writer.counters();
  EXPECT_EQ(c.frames_sent, 20u);
  EXPECT_EQ(written.load(), 20u);
  EXPECT_EQ(c.dropped_at_stop, 0u);
  expect_every_frame_accounted(c);
}

TEST(QueuedWriterStop, CountsWhatTheDeviceDidNotTakeAndReturnsWithinTheBound) {
  std::atomic<std::uint64_t> written{0};
  std::vector<std::string> log;
  QueuedWriterOptions o = quiet_options();
  o.log = [&log](std::string_view line) { log.emplace_back(line); };
  QueuedWriter writer(std::make_unique<SlowDevice>(std::chrono::milliseconds(0), true, written), o);
  const std::vector<std::byte> frame(32, std::byte{0x5a});
  for (int i = 0; i < 10; ++i) ASSERT_TRUE(writer.offer(frame));
  const auto t0 = std::chrono::steady_clock::now();
  writer.stop(std::chrono::milliseconds(100));
  // The drain is bounded (100 ms asked; generous for a loaded host).
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(10));
  const TransportCounters c = writer.counters();
  EXPECT_EQ(c.frames_sent, 0u);
  EXPECT_EQ(c.dropped_at_stop, 10u);
  expect_every_frame_accounted(c);
  ASSERT_FALSE(log.empty());
  EXPECT_NE(log.back().find("10 queued frame(s) not written"), std::string::npos) << log.back();
  writer.stop(std::chrono::milliseconds(100));  // idempotent: nothing counted twice
  EXPECT_EQ(writer.counters().dropped_at_stop, 10u);
}

}  // namespace
}  // namespace imuemu::drivers
}  // namespace unity_engine_test_emission
