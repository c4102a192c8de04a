// [[imu.fault]] and [imu.random_faults] in scene files (daemon/fault_config,
// docs/faults.md): datasheet units converted to SI exactly as written here
// from the unit definitions (1 deg = pi/180 rad, 1 mg = 9.80665e-3 m/s^2),
// the start clock, the sensor implied by the parameters, the seeds' default,
// and every refusal naming the file, the line and the dotted key.
#include <gtest/gtest.h>

#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <sstream>
#include <string>

#include <nlohmann/json.hpp>

#include "daemon/scene/fault_config.hpp"
#include "daemon/scene/scene_config.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_scene_test_fault_config {
namespace imuemu { using namespace ::imuemu; }

using namespace imuemu;
using namespace imuemu::scene;

namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

// Header lines 1..9, the faults from line 10 on.
std::string scene_with(const std::string& imu_tail) {
  return "[scene]\n"                       // 1
         "name = \"faults\"\n"             // 2
         "physics = \"flat\"\n"            // 3
         "[trajectory]\n"                  // 4
         "source = \"sample:static\"\n"    // 5
         "[[imu]]\n"                       // 6
         "name = \"imu0\"\n"               // 7
         "protocol = \"native\"\n"         // 8
         "rate_hz = 200\n"                 // 9
         "[imu.transport]\ntype = \"null\"\n"  // 10, 11
         "[imu.error_model]\nseed = 77\n"      // 12, 13
         + imu_tail;                           // 14...
}

SceneConfig parse(const std::string& tail) { return parse_scene_text(scene_with(tail), "f.toml", "."); }

// The SceneError of a scene: file, line, key, message.
struct Refusal {
  std::string file, key, what;
  std::uint32_t line = 0;
};
Refusal refusal(const std::string& tail) {
  try {
    (void)parse(tail);
  } catch (const SceneError& e) {
    return {e.file(), e.key(), e.what(), e.line()};
  }
  return {"", "", "accepted", 0};
}

}  // namespace

TEST(FaultConfig, KeysInDatasheetUnitsBecomeTheSpecInSi) {
  const SceneConfig s = parse(
      "[[imu.fault]]\ntype = \"bias_step\"\nafter_s = 2.5\nduration_s = 1\nbias_deg_h = 36\naxes = \"xz\"\n"
      "flag_status = true\n"
      "[[imu.fault]]\ntype = \"bias_ramp\"\nat_s = 12\nramp_mg_per_s = 3\n"
      "[[imu.fault]]\ntype = \"delayed\"\nafter_s = 0\ndelay_ms = 20\nsensor = \"both\"\n"
      "[[imu.fault]]\ntype = \"intermittent\"\nafter_s = 1\non_ms = 5\noff_ms = 15\n"
      "[[imu.fault]]\ntype = \"drop\"\nafter_s = 1\nburst_samples = 4\nburst_rate_hz = 2\n"
      "[[imu.fault]]\ntype = \"time_jump\"\nafter_s = 1\ntime_step_ms = -2.5\nseed = 5\n"
      "[[imu.fault]]\ntype = \"spikes\"\nafter_s = 1\nspike_rate_hz = 3\nspike_mg = -40\n"
      "[[imu.fault]]\ntype = \"duplicate\"\nafter_s = 1\n");
  const std::vector<fault::FaultSpec>& f = s.imus[0].faults;
  ASSERT_EQ(f.size(), 8u);
  EXPECT_EQ(f[0].kind, fault::Kind::bias_step);
  EXPECT_EQ(f[0].clock, fault::Clock::since_start);
  EXPECT_EQ(f[0].start_ns, 2'500'000'000);
  EXPECT_EQ(f[0].duration_ns, 1'000'000'000);
  EXPECT_NEAR(f[0].gyro_bias_rad_s, 0.01 * kDeg, 1e-18);  // 36 deg/h = 0.01 deg/s
  EXPECT_EQ(f[0].triad, fault::Triad::gyro) << "only gyro parameters: the gyro";
  EXPECT_EQ(f[0].axes, 0b101);
  EXPECT_TRUE(f[0].flag_status);
  EXPECT_EQ(f[0].seed, 77u) << "the error model's seed by default";
  EXPECT_EQ(f[0].device, "imu0");
  EXPECT_EQ(f[0].source, "scene");
  EXPECT_EQ(f[1].clock, fault::Clock::trajectory);
  EXPECT_EQ(f[1].start_ns, 12'000'000'000);
  EXPECT_EQ(f[1].duration_ns, 0);
  EXPECT_NEAR(f[1].accel_ramp_m_s3, 3 * 9.80665e-3, 1e-15);
  EXPECT_EQ(f[1].triad, fault::Triad::accel);
  EXPECT_EQ(f[2].delay_ns, 20'000'000);
  EXPECT_EQ(f[2].triad, fault::Triad::both);
  EXPECT_EQ(f[3].on_ns, 5'000'000);
  EXPECT_EQ(f[3].off_ns, 15'000'000);
  EXPECT_EQ(f[4].burst_samples, 4u);
  EXPECT_EQ(f[4].rate_hz, 2.0);
  EXPECT_EQ(f[5].time_step_ns, -2'500'000);
  EXPECT_EQ(f[5].seed, 5u);
  EXPECT_EQ(f[6].rate_hz, 3.0);
  EXPECT_NEAR(f[6].accel_bias_m_s2, -40 * 9.80665e-3, 1e-15);
  EXPECT_EQ(f[7].probability, 1.0) << "per-packet faults default to every packet";
  const std::vector<std::string> lines = fault_lines(f, s.imus[0].random_faults);
  ASSERT_EQ(lines.size(), 8u);
  EXPECT_NE(lines[0].find("fault 1: bias_step gyro xz at 2.5 s since start for 1 s: gyro 0.01 deg/s"), std::string::npos)
      << lines[0];
  EXPECT_NE(lines[1].find("at 12 s trajectory time until cleared"), std::string::npos) << lines[1];
}

TEST(FaultConfig, RandomFaultsTakeTypesRateDurationAndTheSeed) {
  const SceneConfig s = parse(
      "[imu.random_faults]\nper_hour = 12\ntypes = [\"stuck\", \"bias_step\", \"drop\"]\nduration_s = 3\n"
      "bias_mg = 20\n");
  const fault::RandomFaults& r = s.imus[0].random_faults;
  EXPECT_EQ(r.per_hour, 12.0);
  ASSERT_EQ(r.kinds.size(), 3u);
  EXPECT_EQ(r.kinds[2], fault::Kind::drop);
  EXPECT_EQ(r.duration_ns, 3'000'000'000);
  EXPECT_EQ(r.seed, 77u);
  EXPECT_NEAR(r.parameters.accel_bias_m_s2, 20 * 9.80665e-3, 1e-15);
  const std::vector<std::string> lines = fault_lines({}, r);
  ASSERT_EQ(lines.size(), 1u);
  EXPECT_EQ(lines[0], "random faults: 12 per hour of stuck, bias_step, drop, 3 s each, seed 77");
  const SceneConfig seeded = parse("[imu.random_faults]\nper_hour = 1\ntypes = [\"dead\"]\nseed = 9\n");
  EXPECT_EQ(seeded.imus[0].random_faults.seed, 9u);
}

TEST(FaultConfig, RefusalsNameTheFileLineKeyAndWhatIsExpected) {
  // Line 14 is the first line of the tail.
  Refusal r = refusal("[[imu.fault]]\ntype = \"bias_step\"\nafter_s = 1\nbias_mg = 1\nbias_degs = 2\n");
  EXPECT_EQ(r.file, "f.toml");
  EXPECT_EQ(r.line, 18u);
  EXPECT_EQ(r.key, "imu[0].fault[0].bias_degs");
  EXPECT_NE(r.what.find("unknown key 'bias_degs'"), std::string::npos) << r.what;
  EXPECT_NE(r.what.find("bias_deg_s, bias_deg_h, bias_mg"), std::string::npos) << r.what;

  r = refusal("[[imu.fault]]\ntype = \"dead\"\nafter_s = 1\nbias_mg = 1\n");
  EXPECT_EQ(r.key, "imu[0].fault[0].bias_mg") << "a parameter of another type";
  EXPECT_EQ(r.line, 17u);

  r = refusal("[[imu.fault]]\ntype = \"stuk\"\nafter_s = 1\n");
  EXPECT_EQ(r.key, "imu[0].fault[0].type");
  EXPECT_EQ(r.line, 15u);
  EXPECT_NE(r.what.find("expected one of stuck, dead, garbage"), std::string::npos) << r.what;

  r = refusal("[[imu.fault]]\ntype = \"dead\"\nafter_s = 1\nat_s = 2\n");
  EXPECT_EQ(r.key, "imu[0].fault[0]");
  EXPECT_NE(r.what.find("either at_s or after_s"), std::string::npos) << r.what;

  r = refusal("[[imu.fault]]\ntype = \"dead\"\n");
  EXPECT_NE(r.what.find("missing the start"), std::string::npos) << r.what;

  r = refusal("[[imu.fault]]\ntype = \"dead\"\nafter_s = -1\n");
  EXPECT_EQ(r.key, "imu[0].fault[0].after_s");
  EXPECT_EQ(r.line, 16u);

  r = refusal("[[imu.fault]]\ntype = \"dead\"\nafter_s = 1\naxes = \"xw\"\n");
  EXPECT_EQ(r.key, "imu[0].fault[0].axes");
  EXPECT_NE(r.what.find("subset of \"xyz\""), std::string::npos) << r.what;

  r = refusal("[[imu.fault]]\ntype = \"drop\"\nafter_s = 1\nsensor = \"gyro\"\n");
  EXPECT_EQ(r.key, "imu[0].fault[0].sensor") << "sensor is not a key of a link fault";

  r = refusal("[[imu.fault]]\ntype = \"bias_step\"\nafter_s = 1\nbias_deg_s = 1\nbias_deg_h = 2\n");
  EXPECT_EQ(r.key, "imu[0].fault[0].bias_deg_h");
  EXPECT_NE(r.what.find("ambiguous"), std::string::npos) << r.what;

  r = refusal("[[imu.fault]]\ntype = \"bias_step\"\nafter_s = 1\n");
  EXPECT_NE(r.what.find("gyro_bias_rad_s or accel_bias_m_s2"), std::string::npos) << r.what;

  r = refusal("[[imu.fault]]\ntype = \"slow\"\nafter_s = 1\ndivisor = 1.5\n");
  EXPECT_EQ(r.key, "imu[0].fault[0].divisor");
  EXPECT_NE(r.what.find("expected an integer"), std::string::npos) << r.what;

  r = refusal("[[imu.fault]]\ntype = \"delayed\"\nafter_s = 1\ndelay_ms = 1500\n");
  EXPECT_EQ(r.key, "imu[0].fault[0].delay_ms");
  EXPECT_NE(r.what.find("out of range"), std::string::npos) << r.what;

  r = refusal("[[imu.fault]]\ntype = \"restart\"\nafter_s = 1\n");
  EXPECT_NE(r.what.find("duration"), std::string::npos) << r.what;

  r = refusal("[imu.random_faults]\nper_hour = 5\ntypes = [\"dead\", \"nope\"]\n");
  EXPECT_EQ(r.key, "imu[0].random_faults.types");
  EXPECT_EQ(r.line, 16u);

  r = refusal("[imu.random_faults]\nper_hour = 5000\ntypes = [\"dead\"]\n");
  EXPECT_EQ(r.key, "imu[0].random_faults.per_hour");

  r = refusal("[imu.random_faults]\nper_hour = 5\ntypes = [\"dead\"]\nspike_mg = 3\n");
  EXPECT_EQ(r.key, "imu[0].random_faults.spike_mg") << "a parameter of no listed type";

  r = refusal("[imu.faults]\n");
  EXPECT_NE(r.what.find("unknown key 'faults'"), std::string::npos) << r.what;
}

// ---- `imuemu generate --scene-file` with faults ----

namespace {

int run_cli(const std::string& args, std::string* output = nullptr) {
  const std::string cmd = std::string(IMUEMU_CLI_PATH) + " " + args + " 2>&1";
  FILE* p = ::popen(cmd.c_str(), "r");
  if (p == nullptr) return -1;
  char buf[4096];
  std::string out;
  std::size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) out.append(buf, n);
  const int status = ::pclose(p);
  if (output != nullptr) *output = out;
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::vector<std::string> lines_of(const std::string& path) {
  std::ifstream in(path);
  std::vector<std::string> out;
  for (std::string line; std::getline(in, line);) out.push_back(line);
  return out;
}

std::vector<double> cells_of(const std::string& line) {
  std::vector<double> out;
  std::stringstream ss(line);
  for (std::string cell; std::getline(ss, cell, ',');) out.push_back(std::strtod(cell.c_str(), nullptr));
  return out;
}

}  // namespace

TEST(FaultGenerate, SceneFaultsChangeExactlyTheirSamplesAndTheLogNamesThem) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("imuemu_fault_gen_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  auto write = [&](const std::string& name, const std::string& text) {
    std::ofstream(dir / name) << text;
    return (dir / name).string();
  };
  const std::string base = scene_with("");
  const std::string plain = write("plain.toml", base);
  const std::string faulty = write(
      "faulty.toml", base +
                         "[[imu.fault]]\ntype = \"bias_step\"\nafter_s = 1\nduration_s = 0.5\nbias_deg_s = 1\naxes = \"z\"\n"
                         "[[imu.fault]]\ntype = \"dead\"\nafter_s = 2\nduration_s = 0.25\nsensor = \"accel\"\n");
  const std::string out_plain = (dir / "plain.csv").string(), out_faulty = (dir / "faulty.csv").string();
  ASSERT_EQ(run_cli("generate --scene-file " + plain + " --max-seconds 3 --quiet --out " + out_plain), 0);
  std::string messages;
  ASSERT_EQ(run_cli("generate --scene-file " + faulty + " --max-seconds 3 --out " + out_faulty, &messages), 0)
      << messages;
  EXPECT_NE(messages.find("fault 1: bias_step gyro z at 1 s since start for 0.5 s"), std::string::npos) << messages;
  EXPECT_NE(messages.find("150 samples faulted, 4 fault events"), std::string::npos) << messages;
  EXPECT_FALSE(std::filesystem::exists(dir / "plain.faults.jsonl")) << "no faults, no log";
  const std::vector<std::string> a = lines_of(out_plain), b = lines_of(out_faulty);
  ASSERT_EQ(a.size(), b.size());
  ASSERT_GE(a.size(), 601u);  // header + 3 s at 200 Hz
  // Row k + 1 is sample k (t_k = t_0 + k / 200 s).
  for (std::size_t k = 0; k + 1 < a.size(); ++k) {
    const bool biased = k >= 200 && k < 300, dead = k >= 400 && k < 450;
    if (!biased && !dead) {
      EXPECT_EQ(a[k + 1], b[k + 1]) << "sample " << k << " changed";
      continue;
    }
    const std::vector<double> x = cells_of(a[k + 1]), y = cells_of(b[k + 1]);
    ASSERT_EQ(x.size(), y.size());
    EXPECT_EQ(x[0], y[0]) << "the time stays";
    for (int i = 1; i <= 6; ++i) {
      double expected = x[i];
      if (biased && i == 3) expected = x[i] + kDeg;  // gyro z + 1 deg/s
      if (dead && i >= 4) expected = 0.0;            // accel dead
      EXPECT_DOUBLE_EQ(y[i], expected) << "sample " << k << " column " << i;
    }
  }
  const std::vector<std::string> log = lines_of((dir / "faulty.faults.jsonl").string());
  ASSERT_EQ(log.size(), 4u);
  const std::int64_t t0 = static_cast<std::int64_t>(cells_of(a[1])[0]);
  const struct {
    const char* phase;
    const char* type;
    std::uint64_t sample;
  } expected[4] = {{"start", "bias_step", 200}, {"end", "bias_step", 299}, {"start", "dead", 400}, {"end", "dead", 449}};
  for (int i = 0; i < 4; ++i) {
    const nlohmann::json j = nlohmann::json::parse(log[i]);
    EXPECT_EQ(j["phase"], expected[i].phase) << log[i];
    EXPECT_EQ(j["type"], expected[i].type) << log[i];
    EXPECT_EQ(j["sample_counter"], expected[i].sample) << log[i];
    EXPECT_EQ(j["t_ns"], t0 + static_cast<std::int64_t>(expected[i].sample) * 5'000'000) << log[i];
    EXPECT_EQ(j["device"], "imu0");
    EXPECT_EQ(j["source"], "scene");
  }
  std::filesystem::remove_all(dir);
}
}  // namespace unity_scene_test_fault_config
