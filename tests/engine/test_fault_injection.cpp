// Issue 18 at the engine level (daemon/engine/emission.hpp, daemon/device/device_faults.hpp):
// the CAN faults through the CanOutput test double and the drivers' DroneCAN
// decoder (a vcan end-to-end run needs the HIL kernels, tests/hil/), the
// run-time mailbox (inject / list / clear, refusals change nothing, a
// stalled producer times out without a half-done request), and random
// faults reproducible from one seed. The pty end-to-end tests with the
// independent reference decoder: tests/loopback/fault_injection.py.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <new>
#include <cmath>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

#include "tests/support/recording_transport.hpp"
#include "core/fault/fault.hpp"
#include "core/reference_motion.hpp"
#include "daemon/device/device.hpp"
#include "daemon/engine/emission.hpp"
#include "daemon/service/fault_control.hpp"
#include "io/fault_log.hpp"
#include "drivers/link_fault.hpp"
#include "drivers/protocols/can_protocols.hpp"
#include "drivers/protocols/stream_protocols.hpp"

// Counts this binary's allocations while g_counting is set (the emission thread must allocate nothing per sample, link faults included).
#include "tests/support/allocation_counter.hpp"

namespace imuemu::emission {
namespace {

using namespace std::chrono_literals;

class RecordingCanOutput final : public device::CanOutput {
 public:
  bool send(const drivers::CanFrame& frame) override {
    std::lock_guard lock(mutex_);
    frames_.push_back(frame);
    return true;
  }
  std::string describe() const override { return "recording can"; }
  drivers::TransportCounters counters() const override { return {}; }
  std::vector<drivers::CanFrame> frames() const {
    std::lock_guard lock(mutex_);
    return frames_;
  }

 private:
  mutable std::mutex mutex_;
  std::vector<drivers::CanFrame> frames_;
};

using RecordingTransport = test_support::RecordingTransport;

std::vector<Pose> circle_knots(double duration_s) {
  const reference::Circle circle(200.0, 20.0, 0, static_cast<TimeNs>(duration_s * 1e9));
  return reference::sample_knots(circle, kNsPerSecond);
}

PipelineOptions flat_pipeline(std::int64_t rate_hz) {
  PipelineOptions po;
  po.scene.physics = Physics::flat;
  po.rate_hz = rate_hz;
  po.kernel.delta = static_cast<int>(rate_hz);
  return po;
}

// A fault on samples [first, first + count) at `rate_hz`, on the device's own clock.
fault::FaultSpec window(fault::Kind kind, std::uint64_t first, std::uint64_t count, std::int64_t rate_hz) {
  fault::FaultSpec s = fault::default_spec(kind);
  s.clock = fault::Clock::since_start;
  s.start_ns = static_cast<TimeNs>(first) * kNsPerSecond / rate_hz;
  s.duration_ns = static_cast<TimeNs>(count) * kNsPerSecond / rate_hz;
  return s;
}

// ring: samples the producer may compute ahead (0: the engine's default,
// 250 ms; more: the whole run up front, so no tick can be late on a busy host).
EngineOptions fast_options(const std::vector<Pose>& knots, std::uint64_t ticks, std::int64_t speed, std::size_t ring = 0) {
  EngineOptions eo;
  eo.ring_capacity = ring;
  eo.trajectory = knots;
  eo.max_ticks_per_device = ticks;
  eo.drop_late_ticks = false;  // every tick goes out, however the host schedules us
  eo.speed = live::SpeedFactor{speed, 1};
  return eo;
}

struct CanRun {
  std::vector<drivers::CanFrame> frames;
  std::vector<fault::FaultEvent> events;
  DeviceStats stats;
};

CanRun run_can(std::vector<fault::FaultSpec> faults) {
  DeviceOptions d;
  d.name = "can0";
  d.rate_hz = 100;
  d.pipeline = flat_pipeline(100);
  auto out = std::make_unique<RecordingCanOutput>();
  RecordingCanOutput* rec = out.get();
  d.device = device::make_can_device(drivers::make_can_encoder("dronecan"), std::move(out));
  d.faults.scheduled = std::move(faults);
  std::vector<DeviceOptions> devices;
  devices.push_back(std::move(d));
  EmissionEngine engine(fast_options(circle_knots(4.0), 200, 4, 256), std::move(devices));
  engine.start();
  EXPECT_TRUE(engine.wait(20s));
  engine.stop();
  return {rec->frames(), engine.take_fault_events(), engine.stats().devices[0]};
}

// DroneCAN decoded by the drivers' decoder, keyed by the sample's
// microsecond timestamp (its transfer id is `sequence`).
std::map<TimeNs, drivers::DecodedSample> decode_dronecan(const std::vector<drivers::CanFrame>& frames,
                                                         drivers::DecoderCounters* counters = nullptr) {
  auto decoder = drivers::make_can_decoder("dronecan");
  std::map<TimeNs, drivers::DecodedSample> out;
  for (const drivers::CanFrame& f : frames)
    decoder->feed(f, [&](const drivers::DecodedSample& s) { out.emplace(s.t_ns, s); });
  if (counters != nullptr) *counters = decoder->counters();
  return out;
}

// CAN faults, each on its own 10 samples of a 100 Hz DroneCAN device: the
// decoder loses exactly those samples (wrong id: not the RawIMU subject id;
// missing frame: the multi-frame transfer never completes; silence: nothing
// sent), every other sample - transfer id included, so the encoder's state
// moved on through the faults - is the fault-free run's, and the ground
// truth names exactly the windows.
TEST(FaultEngine, CanFaultsActOnExactlyTheirSamplesAndNothingElse) {
  const CanRun clean = run_can({});
  fault::FaultSpec wrong_id = window(fault::Kind::can_wrong_id, 40, 10, 100);
  wrong_id.can_id = 0x123;
  const CanRun faulty = run_can({wrong_id, window(fault::Kind::can_missing_frame, 80, 10, 100),
                                 window(fault::Kind::silence, 120, 10, 100)});
  drivers::DecoderCounters counters;
  const auto clean_samples = decode_dronecan(clean.frames);
  const auto faulty_samples = decode_dronecan(faulty.frames, &counters);
  ASSERT_EQ(clean_samples.size(), 200u);
  ASSERT_EQ(faulty_samples.size(), 170u);
  std::vector<TimeNs> times;
  for (const auto& [t, s] : clean_samples) times.push_back(t);
  for (std::size_t k = 0; k < times.size(); ++k) {
    const bool in_fault = (k >= 40 && k < 50) || (k >= 80 && k < 90) || (k >= 120 && k < 130);
    const auto it = faulty_samples.find(times[k]);
    ASSERT_EQ(it != faulty_samples.end(), !in_fault) << "sample " << k;
    if (in_fault) continue;
    const drivers::DecodedSample& a = clean_samples.at(times[k]);
    EXPECT_EQ(it->second.sequence, a.sequence) << k;
    EXPECT_EQ(it->second.gyro_rad_s, a.gyro_rad_s) << k;
    EXPECT_EQ(it->second.accel_m_s2, a.accel_m_s2) << k;
  }
  // Wrong identifier: every frame of those 10 samples' transfers under 0x123, none elsewhere.
  std::size_t wrong = 0;
  for (const drivers::CanFrame& f : faulty.frames) wrong += f.id == 0x123 ? 1 : 0;
  EXPECT_GT(wrong, 0u);
  EXPECT_EQ(wrong % 10, 0u) << wrong;
  // Silence: 10 ticks counted, not emitted, not write errors.
  EXPECT_EQ(faulty.stats.faults.silenced, 10u);
  EXPECT_EQ(faulty.stats.emitted, 190u);
  EXPECT_EQ(faulty.stats.write_errors, 0u);
  EXPECT_EQ(faulty.stats.ticks, faulty.stats.emitted + faulty.stats.faults.silenced);
  // Ground truth.
  std::vector<std::tuple<std::string, std::string, std::uint64_t>> got;
  for (const fault::FaultEvent& e : faulty.events)
    got.emplace_back(std::string(fault::kind_name(e.spec.kind)), e.phase == fault::FaultEvent::Phase::start ? "start" : "end",
                     e.sample_counter);
  const std::vector<std::tuple<std::string, std::string, std::uint64_t>> want{
      {"can_wrong_id", "start", 40}, {"can_wrong_id", "end", 49},      {"can_missing_frame", "start", 80},
      {"can_missing_frame", "end", 89}, {"silence", "start", 120},   {"silence", "end", 129}};
  EXPECT_EQ(got, want);
  EXPECT_EQ(faulty.stats.faults.started, 3u);
  EXPECT_EQ(faulty.stats.faults.ended, 3u);
  EXPECT_EQ(faulty.stats.faults.active, 0u);
  EXPECT_TRUE(clean.events.empty());
}

// The control socket's fault-inject arguments: datasheet units through the
// scene's own [[imu.fault]] parser (bias_deg_s -> rad/s), strict keys, the
// start and duration only as after_s/duration_s; clear wants an id or all.
TEST(FaultControl, ArgumentsAreCheckedBeforeAnythingReachesTheEngine) {
  using nlohmann::json;
  const service::FaultInjectRequest r = service::parse_fault_inject(
      json{{"imu", "imu0"}, {"type", "bias_step"}, {"after_s", 0.25}, {"duration_s", 1.5},
           {"params", {{"sensor", "gyro"}, {"axes", "xz"}, {"bias_deg_s", 10}, {"flag_status", true}}}});
  EXPECT_EQ(r.imu, "imu0");
  EXPECT_EQ(r.after_ns, 250'000'000);
  EXPECT_EQ(r.spec.kind, fault::Kind::bias_step);
  EXPECT_EQ(r.spec.duration_ns, 1'500'000'000);
  EXPECT_EQ(r.spec.triad, fault::Triad::gyro);
  EXPECT_EQ(r.spec.axes, 0b101);
  EXPECT_NEAR(r.spec.gyro_bias_rad_s, 10.0 * 3.14159265358979323846 / 180.0, 1e-15);
  EXPECT_TRUE(r.spec.flag_status);
  EXPECT_EQ(r.spec.source, "control");
  const auto refused = [](const json& args, const std::string& why) {
    try {
      (void)service::parse_fault_inject(args);
      ADD_FAILURE() << "accepted " << args.dump();
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(why), std::string::npos) << e.what();
    }
  };
  refused(json{{"type", "dead"}}, "missing \"imu\"");
  refused(json{{"imu", "imu0"}}, "missing \"type\"");
  // Issue 26 N17: each says what is wrong.
  refused(json{{"imu", "imu0"}, {"type", 5}}, "\"type\": expected a string (a fault type's name");
  refused(json{{"imu", "imu0"}, {"type", "dead"}, {"after_s", 1e10}}, "\"after_s\": expected a finite number >= 0 and <= 9e9 s");
  refused(json{{"imu", "imu0"}, {"type", "intermittent"}, {"params", {{"on_ms", 1e-7}, {"off_ms", 5}}}},
          "expected a number in [1e-06, 1e+09] (the failing part of each cycle in ms, at least 1e-6 ms = 1 ns)");
  // 9e9 s is 9e18 ns: within int64 (it was said not to fit).
  EXPECT_EQ(service::parse_fault_inject(json{{"imu", "imu0"}, {"type", "dead"}, {"after_s", 9e9}}).after_ns,
            9'000'000'000'000'000'000);
  refused(json{{"imu", "imu0"}, {"type", "melt"}}, "'melt' is not a fault type");
  refused(json{{"imu", "imu0"}, {"type", "dead"}, {"colour", 1}}, "unknown key 'colour'");
  refused(json{{"imu", "imu0"}, {"type", "dead"}, {"after_s", -1}}, "\"after_s\": expected a finite number >= 0");
  refused(json{{"imu", "imu0"}, {"type", "dead"}, {"params", {{"at_s", 3}}}}, "params.at_s");
  refused(json{{"imu", "imu0"}, {"type", "dead"}, {"params", {{"bias_deg_s", 1}}}}, "bias_deg_s");
  refused(json{{"imu", "imu0"}, {"type", "dead"}, {"params", {{"axes", json::array()}}}}, "params.axes");
  EXPECT_EQ(service::parse_fault_clear(json{{"imu", "a"}, {"id", 3}}).id, std::optional<std::uint64_t>(3));
  EXPECT_FALSE(service::parse_fault_clear(json{{"imu", "a"}, {"all", true}}).id.has_value());
  EXPECT_THROW(service::parse_fault_clear(json{{"imu", "a"}}), std::invalid_argument);
  EXPECT_THROW(service::parse_fault_clear(json{{"imu", "a"}, {"id", 1}, {"all", true}}), std::invalid_argument);
  EXPECT_THROW(service::parse_fault_clear(json{{"imu", "a"}, {"id", -1}}), std::invalid_argument);
  EXPECT_THROW(service::parse_fault_clear(json{{"imu", "a"}, {"id", 0}}), std::invalid_argument);
  EXPECT_EQ(service::parse_fault_clear(json::parse(R"({"imu": "a", "id": 4})")).id, std::optional<std::uint64_t>(4));
  EXPECT_EQ(service::parse_fault_list(json::object()), "");
  EXPECT_EQ(service::parse_fault_list(json{{"imu", "b"}}), "b");
  EXPECT_THROW(service::parse_fault_list(json{{"id", 1}}), std::invalid_argument);
}

// A scene fault the device's protocol has no field for is refused when the
// engine is built, naming the device and the protocol (on CAN, bit errors:
// the controller's CRC and retransmission hide them).
TEST(FaultEngine, AFaultTheProtocolCannotShowIsRefusedAtBuild) {
  DeviceOptions d;
  d.name = "can0";
  d.rate_hz = 100;
  d.pipeline = flat_pipeline(100);
  d.device = device::make_can_device(drivers::make_can_encoder("dronecan"), std::make_unique<RecordingCanOutput>());
  d.faults.scheduled.push_back(window(fault::Kind::bit_errors, 10, 10, 100));
  d.faults.scheduled.back().bit_error_rate = 0.01;
  std::vector<DeviceOptions> devices;
  devices.push_back(std::move(d));
  try {
    EmissionEngine engine(fast_options(circle_knots(3.0), 100, 1), std::move(devices));
    FAIL() << "bit_errors accepted on CAN";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("fault type bit_errors on imu 'can0' (dronecan)"), std::string::npos) << e.what();
  }
}

std::vector<drivers::DecodedSample> decode_native(const std::vector<std::uint8_t>& bytes,
                                                  drivers::DecoderCounters* counters = nullptr) {
  auto decoder = drivers::make_stream_decoder("native");
  std::vector<drivers::DecodedSample> out;
  decoder->feed(bytes, [&](const drivers::DecodedSample& s) { out.push_back(s); });
  if (counters != nullptr) *counters = decoder->counters();
  return out;
}

struct NativeEngine {
  explicit NativeEngine(std::uint64_t ticks, std::int64_t speed, DeviceFaultPlan plan = {},
                        std::chrono::milliseconds request_timeout = 1000ms, std::size_t ring = 0) {
    DeviceOptions d;
    d.name = "imu0";
    d.rate_hz = 200;
    d.pipeline = flat_pipeline(200);
    auto t = std::make_unique<RecordingTransport>();
    transport = t.get();
    d.device = device::make_stream_device(drivers::make_stream_encoder("native"), std::move(t));
    d.faults = std::move(plan);
    std::vector<DeviceOptions> devices;
    devices.push_back(std::move(d));
    EngineOptions eo = fast_options(circle_knots(static_cast<double>(ticks) / 200.0 + 2.0), ticks, speed, ring);
    eo.fault_request_timeout = request_timeout;
    engine = std::make_unique<EmissionEngine>(std::move(eo), std::move(devices));
  }
  RecordingTransport* transport = nullptr;
  std::unique_ptr<EmissionEngine> engine;
};

// Run time, through the producer's mailbox: a refused request changes
// nothing; inject starts at the sample it names; clear ends the fault at the
// last sample it acted on, and every sample after it is bit-identical with
// a run that never had the fault.
TEST(FaultEngine, InjectListClearThroughTheMailbox) {
  NativeEngine clean(600, 2);
  clean.engine->start();
  NativeEngine run(600, 2);
  EXPECT_THROW(run.engine->inject_fault("imu0", fault::default_spec(fault::Kind::dead), 0), std::runtime_error)
      << "not started: refused";
  run.engine->start();
  std::this_thread::sleep_for(300ms);
  EXPECT_THROW(run.engine->inject_fault("imu9", fault::default_spec(fault::Kind::dead), 0), std::invalid_argument);
  fault::FaultSpec bad = fault::default_spec(fault::Kind::babble);
  bad.babble_factor = 1000;
  EXPECT_THROW(run.engine->inject_fault("imu0", bad, 0), std::invalid_argument);
  EXPECT_TRUE(run.engine->list_faults("").empty()) << "a refused spec changes nothing";
  // A fault the protocol cannot show (native has no CAN identifier) is refused.
  try {
    run.engine->inject_fault("imu0", fault::default_spec(fault::Kind::can_wrong_id), 0);
    ADD_FAILURE() << "can_wrong_id accepted on a native device";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("fault type can_wrong_id on imu 'imu0' (native): the protocol has no CAN identifier"),
              std::string::npos)
        << e.what();
  }
  EXPECT_TRUE(run.engine->list_faults("").empty());
  fault::FaultSpec dead = fault::default_spec(fault::Kind::dead);
  dead.triad = fault::Triad::gyro;
  const EmissionEngine::InjectedFault injected = run.engine->inject_fault("imu0", dead, 100'000'000);
  EXPECT_EQ(injected.id, 1u);
  const std::vector<FaultInfo> listed = run.engine->list_faults("imu0");
  ASSERT_EQ(listed.size(), 1u);
  EXPECT_EQ(listed[0].spec.kind, fault::Kind::dead);
  EXPECT_EQ(listed[0].spec.source, "control");
  std::this_thread::sleep_for(600ms);
  EXPECT_EQ(run.engine->list_faults("imu0").at(0).state, FaultInfo::State::active);
  EXPECT_EQ(run.engine->clear_faults("imu0", 1), std::vector<std::uint64_t>{1});
  EXPECT_THROW(run.engine->clear_faults("imu0", 1), std::invalid_argument) << "cleared already";
  EXPECT_TRUE(run.engine->list_faults("").empty());
  ASSERT_TRUE(run.engine->wait(20s));
  ASSERT_TRUE(clean.engine->wait(20s));
  run.engine->stop();
  clean.engine->stop();
  EXPECT_THROW(run.engine->list_faults(""), std::runtime_error) << "the producer has ended";

  const std::vector<fault::FaultEvent> events = run.engine->take_fault_events();
  ASSERT_EQ(events.size(), 2u);
  const std::uint64_t k0 = events[0].sample_counter, k1 = events[1].sample_counter;
  EXPECT_EQ(k0, injected.first_sample);
  EXPECT_GT(k1, k0);
  const DeviceStats st = run.engine->stats().devices[0];
  EXPECT_EQ(st.faults.injected, 1u);
  EXPECT_EQ(st.faults.cleared, 1u);
  drivers::DecoderCounters counters;
  const auto got = decode_native(run.transport->bytes(), &counters);
  const auto want = decode_native(clean.transport->bytes());
  ASSERT_EQ(got.size(), 600u);
  ASSERT_EQ(want.size(), 600u);
  std::uint64_t zeroed = 0;
  for (std::size_t k = 0; k < got.size(); ++k) {
    ASSERT_EQ(got[k].sequence, k);
    EXPECT_EQ(got[k].t_ns, want[k].t_ns);
    EXPECT_EQ(got[k].accel_m_s2, want[k].accel_m_s2) << k;
    if (k >= k0 && k <= k1) {
      EXPECT_EQ(got[k].gyro_rad_s, Vec3::Zero()) << k;
      ++zeroed;
    } else {
      EXPECT_EQ(got[k].gyro_rad_s, want[k].gyro_rad_s) << k;  // bit for bit, before and after
    }
  }
  EXPECT_EQ(zeroed, k1 - k0 + 1);
}

// A producer that does not take the request in time: the request is
// withdrawn (refused with the timeout), and it never happens later.
TEST(FaultEngine, AStalledProducerTimesOutWithoutAHalfDoneRequest) {
  NativeEngine run(400, 1, {}, 100ms);
  run.engine->start();
  std::this_thread::sleep_for(100ms);
  run.engine->set_producer_stall_for_test(true);
  std::this_thread::sleep_for(20ms);
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_THROW(run.engine->inject_fault("imu0", fault::default_spec(fault::Kind::dead), 0), std::runtime_error);
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 1s);
  run.engine->set_producer_stall_for_test(false);
  EXPECT_TRUE(run.engine->list_faults("imu0").empty());
  run.engine->stop();
  EXPECT_TRUE(run.engine->take_fault_events().empty());
  EXPECT_EQ(run.engine->stats().devices[0].faults.injected, 0u);
}

// Random faults drawn from one seed: two runs, the same ground truth to the
// sample, and the same bytes on the wire.
TEST(FaultEngine, RandomFaultsFromOneSeedReproduceRunToRun) {
  DeviceFaultPlan plan;
  plan.random.per_hour = 1800;
  plan.random.kinds = {fault::Kind::dead, fault::Kind::drop, fault::Kind::duplicate, fault::Kind::bias_step};
  plan.random.duration_ns = 200'000'000;
  plan.random.seed = 7;
  std::vector<std::string> logs[2];
  std::vector<std::uint8_t> bytes[2];
  for (int run = 0; run < 2; ++run) {
    NativeEngine e(4000, 20, plan, 1000ms, 4096);  // 20 s of samples in 1 s, all computed up front
    e.engine->start();
    ASSERT_TRUE(e.engine->wait(30s));
    e.engine->stop();
    for (const fault::FaultEvent& ev : e.engine->take_fault_events()) logs[run].push_back(fault_log::fault_event_json(ev).dump());
    bytes[run] = e.transport->bytes();
  }
  EXPECT_GE(logs[0].size(), 4u) << "1800/h over 20 s: about 10 faults";
  EXPECT_EQ(logs[0].size() % 2, 0u);
  EXPECT_EQ(logs[0], logs[1]);
  EXPECT_EQ(bytes[0], bytes[1]);
}

// Every link action on every byte-stream protocol, 10 samples each, with
// babble at its maximum: once the engine runs (the producer computed every
// sample up front and ended), the emission thread applies them all without
// one heap allocation, and every tick is accounted for.
TEST(FaultEngine, TheEmissionThreadAllocatesNothingWithEveryLinkFault) {
  using fault::Kind;
  g_allocations = 0;
  g_counting = true;
  ::operator delete(::operator new(8));  // the counter itself counts (a call, never elided)
  g_counting = false;
  ASSERT_EQ(g_allocations.load(), 1u);
  for (const std::string protocol : {"native", "mavlink2", "mip"}) {
    DeviceOptions d;
    d.name = "imu0";
    d.rate_hz = 200;
    d.pipeline = flat_pipeline(200);
    auto encoder = drivers::make_stream_encoder(protocol);
    const bool sequence = drivers::link_fault_support(*encoder).sequence;  // MIP has no counter
    d.device = device::make_stream_device(std::move(encoder), std::make_unique<drivers::NullTransport>());
    std::uint64_t at = 120;
    std::uint64_t kinds = 0;
    for (const Kind kind : {Kind::duplicate, Kind::babble, Kind::bad_checksum, Kind::bit_errors, Kind::truncate,
                            Kind::bad_length, Kind::sequence_jump, Kind::sequence_reset, Kind::time_jump,
                            Kind::time_freeze, Kind::silence, Kind::restart, Kind::drop}) {
      if (!sequence && (kind == Kind::sequence_jump || kind == Kind::sequence_reset)) continue;
      ++kinds;
      fault::FaultSpec s = window(kind, at, 10, 200);
      s.babble_factor = fault::kMaxBabbleFactor;
      s.bit_error_rate = 0.01;
      s.truncate_bytes = 8;
      s.sequence_step = 7;
      s.time_step_ns = 3'000'000;
      d.faults.scheduled.push_back(s);
      at += 12;
    }
    std::vector<DeviceOptions> devices;
    devices.push_back(std::move(d));
    EmissionEngine engine(fast_options(circle_knots(4.0), 400, 4, 512), std::move(devices));
    engine.start();
    std::this_thread::sleep_for(100ms);  // the producer has nothing left to compute: it ended
    g_allocations = 0;
    g_counting = true;
    const bool finished = engine.wait(20s);
    g_counting = false;
    const std::uint64_t allocations = g_allocations.load();
    engine.stop();
    ASSERT_TRUE(finished) << protocol;
    EXPECT_EQ(allocations, 0u) << protocol;
    const DeviceStats st = engine.stats().devices[0];
    EXPECT_EQ(st.ticks, 400u) << protocol;
    EXPECT_EQ(st.faults.silenced, 20u) << protocol << ": silence and restart's off time";
    EXPECT_EQ(st.ticks, st.emitted + st.faults.silenced) << protocol;
    EXPECT_EQ(st.write_errors, 0u) << protocol;
    EXPECT_EQ(st.faults.started, kinds) << protocol;
    EXPECT_EQ(st.faults.ended, kinds) << protocol;
  }
}

}  // namespace
}  // namespace imuemu::emission
