// u-blox UBX GNSS receiver output (issue 28): per epoch NAV-PVT and, unless
// turned off, the older navigation messages ArduPilot's UBX driver and
// others read (NAV-TIMEGPS, NAV-SOL, NAV-POSLLH, NAV-VELNED, NAV-STATUS,
// NAV-DOP), then NAV-EOE (end of epoch); the order is in Encoder::encode. Written from the u-blox 8 / u-blox M8
// receiver description (UBX-13003221, "UBX Protocol"); no u-blox code.
//
// A frame: sync 0xB5 0x62, class, id, payload length (u16 little-endian),
// payload (little-endian fields), CK_A CK_B: the 8-bit Fletcher checksum
// over class, id, length and payload (CK_A += byte; CK_B += CK_A).
//
// Resolution on the wire: NAV-PVT latitude / longitude 1e-7 degree, heights
// 1 mm, velocity and ground speed 1 mm/s, heading of motion 1e-5 degree,
// UTC to the ns (nano); iTOW 1 ms.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "drivers/gnss_fix.hpp"
#include "drivers/protocol.hpp"
#include "drivers/protocols/stream_protocols.hpp"

namespace imuemu::drivers::ubx {

inline constexpr std::uint8_t kSync1 = 0xB5;
inline constexpr std::uint8_t kSync2 = 0x62;
inline constexpr std::size_t kHeaderBytes = 6;  // sync1 sync2 class id length(2)
inline constexpr std::size_t kChecksumBytes = 2;

inline constexpr std::uint8_t kClassNav = 0x01;
inline constexpr std::uint8_t kNavPosllh = 0x02;   // 28 bytes
inline constexpr std::uint8_t kNavStatus = 0x03;   // 16
inline constexpr std::uint8_t kNavDop = 0x04;      // 18
inline constexpr std::uint8_t kNavSol = 0x06;      // 52
inline constexpr std::uint8_t kNavPvt = 0x07;      // 92
inline constexpr std::uint8_t kNavVelned = 0x12;   // 36
inline constexpr std::uint8_t kNavTimegps = 0x20;  // 16
inline constexpr std::uint8_t kNavEoe = 0x61;      // 4
inline constexpr std::size_t kNavPvtPayloadBytes = 92;

// CK_A, CK_B over class..payload.
std::array<std::uint8_t, 2> checksum(std::span<const std::uint8_t> class_to_payload_end);

// Each appends one whole frame for the fix.
void append_nav_pvt(const GnssFix& fix, std::vector<std::uint8_t>& out);
void append_nav_posllh(const GnssFix& fix, std::vector<std::uint8_t>& out);
void append_nav_status(const GnssFix& fix, std::vector<std::uint8_t>& out);
void append_nav_dop(const GnssFix& fix, std::vector<std::uint8_t>& out);
void append_nav_sol(const GnssFix& fix, std::vector<std::uint8_t>& out);
void append_nav_velned(const GnssFix& fix, std::vector<std::uint8_t>& out);
void append_nav_timegps(const GnssFix& fix, std::vector<std::uint8_t>& out);
void append_nav_eoe(const GnssFix& fix, std::vector<std::uint8_t>& out);

class Encoder final : public StreamEncoder {
 public:
  explicit Encoder(const StreamEncoderOptions& options);
  std::string name() const override { return "ubx"; }
  void encode(const ImuFrameInput& sample, std::vector<std::uint8_t>& out) override;
  std::size_t max_bytes_per_sample() const override;
  bool needs_navigation() const override { return true; }
  StreamFrameLayout frame_layout(std::span<const std::uint8_t> frame) const override;

 private:
  GnssFixSource fix_source_;  // the trajectory, with the configured errors
  bool legacy_nav_ = true;
};

// Checks each frame's framing and checksum (for `imuemu listen`): counts
// frames, checksum errors and skipped bytes; reports no IMU samples.
class Decoder final : public StreamDecoder {
 public:
  void feed(std::span<const std::uint8_t> bytes, const SampleCallback& on_sample) override;
  const DecoderCounters& counters() const override { return counters_; }

 private:
  std::vector<std::uint8_t> buffer_;
  DecoderCounters counters_;
};

}  // namespace imuemu::drivers::ubx
