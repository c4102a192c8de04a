// The engine's statistics: stats() snapshots every device's counters (the
// relaxed atomics both threads keep, the device's output and GPIO counters,
// the live pose source's) from any thread but the emission thread, and
// to_json gives them the shape `imuemu status` and `imuemu emit
// --stats-json` print (docs/emission.md).
#include <nlohmann/json.hpp>

#include "daemon/engine/engine_state.hpp"

namespace imuemu::emission {

EngineStats EmissionEngine::stats() const {
  const Impl& m = *impl_;
  EngineStats s;
  for (const auto& dp : m.devices) {
    const DeviceState& d = *dp;
    DeviceStats ds;
    ds.name = d.options.name;
    ds.rate_hz = d.options.rate_hz;
    ds.output = d.options.device->describe();
    ds.transport = d.options.device->counters();
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
    ds.dropped_link_down = d.dropped_link_down.load(std::memory_order_relaxed);
    ds.saturated = d.saturated.load(std::memory_order_relaxed);
    ds.packets = ds.transport.frames_sent;
    ds.bytes = ds.transport.bytes_sent;
    ds.queue_overflows = ds.transport.dropped_queue_full;
    ds.gpio = d.options.device->gpio_counters();
    ds.commands = d.options.device->command_status();
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
    p.other_sender = c.other_sender;
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
                     {"dropped_link_down", d.dropped_link_down},
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
                       {"link_down_events", d.transport.link_down_events},
                       // What the client wrote (issue 27): all of it, what no
                       // device protocol took, and the device's replies.
                       {"input_bytes", d.transport.input_bytes},
                       {"input_bytes_discarded", d.transport.input_bytes_discarded},
                       {"replies_sent", d.transport.replies_sent},
                       {"replies_dropped", d.transport.replies_dropped}}},
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
    if (d.commands)
      j["commands"] = {{"received", d.commands->received},
                       {"answered", d.commands->answered},
                       {"nacked", d.commands->nacked},
                       {"not_command_bytes", d.commands->not_command_bytes},
                       {"replies_dropped", d.commands->replies_dropped},
                       {"mode", d.commands->mode},
                       {"format", d.commands->format},
                       {"baud", d.commands->baud}};
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
                        {"connections_replaced", s.pose_source->connections_replaced},
                        {"other_sender", s.pose_source->other_sender}};
  return j;
}

}  // namespace imuemu::emission
