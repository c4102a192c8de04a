// The emission engine (daemon/engine/emission.hpp): building it from its
// options (each device's stream engine, emitter, signal chain, faults and
// ring), and its life cycle on the controlling thread - start (the rings
// filled, the mapping fixed, both threads up), stop (both threads joined,
// each device stopped: a bounded drain, GPIO released), wait, the health
// and test hooks. The threads themselves: producer.cpp, fault_mailbox.cpp,
// emission_thread.cpp; the statistics: engine_stats.cpp; the shared state:
// engine_state.hpp.
#include <sys/mman.h>
#include <time.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <stdexcept>

#include "daemon/engine/engine_state.hpp"
#include "drivers/queued_writer.hpp"

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

TimeNs thread_cpu_ns() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<TimeNs>(ts.tv_sec) * kNsPerSecond + ts.tv_nsec;
}

void sleep_until_monotonic(TimeNs due_ns) noexcept {
  timespec ts{static_cast<time_t>(due_ns / kNsPerSecond), static_cast<long>(due_ns % kNsPerSecond)};
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

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
    // (The message from before the device seam: a scene's CAN protocol on
    // transport null still gets it, there being no CAN output for that.)
    if (!dev.device)
      throw std::invalid_argument(where + "expected exactly one output: a stream encoder with a transport, or a CAN encoder with a CAN output");
    if (dev.blend_ns < 0) throw std::invalid_argument(where + "blend_ns < 0");
    dev.pipeline.rate_hz = dev.rate_hz;
    const TimeNs ring_span_ns = std::max<TimeNs>(o.producer_lead_ns, 250'000'000);
    const std::size_t capacity = o.ring_capacity > 0 ? o.ring_capacity : ring_capacity_for(ring_span_ns, dev.rate_hz);
    auto d = std::make_unique<DeviceState>(std::move(dev), capacity);
    d->nominal_period_ns = kNsPerSecond / d->options.rate_hz;
    d->engine = std::make_unique<StreamPipeline>(d->options.pipeline);
    live::LiveEmitterOptions lo;
    lo.scene = d->options.pipeline.scene;
    lo.underrun = d->options.underrun;
    lo.blend_ns = d->options.blend_ns;
    d->emitter = std::make_unique<live::LiveEmitter>(lo);
    d->chain.emplace(d->options.pipeline.scene, d->options.sensor_model, d->options.chain, d->options.rate_hz,
                     d->options.name);
    d->needs = d->options.device->needs();
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
    const device::Device& port = *d->options.device;
    for (const fault::FaultSpec& f : d->options.faults.scheduled) port.check_supports(d->options.name, f.kind);
    if (d->options.faults.random.per_hour > 0.0)
      for (const fault::Kind kind : d->options.faults.random.kinds) port.check_supports(d->options.name, kind);
    try {
      d->faults = std::make_unique<DeviceFaults>(
          d->options.name, d->options.rate_hz, d->options.sensor_model, d->options.faults,
          port.max_bytes_per_sample());
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument(where + "faults: " + e.what());
    }
    impl_->devices.push_back(std::move(d));
  }
}

EmissionEngine::~EmissionEngine() {
  try {
    stop(std::chrono::milliseconds(200));
  } catch (...) {
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
  // A device that reads its port starts its reader before the first tick.
  for (auto& d : m.devices) d->options.device->start();
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
  for (auto& d : m.devices) out.push_back(d->options.device->take_transport());
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
  // A bounded drain; what the device did not take by then is counted
  // (transport dropped_at_stop) before the final statistics are read. Kept
  // for the next engine: drained the same way, the link stays open. The
  // GPIO lines are released (inactive).
  for (auto& d : m.devices) d->options.device->stop(flush_timeout, keep_transports);
  m.running = false;
  std::lock_guard lock(m.done_mutex);
  m.done_cv.notify_all();
}

TimeNs EmissionEngine::last_progress_ns() const noexcept { return impl_->heartbeat_ns.load(std::memory_order_relaxed); }

bool EmissionEngine::healthy(TimeNs now_monotonic_ns, TimeNs max_silence_ns) const noexcept {
  const TimeNs last = last_progress_ns();
  return last != 0 && now_monotonic_ns - last <= max_silence_ns;
}

void EmissionEngine::set_emission_stall_for_test(bool stalled) noexcept { impl_->emission_stall.store(stalled); }
void EmissionEngine::set_producer_stall_for_test(bool stalled) noexcept { impl_->producer_stall.store(stalled); }
void EmissionEngine::inject_producer_fault_for_test() noexcept { impl_->producer_fault_for_test.store(true); }

std::optional<live::TimeMapping> EmissionEngine::mapping() const {
  if (!impl_->mapping_ready.load(std::memory_order_acquire)) return std::nullopt;
  return impl_->mapping_value;
}

}  // namespace imuemu::emission
