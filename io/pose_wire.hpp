// The two wire formats of live pose streams (docs/pose-wire-format.md):
//   1. pose lines: the trajectory CSV format of docs/trajectory-format.md sent
//      one line at a time (TCP, stdin), optionally opened by a
//      "# imuemu-pose-lines v1" version comment;
//   2. pose datagram v1: one pose per little-endian binary datagram (UDP),
//      sealed with a CRC-32C; v2 is v1 with optional velocity, angular rate
//      and acceleration appended (§2.5; a v2 reader reads both).
// Both decode into a TrajectoryRecord validated by the same rules as the
// trajectory file reader (io/trajectory_csv.hpp): finite values, latitude and
// pitch in [-90, 90] degrees, unit quaternion within kQuaternionNormTolerance
// (then normalised), no ECEF attitude with a local NED position.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>

#include "io/trajectory_csv.hpp"

namespace imuemu::io {

// ---------------------------------------------------------------- pose lines

// The optional first line of a pose line stream, "# imuemu-pose-lines v1".
inline constexpr std::string_view kPoseLinesTag = "# imuemu-pose-lines";
inline constexpr int kPoseLinesVersion = 1;
// Longest line a stream may send (bytes, without its '\n'); a longer one is
// refused (line_too_long) without being buffered. Real records are < 300.
inline constexpr std::size_t kMaxPoseLineBytes = 4096;

// Why a line was refused (docs/pose-wire-format.md §1.3).
enum class LineError : std::uint8_t {
  unsupported_version,  // "# imuemu-pose-lines vN" with N != 1, and every line after it
  bad_header,           // the trajectory CSV rules refuse the header (also data before a valid header)
  bad_record,           // the trajectory CSV rules refuse the data line
  line_too_long,        // more than kMaxPoseLineBytes before the '\n' (detected by the framer)
  unterminated_line,    // bytes without a final '\n' when the stream ended (framer)
};
inline constexpr std::size_t kLineErrorCount = 5;
std::string_view to_string(LineError error) noexcept;

// Decodes one pose line stream, line by line. One decoder per stream (per
// TCP connection): the header belongs to the stream.
class PoseLineDecoder {
 public:
  explicit PoseLineDecoder(std::string source_name);

  enum class Outcome {
    ignored,  // blank line, comment, version line or the accepted header
    record,   // `record` holds the validated record
    error,    // `error_message` says why (trajectory CSV messages, with line numbers)
  };
  // `line` without its '\n' (a trailing '\r' is ignored). Never throws
  // TrajectoryFormatError (errors come back); the stream goes on.
  Outcome decode(std::string_view line, TrajectoryRecord& record, LineError& error, std::string& error_message);

  // Counts a line the framer refused (line_too_long) without decoding it, so
  // the line numbers of later messages stay those of the stream.
  void skip_line();

  bool has_header() const noexcept { return parser_.has_header(); }
  std::size_t line_number() const noexcept { return line_number_; }  // lines decoded so far

 private:
  TrajectoryLineParser parser_;
  std::size_t line_number_ = 0;
  std::size_t refused_version_line_ = 0;  // != 0: the line that declared an unknown version
};

// ---------------------------------------------------------------- datagrams

inline constexpr std::array<std::uint8_t, 4> kPoseDatagramMagic = {'I', 'M', 'U', 'P'};
inline constexpr std::uint8_t kPoseDatagramVersion = 1;
inline constexpr std::size_t kPoseDatagramV1Size = 84;
// Offsets of the v1 fields (byte table in docs/pose-wire-format.md §2.1).
inline constexpr std::size_t kDatagramVersionOffset = 4;
inline constexpr std::size_t kDatagramPositionKindOffset = 5;
inline constexpr std::size_t kDatagramAttitudeKindOffset = 6;
inline constexpr std::size_t kDatagramReservedOffset = 7;
inline constexpr std::size_t kDatagramSequenceOffset = 8;
inline constexpr std::size_t kDatagramTimeOffset = 16;
inline constexpr std::size_t kDatagramPositionOffset = 24;
inline constexpr std::size_t kDatagramAttitudeOffset = 48;
inline constexpr std::size_t kDatagramCrcOffset = 80;
// Version 2 (docs/pose-wire-format.md §2.5): byte 7 is the rates mask, three
// vectors follow the attitude, the CRC moves to the end.
inline constexpr std::uint8_t kPoseDatagramVersion2 = 2;
inline constexpr std::size_t kPoseDatagramV2Size = 156;
inline constexpr std::size_t kDatagramRatesMaskOffset = 7;
inline constexpr std::size_t kDatagramVelocityOffset = 80;
inline constexpr std::size_t kDatagramAngularRateOffset = 104;
inline constexpr std::size_t kDatagramAccelerationOffset = 128;
inline constexpr std::size_t kDatagramV2CrcOffset = 152;
inline constexpr std::uint8_t kRatesVelocity = 0x01;
inline constexpr std::uint8_t kRatesAngularRate = 0x02;
inline constexpr std::uint8_t kRatesAcceleration = 0x04;

struct PoseDatagram {
  std::uint64_t sequence = 0;  // the sender's counter, +1 per datagram
  TrajectoryRecord record;     // record.line is 0
};

// Why a datagram was refused (docs/pose-wire-format.md §2.3), in the order the
// checks are made.
enum class DatagramError : std::uint8_t {
  too_short,            // fewer than the 5 bytes of magic and version
  bad_magic,            // not "IMUP"
  unsupported_version,  // version byte not 1 or 2
  bad_length,           // a v1 datagram must be exactly 84 bytes, a v2 one 156
  bad_checksum,         // CRC-32C mismatch (corrupted in transit)
  bad_kind,             // unknown position/attitude kind byte, or ECEF attitude with local NED position
  reserved_not_zero,    // reserved byte (v1) or unknown rates-mask bit (v2), the 4th attitude component of
                        // heading-pitch-roll, or an absent (mask bit clear) rate vector, not 0
  bad_value,            // not finite, out of range (latitude, pitch) or not a unit quaternion
};
inline constexpr std::size_t kDatagramErrorCount = 8;
std::string_view to_string(DatagramError error) noexcept;

// Physical bounds of the rates a live input may carry (pose datagram v2,
// MAVLink HIL_STATE_QUATERNION; docs/pose-wire-format.md §2.5). A value
// beyond them is no motion of anything and would only become the end slope
// of the causal method's cubics (core/causal_hermite.hpp), so it is refused
// at the door (bad_value), like a latitude beyond 90 deg:
//  - |angular rate| <= 1e4 rad/s (1600 rev/s, 5.7e5 deg/s): a spin-
//    stabilised shell turns at ~300 rev/s (1900 rad/s), the widest gyro
//    ranges are +-4000..+-20000 deg/s (70..350 rad/s);
//  - |velocity| <= 1e5 m/s: above Earth's escape speed (11.2 km/s) plus what
//    the ECEF frame's own rotation adds at the position bound of the
//    trajectory format (omega_ie * 1e9 m = 72.9 km/s);
//  - |acceleration| <= 1e6 m/s^2 (1e5 g): a gun launch is 1.5..3e4 g, shock
//    accelerometers are rated to 6e4 g.
inline constexpr double kMaxLiveAngularRate_rad_s = 1e4;
inline constexpr double kMaxLiveSpeed_m_s = 1e5;
inline constexpr double kMaxLiveAcceleration_m_s2 = 1e6;

struct DatagramDecodeError {
  DatagramError reason = DatagramError::too_short;
  std::string message;  // e.g. "position component 0 (lat_deg): expected a latitude in [-90, 90] degrees, got 91.5"
  // The checksum matched, so the datagram arrived intact and the sequence and
  // record.t_ns written to `out` are the sender's own (for loss statistics).
  bool intact = false;
};

// CRC-32C (Castagnoli: polynomial 0x1EDC6F41, reflected, init and final xor
// 0xFFFFFFFF; check value of "123456789" is 0xE3069283), via Boost.CRC.
std::uint32_t crc32c(std::span<const std::uint8_t> bytes) noexcept;

// Writes a v1 datagram. Does not validate (tests craft invalid ones on
// purpose); kinds are written as their enumerator index.
std::array<std::uint8_t, kPoseDatagramV1Size> encode_pose_datagram(const PoseDatagram& datagram) noexcept;

// Writes a v2 datagram: the rates present in d.record.rates are written and
// flagged in the mask, absent ones are zeros. Does not validate.
std::array<std::uint8_t, kPoseDatagramV2Size> encode_pose_datagram_v2(const PoseDatagram& datagram) noexcept;

// The rates of a decoded record against the bounds above (and finite): false
// with error (bad_value, intact, naming the field, its magnitude and the
// bound) for the first one beyond.
bool check_live_rates(const PoseRates& rates, DatagramDecodeError& error);

// Validates and decodes a datagram (v1 or v2). On failure returns false and fills
// `error`; `out` is then only meaningful as error.intact says.
bool decode_pose_datagram(std::span<const std::uint8_t> bytes, PoseDatagram& out, DatagramDecodeError& error);

}  // namespace imuemu::io
