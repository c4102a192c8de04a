// The emission engine's shared state (internal to daemon/engine/): what the
// producer thread (producer.cpp, fault_mailbox.cpp), the emission thread
// (emission_thread.cpp), the statistics (engine_stats.cpp) and the
// controlling thread (emission.cpp) share, and which thread owns which part.
// Per device: a DeviceState (its stream engine, signal chain, faults, ring of
// computed slots, and its counters as relaxed atomics); for the engine: the
// Impl (the devices, the time mapping, the threads, the fault mailbox).
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <exception>
#include <future>
#include <limits>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <boost/lockfree/spsc_queue.hpp>

#include "core/time_arith.hpp"
#include "daemon/device/device.hpp"
#include "daemon/engine/emission.hpp"
#include "daemon/engine/time_grid.hpp"
#include "io/pose_source.hpp"

namespace imuemu::emission {

inline constexpr TimeNs kMaxSleepChunkNs = 50'000'000;  // a stop request is seen within this
inline constexpr TimeNs kProducerPollNs = 1'000'000;

// CLOCK_THREAD_CPUTIME_ID of the calling thread.
TimeNs thread_cpu_ns() noexcept;
// clock_nanosleep to an absolute CLOCK_MONOTONIC instant (EINTR: sleeps on).
void sleep_until_monotonic(TimeNs due_ns) noexcept;

// Lowers an end tick to k (never raises it): either thread may find the end.
inline void lower_end_tick(std::atomic<std::uint64_t>& end_tick, std::uint64_t k) noexcept {
  std::uint64_t current = end_tick.load(std::memory_order_relaxed);
  while (k < current && !end_tick.compare_exchange_weak(current, k, std::memory_order_relaxed)) {
  }
}

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
// sample needs, so its memory stays O(window) however long the trajectory
// (producer.cpp).
class OnDemandSource final : public live::ExactSampleSource {
 public:
  OnDemandSource(StreamPipeline& engine, const std::vector<Pose>& knots) : engine_(engine), knots_(knots) {}
  std::optional<live::ExactSample> next_sample() override;
  std::uint64_t refused() const { return refused_; }
  std::size_t pushed() const { return next_knot_; }

 private:
  StreamPipeline& engine_;
  const std::vector<Pose>& knots_;
  std::size_t next_knot_ = 0;
  bool finished_ = false;
  std::uint64_t refused_ = 0;
};

struct DeviceState {
  DeviceOptions options;  // options.device: the emulated device (daemon/device/device.hpp)
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
  device::SampleNeeds needs;  // what the device needs computed (asked once)
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

  // Shared (relaxed atomics; snapshot by stats()).
  std::atomic<std::uint64_t> end_tick{std::numeric_limits<std::uint64_t>::max()};  // no tick at or after
  std::atomic<std::uint64_t> ticks{0}, emitted{0}, exact{0}, extrapolated{0}, blending{0}, not_sent{0},
      producer_late{0}, deadline_misses{0}, dropped_late{0}, write_errors{0}, dropped_link_down{0}, last_counter{0},
      saturated{0};
  std::atomic<TimeNs> engine_lag_ns{0};
  std::atomic<std::uint64_t> faults_active{0}, faults_started{0}, faults_ended{0}, faults_injected{0},
      faults_cleared{0}, fault_events_dropped{0}, silenced{0};
  LatenessHistogram lateness;
  // End-to-end latency of live poses (causal method): from a pose's arrival
  // to its first dependent sample handed to the device's output. pose_marks
  // (producer thread only): (previous pose's time, this pose's arrival); the
  // first tick after that time not extrapolated is the first to depend on it.
  LatenessHistogram pose_latency;
  std::deque<std::pair<TimeNs, TimeNs>> pose_marks;
  mutable std::mutex live_mutex;  // producer <-> stats(), never the emission thread
  live::LiveCounters live_counters;

  DeviceState(DeviceOptions o, std::size_t capacity) : options(std::move(o)), ring(capacity) {}
};

struct EmissionEngine::Impl {
  EngineOptions options;
  std::vector<std::unique_ptr<DeviceState>> devices;

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

  // Issue 18 run-time fault requests (fault_mailbox.cpp): the io thread
  // posts one and waits; the producer thread serves the mailbox at the top
  // of each iteration, under the lock (requests are quick: a list, a
  // validate, a push), so a request the caller withdraws after its timeout
  // is never half done.
  struct FaultRequest {
    enum class Op { inject, clear, list } op = Op::list;
    DeviceState* device = nullptr;  // list: nullptr = all
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
  void post_and_wait(FaultRequest& r);
  void stop_serving_fault_requests(const std::string& why);
  void run_request(FaultRequest& r);
  DeviceState& device_named(const std::string& name);
  // Ground-truth events for the daemon's fault log (producer -> io thread).
  mutable std::mutex fault_events_mutex;
  std::deque<fault::FaultEvent> fault_events;  // under fault_events_mutex, at most fault_event_capacity
  void queue_fault_events(DeviceState& d);

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
  TimeNs deadline_ns(const DeviceState& d, std::uint64_t k) const noexcept {
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
  void end_at_time_limit(DeviceState& d, std::uint64_t k) noexcept {
    lower_end_tick(d.end_tick, k);
    time_limit_ends.fetch_add(1, std::memory_order_relaxed);
  }
  // A thread failed with an exception: recorded (the first one's message),
  // counted, and both threads stop; the daemon reports it (EngineStats::fault).
  void record_fault(const char* thread, const char* what) noexcept;
  bool live_input() const { return options.source != nullptr; }

  // producer.cpp
  void produce(DeviceState& d, bool time_gated);
  void take_live_input();
  void take_live_pose(const io::SourcedPose& p);
  void take_live_end();
  void run_producer() noexcept;
  void producer_loop();
  TimeNs producer_wake_ns(TimeNs now) const noexcept;
  // emission_thread.cpp
  void run_emission(std::promise<std::string>* setup) noexcept;
  void emission_loop(std::promise<std::string>* setup, bool& setup_done);
  std::string set_up_realtime();
  void emit_tick(DeviceState& d, std::uint64_t k, bool drop);
  void finish_emission();
};

}  // namespace imuemu::emission
