// The byte-stream device (native, mavlink2, mip): a drivers::StreamEncoder
// whose bytes go to a drivers::Transport (pty, UART, null), with an optional
// GPIO sync pulse. One sample's bytes (with its periodic traffic and its link
// faults) are one write_frame.
#include <algorithm>
#include <span>
#include <stdexcept>
#include <utility>
#include <vector>

#include "daemon/device/device.hpp"
#include "daemon/device/device_parts.hpp"

namespace imuemu::device {

namespace {

// Encoder output reserved up front, so that emit() never allocates, link
// faults included (babble's copies, a restart's power-up traffic).
constexpr std::size_t kReserveBytes = 4096;

class StreamDevice final : public EncoderDevice<drivers::StreamEncoder, std::vector<std::uint8_t>> {
 public:
  StreamDevice(std::unique_ptr<drivers::StreamEncoder> encoder, std::unique_ptr<drivers::Transport> transport,
               std::unique_ptr<drivers::GpioSyncOutput> gpio, drivers::TransportCounters baseline)
      : EncoderDevice(std::move(encoder), std::move(gpio)), transport_(std::move(transport)), baseline_(baseline) {
    if (!encoder_ || !transport_)
      throw std::invalid_argument("a byte-stream device needs a stream encoder and a transport");
    encoded_.reserve(std::max(kReserveBytes, drivers::link_fault_reserve(*encoder_, fault::kMaxBabbleFactor)));
    // A device that answers its driver reads its port from now on (the
    // transport's io thread); a transport without input keeps it send-only.
    responder_ = encoder_->command_responder();
    if (responder_ && !transport_->set_input_handler(responder_)) responder_ = nullptr;
  }
  ~StreamDevice() override {
    if (transport_ && responder_) transport_->set_input_handler(nullptr);
  }

  std::optional<CommandStatus> command_status() const override {
    if (!responder_) return std::nullopt;
    // Replies the device could not queue, and queued ones the transport
    // dropped (its reply queue full, the link lost before they left).
    return command_status_of(responder_->command_counters(), counters().replies_dropped);
  }

  SampleNeeds needs() const override { return encoder_needs(); }
  std::size_t max_bytes_per_sample() const override { return encoder_->max_bytes_per_sample(); }

  void stop(std::chrono::milliseconds drain_timeout, bool keep_transport) override {
    if (transport_) {
      // The device's state goes with it: its io thread stops answering.
      if (responder_) transport_->set_input_handler(nullptr);
      if (keep_transport) (void)transport_->flush(drain_timeout);
      else transport_->stop(drain_timeout);
    }
    sync_.release();
  }
  std::unique_ptr<drivers::Transport> take_transport() override {
    if (!transport_) return nullptr;
    if (responder_) transport_->set_input_handler(nullptr);
    taken_.emplace(describe(), counters());
    return std::move(transport_);
  }

  std::string describe() const override {
    if (taken_) return taken_->first;
    return encoder_->name() + " -> " + transport_->describe();
  }
  drivers::TransportCounters counters() const override {
    if (taken_) return taken_->second;
    return drivers::counters_since(transport_->counters(), baseline_);
  }

 private:
  void hand_over(const std::vector<std::uint8_t>& bytes, EmitOutcome& out) override {
    if (transport_->write_frame(std::as_bytes(std::span<const std::uint8_t>(bytes)))) out.accepted_ns = monotonic_ns();
    else if (!transport_->link_up()) ++out.refused_link_down;  // an atomic load: no reader, the device gone
    else ++out.refused;
  }

  std::unique_ptr<drivers::Transport> transport_;
  drivers::TransportCounters baseline_;
  drivers::CommandResponder* responder_ = nullptr;  // the encoder's, when the transport reads its port
  // The transport as it was when take_transport() moved it out.
  std::optional<std::pair<std::string, drivers::TransportCounters>> taken_;
};

}  // namespace

std::unique_ptr<Device> make_stream_device(std::unique_ptr<drivers::StreamEncoder> encoder,
                                           std::unique_ptr<drivers::Transport> transport,
                                           std::unique_ptr<drivers::GpioSyncOutput> gpio,
                                           drivers::TransportCounters baseline) {
  return std::make_unique<StreamDevice>(std::move(encoder), std::move(transport), std::move(gpio), baseline);
}

}  // namespace imuemu::device
