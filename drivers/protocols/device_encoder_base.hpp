// The skeleton the VectorNav, SBG and Xsens stream encoders share (issue 29):
// a device whose optional command side (its Device, on the io thread)
// publishes the configuration the emission thread streams, a power-up
// instant the device's time stamps count from, restart faults the device is
// told of, and the delta theta / delta velocity summed per output since that
// output last went out. Each encoder keeps its own frames, its own schedule
// (which outputs are due) and its own measurements.
//
// Header-only: the base is a template over the device type, and the Device
// classes are only declared (not defined) where the encoders' headers are
// read. The members that touch the Device are instantiated in the encoders'
// own .cpp files, where it is complete (the vtable, and with it the virtual
// members, is only needed by the constructors and destructor defined there).
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "drivers/protocol.hpp"
#include "drivers/protocols/stream_protocols.hpp"

namespace imuemu::drivers {

// The increments of the samples since an output last went out: VectorNav
// [U] "delta theta and delta velocity ... integrated over the time since the
// last output", SBG [L] IMU_DATA / IMU_SHORT's deltas over the output's
// interval, Xsens [L] dq / dv since the last packet (vectornav.hpp, sbg.hpp,
// xsens.hpp name the documents).
struct IncrementSums {
  double dtime_s = 0.0;
  Vec3 dtheta_rad = Vec3::Zero();
  Vec3 dvel_m_s = Vec3::Zero();

  void add(const ImuFrameInput& sample) noexcept {
    dtime_s += static_cast<double>(sample.period_ns) * 1e-9;
    dtheta_rad += sample.delta_theta_rad;
    dvel_m_s += sample.delta_velocity_m_s;
  }
};

// Sample k of a scene at scene_rate_hz is due for an output at
// rate_per_s / divisor Hz when it crosses a multiple of the output's period
// on the scene's grid: with the scene at the device's own rate a divisor d
// sends every d-th sample, and a scene slower than the output sends every
// sample. Rate or divisor 0: never due.
inline bool due_on_scene_grid(std::uint64_t k, std::uint64_t rate_per_s, std::uint64_t divisor,
                              std::uint64_t scene_rate_hz) noexcept {
  if (divisor == 0 || rate_per_s == 0) return false;
  if (k == 0) return true;
  const std::uint64_t now = k * rate_per_s / scene_rate_hz / divisor;
  const std::uint64_t before = (k - 1) * rate_per_s / scene_rate_hz / divisor;
  return now != before;
}

// How many times per second an output on that schedule goes out in a scene
// at sample_rate_hz (due_on_scene_grid): its own rate, or every sample of a
// slower scene.
inline double sent_per_second(std::uint64_t rate_per_s, std::uint64_t divisor, double sample_rate_hz) noexcept {
  if (divisor == 0 || rate_per_s == 0) return 0.0;
  return std::min(static_cast<double>(rate_per_s) / static_cast<double>(divisor), sample_rate_hz);
}

// Device: the command side (emit_config(), note_restart(),
// publish_measurements()); StreamConfig: what the emission thread streams;
// kIncrementSlots: the outputs that carry increments of their own.
template <class Device, class StreamConfig, std::size_t kIncrementSlots>
class DeviceEncoderBase : public StreamEncoder {
 public:
  CommandResponder* command_responder() override { return responder_; }
  // The three devices' increments are coning and sculling compensated
  // (VectorNav [U], SBG [F], Xsens [L]: the strapdown integration's).
  bool compensated_increments() const override { return true; }
  // Attitude, position and velocity go into their outputs.
  bool needs_navigation() const override { return true; }
  // The device powers up again: its uptime and every output's increments
  // restart, and its command side learns of it (io thread, later). An
  // encoder whose device sends something at power-up appends it after this.
  void restart(TimeNs now_ns, std::vector<std::uint8_t>& out) override {
    (void)out;  // nothing of the shared part goes on the wire
    have_power_up_ = true;
    power_up_t_ns_ = now_ns;
    increments_ = {};
    if (!device_) return;
    ++restarts_;
    note_restart_(*device_);
  }

 protected:
  // The command side, for a device that answers its driver: the Device's
  // members are bound here, in the encoder's .cpp where it is complete.
  // answers_commands = false: the device keeps and streams its settings but
  // nothing answers (a line whose receive wire is not connected).
  void install_device(std::unique_ptr<Device> device, bool answers_commands = true) {
    responder_ = answers_commands ? device.get() : nullptr;
    note_restart_ = [](Device& d) { d.note_restart(); };
    device_ = std::move(device);
  }
  // device_rate_hz: the scene's rate when the options give none (< 1 Hz).
  DeviceEncoderBase(const StreamEncoderOptions& options, std::uint64_t device_rate_hz, const StreamConfig& power_up)
      : options_(options),
        scene_rate_hz_(options.nominal_sample_rate_hz >= 1.0
                           ? static_cast<std::uint64_t>(std::llround(options.nominal_sample_rate_hz))
                           : device_rate_hz),
        power_up_(power_up) {}

  // Every sample's first step: the power-up instant (when no restart set it,
  // the instant of sample 0 of the scene) and the sample's increments added
  // to every output's sums.
  void start_sample(const ImuFrameInput& sample) noexcept {
    if (!have_power_up_) {
      have_power_up_ = true;
      power_up_t_ns_ = sample.t_ns - static_cast<TimeNs>(sample.sample_counter) * sample.period_ns;
    }
    for (IncrementSums& sums : increments_) sums.add(sample);
  }
  // The time since power-up at the sample (0 before it); before the first
  // encode() it counts from the scene's sample 0.
  TimeNs since_power_up_ns(const ImuFrameInput& sample) const noexcept {
    const TimeNs power_up =
        have_power_up_ ? power_up_t_ns_ : sample.t_ns - static_cast<TimeNs>(sample.sample_counter) * sample.period_ns;
    return sample.t_ns > power_up ? sample.t_ns - power_up : 0;
  }
  // Whether the device restarted (a restart fault) and its io thread has not
  // taken it in yet: its published configuration is the one from before.
  template <class EmitConfig>
  bool restart_pending(const EmitConfig& published) const noexcept {
    return published.restarts_handled < restarts_;
  }
  // What the device streams now, for an EmitConfig that keeps its saved
  // settings in `startup`: the power-up configuration without a command
  // side; after a restart the io thread has not taken in, the saved one.
  const StreamConfig& published_or_startup_config() const noexcept {
    if (!device_) return power_up_;
    const auto& published = device_->emit_config();
    return restart_pending(published) ? published.startup : published;
  }
  bool due_on_grid(std::uint64_t k, std::uint64_t rate_per_s, std::uint64_t divisor) const noexcept {
    return due_on_scene_grid(k, rate_per_s, divisor, scene_rate_hz_);
  }

  StreamEncoderOptions options_;
  std::uint64_t scene_rate_hz_;
  std::unique_ptr<Device> device_;
  StreamConfig power_up_;
  std::array<IncrementSums, kIncrementSlots> increments_{};

 private:
  CommandResponder* responder_ = nullptr;  // device_, or nullptr
  void (*note_restart_)(Device&) = nullptr;
  bool have_power_up_ = false;
  TimeNs power_up_t_ns_ = 0;
  std::uint64_t restarts_ = 0;
};

}  // namespace imuemu::drivers
