// `imuemu allan FILE`: overlapping Allan deviation of every axis of an IMU
// CSV (io/sample_writers.hpp format, as `generate` writes it) or of a live
// `imuemu listen --out` capture, with confidence intervals and the five-term
// IEEE Std 952 fit (core/allan/allan.hpp); a table, --json, and --png through
// scripts/plot_allan.py (the C++ side does no plotting). docs/allan.md.
//
// The file is read once, streaming, in large blocks: only the selected axes'
// values are kept (8 bytes per sample and axis), so a 24-hour 200 Hz file
// (17.3 M rows, 2.4 GB of text) needs about 0.8 GB and a few seconds.
// The series must be uniformly sampled and unbroken: a time step off the
// nominal interval by more than half of it, or a jump of the capture's
// sequence counter, is refused naming the line.
#pragma once

#include <cstdint>
#include <iosfwd>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "core/allan/allan.hpp"

namespace CLI {
class App;
}

namespace imuemu::cli {

struct AllanArgs {
  std::string path;
  bool json = false;           // JSON on stdout instead of the table
  std::string png_path;        // non-empty: also plot (scripts/plot_allan.py)
  std::string plot_script;     // empty: the source tree's scripts/plot_allan.py
  std::string axes = "all";    // all | gyro | accel
  double rate_hz = 0.0;        // > 0: nominal rate (needed when the file has no times)
  int points_per_decade = 10;
  double max_tau_fraction = 0.25;
  double confidence = 0.90;
  double fit_min_tau_s = 0.0, fit_max_tau_s = 0.0;  // <= 0: no bound
  std::string terms = "q,n,b,k,r";                  // the fit's terms
  // A series with gaps (missing samples: a sequence jump, or a time step off
  // the nominal by more than half): "refuse" (exit 3 naming the first gap) or
  // "longest" (analyse the longest unbroken run, said on stderr and in the JSON).
  std::string gaps = "refuse";
};

// One axis' samples as read from the file.
struct AllanSeries {
  std::string name;  // gyro_x ... accel_z
  allan::SensorKind kind = allan::SensorKind::gyro;
  std::vector<double> values;  // rad/s or m/s^2
};

struct AllanInput {
  std::string format;  // "imu" or "listen"
  double tau0_s = 0.0;
  std::uint64_t rows = 0;  // samples analysed (the longest run's with --gaps longest)
  std::vector<AllanSeries> series;
  // --gaps longest: the gaps found, the file's data rows, and the run analysed
  // (1-based file lines of its first and last sample). gaps == 0: the whole file.
  std::uint64_t gaps = 0;
  std::uint64_t file_rows = 0;
  std::size_t first_line = 0, last_line = 0;
};

// The reader's number parser for the plain decimal syntax of every CSV
// imuemu writes ([+-]digits[.digits][(e|E)[+-]digits]; digits beyond the
// 19th significant one are dropped, < 1e-18 relative; magnitude within 1e-290 .. 1e290): the value within
// one ulp of the correctly rounded double (exact for up to 15 digits and
// exponents within +-22; otherwise one rounding in 80-bit long double and one
// to double), about 10x faster than std::from_chars here. Returns false for
// anything else (NaN, inf, hex, more digits, garbage), which the reader then
// gives to io::try_parse_double, the exact parser that also names the
// problem. An Allan variance cannot tell 1 ulp.
bool parse_plain_decimal(std::string_view text, double& out) noexcept;

// Reads the file (throws io::CsvFormatError naming file:line:column, or
// std::invalid_argument for options).
// longest_run: a gap ends a run instead of refusing the file, and the
// longest run (the first of equal ones) is returned.
AllanInput read_allan_input(const std::string& path, const std::string& axes, double rate_hz, bool longest_run = false);

nlohmann::json allan_json(const AllanInput& input, const std::vector<allan::Analysis>& analyses,
                          const AllanArgs& args);

// The analysis options of the command line (throws std::invalid_argument
// for a bad option).
allan::AnalysisOptions allan_options(const AllanArgs& args);

// What `imuemu allan` does between reading and printing: allan::analyse on
// every series (two threads), each series' values freed once analysed. The
// first axis' exception is rethrown (std::invalid_argument: too short).
// Tests call it on series generated in memory, so they take the command's
// path without a multi-gigabyte CSV.
std::vector<allan::Analysis> analyse_allan_input(AllanInput& in, const allan::AnalysisOptions& options);

// The command; messages to err. Exit codes (daemon/cli/commands.hpp): kOk,
// kBadInput for a malformed file, kCannotProcess for a valid file that cannot
// be analysed (too short), kUsageError for bad options, kOutputError when the
// plot cannot be made.
int run_allan(const AllanArgs& args, std::ostream& out, std::ostream& err);

void add_allan_command(CLI::App& app, int& exit_code);

}  // namespace imuemu::cli
