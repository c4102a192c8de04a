// Tests of the io room: exact decimal times, the trajectory CSV reader and its
// error messages, the atomic writer and the sample/trajectory writers.
#include <dirent.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <charconv>
#include <chrono>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <cstring>
#include <fstream>
#include <iostream>
#include <limits>
#include <random>
#include <string>
#include <system_error>
#include <vector>

#include "core/limits.hpp"
#include "core/so3.hpp"
#include "io/atomic_file.hpp"
#include "io/decimal_time.hpp"
#include "io/sample_writers.hpp"
#include "io/trajectory_csv.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace imuemu::io {}
namespace unity_io_test_io {
namespace imuemu { using namespace ::imuemu; }
namespace imuemu::io { using namespace ::imuemu::io; }

namespace imuemu::io {
namespace {

// 128-bit integers for independent reference arithmetic (a GCC/Clang
// extension; __extension__ keeps -Wpedantic quiet).
__extension__ typedef __int128 Int128;
__extension__ typedef unsigned __int128 UInt128;

constexpr std::int64_t kInt64Max = std::numeric_limits<std::int64_t>::max();
constexpr std::int64_t kInt64Min = std::numeric_limits<std::int64_t>::min();

// ---------------------------------------------------------------- helpers

// A fresh directory per test, removed (with its files) at the end.
class TempDir {
 public:
  TempDir() {
    char name[] = "/tmp/imuemu_test_io.XXXXXX";
    const char* made = ::mkdtemp(name);
    if (made == nullptr) throw std::runtime_error("mkdtemp failed");
    path_ = made;
  }
  ~TempDir() {
    for (const std::string& f : files()) ::unlink((path_ + "/" + f).c_str());
    ::rmdir(path_.c_str());
  }
  std::string file(const std::string& name) const { return path_ + "/" + name; }
  std::vector<std::string> files() const {
    std::vector<std::string> out;
    if (DIR* d = ::opendir(path_.c_str())) {
      while (const dirent* e = ::readdir(d)) {
        const std::string n = e->d_name;
        if (n != "." && n != "..") out.push_back(n);
      }
      ::closedir(d);
    }
    return out;
  }

 private:
  std::string path_;
};

bool exists(const std::string& path) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0;
}

std::string slurp(const std::string& path) {
  std::string text;
  EXPECT_EQ(read_whole_file(path, text), 0) << path;
  return text;
}

void spit(const std::string& path, const std::string& text) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  ASSERT_NE(f, nullptr);
  ASSERT_EQ(std::fwrite(text.data(), 1, text.size(), f), text.size());
  std::fclose(f);
}

std::uint64_t bits(double v) { return std::bit_cast<std::uint64_t>(v); }

// Parses text and returns the error; fails the test if it parses.
TrajectoryFormatError parse_error(const std::string& text, const TrajectoryReadOptions& options = {}) {
  try {
    parse_trajectory_csv(text, "traj.csv", options);
  } catch (const TrajectoryFormatError& e) {
    return e;
  }
  ADD_FAILURE() << "no error for:\n" << text;
  return TrajectoryFormatError(CsvLocation{}, "", "");
}

// Checks location and message of the error text produces.
void expect_error(const std::string& text, std::size_t line, const std::string& column,
                  std::size_t column_index, const std::vector<std::string>& substrings,
                  const TrajectoryReadOptions& options = {}) {
  const TrajectoryFormatError e = parse_error(text, options);
  const std::string what = e.what();
  EXPECT_EQ(e.file(), "traj.csv") << what;
  EXPECT_EQ(e.line(), line) << what;
  EXPECT_EQ(e.column(), column) << what;
  EXPECT_EQ(e.column_index(), column_index) << what;
  std::string prefix = "traj.csv";
  if (line != 0) prefix += ":" + std::to_string(line);
  if (column_index != 0) prefix += ": column '" + column + "' (" + std::to_string(column_index) + ")";
  EXPECT_EQ(what.rfind(prefix + ": ", 0), 0u) << "message '" << what << "' does not start with '" << prefix << "'";
  for (const std::string& s : substrings) {
    EXPECT_NE(what.find(s), std::string::npos) << "message '" << what << "' lacks '" << s << "'";
  }
}

// ------------------------------------------------------- decimal time

TEST(DecimalTime, ExactValues) {
  struct Case {
    const char* text;
    std::int64_t ns;
  };
  const Case cases[] = {
      {"0.1", 100'000'000},
      {"12.5", 12'500'000'000},
      {"-3", -3'000'000'000},
      {"1700000000.123456789", 1'700'000'000'123'456'789},
      {"0.000000001", 1},
      {"-0.000000001", -1},
      {"0", 0},
      {"-0", 0},
      {"-0.0", 0},
      {"+1", 1'000'000'000},
      {".5", 500'000'000},
      {"5.", 5'000'000'000},
      {"000000000000000000000001.25", 1'250'000'000},
      {"1.5000000000000000", 1'500'000'000},  // extra zero decimals are exact
      {"1099.511627776", std::int64_t{1} << 40},  // 2^40 ns
      {"8589934592", std::int64_t{8'589'934'592} * 1'000'000'000},  // 2^33 s
      {"9223372036.854775807", kInt64Max},
      {"-9223372036.854775808", kInt64Min},
      {"9223372036.8547758070000", kInt64Max},
  };
  for (const Case& c : cases) {
    const TimeParse r = try_parse_decimal_seconds(c.text);
    EXPECT_EQ(r.status, NumberStatus::ok) << c.text;
    EXPECT_EQ(r.ns, c.ns) << c.text;
    EXPECT_EQ(parse_decimal_seconds(c.text), c.ns) << c.text;
  }
}

TEST(DecimalTime, Refusals) {
  struct Case {
    const char* text;
    NumberStatus status;
  };
  const Case cases[] = {
      {"", NumberStatus::empty},
      {"-", NumberStatus::empty},
      {"+", NumberStatus::empty},
      {".", NumberStatus::malformed},
      {"-.", NumberStatus::malformed},
      {"1e3", NumberStatus::malformed},  // exponents are not accepted (documented)
      {"1E3", NumberStatus::malformed},
      {" 1", NumberStatus::malformed},
      {"1 ", NumberStatus::malformed},
      {"1,5", NumberStatus::malformed},
      {"1.2.3", NumberStatus::malformed},
      {"--1", NumberStatus::malformed},
      {"+-1", NumberStatus::malformed},
      {"0x10", NumberStatus::malformed},
      {"nan", NumberStatus::malformed},
      {"inf", NumberStatus::malformed},
      {"1_000", NumberStatus::malformed},
      {"0.0000000005", NumberStatus::too_precise},
      {"1.0000000001", NumberStatus::too_precise},
      {"9223372036.854775808", NumberStatus::out_of_range},   // INT64_MAX + 1 ns
      {"-9223372036.854775809", NumberStatus::out_of_range},  // INT64_MIN - 1 ns
      {"9223372037", NumberStatus::out_of_range},
      {"1099511627776", NumberStatus::out_of_range},  // 2^40 s does not fit in int64 ns
      {"99999999999999999999999999", NumberStatus::out_of_range},
  };
  for (const Case& c : cases) {
    const TimeParse r = try_parse_decimal_seconds(c.text);
    EXPECT_EQ(r.status, c.status) << "'" << c.text << "'";
    EXPECT_THROW(parse_decimal_seconds(c.text), NumberFormatError) << c.text;
  }
  EXPECT_EQ(describe(NumberStatus::too_precise), "more than nanosecond resolution");
}

TEST(DecimalTime, FormatShortestExact) {
  EXPECT_EQ(format_decimal_seconds(12'500'000'000), "12.5");
  EXPECT_EQ(format_decimal_seconds(0), "0");
  EXPECT_EQ(format_decimal_seconds(3'000'000'000), "3");
  EXPECT_EQ(format_decimal_seconds(-1), "-0.000000001");
  EXPECT_EQ(format_decimal_seconds(-1'500'000'000), "-1.5");
  EXPECT_EQ(format_decimal_seconds(100'000'000), "0.1");
  EXPECT_EQ(format_decimal_seconds(1'700'000'000'123'456'789), "1700000000.123456789");
  EXPECT_EQ(format_decimal_seconds(kInt64Max), "9223372036.854775807");
  EXPECT_EQ(format_decimal_seconds(kInt64Min), "-9223372036.854775808");
  EXPECT_EQ(format_decimal_seconds(kInt64Min).size(), kMaxDecimalSecondsChars);
}

// Reference formatter independent of the code under test: printf of the
// seconds and the zero-padded nanoseconds, trailing zeros stripped.
std::string reference_format(std::int64_t ns) {
  const bool negative = ns < 0;
  const UInt128 mag = negative ? static_cast<UInt128>(-static_cast<Int128>(ns)) : static_cast<UInt128>(ns);
  char buf[64];
  std::snprintf(buf, sizeof buf, "%s%" PRIu64 ".%09" PRIu64, negative ? "-" : "",
                static_cast<std::uint64_t>(mag / 1'000'000'000), static_cast<std::uint64_t>(mag % 1'000'000'000));
  std::string s = buf;
  while (s.back() == '0') s.pop_back();
  if (s.back() == '.') s.pop_back();
  return s;
}

TEST(DecimalTime, RandomRoundTripAgainstPrintf) {
  std::mt19937_64 rng(12345);
  for (int i = 0; i < 200'000; ++i) {
    std::int64_t ns = static_cast<std::int64_t>(rng());
    // Also short values and values with few decimals.
    if (i % 3 == 1) ns >>= (rng() % 63);
    if (i % 5 == 2) ns -= ns % 1'000'000;
    const std::string reference = reference_format(ns);
    ASSERT_EQ(format_decimal_seconds(ns), reference) << ns;
    const TimeParse back = try_parse_decimal_seconds(reference);
    ASSERT_EQ(back.status, NumberStatus::ok) << reference;
    ASSERT_EQ(back.ns, ns) << reference;
  }
}

// Independent reference parser: split at the sign and the one '.', check
// the pieces are digit strings (std::string searches; std::regex trips GCC 12
// -Wmaybe-uninitialized under the sanitizers), accumulate in 128 bits.
TimeParse reference_parse(const std::string& s) {
  if (s.empty() || s == "+" || s == "-") return {0, NumberStatus::empty};
  const bool has_sign = s[0] == '+' || s[0] == '-';
  const std::string body = s.substr(has_sign ? 1 : 0);
  const std::size_t dot = body.find('.');
  const std::string int_digits = body.substr(0, dot);
  std::string frac = dot == std::string::npos ? std::string() : body.substr(dot + 1);
  const auto all_digits = [](const std::string& d) { return d.find_first_not_of("0123456789") == std::string::npos; };
  if (!all_digits(int_digits) || !all_digits(frac) || (int_digits.empty() && frac.empty())) {
    return {0, NumberStatus::malformed};
  }
  for (std::size_t k = 9; k < frac.size(); ++k) {
    if (frac[k] != '0') return {0, NumberStatus::too_precise};
  }
  frac.resize(9, '0');
  Int128 v = 0;
  for (const char c : int_digits) {
    v = v * 10 + (c - '0');
    if (v > (static_cast<Int128>(1) << 70)) return {0, NumberStatus::out_of_range};
  }
  v = v * 1'000'000'000 + std::stoll(frac);
  if (s[0] == '-') v = -v;
  if (v > kInt64Max || v < kInt64Min) return {0, NumberStatus::out_of_range};
  return {static_cast<std::int64_t>(v), NumberStatus::ok};
}

TEST(DecimalTime, RandomStringsAgainstReferenceParser) {
  std::mt19937_64 rng(777);
  const std::string alphabet = "0123456789000000.-+e x";
  for (int i = 0; i < 20'000; ++i) {
    std::string s;
    const std::size_t length = rng() % 24;
    for (std::size_t k = 0; k < length; ++k) s += alphabet[rng() % alphabet.size()];
    const TimeParse got = try_parse_decimal_seconds(s);
    const TimeParse want = reference_parse(s);
    ASSERT_EQ(got.status, want.status) << "'" << s << "'";
    ASSERT_EQ(got.ns, want.ns) << "'" << s << "'";
  }
}

TEST(StrictNumbers, Doubles) {
  EXPECT_EQ(parse_double("1.5"), 1.5);
  EXPECT_EQ(parse_double("-2e-3"), -0.002);
  EXPECT_EQ(parse_double("+3"), 3.0);
  EXPECT_EQ(parse_double(".5"), 0.5);
  EXPECT_EQ(parse_double("1.7976931348623157e308"), std::numeric_limits<double>::max());
  EXPECT_EQ(parse_double("4.9e-324"), std::numeric_limits<double>::denorm_min());
  EXPECT_TRUE(std::signbit(parse_double("-0")));
  EXPECT_EQ(parse_double("0.1"), 0.1);
  const std::pair<const char*, NumberStatus> bad[] = {
      {"", NumberStatus::empty},          {"+", NumberStatus::empty},
      {"nan", NumberStatus::not_finite},  {"NaN", NumberStatus::not_finite},
      {"inf", NumberStatus::not_finite},  {"-Infinity", NumberStatus::not_finite},
      {"nan(0x1)", NumberStatus::not_finite},
      {" 1", NumberStatus::malformed},    {"1 ", NumberStatus::malformed},
      {"1x", NumberStatus::malformed},    {"1e", NumberStatus::malformed},
      {"0x10", NumberStatus::malformed},  {"+-1", NumberStatus::malformed},
      {"--1", NumberStatus::malformed},   {"1,5", NumberStatus::malformed},
      {"1e400", NumberStatus::out_of_range}, {"-1e400", NumberStatus::out_of_range},
      {"1e-400", NumberStatus::out_of_range},
  };
  for (const auto& [text, status] : bad) {
    EXPECT_EQ(try_parse_double(text).status, status) << "'" << text << "'";
    EXPECT_THROW(parse_double(text), NumberFormatError) << text;
  }
}

TEST(StrictNumbers, Int64) {
  EXPECT_EQ(parse_int64("-9223372036854775808"), kInt64Min);
  EXPECT_EQ(parse_int64("9223372036854775807"), kInt64Max);
  EXPECT_EQ(parse_int64("+12"), 12);
  EXPECT_EQ(try_parse_int64("9223372036854775808").status, NumberStatus::out_of_range);
  EXPECT_EQ(try_parse_int64("1.0").status, NumberStatus::malformed);
  EXPECT_EQ(try_parse_int64("1e3").status, NumberStatus::malformed);
  EXPECT_EQ(try_parse_int64("").status, NumberStatus::empty);
}

// ------------------------------------------------------- trajectory reader

const char* const kGeoHeader = "time_s,lat_deg,lon_deg,h_m,heading_deg,pitch_deg,roll_deg\n";

TEST(TrajectoryCsv, ParsesGeodeticHprWithCommentsSpacesCrLfAndBom) {
  const std::string text =
      "\xEF\xBB\xBF# a comment line\n"
      "\n"
      "  time_s , lat_deg,\tlon_deg , h_m, heading_deg, pitch_deg, roll_deg\r\n"
      "   # indented comment\r\n"
      "1700000000.123456789, 41.5, 2.25, 120.0, 90, -90, 180\r\n"
      "\r\n"
      "1700000000.2, -90, -720, -5e2, -45.5, 90, +0.5\n";  // (without the newline: refused, issue 13 F2)
  const Trajectory t = parse_trajectory_csv(text, "mem.csv");
  EXPECT_EQ(t.source, "mem.csv");
  EXPECT_EQ(t.position_kind, PositionKind::geodetic);
  EXPECT_EQ(t.attitude_kind, AttitudeKind::heading_pitch_roll);
  ASSERT_EQ(t.records.size(), 2u);
  const TrajectoryRecord& a = t.records[0];
  EXPECT_EQ(a.t_ns, 1'700'000'000'123'456'789);
  EXPECT_EQ(a.line, 5u);
  EXPECT_EQ(a.position, Vec3(41.5, 2.25, 120.0));
  EXPECT_EQ(a.attitude, Eigen::Vector4d(90, -90, 180, 0));
  const TrajectoryRecord& b = t.records[1];
  EXPECT_EQ(b.t_ns, 1'700'000'000'200'000'000);
  EXPECT_EQ(b.line, 7u);
  EXPECT_EQ(b.position, Vec3(-90, -720, -500));
  EXPECT_EQ(b.attitude, Eigen::Vector4d(-45.5, 90, 0.5, 0));
  EXPECT_EQ(b.position_kind, PositionKind::geodetic);
  EXPECT_EQ(b.attitude_kind, AttitudeKind::heading_pitch_roll);
}

TEST(TrajectoryCsv, ColumnOrderIsFreeAndQuaternionsAreNormalised) {
  // |q| = 1 + 5e-7, inside the 1e-6 tolerance: accepted and normalised.
  const double s = 1.0 + 5e-7;
  const std::string text = "qz,qy,down_m,time_s,east_m,qw,north_m,qx\n"
                           "0.5,-0.5,3,0.25,2,0.5,1,-0.5\n"
                           "0," + detail::format_double(0.6 * s) + ",0,0.5,0," +
                           detail::format_double(0.8 * s) + ",0,0\n";
  const Trajectory t = parse_trajectory_csv(text, "q.csv");
  EXPECT_EQ(t.position_kind, PositionKind::local_ned);
  EXPECT_EQ(t.attitude_kind, AttitudeKind::quaternion);
  ASSERT_EQ(t.records.size(), 2u);
  EXPECT_EQ(t.records[0].t_ns, 250'000'000);
  EXPECT_EQ(t.records[0].position, Vec3(1, 2, 3));
  EXPECT_EQ(t.records[0].attitude, Eigen::Vector4d(0.5, -0.5, -0.5, 0.5));  // w, x, y, z
  const Eigen::Vector4d q = t.records[1].attitude;
  EXPECT_NEAR(q[0], 0.8, 1e-15);
  EXPECT_NEAR(q[2], 0.6, 1e-15);
  EXPECT_NEAR(q.norm(), 1.0, 1e-15);
  std::cout << "normalised quaternion |q| - 1 = " << q.norm() - 1.0 << "\n";
}

TEST(TrajectoryCsv, EcefQuaternionKinds) {
  const Trajectory t = parse_trajectory_csv(
      "time_s,x_m,y_m,z_m,qw_ecef,qx_ecef,qy_ecef,qz_ecef\n0,6378137,0,0,0,0,1,0\n", "e.csv");
  EXPECT_EQ(t.position_kind, PositionKind::ecef);
  EXPECT_EQ(t.attitude_kind, AttitudeKind::quaternion_ecef);
  EXPECT_EQ(t.records[0].attitude, Eigen::Vector4d(0, 0, 1, 0));
}

TEST(TrajectoryCsv, ValueErrorsNameFileLineAndColumn) {
  // The brief's example: a latitude of 91.5 on line 17, column 3.
  std::string text = "# header follows\ntime_s,heading_deg,lat_deg,lon_deg,h_m,pitch_deg,roll_deg\n";
  for (int line = 3; line < 17; ++line) text += std::to_string(line) + ",0,10,20,30,0,0\n";
  expect_error(text + "17,0,91.5,20,30,0,0\n", 17, "lat_deg", 3,
               {"traj.csv:17: column 'lat_deg' (3): expected a latitude in [-90, 90] degrees, got '91.5'"});
  expect_error(text + "17,0,-90.000001,20,30,0,0\n", 17, "lat_deg", 3, {"got '-90.000001'"});
  expect_error(text + "17,0,10,20,30,90.5,0\n", 17, "pitch_deg", 6, {"expected a pitch in [-90, 90] degrees, got '90.5'"});
  expect_error(text + "17,0,10,20,abc,0,0\n", 17, "h_m", 5, {"got 'abc'", "not a number"});
  expect_error(text + "17,0,10,20,nan,0,0\n", 17, "h_m", 5, {"got 'nan'", "not finite"});
  expect_error(text + "17,0,10,-inf,30,0,0\n", 17, "lon_deg", 4, {"got '-inf'", "not finite"});
  expect_error(text + "17,0,10,20,1e999,0,0\n", 17, "h_m", 5, {"out of range"});
  expect_error(text + "17,0,10,20,,0,0\n", 17, "h_m", 5, {"got ''", "empty"});
  expect_error(text + "17,0,10,20,3 0,0,0\n", 17, "h_m", 5, {"got '3 0'"});
  expect_error(text + "1e3,0,10,20,30,0,0\n", 17, "time_s", 1, {"got '1e3'", "no exponent"});
  expect_error(text + "17.0000000005,0,10,20,30,0,0\n", 17, "time_s", 1,
               {"got '17.0000000005'", "more than nanosecond resolution"});
  expect_error(text + "99999999999,0,10,20,30,0,0\n", 17, "time_s", 1, {"out of range"});
  expect_error(text + "17,0,10,20,30,0,\x01\xff\n", 17, "roll_deg", 7, {"got '\\x01\\xff'"});
}

// Issue 14, trap 2: an integer count of nanoseconds in time_s is out of
// range as seconds; the message says the unit is seconds and, when the value
// divided by 1e9 fits, gives it exactly (the point moved 9 digits, no double).
TEST(TrajectoryCsv, IntegerNanosecondTimesSayTheUnitAndTheValueInSeconds) {
  const std::string text = "time_s,lat_deg,lon_deg,h_m,heading_deg,pitch_deg,roll_deg\n0,41,2,100,0,0,0\n";
  const std::string seconds = "time_s is in seconds (from -9223372036.854775808 to 9223372036.854775807 s)";
  expect_error(text + "1717243200123456789,41,2,100,0,0,0\n", 3, "time_s", 1,
               {"got '1717243200123456789' (out of range); " + seconds,
                ": if this is an integer count of nanoseconds, divide it by 1e9 and write '1717243200.123456789'"});
  expect_error(text + "+1717243200000000000,41,2,100,0,0,0\n", 3, "time_s", 1, {"write '+1717243200'"});
  expect_error(text + "-9223372036854775808,41,2,100,0,0,0\n", 3, "time_s", 1, {"write '-9223372036.854775808'"});
  // Divided by 1e9 still out of range, or not an integer: the unit only.
  for (const std::string field : {"99999999999999999999999999999", "-9223372036854775809", "12345678901.5"}) {
    const std::string what = parse_error(text + field + ",41,2,100,0,0,0\n").what();
    EXPECT_NE(what.find(seconds), std::string::npos) << what;
    EXPECT_EQ(what.find("divide"), std::string::npos) << what;
  }
  // Other time refusals keep their own words.
  const std::string precise = parse_error(text + "17.0000000005,41,2,100,0,0,0\n").what();
  EXPECT_EQ(precise.find("in seconds"), std::string::npos) << precise;
}

// Issue 14, trap 7: `nan` heading at a pole (geodetic +-90, or ECEF on the
// z axis) is refused saying how to write the pole; elsewhere it is the plain
// "not finite" error.
TEST(TrajectoryCsv, NanHeadingAtAPoleSaysHowToWriteIt) {
  const std::vector<std::string> pole_words{"' at a pole, where heading from north is undefined",
                                            "northward direction of the record's own meridian",
                                            "qw_ecef,qx_ecef,qy_ecef,qz_ecef"};
  expect_error("heading_deg,time_s,lat_deg,lon_deg,h_m,pitch_deg,roll_deg\nnan,0,-90,30,0,0,0\n", 2, "heading_deg", 1,
               pole_words);
  expect_error("time_s,x_m,y_m,z_m,heading_deg,pitch_deg,roll_deg\n0,0,0,6356752.3,NaN,0,0\n", 2, "heading_deg", 5,
               pole_words);
  const std::string near = parse_error("time_s,lat_deg,lon_deg,h_m,heading_deg,pitch_deg,roll_deg\n0,89.9999,30,0,nan,0,0\n").what();
  EXPECT_NE(near.find("not finite"), std::string::npos) << near;
  EXPECT_EQ(near.find("at a pole"), std::string::npos) << near;
  // pitch and roll stay defined at a pole: their nan is not excused.
  const std::string pitch = parse_error("time_s,lat_deg,lon_deg,h_m,heading_deg,pitch_deg,roll_deg\n0,90,30,0,0,nan,0\n").what();
  EXPECT_NE(pitch.find("not finite"), std::string::npos) << pitch;
}

TEST(TrajectoryCsv, TimeOrderErrors) {
  // Lines 2..15 hold times -11.0 .. 2.0, line 16 holds 3.0.
  std::string text = kGeoHeader;
  for (int line = 2; line <= 16; ++line) text += std::to_string(line - 13) + ".0,0,0,0,0,0,0\n";
  // Duplicate time on line 17.
  expect_error(text + "3.0,0,0,0,0,0,0\n", 17, "time_s", 1,
               {"traj.csv:17: column 'time_s' (1): time 3.0 s is not after the previous record's 3.0 s (line 16)"});
  // Same instant written differently is still a duplicate.
  expect_error(text + "3.000000000,0,0,0,0,0,0\n", 17, "time_s", 1, {"time 3.000000000 s is not after"});
  // Decreasing time.
  expect_error(text + "2.999999999,0,0,0,0,0,0\n", 17, "time_s", 1, {"time 2.999999999 s is not after"});
  // One nanosecond later is fine.
  EXPECT_EQ(parse_trajectory_csv(text + "3.000000001,0,0,0,0,0,0\n", "t.csv").records.back().t_ns, 3'000'000'001);
}

TEST(TrajectoryCsv, FieldCountErrors) {
  const std::string h = kGeoHeader;
  expect_error(h + "0,0,0,0,0,0\n", 2, "", 0, {"expected 7 comma-separated fields", "(line 1), got 6"});
  expect_error(h + "0,0,0,0,0,0,0,0\n", 2, "", 0, {"got 8"});
  expect_error(h + "0,0,0,0,0,0,0,\n", 2, "", 0, {"got 8"});  // trailing comma
  expect_error(h + "0,0,0,0,0,0,0\n1;0;0;0;0;0;0\n", 3, "", 0, {"got 1"});
}

TEST(TrajectoryCsv, HeaderErrors) {
  expect_error("time_s,Lat_deg,lon_deg,h_m,heading_deg,pitch_deg,roll_deg\n0,0,0,0,0,0,0\n", 1, "Lat_deg", 2,
               {"unknown column name", "case-sensitive"});
  expect_error("time_s,lat_deg,lon_deg,h_m,heading_deg,pitch_deg,roll_deg,speed\n0,0,0,0,0,0,0,1\n", 1, "speed",
               8, {"unknown column name"});
  expect_error("time_s,lat_deg,lon_deg,h_m,lat_deg,heading_deg,pitch_deg,roll_deg\n", 1, "lat_deg", 5,
               {"duplicate column (also column 2)"});
  expect_error("time_s,lat_deg,,h_m\n", 1, "", 3, {"empty name"});
  expect_error("lat_deg,lon_deg,h_m,heading_deg,pitch_deg,roll_deg\n0,0,0,0,0,0\n", 1, "", 0,
               {"missing column 'time_s'"});
  expect_error("time_s,lat_deg,lon_deg,heading_deg,pitch_deg,roll_deg\n", 1, "", 0,
               {"incomplete geodetic position", "'h_m'"});
  expect_error("time_s,lat_deg,lon_deg,h_m,x_m,y_m,z_m,heading_deg,pitch_deg,roll_deg\n", 1, "", 0,
               {"ambiguous position", "lat_deg,lon_deg,h_m", "x_m,y_m,z_m"});
  expect_error("time_s,lat_deg,lon_deg,h_m,north_m,heading_deg,pitch_deg,roll_deg\n", 1, "", 0,
               {"ambiguous position"});
  expect_error("time_s,heading_deg,pitch_deg,roll_deg\n", 1, "", 0, {"missing position columns"});
  expect_error("time_s,x_m,y_m,z_m\n", 1, "", 0, {"missing attitude columns"});
  expect_error("time_s,x_m,y_m,z_m,qw,qx,qy\n", 1, "", 0, {"incomplete quaternion attitude", "'qz'"});
  expect_error("time_s,x_m,y_m,z_m,qw,qx,qy,qz,heading_deg,pitch_deg,roll_deg\n", 1, "", 0,
               {"ambiguous attitude"});
  expect_error("time_s,north_m,east_m,down_m,qw_ecef,qx_ecef,qy_ecef,qz_ecef\n", 1, "", 0,
               {"needs an Earth-fixed position"});
  // Header on a later line after comments: line numbers are physical lines.
  expect_error("#c\n\n#c\ntime_s,bogus\n", 4, "bogus", 2, {"unknown column name"});
}

TEST(TrajectoryCsv, QuaternionNormTolerance) {
  const std::string h = "time_s,x_m,y_m,z_m,qw,qx,qy,qz\n";
  expect_error(h + "0,1,2,3,1.0001,0,0,0\n", 2, "qw", 5, {"expected a unit quaternion", "1.0001"});
  expect_error(h + "0,1,2,3,0,0,0,0\n", 2, "qw", 5, {"got |q| = 0"});
  expect_error(h + "0,1,2,3,1e200,1e200,0,0\n", 2, "qw", 5, {"unit quaternion"});
  // |q| = 1 - 2e-6: outside; 1 - 0.9e-6: inside.
  expect_error(h + "0,1,2,3,0,0,0,0.999998\n", 2, "qw", 5, {"unit quaternion"});
  const Trajectory ok = parse_trajectory_csv(h + "0,1,2,3,0,0,0,-0.9999991\n", "ok.csv");
  EXPECT_NEAR(ok.records[0].attitude[3], -1.0, 1e-16);
}

TEST(TrajectoryCsv, EmptyAndMissingFiles) {
  expect_error("", 0, "", 0, {"no header row"});
  expect_error("# only\n\n  # comments\n", 0, "", 0, {"no header row"});
  expect_error(std::string(kGeoHeader) + "# no data\n", 0, "", 0, {"no records after the header (line 1)"});

  TempDir dir;
  const std::string missing = dir.file("missing.csv");
  try {
    read_trajectory_csv(missing);
    ADD_FAILURE() << "no error for a missing file";
  } catch (const TrajectoryFormatError& e) {
    EXPECT_EQ(e.file(), missing);
    EXPECT_EQ(e.line(), 0u);
    EXPECT_EQ(std::string(e.what()), missing + ": cannot read the trajectory file: No such file or directory");
  }
  try {
    read_trajectory_csv(dir.file(""));  // the directory itself
    ADD_FAILURE() << "no error for a directory";
  } catch (const TrajectoryFormatError& e) {
    EXPECT_NE(std::string(e.what()).find("Is a directory"), std::string::npos) << e.what();
  }
  const std::string good = dir.file("good.csv");
  spit(good, std::string(kGeoHeader) + "1,2,3,4,5,6,7\n");
  const Trajectory t = read_trajectory_csv(good);
  EXPECT_EQ(t.source, good);
  EXPECT_EQ(t.records.at(0).position, Vec3(2, 3, 4));
}

TEST(TrajectoryCsv, ExtraColumnsOnlyWhenAllowed) {
  const std::string text = "time_s,speed_m_s,x_m,y_m,z_m,heading_deg,pitch_deg,roll_deg\n0,garbage,1,2,3,4,5,6\n";
  expect_error(text, 1, "speed_m_s", 2, {"unknown column name"});
  const Trajectory t = parse_trajectory_csv(text, "x.csv", {.allow_extra_columns = true});
  EXPECT_EQ(t.records.at(0).position, Vec3(1, 2, 3));
  // The field count still has to match the header.
  expect_error("time_s,speed_m_s,x_m,y_m,z_m,heading_deg,pitch_deg,roll_deg\n0,1,2,3,4,5,6\n", 2, "", 0,
               {"got 7"}, {.allow_extra_columns = true});
  // Known columns stay validated.
  expect_error("time_s,extra,x_m,y_m,z_m,heading_deg,pitch_deg,roll_deg\n0,1,2,3,4,5,95,6\n", 2, "pitch_deg", 7,
               {"pitch in [-90, 90]"}, {.allow_extra_columns = true});
}

// A 4-hour 100 Hz file (1.44 M records) read from disk in about a second.
TEST(TrajectoryCsv, LargeFileParsesFast) {
  constexpr int kRecords = 1'440'000;
  constexpr TimeNs kStartNs = 1'700'000'000'000'000'000;
  constexpr TimeNs kStepNs = 10'000'000;
  // Deterministic values with all 53 bits in play (int64: no overflow).
  auto value = [](std::int64_t i, std::int64_t k) {
    return std::ldexp(static_cast<double>((i * 7919 + k * 104729) % 1000003), -13) * 1.0000001 - 60.0;
  };
  std::string text;
  text.reserve(static_cast<std::size_t>(kRecords) * 96);
  text += "time_s,lat_deg,lon_deg,h_m,heading_deg,pitch_deg,roll_deg\n";
  char row[256];
  for (int i = 0; i < kRecords; ++i) {
    char* p = write_decimal_seconds(row, kStartNs + i * kStepNs);
    for (int k = 0; k < 6; ++k) {
      *p++ = ',';
      p = std::to_chars(p, row + sizeof row, value(i, k)).ptr;
    }
    *p++ = '\n';
    text.append(row, p);
  }
  TempDir dir;
  const std::string path = dir.file("big.csv");
  spit(path, text);
  text.clear();
  text.shrink_to_fit();

  // CPU time is what the parser costs; wall time also shows the shared,
  // often busy 2-core machine.
  const std::clock_t cpu_start = std::clock();
  const auto start = std::chrono::steady_clock::now();
  const Trajectory t = read_trajectory_csv(path);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const double cpu_seconds = static_cast<double>(std::clock() - cpu_start) / CLOCKS_PER_SEC;
  std::cout << "read_trajectory_csv: " << kRecords << " records in " << seconds << " s wall, " << cpu_seconds
            << " s CPU\n";
  RecordProperty("parse_seconds_wall", std::to_string(seconds));
  RecordProperty("parse_seconds_cpu", std::to_string(cpu_seconds));
  ASSERT_EQ(t.records.size(), static_cast<std::size_t>(kRecords));
  for (int i = 0; i < kRecords; i += 9973) {
    const TrajectoryRecord& r = t.records[static_cast<std::size_t>(i)];
    ASSERT_EQ(r.t_ns, kStartNs + i * kStepNs);
    ASSERT_EQ(r.line, static_cast<std::size_t>(i) + 2);
    for (int k = 0; k < 3; ++k) ASSERT_EQ(bits(r.position[k]), bits(value(i, k)));
    for (int k = 0; k < 3; ++k) ASSERT_EQ(bits(r.attitude[k]), bits(value(i, k + 3)));
  }
  // Speed is printed here and measured by bench/bench_io.cpp; it is not
  // asserted (timed unit tests flake on a shared machine).
}

// Arbitrary bytes must either parse or raise the format error: nothing else,
// and no UB (the CI's sanitizer build runs this too).
TEST(TrajectoryCsv, RandomAndMutatedInputsOnlyParseOrThrowFormatError) {
  const std::vector<std::string> seeds = {
      "# c\ntime_s, lat_deg, lon_deg, h_m, heading_deg, pitch_deg, roll_deg\n0.0,45,7,100,10,5,-3\n"
      "0.01,45.0001,7.0001,100.5,11,5,-3\n0.02,45.0002,7.0002,101,12,5.5,-3\n",
      "time_s,x_m,y_m,z_m,qw,qx,qy,qz\r\n1700000000.1,4e6,1e5,4.9e6,1,0,0,0\r\n"
      "1700000000.2,4e6,1e5,4.9e6,0.7071067811865476,0,0.7071067811865476,0\r\n",
      "qz,time_s,north_m,east_m,down_m,qw,qy,qx\n0,1,2,3,4,1,0,0\n0,2,2,3,4,1,0,0\n",
      "time_s,x_m,y_m,z_m,qw_ecef,qx_ecef,qy_ecef,qz_ecef,vx_m_s\n0,1,2,3,1,0,0,0,5\n0.5,1,2,3,1,0,0,0,5\n",
  };
  const std::string tokens[] = {",", "\n", "\r\n", "#", " ", ".", "-", "+", "e", "0", "9", "nan", "inf",
                                "1e308", "0.0000000001", "lat_deg", "qw", "x_m", "time_s", "\xEF\xBB\xBF",
                                std::string(1, '\0'), "\xff", "99999999999", ",,,,"};
  std::mt19937_64 rng(2024);
  auto pick = [&rng](std::size_t n) { return n == 0 ? std::size_t{0} : static_cast<std::size_t>(rng() % n); };
  int parsed = 0;
  int refused = 0;
  constexpr int kInputs = 6000;
  for (int n = 0; n < kInputs; ++n) {
    std::string input;
    if (n % 10 == 9) {  // pure random bytes
      const std::size_t length = pick(200);
      for (std::size_t k = 0; k < length; ++k) input += static_cast<char>(rng() & 0xff);
    } else {
      input = seeds[pick(seeds.size())];
      const int mutations = 1 + static_cast<int>(pick(4));
      for (int m = 0; m < mutations; ++m) {
        const std::size_t at = pick(input.size() + 1);
        switch (pick(5)) {
          case 0: if (at < input.size()) input[at] = static_cast<char>(rng() & 0xff); break;
          case 1: input.insert(at, tokens[pick(std::size(tokens))]); break;
          case 2: input.erase(at, pick(8)); break;
          case 3: {  // duplicate a chunk (repeated lines, times)
            const std::size_t length = pick(40);
            input.insert(at, input.substr(pick(input.size()), length));
            break;
          }
          default: if (at < input.size()) input[at] = static_cast<char>(input[at] ^ (1 << pick(8))); break;
        }
      }
    }
    for (const bool extra : {false, true}) {
      try {
        const Trajectory t = parse_trajectory_csv(input, "fuzz.csv", {.allow_extra_columns = extra});
        ++parsed;
        // Whatever parses must satisfy the documented guarantees.
        ASSERT_FALSE(t.records.empty());
        for (std::size_t i = 0; i < t.records.size(); ++i) {
          const TrajectoryRecord& r = t.records[i];
          if (i > 0) {
            ASSERT_GT(r.t_ns, t.records[i - 1].t_ns);
          }
          ASSERT_TRUE(r.position.allFinite());
          ASSERT_TRUE(r.attitude.allFinite());
          if (r.attitude_kind == AttitudeKind::heading_pitch_roll) {
            ASSERT_LE(std::abs(r.attitude[1]), 90.0);
          } else {
            ASSERT_NEAR(r.attitude.norm(), 1.0, 1e-15);
          }
          if (r.position_kind == PositionKind::geodetic) {
            ASSERT_LE(std::abs(r.position[0]), 90.0);
          }
        }
      } catch (const TrajectoryFormatError& e) {
        ++refused;
        ASSERT_EQ(e.file(), "fuzz.csv");
        ASSERT_EQ(std::string(e.what()).rfind("fuzz.csv", 0), 0u);
      }
      // Anything else propagates and fails the test.
      try {
        (void)parse_imu_csv(input, "fuzz.csv");
      } catch (const SampleFormatError&) {
      }
      try {
        (void)parse_kinematics_csv(input, "fuzz.csv");
      } catch (const SampleFormatError&) {
      }
    }
  }
  std::cout << "fuzz: " << kInputs << " inputs x 2 option sets: " << parsed << " parsed, " << refused
            << " refused with TrajectoryFormatError\n";
  EXPECT_GT(parsed, 50);  // the mutations must not all be trivially fatal
  EXPECT_GT(refused, 1000);
}

// ------------------------------------------------------- atomic writer

mode_t process_umask() {
  const mode_t mask = ::umask(0);
  ::umask(mask);
  return mask;
}

TEST(AtomicFile, CommitReplacesAndLeavesNoTemporary) {
  TempDir dir;
  const std::string path = dir.file("out.txt");
  {
    AtomicFileWriter w(path, 16);  // tiny buffer: forces several write(2) calls
    EXPECT_EQ(w.temp_path().rfind(path + ".tmp.", 0), 0u);
    EXPECT_TRUE(exists(w.temp_path()));
    EXPECT_FALSE(exists(path));  // nothing at the target before commit
    w.write("hello, ");
    w.write("this line is longer than the sixteen-byte buffer\n");
    w.write("end\n");
    EXPECT_FALSE(exists(path));
    w.commit();
    EXPECT_TRUE(w.committed());
  }
  EXPECT_EQ(slurp(path), "hello, this line is longer than the sixteen-byte buffer\nend\n");
  EXPECT_EQ(dir.files(), std::vector<std::string>{"out.txt"});
  struct stat st {};
  ASSERT_EQ(::stat(path.c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0666 & ~process_umask());

  // Replacing keeps the old file's mode.
  ASSERT_EQ(::chmod(path.c_str(), 0640), 0);
  write_file_atomically(path, "second\n");
  EXPECT_EQ(slurp(path), "second\n");
  ASSERT_EQ(::stat(path.c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0640u);
  EXPECT_EQ(dir.files().size(), 1u);
}

TEST(AtomicFile, ExceptionLeavesNoFileAndOldTargetUntouched) {
  TempDir dir;
  const std::string fresh = dir.file("fresh.txt");
  try {
    AtomicFileWriter w(fresh, 8);
    w.write(std::string(100, 'x'));  // already flushed to the temp file
    throw std::runtime_error("simulated failure");
  } catch (const std::runtime_error&) {
  }
  EXPECT_TRUE(dir.files().empty());

  const std::string old = dir.file("old.txt");
  spit(old, "previous run\n");
  {
    AtomicFileWriter w(old);
    w.write("half of a new file");
  }  // destroyed without commit
  EXPECT_EQ(slurp(old), "previous run\n");
  EXPECT_EQ(dir.files(), std::vector<std::string>{"old.txt"});

  AtomicFileWriter discarded(dir.file("d.txt"));
  discarded.write("x");
  discarded.discard();
  EXPECT_EQ(dir.files(), std::vector<std::string>{"old.txt"});
  EXPECT_THROW(discarded.write("y"), std::logic_error);
}

TEST(AtomicFile, UnwritableLocationsThrowSystemError) {
  TempDir dir;
  EXPECT_THROW(AtomicFileWriter(dir.file("no/such/dir/out.csv")), std::system_error);
  try {
    write_file_atomically(dir.file("missing_dir/x.csv"), "x");
    ADD_FAILURE();
  } catch (const std::system_error& e) {
    EXPECT_NE(std::string(e.what()).find("missing_dir/x.csv"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(dir.files().empty());
}

// Issue 13 F1: the outputs of one command are replaced together. The second
// output's location is unwritable: the first keeps its old content, and no
// temporary file is left.
TEST(AtomicFile, TransactionReplacesNoOutputWhenOneFails) {
  TempDir dir;
  const std::string first = dir.file("imu.csv");
  write_file_atomically(first, "old imu\n");
  try {
    OutputTransaction outputs;
    write_file_atomically(first, "new imu\n");
    EXPECT_EQ(slurp(first), "old imu\n");  // prepared, not yet renamed
    write_file_atomically(dir.file("missing_dir/traj.csv"), "new traj\n");
    outputs.commit();
    ADD_FAILURE() << "the second output cannot be written";
  } catch (const std::system_error&) {
  }
  EXPECT_EQ(slurp(first), "old imu\n");
  EXPECT_EQ(dir.files(), std::vector<std::string>{"imu.csv"});
  {
    OutputTransaction outputs;
    write_file_atomically(first, "new imu\n");
    write_file_atomically(dir.file("traj.csv"), "new traj\n");
    outputs.commit();
  }
  EXPECT_EQ(slurp(first), "new imu\n");
  EXPECT_EQ(slurp(dir.file("traj.csv")), "new traj\n");
  EXPECT_EQ(dir.files().size(), 2u);
}

// A rename that fails at commit (the second target became a directory after
// its writer started; one that already is a directory is refused at once,
// tests/io/test_output_paths.cpp): the first target, already renamed, gets its
// old content back.
TEST(AtomicFile, TransactionRenameFailureRestoresTheTargetsRenamed) {
  TempDir dir;
  const std::string first = dir.file("a.csv"), blocked = dir.file("b.csv");
  write_file_atomically(first, "old a\n");
  {
    OutputTransaction outputs;
    write_file_atomically(first, "new a\n");
    AtomicFileWriter second(blocked);
    ASSERT_EQ(::mkdir(blocked.c_str(), 0755), 0);
    second.write("new b\n");
    second.commit();
    EXPECT_THROW(outputs.commit(), std::system_error);
  }
  EXPECT_EQ(slurp(first), "old a\n");
  std::vector<std::string> names = dir.files();
  std::sort(names.begin(), names.end());
  EXPECT_EQ(names, (std::vector<std::string>{"a.csv", "b.csv"}));
  ::rmdir(blocked.c_str());
}

// Issue 13: temporary files left by a writer killed with SIGKILL are named
// with its pid; the next writer of the same target removes those of dead
// pids and keeps those of running ones and of other targets.
TEST(AtomicFile, StaleTemporaryFilesOfDeadWritersAreRemoved) {
  TempDir dir;
  const std::string target = dir.file("out.csv");
  // A pid that surely is dead: a child that has exited and been reaped.
  const pid_t child = ::fork();
  if (child == 0) ::_exit(0);
  ASSERT_GT(child, 0);
  ASSERT_EQ(::waitpid(child, nullptr, 0), child);
  const std::string dead = "out.csv.tmp." + std::to_string(child) + ".AbC123";
  const std::string alive = "out.csv.tmp." + std::to_string(::getppid()) + ".XyZ789";
  const std::string other_target = "other.csv.tmp." + std::to_string(child) + ".QqQ000";
  const std::string not_a_temp = "out.csv.tmp.notapid.Z";
  for (const std::string& n : {dead, alive, other_target, not_a_temp}) std::ofstream(dir.file(n)) << "x";
  EXPECT_EQ(temp_file_owner(dead, "out.csv"), child);
  EXPECT_EQ(temp_file_owner(not_a_temp, "out.csv"), -1);
  EXPECT_EQ(temp_file_owner("out.csv.tmp.12", "out.csv"), -1);
  EXPECT_EQ(temp_file_owner("xout.csv.tmp.12.a", "out.csv"), -1);
  {
    AtomicFileWriter w(target);
    // The writer's own temporary file carries this process's pid.
    EXPECT_EQ(temp_file_owner(w.temp_path().substr(w.temp_path().rfind('/') + 1), "out.csv"), ::getpid());
    w.write("new\n");
    w.commit();
  }
  std::vector<std::string> names = dir.files();
  std::sort(names.begin(), names.end());
  std::vector<std::string> expected{alive, not_a_temp, "out.csv", other_target};
  std::sort(expected.begin(), expected.end());
  EXPECT_EQ(names, expected);
}

// Issue 13 R2: 200 MB of blank lines asked reserve() for a record per line
// (bad_alloc). Lines without data reserve nothing, and a text with more data
// lines than limits::kMaxKnots is refused before any record is reserved.
TEST(TrajectoryCsv, BlankLinesReserveNothingAndTheKnotCapComesFirst) {
  EXPECT_EQ(detail::count_lines("\n\n   \n# c\n\t\r\n1,2\n  3\n"), 2u);
  std::string blank(20'000'000, '\n');
  const std::string header = "time_s,north_m,east_m,down_m,heading_deg,pitch_deg,roll_deg\n";
  const Trajectory t = parse_trajectory_csv(header + blank + "0,0,0,0,0,0,0\n1,1,0,0,0,0,0\n" + blank, "blank.csv");
  EXPECT_EQ(t.records.size(), 2u);
  EXPECT_LE(t.records.capacity(), 3u);
  std::string many = header;
  many.reserve(header.size() + 2 * (limits::kMaxKnots + 1));
  for (std::size_t i = 0; i < limits::kMaxKnots + 1; ++i) many += "0\n";
  try {
    (void)parse_trajectory_csv(many, "many.csv");
    ADD_FAILURE() << "more records than the knot cap";
  } catch (const limits::SizeLimitError& e) {
    EXPECT_NE(std::string(e.what()).find("many.csv"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(std::to_string(limits::kMaxKnots)), std::string::npos) << e.what();
  }
}

// Issue 13: h_m = 1e300 passed the reader and ended as a NaN sample at the
// writer (exit 4, an internal message); positions beyond limits::kMaxPositionM
// are refused at file:line, naming the column.
TEST(TrajectoryCsv, HugePositionsAreRefusedAtTheirLine) {
  const std::string text = "time_s,lat_deg,lon_deg,h_m,heading_deg,pitch_deg,roll_deg\n"
                           "0,41,2,100,0,0,0\n"
                           "1,41,2,1e300,0,0,0\n";
  try {
    (void)parse_trajectory_csv(text, "huge.csv");
    ADD_FAILURE();
  } catch (const CsvFormatError& e) {
    EXPECT_NE(std::string(e.what()).find("huge.csv:3"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("h_m"), std::string::npos) << e.what();
  }
}

// ------------------------------------------------------- IMU sample files

std::vector<ImuSample> random_samples(std::size_t n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<ImuSample> out(n);
  TimeNs t = -5'000'000'000 + static_cast<TimeNs>(rng() % 1000);
  for (std::size_t i = 0; i < n; ++i) {
    out[i].t_ns = t;
    t += 1 + static_cast<TimeNs>(rng() % 20'000'000);
    for (int k = 0; k < 3; ++k) {
      // Random bit patterns of finite doubles: every exponent, subnormals, -0.
      double g;
      double a;
      do g = std::bit_cast<double>(rng()); while (!std::isfinite(g));
      do a = std::bit_cast<double>(rng()); while (!std::isfinite(a));
      out[i].gyro_rad_s[k] = (i % 4 == 0) ? g : std::uniform_real_distribution<double>(-10, 10)(rng);
      out[i].accel_m_s2[k] = (i % 4 == 1) ? a : std::uniform_real_distribution<double>(-100, 100)(rng);
    }
  }
  out[0].gyro_rad_s[0] = -0.0;
  out[0].accel_m_s2[1] = std::numeric_limits<double>::denorm_min();
  out[1].accel_m_s2[2] = -std::numeric_limits<double>::max();
  return out;
}

TEST(ImuCsv, RoundTripIsBitExact) {
  TempDir dir;
  const std::string path = dir.file("imu.csv");
  const std::vector<ImuSample> samples = random_samples(20'000, 99);
  write_imu_csv(path, samples);
  EXPECT_EQ(dir.files(), std::vector<std::string>{"imu.csv"});
  const std::string text = slurp(path);
  EXPECT_EQ(text.substr(0, text.find('\n')), kImuCsvHeader);
  const std::vector<ImuSample> back = read_imu_csv(path);
  ASSERT_EQ(back.size(), samples.size());
  std::size_t mismatches = 0;
  for (std::size_t i = 0; i < samples.size(); ++i) {
    mismatches += back[i].t_ns != samples[i].t_ns;
    for (int k = 0; k < 3; ++k) {
      mismatches += bits(back[i].gyro_rad_s[k]) != bits(samples[i].gyro_rad_s[k]);
      mismatches += bits(back[i].accel_m_s2[k]) != bits(samples[i].accel_m_s2[k]);
    }
  }
  EXPECT_EQ(mismatches, 0u);
  // A line is the integer time then the shortest round-trip doubles.
  EXPECT_NE(text.find("\n" + std::to_string(samples[1].t_ns) + ","), std::string::npos);
}

TEST(ImuCsv, WriterRefusesNonFiniteAndNonIncreasingAndEmpty) {
  TempDir dir;
  const std::string path = dir.file("imu.csv");
  std::vector<ImuSample> samples = random_samples(1000, 5);
  samples[700].accel_m_s2[1] = std::numeric_limits<double>::quiet_NaN();
  try {
    write_imu_csv(path, samples);
    ADD_FAILURE();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("sample 700"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("non-finite"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(dir.files().empty());  // no target, no temporary

  samples[700].accel_m_s2[1] = 0.0;
  samples[300].gyro_rad_s[2] = -std::numeric_limits<double>::infinity();
  EXPECT_THROW(write_imu_csv(path, samples), std::invalid_argument);
  samples[300].gyro_rad_s[2] = 0.0;
  samples[301].t_ns = samples[300].t_ns;
  EXPECT_THROW(write_imu_csv(path, samples), std::invalid_argument);
  EXPECT_THROW(write_imu_csv(path, {}), std::invalid_argument);
  EXPECT_TRUE(dir.files().empty());

  // Streaming: a failure half way leaves nothing either.
  {
    ImuCsvWriter w(path);
    w.write(samples[0]);
    ImuSample bad = samples[1];
    bad.gyro_rad_s[0] = std::numeric_limits<double>::quiet_NaN();
    EXPECT_THROW(w.write(bad), std::invalid_argument);
  }
  EXPECT_TRUE(dir.files().empty());
}

TEST(ImuCsv, ReaderErrors) {
  auto error_of = [](const std::string& text) -> std::string {
    try {
      parse_imu_csv(text, "imu.csv");
    } catch (const SampleFormatError& e) {
      return e.what();
    }
    return "no error";
  };
  const std::string h = std::string(kImuCsvHeader) + "\n";
  EXPECT_EQ(error_of(h + "1,0,0,0,0,0,0\n2,0,0,0,0,0,0.5x\n"),
            "imu.csv:3: column 'accel_z_m_s2' (7): expected a finite number, got '0.5x' (not a number in the "
            "accepted syntax)");
  EXPECT_EQ(error_of(h + "1.5,0,0,0,0,0,0\n").rfind("imu.csv:2: column 'time_ns' (1): expected an integer time", 0), 0u);
  EXPECT_EQ(error_of(h + "5,0,0,0,0,0,0\n5,0,0,0,0,0,0\n"),
            "imu.csv:3: column 'time_ns' (1): time 5 ns is not after the previous record's 5 ns (line 2)");
  EXPECT_EQ(error_of(h + "5,0,0,inf,0,0,0\n").rfind("imu.csv:2: column 'gyro_z_rad_s' (4)", 0), 0u);
  EXPECT_EQ(error_of(h), "imu.csv: no samples after the header (line 1)");
  EXPECT_EQ(error_of("time_ns,gyro_x_rad_s\n").rfind("imu.csv:1: missing column 'gyro_y_rad_s'", 0), 0u);
  EXPECT_EQ(error_of(h.substr(0, h.size() - 1) + ",extra\n").rfind("imu.csv:1: column 'extra' (8): unknown", 0), 0u);
  // Column order is free.
  const std::vector<ImuSample> s = parse_imu_csv(
      "accel_z_m_s2,time_ns,gyro_x_rad_s,gyro_y_rad_s,gyro_z_rad_s,accel_x_m_s2,accel_y_m_s2\n-9.8,7,1,2,3,4,5\n",
      "x");
  ASSERT_EQ(s.size(), 1u);
  EXPECT_EQ(s[0].t_ns, 7);
  EXPECT_EQ(s[0].gyro_rad_s, Vec3(1, 2, 3));
  EXPECT_EQ(s[0].accel_m_s2, Vec3(4, 5, -9.8));
  TempDir dir;
  EXPECT_THROW(read_imu_csv(dir.file("none.csv")), SampleFormatError);
}

// ------------------------------------------------------- smoothed trajectory

std::vector<Kinematics> random_states(std::size_t n, std::uint64_t seed, std::vector<Eigen::Vector4d>& q_out) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal;
  std::vector<Kinematics> out(n);
  q_out.resize(n);
  TimeNs t = 1'700'000'000'000'000'000;
  for (std::size_t i = 0; i < n; ++i) {
    Kinematics& s = out[i];
    s.t_ns = t;
    t += 1 + static_cast<TimeNs>(rng() % 10'000'000);
    s.position_m = Vec3(normal(rng), normal(rng), normal(rng)) * 6.4e6;
    s.velocity_m_s = Vec3(normal(rng), normal(rng), normal(rng)) * 300.0;
    s.acceleration_m_s2 = Vec3(normal(rng), normal(rng), normal(rng)) * 20.0;
    s.angular_rate_rad_s = Vec3(normal(rng), normal(rng), normal(rng));
    // Attitude from a known unit quaternion with w > 0 (the independent truth).
    Eigen::Vector4d q(std::abs(normal(rng)) + 1e-3, normal(rng), normal(rng), normal(rng));
    q.normalize();
    q_out[i] = q;
    s.attitude = so3::matrix_from_quaternion(q);
  }
  return out;
}

TEST(KinematicsCsv, RoundTripAndReadableAsTrajectoryInput) {
  for (const Physics physics : {Physics::ecef, Physics::flat}) {
    TempDir dir;
    const std::string path = dir.file("smoothed.csv");
    std::vector<Eigen::Vector4d> q_truth;
    const std::vector<Kinematics> states = random_states(5000, physics == Physics::ecef ? 1 : 2, q_truth);
    write_trajectory_csv(path, states, physics);
    EXPECT_EQ(dir.files(), std::vector<std::string>{"smoothed.csv"});
    const std::string text = slurp(path);
    EXPECT_EQ(text.substr(0, text.find('\n')), kinematics_csv_header(physics));

    const KinematicsTrajectory back = read_kinematics_csv(path);
    EXPECT_EQ(back.physics, physics);
    ASSERT_EQ(back.states.size(), states.size());
    std::size_t mismatches = 0;
    double worst_q = 0.0;
    double worst_R = 0.0;
    for (std::size_t i = 0; i < states.size(); ++i) {
      const Kinematics& a = states[i];
      const Kinematics& b = back.states[i];
      mismatches += a.t_ns != b.t_ns;
      for (int k = 0; k < 3; ++k) {
        mismatches += bits(a.position_m[k]) != bits(b.position_m[k]);
        mismatches += bits(a.velocity_m_s[k]) != bits(b.velocity_m_s[k]);
        mismatches += bits(a.acceleration_m_s2[k]) != bits(b.acceleration_m_s2[k]);
        mismatches += bits(a.angular_rate_rad_s[k]) != bits(b.angular_rate_rad_s[k]);
      }
      worst_q = std::max(worst_q, (back.quaternions[i] - q_truth[i]).cwiseAbs().maxCoeff());
      worst_R = std::max(worst_R, (b.attitude - a.attitude).cwiseAbs().maxCoeff());
    }
    std::cout << (physics == Physics::ecef ? "ecef" : "flat") << ": worst |q_read - q_true| = " << worst_q
              << ", worst |R_read - R| = " << worst_R << "\n";
    EXPECT_EQ(mismatches, 0u);
    EXPECT_LT(worst_q, 1e-15);
    EXPECT_LT(worst_R, 2e-15);

    // The same file is a trajectory input when extra columns are allowed.
    EXPECT_THROW(read_trajectory_csv(path), TrajectoryFormatError);
    const Trajectory t = read_trajectory_csv(path, {.allow_extra_columns = true});
    EXPECT_EQ(t.position_kind, physics == Physics::ecef ? PositionKind::ecef : PositionKind::local_ned);
    EXPECT_EQ(t.attitude_kind, physics == Physics::ecef ? AttitudeKind::quaternion_ecef : AttitudeKind::quaternion);
    ASSERT_EQ(t.records.size(), states.size());
    for (std::size_t i = 0; i < states.size(); ++i) {
      ASSERT_EQ(t.records[i].t_ns, states[i].t_ns);
      for (int k = 0; k < 3; ++k) ASSERT_EQ(bits(t.records[i].position[k]), bits(states[i].position_m[k]));
      ASSERT_LT((t.records[i].attitude - q_truth[i]).cwiseAbs().maxCoeff(), 1e-15);
    }
  }
}

TEST(KinematicsCsv, WriterRefusesBadStates) {
  TempDir dir;
  const std::string path = dir.file("s.csv");
  std::vector<Eigen::Vector4d> q;
  std::vector<Kinematics> states = random_states(100, 3, q);
  states[40].velocity_m_s[2] = std::numeric_limits<double>::infinity();
  EXPECT_THROW(write_trajectory_csv(path, states, Physics::ecef), std::invalid_argument);
  states[40].velocity_m_s[2] = 0.0;
  states[41].attitude(0, 0) += 1e-3;  // not a rotation any more
  EXPECT_THROW(write_trajectory_csv(path, states, Physics::ecef), std::invalid_argument);
  states[41].attitude = -Mat3::Identity();  // orthogonal but a reflection
  EXPECT_THROW(write_trajectory_csv(path, states, Physics::ecef), std::invalid_argument);
  states[41].attitude = Mat3::Identity();
  states[42].t_ns = states[41].t_ns;
  EXPECT_THROW(write_trajectory_csv(path, states, Physics::flat), std::invalid_argument);
  EXPECT_THROW(write_trajectory_csv(path, {}, Physics::flat), std::invalid_argument);
  EXPECT_TRUE(dir.files().empty());
}

}  // namespace
}  // namespace imuemu::io

namespace imuemu::io {
namespace {

// Issue 13 F2: a file cut inside its last field without a final newline
// (`...,2.` of `2.900`, a file still being written) parses as a number; it is
// refused naming file:line, as pose lines refuse an unterminated line. The
// same line with its newline is a record.
TEST(TrajectoryCsv, UnterminatedLastRecordIsRefusedNamingItsLine) {
  const std::string complete =
      "time_s,north_m,east_m,down_m,heading_deg,pitch_deg,roll_deg\n0,0,0,0,0,0,0\n1,1,0,0,0,0,0\n2,2.5,2.900,0,0,0,0\n";
  EXPECT_EQ(parse_trajectory_csv(complete, "traj.csv").records.size(), 3u);
  const std::string cut = complete.substr(0, complete.find("2.900") + 2);  // "...,2.5,2."
  expect_error(cut, 4, "", 0, {"no final newline", "cut off or still being written"});
  // A trailing comment or blank line without a newline is harmless.
  EXPECT_EQ(parse_trajectory_csv(complete + "# done", "traj.csv").records.size(), 3u);
  EXPECT_EQ(parse_trajectory_csv(complete + "   ", "traj.csv").records.size(), 3u);
}

}  // namespace
}  // namespace imuemu::io
}  // namespace unity_io_test_io
