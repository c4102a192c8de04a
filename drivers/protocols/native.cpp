// imuemu native v1 encoder and decoder. Layout, units and axes: see
// docs/native-protocol.md (section numbers below refer to it).
//
// Units and axes: the frame carries exactly what the sensor model emits -
// angular rate omega_ib^b in rad/s and specific force f^b in m/s^2, both in
// body FRD axes (x forward, y right, z down) - so the conversion is the
// identity, done explicitly in frd_to_native() so a reader sees it is meant.
#include "drivers/protocols/native.hpp"

#include <algorithm>
#include <array>
#include <boost/crc.hpp>
#include <limits>

#include "drivers/protocols/wire_bytes.hpp"

namespace imuemu::drivers::native {

namespace {

// Section 2 (CRC): CRC-32C, reflected, init and final xor all ones.
using Crc32cEngine = boost::crc_optimal<32, 0x1EDC6F41, 0xFFFFFFFF, 0xFFFFFFFF, true, true>;

// Section 3 (axes): native frame axes are body FRD; no change.
Vec3 frd_to_native(const Vec3& v_frd) { return v_frd; }
Vec3 native_to_frd(const Vec3& v_native) { return v_native; }

// Section 4 (non-finite input): NaN -> 0 with saturated|fault, +-inf or beyond
// the f64 range -> +-DBL_MAX with saturated. Writes 3 f64 little-endian.
std::uint32_t put_vec3_f64(std::uint8_t* at, const Vec3& v) {
  std::uint32_t status = 0;
  for (int i = 0; i < 3; ++i) {
    const wire::WireValue w = wire::to_wire_float<double>(v[i]);
    if (w.clamped) status |= kStatusSaturated;
    if (w.was_nan) status |= kStatusSaturated | kStatusFault;
    wire::put_le<double>(at + 8 * i, w.value);
  }
  return status;
}

Vec3 get_vec3_f64(const std::uint8_t* at) {
  return {wire::get_le<double>(at), wire::get_le<double>(at + 8), wire::get_le<double>(at + 16)};
}

}  // namespace

std::uint32_t crc32c(std::span<const std::uint8_t> bytes) {
  Crc32cEngine crc;
  crc.process_bytes(bytes.data(), bytes.size());
  return crc.checksum();
}

void Encoder::encode(const ImuFrameInput& sample, std::vector<std::uint8_t>& out) {
  const std::size_t payload = include_deltas_ ? kPayloadBytesDeltas : kPayloadBytesBase;
  std::array<std::uint8_t, kFrameBytesDeltas> frame{};
  std::uint8_t* p = frame.data();

  // Section 1 (header).
  p[0] = kSync0;
  p[1] = kSync1;
  p[2] = kVersion;
  p[3] = include_deltas_ ? kFlagDeltas : std::uint8_t{0};
  wire::put_le<std::uint16_t>(p + 4, static_cast<std::uint16_t>(payload));

  // Section 1 (payload): sequence = the device's sample counter, so a sync
  // pulse that names a counter value names exactly one frame.
  if (reset_pending_) {  // link fault: this frame carries 0
    sequence_offset_ = step_after_reset_ - sample.sample_counter;
    reset_pending_ = false;
    step_after_reset_ = 0;
  }
  wire::put_le<std::uint64_t>(p + 6, sample.sample_counter + sequence_offset_);
  wire::put_le<std::int64_t>(p + 14, sample.t_ns);
  std::uint32_t status = sample.status & kStatusBitsV1;
  status |= put_vec3_f64(p + 26, frd_to_native(sample.gyro_rad_s));
  status |= put_vec3_f64(p + 50, frd_to_native(sample.accel_m_s2));
  if (include_deltas_) {
    status |= put_vec3_f64(p + 74, frd_to_native(sample.delta_theta_rad));
    status |= put_vec3_f64(p + 98, frd_to_native(sample.delta_velocity_m_s));
  }
  wire::put_le<std::uint32_t>(p + 22, status);

  const std::size_t crc_at = kHeaderBytes + payload;
  wire::put_le<std::uint32_t>(p + crc_at, crc32c(std::span<const std::uint8_t>(p, crc_at)));
  out.insert(out.end(), p, p + crc_at + kCrcBytes);
}

StreamFrameLayout Encoder::frame_layout(std::span<const std::uint8_t> frame) const {
  // Section 1: payload_length (u16 LE) at offset 4, the CRC-32C after the payload.
  if (frame.size() < kHeaderBytes) return StreamFrameLayout{frame.size()};
  const std::size_t payload = wire::get_le<std::uint16_t>(frame.data() + 4);
  StreamFrameLayout layout;
  layout.frame_bytes = std::min(frame.size(), kHeaderBytes + payload + kCrcBytes);
  layout.length_offset = 4;
  layout.length_bytes = 2;
  layout.checksum_offset = kHeaderBytes + payload;
  layout.checksum_bytes = layout.checksum_offset + kCrcBytes <= frame.size() ? kCrcBytes : 0;
  return layout;
}

void Decoder::feed(std::span<const std::uint8_t> bytes, const SampleCallback& on_sample) {
  buffer_.insert(buffer_.end(), bytes.begin(), bytes.end());
  static constexpr std::array<std::uint8_t, 2> kSync{kSync0, kSync1};

  wire::scan_frames(buffer_, kSync, counters_, [&](std::span<const std::uint8_t> c) {
    using wire::Candidate;
    if (c.size() < kHeaderBytes) return wire::CandidateResult{Candidate::kNeedMore};
    // Section 5 (decoder): version, flags and length must agree exactly
    // before the CRC is even looked at.
    const std::uint8_t version = c[2];
    const std::uint8_t flags = c[3];
    const std::size_t length = wire::get_le<std::uint16_t>(c.data() + 4);
    const bool has_deltas = (flags & kFlagDeltas) != 0;
    if (version != kVersion || (flags & ~kFlagDeltas) != 0 ||
        length != (has_deltas ? kPayloadBytesDeltas : kPayloadBytesBase)) {
      return wire::CandidateResult{Candidate::kMalformed};
    }
    const std::size_t total = kHeaderBytes + length + kCrcBytes;
    if (c.size() < total) return wire::CandidateResult{Candidate::kNeedMore};
    const std::uint32_t sent_crc = wire::get_le<std::uint32_t>(c.data() + kHeaderBytes + length);
    if (crc32c(c.first(kHeaderBytes + length)) != sent_crc) {
      return wire::CandidateResult{Candidate::kBadChecksum};
    }

    ++counters_.frames;
    DecodedSample s;
    s.sequence = wire::get_le<std::uint64_t>(c.data() + 6);
    s.has_sequence = true;
    s.t_ns = wire::get_le<std::int64_t>(c.data() + 14);
    s.has_time = true;
    s.status = wire::get_le<std::uint32_t>(c.data() + 22) & kStatusBitsV1;
    s.gyro_rad_s = native_to_frd(get_vec3_f64(c.data() + 26));
    s.accel_m_s2 = native_to_frd(get_vec3_f64(c.data() + 50));
    if (has_deltas) {
      s.delta_theta_rad = native_to_frd(get_vec3_f64(c.data() + 74));
      s.delta_velocity_m_s = native_to_frd(get_vec3_f64(c.data() + 98));
    }

    // Sequence gaps: modular difference, so 2^64-1 -> 0 is no gap; a step
    // backwards (sender restarted) re-bases without counting.
    if (last_sequence_) {
      const std::uint64_t step = s.sequence - *last_sequence_;
      if (step >= 1 && step <= (std::numeric_limits<std::uint64_t>::max() >> 1)) {
        counters_.sequence_gaps += step - 1;
      }
    }
    last_sequence_ = s.sequence;

    // A conforming sender never puts NaN/inf on the wire; one that does gets
    // its frame counted and its sample refused, never passed on.
    if (!s.gyro_rad_s.allFinite() || !s.accel_m_s2.allFinite() || !s.delta_theta_rad.allFinite() ||
        !s.delta_velocity_m_s.allFinite()) {
      ++counters_.other_errors;
    } else {
      ++counters_.samples;
      if (on_sample) on_sample(s);
    }
    return wire::CandidateResult{Candidate::kAccepted, total};
  });
}

}  // namespace imuemu::drivers::native
