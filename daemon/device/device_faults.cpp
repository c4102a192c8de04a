// The engine's side of a device's faults: core/fault's FaultTimeline
// (timeline, sensor faults, link decisions, ground truth) mapped onto the
// drivers' frame and LinkActions.
#include "daemon/device/device_faults.hpp"

#include <algorithm>
#include <stdexcept>

#include "core/time_arith.hpp"

namespace imuemu::emission {

const char* state_name(FaultInfo::State state) {
  return state == FaultInfo::State::active ? "active" : "scheduled";
}

struct DeviceFaults::Impl {
  explicit Impl(fault::TimelineOptions o) : timeline(std::move(o)) {}
  fault::FaultTimeline timeline;
  std::size_t frame_bits = 0;
  std::size_t active = 0;  // as of the newest sample
};

DeviceFaults::DeviceFaults(std::string device, std::int64_t rate_hz, const std::optional<sensor::SensorModelSpec>& sensor,
                           DeviceFaultPlan plan, std::size_t frame_bytes) {
  fault::TimelineOptions o;
  o.context = fault::device_context(device, rate_hz, sensor);
  o.faults = std::move(plan.scheduled);
  for (fault::FaultSpec& s : o.faults) s.device = device;
  o.random = std::move(plan.random);
  impl_ = std::make_unique<Impl>(std::move(o));  // validates: throws std::invalid_argument naming the entry
  impl_->frame_bits = 8 * frame_bytes;
}

DeviceFaults::~DeviceFaults() = default;

void DeviceFaults::apply(std::uint64_t k, TimeNs t_k_ns, drivers::ImuFrameInput& frame, drivers::LinkActions& link,
                         std::vector<fault::FaultEvent>& events) noexcept {
  fault::SampleValues v{frame.gyro_rad_s, frame.accel_m_s2, frame.delta_theta_rad, frame.delta_velocity_m_s,
                        frame.period_ns};
  const fault::SampleFaults f = impl_->timeline.step(k, t_k_ns, v);
  impl_->active = f.active;
  frame.gyro_rad_s = v.gyro_rad_s;
  frame.accel_m_s2 = v.accel_m_s2;
  frame.delta_theta_rad = v.delta_theta_rad;
  frame.delta_velocity_m_s = v.delta_velocity_m_s;
  if ((f.flags & fault::kFlagFault) != 0) frame.status |= drivers::kStatusFault;
  if ((f.flags & fault::kFlagSaturated) != 0) frame.status |= drivers::kStatusSaturated;
  const fault::LinkDecision& d = f.link;
  // The protocol's time field lies; the chain's stamp shift (delay
  // compensation) stays on top of it.
  if (d.protocol_time_ns)
    frame.t_ns = saturating_add_ns(*d.protocol_time_ns, saturating_sub_ns(frame.t_ns, t_k_ns));
  link = drivers::LinkActions{};
  link.silence = d.silence;
  link.drop = d.drop;
  link.copies = d.copies;
  link.corrupt_checksum = d.corrupt_checksum;
  if (d.bit_error_rate > 0.0) {
    link.bit_flips = std::min(fault::bit_flip_count(d.bit_error_rate, impl_->frame_bits, d.bit_error_seed),
                              drivers::kMaxBitFlipsPerSample);
    link.bit_error_seed = d.bit_error_seed;
  }
  link.truncate_bytes = d.truncate_bytes;
  link.bad_length = d.bad_length;
  link.sequence_step = d.sequence_step;
  link.sequence_reset = d.sequence_reset;
  link.restart = d.restart;
  link.can_wrong_id = d.can_wrong_id;
  link.can_id = d.can_id;
  link.can_missing_frame = d.can_missing_frame;
  // Events: at most a few per sample; the vector has grown to that before.
  try {
    impl_->timeline.drain_events(events);
  } catch (...) {  // no memory: they stay in the timeline's buffer for the next sample
  }
}

std::uint64_t DeviceFaults::inject(fault::FaultSpec spec) { return impl_->timeline.inject(std::move(spec)); }

std::vector<std::uint64_t> DeviceFaults::clear(std::optional<std::uint64_t> id, std::vector<fault::FaultEvent>& events) {
  std::vector<std::uint64_t> cleared;
  if (id) {
    if (impl_->timeline.clear(*id)) cleared.push_back(*id);
  } else {
    for (const fault::FaultInfo& f : impl_->timeline.list()) cleared.push_back(f.id);
    impl_->timeline.clear_all();
  }
  impl_->timeline.drain_events(events);
  std::size_t acting = 0;
  for (const fault::FaultInfo& f : impl_->timeline.list()) acting += f.started ? 1 : 0;
  impl_->active = acting;
  return cleared;
}

void DeviceFaults::finish(std::vector<fault::FaultEvent>& events) {
  impl_->timeline.finish();
  impl_->timeline.drain_events(events);
  impl_->active = 0;
}

std::vector<FaultInfo> DeviceFaults::list() const {
  std::vector<FaultInfo> out;
  for (const fault::FaultInfo& f : impl_->timeline.list()) {
    FaultInfo info;
    info.id = f.id;
    info.spec = f.spec;
    info.state = f.started ? FaultInfo::State::active : FaultInfo::State::scheduled;
    if (f.started) info.first_sample = f.first_sample;
    out.push_back(std::move(info));
  }
  return out;
}

std::size_t DeviceFaults::active_count() const { return impl_->active; }

const fault::TimelineCounters& DeviceFaults::counters() const { return impl_->timeline.counters(); }

}  // namespace imuemu::emission
