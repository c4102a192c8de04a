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
#include <memory>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "core/pose_rates.hpp"
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
  // Optional derivatives (live inputs only: pose datagram v2, MAVLink
  // HIL_STATE_QUATERNION; docs/pose-wire-format.md §2.5). Velocity and
  // acceleration in the position kind's frame (geodetic: local NED at the
  // record's position; ECEF; local NED), angular rate relative to the
  // attitude's reference frame (local NED for heading-pitch-roll and q_b^l,
  // ECEF for q_b^e), body FRD axes. Files and pose lines carry none.
  PoseRates rates;
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

// ---------------------------------------------------------------- value rules
// One implementation of the per-value rules of docs/trajectory-format.md,
// shared by every pose input: trajectory files, pose line streams and pose
// datagrams (docs/pose-wire-format.md).

// What one column accepts: its header name, the phrase used in messages and
// the inclusive range of valid values (every value must also be finite).
struct ColumnRule {
  std::string_view name;
  std::string_view expected;
  double min = 0.0;
  double max = 0.0;
};

// Rule of position component `component` (0..2) of a record of that kind.
const ColumnRule& position_column_rule(PositionKind kind, int component) noexcept;
// Rule of attitude component `component` (0..2 for heading-pitch-roll, 0..3
// for the quaternions) of a record of that kind.
const ColumnRule& attitude_column_rule(AttitudeKind kind, int component) noexcept;
// 3 for heading-pitch-roll (the 4th record component is 0), 4 for quaternions.
int attitude_component_count(AttitudeKind kind) noexcept;
// False for the one combination without meaning: an ECEF attitude
// (quaternion_ecef) with a local NED position.
bool kinds_compatible(PositionKind position, AttitudeKind attitude) noexcept;
// The unit-quaternion rule: sets `norm` to |q|; if it is within
// kQuaternionNormTolerance of 1, divides q by it and returns true, otherwise
// leaves q alone and returns false (also for an overflowing norm).
bool normalise_unit_quaternion(Eigen::Vector4d& q, double& norm) noexcept;

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

// The reader one line at a time, for pose line streams (docs/pose-wire-format.md):
// the header line, then record lines. parse_trajectory_csv is built on it, so
// files and streams share one implementation of the header and record rules.
// Unlike the file reader it does not require increasing times: the order of a
// live stream is judged by the pose source (io/pose_source.hpp).
class TrajectoryLineParser {
 public:
  explicit TrajectoryLineParser(std::string source_name, TrajectoryReadOptions options = {});
  ~TrajectoryLineParser();
  TrajectoryLineParser(TrajectoryLineParser&&) noexcept;
  TrajectoryLineParser& operator=(TrajectoryLineParser&&) noexcept;

  enum class LineKind {
    skipped,  // blank or comment line
    header,   // the header line, accepted
    record,   // a data line: the record was written to `out`
  };

  // Feeds the next physical line (without its '\n'; a trailing '\r' is
  // trimmed); every call counts one line for the line numbers in messages.
  // A UTF-8 byte order mark is skipped on the first line. Throws
  // TrajectoryFormatError: for a refused header the parser still waits for
  // a header (the next non-comment line is tried as one); for a refused
  // record the next line is parsed normally.
  LineKind feed(std::string_view line, TrajectoryRecord& out);

  // The record before, for the file reader's strictly-increasing-time rule.
  struct Predecessor {
    TimeNs t_ns = 0;
    std::string_view time_text;  // as written, for the message
    std::size_t line = 0;
  };
  // The two steps of feed() on fields already split by detail::CsvLineReader,
  // at the given line number. parse_record needs has_header(); with a
  // predecessor it also refuses a time that is not after it.
  void parse_header(const std::vector<std::string_view>& fields, std::size_t line);
  void parse_record(const std::vector<std::string_view>& fields, std::size_t line, TrajectoryRecord& out,
                    const Predecessor* predecessor = nullptr) const;

  bool has_header() const noexcept { return layout_ != nullptr; }
  // The following need has_header().
  std::size_t header_line() const noexcept;
  PositionKind position_kind() const noexcept;
  AttitudeKind attitude_kind() const noexcept;
  std::size_t time_column() const noexcept;  // 0-based index of time_s
  std::size_t line_number() const noexcept { return line_number_; }  // lines fed so far
  const std::string& source_name() const noexcept { return source_name_; }

 private:
  struct Layout;
  std::string source_name_;
  TrajectoryReadOptions options_;
  std::unique_ptr<Layout> layout_;
  std::size_t line_number_ = 0;
  std::vector<std::string_view> fields_;  // reused by feed()
};

namespace detail {

// Splits one line (without '\n') on ',' into `fields`, trimming spaces, tabs
// and a trailing '\r' around each. Returns false (fields untouched) for a
// blank line or one whose first non-blank character is '#'.
bool split_csv_line(std::string_view line, std::vector<std::string_view>& fields);

// Line and field splitter shared by the CSV readers: skips a UTF-8 byte order
// mark, blank lines and lines whose first non-blank character is '#'; splits
// the others with split_csv_line.
class CsvLineReader {
 public:
  explicit CsvLineReader(std::string_view text) noexcept;
  // Moves to the next non-blank, non-comment line; false at the end of text.
  bool next();
  std::size_t line_number() const noexcept { return line_number_; }  // 1-based
  const std::vector<std::string_view>& fields() const noexcept { return fields_; }
  // The current line is the last and has no final '\n' (a file cut off, or
  // still being written).
  bool unterminated() const noexcept { return unterminated_; }

 private:
  std::string_view text_;
  bool unterminated_ = false;
  std::size_t pos_ = 0;
  std::size_t line_number_ = 0;
  std::vector<std::string_view> fields_;
};

// A field as shown in messages: printable ASCII kept, other bytes as \xNN,
// cut after 40 characters.
std::string printable(std::string_view field);

// Shortest round-trip decimal of a double (std::to_chars).
std::string format_double(double value);

// Number of lines holding data (not blank, not a '#' comment): an upper bound
// on the records of the text, to reserve record vectors before parsing.
std::size_t count_lines(std::string_view text) noexcept;

}  // namespace detail

}  // namespace imuemu::io
