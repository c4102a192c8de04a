// One device's faults inside the emission engine (issue 18): the timeline of
// core/fault (scene entries, random faults, run-time inject/clear), the
// sensor faults applied to each sample after the signal chain (the sensor
// model's output), the per-sample link actions the emission thread applies
// (drivers/link_fault.hpp), the protocol-time override of time_jump and
// time_freeze, the fault status bit, and the ground-truth events.
//
// Producer thread only (the engine's mailbox serialises run-time requests
// onto it); it may allocate. The emission thread never sees this object,
// only the LinkActions it leaves in the sample's ring slot.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/fault/fault.hpp"
#include "core/fault/timeline.hpp"
#include "core/sensor/sensor_model.hpp"
#include "drivers/link_fault.hpp"
#include "drivers/protocol.hpp"

namespace imuemu::emission {

// A device's faults as configured: the scene's [[imu.fault]] entries and
// its random faults (core/fault/timeline.hpp; seeded from the scene).
struct DeviceFaultPlan {
  std::vector<fault::FaultSpec> scheduled;
  fault::RandomFaults random;
};

// What `fault-list` shows of one fault: scheduled (not acted yet) or active.
struct FaultInfo {
  std::uint64_t id = 0;
  fault::FaultSpec spec;
  enum class State : std::uint8_t { scheduled, active } state = State::scheduled;
  std::optional<std::uint64_t> first_sample;  // the first sample it acted on
};
const char* state_name(FaultInfo::State state);

class DeviceFaults {
 public:
  // Throws std::invalid_argument (fault::validate) naming the device and entry.
  // sensor: the device's sensor model (ranges and noise densities for
  // garbage, saturation, noise_gain). frame_bytes: the protocol's largest
  // sample frame (bit_errors draws its flips over that many bits).
  DeviceFaults(std::string device, std::int64_t rate_hz, const std::optional<sensor::SensorModelSpec>& sensor,
               DeviceFaultPlan plan, std::size_t frame_bytes);
  ~DeviceFaults();
  DeviceFaults(const DeviceFaults&) = delete;
  DeviceFaults& operator=(const DeviceFaults&) = delete;

  // Sample k at grid time t_k (t0: the device's sample 0), after the signal
  // chain: applies the active sensor faults to `frame`, sets kStatusFault
  // when an active fault flags it, changes frame.t_ns for time_jump /
  // time_freeze, fills `link`, and appends the start/end events of faults
  // whose first or last affected sample this is (an end is seen at the first
  // sample after it, or at clear()). k increases from call to call. t_k is
  // the sample's grid (trajectory) time; frame.t_ns may differ from it by the
  // chain's stamp shift, which a time fault keeps.
  void apply(std::uint64_t k, TimeNs t_k_ns, drivers::ImuFrameInput& frame, drivers::LinkActions& link,
             std::vector<fault::FaultEvent>& events) noexcept;

  // Run-time: adds a fault (validated first: a refused spec changes nothing);
  // returns its id.
  std::uint64_t inject(fault::FaultSpec spec);
  // Ends fault `id` (nullopt: all, scheduled ones included): an active one
  // gets its end event at the last sample it affected; returns the ids
  // cleared (empty: no such fault, nothing changed).
  std::vector<std::uint64_t> clear(std::optional<std::uint64_t> id, std::vector<fault::FaultEvent>& events);
  // The end of the run: end events for the faults still active.
  void finish(std::vector<fault::FaultEvent>& events);

  std::vector<FaultInfo> list() const;
  std::size_t active_count() const;
  const fault::TimelineCounters& counters() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace imuemu::emission
