// Run-time faults (issue 18): inject, clear and list reach the producer
// thread - the only one that touches a device's fault timeline - through a
// mailbox it serves at the top of each iteration; the ground-truth events go
// the other way through a bounded queue (take_fault_events). A request the
// producer does not take in time is withdrawn whole: nothing changed.
#include <algorithm>
#include <iterator>
#include <stdexcept>

#include "daemon/engine/engine_state.hpp"

namespace imuemu::emission {

void EmissionEngine::Impl::post_and_wait(FaultRequest& r) {
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

void EmissionEngine::Impl::queue_fault_events(DeviceState& d) {
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

DeviceState& EmissionEngine::Impl::device_named(const std::string& name) {
  for (auto& d : devices)
    if (d->options.name == name) return *d;
  std::string names;
  for (auto& d : devices) names += (names.empty() ? "" : ", ") + d->options.name;
  throw std::invalid_argument("no imu '" + name + "' in this scene (imus: " + names + ")");
}

void EmissionEngine::Impl::run_request(FaultRequest& r) {
  switch (r.op) {
    case FaultRequest::Op::inject: {
      DeviceState& d = *r.device;
      // The start, on the device's own clock (time since its sample 0): the
      // next sample this thread computes, plus after_ns.
      const TimeNs next_since_start_ns = grid_ns(0, d.next_produce_tick, d.options.rate_hz);
      r.spec.clock = fault::Clock::since_start;
      r.spec.start_ns = saturating_add_ns(next_since_start_ns, r.after_ns);
      r.spec.device = d.options.name;
      r.spec.source = "control";
      d.options.device->check_supports(d.options.name, r.spec.kind);
      r.injected.id = d.faults->inject(r.spec);  // validates: throws before adding
      r.injected.start_since_start_ns = r.spec.start_ns;
      r.injected.first_sample = first_tick_at_or_after(r.spec.start_ns, d.options.rate_hz);
      d.faults_injected.fetch_add(1, std::memory_order_relaxed);
      d.faults_active.store(d.faults->active_count(), std::memory_order_relaxed);
      break;
    }
    case FaultRequest::Op::clear: {
      DeviceState& d = *r.device;
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

}  // namespace imuemu::emission
