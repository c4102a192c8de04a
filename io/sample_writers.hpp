// Output files of imuemu, written atomically (io/atomic_file.hpp), and their
// strict readers (for `imuemu verify` and for round-trip tests). Formats in
// docs/trajectory-format.md.
//
// Doubles are written with std::to_chars' shortest round-trip form, so reading
// a file back gives every value bit for bit. Non-finite values and
// non-increasing times are refused (std::invalid_argument) before anything
// reaches the target path: a refused run leaves no file behind.
#pragma once

#include <Eigen/Core>
#include <string>
#include <string_view>
#include <vector>

#include "core/trajectory.hpp"
#include "io/atomic_file.hpp"
#include "io/trajectory_csv.hpp"

namespace imuemu::io {

// Format errors of the IMU sample and kinematics files (see CsvFormatError).
class SampleFormatError : public CsvFormatError {
 public:
  using CsvFormatError::CsvFormatError;
};

// ------------------------------------------------------------ IMU samples

inline constexpr std::string_view kImuCsvHeader =
    "time_ns,gyro_x_rad_s,gyro_y_rad_s,gyro_z_rad_s,accel_x_m_s2,accel_y_m_s2,accel_z_m_s2";

// Longest text write_imu_csv_fields writes: an int64 (20 chars), six
// doubles in their shortest round-trip form (at most 24 chars each) and six
// commas.
inline constexpr std::size_t kMaxImuCsvFieldsChars = 20 + 6 * 24 + 6;

// The seven fields of one row of kImuCsvHeader, "time_ns,gyro_x,...,accel_z",
// written at `out` (room for kMaxImuCsvFieldsChars) in the file's form:
// integer ns and std::to_chars' shortest round-trip doubles. No newline; the
// values are not checked. Returns the end of what was written. Every writer
// of IMU rows (the file writer below, `imuemu stream`) goes through it, so
// they write the same bytes for the same sample.
char* write_imu_csv_fields(char* out, const ImuSample& sample) noexcept;

// Streaming writer: one row per write(), header first. Nothing appears at
// `path` until commit(); destroying an uncommitted writer leaves no file.
class ImuCsvWriter {
 public:
  explicit ImuCsvWriter(const std::string& path);
  // Throws std::invalid_argument for a non-finite value or a time not after
  // the previous sample's.
  void write(const ImuSample& sample);
  // Throws std::invalid_argument if no sample was written (an empty sample
  // file is never valid), std::system_error on I/O errors.
  void commit();
  std::size_t count() const noexcept { return count_; }

 private:
  AtomicFileWriter file_;
  std::size_t count_ = 0;
  TimeNs previous_ns_ = 0;
};

void write_imu_csv(const std::string& path, const std::vector<ImuSample>& samples);

// Strict reader: header with exactly the seven columns of kImuCsvHeader (any
// order), integer time_ns strictly increasing, finite values, at least one
// row; '#' comments and blank lines are allowed as in trajectory files.
// Throws SampleFormatError (file, line, column, expected).
std::vector<ImuSample> read_imu_csv(const std::string& path);
std::vector<ImuSample> parse_imu_csv(std::string_view text, const std::string& source_name);

// ------------------------------------------------- smoothed trajectory

// Header of the kinematics file of each scene:
//  ecef: time_s,x_m,y_m,z_m,qw_ecef,qx_ecef,qy_ecef,qz_ecef,vx_m_s,vy_m_s,vz_m_s,
//        ax_m_s2,ay_m_s2,az_m_s2,wx_rad_s,wy_rad_s,wz_rad_s
//  flat: time_s,north_m,east_m,down_m,qw,qx,qy,qz,vx_m_s,...   (same tail)
// The quaternion is that of Kinematics::attitude = R_b^frame (w >= 0):
// q_b^e in the ecef scene (hence the _ecef names), q_b^n = q_b^l in the flat
// one. v and a are in frame axes, w = omega_{frame,b}^b in body axes.
// The file is also a valid trajectory input for
// read_trajectory_csv(path, {.allow_extra_columns = true}).
std::string kinematics_csv_header(Physics physics);

// Streaming writer of the kinematics file: header first, one row per
// write(). Nothing appears at `path` until commit(); destroying an
// uncommitted writer leaves no file.
class KinematicsCsvWriter {
 public:
  KinematicsCsvWriter(const std::string& path, Physics physics);
  // Throws std::invalid_argument (naming the state's index and field) for a
  // non-finite value, an attitude that is not a rotation (|R^T R - I| > 1e-6
  // or det < 0) or a time not after the previous state's; nothing is written
  // then.
  void write(const Kinematics& state);
  // Throws std::invalid_argument if no state was written, std::system_error
  // on I/O errors.
  void commit();
  std::size_t count() const noexcept { return count_; }

 private:
  AtomicFileWriter file_;
  std::size_t count_ = 0;
  TimeNs previous_ns_ = 0;
};

// Throws std::invalid_argument (naming the state's index and field) for an
// empty vector, a non-finite value, an attitude that is not a rotation
// (|R^T R - I| > 1e-6 or det < 0) or non-increasing times, before creating
// any file.
void write_trajectory_csv(const std::string& path, const std::vector<Kinematics>& states,
                          Physics physics);

struct KinematicsTrajectory {
  Physics physics = Physics::flat;  // from the position columns
  std::vector<Kinematics> states;
  // The file's quaternions (w, x, y, z), normalised; states[i].attitude is
  // so3::matrix_from_quaternion(quaternions[i]).
  std::vector<Eigen::Vector4d> quaternions;
};

// Strict reader of write_trajectory_csv's output (exact header column set of
// one scene, any order). Throws SampleFormatError.
KinematicsTrajectory read_kinematics_csv(const std::string& path);
KinematicsTrajectory parse_kinematics_csv(std::string_view text, const std::string& source_name);

}  // namespace imuemu::io
