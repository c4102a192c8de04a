// The emission engine (daemon/engine/emission.hpp): producer thread, lock-free rings,
// one real-time emission thread.
#include "daemon/engine/emission.hpp"

#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <time.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <future>
#include <limits>
#include <mutex>
#include <span>
#include <stdexcept>
#include <thread>

#include <boost/lockfree/spsc_queue.hpp>
#include <nlohmann/json.hpp>

#include "core/attitude.hpp"
#include "core/earth.hpp"
#include "core/stream.hpp"
#include "core/time_arith.hpp"
#include "drivers/queued_writer.hpp"
#include "drivers/link_fault.hpp"
#include "drivers/socketcan.hpp"
#include "io/pose_source.hpp"

namespace imuemu::emission {

TimeNs monotonic_now_ns() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<TimeNs>(ts.tv_sec) * kNsPerSecond + ts.tv_nsec;
}

TimeNs realtime_now_ns() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<TimeNs>(ts.tv_sec) * kNsPerSecond + ts.tv_nsec;
}

namespace {

__extension__ typedef __int128 Int128;  // exact products of int64 times (GCC/Clang)

constexpr TimeNs kMaxSleepChunkNs = 50'000'000;  // a stop request is seen within this
constexpr TimeNs kProducerPollNs = 1'000'000;
// Live input: the producer sleeps on the pose queue (woken by each pose's
// arrival) until its next tick's gate, at most kMaxSleepChunkNs (stop,
// stall and the like are looked at meanwhile), at least this long when the
// gate has passed without the tick being computable (a full ring): never a
// busy loop.
constexpr TimeNs kProducerMinWaitNs = 20'000;
// Poses waiting for their first dependent sample (a stalled emitter must not
// grow the list without bound).
constexpr std::size_t kMaxPoseMarks = 4096;

TimeNs thread_cpu_ns() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<TimeNs>(ts.tv_sec) * kNsPerSecond + ts.tv_nsec;
}

// Pitch and roll of the sensor axes relative to local level (NED), Eq. 1.2,
// from the sample's attitude in the scene frame (flat: R_s^n; ecef: R_s^e,
// turned into NED at the sample's own position, Eq. 1.5).
void set_level_attitude(const Kinematics& k, Physics physics, drivers::ImuFrameInput& f) {
  Mat3 sensor_to_ned = k.attitude;
  if (physics == Physics::ecef) {
    const earth::Geodetic g = earth::geodetic_from_ecef(k.position_m);
    sensor_to_ned = attitude::ned_to_ecef(g.latitude_rad, g.longitude_rad).transpose() * k.attitude;
  }
  const attitude::HeadingPitchRoll hpr = attitude::hpr_from_rotation(sensor_to_ned);
  f.has_level_attitude = true;
  f.pitch_rad = hpr.pitch_rad;
  f.roll_rad = hpr.roll_rad;
}

void sleep_until_monotonic(TimeNs due_ns) noexcept {
  timespec ts{static_cast<time_t>(due_ns / kNsPerSecond), static_cast<long>(due_ns % kNsPerSecond)};
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

// Grid time k of a stream starting at t0: t0 + floor(k * 1e9 / rate), in
// 128 bits (core/pipeline.hpp output_grid), saturated at the int64 limit
// (core/time_arith.hpp): a grid reaching beyond int64 ns (a stream stamped
// near the limit, issue 13 C1) ends there instead of wrapping.
TimeNs grid_ns(TimeNs t0_ns, std::uint64_t k, std::int64_t rate_hz) noexcept {
  const Int128 offset = static_cast<Int128>(k) * kNsPerSecond / rate_hz;
  if (offset > static_cast<Int128>(kMaxTimeNs)) return kMaxTimeNs;
  return saturating_add_ns(t0_ns, static_cast<TimeNs>(offset));
}

// Number of grid ticks with t_k <= t0 + span_ns: the k with k * 1e9 < (span + 1) * rate.
std::uint64_t ticks_within(TimeNs span_ns, std::int64_t rate_hz) {
  const Int128 bound = (static_cast<Int128>(span_ns) + 1) * rate_hz;
  const Int128 ticks = (bound + kNsPerSecond - 1) / kNsPerSecond;
  return ticks > static_cast<Int128>(std::numeric_limits<std::uint64_t>::max()) ? std::numeric_limits<std::uint64_t>::max()
                                                                                : static_cast<std::uint64_t>(ticks);
}

// Lowers an end tick to k (never raises it): either thread may find the end.
void lower_end_tick(std::atomic<std::uint64_t>& end_tick, std::uint64_t k) noexcept {
  std::uint64_t current = end_tick.load(std::memory_order_relaxed);
  while (k < current && !end_tick.compare_exchange_weak(current, k, std::memory_order_relaxed)) {
  }
}

class CanTransportOutput final : public CanOutput {
 public:
  explicit CanTransportOutput(std::unique_ptr<drivers::CanTransport> t) : transport_(std::move(t)) {}
  bool send(const drivers::CanFrame& frame) override { return transport_->send(frame); }
  std::string describe() const override { return transport_->describe(); }
  drivers::TransportCounters counters() const override { return transport_->counters(); }
  bool flush(std::chrono::milliseconds timeout) override { return transport_->flush(timeout); }
  void stop(std::chrono::milliseconds drain_timeout) override { transport_->stop(drain_timeout); }

 private:
  std::unique_ptr<drivers::CanTransport> transport_;
};

// What the producer hands the emission thread for one tick.
struct Slot {
  std::uint64_t tick = 0;
  bool send = false;  // false: the emitter had nothing to send (waiting, paused)
  live::EmissionStatus status = live::EmissionStatus::waiting;
  drivers::ImuFrameInput frame;
  // The arrival (CLOCK_MONOTONIC) of the newest pose this is the first
  // sample to depend on; 0: none (issue 17's end-to-end latency).
  TimeNs pose_receive_ns = 0;
  // Issue 18: what the active link faults do to this sample (decided by the
  // producer; the emission thread only applies it), and the sample's own
  // time for the sync pulse (frame.t_ns may carry a time_jump/time_freeze).
  drivers::LinkActions link;
  TimeNs pulse_t_ns = 0;
};

// Trajectory input: the stream engine is fed knots only as far as the next
// sample needs, so its memory stays O(window) however long the trajectory.
class OnDemandSource final : public live::ExactSampleSource {
 public:
  OnDemandSource(StreamPipeline& engine, const std::vector<Pose>& knots) : engine_(engine), knots_(knots) {}
  std::optional<live::ExactSample> next_sample() override {
    StreamSample s;
    while (!engine_.pop(s)) {
      if (next_knot_ < knots_.size()) {
        try {
          engine_.push(knots_[next_knot_]);
        } catch (const std::exception&) {
          ++refused_;  // a knot the method cannot take: counted, the others go on
        }
        ++next_knot_;
      } else if (!finished_) {
        finished_ = true;
        if (engine_.knots_pushed() >= 2) {
          try {
            engine_.finish();
          } catch (const std::exception&) {
            ++refused_;
          }
        }
      } else {
        return std::nullopt;
      }
    }
    return s;
  }
  std::uint64_t refused() const { return refused_; }
  std::size_t pushed() const { return next_knot_; }

 private:
  StreamPipeline& engine_;
  const std::vector<Pose>& knots_;
  std::size_t next_knot_ = 0;
  bool finished_ = false;
  std::uint64_t refused_ = 0;
};

void check_protocol_supports(const DeviceOptions& d, fault::Kind kind) {
  emission::check_protocol_supports(d.name, d.stream_encoder.get(), d.can_encoder.get(), kind);
}

}  // namespace

std::unique_ptr<CanOutput> can_transport_output(std::unique_ptr<drivers::CanTransport> transport) {
  return std::make_unique<CanTransportOutput>(std::move(transport));
}

struct Device {
  DeviceOptions options;
  TimeNs nominal_period_ns = 0;
  std::unique_ptr<StreamPipeline> engine;
  std::unique_ptr<live::LiveEmitter> emitter;
  std::unique_ptr<live::ExactSampleSource> samples;
  OnDemandSource* on_demand = nullptr;  // trajectory input: == samples
  bool mounted = false;                 // mounting is not the identity
  std::vector<Pose> sensor_knots;       // trajectory input, mounted: the sensor's poses
  // Producer only: the sensor model, internal rate, filters and the exact
  // increments (core/signal_chain/); passes ideal samples through untouched
  // for the ideal sensor and chain.
  std::optional<signal_chain::DeviceChain> chain;
  signal_chain::IncrementConvention increments = signal_chain::IncrementConvention::raw;  // the encoder's
  boost::lockfree::spsc_queue<Slot> ring;

  // Producer thread only (run-time requests reach it through the engine's mailbox).
  std::unique_ptr<DeviceFaults> faults;
  std::vector<fault::FaultEvent> fault_scratch;  // this sample's events, before they are queued
  std::uint64_t next_produce_tick = 0;
  std::optional<std::pair<std::uint64_t, Kinematics>> previous;  // tick k - 1: the interval's start

  // Emission thread only.
  std::uint64_t next_emit_tick = 0;
  TimeNs next_deadline_ns = 0;
  bool done = false;
  std::vector<std::uint8_t> bytes;
  std::vector<drivers::CanFrame> can_frames;

  // Shared (relaxed atomics; snapshot by stats()).
  std::atomic<std::uint64_t> end_tick{std::numeric_limits<std::uint64_t>::max()};  // no tick at or after
  std::atomic<std::uint64_t> ticks{0}, emitted{0}, exact{0}, extrapolated{0}, blending{0}, not_sent{0},
      producer_late{0}, deadline_misses{0}, dropped_late{0}, write_errors{0}, last_counter{0}, saturated{0};
  std::atomic<TimeNs> engine_lag_ns{0};
  std::atomic<std::uint64_t> faults_active{0}, faults_started{0}, faults_ended{0}, faults_injected{0},
      faults_cleared{0}, fault_events_dropped{0}, silenced{0};
  LatenessHistogram lateness;
  // End-to-end latency of live poses (causal method): from a pose's arrival
  // to its first dependent sample handed to the transport. pose_marks
  // (producer thread only): (previous pose's time, this pose's arrival); the
  // first tick after that time not extrapolated is the first to depend on it.
  LatenessHistogram pose_latency;
  std::deque<std::pair<TimeNs, TimeNs>> pose_marks;
  mutable std::mutex live_mutex;  // producer <-> stats(), never the emission thread
  live::LiveCounters live_counters;
  // The transport as it was when take_transports() moved it out.
  std::optional<std::pair<std::string, drivers::TransportCounters>> transport_final;
  std::optional<drivers::GpioSyncCounters> gpio_final;  // after the lines were released

  Device(DeviceOptions o, std::size_t capacity) : options(std::move(o)), ring(capacity) {}
};

struct EmissionEngine::Impl {
  EngineOptions options;
  std::vector<std::unique_ptr<Device>> devices;

  std::optional<live::TimeMapping> mapping_value;  // written once before mapping_ready is released
  std::atomic<bool> mapping_ready{false};
  TimeNs t0_ns = 0;

  std::atomic<bool> stop_requested{false};
  std::atomic<bool> emission_stall{false};
  std::atomic<bool> producer_stall{false};
  std::atomic<TimeNs> heartbeat_ns{0};
  std::atomic<bool> running{false};
  std::atomic<bool> finished{false};
  std::atomic<bool> input_without_poses{false};
  std::vector<io::SourcedPose> pose_batch;  // producer only
  std::atomic<std::uint64_t> poses_pushed{0}, poses_refused{0};
  // The newest refusal's reason, for the daemon's rate-limited log line
  // (producer thread writes, stats() reads; never the emission thread).
  mutable std::mutex refusal_mutex;
  std::string last_refusal;
  void note_refusal(const char* why) noexcept {
    try {
      std::lock_guard lock(refusal_mutex);
      last_refusal = why;
    } catch (...) {  // no memory for the text: the count still says it
    }
  }
  LatenessHistogram lateness;
  std::atomic<std::uint64_t> deadline_misses{0};
  std::atomic<TimeNs> emission_cpu_ns{0}, producer_cpu_ns{0}, emission_wall_ns{0};
  bool realtime_priority = false, memory_locked = false;
  std::string realtime_note;
  bool live_input_finished = false;  // producer only
  std::atomic<std::uint64_t> faults{0}, time_limit_ends{0}, pose_faults{0};
  mutable std::mutex fault_mutex;
  std::string fault;  // under fault_mutex
  std::atomic<bool> producer_fault_for_test{false};
  bool started = false, stopped = false;

  // Issue 18 run-time fault requests: the io thread posts one and waits; the
  // producer thread serves the mailbox at the top of each iteration, under
  // the lock (requests are quick: a list, a validate, a push), so a request
  // the caller withdraws after its timeout is never half done.
  struct FaultRequest {
    enum class Op { inject, clear, list } op = Op::list;
    Device* device = nullptr;  // list: nullptr = all
    fault::FaultSpec spec;
    TimeNs after_ns = 0;
    std::optional<std::uint64_t> id;
    bool done = false;
    std::exception_ptr error;
    InjectedFault injected;
    std::vector<std::uint64_t> cleared;
    std::vector<FaultInfo> infos;
  };
  std::mutex mailbox_mutex;
  std::condition_variable mailbox_cv;
  std::vector<FaultRequest*> mailbox;  // under mailbox_mutex
  bool producer_serving = false;       // under mailbox_mutex: the producer loop runs and will look
  std::string producer_gone_reason = "the engine has not started";  // under mailbox_mutex
  void serve_fault_requests();
  // Posts r and waits until the producer served it, or withdraws it (the
  // timeout, the producer gone) and throws; r's error is rethrown.
  void post_and_wait(FaultRequest& r) {
    std::unique_lock lock(mailbox_mutex);
    if (!producer_serving) throw std::runtime_error(producer_gone_reason);
    mailbox.push_back(&r);
    if (!mailbox_cv.wait_for(lock, options.fault_request_timeout, [&] { return r.done; })) {
      mailbox.erase(std::find(mailbox.begin(), mailbox.end(), &r));  // never served: nothing changed
      throw std::runtime_error("the producer thread did not take the request within " +
                               std::to_string(options.fault_request_timeout.count()) + " ms (nothing changed)");
    }
    if (r.error) std::rethrow_exception(r.error);
  }
  void stop_serving_fault_requests(const std::string& why);
  void run_request(FaultRequest& r);
  Device& device_named(const std::string& name);
  // Ground-truth events for the daemon's fault log (producer -> io thread).
  mutable std::mutex fault_events_mutex;
  std::deque<fault::FaultEvent> fault_events;  // under fault_events_mutex, at most fault_event_capacity
  void queue_fault_events(Device& d);

  std::thread producer, emitter;
  std::mutex done_mutex;
  std::condition_variable done_cv;
  bool emitter_exited = false;

  // When tick k is due on CLOCK_MONOTONIC; kNeverDueNs when that instant
  // (or the tick's time plus the emit delay) is beyond int64 ns: a slow
  // replay speed or a stream stamped near the limit (issue 13 C1: this threw
  // std::overflow_error on the producer thread and aborted imuemud). The
  // callers end the device's grid at the first such tick.
  static constexpr TimeNs kNeverDueNs = kMaxTimeNs;
  TimeNs deadline_ns(const Device& d, std::uint64_t k) const noexcept {
    const TimeNs tick_ns = grid_ns(t0_ns, k, d.options.rate_hz);
    const std::optional<TimeNs> shifted = checked_add_ns(tick_ns, options.emit_delay_ns);
    if (tick_ns == kMaxTimeNs || !shifted) return kNeverDueNs;
    try {
      return mapping_value->monotonic_at(*shifted);
    } catch (const std::exception&) {  // std::overflow_error: not representable
      return kNeverDueNs;
    }
  }
  // A device whose next tick can never be due ends there (counted once).
  void end_at_time_limit(Device& d, std::uint64_t k) noexcept {
    lower_end_tick(d.end_tick, k);
    time_limit_ends.fetch_add(1, std::memory_order_relaxed);
  }
  // A thread failed with an exception: recorded (the first one's message),
  // counted, and both threads stop; the daemon reports it (EngineStats::fault).
  void record_fault(const char* thread, const char* what) noexcept;
  bool live_input() const { return options.source != nullptr; }

  void produce(Device& d, bool time_gated);
  void take_live_input();
  void take_live_pose(const io::SourcedPose& p);
  void take_live_end();
  void run_producer() noexcept;
  void producer_loop();
  TimeNs producer_wake_ns(TimeNs now) const noexcept;
  void run_emission(std::promise<std::string>* setup) noexcept;
  void emission_loop(std::promise<std::string>* setup, bool& setup_done);
  void emit_tick(Device& d, std::uint64_t k, bool drop);
  void finish_emission();
};

EmissionEngine::EmissionEngine(EngineOptions options, std::vector<DeviceOptions> devices)
    : impl_(std::make_unique<Impl>()) {
  impl_->options = std::move(options);
  EngineOptions& o = impl_->options;
  if (devices.empty()) throw std::invalid_argument("emission: no device configured");
  if (o.source == nullptr && o.trajectory.size() < 2)
    throw std::invalid_argument("emission: the trajectory has " + std::to_string(o.trajectory.size()) +
                                " poses; at least two are needed");
  if (o.source != nullptr && !o.trajectory.empty())
    throw std::invalid_argument("emission: give either a trajectory or a pose source, not both");
  if (o.emit_delay_ns < 0 || o.producer_lead_ns <= 0 || o.start_lead_ns < 0)
    throw std::invalid_argument("emission: emit_delay_ns and start_lead_ns must be >= 0, producer_lead_ns > 0");
  if (o.source == nullptr) o.emit_delay_ns = 0;  // all poses are there: no look-ahead to wait for
  if (o.realtime.priority < 0 || o.realtime.priority > 99)
    throw std::invalid_argument("emission: SCHED_FIFO priority " + std::to_string(o.realtime.priority) +
                                " is not in 1..99 (0: normal scheduling)");
  for (DeviceOptions& dev : devices) {
    const std::string where = "emission device '" + dev.name + "': ";
    if (dev.rate_hz < 1 || dev.rate_hz > 1'000'000)
      throw std::invalid_argument(where + "rate " + std::to_string(dev.rate_hz) + " Hz is not in 1..1000000");
    const bool stream = dev.stream_encoder && dev.transport;
    const bool can = dev.can_encoder && dev.can_output;
    if (stream == can || (stream && (dev.can_encoder || dev.can_output)) ||
        (can && (dev.stream_encoder || dev.transport)))
      throw std::invalid_argument(where + "expected exactly one output: a stream encoder with a transport, or a CAN encoder with a CAN output");
    if (dev.blend_ns < 0) throw std::invalid_argument(where + "blend_ns < 0");
    dev.pipeline.rate_hz = dev.rate_hz;
    const TimeNs ring_span_ns = std::max<TimeNs>(o.producer_lead_ns, 250'000'000);
    const std::size_t capacity =
        o.ring_capacity > 0 ? o.ring_capacity
                            : static_cast<std::size_t>(std::max<Int128>(
                                  16, static_cast<Int128>(ring_span_ns) * dev.rate_hz / kNsPerSecond + 2));
    auto d = std::make_unique<Device>(std::move(dev), capacity);
    d->nominal_period_ns = kNsPerSecond / d->options.rate_hz;
    d->engine = std::make_unique<StreamPipeline>(d->options.pipeline);
    live::LiveEmitterOptions lo;
    lo.scene = d->options.pipeline.scene;
    lo.underrun = d->options.underrun;
    lo.blend_ns = d->options.blend_ns;
    d->emitter = std::make_unique<live::LiveEmitter>(lo);
    d->chain.emplace(d->options.pipeline.scene, d->options.sensor_model, d->options.chain, d->options.rate_hz,
                     d->options.name);
    const bool compensated = d->options.stream_encoder ? d->options.stream_encoder->compensated_increments()
                                                       : d->options.can_encoder->compensated_increments();
    d->increments = compensated ? signal_chain::IncrementConvention::compensated : signal_chain::IncrementConvention::raw;
    d->mounted = d->options.mounting.sensor_to_body != Mat3::Identity() || !d->options.mounting.lever_arm_b_m.isZero();
    if (o.source == nullptr) {
      if (d->mounted) {
        d->sensor_knots.reserve(o.trajectory.size());
        for (const Pose& p : o.trajectory) d->sensor_knots.push_back(sensor_pose(p, d->options.mounting));
      }
      auto s = std::make_unique<OnDemandSource>(*d->engine, d->mounted ? d->sensor_knots : o.trajectory);
      d->on_demand = s.get();
      d->samples = std::move(s);
      const std::uint64_t n = ticks_within(saturating_sub_ns(o.trajectory.back().t_ns, o.trajectory.front().t_ns), d->options.rate_hz);
      d->end_tick = o.max_ticks_per_device ? std::min(n, *o.max_ticks_per_device) : n;
    } else {
      d->samples = std::make_unique<live::StreamSampleSource>(*d->engine);
      if (o.max_ticks_per_device) d->end_tick = *o.max_ticks_per_device;
    }
    for (const fault::FaultSpec& f : d->options.faults.scheduled) check_protocol_supports(d->options, f.kind);
    if (d->options.faults.random.per_hour > 0.0)
      for (const fault::Kind kind : d->options.faults.random.kinds) check_protocol_supports(d->options, kind);
    try {
      d->faults = std::make_unique<DeviceFaults>(
          d->options.name, d->options.rate_hz, d->options.sensor_model, d->options.faults,
          d->options.stream_encoder ? d->options.stream_encoder->max_bytes_per_sample() : 0);
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument(where + "faults: " + e.what());
    }
    // Reserved now so that encoding on the emission thread never allocates,
    // link faults included (babble's copies, a restart's power-up traffic).
    if (d->options.stream_encoder)
      d->bytes.reserve(std::max(o.reserve_bytes, drivers::link_fault_reserve(*d->options.stream_encoder, fault::kMaxBabbleFactor)));
    d->can_frames.reserve(std::max(o.reserve_can_frames, drivers::link_fault_reserve_can_frames(fault::kMaxBabbleFactor)));
    impl_->devices.push_back(std::move(d));
  }
}

EmissionEngine::~EmissionEngine() {
  try {
    stop(std::chrono::milliseconds(200));
  } catch (...) {
  }
}

// Computes the slots of the ticks that are due for computing. time_gated
// (live input): tick k is computed no earlier than producer_lead before its
// deadline, so the LiveEmitter's exact/extrapolated decision is taken as late
// as the lead allows. Trajectory input is not gated: every sample is
// computable, so the ring is simply kept full.
void EmissionEngine::Impl::produce(Device& d, bool time_gated) {
  const bool have_mapping = mapping_ready.load(std::memory_order_acquire);
  const TimeNs now = monotonic_now_ns();
  while (d.next_produce_tick < d.end_tick.load(std::memory_order_relaxed) && d.ring.write_available() > 0 &&
         !stop_requested.load(std::memory_order_relaxed)) {
    const std::uint64_t k = d.next_produce_tick;
    const TimeNs tick_ns = grid_ns(t0_ns, k, d.options.rate_hz);
    if (have_mapping) {
      const TimeNs due = deadline_ns(d, k);
      if (due == kNeverDueNs) {  // the end of representable time: the grid ends here
        end_at_time_limit(d, k);
        break;
      }
      if (time_gated && now < saturating_sub_ns(due, options.producer_lead_ns)) break;
      if (now > due) {  // already too late to send: the emission thread counts it; skip the work
        ++d.next_produce_tick;
        d.previous.reset();
        continue;
      }
    }
    if (live_input() && live_input_finished && d.engine->ready() == 0 && tick_ns > d.engine->last_knot_ns()) {
      d.end_tick.store(k, std::memory_order_relaxed);  // past the end of the input
      break;
    }
    const live::Emission e = d.emitter->emit(tick_ns, *d.samples);
    Slot slot;
    slot.tick = k;
    slot.status = e.status;
    slot.send = e.has_sample();
    if (slot.send && e.status != live::EmissionStatus::extrapolated) {
      while (!d.pose_marks.empty() && d.pose_marks.front().first < tick_ns) {
        slot.pose_receive_ns = d.pose_marks.front().second;
        d.pose_marks.pop_front();
      }
    }
    if (slot.send) {
      drivers::ImuFrameInput& f = slot.frame;
      f.sample_counter = k;
      f.t_ns = tick_ns;
      // The signal chain (core/signal_chain/): the interval (t_{k-1}, t_k] at
      // the internal rate through the sensor model and the filters, decimated
      // to tick k, as `imuemu generate` and `imuemu stream` run it; the
      // increments exact over the interval in the encoder's convention.
      const Kinematics* previous = d.previous && d.previous->first + 1 == k ? &d.previous->second : nullptr;
      const signal_chain::ChainOutput m = d.chain->step(k, e.kinematics, e.imu, previous, d.increments);
      if (m.saturated_axes != 0) f.status |= drivers::kStatusSaturated;  // counted when sent
      if (m.has_temperature) {
        // The model's temperature profile, for the protocols that carry one
        // (MAVLink HIL_SENSOR/HIGHRES_IMU); ideal sensors keep the option's value.
        f.has_temperature = true;
        f.temperature_c = m.temperature_c;
      }
      f.t_ns = saturating_sub_ns(tick_ns, m.stamp_shift_ns);  // delay compensation (0 unless configured)
      f.gyro_rad_s = m.gyro_rad_s;
      f.accel_m_s2 = m.accel_m_s2;
      f.period_ns = k > 0 ? tick_ns - grid_ns(t0_ns, k - 1, d.options.rate_hz)
                          : grid_ns(t0_ns, 1, d.options.rate_hz) - tick_ns;
      f.delta_theta_rad = m.delta_theta_rad;
      f.delta_velocity_m_s = m.delta_velocity_m_s;
      if (!e.exact()) f.status |= drivers::kStatusExtrapolated;
      if (d.options.can_encoder && d.options.can_encoder->needs_level_attitude())
        set_level_attitude(e.kinematics, d.options.pipeline.scene.physics, f);
      d.previous.emplace(k, e.kinematics);
      slot.pulse_t_ns = f.t_ns;
      // Issue 18: the faults act on the signal chain's output (the sensor
      // model's stage) and decide what the link does with this sample. Every
      // sample goes through the timeline (its clock starts at the first, and
      // `delayed`/`stuck` need the unfaulted history); with no fault acting
      // the values come back untouched, bit for bit, and no link action.
      d.faults->apply(k, tick_ns, f, slot.link, d.fault_scratch);
      if (!d.fault_scratch.empty()) queue_fault_events(d);
      d.faults_active.store(d.faults->active_count(), std::memory_order_relaxed);
    } else {
      d.previous.reset();
    }
    d.ring.push(slot);
    ++d.next_produce_tick;
  }
  d.engine_lag_ns.store(d.engine->current_lag_ns(), std::memory_order_relaxed);
  std::lock_guard lock(d.live_mutex);
  d.live_counters = d.emitter->counters();
}

void EmissionEngine::Impl::take_live_input() {
  std::vector<io::SourcedPose>& batch = pose_batch;
  batch.clear();
  options.source->queue().drain(batch);
  for (const io::SourcedPose& p : batch) {
    // Whatever one pose does, the next is taken: a failure is that pose's
    // refusal (counted), never the end of the producer thread.
    try {
      take_live_pose(p);
    } catch (const std::exception& e) {
      note_refusal(e.what());
      pose_faults.fetch_add(1, std::memory_order_relaxed);
      poses_refused.fetch_add(1, std::memory_order_relaxed);
    }
  }
  take_live_end();
}

void EmissionEngine::Impl::take_live_pose(const io::SourcedPose& p) {
  {
    bool refused = false;
    for (auto& d : devices) {
      try {
        // The pose's own rates are the body's; a mounted sensor's differ
        // (lever arm, misalignment): its slopes are estimated from its poses.
        const bool had_knot = d->engine->knots_pushed() > 0;
        const TimeNs previous_ns = d->engine->last_knot_ns();
        if (d->mounted) d->engine->push(sensor_pose(p.pose, d->options.mounting));
        else d->engine->push(p.pose, p.rates);
        // The causal method's first sample depending on this pose is the
        // first tick after the previous pose's time.
        if (d->options.pipeline.causal && had_knot && p.receive_ns > 0) {
          d->pose_marks.emplace_back(previous_ns, p.receive_ns);
          if (d->pose_marks.size() > kMaxPoseMarks) d->pose_marks.pop_front();
        }
      } catch (const std::exception& e) {
        refused = true;  // counted, never fatal (as `imuemu stream`)
        note_refusal(e.what());
      }
    }
    if (refused) poses_refused.fetch_add(1, std::memory_order_relaxed);
    else poses_pushed.fetch_add(1, std::memory_order_relaxed);
    if (!mapping_ready.load(std::memory_order_relaxed) && devices.front()->engine->knots_pushed() > 0) {
      // The first pose fixes the grid and the clock: its time is the
      // instant it arrived (receive_ns), not when the producer took it (a
      // stream is acquired at its second pose): else
      // that wait, a pose interval and more, would add to every sample's
      // latency (issue 17). Ticks go out emit_delay_ns after their own time.
      t0_ns = devices.front()->engine->first_knot_ns();
      const TimeNs now = p.receive_ns > 0 ? std::min(p.receive_ns, monotonic_now_ns()) : monotonic_now_ns();
      mapping_value = options.start == StartAlignment::now
                          ? live::TimeMapping::start_now(t0_ns, now, options.speed)
                          : live::TimeMapping::start_at_next_realtime_second(t0_ns, now, realtime_now_ns(), 0,
                                                                             options.speed);
      mapping_ready.store(true, std::memory_order_release);
    }
  }
}

void EmissionEngine::Impl::take_live_end() {
  // A source whose thread failed is not an end of input: the scene fails.
  if (options.source->finished())
    if (const std::string why = options.source->failure(); !why.empty())
      throw std::runtime_error("pose source " + options.source->name() + " failed: " + why);
  if (!live_input_finished && options.source->finished() && options.source->queue().size() == 0) {
    live_input_finished = true;
    for (auto& d : devices) {
      if (d->engine->knots_pushed() < 2) {
        d->end_tick.store(0, std::memory_order_relaxed);
        continue;
      }
      try {
        d->engine->finish();
      } catch (const std::exception& e) {
        note_refusal(e.what());
        poses_refused.fetch_add(1, std::memory_order_relaxed);
      }
      // The grid ends at the last pose: known now, so the emission thread
      // stops there even if the producer runs late.
      const std::uint64_t n = ticks_within(saturating_sub_ns(d->engine->last_knot_ns(), t0_ns), d->options.rate_hz);
      if (n < d->end_tick.load(std::memory_order_relaxed)) d->end_tick.store(n, std::memory_order_relaxed);
    }
  }
}

void EmissionEngine::Impl::record_fault(const char* thread, const char* what) noexcept {
  faults.fetch_add(1, std::memory_order_relaxed);
  try {
    std::lock_guard lock(fault_mutex);
    if (fault.empty()) fault = std::string(thread) + " thread: " + what;
  } catch (...) {  // no memory for the message: the count says it
  }
  stop_requested.store(true, std::memory_order_release);
}

// No exception leaves a thread (std::terminate would abort the daemon without
// closing its devices): it is recorded, both threads stop, and the daemon
// stops the scene with the message and a failure exit code.
void EmissionEngine::Impl::run_producer() noexcept {
  if (live_input() && options.realtime.priority > 1) {  // see start(); refused: the emission thread's note says why
    sched_param sp{};
    sp.sched_priority = options.realtime.priority - 1;
    (void)pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);
  }
  try {
    producer_loop();
  } catch (const std::exception& e) {
    record_fault("producer", e.what());
  } catch (...) {
    record_fault("producer", "unknown exception");
  }
  // The faults still active end with the last sample computed (ground truth).
  try {
    for (auto& d : devices) {
      d->faults->finish(d->fault_scratch);
      if (!d->fault_scratch.empty()) queue_fault_events(*d);
      d->faults_active.store(0, std::memory_order_relaxed);
    }
  } catch (...) {  // no memory for the events: counted as dropped by queue_fault_events where it could
  }
  stop_serving_fault_requests(stop_requested.load() ? "the engine is stopping" : "the engine's input has ended (every sample is computed)");
}

void EmissionEngine::Impl::queue_fault_events(Device& d) {
  for (const fault::FaultEvent& e : d.fault_scratch)
    (e.phase == fault::FaultEvent::Phase::start ? d.faults_started : d.faults_ended).fetch_add(1, std::memory_order_relaxed);
  {
    std::lock_guard lock(fault_events_mutex);
    for (fault::FaultEvent& e : d.fault_scratch) {
      if (fault_events.size() >= options.fault_event_capacity) {
        d.fault_events_dropped.fetch_add(1, std::memory_order_relaxed);
        continue;
      }
      fault_events.push_back(std::move(e));
    }
  }
  d.fault_scratch.clear();
}

Device& EmissionEngine::Impl::device_named(const std::string& name) {
  for (auto& d : devices)
    if (d->options.name == name) return *d;
  std::string names;
  for (auto& d : devices) names += (names.empty() ? "" : ", ") + d->options.name;
  throw std::invalid_argument("no imu '" + name + "' in this scene (imus: " + names + ")");
}

void EmissionEngine::Impl::run_request(FaultRequest& r) {
  switch (r.op) {
    case FaultRequest::Op::inject: {
      Device& d = *r.device;
      // The start, on the device's own clock (time since its sample 0): the
      // next sample this thread computes, plus after_ns.
      const TimeNs next_since_start_ns = grid_ns(0, d.next_produce_tick, d.options.rate_hz);
      r.spec.clock = fault::Clock::since_start;
      r.spec.start_ns = saturating_add_ns(next_since_start_ns, r.after_ns);
      r.spec.device = d.options.name;
      r.spec.source = "control";
      check_protocol_supports(d.options, r.spec.kind);
      r.injected.id = d.faults->inject(r.spec);  // validates: throws before adding
      r.injected.start_since_start_ns = r.spec.start_ns;
      // The first k with floor(k 1e9 / rate) >= start: ceil(start rate / 1e9).
      const Int128 first = (static_cast<Int128>(r.spec.start_ns) * d.options.rate_hz + kNsPerSecond - 1) / kNsPerSecond;
      r.injected.first_sample = static_cast<std::uint64_t>(first);
      d.faults_injected.fetch_add(1, std::memory_order_relaxed);
      d.faults_active.store(d.faults->active_count(), std::memory_order_relaxed);
      break;
    }
    case FaultRequest::Op::clear: {
      Device& d = *r.device;
      r.cleared = d.faults->clear(r.id, d.fault_scratch);
      if (!d.fault_scratch.empty()) queue_fault_events(d);
      if (r.cleared.empty())
        throw std::invalid_argument(r.id ? "imu '" + d.options.name + "' has no fault " + std::to_string(*r.id) + " to clear"
                                         : "imu '" + d.options.name + "' has no fault to clear");
      d.faults_cleared.fetch_add(r.cleared.size(), std::memory_order_relaxed);
      d.faults_active.store(d.faults->active_count(), std::memory_order_relaxed);
      break;
    }
    case FaultRequest::Op::list:
      for (auto& d : devices)
        if (r.device == nullptr || r.device == d.get())
          for (FaultInfo& info : d->faults->list()) r.infos.push_back(std::move(info));
      break;
  }
}

void EmissionEngine::Impl::serve_fault_requests() {
  std::lock_guard lock(mailbox_mutex);
  producer_serving = true;
  if (mailbox.empty()) return;
  for (FaultRequest* r : mailbox) {
    try {
      run_request(*r);
    } catch (...) {
      r->error = std::current_exception();
    }
    r->done = true;
  }
  mailbox.clear();
  mailbox_cv.notify_all();
}

void EmissionEngine::Impl::stop_serving_fault_requests(const std::string& why) {
  std::lock_guard lock(mailbox_mutex);
  producer_serving = false;
  producer_gone_reason = why;
  for (FaultRequest* r : mailbox) {
    r->error = std::make_exception_ptr(std::runtime_error(why));
    r->done = true;
  }
  mailbox.clear();
  mailbox_cv.notify_all();
}

void EmissionEngine::Impl::producer_loop() {
  while (!stop_requested.load(std::memory_order_acquire)) {
    if (producer_fault_for_test.exchange(false)) throw std::runtime_error("test hook: a fault on the producer thread");
    if (producer_stall.load(std::memory_order_relaxed)) {
      sleep_until_monotonic(monotonic_now_ns() + kProducerPollNs);
      continue;
    }
    serve_fault_requests();
    if (live_input()) {
      take_live_input();
      if (!mapping_ready.load(std::memory_order_acquire)) {
        if (live_input_finished) {  // the input ended before any pose: nothing to emit
          input_without_poses.store(true, std::memory_order_release);
          break;
        }
        // Woken by the first pose's arrival (issue 17).
        options.source->queue().wait_for_items_until(saturating_add_ns(monotonic_now_ns(), kMaxSleepChunkNs));
        continue;
      }
    }
    bool all_done = true;
    for (auto& d : devices) {
      produce(*d, live_input());
      if (d->next_produce_tick < d->end_tick.load(std::memory_order_relaxed)) all_done = false;
    }
    if (!live_input()) {
      std::uint64_t pushed = 0, refused = 0;
      for (auto& d : devices) {
        pushed = std::max<std::uint64_t>(pushed, d->on_demand->pushed());
        refused = std::max(refused, d->on_demand->refused());
      }
      poses_pushed.store(pushed, std::memory_order_relaxed);
      poses_refused.store(refused, std::memory_order_relaxed);
    }
    producer_cpu_ns.store(thread_cpu_ns(), std::memory_order_relaxed);
    if (all_done) break;
    if (live_input()) {
      // Until a pose arrives or the next tick may be computed, whichever is
      // first: a pose is taken when it arrives, not at a poll (issue 17).
      const TimeNs now = monotonic_now_ns();
      options.source->queue().wait_for_items_until(std::max(producer_wake_ns(now), saturating_add_ns(now, kProducerMinWaitNs)));
    } else {
      sleep_until_monotonic(monotonic_now_ns() + kProducerPollNs);
    }
  }
}

// Live input, mapping known: when the producer's next tick may be computed
// (producer_lead before it is due) on the device that comes first; a full
// ring is looked at again after kProducerPollNs.
TimeNs EmissionEngine::Impl::producer_wake_ns(TimeNs now) const noexcept {
  TimeNs wake = saturating_add_ns(now, kMaxSleepChunkNs);
  for (const auto& d : devices) {
    if (d->next_produce_tick >= d->end_tick.load(std::memory_order_relaxed)) continue;
    if (d->ring.write_available() == 0) {
      wake = std::min(wake, saturating_add_ns(now, kProducerPollNs));
      continue;
    }
    const TimeNs due = deadline_ns(*d, d->next_produce_tick);
    if (due != kNeverDueNs) wake = std::min(wake, saturating_sub_ns(due, options.producer_lead_ns));
  }
  return wake;
}

// On the emission thread: no allocation, no logging, no blocking call.
void EmissionEngine::Impl::emit_tick(Device& d, std::uint64_t k, bool drop) {
  d.ticks.fetch_add(1, std::memory_order_relaxed);
  Slot* slot = nullptr;
  while (d.ring.read_available() > 0) {
    Slot& front = d.ring.front();
    if (front.tick < k) {  // computed after its deadline had passed: already counted late
      d.ring.pop();
      continue;
    }
    if (front.tick == k) slot = &front;
    break;
  }
  if (slot == nullptr) {
    d.producer_late.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  if (drop) {
    d.dropped_late.fetch_add(1, std::memory_order_relaxed);
    d.ring.pop();
    return;
  }
  if (!slot->send) {
    d.not_sent.fetch_add(1, std::memory_order_relaxed);
    d.ring.pop();
    return;
  }
  // Issue 18 silence (the device off, a restart's off time): the encoder
  // still runs (its counters move on as if the frames went out, so the
  // output after the fault is the fault-free run's) but nothing reaches the
  // wire and no sync pulse is raised; not a write error.
  const bool silenced = slot->link.silence;
  if (silenced) d.silenced.fetch_add(1, std::memory_order_relaxed);
  const drivers::ImuFrameInput& frame = slot->frame;
  try {
  // encode() then periodic(), with the sample's link faults applied (no
  // action: exactly what the encoder alone writes; drivers/link_fault.hpp).
  if (d.options.stream_encoder) {
    d.bytes.clear();
    drivers::encode_with_link_faults(slot->link, *d.options.stream_encoder, frame, d.bytes);
    // A dropped sample with no periodic traffic leaves nothing to write.
    if (!d.bytes.empty()) {
      if (!d.options.transport->write_frame(std::as_bytes(std::span<const std::uint8_t>(d.bytes))))
        d.write_errors.fetch_add(1, std::memory_order_relaxed);
      else if (slot->pose_receive_ns > 0)
        d.pose_latency.record(saturating_sub_ns(monotonic_now_ns(), slot->pose_receive_ns));
    }
  } else {
    d.can_frames.clear();
    drivers::encode_with_link_faults(slot->link, *d.options.can_encoder, frame, d.can_frames);
    for (const drivers::CanFrame& f : d.can_frames)
      if (!d.options.can_output->send(f)) d.write_errors.fetch_add(1, std::memory_order_relaxed);
  }
  } catch (const std::exception&) {  // an encoder refusing a sample: counted, the schedule goes on
    d.write_errors.fetch_add(1, std::memory_order_relaxed);
  }
  if (silenced) {  // not emitted: ticks = emitted + not_sent + underruns + dropped_late + silenced
    d.ring.pop();
    return;
  }
  if (d.options.gpio) d.options.gpio->pulse(frame.sample_counter, slot->pulse_t_ns);
  if ((frame.status & drivers::kStatusSaturated) != 0) d.saturated.fetch_add(1, std::memory_order_relaxed);
  switch (slot->status) {
    case live::EmissionStatus::exact: d.exact.fetch_add(1, std::memory_order_relaxed); break;
    case live::EmissionStatus::extrapolated: d.extrapolated.fetch_add(1, std::memory_order_relaxed); break;
    default: d.blending.fetch_add(1, std::memory_order_relaxed); break;
  }
  d.last_counter.store(frame.sample_counter, std::memory_order_relaxed);
  d.emitted.fetch_add(1, std::memory_order_release);
  d.ring.pop();
}

// One thread for all devices: the devices share one timeline (one mapping,
// one t0), so their deadlines merge into one ordered sequence and the thread
// always sleeps to the earliest; per-sample work is a ring pop, an encode of
// ~100 bytes and a queue write (microseconds), far below any period, so one
// core-bound thread serves many devices, and with SCHED_FIFO there is one
// real-time thread to configure and watch instead of one per device.
void EmissionEngine::Impl::run_emission(std::promise<std::string>* setup) noexcept {
  bool setup_done = false;
  try {
    emission_loop(setup, setup_done);
    return;  // emission_loop ends in finish_emission()
  } catch (const std::exception& e) {
    record_fault("emission", e.what());
  } catch (...) {
    record_fault("emission", "unknown exception");
  }
  if (!setup_done) {  // start() is waiting for the setup: it rethrows this
    try {
      setup->set_exception(std::current_exception());
    } catch (...) {
    }
  }
  finish_emission();
}

void EmissionEngine::Impl::emission_loop(std::promise<std::string>* setup, bool& setup_done) {
  std::string note;
  if (options.realtime.priority > 0) {
    sched_param sp{};
    sp.sched_priority = options.realtime.priority;
    const int rc = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);
    if (rc != 0)
      note = "SCHED_FIFO priority " + std::to_string(options.realtime.priority) + " refused: " + std::strerror(rc);
    else
      realtime_priority = true;
  }
  {
    // Pre-fault the stack the loop will use, so the first deadlines do not
    // page-fault (with mlockall the pages then stay).
    volatile unsigned char stack_touch[128 * 1024];
    for (std::size_t i = 0; i < sizeof(stack_touch); i += 4096) stack_touch[i] = 0;
  }
  const bool give_up = !note.empty() && options.realtime.require_realtime;
  setup->set_value(note);
  setup_done = true;
  if (give_up) return;

  heartbeat_ns.store(monotonic_now_ns(), std::memory_order_relaxed);
  // Live input: the clock is fixed by the first pose.
  while (!mapping_ready.load(std::memory_order_acquire)) {
    if (stop_requested.load(std::memory_order_acquire)) return finish_emission();
    if (input_without_poses.load(std::memory_order_acquire)) {
      finished.store(true, std::memory_order_release);
      return finish_emission();
    }
    const TimeNs now = monotonic_now_ns();
    if (!emission_stall.load(std::memory_order_relaxed)) heartbeat_ns.store(now, std::memory_order_relaxed);
    sleep_until_monotonic(now + kProducerPollNs);
  }
  TimeNs first_deadline_ns = std::numeric_limits<TimeNs>::max();
  for (auto& d : devices) {
    d->next_emit_tick = 0;
    d->next_deadline_ns = deadline_ns(*d, 0);
    if (d->next_deadline_ns == kNeverDueNs) end_at_time_limit(*d, 0);
    first_deadline_ns = std::min(first_deadline_ns, d->next_deadline_ns);
  }
  const TimeNs cpu_at_start_ns = thread_cpu_ns();
  std::uint64_t iterations = 0;
  while (!stop_requested.load(std::memory_order_acquire)) {
    const TimeNs loop_now = monotonic_now_ns();
    if (emission_stall.load(std::memory_order_relaxed)) {  // test hook: no progress, no heartbeat
      sleep_until_monotonic(loop_now + kProducerPollNs);
      continue;
    }
    heartbeat_ns.store(loop_now, std::memory_order_relaxed);
    Device* next = nullptr;
    for (auto& d : devices) {
      if (d->done) continue;
      if (d->next_emit_tick >= d->end_tick.load(std::memory_order_relaxed)) {
        d->done = true;
        continue;
      }
      if (next == nullptr || d->next_deadline_ns < next->next_deadline_ns) next = d.get();
    }
    if (next == nullptr) {
      finished.store(true, std::memory_order_release);
      break;
    }
    if (next->next_deadline_ns - loop_now > kMaxSleepChunkNs) {  // long wait: look at stop/stall meanwhile
      sleep_until_monotonic(loop_now + kMaxSleepChunkNs);
      continue;
    }
    // Devices sharing an instant (400 and 1000 Hz every 5 ms): the later ones
    // are due already, no system call needed.
    const TimeNs woke = next->next_deadline_ns > loop_now ? (sleep_until_monotonic(next->next_deadline_ns), monotonic_now_ns())
                                                          : loop_now;
    const TimeNs lateness_ns = woke - next->next_deadline_ns;
    next->lateness.record(lateness_ns);
    lateness.record(lateness_ns);
    const bool missed = lateness_ns > next->nominal_period_ns;
    if (missed) {
      next->deadline_misses.fetch_add(1, std::memory_order_relaxed);
      deadline_misses.fetch_add(1, std::memory_order_relaxed);
    }
    emit_tick(*next, next->next_emit_tick, missed && options.drop_late_ticks);
    ++next->next_emit_tick;
    next->next_deadline_ns = deadline_ns(*next, next->next_emit_tick);
    if (next->next_deadline_ns == kNeverDueNs) end_at_time_limit(*next, next->next_emit_tick);
    heartbeat_ns.store(woke, std::memory_order_relaxed);
    if (++iterations % 256 == 0) {  // CPU time is a system call: not on every tick
      emission_cpu_ns.store(thread_cpu_ns() - cpu_at_start_ns, std::memory_order_relaxed);
      emission_wall_ns.store(woke - first_deadline_ns, std::memory_order_relaxed);
    }
  }
  emission_cpu_ns.store(thread_cpu_ns() - cpu_at_start_ns, std::memory_order_relaxed);
  emission_wall_ns.store(std::max<TimeNs>(0, monotonic_now_ns() - first_deadline_ns), std::memory_order_relaxed);
  finish_emission();
}

void EmissionEngine::Impl::finish_emission() {
  std::lock_guard lock(done_mutex);
  emitter_exited = true;
  done_cv.notify_all();
}

void EmissionEngine::start() {
  Impl& m = *impl_;
  if (m.started) throw std::logic_error("emission: start() called twice");
  m.started = true;
  if (m.options.realtime.lock_memory) {
    if (mlockall(MCL_CURRENT | MCL_FUTURE) != 0) {
      m.realtime_note = std::string("mlockall refused: ") + std::strerror(errno);
      if (m.options.realtime.require_realtime) throw std::runtime_error("emission: " + m.realtime_note);
    } else {
      m.memory_locked = true;
    }
  }
  // The transports' writer threads one step below the emission thread
  // (issue 17: under load, a normal-priority writer delayed bytes the
  // emission thread had queued on time); 0 restores normal scheduling.
  drivers::set_writer_threads_realtime_priority(m.options.realtime.priority > 1 ? m.options.realtime.priority - 1 : 0);
  if (!m.live_input()) {
    // Every pose is here: fill the rings before the clock starts, so the
    // first tick can be due right away (start_lead_ns).
    m.t0_ns = m.options.trajectory.front().t_ns;
    for (auto& d : m.devices) m.produce(*d, false);
    const TimeNs now = monotonic_now_ns();
    m.mapping_value = m.options.start == StartAlignment::now
                          ? live::TimeMapping::start_now(m.t0_ns, now + m.options.start_lead_ns, m.options.speed)
                          : live::TimeMapping::start_at_next_realtime_second(m.t0_ns, now, realtime_now_ns(),
                                                                             m.options.start_lead_ns, m.options.speed);
    m.mapping_ready.store(true, std::memory_order_release);
  } else {
    m.options.source->start();
    // Live input with SCHED_FIFO: the pose source's thread and the producer
    // (run_producer) one step below the emission thread, so that under load
    // a pose is read, taken and computed into its ticks when it arrives
    // (issue 17); the emission thread, microseconds per tick, stays first.
    if (m.options.realtime.priority > 1) {
      const std::string refused = m.options.source->set_realtime_priority(m.options.realtime.priority - 1);
      if (!refused.empty())
        m.realtime_note += (m.realtime_note.empty() ? "" : "; ") + std::string("pose source SCHED_FIFO refused: ") + refused;
    }
  }
  std::promise<std::string> setup;
  auto setup_result = setup.get_future();
  m.running = true;
  m.emitter = std::thread([&m, &setup] { m.run_emission(&setup); });
  std::string note;
  try {
    note = setup_result.get();
  } catch (...) {  // the emission thread failed before its loop: nothing runs
    m.emitter.join();
    m.running = false;
    if (m.live_input()) m.options.source->stop();
    throw;
  }
  if (!note.empty()) {
    m.realtime_note += (m.realtime_note.empty() ? "" : "; ") + note;
    if (m.options.realtime.require_realtime) {
      m.emitter.join();
      m.running = false;
      if (m.live_input()) m.options.source->stop();
      throw std::runtime_error("emission: " + note);
    }
  }
  m.producer = std::thread([&m] { m.run_producer(); });
}

void EmissionEngine::request_stop() noexcept {
  impl_->stop_requested.store(true, std::memory_order_release);
  if (impl_->live_input()) {  // the producer may sleep on the pose queue: it sees the stop at once
    try {
      impl_->options.source->queue().wake_consumer();
    } catch (...) {  // std::system_error from the mutex: the producer's own deadline still comes
    }
  }
}

bool EmissionEngine::wait(std::chrono::milliseconds timeout) {
  Impl& m = *impl_;
  std::unique_lock lock(m.done_mutex);
  if (timeout.count() < 0) m.done_cv.wait(lock, [&] { return m.emitter_exited || !m.running; });
  else m.done_cv.wait_for(lock, timeout, [&] { return m.emitter_exited || !m.running; });
  return m.finished.load(std::memory_order_acquire);
}

void EmissionEngine::stop(std::chrono::milliseconds flush_timeout) { stop_engine(flush_timeout, false); }

void EmissionEngine::stop_keeping_transports(std::chrono::milliseconds flush_timeout) {
  stop_engine(flush_timeout, true);
}

std::vector<std::unique_ptr<drivers::Transport>> EmissionEngine::take_transports() {
  Impl& m = *impl_;
  if (m.started && !m.stopped) throw std::logic_error("take_transports: the engine is running");
  std::vector<std::unique_ptr<drivers::Transport>> out;
  for (auto& d : m.devices) {
    if (d->options.transport && d->options.stream_encoder) {
      d->transport_final.emplace(d->options.stream_encoder->name() + " -> " + d->options.transport->describe(),
                                 drivers::counters_since(d->options.transport->counters(), d->options.transport_baseline));
    }
    out.push_back(std::move(d->options.transport));
  }
  return out;
}

void EmissionEngine::stop_engine(std::chrono::milliseconds flush_timeout, bool keep_transports) {
  Impl& m = *impl_;
  if (!m.started || m.stopped) return;
  m.stopped = true;
  request_stop();
  if (m.emitter.joinable()) m.emitter.join();
  if (m.producer.joinable()) m.producer.join();
  if (m.live_input()) m.options.source->stop();
  for (auto& d : m.devices) {
    // A bounded drain; what the device did not take by then is counted
    // (transport dropped_at_stop) before the final statistics are read.
    // Kept for the next engine: drained the same way, the link stays open.
    if (d->options.transport) {
      if (keep_transports) (void)d->options.transport->flush(flush_timeout);
      else d->options.transport->stop(flush_timeout);
    }
    if (d->options.can_output) d->options.can_output->stop(flush_timeout);
    if (d->options.gpio) {
      d->gpio_final = d->options.gpio->counters();
      d->options.gpio.reset();  // releases the lines (inactive)
    }
  }
  m.running = false;
  std::lock_guard lock(m.done_mutex);
  m.done_cv.notify_all();
}

EngineStats EmissionEngine::stats() const {
  const Impl& m = *impl_;
  EngineStats s;
  for (const auto& dp : m.devices) {
    const Device& d = *dp;
    DeviceStats ds;
    ds.name = d.options.name;
    ds.rate_hz = d.options.rate_hz;
    if (d.transport_final) {
      ds.output = d.transport_final->first;
      ds.transport = d.transport_final->second;
    } else if (d.options.stream_encoder) {
      ds.output = d.options.stream_encoder->name() + " -> " + d.options.transport->describe();
      ds.transport = drivers::counters_since(d.options.transport->counters(), d.options.transport_baseline);
    } else {
      ds.output = d.options.can_encoder->name() + " -> " + d.options.can_output->describe();
      ds.transport = d.options.can_output->counters();
    }
    ds.emitted = d.emitted.load(std::memory_order_acquire);
    ds.ticks = d.ticks.load(std::memory_order_relaxed);
    ds.exact = d.exact.load(std::memory_order_relaxed);
    ds.extrapolated = d.extrapolated.load(std::memory_order_relaxed);
    ds.blending = d.blending.load(std::memory_order_relaxed);
    ds.not_sent = d.not_sent.load(std::memory_order_relaxed);
    ds.producer_late = d.producer_late.load(std::memory_order_relaxed);
    ds.deadline_misses = d.deadline_misses.load(std::memory_order_relaxed);
    ds.dropped_late = d.dropped_late.load(std::memory_order_relaxed);
    ds.write_errors = d.write_errors.load(std::memory_order_relaxed);
    ds.saturated = d.saturated.load(std::memory_order_relaxed);
    ds.packets = ds.transport.frames_sent;
    ds.bytes = ds.transport.bytes_sent;
    ds.queue_overflows = ds.transport.dropped_queue_full;
    if (d.options.gpio) ds.gpio = d.options.gpio->counters();
    else ds.gpio = d.gpio_final;
    {
      std::lock_guard lock(d.live_mutex);
      ds.live = d.live_counters;
    }
    ds.lateness = d.lateness.summary();
    ds.pose_latency = d.pose_latency.summary();
    ds.pose_latency.buckets = d.pose_latency.buckets();
    ds.engine_lag_ns = d.engine_lag_ns.load(std::memory_order_relaxed);
    ds.last_sample_counter = d.last_counter.load(std::memory_order_relaxed);
    ds.faults.active = d.faults_active.load(std::memory_order_relaxed);
    ds.faults.started = d.faults_started.load(std::memory_order_relaxed);
    ds.faults.ended = d.faults_ended.load(std::memory_order_relaxed);
    ds.faults.injected = d.faults_injected.load(std::memory_order_relaxed);
    ds.faults.cleared = d.faults_cleared.load(std::memory_order_relaxed);
    ds.faults.dropped_events = d.fault_events_dropped.load(std::memory_order_relaxed);
    ds.faults.silenced = d.silenced.load(std::memory_order_relaxed);
    s.emitted += ds.emitted;
    s.devices.push_back(std::move(ds));
  }
  s.lateness = m.lateness.summary();
  s.deadline_misses = m.deadline_misses.load(std::memory_order_relaxed);
  s.emit_delay_ns = m.options.emit_delay_ns;
  s.poses_pushed = m.poses_pushed.load(std::memory_order_relaxed);
  s.poses_refused = m.poses_refused.load(std::memory_order_relaxed);
  {
    std::lock_guard lock(m.refusal_mutex);
    s.last_pose_refusal = m.last_refusal;
  }
  if (m.live_input()) {
    const io::PoseSourceCounters c = m.options.source->counters();
    PoseSourceStats& p = s.pose_source.emplace();
    p.name = m.options.source->name();
    p.received = c.received;
    p.accepted = c.accepted;
    p.rejected = c.rejected();
    p.duplicate = c.duplicate;
    p.out_of_order = c.out_of_order;
    p.overflow_dropped = c.overflow_dropped;
    p.lost = c.lost();
    p.time_jump = c.time_jump;
    p.resyncs = c.resyncs;
    p.held = c.held;
    p.connections = c.connections;
    p.connections_refused = c.connections_refused;
    p.connections_idle_closed = c.connections_idle_closed;
    p.connections_replaced = c.connections_replaced;
  }
  s.realtime_priority = m.realtime_priority;
  s.memory_locked = m.memory_locked;
  s.realtime_note = m.realtime_note;
  s.running = m.running.load() && !m.stopped;
  s.finished = m.finished.load(std::memory_order_acquire);
  s.emission_cpu_ns = m.emission_cpu_ns.load(std::memory_order_relaxed);
  s.producer_cpu_ns = m.producer_cpu_ns.load(std::memory_order_relaxed);
  s.emission_wall_ns = m.emission_wall_ns.load(std::memory_order_relaxed);
  s.thread_faults = m.faults.load(std::memory_order_relaxed);
  s.pose_faults = m.pose_faults.load(std::memory_order_relaxed);
  s.time_limit_ends = m.time_limit_ends.load(std::memory_order_relaxed);
  {
    std::lock_guard lock(m.fault_mutex);
    s.fault = m.fault;
  }
  return s;
}

TimeNs EmissionEngine::last_progress_ns() const noexcept { return impl_->heartbeat_ns.load(std::memory_order_relaxed); }

bool EmissionEngine::healthy(TimeNs now_monotonic_ns, TimeNs max_silence_ns) const noexcept {
  const TimeNs last = last_progress_ns();
  return last != 0 && now_monotonic_ns - last <= max_silence_ns;
}

void EmissionEngine::set_emission_stall_for_test(bool stalled) noexcept { impl_->emission_stall.store(stalled); }
void EmissionEngine::set_producer_stall_for_test(bool stalled) noexcept { impl_->producer_stall.store(stalled); }
void EmissionEngine::inject_producer_fault_for_test() noexcept { impl_->producer_fault_for_test.store(true); }

EmissionEngine::InjectedFault EmissionEngine::inject_fault(const std::string& device, fault::FaultSpec spec,
                                                          TimeNs after_ns) {
  if (after_ns < 0) throw std::invalid_argument("the start delay must be >= 0");
  Impl::FaultRequest r;
  r.op = Impl::FaultRequest::Op::inject;
  r.device = &impl_->device_named(device);
  r.spec = std::move(spec);
  r.after_ns = after_ns;
  impl_->post_and_wait(r);
  return r.injected;
}

std::vector<std::uint64_t> EmissionEngine::clear_faults(const std::string& device, std::optional<std::uint64_t> id) {
  Impl::FaultRequest r;
  r.op = Impl::FaultRequest::Op::clear;
  r.device = &impl_->device_named(device);
  r.id = id;
  impl_->post_and_wait(r);
  return r.cleared;
}

std::vector<FaultInfo> EmissionEngine::list_faults(const std::string& device) {
  Impl::FaultRequest r;
  r.op = Impl::FaultRequest::Op::list;
  if (!device.empty()) r.device = &impl_->device_named(device);
  impl_->post_and_wait(r);
  return r.infos;
}

std::vector<fault::FaultEvent> EmissionEngine::take_fault_events() {
  std::lock_guard lock(impl_->fault_events_mutex);
  std::vector<fault::FaultEvent> out(std::make_move_iterator(impl_->fault_events.begin()),
                                     std::make_move_iterator(impl_->fault_events.end()));
  impl_->fault_events.clear();
  return out;
}

std::optional<live::TimeMapping> EmissionEngine::mapping() const {
  if (!impl_->mapping_ready.load(std::memory_order_acquire)) return std::nullopt;
  return impl_->mapping_value;
}

namespace {
nlohmann::json lateness_json(const LatenessSummary& l) {
  return {{"count", l.count},     {"p50_ns", l.p50_ns}, {"p99_ns", l.p99_ns},
          {"p99_9_ns", l.p999_ns}, {"max_ns", l.max_ns}, {"mean_ns", l.mean_ns}};
}
// With the non-empty buckets (upper bound in us, count), for a histogram
// against a goal (issue 17: pose_latency).
nlohmann::json lateness_json_with_buckets(const LatenessSummary& l) {
  nlohmann::json j = lateness_json(l);
  nlohmann::json buckets = nlohmann::json::array();
  for (const LatenessBucket& b : l.buckets)
    buckets.push_back({{"upper_us", static_cast<double>(b.upper_ns) / 1e3}, {"count", b.count}});
  j["buckets"] = std::move(buckets);
  return j;
}
}  // namespace

nlohmann::json to_json(const EngineStats& s) {
  nlohmann::json devices = nlohmann::json::array();
  for (const DeviceStats& d : s.devices) {
    nlohmann::json j{{"name", d.name},
                     {"output", d.output},
                     {"rate_hz", d.rate_hz},
                     {"ticks", d.ticks},
                     {"emitted", d.emitted},
                     {"samples", {{"exact", d.exact}, {"extrapolated", d.extrapolated}, {"blending", d.blending}}},
                     {"not_sent", d.not_sent},
                     {"underruns", d.producer_late},
                     {"deadline_misses", d.deadline_misses},
                     {"dropped_late", d.dropped_late},
                     {"write_errors", d.write_errors},
                     {"saturated", d.saturated},
                     {"packets", d.packets},
                     {"bytes", d.bytes},
                     {"queue_overflows", d.queue_overflows},
                     {"transport",
                      {{"frames", d.transport.frames},
                       {"frames_sent", d.transport.frames_sent},
                       {"dropped_queue_full", d.transport.dropped_queue_full},
                       {"dropped_link_down", d.transport.dropped_link_down},
                       {"write_errors", d.transport.write_errors},
                       {"queued", d.transport.queued},
                       {"dropped_at_stop", d.transport.dropped_at_stop},
                       {"link_down_events", d.transport.link_down_events}}},
                     {"live",
                      {{"ticks", d.live.ticks},
                       {"exact", d.live.exact},
                       {"extrapolated", d.live.extrapolated},
                       {"blending", d.live.blending},
                       {"paused", d.live.paused},
                       {"waiting", d.live.waiting},
                       {"gap", d.live.gap},
                       {"gap_events", d.live.gap_events},
                       {"underrun_events", d.live.underrun_events},
                       {"stale_discarded", d.live.stale_discarded}}},
                     {"lateness", lateness_json(d.lateness)},
                     {"pose_latency", lateness_json_with_buckets(d.pose_latency)},
                     {"engine_lag_ns", d.engine_lag_ns},
                     {"last_sample_counter", d.last_sample_counter},
                     {"faults",
                      {{"active", d.faults.active},
                       {"started", d.faults.started},
                       {"ended", d.faults.ended},
                       {"injected", d.faults.injected},
                       {"cleared", d.faults.cleared},
                       {"dropped_events", d.faults.dropped_events},
                       {"silenced", d.faults.silenced}}}};
    if (d.gpio)
      j["gpio"] = {{"pulses", d.gpio->pulses},
                   {"pps_pulses", d.gpio->pps_pulses},
                   {"skipped_pulses", d.gpio->skipped_pulses},
                   {"set_errors", d.gpio->set_errors},
                   {"max_trailing_edge_delay_ns", d.gpio->max_trailing_edge_delay_ns},
                   {"helper_faults", d.gpio->helper_faults},
                   {"down", d.gpio->down}};
    devices.push_back(std::move(j));
  }
  nlohmann::json j{{"devices", std::move(devices)},
                   {"emitted", s.emitted},
                   {"deadline_misses", s.deadline_misses},
                   {"lateness", lateness_json(s.lateness)},
                   {"emit_delay_ns", s.emit_delay_ns},
                   {"poses_pushed", s.poses_pushed},
                   {"poses_refused", s.poses_refused},
                   {"last_pose_refusal", s.last_pose_refusal},
                   {"realtime_priority", s.realtime_priority},
                   {"memory_locked", s.memory_locked},
                   {"realtime_note", s.realtime_note},
                   {"running", s.running},
                   {"emission_cpu_ns", s.emission_cpu_ns},
                   {"producer_cpu_ns", s.producer_cpu_ns},
                   {"emission_wall_ns", s.emission_wall_ns},
                   {"thread_faults", s.thread_faults},
                   {"pose_faults", s.pose_faults},
                   {"time_limit_ends", s.time_limit_ends},
                   {"fault", s.fault},
                   {"finished", s.finished}};
  if (s.pose_source)
    j["pose_source"] = {{"name", s.pose_source->name},
                        {"received", s.pose_source->received},
                        {"accepted", s.pose_source->accepted},
                        {"rejected", s.pose_source->rejected},
                        {"duplicate", s.pose_source->duplicate},
                        {"out_of_order", s.pose_source->out_of_order},
                        {"overflow_dropped", s.pose_source->overflow_dropped},
                        {"lost", s.pose_source->lost},
                        {"time_jump", s.pose_source->time_jump},
                        {"resyncs", s.pose_source->resyncs},
                        {"held", s.pose_source->held},
                        {"connections", s.pose_source->connections},
                        {"connections_refused", s.pose_source->connections_refused},
                        {"connections_idle_closed", s.pose_source->connections_idle_closed},
                        {"connections_replaced", s.pose_source->connections_replaced}};
  return j;
}

}  // namespace imuemu::emission
