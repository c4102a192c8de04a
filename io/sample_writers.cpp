#include "io/sample_writers.hpp"

#include <array>
#include <charconv>
#include <cmath>
#include <stdexcept>
#include <system_error>

#include "core/so3.hpp"
#include "io/decimal_time.hpp"

namespace imuemu::io {
namespace {

// ---------------------------------------------------------------- writing

// Appends the shortest round-trip form of v (caller guarantees room).
char* put_double(char* out, double v) {
  return std::to_chars(out, out + 24, v).ptr;  // the shortest form of a double is at most 24 chars
}

char* put_int64(char* out, std::int64_t v) { return std::to_chars(out, out + 24, v).ptr; }

std::string describe_time(TimeNs t_ns) { return format_decimal_seconds(t_ns) + " s"; }

void require_finite(const char* who, std::size_t index, TimeNs t_ns, const char* field,
                    const Vec3& v) {
  for (int k = 0; k < 3; ++k) {
    if (!std::isfinite(v[k])) {
      throw std::invalid_argument(std::string(who) + ": sample " + std::to_string(index) + " (t = " +
                                  describe_time(t_ns) + "): " + field + " component " +
                                  std::to_string(k) + " is " + detail::format_double(v[k]) +
                                  "; refusing to write a non-finite value");
    }
  }
}

void require_increasing(const char* who, std::size_t index, TimeNs previous_ns, TimeNs t_ns) {
  if (index > 0 && t_ns <= previous_ns) {
    throw std::invalid_argument(std::string(who) + ": sample " + std::to_string(index) + " time " +
                                describe_time(t_ns) + " is not after the previous sample's " +
                                describe_time(previous_ns));
  }
}

// ---------------------------------------------------------------- reading

[[noreturn]] void fail_sample_csv(const std::string& file, std::size_t line, std::string column,
                       std::size_t column_index, std::string expected, std::string detail) {
  throw SampleFormatError(CsvLocation{file, line, std::move(column), column_index},
                          std::move(expected), std::move(detail));
}

std::string join(const std::vector<std::string_view>& names) {
  std::string out;
  for (const std::string_view name : names) {
    if (!out.empty()) out += ",";
    out += name;
  }
  return out;
}

// For each header column, the index of its name in `schema`. Every schema
// name must appear exactly once and nothing else may.
std::vector<std::size_t> map_header(const std::vector<std::string_view>& fields, std::size_t line,
                                    const std::string& file,
                                    const std::vector<std::string_view>& schema) {
  const std::string expected = "the columns " + join(schema) + " (any order)";
  std::vector<std::size_t> map(fields.size());
  std::vector<std::size_t> seen_at(schema.size(), 0);
  for (std::size_t i = 0; i < fields.size(); ++i) {
    std::size_t k = 0;
    while (k < schema.size() && schema[k] != fields[i]) ++k;
    if (k == schema.size()) {
      fail_sample_csv(file, line, std::string(fields[i]), i + 1, expected,
           "unknown column name; expected " + expected);
    }
    if (seen_at[k] != 0) {
      fail_sample_csv(file, line, std::string(fields[i]), i + 1, expected,
           "duplicate column (also column " + std::to_string(seen_at[k]) + ")");
    }
    seen_at[k] = i + 1;
    map[i] = k;
  }
  for (std::size_t k = 0; k < schema.size(); ++k) {
    if (seen_at[k] == 0) {
      fail_sample_csv(file, line, "", 0, expected,
           "missing column '" + std::string(schema[k]) + "'; expected " + expected);
    }
  }
  return map;
}

void check_width(const std::vector<std::string_view>& fields, std::size_t width, std::size_t line,
                 std::size_t header_line, const std::string& file) {
  if (fields.size() != width) {
    fail_sample_csv(file, line, "", 0, std::to_string(width) + " fields",
         "expected " + std::to_string(width) + " comma-separated fields as named by the header (line " +
             std::to_string(header_line) + "), got " + std::to_string(fields.size()));
  }
}

double field_double(std::string_view field, const std::string& file, std::size_t line,
                    std::string_view column, std::size_t column_index) {
  const DoubleParse v = try_parse_double(field);
  if (v.status != NumberStatus::ok) {
    fail_sample_csv(file, line, std::string(column), column_index, "a finite number",
         "expected a finite number, got '" + detail::printable(field) + "' (" +
             std::string(describe(v.status)) + ")");
  }
  return v.value;
}

void header_or_fail(detail::CsvLineReader& reader, const std::string& file) {
  if (!reader.next()) {
    fail_sample_csv(file, 0, "", 0, "a header row",
         "no header row: the file is empty or holds only comments and blank lines");
  }
}

[[noreturn]] void fail_time_order(const std::string& file, std::size_t line, std::string_view column,
                                  std::size_t column_index, std::string_view unit,
                                  std::string_view now_text, std::string_view previous_text,
                                  std::size_t previous_line) {
  fail_sample_csv(file, line, std::string(column), column_index, "a time after the previous record's",
       "time " + detail::printable(now_text) + std::string(unit) + " is not after the previous record's " +
           detail::printable(previous_text) + std::string(unit) + " (line " + std::to_string(previous_line) +
           ")");
}

std::string read_or_fail(const std::string& path, std::string_view what) {
  std::string text;
  if (const int error = read_whole_file(path, text); error != 0) {
    fail_sample_csv(path, 0, "", 0, "a readable file",
         "cannot read the " + std::string(what) + ": " + std::generic_category().message(error));
  }
  return text;
}

const std::vector<std::string_view> kImuColumns{"time_ns",      "gyro_x_rad_s", "gyro_y_rad_s",
                                                "gyro_z_rad_s", "accel_x_m_s2", "accel_y_m_s2",
                                                "accel_z_m_s2"};

// Kinematics columns; index 0 is time, 1-3 position, 4-7 quaternion, then
// velocity, acceleration, angular rate.
const std::vector<std::string_view> kKinematicsEcef{
    "time_s",  "x_m",     "y_m",     "z_m",     "qw_ecef",  "qx_ecef",  "qy_ecef",  "qz_ecef", "vx_m_s",
    "vy_m_s",  "vz_m_s",  "ax_m_s2", "ay_m_s2", "az_m_s2",  "wx_rad_s", "wy_rad_s", "wz_rad_s"};
const std::vector<std::string_view> kKinematicsFlat{
    "time_s",  "north_m", "east_m",  "down_m",  "qw",       "qx",       "qy",       "qz",      "vx_m_s",
    "vy_m_s",  "vz_m_s",  "ax_m_s2", "ay_m_s2", "az_m_s2",  "wx_rad_s", "wy_rad_s", "wz_rad_s"};

const std::vector<std::string_view>& kinematics_schema(Physics physics) {
  return physics == Physics::ecef ? kKinematicsEcef : kKinematicsFlat;
}

}  // namespace

// ------------------------------------------------------------ IMU samples

char* write_imu_csv_fields(char* out, const ImuSample& sample) noexcept {
  char* p = put_int64(out, sample.t_ns);
  for (int k = 0; k < 3; ++k) {
    *p++ = ',';
    p = put_double(p, sample.gyro_rad_s[k]);
  }
  for (int k = 0; k < 3; ++k) {
    *p++ = ',';
    p = put_double(p, sample.accel_m_s2[k]);
  }
  return p;
}

ImuCsvWriter::ImuCsvWriter(const std::string& path) : file_(path) {
  file_.write(kImuCsvHeader);
  file_.write("\n");
}

void ImuCsvWriter::write(const ImuSample& sample) {
  static constexpr const char* kWho = "write_imu_csv";
  require_increasing(kWho, count_, previous_ns_, sample.t_ns);
  require_finite(kWho, count_, sample.t_ns, "gyro_rad_s", sample.gyro_rad_s);
  require_finite(kWho, count_, sample.t_ns, "accel_m_s2", sample.accel_m_s2);
  char row[kMaxImuCsvFieldsChars + 1];
  char* p = write_imu_csv_fields(row, sample);
  *p++ = '\n';
  file_.write(std::string_view(row, static_cast<std::size_t>(p - row)));
  previous_ns_ = sample.t_ns;
  ++count_;
}

void ImuCsvWriter::commit() {
  if (count_ == 0) {
    throw std::invalid_argument("write_imu_csv: no samples to write to '" + file_.target_path() + "'");
  }
  file_.commit();
}

void write_imu_csv(const std::string& path, const std::vector<ImuSample>& samples) {
  if (samples.empty()) throw std::invalid_argument("write_imu_csv: no samples to write to '" + path + "'");
  ImuCsvWriter writer(path);
  for (const ImuSample& s : samples) writer.write(s);
  writer.commit();
}

std::vector<ImuSample> parse_imu_csv(std::string_view text, const std::string& source_name) {
  const std::string& file = source_name;
  detail::CsvLineReader reader(text);
  header_or_fail(reader, file);
  const std::size_t header_line = reader.line_number();
  const std::vector<std::size_t> map = map_header(reader.fields(), header_line, file, kImuColumns);
  const std::size_t width = map.size();

  std::vector<ImuSample> samples;
  samples.reserve(detail::count_lines(text));
  std::string_view previous_text;
  std::size_t previous_line = 0;
  while (reader.next()) {
    const std::vector<std::string_view>& fields = reader.fields();
    const std::size_t line = reader.line_number();
    check_width(fields, width, line, header_line, file);
    ImuSample s;
    std::size_t time_column = 0;
    for (std::size_t i = 0; i < width; ++i) {
      const std::size_t k = map[i];
      if (k == 0) {
        const Int64Parse t = try_parse_int64(fields[i]);
        if (t.status != NumberStatus::ok) {
          fail_sample_csv(file, line, "time_ns", i + 1, "an integer time in nanoseconds",
               "expected an integer time in nanoseconds, got '" + detail::printable(fields[i]) + "' (" +
                   std::string(describe(t.status)) + ")");
        }
        s.t_ns = t.value;
        time_column = i;
      } else {
        const double v = field_double(fields[i], file, line, kImuColumns[k], i + 1);
        if (k <= 3) {
          s.gyro_rad_s[static_cast<Eigen::Index>(k - 1)] = v;
        } else {
          s.accel_m_s2[static_cast<Eigen::Index>(k - 4)] = v;
        }
      }
    }
    if (!samples.empty() && s.t_ns <= samples.back().t_ns) {
      fail_time_order(file, line, "time_ns", time_column + 1, " ns", fields[time_column], previous_text,
                      previous_line);
    }
    previous_text = fields[time_column];
    previous_line = line;
    samples.push_back(s);
  }
  if (samples.empty()) {
    fail_sample_csv(file, 0, "", 0, "at least one sample",
         "no samples after the header (line " + std::to_string(header_line) + ")");
  }
  return samples;
}

std::vector<ImuSample> read_imu_csv(const std::string& path) {
  const std::string text = read_or_fail(path, "IMU sample file");
  return parse_imu_csv(text, path);
}

// ------------------------------------------------- smoothed trajectory

std::string kinematics_csv_header(Physics physics) { return join(kinematics_schema(physics)); }

namespace {

constexpr const char* kKinematicsWho = "write_trajectory_csv";

// Every rule a kinematics row must meet (index: the state's index, for messages).
void check_state(std::size_t index, TimeNs previous_ns, const Kinematics& s) {
  require_increasing(kKinematicsWho, index, previous_ns, s.t_ns);
  require_finite(kKinematicsWho, index, s.t_ns, "position_m", s.position_m);
  require_finite(kKinematicsWho, index, s.t_ns, "velocity_m_s", s.velocity_m_s);
  require_finite(kKinematicsWho, index, s.t_ns, "acceleration_m_s2", s.acceleration_m_s2);
  require_finite(kKinematicsWho, index, s.t_ns, "angular_rate_rad_s", s.angular_rate_rad_s);
  // The quaternion only means something for a rotation matrix; the reader
  // accepts |q| within 1e-6 of 1, so the matrix must be that close to SO(3).
  const bool finite = s.attitude.allFinite();
  const double orthogonality =
      finite ? (s.attitude.transpose() * s.attitude - Mat3::Identity()).cwiseAbs().maxCoeff() : 0.0;
  if (!finite || orthogonality > 1e-6 || s.attitude.determinant() <= 0.0) {
    throw std::invalid_argument(std::string(kKinematicsWho) + ": sample " + std::to_string(index) + " (t = " +
                                describe_time(s.t_ns) +
                                "): attitude is not a rotation matrix (non-finite, |R^T R - I| = " +
                                detail::format_double(orthogonality) + " > 1e-6, or det <= 0)");
  }
}

// One row of a state already checked.
void put_state_row(AtomicFileWriter& file, const Kinematics& s) {
  char row[512];  // 1 time (<= 21) + 16 doubles (<= 24 each) + separators
  char* p = write_decimal_seconds(row, s.t_ns);
  const Eigen::Vector4d q = so3::quaternion_from_matrix(s.attitude);
  const auto put3 = [&p](const Vec3& v) {
    for (int k = 0; k < 3; ++k) {
      *p++ = ',';
      p = put_double(p, v[k]);
    }
  };
  put3(s.position_m);
  for (int k = 0; k < 4; ++k) {
    *p++ = ',';
    p = put_double(p, q[k]);
  }
  put3(s.velocity_m_s);
  put3(s.acceleration_m_s2);
  put3(s.angular_rate_rad_s);
  *p++ = '\n';
  file.write(std::string_view(row, static_cast<std::size_t>(p - row)));
}

}  // namespace

KinematicsCsvWriter::KinematicsCsvWriter(const std::string& path, Physics physics) : file_(path) {
  file_.write(kinematics_csv_header(physics));
  file_.write("\n");
}

void KinematicsCsvWriter::write(const Kinematics& state) {
  check_state(count_, previous_ns_, state);
  put_state_row(file_, state);
  previous_ns_ = state.t_ns;
  ++count_;
}

void KinematicsCsvWriter::commit() {
  if (count_ == 0)
    throw std::invalid_argument(std::string(kKinematicsWho) + ": no states to write to '" + file_.target_path() + "'");
  file_.commit();
}

void write_trajectory_csv(const std::string& path, const std::vector<Kinematics>& states,
                          Physics physics) {
  if (states.empty()) throw std::invalid_argument(std::string(kKinematicsWho) + ": no states to write to '" + path + "'");
  // Validate everything first: a refused run must not even create the
  // temporary file.
  for (std::size_t i = 0; i < states.size(); ++i) check_state(i, i > 0 ? states[i - 1].t_ns : 0, states[i]);
  AtomicFileWriter file(path);
  file.write(kinematics_csv_header(physics));
  file.write("\n");
  for (const Kinematics& s : states) put_state_row(file, s);
  file.commit();
}

KinematicsTrajectory parse_kinematics_csv(std::string_view text, const std::string& source_name) {
  const std::string& file = source_name;
  detail::CsvLineReader reader(text);
  header_or_fail(reader, file);
  const std::size_t header_line = reader.line_number();
  KinematicsTrajectory out;
  // The position columns name the scene; map_header then insists on the rest.
  out.physics = Physics::flat;
  for (const std::string_view name : reader.fields()) {
    if (name == "x_m") out.physics = Physics::ecef;
  }
  const std::vector<std::string_view>& schema = kinematics_schema(out.physics);
  const std::vector<std::size_t> map = map_header(reader.fields(), header_line, file, schema);
  const std::size_t width = map.size();
  std::size_t qw_column = 0;
  for (std::size_t i = 0; i < width; ++i) {
    if (map[i] == 4) qw_column = i;
  }

  const std::size_t expected_rows = detail::count_lines(text);
  out.states.reserve(expected_rows);
  out.quaternions.reserve(expected_rows);
  std::string_view previous_text;
  std::size_t previous_line = 0;
  std::array<double, 17> values{};
  while (reader.next()) {
    const std::vector<std::string_view>& fields = reader.fields();
    const std::size_t line = reader.line_number();
    check_width(fields, width, line, header_line, file);
    Kinematics s;
    std::size_t time_column = 0;
    for (std::size_t i = 0; i < width; ++i) {
      const std::size_t k = map[i];
      if (k == 0) {
        const TimeParse t = try_parse_decimal_seconds(fields[i]);
        if (t.status != NumberStatus::ok) {
          fail_sample_csv(file, line, "time_s", i + 1, "a time in decimal seconds",
               "expected a time in decimal seconds, got '" + detail::printable(fields[i]) + "' (" +
                   std::string(describe(t.status)) + ")");
        }
        s.t_ns = t.ns;
        time_column = i;
      } else {
        values[k] = field_double(fields[i], file, line, schema[k], i + 1);
      }
    }
    if (!out.states.empty() && s.t_ns <= out.states.back().t_ns) {
      fail_time_order(file, line, "time_s", time_column + 1, " s", fields[time_column], previous_text,
                      previous_line);
    }
    Eigen::Vector4d q(values[4], values[5], values[6], values[7]);
    const double norm = q.norm();
    if (!(std::abs(norm - 1.0) <= kQuaternionNormTolerance)) {
      fail_sample_csv(file, line, std::string(schema[4]), qw_column + 1, "a unit quaternion",
           "expected a unit quaternion (|q| within 1e-6 of 1), got |q| = " + detail::format_double(norm));
    }
    q /= norm;
    s.position_m = Vec3(values[1], values[2], values[3]);
    s.attitude = so3::matrix_from_quaternion(q);
    s.velocity_m_s = Vec3(values[8], values[9], values[10]);
    s.acceleration_m_s2 = Vec3(values[11], values[12], values[13]);
    s.angular_rate_rad_s = Vec3(values[14], values[15], values[16]);
    previous_text = fields[time_column];
    previous_line = line;
    out.states.push_back(s);
    out.quaternions.push_back(q);
  }
  if (out.states.empty()) {
    fail_sample_csv(file, 0, "", 0, "at least one state",
         "no records after the header (line " + std::to_string(header_line) + ")");
  }
  return out;
}

KinematicsTrajectory read_kinematics_csv(const std::string& path) {
  const std::string text = read_or_fail(path, "trajectory file");
  return parse_kinematics_csv(text, path);
}

}  // namespace imuemu::io
