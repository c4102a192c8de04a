// The buffer and counters of a byte-stream decoder that resynchronises on
// the next frame start after corruption (the VectorNav, SBG and Xsens
// decoders of `imuemu listen`): the bytes are kept until a whole frame is in,
// and a byte that starts no valid frame is skipped and counted.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "drivers/protocol.hpp"

namespace imuemu::drivers {

class ResyncingDecoder : public StreamDecoder {
 public:
  void feed(std::span<const std::uint8_t> bytes, const SampleCallback& on_sample) final {
    buffer_.insert(buffer_.end(), bytes.begin(), bytes.end());
    const std::size_t used = decode_buffer(on_sample);
    buffer_.erase(buffer_.begin(), buffer_.begin() + static_cast<std::ptrdiff_t>(used));
  }
  const DecoderCounters& counters() const final { return counters_; }

 protected:
  // Decodes the whole frames at the front of buffer_; returns how many bytes
  // it is done with (the rest waits for more input).
  virtual std::size_t decode_buffer(const SampleCallback& on_sample) = 0;
  // The byte at pos starts no frame: skipped and counted as a resync byte,
  // and as `error` too when the byte looked like a frame that was not one.
  void skip_byte(std::size_t& pos, std::uint64_t DecoderCounters::*error = nullptr) noexcept {
    if (error != nullptr) ++(counters_.*error);
    ++counters_.resync_bytes;
    ++pos;
  }

  enum class FrameStart { found, skipped, need_more };
  // Whether a frame starts at pos with the sync bytes `sync`: the first is
  // checked at once (skipped and counted when it is not there), the others
  // once `header_bytes` (at least the sync's) are in; need_more until then.
  FrameStart frame_start_at(std::size_t& pos, std::span<const std::uint8_t> sync, std::size_t header_bytes) noexcept {
    if (buffer_[pos] != sync[0]) return skip_byte(pos), FrameStart::skipped;
    if (pos + header_bytes > buffer_.size()) return FrameStart::need_more;
    for (std::size_t i = 1; i < sync.size(); ++i)
      if (buffer_[pos + i] != sync[i]) return skip_byte(pos), FrameStart::skipped;
    return FrameStart::found;
  }

  std::vector<std::uint8_t> buffer_;
  DecoderCounters counters_;
};

}  // namespace imuemu::drivers
