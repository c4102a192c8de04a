// `imuemu allan` (daemon/cli/allan_command.hpp) on files: what io::write_imu_csv
// writes and what `imuemu listen --out` writes (header copied from
// daemon/cli/listen_command.cpp), the coefficients it reports in datasheet units
// against the noise put in, and every refusal naming file:line.
#include <gtest/gtest.h>

#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "daemon/cli/allan_command.hpp"
#include "daemon/cli/commands.hpp"
#include "io/sample_writers.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_cli_test_allan_command {
namespace imuemu { using namespace ::imuemu; }

namespace cli = imuemu::cli;
namespace fs = std::filesystem;

namespace {

class AllanCommand : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("imuemu_test_allan_" + std::to_string(::getpid()) + "_" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }

  int run(cli::AllanArgs args) {
    out_.str("");
    err_.str("");
    return cli::run_allan(args, out_, err_);
  }
  static void write_text(const std::string& p, const std::string& text) { std::ofstream(p) << text; }

  fs::path dir_;
  std::ostringstream out_, err_;
};

constexpr double kTau0 = 0.005;  // 200 Hz

// Static IMU: white gyro noise of density N (rad/s/sqrt(Hz)) on every gyro
// axis, white accel noise of density A, gravity on z.
std::vector<imuemu::ImuSample> white_samples(std::size_t n, double gyro_n, double accel_n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::vector<imuemu::ImuSample> s(n);
  for (std::size_t k = 0; k < n; ++k) {
    s[k].t_ns = static_cast<imuemu::TimeNs>(k) * 5'000'000;
    for (int a = 0; a < 3; ++a) {
      s[k].gyro_rad_s[a] = gyro_n / std::sqrt(kTau0) * normal(rng);
      s[k].accel_m_s2[a] = accel_n / std::sqrt(kTau0) * normal(rng) + (a == 2 ? -9.80665 : 0.0);
    }
  }
  return s;
}

std::string listen_header() {
  return "sequence,t_ns,gyro_x_rad_s,gyro_y_rad_s,gyro_z_rad_s,accel_x_m_s2,accel_y_m_s2,accel_z_m_s2,"
         "dtheta_x_rad,dtheta_y_rad,dtheta_z_rad,dv_x_m_s,dv_y_m_s,dv_z_m_s,status\n";
}

std::string listen_row(const std::string& sequence, const std::string& t_ns, const imuemu::ImuSample& s) {
  char b[512];
  std::snprintf(b, sizeof b, "%s,%s,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,0,0,0,0,0,0,0\n", sequence.c_str(),
                t_ns.c_str(), s.gyro_rad_s.x(), s.gyro_rad_s.y(), s.gyro_rad_s.z(), s.accel_m_s2.x(),
                s.accel_m_s2.y(), s.accel_m_s2.z());
  return b;
}

}  // namespace

// 1 h of white noise at 200 Hz: ARW and VRW come back in datasheet units
// within 3 % (the white term's formal sigma here is ~0.1 %; its estimate uses
// every tau), the other terms far below it.
TEST_F(AllanCommand, ImuCsvWhiteNoiseInDatasheetUnits) {
  const double arw_deg_rt_h = 0.3;                                    // deg/sqrt(h)
  const double gyro_n = arw_deg_rt_h * std::numbers::pi / 180.0 / 60.0;  // rad/s/sqrt(Hz)
  const double accel_ug_rt_hz = 70.0;
  const double accel_n = accel_ug_rt_hz * 9.80665e-6;
  const std::string file = path("white.csv");
  imuemu::io::write_imu_csv(file, white_samples(720'000, gyro_n, accel_n, 3));
  cli::AllanArgs args;
  args.path = file;
  args.json = true;
  ASSERT_EQ(run(args), cli::kOk) << err_.str();
  const nlohmann::json j = nlohmann::json::parse(out_.str());
  EXPECT_EQ(j["format"], "imu");
  EXPECT_EQ(j["samples"], 720000);
  EXPECT_NEAR(j["tau0_s"].get<double>(), kTau0, 1e-15);
  ASSERT_EQ(j["axes"].size(), 6u);
  for (int a = 0; a < 6; ++a) {
    const nlohmann::json& ax = j["axes"][static_cast<std::size_t>(a)];
    const nlohmann::json& w = ax["terms"]["white"];
    if (a < 3) {
      EXPECT_EQ(ax["sensor"], "gyro");
      EXPECT_NEAR(w["units"]["deg/sqrt(h)"]["value"].get<double>() / arw_deg_rt_h, 1.0, 0.03) << ax["name"];
    } else {
      EXPECT_EQ(ax["sensor"], "accel");
      EXPECT_NEAR(w["units"]["ug/sqrt(Hz)"]["value"].get<double>() / accel_ug_rt_hz, 1.0, 0.03) << ax["name"];
    }
    const std::vector<double> tau = ax["tau_s"], adev = ax["adev"], lo = ax["ci_low"], hi = ax["ci_high"];
    ASSERT_EQ(tau.size(), adev.size());
    for (std::size_t i = 0; i < tau.size(); ++i) {
      EXPECT_LE(lo[i], adev[i]);
      EXPECT_GE(hi[i], adev[i]);
    }
  }
  // The table names the axes and the datasheet units.
  args.json = false;
  ASSERT_EQ(run(args), cli::kOk);
  EXPECT_NE(out_.str().find("gyro_z (rad/s)"), std::string::npos);
  EXPECT_NE(out_.str().find("deg/sqrt(h)"), std::string::npos);
  EXPECT_NE(out_.str().find("ug/sqrt(Hz)"), std::string::npos);
}

// A live capture: the listen CSV, with its sequence counter; the same noise
// gives the same figure; a missing sample or a capture without times is
// refused unless --rate gives the interval.
TEST_F(AllanCommand, ListenCapture) {
  const double gyro_n = 1e-3;
  const std::vector<imuemu::ImuSample> s = white_samples(100'000, gyro_n, 1e-3, 4);
  std::string text = listen_header();
  for (std::size_t k = 0; k < s.size(); ++k) text += listen_row(std::to_string(1000 + k), std::to_string(s[k].t_ns), s[k]);
  write_text(path("listen.csv"), text);
  cli::AllanArgs args;
  args.path = path("listen.csv");
  args.json = true;
  args.axes = "gyro";
  ASSERT_EQ(run(args), cli::kOk) << err_.str();
  const nlohmann::json j = nlohmann::json::parse(out_.str());
  EXPECT_EQ(j["format"], "listen");
  ASSERT_EQ(j["axes"].size(), 3u);
  EXPECT_NEAR(j["axes"][0]["terms"]["white"]["value"].get<double>() / gyro_n, 1.0, 0.05);

  // Without times (mip-like: no counter, no time) only with --rate.
  std::string timeless = listen_header();
  for (std::size_t k = 0; k < 5000; ++k) timeless += listen_row("", "", s[k]);
  write_text(path("timeless.csv"), timeless);
  args.path = path("timeless.csv");
  EXPECT_EQ(run(args), cli::kUsageError);
  EXPECT_NE(err_.str().find("--rate"), std::string::npos) << err_.str();
  args.rate_hz = 200.0;
  ASSERT_EQ(run(args), cli::kOk) << err_.str();
  EXPECT_NEAR(nlohmann::json::parse(out_.str())["tau0_s"].get<double>(), kTau0, 1e-15);

  // A dropped frame: sequence 1000..1009, then 1011 on line 12.
  std::string gap = listen_header();
  for (std::size_t k = 0; k < 100; ++k)
    gap += listen_row(std::to_string(1000 + k + (k >= 10 ? 1 : 0)), std::to_string(s[k].t_ns), s[k]);
  write_text(path("gap.csv"), gap);
  args.path = path("gap.csv");
  args.rate_hz = 0.0;
  EXPECT_EQ(run(args), cli::kBadInput);
  EXPECT_NE(err_.str().find("gap.csv:12"), std::string::npos) << err_.str();
  EXPECT_NE(err_.str().find("sequence 1011 after 1009"), std::string::npos) << err_.str();
}

TEST_F(AllanCommand, BadInputNamesFileLineAndColumn) {
  const std::vector<imuemu::ImuSample> s = white_samples(200, 1e-3, 1e-3, 5);
  const std::string header = std::string(imuemu::io::kImuCsvHeader) + "\n";
  auto row = [&](std::size_t k, const std::string& t, const std::string& gyro_y) {
    char b[400];
    std::snprintf(b, sizeof b, "%s,%.17g,%s,%.17g,%.17g,%.17g,%.17g\n", t.c_str(), s[k].gyro_rad_s.x(), gyro_y.c_str(),
                  s[k].gyro_rad_s.z(), s[k].accel_m_s2.x(), s[k].accel_m_s2.y(), s[k].accel_m_s2.z());
    return std::string(b);
  };
  auto body = [&](std::size_t bad_k, const std::string& bad_t, const std::string& bad_gyro_y) {
    std::string text = "# a comment line\n" + header;  // data row k is on line k + 3
    for (std::size_t k = 0; k < s.size(); ++k) {
      const std::string t = k == bad_k && !bad_t.empty() ? bad_t : std::to_string(s[k].t_ns);
      const std::string g = k == bad_k && !bad_gyro_y.empty() ? bad_gyro_y : std::to_string(s[k].gyro_rad_s.y());
      text += row(k, t, g);
    }
    return text;
  };
  cli::AllanArgs args;
  args.path = path("bad.csv");

  write_text(args.path, body(40, "", "nan"));
  EXPECT_EQ(run(args), cli::kBadInput);
  EXPECT_NE(err_.str().find("bad.csv:43: column 'gyro_y_rad_s' (3)"), std::string::npos) << err_.str();
  EXPECT_NE(err_.str().find("finite number"), std::string::npos) << err_.str();

  write_text(args.path, body(60, std::to_string(s[60].t_ns + 5'000'000), ""));  // a skipped sample
  EXPECT_EQ(run(args), cli::kBadInput);
  EXPECT_NE(err_.str().find("bad.csv:63: column 'time_ns' (1)"), std::string::npos) << err_.str();
  EXPECT_NE(err_.str().find("uniformly sampled"), std::string::npos) << err_.str();

  write_text(args.path, body(70, std::to_string(s[69].t_ns), ""));  // time not increasing
  EXPECT_EQ(run(args), cli::kBadInput);
  EXPECT_NE(err_.str().find("bad.csv:73"), std::string::npos) << err_.str();

  write_text(args.path, body(80, "1.5", ""));
  EXPECT_EQ(run(args), cli::kBadInput);
  EXPECT_NE(err_.str().find("bad.csv:83: column 'time_ns'"), std::string::npos) << err_.str();

  write_text(args.path, "time_ns,gyro_x_rad_s,gyro_y_rad_s,gyro_z_rad_s,accel_x_m_s2,accel_y_m_s2,accel_z_m_s2,extra\n");
  EXPECT_EQ(run(args), cli::kBadInput);
  EXPECT_NE(err_.str().find("bad.csv:1: column 'extra' (8)"), std::string::npos) << err_.str();

  write_text(args.path, header + "0,1,2,3\n");
  EXPECT_EQ(run(args), cli::kBadInput);
  EXPECT_NE(err_.str().find("bad.csv:2"), std::string::npos) << err_.str();

  write_text(args.path, "");
  EXPECT_EQ(run(args), cli::kBadInput);
  EXPECT_NE(err_.str().find("no header"), std::string::npos) << err_.str();

  args.path = path("missing.csv");
  EXPECT_EQ(run(args), cli::kBadInput);
  EXPECT_NE(err_.str().find("missing.csv"), std::string::npos) << err_.str();

  // Valid but too short for the analysis.
  std::string short_text = header;
  for (std::size_t k = 0; k < 20; ++k) short_text += row(k, std::to_string(s[k].t_ns), std::to_string(s[k].gyro_rad_s.y()));
  args.path = path("short.csv");
  write_text(args.path, short_text);
  EXPECT_EQ(run(args), cli::kCannotProcess);
  EXPECT_NE(err_.str().find("too short"), std::string::npos) << err_.str();

  // Options.
  args.terms = "n,x";
  EXPECT_EQ(run(args), cli::kUsageError);
  EXPECT_NE(err_.str().find("'x'"), std::string::npos);
}

// --png runs scripts/plot_allan.py under /usr/bin/python3 and leaves a PNG.
TEST_F(AllanCommand, PngThroughThePlotScript) {
  const std::string file = path("white.csv");
  imuemu::io::write_imu_csv(file, white_samples(20'000, 1e-3, 1e-3, 6));
  cli::AllanArgs args;
  args.path = file;
  args.axes = "gyro";
  args.png_path = path("out.png");
  args.plot_script = std::string(IMUEMU_SOURCE_DIR) + "/scripts/plot_allan.py";
  ASSERT_EQ(run(args), cli::kOk) << err_.str();
  std::ifstream png(args.png_path, std::ios::binary);
  char magic[8] = {};
  png.read(magic, 8);
  EXPECT_EQ(std::string(magic + 1, 3), "PNG");
  args.plot_script = path("no_such_script.py");
  EXPECT_EQ(run(args), cli::kOutputError);
}

// The reader's fast number parser against std::from_chars (the exact
// reference): within one ulp for shortest round-trip, %.17g and %.6e forms of
// values over 80 decades, exact where Clinger's fast path applies, and
// declining (so the exact reader refuses and names it) everything else.
TEST(AllanFastParser, WithinOneUlpOfFromCharsAndDeclinesTheRest) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> mant(-1.0, 1.0);
  std::uniform_int_distribution<int> expo(-40, 40);
  int exact = 0, one_ulp = 0, declined = 0;
  for (int i = 0; i < 300'000; ++i) {
    const double x = mant(rng) * std::pow(10.0, expo(rng));
    char buffers[3][64];
    const auto r = std::to_chars(buffers[0], buffers[0] + 64, x);
    *r.ptr = '\0';
    std::snprintf(buffers[1], 64, "%.17g", x);
    std::snprintf(buffers[2], 64, "%.6e", x);
    for (const char* b : buffers) {
      const std::string_view text(b);
      double reference = 0.0;
      std::from_chars(text.data(), text.data() + text.size(), reference);
      double fast = 0.0;
      if (!cli::parse_plain_decimal(text, fast)) {
        if (++declined < 5) ADD_FAILURE() << "declined " << text;
        continue;
      }
      if (fast == reference) {
        ++exact;
      } else {
        ++one_ulp;
        EXPECT_TRUE(std::nextafter(reference, fast) == fast) << text << " fast " << fast << " exact " << reference;
      }
    }
  }
  EXPECT_EQ(declined, 0);
  EXPECT_LT(one_ulp, exact / 100);      // double rounding is rare
  double v = 0.0;
  EXPECT_TRUE(cli::parse_plain_decimal("9.80665", v));
  EXPECT_EQ(v, 9.80665);
  EXPECT_TRUE(cli::parse_plain_decimal("-0", v));
  EXPECT_TRUE(std::signbit(v));
  EXPECT_TRUE(cli::parse_plain_decimal("12345678901234567890123.5", v));
  EXPECT_EQ(v, 12345678901234567890123.5);
  EXPECT_TRUE(cli::parse_plain_decimal("+.5e1", v));
  EXPECT_EQ(v, 5.0);
  for (const char* bad : {"", "-", "+", ".", "e5", "1e", "1e+", "1.2.3", "nan", "inf", "-Infinity", "0x1p3", "1,5",
                          " 1", "1 ", "1e99999", "1e-300"})
    EXPECT_FALSE(cli::parse_plain_decimal(bad, v)) << bad;
}

// A capture with dropped ticks (what `imuemu listen --out` writes when the
// emitter drops late ticks: the sequence and the time jump together) and an
// IMU CSV with a time gap. As `imuemu allan --help` says (--gaps): refused by
// default naming the line, with the remedies; with --gaps longest the longest
// unbroken run is analysed, exactly as a file holding only that run would be,
// and named on stderr and in the JSON. Repeated samples are refused either way.
TEST_F(AllanCommand, DroppedTicksAndTimeGaps) {
  const std::vector<imuemu::ImuSample> s = white_samples(60'000, 1e-3, 1e-3, 6);
  const auto dropped = [](std::size_t k) { return k == 10'000 || k == 25'000 || k == 25'001 || k == 40'000; };
  std::string capture = listen_header(), last_run = listen_header();
  for (std::size_t k = 0; k < s.size(); ++k) {
    if (dropped(k)) continue;
    const std::string row = listen_row(std::to_string(k), std::to_string(s[k].t_ns), s[k]);
    capture += row;
    if (k > 40'000) last_run += row;
  }
  write_text(path("dropped.csv"), capture);
  write_text(path("last_run.csv"), last_run);
  cli::AllanArgs args;
  args.path = path("dropped.csv");
  args.json = true;
  args.axes = "gyro";
  // Refused: the first gap is sample 10000; sample 10001 is file line 10002
  // (header on line 1, sample k < 10000 on line k + 2).
  EXPECT_EQ(run(args), cli::kBadInput);
  EXPECT_NE(err_.str().find("dropped.csv:10002: column 'sequence' (1): sequence 10001 after 9999 (line 10001): 1 sample missing"),
            std::string::npos) << err_.str();
  EXPECT_NE(err_.str().find("--gaps longest"), std::string::npos) << err_.str();
  EXPECT_NE(err_.str().find("--late-ticks send"), std::string::npos) << err_.str();
  EXPECT_EQ(out_.str(), "");

  // --gaps longest: runs of 10000, 14999, 14998 and 19999 samples; the last
  // (samples 40001..59999, file lines 39999..59997) is analysed.
  args.gaps = "longest";
  ASSERT_EQ(run(args), cli::kOk) << err_.str();
  const nlohmann::json j = nlohmann::json::parse(out_.str());
  EXPECT_EQ(j["samples"], 19'999);
  EXPECT_EQ(j["gaps"]["count"], 3);
  EXPECT_EQ(j["gaps"]["file_samples"], 59'996);
  EXPECT_EQ(j["gaps"]["first_line"], 39'999);
  EXPECT_EQ(j["gaps"]["last_line"], 59'997);
  EXPECT_NEAR(j["tau0_s"].get<double>(), kTau0, 1e-15);
  EXPECT_NE(err_.str().find("3 gaps (missing samples); analysing the longest unbroken run, lines 39999..59997 (19999 of 59996 samples)"),
            std::string::npos) << err_.str();
  args.path = path("last_run.csv");
  ASSERT_EQ(run(args), cli::kOk) << err_.str();
  const nlohmann::json alone = nlohmann::json::parse(out_.str());
  EXPECT_FALSE(alone.contains("gaps"));
  for (std::size_t a = 0; a < 3; ++a) {
    EXPECT_EQ(j["axes"][a]["tau_s"], alone["axes"][a]["tau_s"]) << a;
    EXPECT_EQ(j["axes"][a]["adev"], alone["axes"][a]["adev"]) << a;
  }

  // An IMU CSV (no counter) whose clock jumps 1 s after sample 29999: refused
  // naming the step, or the longer side (30000 samples, lines 32002..) analysed.
  std::vector<imuemu::ImuSample> jumped = s;
  for (std::size_t k = 30'000; k < jumped.size(); ++k) jumped[k].t_ns += 1'000'000'000;
  imuemu::io::write_imu_csv(path("jump.csv"), jumped);
  args.path = path("jump.csv");
  args.gaps = "refuse";
  EXPECT_EQ(run(args), cli::kBadInput);
  EXPECT_NE(err_.str().find("jump.csv:30002: column 'time_ns' (1): time step 1005000000 ns from line 30001 is off the nominal 5000000 ns"),
            std::string::npos) << err_.str();
  args.gaps = "longest";
  ASSERT_EQ(run(args), cli::kOk) << err_.str();
  const nlohmann::json jumped_json = nlohmann::json::parse(out_.str());
  EXPECT_EQ(jumped_json["samples"], 30'000);
  EXPECT_EQ(jumped_json["gaps"]["count"], 1);
  EXPECT_EQ(jumped_json["gaps"]["first_line"], 2);  // the first of the two equal runs
  EXPECT_EQ(jumped_json["gaps"]["last_line"], 30'001);
  EXPECT_NEAR(jumped_json["tau0_s"].get<double>(), kTau0, 1e-15);

  // A repeated sample is no gap: refused with --gaps longest too.
  std::string repeated = listen_header();
  for (std::size_t k = 0; k < 100; ++k) repeated += listen_row(std::to_string(k == 50 ? 49 : k), std::to_string(s[k].t_ns), s[k]);
  write_text(path("repeated.csv"), repeated);
  args.path = path("repeated.csv");
  EXPECT_EQ(run(args), cli::kBadInput);
  EXPECT_NE(err_.str().find("repeated.csv:52: column 'sequence' (1): sequence 49 after 49"), std::string::npos) << err_.str();
}
}  // namespace unity_cli_test_allan_command
