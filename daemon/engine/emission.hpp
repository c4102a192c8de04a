// The daemon's real-time emission engine (issue 6): emulated IMUs ("devices")
// sending the streaming engine's samples on their own output grids, each
// sample at its instant on CLOCK_MONOTONIC.
//
//   poses (trajectory up front, or an io::PoseSource)
//     --producer thread (normal priority): per device StreamPipeline +
//       LiveEmitter, a bounded lead ahead of each deadline --> ImuFrameInput
//     --lock-free SPSC ring per device-->
//   emission thread (optionally SCHED_FIFO): sleeps to absolute deadlines,
//     pops, hands the sample to its device (daemon/device/device.hpp:
//     encodes, queues on the output, pulses GPIO; never blocks), records
//     lateness.
//
// Timeline: the output grid of a device at rate r is the stream's
//   t_k = t0 + floor(k * 1e9 / r) ns  (core/pipeline.hpp output_grid),
// t0 the first pose's time; tick k is due at
//   mapping.monotonic_at(t_k + emit_delay_ns)  (core/time_mapping.hpp),
// computed from k in integers (no accumulated drift). sample_counter = k, so
// sample k is `imuemu generate`'s sample k at the same rate; a tick that is
// not sent (producer late, pause policy) leaves a gap the receiver sees.
//
// Faults (issue 18, daemon/device/device_faults.hpp): the producer runs every
// sample through the device's fault timeline after the signal chain (sensor
// faults change the values, time faults the frame's t_ns) and leaves the
// sample's drivers::LinkActions in its ring slot; the emission thread hands
// them with the sample to the device, which applies them in
// drivers::encode_with_link_faults (no action: encode() + periodic() byte
// for byte). Run-time inject/list/clear reach the producer through a
// mailbox; the ground-truth events go the other way through a bounded queue
// (take_fault_events). The emission thread takes no lock and allocates
// nothing for any of it.
//
// Thread safety: start/request_stop/wait/stop from one controlling thread;
// stats(), last_progress_ns(), the test hooks and the fault requests from
// any thread but the emission thread.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "core/live_emitter.hpp"
#include "core/mounting.hpp"
#include "core/pipeline.hpp"
#include "core/sensor/sensor_model.hpp"
#include "core/signal_chain/signal_chain.hpp"
#include "core/time_mapping.hpp"
#include "daemon/device/device.hpp"
#include "daemon/device/device_faults.hpp"
#include "daemon/engine/lateness_histogram.hpp"
#include "drivers/gpio_sync.hpp"
#include "drivers/transport.hpp"

namespace imuemu::io {
class PoseSource;
struct PoseSourceCounters;
}  // namespace imuemu::io

namespace imuemu::emission {

// One emulated IMU: its samples (rate, streaming engine, mounting, sensor,
// signal chain, faults) and the device they go out of.
struct DeviceOptions {
  std::string name = "imu0";
  std::int64_t rate_hz = 400;  // output rate, integer Hz (sets pipeline.rate_hz)
  // Streaming engine settings (kernel window, scene physics, ...); rate_hz is
  // overwritten by the device's.
  PipelineOptions pipeline;
  live::UnderrunPolicy underrun = live::UnderrunPolicy::extrapolate;
  TimeNs blend_ns = 200'000'000;
  // What the navigation computer sees on the port (daemon/device/device.hpp):
  // device::make_stream_device (encoder, transport, optional GPIO sync) or
  // device::make_can_device (encoder, CAN output, optional GPIO sync).
  std::unique_ptr<device::Device> device;
  // Where this IMU sits on the body (core/mounting.hpp): the device smooths
  // and differentiates the sensor's own poses, sensor_pose(pose, mounting).
  Mounting mounting;
  // The sensor's errors (core/sensor/sensor_model.hpp), run at the signal
  // chain's internal rate (the noise streams are keyed by the device's name);
  // empty or ideal: none.
  std::optional<sensor::SensorModelSpec> sensor_model;
  // The device's signal chain (core/signal_chain/signal_chain.hpp): internal
  // rate, filters, decimation, delay compensation; ideal by default.
  signal_chain::ChainSpec chain;
  // Fault injection (issue 18, daemon/device/device_faults.hpp): the scene's faults
  // of this device; more are injected at run time (inject_fault). Sensor
  // faults act on the signal chain's output, link faults at the encoder.
  DeviceFaultPlan faults;
};

enum class StartAlignment { now, next_realtime_second };

struct RealtimeOptions {
  int priority = 0;              // SCHED_FIFO priority of the emission thread (1..99); 0: normal scheduling
                                 // (from 2: the writer threads and, live, the producer and the pose source at -1)
  bool lock_memory = false;      // mlockall(MCL_CURRENT | MCL_FUTURE)
  bool require_realtime = false; // start() throws when the priority or the lock is refused
};

struct EngineOptions {
  // Input: either every pose up front (trajectory file, built-in sample), or
  // a live source (not owned; started and stopped by the engine).
  std::vector<Pose> trajectory;
  io::PoseSource* source = nullptr;

  StartAlignment start = StartAlignment::now;
  // Trajectory input: the first tick is due this long after start() (the
  // producer has filled the rings before; this only covers the thread start).
  TimeNs start_lead_ns = 20'000'000;
  // Live input: ticks are due emit_delay_ns after their trajectory time on the
  // mapping anchored at the first pose's arrival (the engine's look-ahead plus
  // a margin, as `imuemu stream`), and the producer asks the LiveEmitter for
  // a tick producer_lead_ns before it is due.
  TimeNs emit_delay_ns = 1'100'000'000;
  TimeNs producer_lead_ns = 20'000'000;
  live::SpeedFactor speed;
  // Stop after this many ticks per device (e.g. rate x seconds); empty: to the
  // end of the input.
  std::optional<std::uint64_t> max_ticks_per_device;
  // Ring capacity per device in samples; 0: enough for max(producer lead,
  // 250 ms) at the device's rate.
  std::size_t ring_capacity = 0;
  RealtimeOptions realtime;
  // A tick whose wake-up is more than one period late (a deadline miss) is
  // not sent: it would reach the receiver after the next sample was due, and
  // after a stall the backlog would go out as a burst no real IMU produces.
  // The receiver sees a gap in sample_counter instead. false: send it late.
  bool drop_late_ticks = true;
  // Ground-truth fault events waiting for take_fault_events() (all devices);
  // beyond this they are dropped and counted (faults.dropped_events).
  std::size_t fault_event_capacity = 4096;
  // How long inject_fault/clear_faults/list_faults wait for the producer
  // thread to take the request (it looks every millisecond); after that the
  // request is withdrawn (nothing changed) and refused.
  std::chrono::milliseconds fault_request_timeout{1000};
};

// Issue 18 counters of one device.
struct FaultCounters {
  std::uint64_t active = 0;          // faults affecting samples now (a gauge, as of the newest sample computed)
  std::uint64_t started = 0, ended = 0;  // start / end events (first / last affected sample)
  std::uint64_t injected = 0, cleared = 0;  // run-time requests taken
  std::uint64_t dropped_events = 0;  // ground-truth events lost: the queue was full (the log writer too slow)
  std::uint64_t silenced = 0;        // ticks not sent: silence, a restart's off time (not write errors)
};

struct DeviceStats {
  std::string name, output;     // output: encoder and transport description
  std::int64_t rate_hz = 0;
  std::uint64_t ticks = 0;      // deadlines passed: emitted + not_sent + producer_late + dropped_late
  std::uint64_t emitted = 0;    // samples encoded and offered to the transport
  std::uint64_t exact = 0, extrapolated = 0, blending = 0;
  std::uint64_t not_sent = 0;   // the producer had the tick but nothing to send (waiting, paused)
  std::uint64_t producer_late = 0;  // underruns: nothing from the producer when the tick was due
  std::uint64_t deadline_misses = 0;  // woke more than one period late
  std::uint64_t dropped_late = 0;     // deadline misses not sent (EngineOptions::drop_late_ticks)
  std::uint64_t write_errors = 0;     // frames the transport refused while its link was up (queue full, kernel, invalid)
  std::uint64_t dropped_link_down = 0;  // frames the transport refused while its link was down (no reader on the pty)
  std::uint64_t saturated = 0;        // samples with an axis clipped to the sensor's range (kStatusSaturated)
  std::uint64_t packets = 0, bytes = 0, queue_overflows = 0;  // the transport's own counters
  drivers::TransportCounters transport;
  std::optional<drivers::GpioSyncCounters> gpio;
  std::optional<device::CommandStatus> commands;  // a device that answers its driver
  live::LiveCounters live;
  LatenessSummary lateness;
  // Live input, causal method: pose arrival -> its first dependent sample
  // handed to the transport (docs/streaming.md "Low-latency live input").
  LatenessSummary pose_latency;
  TimeNs engine_lag_ns = 0;          // StreamPipeline::current_lag_ns, as last seen by the producer
  std::uint64_t last_sample_counter = 0;
  FaultCounters faults;
};

// The live pose source's counters (io::PoseSourceCounters, the main ones).
struct PoseSourceStats {
  std::string name;
  std::uint64_t received = 0, accepted = 0, rejected = 0, duplicate = 0, out_of_order = 0, overflow_dropped = 0,
                lost = 0;
  // Live time (docs/pose-wire-format.md "Live time"): strays dropped, stream
  // re-acquisitions, poses held now (a gauge).
  std::uint64_t time_jump = 0, resyncs = 0, held = 0;
  // TCP: clients accepted, refused (slot taken), closed idle, replaced while idle.
  std::uint64_t connections = 0, connections_refused = 0, connections_idle_closed = 0, connections_replaced = 0;
  // MAVLink: packets of a vehicle other than the one the source took (also in rejected).
  std::uint64_t other_sender = 0;
};

struct EngineStats {
  std::vector<DeviceStats> devices;
  LatenessSummary lateness;          // all devices' wake-ups
  std::uint64_t deadline_misses = 0;
  std::uint64_t emitted = 0;
  TimeNs emit_delay_ns = 0;          // live input: how far behind the poses ticks go out
  std::uint64_t poses_pushed = 0;
  std::uint64_t poses_refused = 0;   // poses the method refused (counted, not fatal)
  std::string last_pose_refusal;     // the method's reason for the newest one (empty: none)
  std::optional<PoseSourceStats> pose_source;  // live input only
  bool realtime_priority = false;    // SCHED_FIFO granted
  bool memory_locked = false;
  std::string realtime_note;         // why not, when asked for
  bool running = false;
  bool finished = false;             // every device reached its end
  // CPU time the threads used (CLOCK_THREAD_CPUTIME_ID), updated as they run;
  // emission_wall_ns: the emission thread's time from its first deadline on.
  TimeNs emission_cpu_ns = 0, producer_cpu_ns = 0, emission_wall_ns = 0;
  // No exception leaves the engine's threads: one that reaches a thread's
  // top is recorded here (fault: the first one's "producer thread: what"),
  // both threads stop, and the caller decides (imuemud stops the scene with
  // a failure exit code). pose_faults: live poses whose handling failed,
  // counted as refused and skipped. time_limit_ends: devices whose grid ended
  // because the next tick's instant does not fit int64 ns (a stream stamped
  // near the limit, a very slow replay speed).
  std::uint64_t thread_faults = 0, pose_faults = 0, time_limit_ends = 0;
  std::string fault;
};

nlohmann::json to_json(const EngineStats& stats);

class EmissionEngine {
 public:
  // Validates (throws std::invalid_argument naming the device and option):
  // devices present with a device each, rate 1..1'000'000, input given, the
  // scene's faults ones the device's protocol can show.
  EmissionEngine(EngineOptions options, std::vector<DeviceOptions> devices);
  ~EmissionEngine();  // stops if running
  EmissionEngine(const EmissionEngine&) = delete;
  EmissionEngine& operator=(const EmissionEngine&) = delete;

  // Starts the producer and the emission thread. Throws std::runtime_error if
  // realtime.require_realtime and the system refused; std::invalid_argument
  // if the trajectory cannot start (fewer than two poses).
  void start();
  // Asks both threads to stop; the emission thread finishes the tick it is on
  // (packets are whole). One lock-free atomic store: async-signal-safe.
  void request_stop() noexcept;
  // Waits until every device has reached its end or a stop was requested;
  // true if finished. timeout < 0: no limit.
  bool wait(std::chrono::milliseconds timeout = std::chrono::milliseconds(-1));
  // request_stop + join + stop the devices (each output a bounded drain of up
  // to flush_timeout, then what is left counted as dropped_at_stop; GPIO
  // released).
  void stop(std::chrono::milliseconds flush_timeout = std::chrono::milliseconds(500));
  // As stop(), but the byte-stream transports are only flushed (bounded by
  // flush_timeout), not stopped: take_transports() then hands them to the
  // next engine, so a reload does not hang up a pty's reader.
  void stop_keeping_transports(std::chrono::milliseconds flush_timeout = std::chrono::milliseconds(500));
  // After a stop: each device's byte-stream transport (nullptr for CAN),
  // moved out; stats() keeps reporting their counters as they were.
  std::vector<std::unique_ptr<drivers::Transport>> take_transports();

  EngineStats stats() const;
  // CLOCK_MONOTONIC of the emission thread's last loop iteration (0 before
  // start): the watchdog reports healthy only while this advances.
  TimeNs last_progress_ns() const noexcept;
  bool healthy(TimeNs now_monotonic_ns, TimeNs max_silence_ns) const noexcept;

  // Test hooks: the emission thread stops making progress (no ticks, no
  // heartbeat) while stalled; the producer computes nothing while starved.
  void set_emission_stall_for_test(bool stalled) noexcept;
  void set_producer_stall_for_test(bool stalled) noexcept;
  // Test hook: the producer thread's next iteration throws (the catch-all
  // that keeps an exception from aborting the process is what is tested).
  void inject_producer_fault_for_test() noexcept;

  // The mapping once known (trajectory: at start(); live: at the first pose).
  std::optional<live::TimeMapping> mapping() const;

  // Run-time faults (issue 18): from any thread but the emission thread
  // (the daemon's io thread). The request goes through a mailbox the producer
  // thread takes within about a millisecond; the reply comes from there.
  // Throws std::invalid_argument (unknown device, a spec fault::validate
  // refuses, no such fault id) and std::runtime_error (the engine is not
  // running, its input ended, or the producer did not take the request
  // within fault_request_timeout); a refused request changes nothing.
  struct InjectedFault {
    std::uint64_t id = 0;
    std::uint64_t first_sample = 0;  // the first sample at or after the start (unless the fault is intermittent)
    TimeNs start_since_start_ns = 0;
  };
  // The fault starts after_ns after the next sample the producer computes
  // (the samples before it are in the ring already, at most the producer's
  // lead); spec.clock and spec.start_ns are set from that.
  InjectedFault inject_fault(const std::string& device, fault::FaultSpec spec, TimeNs after_ns);
  // Ends fault `id` of the device, or all (nullopt); returns the ids ended.
  std::vector<std::uint64_t> clear_faults(const std::string& device, std::optional<std::uint64_t> id);
  // Every fault the device knows (scheduled, active, ended); empty device: all.
  std::vector<FaultInfo> list_faults(const std::string& device);
  // The ground-truth events since the last call, in the order they happened
  // per device (the daemon writes them to the fault log).
  std::vector<fault::FaultEvent> take_fault_events();

 private:
  void stop_engine(std::chrono::milliseconds flush_timeout, bool keep_transports);
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

TimeNs monotonic_now_ns() noexcept;
TimeNs realtime_now_ns() noexcept;

}  // namespace imuemu::emission
