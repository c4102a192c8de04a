// The one narrow interface every transport plug-in implements (UART, pty,
// CAN, ...). Encoders produce frames; a transport only moves bytes/frames.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

namespace imuemu::drivers {

struct TransportCounters {
  std::uint64_t frames = 0;
  std::uint64_t bytes = 0;
  std::uint64_t write_errors = 0;
};

class Transport {
 public:
  virtual ~Transport() = default;
  // Queues one encoded frame; never blocks the emission thread. Returns false
  // (and counts a write error) when the frame could not be accepted.
  virtual bool write_frame(std::span<const std::byte> frame) = 0;
  virtual std::string describe() const = 0;
  virtual const TransportCounters& counters() const = 0;
};

// Discards frames, counting them: for timing benchmarks and dry runs.
class NullTransport final : public Transport {
 public:
  bool write_frame(std::span<const std::byte> frame) override {
    ++counters_.frames;
    counters_.bytes += frame.size();
    return true;
  }
  std::string describe() const override { return "null"; }
  const TransportCounters& counters() const override { return counters_; }

 private:
  TransportCounters counters_;
};

}  // namespace imuemu::drivers
