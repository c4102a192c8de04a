#include "daemon/cli/allan_command.hpp"

#include <fcntl.h>
#include <spawn.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <bit>
#include <atomic>
#include <exception>
#include <thread>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iostream>
#include <memory>
#include <sstream>
#include <system_error>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "daemon/cli/cli_options.hpp"
#include "daemon/cli/commands.hpp"
#include "io/decimal_time.hpp"
#include "io/installed_paths.hpp"
#include "io/sample_writers.hpp"
#include "io/trajectory_csv.hpp"

extern char** environ;

namespace imuemu::cli {
namespace {

constexpr std::array<const char*, 6> kAxisNames{"gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"};
constexpr std::array<const char*, 6> kImuAxisColumns{"gyro_x_rad_s", "gyro_y_rad_s", "gyro_z_rad_s",
                                                     "accel_x_m_s2", "accel_y_m_s2", "accel_z_m_s2"};
// `imuemu listen --out` (daemon/cli/listen_command.cpp): sequence and time may be
// empty when the protocol has none.
const std::vector<std::string_view> kListenColumns{
    "sequence",     "t_ns",         "gyro_x_rad_s", "gyro_y_rad_s", "gyro_z_rad_s", "accel_x_m_s2", "accel_y_m_s2",
    "accel_z_m_s2", "dtheta_x_rad", "dtheta_y_rad", "dtheta_z_rad", "dv_x_m_s",     "dv_y_m_s",     "dv_z_m_s",
    "status"};

[[noreturn]] void fail(const std::string& file, std::size_t line, std::string column, std::size_t column_index,
                       std::string expected, std::string detail) {
  throw io::SampleFormatError(io::CsvLocation{file, line, std::move(column), column_index}, std::move(expected),
                              std::move(detail));
}

// Powers of ten exact in long double (x86 80-bit: 64-bit significand;
// 10^27 = 2^27 5^27 and 5^27 < 2^63).
constexpr int kExactPow10 = 27;
long double pow10_exact(int e) {
  static const auto table = [] {
    std::array<long double, kExactPow10 + 1> t{};
    t[0] = 1.0L;
    for (int i = 1; i <= kExactPow10; ++i) t[static_cast<std::size_t>(i)] = t[static_cast<std::size_t>(i - 1)] * 10.0L;
    return t;
  }();
  return table[static_cast<std::size_t>(e)];
}

// SWAR digit parsing (eight ASCII bytes in one little-endian word; the
// method of Lemire, "Number parsing at a gigabyte per second", Software:
// Practice and Experience 51(8), 2021, section 4): all eight are '0'..'9'...
constexpr bool eight_digits(std::uint64_t chunk) noexcept {
  return ((chunk & 0xF0F0F0F0F0F0F0F0u) | (((chunk + 0x0606060606060606u) & 0xF0F0F0F0F0F0F0F0u) >> 4)) ==
         0x3333333333333333u;
}
// ... and their value, the first byte the most significant digit.
constexpr std::uint64_t eight_digit_value(std::uint64_t chunk) noexcept {
  chunk = (chunk & 0x0F0F0F0F0F0F0F0Fu) * 2561u >> 8;
  chunk = (chunk & 0x00FF00FF00FF00FFu) * 6553601u >> 16;
  return ((chunk & 0x0000FFFF0000FFFFu) * 42949672960001u >> 32) & 0xFFFFFFFFu;
}
static_assert(eight_digit_value(0x3837363534333231u) == 12345678u);  // "12345678" little-endian
static_assert(eight_digits(0x3837363534333231u) && !eight_digits(0x383736352E333231u) && !eight_digits(0x3837363534333A31u));

}  // namespace

bool parse_plain_decimal(std::string_view text, double& out) noexcept {
  const char* p = text.data();
  const char* const end = p + text.size();
  bool negative = false;
  if (p != end && (*p == '-' || *p == '+')) negative = *p++ == '-';
  std::uint64_t mantissa = 0;
  int digits = 0;          // significant digits kept in mantissa (at most 19)
  int exponent10 = 0;      // value = mantissa * 10^exponent10
  bool any_digit = false;
  for (; p != end && *p >= '0' && *p <= '9'; ++p) {
    any_digit = true;
    if (mantissa == 0 && *p == '0') continue;
    if (digits == 19) {  // beyond 19 significant digits: dropped (< 1e-18 relative)
      ++exponent10;
      continue;
    }
    mantissa = mantissa * 10 + static_cast<std::uint64_t>(*p - '0');
    ++digits;
  }
  if (p != end && *p == '.') {
    for (++p; p != end && *p >= '0' && *p <= '9'; ++p) {
      any_digit = true;
      if (mantissa == 0 && *p == '0') {
        --exponent10;
        continue;
      }
      // Eight digits at a time once the leading zeros are behind (the same
      // digits, in the same order, as the loop below takes one by one).
      if constexpr (std::endian::native == std::endian::little) {
        while (mantissa != 0 && digits + 8 <= 19 && end - p >= 8) {
          std::uint64_t chunk = 0;
          std::memcpy(&chunk, p, 8);
          if (!eight_digits(chunk)) break;
          mantissa = mantissa * 100'000'000u + eight_digit_value(chunk);
          digits += 8;
          exponent10 -= 8;
          p += 8;
        }
        if (p == end || *p < '0' || *p > '9') break;
      }
      if (mantissa == 0 && *p == '0') {
        --exponent10;
        continue;
      }
      if (digits == 19) continue;  // dropped, as above
      mantissa = mantissa * 10 + static_cast<std::uint64_t>(*p - '0');
      ++digits;
      --exponent10;
    }
  }
  if (!any_digit) return false;
  if (p != end && (*p == 'e' || *p == 'E')) {
    ++p;
    bool exp_negative = false;
    if (p != end && (*p == '-' || *p == '+')) exp_negative = *p++ == '-';
    if (p == end) return false;
    int e = 0;
    for (; p != end && *p >= '0' && *p <= '9'; ++p) {
      if (e > 10000) return false;
      e = e * 10 + (*p - '0');
    }
    exponent10 += exp_negative ? -e : e;
  }
  if (p != end) return false;  // anything else: the exact reader decides (and names the problem)
  if (mantissa == 0) {
    out = negative ? -0.0 : 0.0;
    return true;
  }
  // Far beyond the magnitudes of IMU data (and near subnormals or overflow):
  // the exact reader.
  if (exponent10 + digits < -290 || exponent10 + digits > 290) return false;
  double v = 0.0;
  if (mantissa < (std::uint64_t{1} << 53) && exponent10 >= -22 && exponent10 <= 22) {
    // Clinger's fast path: both operands exact in double, one rounding.
    static constexpr double kPow10[] = {1e0,  1e1,  1e2,  1e3,  1e4,  1e5,  1e6,  1e7,  1e8,  1e9,  1e10, 1e11,
                                        1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22};
    const auto m = static_cast<double>(mantissa);
    v = exponent10 >= 0 ? m * kPow10[exponent10] : m / kPow10[-exponent10];
  } else {
    // Both operands exact in long double, one rounding there, one to double.
    const auto m = static_cast<long double>(mantissa);
    const int e = exponent10 >= 0 ? exponent10 : -exponent10;
    // 10^e exact up to 10^27, else powl (within an ulp of long double, 2^-63
    // relative, far below the final rounding to double).
    const long double scale = e <= kExactPow10 ? pow10_exact(e) : std::pow(10.0L, static_cast<long double>(e));
    const long double r = exponent10 >= 0 ? m * scale : m / scale;
    v = static_cast<double>(r);
  }
  out = negative ? -v : v;
  return true;
}

namespace {

enum class Role { ignore, time, sequence, axis };

struct Column {
  Role role = Role::ignore;
  int axis = -1;  // 0..5 for Role::axis
  std::string_view name;
};

// Streaming parse of one file: header, then rows into the kept axes.
class Reader {
 public:
  Reader(std::string path, std::array<bool, 6> keep, double rate_hz, bool longest_run)
      : path_(std::move(path)), keep_(keep), rate_hz_(rate_hz), longest_run_(longest_run) {}

  AllanInput read() {
    const int fd = ::open(path_.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) fail(path_, 0, "", 0, "a readable file", std::string("cannot open: ") + std::strerror(errno));
    struct FdCloser {
      int fd;
      ~FdCloser() { ::close(fd); }
    } closer{fd};
    struct stat st {};
    if (::fstat(fd, &st) == 0) file_bytes_ = static_cast<std::uint64_t>(st.st_size);
    ::posix_fadvise(fd, 0, 0, POSIX_FADV_SEQUENTIAL);

    constexpr std::size_t kBlock = 8u << 20;
    std::vector<char> buffer(kBlock);
    std::size_t carried = 0;  // bytes of an unfinished line at the buffer's start
    for (;;) {
      if (carried == buffer.size()) buffer.resize(buffer.size() * 2);  // a line longer than a block
      const ssize_t got = ::read(fd, buffer.data() + carried, buffer.size() - carried);
      if (got < 0) {
        if (errno == EINTR) continue;
        fail(path_, line_, "", 0, "a readable file", std::string("read error: ") + std::strerror(errno));
      }
      const std::size_t filled = carried + static_cast<std::size_t>(got);
      std::size_t begin = 0;
      while (begin < filled) {
        const void* nl = std::memchr(buffer.data() + begin, '\n', filled - begin);
        if (nl == nullptr) break;
        const auto end = static_cast<std::size_t>(static_cast<const char*>(nl) - buffer.data());
        on_line(std::string_view(buffer.data() + begin, end - begin));
        begin = end + 1;
      }
      carried = filled - begin;
      if (carried > 0 && begin > 0) std::memmove(buffer.data(), buffer.data() + begin, carried);
      if (got == 0) {
        if (carried > 0) on_line(std::string_view(buffer.data(), carried));  // last line without '\n'
        break;
      }
    }
    return finish();
  }

 private:
  void on_line(std::string_view text) {
    ++line_;
    if (line_ == 1 && text.starts_with("\xEF\xBB\xBF")) text.remove_prefix(3);
    if (!io::detail::split_csv_line(text, fields_)) return;
    if (columns_.empty()) {
      header(text.size());
      return;
    }
    row();
  }

  void header(std::size_t header_bytes) {
    header_line_ = line_;
    auto find = [&](std::string_view name) {
      for (std::size_t i = 0; i < fields_.size(); ++i)
        if (fields_[i] == name) return true;
      return false;
    };
    std::vector<std::string_view> schema;
    const bool listen = find("t_ns") || find("sequence");
    if (listen) {
      format_ = "listen";
      schema = kListenColumns;
    } else {
      format_ = "imu";
      schema = {"time_ns"};
      for (const char* c : kImuAxisColumns) schema.push_back(c);
    }
    std::string expected;
    for (std::string_view s : schema) expected += (expected.empty() ? "" : ",") + std::string(s);
    expected = "the columns " + expected + " (any order)";
    if (!listen) expected += ", or those of an `imuemu listen --out` capture";
    std::vector<std::size_t> seen(schema.size(), 0);
    columns_.resize(fields_.size());
    for (std::size_t i = 0; i < fields_.size(); ++i) {
      std::size_t k = 0;
      while (k < schema.size() && schema[k] != fields_[i]) ++k;
      if (k == schema.size())
        fail(path_, line_, std::string(fields_[i]), i + 1, expected, "unknown column name; expected " + expected);
      if (seen[k] != 0)
        fail(path_, line_, std::string(fields_[i]), i + 1, expected,
             "duplicate column (also column " + std::to_string(seen[k]) + ")");
      seen[k] = i + 1;
      Column& c = columns_[i];
      c.name = schema[k];
      if (schema[k] == "time_ns" || schema[k] == "t_ns") {
        c.role = Role::time;
        time_column_ = i;
      } else if (schema[k] == "sequence") {
        c.role = Role::sequence;
      } else {
        for (int a = 0; a < 6; ++a)
          if (schema[k] == kImuAxisColumns[static_cast<std::size_t>(a)]) {
            c.role = Role::axis;
            c.axis = a;
          }
      }
    }
    for (std::size_t k = 0; k < schema.size(); ++k)
      if (seen[k] == 0)
        fail(path_, line_, "", 0, expected, "missing column '" + std::string(schema[k]) + "'; expected " + expected);
    // Reserve from the file size: every data row is at least about as long
    // as this header's number of fields times a few bytes; over-reserving by
    // a rough estimate costs only address space.
    const std::uint64_t estimate = file_bytes_ / std::max<std::uint64_t>(16, header_bytes) + 16;
    for (int a = 0; a < 6; ++a)
      if (keep_[static_cast<std::size_t>(a)]) values_[static_cast<std::size_t>(a)].reserve(static_cast<std::size_t>(estimate));
  }

  void row() {
    const TimeNs previous_t_ns = last_t_ns_;
    const std::size_t previous_line = last_row_line_;
    gap_in_row_ = false;
    if (fields_.size() != columns_.size())
      fail(path_, line_, "", 0, std::to_string(columns_.size()) + " fields",
           "expected " + std::to_string(columns_.size()) + " comma-separated fields as named by the header (line " +
               std::to_string(header_line_) + "), got " + std::to_string(fields_.size()));
    for (std::size_t i = 0; i < fields_.size(); ++i) {
      const Column& c = columns_[i];
      const std::string_view f = fields_[i];
      switch (c.role) {
        case Role::ignore: break;
        case Role::time: time(f, i); break;
        case Role::sequence: sequence(f, i); break;
        case Role::axis: {
          if (!keep_[static_cast<std::size_t>(c.axis)]) break;
          double fast = 0.0;
          if (parse_plain_decimal(f, fast)) {
            values_[static_cast<std::size_t>(c.axis)].push_back(fast);
            break;
          }
          const io::DoubleParse v = io::try_parse_double(f);
          if (v.status != io::NumberStatus::ok)
            fail(path_, line_, std::string(c.name), i + 1, "a finite number",
                 "expected a finite number, got '" + io::detail::printable(f) + "' (" +
                     std::string(io::describe(v.status)) + ")");
          values_[static_cast<std::size_t>(c.axis)].push_back(v.value);
          break;
        }
      }
    }
    if (rows_ == 0) {
      run_ = Run{0, first_t_ns_, line_, 0, 0, 0};
    } else if (gap_in_row_) {
      close_run(previous_t_ns, previous_line);
      run_ = Run{rows_, last_t_ns_, line_, 0, 0, 0};
    }
    last_row_line_ = line_;
    ++rows_;
  }

  // The samples of one unbroken run: rows [start_row, start_row + rows).
  struct Run {
    std::uint64_t start_row = 0;
    TimeNs first_t_ns = 0;
    std::size_t first_line = 0;
    TimeNs last_t_ns = 0;
    std::size_t last_line = 0;
    std::uint64_t rows = 0;
  };

  void close_run(TimeNs last_t_ns, std::size_t last_line) {
    run_.last_t_ns = last_t_ns;
    run_.last_line = last_line;
    run_.rows = rows_ - run_.start_row;
    if (run_.rows > best_.rows) best_ = run_;
  }

  // A gap at this row: refused (what is missing, where, and the remedies), or
  // with --gaps longest the end of a run.
  void gap(std::size_t column, std::string_view name, const std::string& expected, const std::string& detail) {
    ++gaps_;
    gap_in_row_ = true;
    if (longest_run_) return;
    fail(path_, line_, std::string(name), column, expected,
         detail + "; Allan variance needs an unbroken, uniformly sampled series. `imuemu allan --gaps longest` "
                  "analyses the longest unbroken run; a capture of imuemu emit or imuemud misses samples where the "
                  "emitter dropped a late tick (--late-ticks drop, the default): capture with --late-ticks send");
  }

  void time(std::string_view f, std::size_t i) {
    if (rows_ == 0 && f.empty() && format_ == "listen") {
      timeless_ = true;  // the protocol carries no time: --rate gives it
      return;
    }
    if (timeless_) return;
    const io::Int64Parse t = io::try_parse_int64(f);
    if (t.status != io::NumberStatus::ok)
      fail(path_, line_, std::string(columns_[i].name), i + 1, "an integer time in nanoseconds",
           "expected an integer time in nanoseconds, got '" + io::detail::printable(f) + "' (" +
               std::string(io::describe(t.status)) + ")");
    if (rows_ == 0) {
      first_t_ns_ = t.value;
    } else {
      const TimeNs step = t.value - last_t_ns_;  // int64 times of one file: differences do not overflow in practice
      if (step <= 0)
        fail(path_, line_, std::string(columns_[i].name), i + 1, "a time after the previous row's",
             "time " + std::to_string(t.value) + " ns is not after the previous row's " + std::to_string(last_t_ns_) +
                 " ns (line " + std::to_string(last_time_line_) + ")");
      if (nominal_step_ns_ <= 0) nominal_step_ns_ = rate_hz_ > 0.0 ? static_cast<TimeNs>(std::llround(1e9 / rate_hz_)) : step;
      if ((step * 2 < nominal_step_ns_ || step * 2 > 3 * nominal_step_ns_) && !gap_in_row_)
        gap(i + 1, columns_[i].name, "a uniformly sampled series",
            "time step " + std::to_string(step) + " ns from line " + std::to_string(last_time_line_) +
                " is off the nominal " + std::to_string(nominal_step_ns_) +
                " ns by more than half (a gap or a rate change here)");
    }
    last_t_ns_ = t.value;
    last_time_line_ = line_;
  }

  void sequence(std::string_view f, std::size_t i) {
    if (f.empty()) return;  // the protocol has no counter
    const io::Int64Parse s = io::try_parse_int64(f);
    if (s.status != io::NumberStatus::ok || s.value < 0)
      fail(path_, line_, "sequence", i + 1, "a non-negative integer sequence number",
           "expected a non-negative integer, got '" + io::detail::printable(f) + "'");
    if (has_sequence_ && s.value <= last_sequence_)
      fail(path_, line_, "sequence", i + 1, "the previous row's sequence + 1",
           "sequence " + std::to_string(s.value) + " after " + std::to_string(last_sequence_) + " (line " +
               std::to_string(last_sequence_line_) +
               "): samples are repeated or out of order; Allan variance needs an unbroken series");
    if (has_sequence_ && s.value > last_sequence_ + 1 && !gap_in_row_)
      gap(i + 1, "sequence", "the previous row's sequence + 1",
          "sequence " + std::to_string(s.value) + " after " + std::to_string(last_sequence_) + " (line " +
              std::to_string(last_sequence_line_) + "): " + std::to_string(s.value - last_sequence_ - 1) +
              (s.value - last_sequence_ == 2 ? " sample" : " samples") + " missing");
    has_sequence_ = true;
    last_sequence_ = s.value;
    last_sequence_line_ = line_;
  }

  AllanInput finish() {
    if (columns_.empty())
      fail(path_, 0, "", 0, "a header row", "no header row: the file is empty or holds only comments and blank lines");
    if (rows_ == 0) fail(path_, 0, "", 0, "samples", "no samples after the header (line " + std::to_string(header_line_) + ")");
    AllanInput in;
    in.format = format_;
    in.file_rows = rows_;
    in.gaps = gaps_;
    close_run(last_t_ns_, last_row_line_);
    // The run analysed: the whole file without gaps, else the longest.
    const Run use = best_;
    in.rows = use.rows;
    in.first_line = use.first_line;
    in.last_line = use.last_line;
    if (use.rows != rows_)
      for (auto& v : values_)
        if (!v.empty()) {
          v.erase(v.begin() + static_cast<std::ptrdiff_t>(use.start_row + use.rows), v.end());
          v.erase(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(use.start_row));
        }
    if (rate_hz_ > 0.0) {
      in.tau0_s = 1.0 / rate_hz_;
    } else if (timeless_) {
      throw std::invalid_argument(path_ + ": the capture has no sample times (the protocol carries none): give --rate HZ");
    } else if (use.rows < 2) {
      fail(path_, 0, "", 0, "at least two samples",
           gaps_ > 0 ? "the longest unbroken run (line " + std::to_string(use.first_line) + ") has one sample"
                     : std::string("one sample has no interval"));
    } else {
      // Mean interval over the whole record (run): exact for a uniform grid,
      // and the right tau0 for a clock with a small constant rate error.
      in.tau0_s = seconds_between(use.first_t_ns, use.last_t_ns) / static_cast<double>(use.rows - 1);
    }
    for (int a = 0; a < 6; ++a) {
      const auto au = static_cast<std::size_t>(a);
      if (!keep_[au]) continue;
      AllanSeries s;
      s.name = kAxisNames[au];
      s.kind = a < 3 ? allan::SensorKind::gyro : allan::SensorKind::accel;
      s.values = std::move(values_[au]);
      in.series.push_back(std::move(s));
    }
    return in;
  }

  std::string path_;
  std::array<bool, 6> keep_;
  double rate_hz_;
  std::uint64_t file_bytes_ = 0;
  std::size_t line_ = 0, header_line_ = 0;
  std::vector<std::string_view> fields_;
  std::vector<Column> columns_;
  std::size_t time_column_ = 0;
  std::string format_;
  std::array<std::vector<double>, 6> values_;
  std::uint64_t rows_ = 0;
  bool timeless_ = false;
  TimeNs first_t_ns_ = 0, last_t_ns_ = 0, nominal_step_ns_ = 0;
  std::size_t last_time_line_ = 0;
  bool has_sequence_ = false;
  std::int64_t last_sequence_ = 0;
  std::size_t last_sequence_line_ = 0;
  bool longest_run_ = false;
  bool gap_in_row_ = false;
  std::uint64_t gaps_ = 0;
  std::size_t last_row_line_ = 0;
  Run run_, best_;
};

std::array<bool, allan::kTermCount> parse_terms(const std::string& list) {
  std::array<bool, allan::kTermCount> on{};
  std::stringstream ss(list);
  std::string item;
  while (std::getline(ss, item, ',')) {
    if (item == "q") on[allan::quantization] = true;
    else if (item == "n") on[allan::white] = true;
    else if (item == "b") on[allan::bias_instability] = true;
    else if (item == "k") on[allan::rate_random_walk] = true;
    else if (item == "r") on[allan::rate_ramp] = true;
    else
      throw std::invalid_argument("--terms: unknown term '" + item +
                                  "'; expected a comma-separated list of q (quantization), n (white), b (bias "
                                  "instability), k (rate random walk), r (rate ramp)");
  }
  return on;
}

std::string unit_of(allan::SensorKind kind) { return kind == allan::SensorKind::gyro ? "rad/s" : "m/s^2"; }

const char* term_symbol(int k) {
  static constexpr const char* kSymbols[] = {"Q", "N", "B", "K", "R"};
  return kSymbols[k];
}

const char* term_label(allan::SensorKind kind, int k) {
  const bool gyro = kind == allan::SensorKind::gyro;
  switch (k) {
    case allan::quantization: return gyro ? "angle quantization" : "velocity quantization";
    case allan::white: return gyro ? "angle random walk" : "velocity random walk";
    case allan::bias_instability: return "bias instability";
    case allan::rate_random_walk: return gyro ? "rate random walk" : "acceleration random walk";
    default: return gyro ? "rate ramp" : "acceleration ramp";
  }
}

std::string fmt(double v, int digits = 4) {
  char b[64];
  std::snprintf(b, sizeof b, "%.*g", digits, v);
  return b;
}

void print_table(std::ostream& out, const AllanInput& in, const std::vector<allan::Analysis>& analyses,
                 const AllanArgs& args) {
  const double duration_s = static_cast<double>(in.rows) * in.tau0_s;
  out << "imuemu allan: " << args.path << " (" << in.format << "): " << in.rows << " samples, tau0 "
      << fmt(in.tau0_s, 9) << " s (" << fmt(1.0 / in.tau0_s, 9) << " Hz), " << fmt(duration_s / 3600.0, 5) << " h\n"
      << "overlapping Allan deviation; " << fmt(args.confidence * 100.0, 3)
      << " % intervals from chi^2 with the EDF of Howe-Allan-Barnes (NIST SP 1065 Table 5)\n";
  for (std::size_t s = 0; s < analyses.size(); ++s) {
    const AllanSeries& series = in.series[s];
    const allan::Analysis& a = analyses[s];
    out << "\n" << series.name << " (" << unit_of(series.kind) << ")\n";
    char line[200];
    std::snprintf(line, sizeof line, "  %12s %12s %12s %12s %10s  %s\n", "tau_s", "adev", "ci_low", "ci_high", "edf",
                  "noise (for the EDF)");
    out << line;
    for (const allan::Point& p : a.points) {
      std::snprintf(line, sizeof line, "  %12.6g %12.5g %12.5g %12.5g %10.4g  %s%s\n", p.tau_s, p.adev, p.ci_low,
                    p.ci_high, p.edf, allan::to_string(p.noise).c_str(), p.in_fit ? "" : "  (not fitted)");
      out << line;
    }
    out << "  fit: sigma^2 = 3Q^2/tau^2 + N^2/tau + (2 ln2/pi) B^2 + K^2 tau/3 + R^2 tau^2/2 (IEEE Std 952-1997 "
           "Annex C), weighted NNLS; +- 1-sigma (sandwich covariance over the correlated tau), [" << fmt(args.confidence * 100.0, 3)
        << " % interval]\n";
    for (int k = 0; k < allan::kTermCount; ++k) {
      const allan::FittedTerm& t = a.terms[static_cast<std::size_t>(k)];
      out << "    " << term_symbol(k) << "  " << term_label(series.kind, k) << ": ";
      if (!t.enabled) {
        out << "not fitted (--terms)\n";
        continue;
      }
      if (t.value <= 0.0) {
        out << "0 (not detected)\n";
        continue;
      }
      const std::vector<allan::UnitValue> units = allan::datasheet_units(series.kind, k, t.value);
      const std::vector<allan::UnitValue> sig = allan::datasheet_units(series.kind, k, t.sigma);
      const std::vector<allan::UnitValue> lo = allan::datasheet_units(series.kind, k, t.low);
      const std::vector<allan::UnitValue> hi = allan::datasheet_units(series.kind, k, t.high);
      for (std::size_t u = 0; u < units.size(); ++u) {
        out << (u == 0 ? "" : " = ") << fmt(units[u].value) << " " << units[u].unit;
        if (u == 0) out << " +- " << fmt(sig[u].value, 2) << " [" << fmt(lo[u].value, 3) << ", " << fmt(hi[u].value, 3) << "]";
      }
      out << "\n";
    }
  }
}

// The plotting script beside the program, as installed: PREFIX/bin/imuemu and
// PREFIX/share/imuemu/plot_allan.py (/usr for the Debian package). A build tree
// has the same layout (build/<flavour>/daemon/imuemu and
// build/<flavour>/share/imuemu/, copied there by daemon/CMakeLists.txt), so
// no source-tree path is compiled in.
std::string default_plot_script() { return (io::installed_data_dir() / "plot_allan.py").string(); }

// /usr/bin/python3 SCRIPT JSON PNG, waited for.
void run_plot(const std::string& script, const std::string& json_text, const std::string& png_path) {
  char tmpl[] = "/tmp/imuemu-allan-XXXXXX.json";
  const int fd = ::mkstemps(tmpl, 5);
  if (fd < 0) throw std::runtime_error(std::string("cannot create a temporary JSON file: ") + std::strerror(errno));
  struct Remove {
    const char* p;
    ~Remove() { ::unlink(p); }
  } remove{tmpl};
  std::size_t done = 0;
  while (done < json_text.size()) {
    const ssize_t w = ::write(fd, json_text.data() + done, json_text.size() - done);
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) {
      ::close(fd);
      throw std::runtime_error(std::string("cannot write the temporary JSON file: ") + std::strerror(errno));
    }
    done += static_cast<std::size_t>(w);
  }
  ::close(fd);
  std::string python = "/usr/bin/python3";  // Debian's, with matplotlib (pyenv's first on PATH has none)
  std::vector<std::string> argv_s{python, script, tmpl, png_path};
  std::vector<char*> argv;
  for (std::string& s : argv_s) argv.push_back(s.data());
  argv.push_back(nullptr);
  pid_t pid = 0;
  const int rc = ::posix_spawn(&pid, python.c_str(), nullptr, nullptr, argv.data(), environ);
  if (rc != 0) throw std::runtime_error("cannot run " + python + ": " + std::strerror(rc));
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0)
    throw std::runtime_error(python + " " + script + " failed (exit status " +
                             std::to_string(WIFEXITED(status) ? WEXITSTATUS(status) : -1) + "); no plot written to " +
                             png_path);
}

}  // namespace

AllanInput read_allan_input(const std::string& path, const std::string& axes, double rate_hz, bool longest_run) {
  std::array<bool, 6> keep{};
  if (axes == "all" || axes == "gyro") keep[0] = keep[1] = keep[2] = true;
  if (axes == "all" || axes == "accel") keep[3] = keep[4] = keep[5] = true;
  if (axes != "all" && axes != "gyro" && axes != "accel")
    throw std::invalid_argument("--axes must be all, gyro or accel, not '" + axes + "'");
  if (rate_hz < 0.0 || !std::isfinite(rate_hz)) throw std::invalid_argument("--rate must be a positive rate in Hz");
  return Reader(path, keep, rate_hz, longest_run).read();
}

nlohmann::json allan_json(const AllanInput& in, const std::vector<allan::Analysis>& analyses, const AllanArgs& args) {
  nlohmann::json j;
  j["file"] = args.path;
  j["format"] = in.format;
  j["samples"] = in.rows;
  if (in.gaps > 0) {
    // --gaps longest: which part of the file was analysed.
    j["gaps"] = {{"count", in.gaps}, {"file_samples", in.file_rows}, {"first_line", in.first_line},
                 {"last_line", in.last_line}};
  }
  j["tau0_s"] = in.tau0_s;
  j["duration_s"] = static_cast<double>(in.rows) * in.tau0_s;
  j["confidence"] = args.confidence;
  j["edf_method"] = "Howe-Allan-Barnes 1981 approximations, NIST SP 1065 Table 5 (dominant noise from the fitted model)";
  j["model"] = "sigma^2 = 3Q^2/tau^2 + N^2/tau + (2 ln2/pi) B^2 + K^2 tau/3 + R^2 tau^2/2 (IEEE Std 952-1997 Annex C)";
  nlohmann::json axes = nlohmann::json::array();
  for (std::size_t s = 0; s < analyses.size(); ++s) {
    const allan::Analysis& a = analyses[s];
    const AllanSeries& series = in.series[s];
    nlohmann::json ax;
    ax["name"] = series.name;
    ax["sensor"] = series.kind == allan::SensorKind::gyro ? "gyro" : "accel";
    ax["unit"] = unit_of(series.kind);
    std::vector<double> tau, adev, lo, hi, edf;
    std::vector<std::string> noise;
    std::vector<bool> in_fit;
    for (const allan::Point& p : a.points) {
      tau.push_back(p.tau_s);
      adev.push_back(p.adev);
      lo.push_back(p.ci_low);
      hi.push_back(p.ci_high);
      edf.push_back(p.edf);
      noise.push_back(allan::to_string(p.noise));
      in_fit.push_back(p.in_fit);
    }
    ax["tau_s"] = tau;
    ax["adev"] = adev;
    ax["ci_low"] = lo;
    ax["ci_high"] = hi;
    ax["edf"] = edf;
    ax["noise"] = noise;
    ax["in_fit"] = in_fit;
    ax["model_adev"] = a.model_adev;
    nlohmann::json terms = nlohmann::json::object();
    for (int k = 0; k < allan::kTermCount; ++k) {
      const allan::FittedTerm& t = a.terms[static_cast<std::size_t>(k)];
      nlohmann::json tj;
      tj["symbol"] = term_symbol(k);
      tj["label"] = term_label(series.kind, k);
      tj["enabled"] = t.enabled;
      tj["value"] = t.value;
      tj["sigma"] = t.sigma;
      tj["formal_sigma"] = t.formal_sigma;
      tj["low"] = t.low;
      tj["high"] = t.high;
      nlohmann::json units = nlohmann::json::object();
      const auto v = allan::datasheet_units(series.kind, k, t.value);
      const auto sg = allan::datasheet_units(series.kind, k, t.sigma);
      for (std::size_t u = 0; u < v.size(); ++u) units[v[u].unit] = {{"value", v[u].value}, {"sigma", sg[u].value}};
      tj["si_unit"] = v.empty() ? "" : v.front().unit;
      tj["units"] = units;
      tj["adev"] = a.term_adev[static_cast<std::size_t>(k)];
      terms[allan::term_name(k)] = tj;
    }
    ax["terms"] = terms;
    axes.push_back(ax);
  }
  j["axes"] = axes;
  return j;
}

allan::AnalysisOptions allan_options(const AllanArgs& args) {
  allan::AnalysisOptions opt;
  opt.terms = parse_terms(args.terms);
  opt.points_per_decade = args.points_per_decade;
  opt.max_tau_fraction = args.max_tau_fraction;
  opt.confidence = args.confidence;
  opt.fit_min_tau_s = args.fit_min_tau_s;
  opt.fit_max_tau_s = args.fit_max_tau_s;
  (void)allan::log_spaced_factors(1000, opt.points_per_decade, opt.max_tau_fraction);  // option checks
  if (!(opt.confidence > 0.0 && opt.confidence < 1.0)) throw std::invalid_argument("--confidence must be in (0, 1)");
  return opt;
}

std::vector<allan::Analysis> analyse_allan_input(AllanInput& in, const allan::AnalysisOptions& opt) {
  // The axes are independent: two workers (the machine's cores), each
  // freeing an axis' samples once analysed. Exceptions are carried out of
  // the threads and the first one rethrown here.
  std::vector<allan::Analysis> analyses(in.series.size());
  std::vector<std::exception_ptr> failures(in.series.size());
  std::atomic<std::size_t> next{0};
  const auto work = [&] {
    for (std::size_t k = next++; k < in.series.size(); k = next++) {
      try {
        analyses[k] = allan::analyse(in.series[k].values, in.tau0_s, opt);
      } catch (...) {
        failures[k] = std::current_exception();
      }
      std::vector<double>().swap(in.series[k].values);
    }
  };
  {
    std::thread helper;
    try {
      if (in.series.size() > 1) helper = std::thread(work);
    } catch (const std::system_error&) {
      // no second thread: the calling thread does it all
    }
    work();
    if (helper.joinable()) helper.join();
  }
  for (const std::exception_ptr& f : failures)
    if (f) std::rethrow_exception(f);
  return analyses;
}

int run_allan(const AllanArgs& args, std::ostream& out, std::ostream& err) {
  allan::AnalysisOptions opt;
  AllanInput in;
  try {
    opt = allan_options(args);
  } catch (const std::invalid_argument& e) {
    err << "imuemu allan: " << e.what() << "\n";
    return kUsageError;
  }
  try {
    if (args.gaps != "refuse" && args.gaps != "longest")
      throw std::invalid_argument("--gaps must be refuse or longest, not '" + args.gaps + "'");
    in = read_allan_input(args.path, args.axes, args.rate_hz, args.gaps == "longest");
    if (in.gaps > 0)
      err << "imuemu allan: " << args.path << ": " << in.gaps << (in.gaps == 1 ? " gap" : " gaps")
          << " (missing samples); analysing the longest unbroken run, lines " << in.first_line << ".." << in.last_line
          << " (" << in.rows << " of " << in.file_rows << " samples)\n";
  } catch (const io::CsvFormatError& e) {
    err << "imuemu allan: " << e.what() << "\n";
    return kBadInput;
  } catch (const std::invalid_argument& e) {
    err << "imuemu allan: " << e.what() << "\n";
    return kUsageError;
  } catch (const std::bad_alloc&) {
    err << "imuemu allan: " << args.path << ": not enough memory to hold the samples (try --axes gyro or accel)\n";
    return kCannotProcess;
  }
  std::vector<allan::Analysis> analyses;
  try {
    analyses = analyse_allan_input(in, opt);
  } catch (const std::invalid_argument& e) {
    err << "imuemu allan: " << args.path << ": " << e.what() << "\n";
    return kCannotProcess;
  } catch (const std::exception& e) {
    err << "imuemu allan: internal error: " << e.what() << "\n";
    return kInternalError;
  }
  const nlohmann::json j = allan_json(in, analyses, args);
  if (args.json) {
    out << j.dump(1) << "\n";
  } else {
    print_table(out, in, analyses, args);
  }
  out.flush();
  if (!args.png_path.empty()) {
    try {
      run_plot(args.plot_script.empty() ? default_plot_script() : args.plot_script, j.dump(),
               args.png_path);
    } catch (const std::exception& e) {
      err << "imuemu allan: --png: " << e.what() << "\n";
      return kOutputError;
    }
  }
  return kOk;
}

void add_allan_command(CLI::App& app, int& exit_code) {
  auto a = std::make_shared<AllanArgs>();
  auto* c = app.add_subcommand(
      "allan",
      "Overlapping Allan deviation of each axis of an IMU CSV or `listen --out` capture, with confidence intervals "
      "and the five-term IEEE 952 fit (docs/allan.md)");
  c->add_option("FILE", a->path, "IMU CSV (time_ns, gyro rad/s, accel m/s^2) or an `imuemu listen --out` capture")
      ->required();
  c->add_flag("--json", a->json, "JSON on stdout instead of the table");
  c->add_option("--png", a->png_path, "Also write a log-log plot (estimate, CI band, fitted terms) via /usr/bin/python3 and the plotting script (needs python3-matplotlib)");
  c->add_option("--plot-script", a->plot_script, "The plotting script (default: share/imuemu/plot_allan.py beside the program's bin/, /usr/share/imuemu/plot_allan.py when installed)");
  c->add_option("--axes", a->axes, "Which axes: all, gyro or accel")->capture_default_str()
      ->check(CLI::IsMember({"all", "gyro", "accel"}));
  c->add_option("--rate", a->rate_hz, "Nominal sample rate in Hz (needed when the capture has no sample times)")
      ->check(finite_in(0.0, 1e9, true));
  c->add_option("--points-per-decade", a->points_per_decade, "tau grid density")->capture_default_str()
      ->check(CLI::Range(1, 1000));
  c->add_option("--max-tau-fraction", a->max_tau_fraction, "Largest tau as a fraction of the record (<= 0.5)")
      ->capture_default_str()->check(finite_in(0.0, 0.5, true));
  c->add_option("--confidence", a->confidence, "Confidence of the intervals")->capture_default_str();
  c->add_option("--fit-min-tau-s", a->fit_min_tau_s, "Fit only tau >= this (s)")->check(seconds_in(0.0, kMaxDurationS));
  c->add_option("--fit-max-tau-s", a->fit_max_tau_s, "Fit only tau <= this (s)")->check(seconds_in(0.0, kMaxDurationS));
  c->add_option("--terms", a->terms,
                "Fit terms: comma list of q (quantization), n (ARW/VRW), b (bias instability), k (rate random walk), "
                "r (rate ramp)")
      ->capture_default_str();
  c->add_option("--gaps", a->gaps,
                "A series with gaps (a sequence number jump, or a time step off the nominal by more than half): "
                "refuse (exit 3 naming the line) or longest (analyse the longest unbroken run, named on stderr and "
                "in the JSON's \"gaps\"). Repeated or backward samples are always refused")
      ->capture_default_str()->check(CLI::IsMember({"refuse", "longest"}));
  c->callback([a, &exit_code] { exit_code = run_allan(*a, std::cout, std::cerr); });
}

}  // namespace imuemu::cli
