// What the byte-stream and the CAN device share (internal to
// daemon/device/): the GPIO sync output (drivers/gpio_sync.hpp) with its
// counters after release, the clock an output's acceptance is stamped on,
// and EncoderDevice, the emit() both run: encode with the link faults, hand
// the result to the output, pulse unless silent.
#pragma once

#include <time.h>

#include <exception>
#include <memory>
#include <optional>
#include <string>
#include <utility>

#include "core/signal_chain/increments.hpp"
#include "core/types.hpp"
#include "daemon/device/device.hpp"
#include "drivers/gpio_sync.hpp"
#include "drivers/link_fault.hpp"

namespace imuemu::device {


// CLOCK_MONOTONIC, the engine's clock (its deadlines and the poses' arrival stamps).
inline TimeNs monotonic_ns() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<TimeNs>(ts.tv_sec) * kNsPerSecond + ts.tv_nsec;
}

class SyncPulse {
 public:
  explicit SyncPulse(std::unique_ptr<drivers::GpioSyncOutput> gpio) : gpio_(std::move(gpio)) {}
  // The emission thread: the pulse of sample k at t_ns (never blocks).
  void pulse(std::uint64_t sample_counter, TimeNs t_ns, const std::optional<drivers::DeviceSyncPulse>& device) {
    if (!gpio_) return;
    if (device) gpio_->pulse(sample_counter, t_ns, *device);
    else gpio_->pulse(sample_counter, t_ns);
  }
  // The lines released (inactive); the counters as they were stay readable.
  void release() {
    if (!gpio_) return;
    final_ = gpio_->counters();
    gpio_.reset();
  }
  std::optional<drivers::GpioSyncCounters> counters() const {
    if (gpio_) return gpio_->counters();
    return final_;
  }

 private:
  std::unique_ptr<drivers::GpioSyncOutput> gpio_;
  std::optional<drivers::GpioSyncCounters> final_;
};

// A device built on a protocol encoder (drivers::StreamEncoder writing a
// byte Buffer, or drivers::CanEncoder writing CAN frames): the encoder, its
// output buffer (reserved by the derived class so that emit() never
// allocates), the sync pulse; the derived class owns the output.
template <class Encoder, class Buffer>
class EncoderDevice : public Device {
 public:
  EncoderDevice(std::unique_ptr<Encoder> encoder, std::unique_ptr<drivers::GpioSyncOutput> gpio)
      : encoder_(std::move(encoder)), sync_(std::move(gpio)) {}

  void check_supports(const std::string& imu, fault::Kind kind) const final {
    device::check_supports(imu, *encoder_, kind);
  }
  std::optional<drivers::GpioSyncCounters> gpio_counters() const final { return sync_.counters(); }

  EmitOutcome emit(const drivers::ImuFrameInput& frame, const drivers::LinkActions& link, TimeNs pulse_t_ns) final {
    EmitOutcome out;
    try {
      encoded_.clear();
      drivers::encode_with_link_faults(link, *encoder_, frame, encoded_);
      // Silence (and a dropped sample with no periodic traffic) leaves nothing to hand over.
      if (!encoded_.empty()) hand_over(encoded_, out);
    } catch (const std::exception&) {  // the encoder refusing a sample: counted, the schedule goes on
      ++out.refused;
    }
    if (!link.silence) {
      // A device with its own sync-out setting (a StreamEncoder's
      // device_sync_pulse) drives the line; a CAN encoder has none.
      std::optional<drivers::DeviceSyncPulse> device_pulse;
      if constexpr (requires { encoder_->device_sync_pulse(); }) device_pulse = encoder_->device_sync_pulse();
      sync_.pulse(frame.sample_counter, pulse_t_ns, device_pulse);
    }
    return out;
  }

 protected:
  // The sample's encoded output (not empty) to the output: each refusal
  // counted in out.refused, out.accepted_ns stamped (monotonic_ns()) when
  // anything was taken. The emission thread: never allocates or blocks.
  virtual void hand_over(const Buffer& encoded, EmitOutcome& out) = 0;
  // The increments in the convention the encoder asks for.
  SampleNeeds encoder_needs() const {
    SampleNeeds n;
    n.increments = encoder_->compensated_increments() ? signal_chain::IncrementConvention::compensated
                                                      : signal_chain::IncrementConvention::raw;
    if constexpr (requires(const Encoder& e) { e.needs_navigation(); }) n.navigation = encoder_->needs_navigation();
    return n;
  }

  std::unique_ptr<Encoder> encoder_;
  SyncPulse sync_;
  Buffer encoded_;  // the emission thread's
};

}  // namespace imuemu::device
