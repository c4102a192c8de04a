// The CAN device (dronecan, j1939): a drivers::CanEncoder whose frames go to
// a CanOutput (a SocketCAN interface or a test double), with an optional GPIO
// sync pulse. Each frame of a sample is one send().
#include <algorithm>
#include <stdexcept>
#include <utility>
#include <vector>

#include "daemon/device/device.hpp"
#include "daemon/device/device_parts.hpp"
#include "drivers/socketcan.hpp"

namespace imuemu::device {

namespace {

// Frames reserved up front, so that emit() never allocates (link faults included).
constexpr std::size_t kReserveCanFrames = 64;

class CanTransportOutput final : public CanOutput {
 public:
  explicit CanTransportOutput(std::unique_ptr<drivers::CanTransport> t) : transport_(std::move(t)) {}
  bool send(const drivers::CanFrame& frame) override { return transport_->send(frame); }
  std::string describe() const override { return transport_->describe(); }
  drivers::TransportCounters counters() const override { return transport_->counters(); }
  bool flush(std::chrono::milliseconds timeout) override { return transport_->flush(timeout); }
  void stop(std::chrono::milliseconds drain_timeout) override { transport_->stop(drain_timeout); }
  bool set_command_responder(drivers::CanCommandResponder* responder) override {
    transport_->set_command_responder(responder);
    return true;
  }

 private:
  std::unique_ptr<drivers::CanTransport> transport_;
};

class CanDevice final : public EncoderDevice<drivers::CanEncoder, std::vector<drivers::CanFrame>> {
 public:
  CanDevice(std::unique_ptr<drivers::CanEncoder> encoder, std::unique_ptr<CanOutput> output,
            std::unique_ptr<drivers::GpioSyncOutput> gpio)
      : EncoderDevice(std::move(encoder), std::move(gpio)), output_(std::move(output)) {
    if (!encoder_ || !output_) throw std::invalid_argument("a CAN device needs a CAN encoder and a CAN output");
    encoded_.reserve(std::max(kReserveCanFrames, drivers::link_fault_reserve_can_frames(fault::kMaxBabbleFactor)));
    // A node that answers requests addressed to it (GetNodeInfo, the J1939
    // Request PGN) reads them on its output's io thread from now on.
    responder_ = encoder_->command_responder();
    if (responder_ && !output_->set_command_responder(responder_)) responder_ = nullptr;
  }
  ~CanDevice() override {
    if (responder_) output_->set_command_responder(nullptr);
  }

  std::optional<CommandStatus> command_status() const override {
    if (!responder_) return std::nullopt;
    return command_status_of(responder_->command_counters(), output_->counters().replies_dropped);
  }

  SampleNeeds needs() const override {
    SampleNeeds n = encoder_needs();
    n.level_attitude = encoder_->needs_level_attitude();
    return n;
  }
  std::size_t max_bytes_per_sample() const override { return 0; }

  void stop(std::chrono::milliseconds drain_timeout, bool keep_transport) override {
    (void)keep_transport;  // nothing to keep: a CAN interface is not handed to the next engine
    if (responder_) output_->set_command_responder(nullptr);
    responder_ = nullptr;
    output_->stop(drain_timeout);
    sync_.release();
  }
  std::unique_ptr<drivers::Transport> take_transport() override { return nullptr; }

  std::string describe() const override { return encoder_->name() + " -> " + output_->describe(); }
  drivers::TransportCounters counters() const override { return output_->counters(); }

 private:
  void hand_over(const std::vector<drivers::CanFrame>& frames, EmitOutcome& out) override {
    bool accepted = false;
    for (const drivers::CanFrame& f : frames) {
      if (output_->send(f)) accepted = true;
      else ++out.refused;
    }
    if (accepted) out.accepted_ns = monotonic_ns();
  }

  std::unique_ptr<CanOutput> output_;
  drivers::CanCommandResponder* responder_ = nullptr;
};

}  // namespace

std::unique_ptr<CanOutput> can_transport_output(std::unique_ptr<drivers::CanTransport> transport) {
  return std::make_unique<CanTransportOutput>(std::move(transport));
}

std::unique_ptr<Device> make_can_device(std::unique_ptr<drivers::CanEncoder> encoder, std::unique_ptr<CanOutput> output,
                                        std::unique_ptr<drivers::GpioSyncOutput> gpio) {
  return std::make_unique<CanDevice>(std::move(encoder), std::move(output), std::move(gpio));
}

}  // namespace imuemu::device
