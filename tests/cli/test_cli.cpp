// The imuemu command line end to end: exit codes, error messages naming the
// file/line/column, no output left behind on failure, and the closed loop of
// acceptance item 5 (generate -> verify) with asserted drift bounds.
#include "tests/support/sanitizer.hpp"
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/wait.h>

#include "tests/support/spawn.hpp"

#include <iostream>

#include <algorithm>
#include <cstdio>
#include <functional>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace fs = std::filesystem;

namespace {

struct CliRun {
  int exit_code;
  std::string output;  // stdout + stderr
};

CliRun run(const std::string& args) {
  const std::string cmd = std::string(IMUEMU_CLI_PATH) + " " + args + " 2>&1";
  CliRun r{-1, {}};
  FILE* p = ::popen(cmd.c_str(), "r");
  if (!p) return r;
  char buf[4096];
  std::size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) r.output.append(buf, n);
  const int status = ::pclose(p);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

class Cli : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("imuemu_cli_" + std::to_string(::getpid()) + "_" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  void write(const std::string& name, const std::string& text) const { std::ofstream(path(name)) << text; }
  fs::path dir_;
};

// Seconds of flight for the closed loop: one hour normally; ten minutes under
// the sanitizers, which are ~20x slower.
#if IMUEMU_UNDER_ASAN
constexpr int kFlightSeconds = 600;
#else
constexpr int kFlightSeconds = 3600;
#endif

}  // namespace

TEST_F(Cli, HelpAndUsageErrors) {
  EXPECT_EQ(run("--help").exit_code, 0);
  EXPECT_EQ(run("generate --help").exit_code, 0);
  EXPECT_EQ(run("").exit_code, 2);
  EXPECT_EQ(run("generate --in x.csv").exit_code, 2);  // --out missing
  EXPECT_EQ(run("generate --in x.csv --out y.csv --rate 0").exit_code, 2);
}

TEST_F(Cli, MalformedInputNamesFileLineAndColumnAndLeavesNoOutput) {
  write("bad.csv",
        "time_s,lat_deg,lon_deg,h_m,heading_deg,pitch_deg,roll_deg\n"
        "0,41,2,100,0,0,0\n"
        "1,41,2,100,0,0,0\n"
        "2,91.5,2,100,0,0,0\n");
  const CliRun r = run("generate --quiet --in " + path("bad.csv") + " --out " + path("imu.csv"));
  EXPECT_EQ(r.exit_code, 3) << r.output;
  EXPECT_NE(r.output.find("bad.csv:4"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("lat_deg"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(path("imu.csv")));
  for (const auto& e : fs::directory_iterator(dir_)) EXPECT_EQ(e.path().filename(), "bad.csv");
}

TEST_F(Cli, DuplicateTimeIsRejected) {
  write("dup.csv",
        "time_s,north_m,east_m,down_m,heading_deg,pitch_deg,roll_deg\n"
        "0,0,0,0,0,0,0\n1,1,0,0,0,0,0\n1,2,0,0,0,0,0\n");
  const CliRun r = run("generate --quiet --scene flat --in " + path("dup.csv") + " --out " + path("imu.csv"));
  EXPECT_EQ(r.exit_code, 3) << r.output;
  EXPECT_NE(r.output.find("dup.csv:4"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(path("imu.csv")));
}

TEST_F(Cli, AntipodalKnotsAreReportedNamingBothKnots) {
  // Heading 0 then 180 deg: R_{0}^T R_{1} has trace -1, the geodesic is not unique.
  write("anti.csv",
        "time_s,north_m,east_m,down_m,heading_deg,pitch_deg,roll_deg\n"
        "0,0,0,0,0,0,0\n1,1,0,0,10,0,0\n2,2,0,0,190,0,0\n3,3,0,0,190,0,0\n");
  const CliRun r = run("generate --quiet --scene flat --in " + path("anti.csv") + " --out " + path("imu.csv"));
  EXPECT_EQ(r.exit_code, 4) << r.output;
  EXPECT_NE(r.output.find("antipodal"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("knots 1"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(path("imu.csv")));
}

TEST_F(Cli, LocalPositionsInTheEcefSceneAreRefused) {
  write("ned.csv", "time_s,north_m,east_m,down_m,heading_deg,pitch_deg,roll_deg\n0,0,0,0,0,0,0\n1,1,0,0,0,0,0\n");
  const CliRun r = run("generate --quiet --scene ecef --in " + path("ned.csv") + " --out " + path("imu.csv"));
  EXPECT_EQ(r.exit_code, 3) << r.output;
  EXPECT_NE(r.output.find("ned.csv:2"), std::string::npos) << r.output;
}

TEST_F(Cli, ClosedLoopOneHourFlightDriftStaysWithinBounds) {
  // Acceptance item 5: the ideal IMU of the flight, integrated back by
  // `imuemu verify`, against the smoothed trajectory it was derived from.
  const std::string traj = path("flight.csv");
  ASSERT_EQ(run("sample-trajectory --kind flight --duration-s " + std::to_string(kFlightSeconds) + " --out " + traj)
                .exit_code, 0);
  for (const std::string scene : {"ecef", "flat"}) {
    const std::string imu = path(scene + "_imu.csv"), smooth = path(scene + "_smooth.csv");
    const CliRun g = run("generate --quiet --scene " + scene + " --rate 200 --in " + traj + " --out " + imu +
                      " --trajectory-out " + smooth);
    ASSERT_EQ(g.exit_code, 0) << g.output;
    // Bounds: the emitted IMU is the exact derivative of the emitted
    // trajectory (kernel derivatives, exact for quadratics on the grid), so
    // integrated back with 4th-order Runge-Kutta it stays on it: measured over
    // the hour at 200 Hz, ecef 9.2e-6 m, flat 2.6e-5 m, attitude 9e-13 rad.
    // Asserted at the accuracy issue's targets: 1e-3 m (flat's target; ecef's
    // is 0.1 m) and 1e-7 rad (target 1e-6 rad).
    const std::string bound = "1e-3";
    const CliRun v = run("verify --scene " + scene + " --imu " + imu + " --trajectory " + smooth +
                      (scene == "ecef" ? " --aid-vertical" : "") + " --start-s 1 --report-every-s 600" +
                      " --max-position-error-m " + bound + " --max-attitude-error-rad 1e-7");
    std::cout << v.output;
    EXPECT_EQ(v.exit_code, 0) << v.output;
    EXPECT_NE(v.output.find("# max: position"), std::string::npos);
  }
  // The bound is live: an impossible one fails with exit code 6.
  const CliRun tight = run("verify --scene ecef --aid-vertical --start-s 1 --imu " + path("ecef_imu.csv") +
                        " --trajectory " + path("ecef_smooth.csv") + " --max-position-error-m 1e-12");
  EXPECT_EQ(tight.exit_code, 6) << tight.output;
}

TEST_F(Cli, DemoRunsAndWritesItsFiles) {
  const CliRun r = run("demo --rate 100 --out-dir " + path("demo"));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(fs::exists(path("demo/imu.csv")));
  EXPECT_TRUE(fs::exists(path("demo/smoothed.csv")));
  EXPECT_NE(r.output.find("# max: position"), std::string::npos) << r.output;
}

namespace {
// Numeric rows of an IMU CSV (first 7 columns), skipping '#' comments and the header.
std::vector<std::vector<double>> imu_rows(const std::string& file, std::vector<std::string>* status = nullptr) {
  std::ifstream in(file);
  std::string line;
  std::vector<std::vector<double>> rows;
  bool header = true;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    if (header) {
      header = false;
      continue;
    }
    std::stringstream ss(line);
    std::string field;
    std::vector<double> row;
    for (int k = 0; k < 7 && std::getline(ss, field, ','); ++k) row.push_back(std::stod(field));
    if (status != nullptr && std::getline(ss, field, ',')) status->push_back(field);
    rows.push_back(row);
  }
  return rows;
}
}  // namespace

// `imuemu stream` replays a file through the streaming engine and the live
// emitter: paced on the monotonic clock (x20) and as fast as possible, and
// from stdin, the samples are exactly `imuemu generate`'s (the same engine),
// all flagged exact (no pose is late in a replay; the paced runs keep 1 s of
// trajectory time, 50 ms of wall time, as margin for a loaded machine).
TEST_F(Cli, StreamReplayEqualsGenerate) {
  ASSERT_EQ(run("sample-trajectory --kind circle --duration-s 20 --period-s 0.1 --out " + path("c.csv")).exit_code, 0);
  const CliRun g = run("generate --in " + path("c.csv") + " --out " + path("g.csv") + " --rate 200 --scene flat --delta 20 --quiet");
  ASSERT_EQ(g.exit_code, 0) << g.output;
  const auto reference = imu_rows(path("g.csv"));
  ASSERT_EQ(reference.size(), 4001u);
  // Paced replays (x20) run on the wall clock: a host too loaded to deliver
  // a pose within the margin (4 s of trajectory time, 0.2 s of wall time)
  // gets flagged extrapolated samples, which is the live path doing its job,
  // not a fault. So there, every sample flagged exact must be generate's to
  // the bit; only the unpaced replay (--speed max: no clock) must be exact
  // throughout. Real-time delivery is the loopback tests' subject.
  struct Replay {
    std::string how;
    bool paced;
  };
  for (const Replay& r : {Replay{std::string("--source file:") + path("c.csv") + " --speed 20", true},
                          Replay{std::string("--source file:") + path("c.csv") + " --speed max", false},
                          Replay{std::string("--source stdin --speed 20 < ") + path("c.csv"), true}}) {
    const std::string& how = r.how;
    const CliRun s = run("stream " + how + " --rate 200 --scene flat --knot-interval-s 0.1 --margin-s 4 --out " +
                         path("s.csv"));
    ASSERT_EQ(s.exit_code, 0) << how << "\n" << s.output;
    std::vector<std::string> status;
    const auto rows = imu_rows(path("s.csv"), &status);
    ASSERT_EQ(rows.size(), reference.size()) << how << "\n" << s.output;
    std::size_t exact_differing = 0, not_exact = 0;
    for (std::size_t i = 0; i < rows.size(); ++i) {
      if (status[i] != "exact") ++not_exact;
      else if (rows[i] != reference[i]) ++exact_differing;
    }
    std::cout << how << ": " << rows.size() - not_exact << " exact, " << not_exact << " flagged\n";
    EXPECT_EQ(exact_differing, 0u) << how;
    if (!r.paced) EXPECT_EQ(not_exact, 0u) << how << "\n" << s.output;
    else EXPECT_LT(not_exact, rows.size()) << how << "\n" << s.output;
  }
  const CliRun bad = run("stream --source carrier-pigeon --out " + path("x.csv"));
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.output.find("expected file:PATH"), std::string::npos) << bad.output;
}

// ------------------------------------------- issue 13: generate streams to its writers
// Batch generation writes each sample as it is made (daemon/cli/batch_generation.hpp);
// the in-memory path it replaced (run_batch, then the sensor stage over the
// vector, then the writers) is the reference here, byte for byte.
#include "core/pipeline.hpp"
#include "daemon/scene/error_model_config.hpp"
#include "io/atomic_file.hpp"
#include "io/sample_writers.hpp"
#include "io/scene_poses.hpp"
#include "io/trajectory_csv.hpp"
#include "core/attitude.hpp"
#include "core/earth.hpp"
#include "core/so3.hpp"
#include "io/decimal_time.hpp"

namespace {
std::string file_bytes(const std::string& p) {
  std::string text;
  EXPECT_EQ(imuemu::io::read_whole_file(p, text), 0) << p;
  return text;
}
}  // namespace

TEST_F(Cli, GenerateStreamedEqualsInMemoryBatchByteForByte) {
  using namespace imuemu;
  ASSERT_EQ(run("sample-trajectory --kind circle --duration-s 60 --period-s 0.1 --out " + path("c.csv")).exit_code, 0);
  const CliRun g = run("generate --in " + path("c.csv") + " --out " + path("g.csv") + " --trajectory-out " +
                       path("k.csv") + " --rate 200 --scene flat --delta 20 --sensor adis16470 --seed 3 --quiet");
  ASSERT_EQ(g.exit_code, 0) << g.output;
  PipelineOptions o;
  o.scene.physics = Physics::flat;
  o.scene.flat_gravity_m_s2 = Vec3(0.0, 0.0, 9.80665);
  o.rate_hz = 200;
  o.kernel.delta = 20;
  const std::vector<Pose> knots = io::poses_in_scene(io::read_trajectory_csv(path("c.csv")), Physics::flat);
  BatchResult b = run_batch(knots, o);
  ASSERT_EQ(b.imu.size(), 12001u);
  const std::uint64_t saturated = scene::apply_error_model(scene::error_model_from_option("adis16470", 3), "imu0",
                                                           200, knots.front().t_ns, b.imu);
  EXPECT_EQ(saturated, 0u);
  io::write_imu_csv(path("want_imu.csv"), b.imu);
  io::write_trajectory_csv(path("want_k.csv"), b.trajectory, Physics::flat);
  EXPECT_EQ(file_bytes(path("g.csv")), file_bytes(path("want_imu.csv")));
  EXPECT_EQ(file_bytes(path("k.csv")), file_bytes(path("want_k.csv")));
}

// F1: --trajectory-out that cannot be written refuses the run before --out is
// replaced (before, --out was written first and then the run failed, exit 5).
TEST_F(Cli, UnwritableTrajectoryOutLeavesOutUntouched) {
  ASSERT_EQ(run("sample-trajectory --kind circle --duration-s 10 --period-s 0.1 --out " + path("c.csv")).exit_code, 0);
  write("imu.csv", "old\n");
  const CliRun r = run("generate --quiet --scene flat --in " + path("c.csv") + " --out " + path("imu.csv") +
                       " --trajectory-out " + path("missing/k.csv"));
  EXPECT_EQ(r.exit_code, 5) << r.output;
  EXPECT_EQ(file_bytes(path("imu.csv")), "old\n");
  for (const auto& e : fs::directory_iterator(dir_))
    EXPECT_TRUE(e.path().filename() == "c.csv" || e.path().filename() == "imu.csv") << e.path();
}

// A run refused after samples were already streamed out (a gap beyond
// --max-gap-s at the end) replaces neither file and leaves no temporary.
TEST_F(Cli, RefusalAfterStreamingStartedLeavesNoOutput) {
  std::string text = "time_s,north_m,east_m,down_m,heading_deg,pitch_deg,roll_deg\n";
  for (int t = 0; t <= 60; ++t) text += std::to_string(t) + "," + std::to_string(10 * t) + ",0,0,0,0,0\n";
  text += "90,900,0,0,0,0,0\n";  // 30 s after the previous knot
  write("gap.csv", text);
  write("imu.csv", "old\n");
  write("k.csv", "old k\n");
  const CliRun r = run("generate --quiet --scene flat --rate 400 --in " + path("gap.csv") + " --out " + path("imu.csv") +
                       " --trajectory-out " + path("k.csv"));
  EXPECT_EQ(r.exit_code, 4) << r.output;
  EXPECT_NE(r.output.find("gap limit"), std::string::npos) << r.output;
  EXPECT_EQ(file_bytes(path("imu.csv")), "old\n");
  EXPECT_EQ(file_bytes(path("k.csv")), "old k\n");
  std::size_t files = 0;
  for (const auto& e : fs::directory_iterator(dir_)) {
    ++files;
    EXPECT_EQ(e.path().string().find(".tmp."), std::string::npos) << e.path();
  }
  EXPECT_EQ(files, 3u);
}

// ---------------------------------------------------------------- issue 13

namespace {

// Knots `step` (a decimal seconds string per index) apart in the flat scene.
std::string knots_csv(int count, const std::function<std::string(int)>& time_of) {
  std::string text = "time_s,north_m,east_m,down_m,heading_deg,pitch_deg,roll_deg\n";
  for (int i = 0; i < count; ++i) text += time_of(i) + "," + std::to_string(i) + ",0,0,0,0,0\n";
  return text;
}

// The child's exit code and peak RSS (KiB), via wait4.
struct MeasuredRun {
  int exit_code = -1;
  long max_rss_kib = 0;
  std::string output;
};

MeasuredRun run_measured(const std::vector<std::string>& args, const std::string& log_path) {
  MeasuredRun r;
  const pid_t pid = imuemu::test::spawn_logged(IMUEMU_CLI_PATH, args, log_path);
  if (pid <= 0) return r;
  int status = 0;
  struct rusage usage {};
  if (::wait4(pid, &status, 0, &usage) != pid) return r;
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  r.max_rss_kib = usage.ru_maxrss;
  std::ifstream in(log_path);
  std::stringstream text;
  text << in.rdbuf();
  r.output = text.str();
  return r;
}

}  // namespace

// C2: every option converted from seconds or Hz to int64 ns or a sample count
// is refused out of range with exit 2 naming it (was SIGABRT for --blend-s
// 1e300, --knot-interval-s 1e300 and --rate 1000000 --knot-interval-s 3600;
// --margin-s 1e300 ran with an overflowed delay). NaN passes CLI11's own
// range checks, so it is tried everywhere too.
TEST_F(Cli, SecondsAndRateOptionsOutOfRangeAreUsageErrorsNamingTheOption) {
  write("c.csv", knots_csv(5, [](int i) { return std::to_string(i); }));
  const std::string stream = "stream --source file:" + path("c.csv") + " --speed max --scene flat --out " + path("s.csv") + " ";
  const std::string gen = "generate --quiet --in " + path("c.csv") + " --scene flat --out " + path("g.csv") + " ";
  const std::vector<std::pair<std::string, std::string>> cases = {
      {stream + "--blend-s 1e300", "--blend-s"},
      {stream + "--blend-s nan", "--blend-s"},
      {stream + "--knot-interval-s 1e300", "--knot-interval-s"},
      {stream + "--rate 1000000 --knot-interval-s 3600", "--knot-interval-s"},
      {stream + "--margin-s 1e300", "--margin-s"},
      {stream + "--duration-s 1e300", "--duration-s"},
      {stream + "--max-gap-s nan", "--max-gap-s"},
      {stream + "--gravity nan", "--gravity"},
      {gen + "--gravity nan", "--gravity"},
      {gen + "--method min-accel --sigma nan", "--sigma"},
      {gen + "--method min-accel --sigma 1e308", "--sigma"},
      {gen + "--method min-accel --sigma -5", "--sigma"},  // the scene parser's range, [0, 3]
      {gen + "--method min-accel --mu 4", "--mu"},
      {gen + "--delta 0", "--delta"},
      {gen + "--max-gap-s nan", "--max-gap-s"},
      {gen + "--kernel seconds --kernel-half-width-s inf", "--kernel-half-width-s"},
      {"verify --imu x --trajectory y --gravity nan", "--gravity"},
      {"verify --imu x --trajectory y --start-s 1e300", "--start-s"},
      {"sample-trajectory --out " + path("t.csv") + " --duration-s 1e300", "--duration-s"},
      {"sample-trajectory --out " + path("t.csv") + " --period-s nan", "--period-s"},
      {"sensors --rate nan", "--rate"},
      {"emit --sample flight --device pty:" + path("p") + " --knot-interval-s 1e300", "--knot-interval-s"},
      {"emit --sample flight --device pty:" + path("p") + " --margin-s 1e300", "--margin-s"},
      {"emit --sample flight --device pty:" + path("p") + " --seconds nan", "--seconds"},
      {"emit --sample flight --device pty:" + path("p") + " --gravity nan", "--gravity"},
      {"budget --protocol native --rate nan", "--rate"},
      {"status --timeout-s nan", "--timeout-s"},
      {"status --timeout-s 1e300", "--timeout-s"},
      {"allan " + path("c.csv") + " --rate nan", "--rate"},
      {"allan " + path("c.csv") + " --fit-min-tau-s nan", "--fit-min-tau-s"},
      // listen used CLI11's NonNegativeNumber/PositiveNumber (NaN passes;
      // --duration-s 1e300 then overflowed llround(s * 1e9)).
      {"listen --protocol native --device " + path("none") + " --duration-s nan", "--duration-s"},
      {"listen --protocol native --device " + path("none") + " --duration-s 1e300", "--duration-s"},
      {"listen --protocol native --device " + path("none") + " --expect-rate nan", "--expect-rate"},
      {"listen --protocol native --device " + path("none") + " --rate-tolerance nan", "--rate-tolerance"},
  };
  for (const auto& [args, option] : cases) {
    const CliRun r = run(args);
    EXPECT_EQ(r.exit_code, 2) << args << "\n" << r.output;
    EXPECT_NE(r.output.find(option), std::string::npos) << args << "\n" << r.output;
    EXPECT_EQ(r.output.find("terminate called"), std::string::npos) << args << "\n" << r.output;
  }
  EXPECT_FALSE(fs::exists(path("g.csv")));
  // In range, the same options still run.
  EXPECT_EQ(run(stream + "--blend-s 3600 --margin-s 0").exit_code, 0);
  EXPECT_EQ(run(gen + "--method min-accel --sigma 3 --mu 0").exit_code, 0);
  EXPECT_EQ(run(gen + "--delta 0 --derivatives finite-difference").exit_code, 0);
}

// R1/R2: sizes derived from the input are checked against core/limits.hpp
// before anything is allocated for them, refused with exit 4 naming why.
TEST_F(Cli, DerivedSizesAreRefusedBeforeAllocating) {
  // 1001 knots 1 us apart at 100 Hz: one output sample (README: exit 4); was
  // rc 0 after 500 MB of virtual end knots.
  write("us.csv", knots_csv(1001, [](int i) {
          char t[32];
          std::snprintf(t, sizeof t, "0.%06d", i);
          return std::string(t);
        }));
  CliRun r = run("generate --quiet --scene flat --rate 100 --in " + path("us.csv") + " --out " + path("o.csv"));
  EXPECT_EQ(r.exit_code, 4) << r.output;
  EXPECT_NE(r.output.find("shorter than two output samples"), std::string::npos) << r.output;
  // 1 ns apart: was bad_alloc.
  write("ns.csv", knots_csv(1001, [](int i) {
          char t[32];
          std::snprintf(t, sizeof t, "0.%09d", i);
          return std::string(t);
        }));
  r = run("generate --quiet --scene flat --rate 100 --in " + path("ns.csv") + " --out " + path("o.csv"));
  EXPECT_EQ(r.exit_code, 4) << r.output;
  EXPECT_NE(r.output.find("shorter than two output samples"), std::string::npos) << r.output;
  // Two knots an hour apart at 4 kHz: the automatic window (14.4 million
  // samples) was uncapped (bad_alloc); it now meets the one window cap.
  write("hour.csv", knots_csv(2, [](int i) { return std::to_string(3600 * i); }));
  r = run("generate --quiet --scene flat --rate 4000 --max-gap-s 4000 --in " + path("hour.csv") + " --out " + path("o.csv"));
  EXPECT_EQ(r.exit_code, 4) << r.output;
  EXPECT_NE(r.output.find("automatic window"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("1000000"), std::string::npos) << r.output;
  // A sample trajectory beyond the knot cap.
  r = run("sample-trajectory --out " + path("t.csv") + " --duration-s 2000000 --period-s 0.01");
  EXPECT_EQ(r.exit_code, 4) << r.output;
  EXPECT_NE(r.output.find("knots"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(path("o.csv")));
  EXPECT_FALSE(fs::exists(path("t.csv")));
}

// R1: knots 1 us apart over 5 ms at 1 kHz are a valid trajectory, but the end
// extrapolation placed its virtual knots 1 us apart over a whole second of
// padding per end (a million knots, ~500 MB). Their number is capped
// (limits::kMaxPaddingKnots): the run succeeds in bounded memory.
TEST_F(Cli, DenseKnotsKeepTheEndPaddingBounded) {
  write("dense.csv", knots_csv(5001, [](int i) {
          char t[32];
          std::snprintf(t, sizeof t, "0.%06d", i);
          return std::string(t);
        }));
  const MeasuredRun r = run_measured({"generate", "--quiet", "--scene", "flat", "--rate", "1000", "--in", path("dense.csv"),
                                      "--out", path("o.csv")},
                                     path("log.txt"));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  // was ~500 MB; under ASan the peak is its shadow memory, not the run's
  if (!IMUEMU_UNDER_ASAN) {
    EXPECT_LT(r.max_rss_kib, 200 * 1024) << r.output;
  }
  std::ifstream in(path("o.csv"));
  std::string line;
  int rows = 0;
  while (std::getline(in, line)) ++rows;
  EXPECT_EQ(rows, 1 + 6);  // header + samples at 0..5 ms
}

// F1: --out A --trajectory-out B with B unwritable: exit 5 and A as it was
// (A used to be replaced before B failed); no temporary file left.
TEST_F(Cli, GenerateReplacesAllOutputsOrNone) {
  write("c.csv", knots_csv(5, [](int i) { return std::to_string(i); }));
  write("imu.csv", "old imu\n");
  const CliRun r = run("generate --quiet --scene flat --in " + path("c.csv") + " --out " + path("imu.csv") +
                       " --trajectory-out " + path("missing_dir/traj.csv"));
  EXPECT_EQ(r.exit_code, 5) << r.output;
  EXPECT_NE(r.output.find("missing_dir/traj.csv"), std::string::npos) << r.output;
  std::ifstream in(path("imu.csv"));
  std::stringstream text;
  text << in.rdbuf();
  EXPECT_EQ(text.str(), "old imu\n");
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(dir_)) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  EXPECT_EQ(names, (std::vector<std::string>{"c.csv", "imu.csv"}));
  // Writable: both are written.
  EXPECT_EQ(run("generate --quiet --scene flat --in " + path("c.csv") + " --out " + path("imu.csv") +
                " --trajectory-out " + path("traj.csv")).exit_code, 0);
  EXPECT_TRUE(fs::exists(path("traj.csv")));
}

// ------------------------------------------- issue 14, acceptance 3: input-convention traps
namespace {
std::vector<std::string> text_lines(const std::string& file) {
  std::ifstream in(file);
  std::vector<std::string> lines;
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}
}  // namespace

// Trap 1: ECEF positions with qw,qx,qy,qz holding q_b^e (the smoothed
// trajectory's own qw_ecef.. values under the local-level names) ran with
// exit 0 and ~18 m/s^2 of accelerometer error, silently. Now a warning gives
// the angle between the implied specific force and the body's up axis under
// both readings; the same file with the right names, and the geodetic
// heading-pitch-roll flight it came from, stay silent.
TEST_F(Cli, TrapQuaternionHoldingEcefAttitudeWarnsWithNumbers) {
  ASSERT_EQ(run("sample-trajectory --kind flight --duration-s 120 --period-s 1 --out " + path("f.csv")).exit_code, 0);
  const CliRun k = run("generate --quiet --scene ecef --rate 10 --in " + path("f.csv") + " --out " + path("fi.csv") +
                       " --trajectory-out " + path("fk.csv"));
  ASSERT_EQ(k.exit_code, 0) << k.output;
  // The same rows under the local-level names (qw..qz) and the ECEF ones.
  const auto write_under_both_names = [&](const std::string& rows, const std::string& as_local,
                                          const std::string& as_ecef) {
    write(as_local, "time_s,x_m,y_m,z_m,qw,qx,qy,qz\n" + rows);
    write(as_ecef, "time_s,x_m,y_m,z_m,qw_ecef,qx_ecef,qy_ecef,qz_ecef\n" + rows);
  };
  // Whole-second states only: the knots of the original 1 Hz file.
  std::string q_b_e_rows;
  const std::vector<std::string> lines = text_lines(path("fk.csv"));
  ASSERT_EQ(lines.front().rfind("time_s,x_m,y_m,z_m,qw_ecef,qx_ecef,qy_ecef,qz_ecef,", 0), 0u) << lines.front();
  for (std::size_t i = 1; i < lines.size(); ++i) {
    std::stringstream ss(lines[i]);
    std::string field, row;
    for (int c = 0; c < 8 && std::getline(ss, field, ','); ++c) row += (c == 0 ? "" : ",") + field;
    if (row.substr(0, row.find(',')).find('.') == std::string::npos) q_b_e_rows += row + "\n";
  }
  write_under_both_names(q_b_e_rows, "trap.csv", "right.csv");
  const CliRun t = run("generate --quiet --scene ecef --in " + path("trap.csv") + " --out " + path("o.csv"));
  std::cout << t.output;
  EXPECT_EQ(t.exit_code, 0) << t.output;  // a warning, not a refusal: the file may be what it says
  EXPECT_NE(t.output.find("warning: " + path("trap.csv") + ": the columns qw,qx,qy,qz are read as q_b^l"),
            std::string::npos) << t.output;
  EXPECT_NE(t.output.find("the file probably holds q_b^e (body to ECEF); if so, name the columns "
                          "qw_ecef,qx_ecef,qy_ecef,qz_ecef"),
            std::string::npos) << t.output;
  // The numbers: the angle read as written is far from a vehicle's (Barcelona,
  // level flight: 90 + latitude ~ 131 deg), the other reading near 0.
  const std::size_t at = t.output.find(" deg (median) from the body's up axis");
  ASSERT_NE(at, std::string::npos) << t.output;
  const double written_deg = std::stod(t.output.substr(t.output.rfind(" is ", at) + 4));
  EXPECT_GT(written_deg, 100.0);
  EXPECT_LT(written_deg, 160.0);
  // The same knots with q_b^l = R_l^e(lat, lon)^T q_b^e (Eq. 1.4, 1.5)
  // under qw..qz (right) and under qw_ecef.. (the other confusion).
  std::string q_b_l_rows;
  const imuemu::io::Trajectory ecef = imuemu::io::read_trajectory_csv(path("right.csv"));
  for (const imuemu::io::TrajectoryRecord& rec : ecef.records) {
    const imuemu::earth::Geodetic g = imuemu::earth::geodetic_from_ecef(rec.position);
    const imuemu::Mat3 R_b_l = imuemu::attitude::ned_to_ecef(g.latitude_rad, g.longitude_rad).transpose() *
                               imuemu::so3::matrix_from_quaternion(rec.attitude);
    const Eigen::Vector4d q = imuemu::so3::quaternion_from_matrix(R_b_l);
    std::string row = imuemu::io::format_decimal_seconds(rec.t_ns);
    for (double v : {rec.position.x(), rec.position.y(), rec.position.z(), q[0], q[1], q[2], q[3]})
      row += "," + imuemu::io::detail::format_double(v);
    q_b_l_rows += row + "\n";
  }
  write_under_both_names(q_b_l_rows, "local.csv", "swapped.csv");
  const CliRun sw = run("generate --quiet --scene ecef --in " + path("swapped.csv") + " --out " + path("o.csv"));
  std::cout << sw.output;
  EXPECT_NE(sw.output.find("the columns qw_ecef,qx_ecef,qy_ecef,qz_ecef are read as q_b^e"), std::string::npos)
      << sw.output;
  EXPECT_NE(sw.output.find("if so, name the columns qw,qx,qy,qz."), std::string::npos) << sw.output;
  for (const std::string f : {"right.csv", "local.csv", "f.csv"}) {
    const CliRun ok = run("generate --quiet --scene ecef --in " + path(f) + " --out " + path("o.csv"));
    EXPECT_EQ(ok.exit_code, 0) << ok.output;
    EXPECT_EQ(ok.output.find("warning"), std::string::npos) << f << ": " << ok.output;
  }
}

// Trap 2: integer nanoseconds in time_s were refused as "out of range" only.
TEST_F(Cli, TrapIntegerNanosecondTimesSayTheUnitIsSeconds) {
  write("ns.csv", "time_s,north_m,east_m,down_m,heading_deg,pitch_deg,roll_deg\n"
                  "# a tool that writes integer ns\n"
                  "1717243200123456789,0,0,0,0,0,0\n"
                  "1717243201123456789,1,0,0,0,0,0\n");
  const CliRun r = run("generate --quiet --scene flat --in " + path("ns.csv") + " --out " + path("o.csv"));
  std::cout << r.output;
  EXPECT_EQ(r.exit_code, 3) << r.output;
  EXPECT_NE(r.output.find(path("ns.csv") + ":3: column 'time_s' (1): "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("time_s is in seconds"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("divide it by 1e9 and write '1717243200.123456789'"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(path("o.csv")));
}

// Trap 3: --scene flat on Earth-scale coordinates ran without a word. Now:
// Earth-fixed input warns with what flat physics leaves out (Earth rate
// 7.29e-5 rad/s, Coriolis, gravity's turn g d/R); ECEF values in the
// north/east/down columns warn that they look like ECEF. A local circle
// stays silent.
TEST_F(Cli, TrapFlatSceneOnEarthScaleCoordinatesWarnsWithNumbers) {
  ASSERT_EQ(run("sample-trajectory --kind flight --duration-s 60 --period-s 1 --out " + path("f.csv")).exit_code, 0);
  const CliRun g = run("generate --quiet --scene flat --in " + path("f.csv") + " --out " + path("o.csv"));
  std::cout << g.output;
  EXPECT_EQ(g.exit_code, 0) << g.output;
  EXPECT_NE(g.output.find("warning: " + path("f.csv") + ": --scene flat on Earth-fixed"), std::string::npos) << g.output;
  EXPECT_NE(g.output.find("Earth rate (7.29e-05 rad/s in the gyros)"), std::string::npos) << g.output;
  EXPECT_NE(g.output.find("m/s^2 in the accelerometers); --scene ecef has them all"), std::string::npos) << g.output;

  // ECEF coordinates (Barcelona) under north_m,east_m,down_m.
  write("ned.csv", "time_s,north_m,east_m,down_m,heading_deg,pitch_deg,roll_deg\n"
                   "0,4789000.0,176000.0,4194000.0,0,0,0\n"
                   "1,4789010.0,176000.0,4194000.0,0,0,0\n"
                   "2,4789020.0,176000.0,4194000.0,0,0,0\n");
  const CliRun n = run("generate --quiet --scene flat --in " + path("ned.csv") + " --out " + path("o.csv"));
  std::cout << n.output;
  EXPECT_NE(n.output.find("warning: " + path("ned.csv") + ":4: the flat scene's local NED position"), std::string::npos)
      << n.output;
  EXPECT_NE(n.output.find("6.37e+06 m from the frame origin"), std::string::npos) << n.output;
  EXPECT_NE(n.output.find("these look like ECEF coordinates; name the columns x_m,y_m,z_m"), std::string::npos)
      << n.output;

  ASSERT_EQ(run("sample-trajectory --kind circle --duration-s 20 --period-s 0.1 --out " + path("c.csv")).exit_code, 0);
  const CliRun c = run("generate --quiet --scene flat --in " + path("c.csv") + " --out " + path("o.csv"));
  EXPECT_EQ(c.exit_code, 0) << c.output;
  EXPECT_EQ(c.output.find("warning"), std::string::npos) << c.output;
}

// Trap 4: the --delta help said "two median knot intervals"; the default
// method (hermite) uses one (daemon/cli/commands.cpp auto_delta), the others two.
// The summary line shows what the code chose: 1 Hz knots at 400 Hz.
TEST_F(Cli, TrapDeltaHelpSaysWhatTheCodeDoes) {
  const CliRun h = run("generate --help");
  EXPECT_EQ(h.output.find("default: two median knot intervals"), std::string::npos) << h.output;
  EXPECT_NE(h.output.find("default: one median knot interval of output samples with --method hermite, the default, "
                          "two with the other methods"),
            std::string::npos) << h.output;
  ASSERT_EQ(run("sample-trajectory --kind circle --duration-s 30 --period-s 1 --out " + path("c.csv")).exit_code, 0);
  const CliRun hermite = run("generate --scene flat --rate 400 --in " + path("c.csv") + " --out " + path("o.csv"));
  EXPECT_NE(hermite.output.find("(flat, hermite, Delta 400,"), std::string::npos) << hermite.output;
  const CliRun geodesic =
      run("generate --scene flat --rate 400 --method geodesic --in " + path("c.csv") + " --out " + path("o.csv"));
  EXPECT_NE(geodesic.output.find("(flat, geodesic, Delta 800,"), std::string::npos) << geodesic.output;
}

// Trap 5: `imuemu stream --speed max` said "samples 0 exact" after writing
// every row exact, and wrote %.17g where generate writes the shortest exact
// form. Now its seven IMU fields are generate's bytes and the count is right.
TEST_F(Cli, TrapStreamWritesGenerateBytesAndCountsItsRows) {
  ASSERT_EQ(run("sample-trajectory --kind circle --duration-s 20 --period-s 0.1 --out " + path("c.csv")).exit_code, 0);
  ASSERT_EQ(run("generate --quiet --in " + path("c.csv") + " --out " + path("g.csv") + " --rate 200 --scene flat --delta 20")
                .exit_code,
            0);
  const CliRun s = run("stream --source file:" + path("c.csv") + " --speed max --rate 200 --scene flat "
                       "--knot-interval-s 0.1 --out " + path("s.csv"));
  ASSERT_EQ(s.exit_code, 0) << s.output;
  std::cout << s.output;
  const std::vector<std::string> g = text_lines(path("g.csv")), st = text_lines(path("s.csv"));
  ASSERT_EQ(g.size(), 4002u);
  ASSERT_EQ(st.size(), g.size());
  std::size_t differing = 0;
  for (std::size_t i = 1; i < g.size(); ++i)
    if (st[i] != g[i] + ",exact") ++differing;
  EXPECT_EQ(differing, 0u) << st[1] << "\n" << g[1];
  EXPECT_NE(s.output.find("samples 4001 exact, 0 extrapolated"), std::string::npos) << s.output;
}

// Trap 6: gap messages rounded times to us (std::to_string of a double) and
// named 0-based knot indices. Now: exact decimal seconds and file lines.
TEST_F(Cli, TrapGapMessageNamesExactTimesAndFileLines) {
  std::string text = "time_s,north_m,east_m,down_m,heading_deg,pitch_deg,roll_deg\n";
  for (int t = 0; t <= 60; ++t) text += std::to_string(1700000000 + t) + ".123456789," + std::to_string(10 * t) + ",0,0,0,0,0\n";
  text += "1700000090.000000001,900,0,0,0,0,0\n";  // line 63, 29.876543212 s after line 62
  write("gap.csv", text);
  const CliRun r = run("generate --quiet --scene flat --in " + path("gap.csv") + " --out " + path("o.csv"));
  std::cout << r.output;
  EXPECT_EQ(r.exit_code, 4) << r.output;
  EXPECT_NE(r.output.find("the knot at " + path("gap.csv") + ":62 (t=1700000060.123456789 s) and the knot at " +
                          path("gap.csv") + ":63 (t=1700000090.000000001 s) are 29.876543212 s apart, more than the "
                          "10 s gap limit"),
            std::string::npos) << r.output;
}

// Trap 7: `nan` heading at a pole was refused as "not finite" only. At a
// pole heading from north is undefined, and the record gives nothing else
// about the rotation about the vertical: refused, saying how to write it.
// A nan heading elsewhere keeps the plain message.
TEST_F(Cli, TrapNanHeadingAtAPoleSaysHowToWriteThePole) {
  write("pole.csv", "time_s,lat_deg,lon_deg,h_m,heading_deg,pitch_deg,roll_deg\n"
                    "0,89.99,0,100,180,0,0\n"
                    "1,90,0,100,nan,0,0\n"
                    "2,89.99,180,100,0,0,0\n");
  const CliRun r = run("generate --quiet --in " + path("pole.csv") + " --out " + path("o.csv"));
  std::cout << r.output;
  EXPECT_EQ(r.exit_code, 3) << r.output;
  EXPECT_NE(r.output.find(path("pole.csv") + ":3: column 'heading_deg' (5): got 'nan' at a pole"), std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("northward direction of the record's own meridian"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("qw_ecef,qx_ecef,qy_ecef,qz_ecef"), std::string::npos) << r.output;
  write("mid.csv", "time_s,lat_deg,lon_deg,h_m,heading_deg,pitch_deg,roll_deg\n"
                   "0,41,2,100,0,0,0\n"
                   "1,41,2,100,nan,0,0\n");
  const CliRun m = run("generate --quiet --in " + path("mid.csv") + " --out " + path("o.csv"));
  EXPECT_EQ(m.exit_code, 3) << m.output;
  EXPECT_NE(m.output.find("(not finite (NaN or infinity))"), std::string::npos) << m.output;
  EXPECT_EQ(m.output.find("at a pole"), std::string::npos) << m.output;
}

namespace {

// Issue 26 N17: frames dropped while no process had the pty open were
// called "write errors" (1847 in one run, with transport write_errors 0).
TEST_F(Cli, EmitNamesFramesDroppedWhileNoReaderHadThePtyOpen) {
  const CliRun r = run("emit --sample static --device pty:" + path("tty") + " --seconds 0.5");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  const std::size_t at = r.output.find(" dropped (no reader), 0 write errors");
  ASSERT_NE(at, std::string::npos) << r.output;
  const std::size_t start = r.output.rfind(", ", at);
  ASSERT_NE(start, std::string::npos) << r.output;
  EXPECT_GT(std::stoull(r.output.substr(start + 2, at - start - 2)), 0u) << r.output;
}

}  // namespace

// Issue 28: generate --gnss-out / --baro-out write the device's HIL_GPS fixes
// and barometer readings as its encoder computes them. With the errors off
// they are the trajectory itself: each fix is the smoothed trajectory
// (--trajectory-out) at the fix's instant, on the 5 Hz grid, and each
// pressure is the US Standard Atmosphere 1976 troposphere (written here from
// the standard: p = p0 (1 - L H / T0)^(g0 M0 / (R* L)), H = r0 Z / (r0 + Z))
// at the sample's height. The IMU file is the same bytes with or without
// them. A flat scene, or a device that sends no GNSS / barometer, is refused
// with no file written.
namespace {
std::string aiding_scene(const std::string& physics, const std::string& mavlink) {
  return "[scene]\nname = \"aiding\"\nphysics = \"" + physics +
         "\"\n[trajectory]\nsource = \"sample:flight\"\nduration_s = 20\nknot_interval_s = 1.0\n"
         "[[imu]]\nname = \"nav\"\nrate_hz = 50\nprotocol = \"mavlink2\"\n"
         "[imu.transport]\ntype = \"pty\"\nlink = \"/run/imuemu/ttyNAVTEST\"\n" +
         mavlink + "[imu.error_model]\nseed = 4\n[imu.error_model.gyro]\narw_deg_rt_h = 0.3\n";
}
std::vector<std::vector<double>> csv_rows(const std::string& file) {
  std::vector<std::vector<double>> rows;
  std::ifstream in(file);
  std::string line;
  std::getline(in, line);  // header
  while (std::getline(in, line)) {
    std::vector<double> row;
    std::stringstream ss(line);
    std::string cell;
    while (std::getline(ss, cell, ',')) row.push_back(cell.empty() ? std::nan("") : std::stod(cell));
    rows.push_back(row);
  }
  return rows;
}
}  // namespace

TEST_F(Cli, GenerateWritesTheDevicesGnssAndBaroFromTheSameTrajectory) {
  write("s.toml", aiding_scene("ecef", "[imu.mavlink]\nbaro = true\nhil_gps_rate_hz = 5\n"));
  const CliRun g = run("generate --quiet --scene-file " + path("s.toml") + " --out " + path("imu.csv") +
                       " --trajectory-out " + path("k.csv") + " --gnss-out " + path("gnss.csv") + " --baro-out " +
                       path("baro.csv"));
  ASSERT_EQ(g.exit_code, 0) << g.output;
  ASSERT_EQ(run("generate --quiet --scene-file " + path("s.toml") + " --out " + path("imu_only.csv")).exit_code, 0);
  EXPECT_EQ(file_bytes(path("imu.csv")), file_bytes(path("imu_only.csv")));
  EXPECT_EQ(text_lines(path("gnss.csv")).front(),
            "time_ns,gps_time_ns,latitude_rad,longitude_rad,height_m,velocity_north_m_s,velocity_east_m_s,"
            "velocity_down_m_s,fix_type,satellites,hdop,vdop");
  EXPECT_EQ(text_lines(path("baro.csv")).front(), "time_ns,pressure_pa,temperature_k,pressure_altitude_m");
  // The smoothed trajectory by time: time_s, x, y, z, qw..qz, vx, vy, vz, ...
  std::map<std::int64_t, std::vector<double>> truth;
  for (const auto& r : csv_rows(path("k.csv"))) truth[std::llround(r[0] * 1e9)] = r;
  const auto gnss = csv_rows(path("gnss.csv"));
  const auto baro = csv_rows(path("baro.csv"));
  ASSERT_EQ(gnss.size(), 101u);  // 0..20 s at 5 Hz, both ends
  ASSERT_EQ(baro.size(), 1001u);  // every sample at 50 Hz
  for (std::size_t j = 0; j < gnss.size(); ++j) {
    const auto& f = gnss[j];
    const auto t_ns = static_cast<std::int64_t>(f[0]);
    ASSERT_EQ(t_ns, static_cast<std::int64_t>(j) * 200'000'000) << j;
    EXPECT_EQ(static_cast<std::int64_t>(f[1]), 2400LL * 604'800'000'000'000LL + t_ns);  // GPS week 2400 + t
    const auto& k = truth.at(t_ns);
    // lat, lon, h -> ECEF (WGS84, NIMA TR8350.2 eq. 4-14) = the trajectory's position.
    const double a = 6378137.0, e2 = 6.69437999014e-3;
    const double n = a / std::sqrt(1.0 - e2 * std::sin(f[2]) * std::sin(f[2]));
    const double x = (n + f[4]) * std::cos(f[2]) * std::cos(f[3]), y = (n + f[4]) * std::cos(f[2]) * std::sin(f[3]),
                 z = (n * (1.0 - e2) + f[4]) * std::sin(f[2]);
    EXPECT_NEAR(x, k[1], 1e-6) << j;
    EXPECT_NEAR(y, k[2], 1e-6) << j;
    EXPECT_NEAR(z, k[3], 1e-6) << j;
    // NED velocity -> ECEF (C_n^e) = the trajectory's velocity.
    const double sl = std::sin(f[2]), cl = std::cos(f[2]), so = std::sin(f[3]), co = std::cos(f[3]);
    const double vn = f[5], ve = f[6], vd = f[7];
    EXPECT_NEAR(-sl * co * vn - so * ve - cl * co * vd, k[8], 1e-9) << j;
    EXPECT_NEAR(-sl * so * vn + co * ve - cl * so * vd, k[9], 1e-9) << j;
    EXPECT_NEAR(cl * vn - sl * vd, k[10], 1e-9) << j;
    EXPECT_EQ(f[8], 3.0);
  }
  for (std::size_t i = 0; i < baro.size(); ++i) {
    const auto& b = baro[i];
    const auto t_ns = static_cast<std::int64_t>(b[0]);
    ASSERT_EQ(t_ns, static_cast<std::int64_t>(i) * 20'000'000) << i;
    const auto& k = truth.at(t_ns);
    // Height above the ellipsoid of the trajectory's position (Bowring,
    // converged), geoid undulation 0.
    const double a = 6378137.0, e2 = 6.69437999014e-3;
    const double p_xy = std::hypot(k[1], k[2]);
    double lat = std::atan2(k[3], p_xy * (1.0 - e2)), h = 0.0;
    for (int it = 0; it < 6; ++it) {
      const double n = a / std::sqrt(1.0 - e2 * std::sin(lat) * std::sin(lat));
      h = p_xy / std::cos(lat) - n;
      lat = std::atan2(k[3], p_xy * (1.0 - e2 * n / (n + h)));
    }
    const double r0 = 6356766.0, H = r0 * h / (r0 + h);
    const double T = 288.15 - 0.0065 * H;
    const double p = 101325.0 * std::pow(T / 288.15, 9.80665 * 0.0289644 / (8.31432 * 0.0065));
    EXPECT_NEAR(b[1], p, 1e-6 * p) << i;
    EXPECT_NEAR(b[2], T, 1e-9 * T) << i;
    EXPECT_NEAR(b[3], H, 1e-3) << i;
  }
}

TEST_F(Cli, GenerateRefusesGnssAndBaroOutputsTheDeviceDoesNotSend) {
  write("flat.toml", aiding_scene("flat", "[imu.mavlink]\nbaro = true\nhil_gps_rate_hz = 5\n"));
  write("none.toml", aiding_scene("ecef", ""));
  const CliRun flat = run("generate --quiet --scene-file " + path("flat.toml") + " --out " + path("imu.csv") +
                          " --baro-out " + path("baro.csv"));
  EXPECT_EQ(flat.exit_code, 4) << flat.output;
  EXPECT_NE(flat.output.find("ecef scene"), std::string::npos) << flat.output;
  const CliRun gnss = run("generate --quiet --scene-file " + path("none.toml") + " --out " + path("imu.csv") +
                          " --gnss-out " + path("gnss.csv"));
  EXPECT_EQ(gnss.exit_code, 4) << gnss.output;
  EXPECT_NE(gnss.output.find("--gnss-out: the device sends no GNSS fix"), std::string::npos) << gnss.output;
  const CliRun baro = run("generate --quiet --scene-file " + path("none.toml") + " --out " + path("imu.csv") +
                          " --baro-out " + path("baro.csv"));
  EXPECT_EQ(baro.exit_code, 4) << baro.output;
  EXPECT_NE(baro.output.find("--baro-out: the device sends no barometer"), std::string::npos) << baro.output;
  const CliRun no_scene = run("generate --quiet --in " + path("none.toml") + " --out " + path("imu.csv") +
                              " --gnss-out " + path("gnss.csv"));
  EXPECT_EQ(no_scene.exit_code, 2) << no_scene.output;
  for (const auto& e : fs::directory_iterator(dir_))
    EXPECT_TRUE(e.path().extension() == ".toml") << e.path();
}
