// The engine's emission thread (optionally SCHED_FIFO): it sleeps to each
// device's next absolute deadline, takes that tick's slot from the device's
// ring, hands the sample to the device (daemon/device/device.hpp: encode,
// write, sync pulse) and records the wake-up's lateness. On this thread:
// no allocation, no lock, no logging, no blocking call.
#include <pthread.h>
#include <sched.h>

#include <algorithm>
#include <cstring>
#include <limits>

#include "daemon/engine/engine_state.hpp"

namespace imuemu::emission {

// On the emission thread: no allocation, no logging, no blocking call.
void EmissionEngine::Impl::emit_tick(DeviceState& d, std::uint64_t k, bool drop) {
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
  // Issue 18 silence (the device off, a restart's off time): the device's
  // encoder still runs (its counters move on as if the frames went out, so
  // the output after the fault is the fault-free run's) but nothing reaches
  // the wire and no sync pulse is raised; not a write error.
  const bool silenced = slot->link.silence;
  if (silenced) d.silenced.fetch_add(1, std::memory_order_relaxed);
  const drivers::ImuFrameInput& frame = slot->frame;
  // encode() then periodic() with the sample's link faults applied, the
  // frames to the output, the sync pulse: the device's (daemon/device/device.hpp).
  const device::EmitOutcome out = d.options.device->emit(frame, slot->link, slot->pulse_t_ns);
  if (out.refused > 0) d.write_errors.fetch_add(out.refused, std::memory_order_relaxed);
  if (out.refused_link_down > 0) d.dropped_link_down.fetch_add(out.refused_link_down, std::memory_order_relaxed);
  if (out.accepted_ns != 0 && slot->pose_receive_ns > 0)
    d.pose_latency.record(saturating_sub_ns(out.accepted_ns, slot->pose_receive_ns));
  if (silenced) {  // not emitted: ticks = emitted + not_sent + underruns + dropped_late + silenced
    d.ring.pop();
    return;
  }
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

// SCHED_FIFO at options.realtime.priority (0: normal scheduling) and a
// pre-faulted stack; returns why the priority was refused (empty: granted
// or not asked for).
std::string EmissionEngine::Impl::set_up_realtime() {
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
  return note;
}

void EmissionEngine::Impl::emission_loop(std::promise<std::string>* setup, bool& setup_done) {
  const std::string note = set_up_realtime();
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
    DeviceState* next = nullptr;
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

}  // namespace imuemu::emission
