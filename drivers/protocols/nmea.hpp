// NMEA 0183 (v4.10 sentence formats) GNSS receiver output (issue 28): per
// epoch RMC, VTG, GGA, GSA and ZDA, in the order a u-blox M8 sends its
// default set (u-blox 8/M8 receiver description, "NMEA Protocol"), with the
// talker id GP or GN. Written from the NMEA 0183 sentence definitions; no
// receiver's code.
//
// A sentence: '$', talker (2) + formatter (3), comma-separated fields, '*',
// the checksum as two upper-case hex digits, <CR><LF>; at most 82 characters
// in all. The checksum is the XOR of every character between '$' and '*'
// (exclusive).
//
// Resolution on the wire (what a reader gets back at best):
//   latitude / longitude: ddmm.mmmmmm, 1e-6 arc minute (1.9 mm)
//   time: hhmmss.ss UTC, 10 ms (the epoch rounded to it)
//   altitude (GGA, MSL) and geoid separation: 0.01 m
//   speed: 0.001 knot (RMC, VTG), 0.001 km/h (VTG)
//   course over ground (true): 0.01 degree
//   HDOP 0.1, PDOP / VDOP 0.01
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "drivers/gnss_fix.hpp"
#include "drivers/protocol.hpp"
#include "drivers/protocols/stream_protocols.hpp"

namespace imuemu::drivers::nmea {

inline constexpr std::size_t kMaxSentenceChars = 82;  // '$' to <LF> inclusive

// XOR of the characters between '$' and '*'.
std::uint8_t checksum(std::string_view between_dollar_and_star);

// Each appends one whole sentence ($..*hh<CR><LF>) for the fix; talker "GP"
// or "GN". Never allocates beyond `out`'s growth (formatted in a stack buffer).
void append_gga(const GnssFix& fix, std::string_view talker, std::vector<std::uint8_t>& out);
void append_rmc(const GnssFix& fix, std::string_view talker, std::vector<std::uint8_t>& out);
void append_vtg(const GnssFix& fix, std::string_view talker, std::vector<std::uint8_t>& out);
void append_gsa(const GnssFix& fix, std::string_view talker, std::vector<std::uint8_t>& out);
void append_zda(const GnssFix& fix, std::string_view talker, std::vector<std::uint8_t>& out);

// A GNSS receiver sending NMEA: one epoch (RMC, VTG, GGA, GSA, ZDA) per
// device sample; the device's rate is the navigation rate.
class Encoder final : public StreamEncoder {
 public:
  explicit Encoder(const StreamEncoderOptions& options);
  std::string name() const override { return "nmea"; }
  void encode(const ImuFrameInput& sample, std::vector<std::uint8_t>& out) override;
  std::size_t max_bytes_per_sample() const override { return 5 * kMaxSentenceChars; }
  bool needs_navigation() const override { return true; }
  // Each sentence is a frame of its own: checksum at '*' + 1 (two hex digits).
  StreamFrameLayout frame_layout(std::span<const std::uint8_t> frame) const override;

 private:
  GnssFixSource fix_source_;  // the trajectory, with the configured errors
  char talker_[3] = {'G', 'P', '\0'};
};

// Checks the framing and checksum of each sentence (for `imuemu listen`):
// counts frames, checksum errors and skipped bytes; reports no IMU samples.
class Decoder final : public StreamDecoder {
 public:
  void feed(std::span<const std::uint8_t> bytes, const SampleCallback& on_sample) override;
  const DecoderCounters& counters() const override { return counters_; }

 private:
  std::vector<std::uint8_t> buffer_;
  DecoderCounters counters_;
};

}  // namespace imuemu::drivers::nmea
