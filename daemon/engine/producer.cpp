// The engine's producer thread (normal priority, or one step below the
// emission thread with live input and SCHED_FIFO): it computes each
// device's ticks a bounded lead ahead of their deadlines - stream engine,
// LiveEmitter, signal chain, faults - into the device's lock-free ring, and
// takes the live poses as they arrive. The run-time fault requests it serves
// between iterations are in fault_mailbox.cpp.
#include <pthread.h>
#include <sched.h>

#include <algorithm>
#include <stdexcept>

#include "core/attitude.hpp"
#include "core/earth.hpp"
#include "core/stream.hpp"
#include "daemon/device/frame_navigation.hpp"
#include "daemon/engine/engine_state.hpp"

namespace imuemu::emission {

namespace {

// Live input: the producer sleeps on the pose queue (woken by each pose's
// arrival) until its next tick's gate, at most kMaxSleepChunkNs (stop,
// stall and the like are looked at meanwhile), at least this long when the
// gate has passed without the tick being computable (a full ring): never a
// busy loop.
constexpr TimeNs kProducerMinWaitNs = 20'000;
// Poses waiting for their first dependent sample (a stalled emitter must not
// grow the list without bound).
constexpr std::size_t kMaxPoseMarks = 4096;

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

}  // namespace

std::optional<live::ExactSample> OnDemandSource::next_sample() {
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

// Computes the slots of the ticks that are due for computing. time_gated
// (live input): tick k is computed no earlier than producer_lead before its
// deadline, so the LiveEmitter's exact/extrapolated decision is taken as late
// as the lead allows. Trajectory input is not gated: every sample is
// computable, so the ring is simply kept full.
void EmissionEngine::Impl::produce(DeviceState& d, bool time_gated) {
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
      // increments exact over the interval in the device's convention.
      const Kinematics* previous = d.previous && d.previous->first + 1 == k ? &d.previous->second : nullptr;
      const signal_chain::ChainOutput m = d.chain->step(k, e.kinematics, e.imu, previous, d.needs.increments);
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
      if (d.needs.level_attitude) set_level_attitude(e.kinematics, d.options.pipeline.scene.physics, f);
      if (d.needs.navigation) device::set_frame_navigation(e.kinematics, d.options.pipeline.scene.physics, f);
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

}  // namespace imuemu::emission
