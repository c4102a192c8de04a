// A byte-stream transport that keeps every byte written to it, for tests
// that decode what an engine sent (thread-safe: the engine's emission
// thread writes, the test reads).
#pragma once

#include <cstddef>
#include <cstdint>
#include <mutex>
#include <span>
#include <string>
#include <vector>

#include "drivers/transport.hpp"

namespace imuemu::test_support {

class RecordingTransport final : public drivers::Transport {
 public:
  bool write_frame(std::span<const std::byte> frame) override {
    std::lock_guard lock(mutex_);
    const auto* p = reinterpret_cast<const std::uint8_t*>(frame.data());
    bytes_.insert(bytes_.end(), p, p + frame.size());
    return true;
  }
  std::string describe() const override { return "recording"; }
  drivers::TransportCounters counters() const override { return {}; }
  std::vector<std::uint8_t> bytes() const {
    std::lock_guard lock(mutex_);
    return bytes_;
  }

 private:
  mutable std::mutex mutex_;
  std::vector<std::uint8_t> bytes_;
};

}  // namespace imuemu::test_support
