#include "io/pose_wire.hpp"

#include <bit>
#include <boost/crc.hpp>
#include <cmath>
#include <cstring>
#include <optional>
#include <utility>

namespace imuemu::io {

// ---------------------------------------------------------------- pose lines

std::string_view to_string(LineError error) noexcept {
  switch (error) {
    case LineError::unsupported_version: return "unsupported_version";
    case LineError::bad_header: return "bad_header";
    case LineError::bad_record: return "bad_record";
    case LineError::line_too_long: return "line_too_long";
    case LineError::unterminated_line: return "unterminated_line";
  }
  return "unknown";
}

namespace {

std::string_view trim_blanks(std::string_view s) noexcept {
  auto blank = [](char c) { return c == ' ' || c == '\t' || c == '\r'; };
  while (!s.empty() && blank(s.front())) s.remove_prefix(1);
  while (!s.empty() && blank(s.back())) s.remove_suffix(1);
  return s;
}

}  // namespace

PoseLineDecoder::PoseLineDecoder(std::string source_name) : parser_(std::move(source_name)) {}

PoseLineDecoder::Outcome PoseLineDecoder::decode(std::string_view line, TrajectoryRecord& record, LineError& error,
                                                 std::string& error_message) {
  ++line_number_;
  std::string_view content = line;
  if (line_number_ == 1 && content.size() >= 3 && std::memcmp(content.data(), "\xEF\xBB\xBF", 3) == 0) {
    content.remove_prefix(3);
  }
  content = trim_blanks(content);
  const bool comment_or_blank = content.empty() || content.front() == '#';
  if (refused_version_line_ != 0) {
    // The stream declared a format this reader does not know: none of its
    // lines can be trusted to mean what v1 says.
    if (comment_or_blank) return Outcome::ignored;
    error = LineError::unsupported_version;
    error_message = parser_.source_name() + ":" + std::to_string(line_number_) +
                    ": line of a stream that declared an unsupported version (line " +
                    std::to_string(refused_version_line_) + ")";
    return Outcome::error;
  }
  // The version line is recognised before the header only; after it, every
  // comment is just a comment (as in a trajectory file).
  if (!parser_.has_header() && content.starts_with(kPoseLinesTag) &&
      (content.size() == kPoseLinesTag.size() || content[kPoseLinesTag.size()] == ' ' ||
       content[kPoseLinesTag.size()] == '\t')) {
    const std::string_view version = trim_blanks(content.substr(kPoseLinesTag.size()));
    if (version != "v1") {
      refused_version_line_ = line_number_;
      error = LineError::unsupported_version;
      error_message = parser_.source_name() + ":" + std::to_string(line_number_) + ": unsupported version '" +
                      detail::printable(version) + "'; this reader knows " + std::string(kPoseLinesTag) + " v" +
                      std::to_string(kPoseLinesVersion);
      return Outcome::error;
    }
  }
  const bool had_header = parser_.has_header();
  try {
    // The parser counts lines itself; it sees every line the decoder does.
    const TrajectoryLineParser::LineKind kind = parser_.feed(line, record);
    return kind == TrajectoryLineParser::LineKind::record ? Outcome::record : Outcome::ignored;
  } catch (const TrajectoryFormatError& e) {
    error = had_header ? LineError::bad_record : LineError::bad_header;
    error_message = e.what();
    return Outcome::error;
  }
}

void PoseLineDecoder::skip_line() {
  ++line_number_;
  TrajectoryRecord unused;
  parser_.feed({}, unused);  // a blank line: only counted
}

// ---------------------------------------------------------------- datagrams

std::string_view to_string(DatagramError error) noexcept {
  switch (error) {
    case DatagramError::too_short: return "too_short";
    case DatagramError::bad_magic: return "bad_magic";
    case DatagramError::unsupported_version: return "unsupported_version";
    case DatagramError::bad_length: return "bad_length";
    case DatagramError::bad_checksum: return "bad_checksum";
    case DatagramError::bad_kind: return "bad_kind";
    case DatagramError::reserved_not_zero: return "reserved_not_zero";
    case DatagramError::bad_value: return "bad_value";
  }
  return "unknown";
}

namespace {

// CRC-32C as specified for iSCSI (RFC 3720 §B.4) and used by ext4 and SCTP.
using Crc32c = boost::crc_optimal<32, 0x1EDC6F41, 0xFFFFFFFF, 0xFFFFFFFF, true, true>;

void put_u64(std::uint8_t* out, std::uint64_t v) noexcept {
  for (int i = 0; i < 8; ++i) out[i] = static_cast<std::uint8_t>(v >> (8 * i));
}
std::uint64_t get_u64(const std::uint8_t* in) noexcept {
  std::uint64_t v = 0;
  for (int i = 7; i >= 0; --i) v = (v << 8) | in[i];
  return v;
}
std::uint32_t get_u32(const std::uint8_t* in) noexcept {
  return static_cast<std::uint32_t>(in[0]) | static_cast<std::uint32_t>(in[1]) << 8 |
         static_cast<std::uint32_t>(in[2]) << 16 | static_cast<std::uint32_t>(in[3]) << 24;
}

constexpr std::uint8_t kPositionKinds = 3;
constexpr std::uint8_t kAttitudeKinds = 3;

std::string hex_byte(std::uint8_t b) {
  static constexpr char kHex[] = "0123456789abcdef";
  return std::string("0x") + kHex[b >> 4] + kHex[b & 0xf];
}

bool fail(DatagramDecodeError& error, DatagramError reason, std::string message, bool intact) {
  error.reason = reason;
  error.message = std::move(message);
  error.intact = intact;
  return false;
}

// One value against its column's rule (the trajectory file's rule).
bool check_value(double value, std::string_view what, int component, const ColumnRule& rule,
                 DatagramDecodeError& error) {
  if (std::isfinite(value) && value >= rule.min && value <= rule.max) return true;
  return fail(error, DatagramError::bad_value,
              std::string(what) + " component " + std::to_string(component) + " (" + std::string(rule.name) +
                  "): expected " + std::string(rule.expected) + ", got " + detail::format_double(value),
              true);
}

}  // namespace

std::uint32_t crc32c(std::span<const std::uint8_t> bytes) noexcept {
  Crc32c crc;
  crc.process_bytes(bytes.data(), bytes.size());
  return crc.checksum();
}

namespace {

// The fields v1 and v2 share (bytes 0..79 but the version and byte 7).
void encode_common(const PoseDatagram& d, std::uint8_t version, std::uint8_t byte7, std::uint8_t* out) noexcept {
  std::memcpy(out, kPoseDatagramMagic.data(), kPoseDatagramMagic.size());
  out[kDatagramVersionOffset] = version;
  out[kDatagramPositionKindOffset] = static_cast<std::uint8_t>(d.record.position_kind);
  out[kDatagramAttitudeKindOffset] = static_cast<std::uint8_t>(d.record.attitude_kind);
  out[kDatagramReservedOffset] = byte7;
  put_u64(&out[kDatagramSequenceOffset], d.sequence);
  put_u64(&out[kDatagramTimeOffset], static_cast<std::uint64_t>(d.record.t_ns));
  for (int k = 0; k < 3; ++k)
    put_u64(&out[kDatagramPositionOffset + 8 * static_cast<std::size_t>(k)],
            std::bit_cast<std::uint64_t>(d.record.position[k]));
  for (int k = 0; k < 4; ++k)
    put_u64(&out[kDatagramAttitudeOffset + 8 * static_cast<std::size_t>(k)],
            std::bit_cast<std::uint64_t>(d.record.attitude[k]));
}

void put_vec3(std::uint8_t* out, const Vec3& v) noexcept {
  for (int k = 0; k < 3; ++k) put_u64(out + 8 * k, std::bit_cast<std::uint64_t>(v[k]));
}
Vec3 get_vec3(const std::uint8_t* in) noexcept {
  return {std::bit_cast<double>(get_u64(in)), std::bit_cast<double>(get_u64(in + 8)),
          std::bit_cast<double>(get_u64(in + 16))};
}

void seal(std::uint8_t* out, std::size_t crc_offset) noexcept {
  const std::uint32_t crc = crc32c(std::span<const std::uint8_t>(out, crc_offset));
  for (std::size_t i = 0; i < 4; ++i) out[crc_offset + i] = static_cast<std::uint8_t>(crc >> (8 * i));
}

}  // namespace

std::array<std::uint8_t, kPoseDatagramV1Size> encode_pose_datagram(const PoseDatagram& d) noexcept {
  std::array<std::uint8_t, kPoseDatagramV1Size> out{};
  encode_common(d, kPoseDatagramVersion, 0, out.data());
  seal(out.data(), kDatagramCrcOffset);
  return out;
}

std::array<std::uint8_t, kPoseDatagramV2Size> encode_pose_datagram_v2(const PoseDatagram& d) noexcept {
  std::array<std::uint8_t, kPoseDatagramV2Size> out{};
  const PoseRates& r = d.record.rates;
  const std::uint8_t mask = static_cast<std::uint8_t>((r.velocity_m_s ? kRatesVelocity : 0) |
                                                      (r.angular_rate_rad_s ? kRatesAngularRate : 0) |
                                                      (r.acceleration_m_s2 ? kRatesAcceleration : 0));
  encode_common(d, kPoseDatagramVersion2, mask, out.data());
  if (r.velocity_m_s) put_vec3(&out[kDatagramVelocityOffset], *r.velocity_m_s);
  if (r.angular_rate_rad_s) put_vec3(&out[kDatagramAngularRateOffset], *r.angular_rate_rad_s);
  if (r.acceleration_m_s2) put_vec3(&out[kDatagramAccelerationOffset], *r.acceleration_m_s2);
  seal(out.data(), kDatagramV2CrcOffset);
  return out;
}

bool decode_pose_datagram(std::span<const std::uint8_t> bytes, PoseDatagram& out, DatagramDecodeError& error) {
  // Structure first (docs/pose-wire-format.md §2.3): nothing inside is read
  // before the checksum says the bytes are the sender's.
  if (bytes.size() < kDatagramVersionOffset + 1) {
    return fail(error, DatagramError::too_short,
                "datagram of " + std::to_string(bytes.size()) + " bytes: too short for magic and version", false);
  }
  if (std::memcmp(bytes.data(), kPoseDatagramMagic.data(), kPoseDatagramMagic.size()) != 0) {
    return fail(error, DatagramError::bad_magic,
                "datagram does not start with the magic \"IMUP\" (49 4d 55 50): got " +
                    detail::printable(std::string_view(reinterpret_cast<const char*>(bytes.data()), 4)),
                false);
  }
  const std::uint8_t version = bytes[kDatagramVersionOffset];
  if (version != kPoseDatagramVersion && version != kPoseDatagramVersion2) {
    return fail(error, DatagramError::unsupported_version,
                "datagram version " + std::to_string(version) + " is not supported; this reader knows versions 1 and 2",
                false);
  }
  const bool v2 = version == kPoseDatagramVersion2;
  const std::size_t expected_size = v2 ? kPoseDatagramV2Size : kPoseDatagramV1Size;
  if (bytes.size() != expected_size) {
    return fail(error, DatagramError::bad_length,
                "datagram of " + std::to_string(bytes.size()) + " bytes: a version " + std::to_string(version) +
                    " pose datagram has " + std::to_string(expected_size),
                false);
  }
  const std::size_t crc_offset = v2 ? kDatagramV2CrcOffset : kDatagramCrcOffset;
  const std::uint32_t expected_crc = crc32c(bytes.first(crc_offset));
  const std::uint32_t sent_crc = get_u32(&bytes[crc_offset]);
  if (sent_crc != expected_crc) {
    return fail(error, DatagramError::bad_checksum, "datagram CRC-32C mismatch (corrupted in transit)", false);
  }

  out.sequence = get_u64(&bytes[kDatagramSequenceOffset]);
  out.record = TrajectoryRecord{};
  out.record.t_ns = static_cast<TimeNs>(get_u64(&bytes[kDatagramTimeOffset]));
  const std::uint8_t position_kind = bytes[kDatagramPositionKindOffset];
  const std::uint8_t attitude_kind = bytes[kDatagramAttitudeKindOffset];
  if (position_kind >= kPositionKinds) {
    return fail(error, DatagramError::bad_kind,
                "unknown position kind " + hex_byte(position_kind) + "; expected 0 (geodetic), 1 (ECEF) or 2 (local NED)",
                true);
  }
  if (attitude_kind >= kAttitudeKinds) {
    return fail(error, DatagramError::bad_kind,
                "unknown attitude kind " + hex_byte(attitude_kind) +
                    "; expected 0 (heading-pitch-roll), 1 (quaternion q_b^l) or 2 (quaternion q_b^e)",
                true);
  }
  TrajectoryRecord& r = out.record;
  r.position_kind = static_cast<PositionKind>(position_kind);
  r.attitude_kind = static_cast<AttitudeKind>(attitude_kind);
  if (!kinds_compatible(r.position_kind, r.attitude_kind)) {
    return fail(error, DatagramError::bad_kind,
                "an ECEF attitude (kind 2) needs an Earth-fixed position (kind 0 or 1), not a local NED one", true);
  }
  const std::uint8_t byte7 = bytes[kDatagramReservedOffset];
  constexpr std::uint8_t kKnownRates = kRatesVelocity | kRatesAngularRate | kRatesAcceleration;
  if (!v2 && byte7 != 0) {
    return fail(error, DatagramError::reserved_not_zero,
                "reserved byte 7 is " + hex_byte(byte7) + ", expected 0x00", true);
  }
  if (v2 && (byte7 & ~kKnownRates) != 0) {
    return fail(error, DatagramError::reserved_not_zero,
                "rates mask (byte 7) is " + hex_byte(byte7) + ": only bits 0x01 (velocity), 0x02 (angular rate) and "
                "0x04 (acceleration) are defined",
                true);
  }
  for (int k = 0; k < 3; ++k)
    r.position[k] = std::bit_cast<double>(get_u64(&bytes[kDatagramPositionOffset + 8 * static_cast<std::size_t>(k)]));
  for (int k = 0; k < 4; ++k)
    r.attitude[k] = std::bit_cast<double>(get_u64(&bytes[kDatagramAttitudeOffset + 8 * static_cast<std::size_t>(k)]));
  for (int k = 0; k < 3; ++k) {
    if (!check_value(r.position[k], "position", k, position_column_rule(r.position_kind, k), error)) return false;
  }
  const int attitude_components = attitude_component_count(r.attitude_kind);
  for (int k = 0; k < attitude_components; ++k) {
    if (!check_value(r.attitude[k], "attitude", k, attitude_column_rule(r.attitude_kind, k), error)) return false;
  }
  if (r.attitude_kind == AttitudeKind::heading_pitch_roll) {
    if (r.attitude[3] != 0.0) {
      return fail(error, DatagramError::reserved_not_zero,
                  "attitude component 3 of a heading-pitch-roll pose is " + detail::format_double(r.attitude[3]) +
                      ", expected 0",
                  true);
    }
    r.attitude[3] = 0.0;  // -0.0 becomes +0.0, as a file record has it
  } else {
    double norm = 0.0;
    if (!normalise_unit_quaternion(r.attitude, norm)) {
      return fail(error, DatagramError::bad_value,
                  "expected a unit quaternion (|q| within 1e-6 of 1), got |q| = " + detail::format_double(norm), true);
    }
  }
  if (v2) {
    // Each rate vector: finite when its mask bit is set, all zero when not
    // (so a sender cannot mean something the reader ignores).
    struct RateField {
      std::uint8_t bit;
      std::size_t offset;
      const char* name;
      std::optional<Vec3>* into;
    };
    const RateField fields[] = {{kRatesVelocity, kDatagramVelocityOffset, "velocity_m_s", &r.rates.velocity_m_s},
                                {kRatesAngularRate, kDatagramAngularRateOffset, "angular_rate_rad_s",
                                 &r.rates.angular_rate_rad_s},
                                {kRatesAcceleration, kDatagramAccelerationOffset, "acceleration_m_s2",
                                 &r.rates.acceleration_m_s2}};
    for (const RateField& f : fields) {
      const Vec3 v = get_vec3(&bytes[f.offset]);
      if ((byte7 & f.bit) == 0) {
        for (int k = 0; k < 3; ++k) {
          if (std::bit_cast<std::uint64_t>(v[k]) != 0)
            return fail(error, DatagramError::reserved_not_zero,
                        std::string(f.name) + " component " + std::to_string(k) + " is " + detail::format_double(v[k]) +
                            " with its rates-mask bit clear, expected 0",
                        true);
        }
        continue;
      }
      for (int k = 0; k < 3; ++k) {
        if (!std::isfinite(v[k]))
          return fail(error, DatagramError::bad_value,
                      std::string(f.name) + " component " + std::to_string(k) + ": expected a finite value, got " +
                          detail::format_double(v[k]),
                      true);
      }
      *f.into = v;
    }
    if (!check_live_rates(r.rates, error)) return false;
  }
  return true;
}

bool check_live_rates(const PoseRates& rates, DatagramDecodeError& error) {
  struct Bound {
    const std::optional<Vec3>& value;
    double max;
    const char* name;
    const char* unit;
    const char* reason;
  };
  const Bound bounds[] = {
      {rates.velocity_m_s, kMaxLiveSpeed_m_s, "velocity_m_s", "m/s",
       "above escape speed plus the ECEF frame's rotation at the 1e9-m position bound"},
      {rates.angular_rate_rad_s, kMaxLiveAngularRate_rad_s, "angular_rate_rad_s", "rad/s",
       "1600 rev/s: no vehicle turns and no gyro measures that fast"},
      {rates.acceleration_m_s2, kMaxLiveAcceleration_m_s2, "acceleration_m_s2", "m/s^2",
       "1e5 g: beyond a gun launch"}};
  for (const Bound& b : bounds) {
    if (!b.value) continue;
    // The norm of finite components may overflow to inf: still beyond.
    const double magnitude = b.value->norm();
    if (b.value->allFinite() && magnitude <= b.max) continue;
    return fail(error, DatagramError::bad_value,
                std::string(b.name) + ": magnitude " + detail::format_double(magnitude) + " " + b.unit +
                    " is beyond " + detail::format_double(b.max) + " " + b.unit + " (" + b.reason + ")",
                true);
  }
  return true;
}

}  // namespace imuemu::io
