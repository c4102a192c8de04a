// Reader of the trajectory CSV format documented in docs/trajectory-format.md.
//
// The io room only reads: records come back in the file's own units and
// parametrisation (degrees, metres, heading-pitch-roll or quaternion), with the
// one exception that quaternions are normalised. Converting them to the scene
// frame (thesis §1.3, Eq. 1.1-1.5) is core/attitude and core/earth's job.
//
// Every malformed input is reported as a TrajectoryFormatError naming the file,
// the 1-based line, the column (header name and 1-based index) and what was
// expected, e.g.
//   traj.csv:17: column 'lat_deg' (3): expected a latitude in [-90, 90] degrees, got '91.5'
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "core/types.hpp"

namespace imuemu::io {

// Where a CSV problem is. line == 0: the file as a whole (missing, empty);
// column_index == 0: the line as a whole (wrong number of fields, ...).
struct CsvLocation {
  std::string file;
  std::size_t line = 0;
  std::string column;          // header name of the column
  std::size_t column_index = 0;  // 1-based
};

// Base of the format errors of every CSV file imuemu reads.
// what() = "<file>[:<line>][: column '<name>' (<index>)]: <detail>".
class CsvFormatError : public std::runtime_error {
 public:
  // expected: what the reader wanted there ("a latitude in [-90, 90] degrees");
  // detail: the sentence after the location ("expected ..., got '91.5'").
  CsvFormatError(CsvLocation where, std::string expected, std::string detail);

  const std::string& file() const noexcept { return where_.file; }
  std::size_t line() const noexcept { return where_.line; }
  const std::string& column() const noexcept { return where_.column; }
  std::size_t column_index() const noexcept { return where_.column_index; }
  const std::string& expected() const noexcept { return expected_; }
  const std::string& detail() const noexcept { return detail_; }

 private:
  CsvLocation where_;
  std::string expected_;
  std::string detail_;
};

class TrajectoryFormatError : public CsvFormatError {
 public:
  using CsvFormatError::CsvFormatError;
};

enum class PositionKind {
  geodetic,   // lat_deg, lon_deg, h_m: WGS84 latitude, longitude (deg), ellipsoidal height (m)
  ecef,       // x_m, y_m, z_m: WGS84 ECEF (m)
  local_ned,  // north_m, east_m, down_m: a fixed local NED frame (m)
};

enum class AttitudeKind {
  // heading_deg, pitch_deg, roll_deg: Tait-Bryan z-y-x of R_b^l, body FRD to
  // local NED (thesis Eq. 1.2); attitude = (heading, pitch, roll, 0) in degrees.
  heading_pitch_roll,
  // qw, qx, qy, qz: unit quaternion q_b^l, body FRD to local NED, Hamilton,
  // R_b^l = transpose of the thesis' Eq. 1.3 matrix; attitude = (w, x, y, z).
  quaternion,
  // qw_ecef, qx_ecef, qy_ecef, qz_ecef: unit quaternion q_b^e, body FRD to
  // ECEF (R_b^e of Eq. 1.4); attitude = (w, x, y, z). Needs an Earth-fixed
  // position (geodetic or ecef). Written by write_trajectory_csv for the ecef
  // scene, whose attitude is R_b^e.
  quaternion_ecef,
};

std::string_view to_string(PositionKind kind) noexcept;
std::string_view to_string(AttitudeKind kind) noexcept;

struct TrajectoryRecord {
  TimeNs t_ns = 0;
  PositionKind position_kind = PositionKind::geodetic;
  Vec3 position = Vec3::Zero();  // as in the file: (lat deg, lon deg, h m) or metres
  AttitudeKind attitude_kind = AttitudeKind::heading_pitch_roll;
  // hpr: (heading, pitch, roll, 0) in degrees; quaternions: (w, x, y, z), unit.
  Eigen::Vector4d attitude = Eigen::Vector4d::Zero();
  std::size_t line = 0;  // 1-based line of the file the record came from
};

struct Trajectory {
  std::string source;  // file name (or the source_name given to the parser)
  PositionKind position_kind = PositionKind::geodetic;
  AttitudeKind attitude_kind = AttitudeKind::heading_pitch_roll;
  std::vector<TrajectoryRecord> records;  // at least one; times strictly increasing
};

// A quaternion whose norm differs from 1 by more than this is refused; within
// it, the quaternion is normalised (rounding in whatever wrote the file).
inline constexpr double kQuaternionNormTolerance = 1e-6;

struct TrajectoryReadOptions {
  // Ignore columns the format does not know (their fields are not even
  // parsed, but each row must still have one field per header column).
  // Off by default so a typo in a column name is an error, not a silent loss.
  bool allow_extra_columns = false;
};

// Reads and validates a whole trajectory file. Throws TrajectoryFormatError
// (including for a missing or unreadable file, with line() == 0).
Trajectory read_trajectory_csv(const std::string& path, const TrajectoryReadOptions& options = {});

// Same, for text already in memory; source_name is used in messages.
Trajectory parse_trajectory_csv(std::string_view text, const std::string& source_name,
                                const TrajectoryReadOptions& options = {});

namespace detail {

// Line and field splitter shared by the CSV readers: skips a UTF-8 byte order
// mark, blank lines and lines whose first non-blank character is '#'; splits
// the others on ',' and trims spaces, tabs and a trailing '\r' around fields.
class CsvLineReader {
 public:
  explicit CsvLineReader(std::string_view text) noexcept;
  // Moves to the next non-blank, non-comment line; false at the end of text.
  bool next();
  std::size_t line_number() const noexcept { return line_number_; }  // 1-based
  const std::vector<std::string_view>& fields() const noexcept { return fields_; }

 private:
  std::string_view text_;
  std::size_t pos_ = 0;
  std::size_t line_number_ = 0;
  std::vector<std::string_view> fields_;
};

// A field as shown in messages: printable ASCII kept, other bytes as \xNN,
// cut after 40 characters.
std::string printable(std::string_view field);

// Shortest round-trip decimal of a double (std::to_chars).
std::string format_double(double value);

// Number of '\n' in text (to reserve record vectors before parsing).
std::size_t count_lines(std::string_view text) noexcept;

}  // namespace detail

}  // namespace imuemu::io
