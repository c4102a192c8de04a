#pragma once
// Shared by the datagram fuzz targets: lets the fuzzer reach past the wire
// checks it cannot guess (docs/pose-wire-format.md). Flag bit 1 writes the
// magic and version, bit 0 the CRC-32C of a full-size datagram, so mutations
// land on the pose fields and the admission rules behind them.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "io/pose_wire.hpp"

namespace imuemu::io::fuzz {

inline void reseal_datagram(std::vector<std::uint8_t>& d, std::uint8_t flags) {
  if ((flags & 2) != 0 && d.size() > kDatagramVersionOffset) {
    std::copy(kPoseDatagramMagic.begin(), kPoseDatagramMagic.end(), d.begin());
    d[kDatagramVersionOffset] = kPoseDatagramVersion;
  }
  if ((flags & 1) != 0 && d.size() == kPoseDatagramV1Size) {
    const std::uint32_t crc = crc32c(std::span(d.data(), kDatagramCrcOffset));
    for (std::size_t i = 0; i < 4; ++i) d[kDatagramCrcOffset + i] = static_cast<std::uint8_t>(crc >> (8 * i));
  }
}

}  // namespace imuemu::io::fuzz
