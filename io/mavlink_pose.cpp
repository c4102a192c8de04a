// MAVLink 2 HIL_STATE_QUATERNION reader (io/mavlink_pose.hpp).
//
// Sources (read, nothing copied):
//  [G] MAVLink developer guide, "Packet Serialization": MAVLink 2 packet
//      (STX 0xFD, len, incompat_flags, compat_flags, seq, sysid, compid,
//      msgid 24 bits, payload, checksum, optional 13-byte signature),
//      little-endian fields sorted by type size (extensions last), trailing
//      zero bytes of the payload truncated, X.25 CRC over everything but STX
//      followed by CRC_EXTRA; a packet with an unknown incompat flag is dropped.
//  [X] common.xml HIL_STATE_QUATERNION (#115): time_usec (us), attitude_quaternion
//      (w, x, y, z; 1 0 0 0 = null rotation), rollspeed/pitchspeed/yawspeed
//      (rad/s, body frame), lat/lon (degE7), alt (mm), vx/vy/vz (cm/s, ground
//      speed), ind_airspeed/true_airspeed (cm/s), xacc/yacc/zacc (mG).
#include "io/mavlink_pose.hpp"

#include <algorithm>
#include <bit>
#include <boost/crc.hpp>
#include <cmath>
#include <cstring>
#include <limits>

namespace imuemu::io::mavlink {
namespace {

using X25 = boost::crc_optimal<16, 0x1021, 0xFFFF, 0, true, true>;

template <class T>
void put(std::uint8_t* at, T value) {
  using U = std::conditional_t<sizeof(T) == 1, std::uint8_t,
            std::conditional_t<sizeof(T) == 2, std::uint16_t,
            std::conditional_t<sizeof(T) == 4, std::uint32_t, std::uint64_t>>>;
  const U bits = std::bit_cast<U>(value);
  for (std::size_t i = 0; i < sizeof(T); ++i) at[i] = static_cast<std::uint8_t>(bits >> (8 * i));
}
template <class T>
T get(const std::uint8_t* at) {
  using U = std::conditional_t<sizeof(T) == 1, std::uint8_t,
            std::conditional_t<sizeof(T) == 2, std::uint16_t,
            std::conditional_t<sizeof(T) == 4, std::uint32_t, std::uint64_t>>>;
  U bits = 0;
  for (std::size_t i = 0; i < sizeof(T); ++i) bits = static_cast<U>(bits | static_cast<U>(U{at[i]} << (8 * i)));
  return std::bit_cast<T>(bits);
}

// [X] field offsets in wire order ([G] reordering leaves the XML order: it
// is already sorted by size, 8, 4 (x 10), 2 (x 8)).
constexpr std::size_t kOffTimeUsec = 0;
constexpr std::size_t kOffQuaternion = 8;
constexpr std::size_t kOffRollspeed = 24;
constexpr std::size_t kOffLat = 36;
constexpr std::size_t kOffLon = 40;
constexpr std::size_t kOffAlt = 44;
constexpr std::size_t kOffVx = 48;
constexpr std::size_t kOffIndAirspeed = 54;
constexpr std::size_t kOffTrueAirspeed = 56;
constexpr std::size_t kOffXacc = 58;

std::uint16_t packet_crc(std::span<const std::uint8_t> after_stx, std::uint8_t crc_extra) {
  X25 crc;
  crc.process_bytes(after_stx.data(), after_stx.size());
  crc.process_byte(crc_extra);
  return crc.checksum();
}

bool fail(DatagramDecodeError& error, DatagramError reason, std::string message, bool intact) {
  error.reason = reason;
  error.message = std::move(message);
  error.intact = intact;
  return false;
}

std::string hex_byte(std::uint8_t b) {
  static constexpr char kHex[] = "0123456789abcdef";
  return std::string("0x") + kHex[b >> 4] + kHex[b & 0xf];
}

}  // namespace

std::uint16_t crc16_mcrf4xx(std::span<const std::uint8_t> bytes) noexcept {
  X25 crc;
  crc.process_bytes(bytes.data(), bytes.size());
  return crc.checksum();
}

std::vector<std::uint8_t> encode_hil_state_quaternion(const HilStateQuaternion& m, const PacketInfo& header) {
  std::array<std::uint8_t, kHilStateQuaternionPayloadBytes> p{};
  put<std::uint64_t>(&p[kOffTimeUsec], m.time_usec);
  for (std::size_t i = 0; i < 4; ++i) put<float>(&p[kOffQuaternion + 4 * i], m.attitude_quaternion[i]);
  put<float>(&p[kOffRollspeed], m.rollspeed_rad_s);
  put<float>(&p[kOffRollspeed + 4], m.pitchspeed_rad_s);
  put<float>(&p[kOffRollspeed + 8], m.yawspeed_rad_s);
  put<std::int32_t>(&p[kOffLat], m.lat_degE7);
  put<std::int32_t>(&p[kOffLon], m.lon_degE7);
  put<std::int32_t>(&p[kOffAlt], m.alt_mm);
  put<std::int16_t>(&p[kOffVx], m.vx_cm_s);
  put<std::int16_t>(&p[kOffVx + 2], m.vy_cm_s);
  put<std::int16_t>(&p[kOffVx + 4], m.vz_cm_s);
  put<std::uint16_t>(&p[kOffIndAirspeed], m.ind_airspeed_cm_s);
  put<std::uint16_t>(&p[kOffTrueAirspeed], m.true_airspeed_cm_s);
  put<std::int16_t>(&p[kOffXacc], m.xacc_mG);
  put<std::int16_t>(&p[kOffXacc + 2], m.yacc_mG);
  put<std::int16_t>(&p[kOffXacc + 4], m.zacc_mG);
  // [G] "Empty-Byte Payload Truncation": trailing zeros are not sent, the
  // first payload byte always is.
  std::size_t len = p.size();
  while (len > 1 && p[len - 1] == 0) --len;
  std::vector<std::uint8_t> out(kHeaderBytes + len + kChecksumBytes);
  out[0] = kMagicV2;
  out[1] = static_cast<std::uint8_t>(len);
  out[2] = 0;  // incompat_flags: unsigned
  out[3] = 0;  // compat_flags
  out[4] = header.sequence;
  out[5] = header.system_id;
  out[6] = header.component_id;
  out[7] = static_cast<std::uint8_t>(kHilStateQuaternionId);
  out[8] = static_cast<std::uint8_t>(kHilStateQuaternionId >> 8);
  out[9] = static_cast<std::uint8_t>(kHilStateQuaternionId >> 16);
  std::copy_n(p.begin(), len, out.begin() + kHeaderBytes);
  const std::uint16_t crc =
      packet_crc(std::span<const std::uint8_t>(out.data() + 1, kHeaderBytes - 1 + len), kHilStateQuaternionCrcExtra);
  put<std::uint16_t>(&out[kHeaderBytes + len], crc);
  return out;
}

Outcome decode_datagram(std::span<const std::uint8_t> bytes, HilStateQuaternion& m, PacketInfo& info,
                        DatagramDecodeError& error) {
  if (bytes.empty()) {
    fail(error, DatagramError::too_short, "empty datagram: expected MAVLink 2 packets", false);
    return Outcome::refused;
  }
  bool found = false;
  std::size_t at = 0;
  while (at < bytes.size()) {
    const std::span<const std::uint8_t> rest = bytes.subspan(at);
    const std::string where = "packet at byte " + std::to_string(at) + ": ";
    if (rest[0] == kMagicV1) {
      fail(error, DatagramError::unsupported_version,
           where + "MAVLink 1 (STX 0xfe); HIL_STATE_QUATERNION is read as MAVLink 2 (STX 0xfd)", false);
      return Outcome::refused;
    }
    if (rest[0] != kMagicV2) {
      fail(error, DatagramError::bad_magic, where + "expected the MAVLink 2 STX 0xfd, got " + hex_byte(rest[0]), false);
      return Outcome::refused;
    }
    if (rest.size() < kHeaderBytes) {
      fail(error, DatagramError::too_short,
           where + "truncated header (" + std::to_string(rest.size()) + " of 10 bytes)", false);
      return Outcome::refused;
    }
    // [G] "Incompatibility Flags": a flag this reader does not understand
    // means the packet cannot be read. Signed packets are read; their
    // signature is skipped (no key here).
    const std::uint8_t incompat = rest[2];
    if ((incompat & ~kIncompatSigned) != 0) {
      fail(error, DatagramError::unsupported_version,
           where + "unknown incompat_flags " + hex_byte(incompat) + " (only 0x01, signed, is known)", false);
      return Outcome::refused;
    }
    const std::size_t len = rest[1];
    const std::size_t total =
        kHeaderBytes + len + kChecksumBytes + ((incompat & kIncompatSigned) != 0 ? kSignatureBytes : 0);
    if (rest.size() < total) {
      fail(error, DatagramError::bad_length,
           where + "truncated: its header says " + std::to_string(total) + " bytes, the datagram holds " +
               std::to_string(rest.size()),
           false);
      return Outcome::refused;
    }
    const std::uint32_t msgid = std::uint32_t{rest[7]} | std::uint32_t{rest[8]} << 8 | std::uint32_t{rest[9]} << 16;
    if (msgid == kHilStateQuaternionId) {
      if (found) {
        fail(error, DatagramError::bad_length, where + "a second HIL_STATE_QUATERNION in one datagram", false);
        return Outcome::refused;
      }
      const std::uint16_t sent = get<std::uint16_t>(&rest[kHeaderBytes + len]);
      if (packet_crc(rest.subspan(1, kHeaderBytes - 1 + len), kHilStateQuaternionCrcExtra) != sent) {
        fail(error, DatagramError::bad_checksum, where + "HIL_STATE_QUATERNION checksum mismatch (corrupted)", false);
        return Outcome::refused;
      }
      // [G] truncation: zero-extend to the full length; a longer payload
      // carries extension fields of a newer dialect, ignored.
      std::array<std::uint8_t, 255> p{};
      std::copy_n(rest.begin() + kHeaderBytes, len, p.begin());
      m.time_usec = get<std::uint64_t>(&p[kOffTimeUsec]);
      for (std::size_t i = 0; i < 4; ++i) m.attitude_quaternion[i] = get<float>(&p[kOffQuaternion + 4 * i]);
      m.rollspeed_rad_s = get<float>(&p[kOffRollspeed]);
      m.pitchspeed_rad_s = get<float>(&p[kOffRollspeed + 4]);
      m.yawspeed_rad_s = get<float>(&p[kOffRollspeed + 8]);
      m.lat_degE7 = get<std::int32_t>(&p[kOffLat]);
      m.lon_degE7 = get<std::int32_t>(&p[kOffLon]);
      m.alt_mm = get<std::int32_t>(&p[kOffAlt]);
      m.vx_cm_s = get<std::int16_t>(&p[kOffVx]);
      m.vy_cm_s = get<std::int16_t>(&p[kOffVx + 2]);
      m.vz_cm_s = get<std::int16_t>(&p[kOffVx + 4]);
      m.ind_airspeed_cm_s = get<std::uint16_t>(&p[kOffIndAirspeed]);
      m.true_airspeed_cm_s = get<std::uint16_t>(&p[kOffTrueAirspeed]);
      m.xacc_mG = get<std::int16_t>(&p[kOffXacc]);
      m.yacc_mG = get<std::int16_t>(&p[kOffXacc + 2]);
      m.zacc_mG = get<std::int16_t>(&p[kOffXacc + 4]);
      info = {rest[4], rest[5], rest[6]};
      found = true;
    }
    at += total;
  }
  return found ? Outcome::hil_state : Outcome::other;
}

bool to_record(const HilStateQuaternion& m, TrajectoryRecord& r, DatagramDecodeError& error) {
  r = TrajectoryRecord{};
  if (m.time_usec > static_cast<std::uint64_t>(std::numeric_limits<TimeNs>::max() / 1000)) {
    return fail(error, DatagramError::bad_value,
                "time_usec " + std::to_string(m.time_usec) + " is beyond the int64 nanosecond range", true);
  }
  r.t_ns = static_cast<TimeNs>(m.time_usec) * 1000;
  // [X] lat/lon in 1e-7 degrees, alt in mm (taken as the height above the
  // WGS84 ellipsoid: docs/pose-wire-format.md §4.2).
  if (m.lat_degE7 < -900'000'000 || m.lat_degE7 > 900'000'000)
    return fail(error, DatagramError::bad_value,
                "lat " + std::to_string(m.lat_degE7) + " degE7: expected a latitude in [-90, 90] degrees", true);
  if (m.lon_degE7 < -1'800'000'000 || m.lon_degE7 > 1'800'000'000)
    return fail(error, DatagramError::bad_value,
                "lon " + std::to_string(m.lon_degE7) + " degE7: expected a longitude in [-180, 180] degrees", true);
  r.position_kind = PositionKind::geodetic;
  r.position = Vec3(m.lat_degE7 * 1e-7, m.lon_degE7 * 1e-7, m.alt_mm * 1e-3);
  r.attitude_kind = AttitudeKind::quaternion;
  for (int i = 0; i < 4; ++i) r.attitude[i] = static_cast<double>(m.attitude_quaternion[static_cast<std::size_t>(i)]);
  double norm = 0.0;
  if (!r.attitude.allFinite() || !normalise_unit_quaternion(r.attitude, norm)) {
    return fail(error, DatagramError::bad_value,
                "attitude_quaternion: expected a finite unit quaternion (|q| within 1e-6 of 1), got |q| = " +
                    detail::format_double(r.attitude.norm()),
                true);
  }
  const Vec3 rate(m.rollspeed_rad_s, m.pitchspeed_rad_s, m.yawspeed_rad_s);
  if (!rate.allFinite())
    return fail(error, DatagramError::bad_value, "rollspeed/pitchspeed/yawspeed: expected finite body rates", true);
  r.rates.angular_rate_rad_s = rate;
  r.rates.velocity_m_s = Vec3(m.vx_cm_s, m.vy_cm_s, m.vz_cm_s) * 1e-2;  // NED ground velocity (int16: < 328 m/s)
  // A float rate up to FLT_MAX is finite but no motion (io/pose_wire.hpp kMaxLive*).
  if (!check_live_rates(r.rates, error)) {
    error.message = "rollspeed/pitchspeed/yawspeed as " + error.message;
    return false;
  }
  // xacc..zacc (mG, body frame, specific force or kinematic acceleration
  // depending on the bridge) are not used as the kinematic acceleration.
  return true;
}

SenderFilter::SenderFilter(std::optional<std::uint8_t> system_id, std::optional<std::uint8_t> component_id)
    : system_id_(system_id), component_id_(component_id) {}

SenderFilter::Verdict SenderFilter::judge(const PacketInfo& info) noexcept {
  if (taken_) {
    return info.system_id == taken_->system_id && info.component_id == taken_->component_id ? Verdict::taken
                                                                                            : Verdict::other;
  }
  if ((system_id_ && info.system_id != *system_id_) || (component_id_ && info.component_id != *component_id_))
    return Verdict::other;
  taken_ = PacketInfo{0, info.system_id, info.component_id};
  return Verdict::taken_now;
}

std::uint64_t SequenceWidener::widen(const PacketInfo& info) {
  const auto key = static_cast<std::uint16_t>(std::uint16_t{info.system_id} << 8 | info.component_id);
  // Starts one wrap up, so that an early reordered packet cannot go below 0.
  auto [it, fresh] = senders_.try_emplace(key, State{info.sequence, 256u + info.sequence});
  if (fresh) return it->second.widened;
  // A step below half the 8-bit range is forward (a step of k: k - 1 lost);
  // above it, the packet is an earlier one arriving late (reordered), whose
  // number lies behind the highest: the reference does not move.
  const auto step = static_cast<std::uint8_t>(info.sequence - it->second.last);
  if (step < 128) {
    it->second.widened += step;
    it->second.last = info.sequence;
    return it->second.widened;
  }
  return it->second.widened - (256u - step);
}

}  // namespace imuemu::io::mavlink
