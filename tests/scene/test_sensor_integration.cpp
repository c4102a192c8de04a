// The sensor model in every path (issue 15): `imuemu generate` (batch),
// `imuemu stream`, and the emission engine imuemud runs give the same bits
// for one seed and scene; the saturated flag reaches the wire; the
// [imu.error_model] table is parsed strictly.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <mutex>
#include <numbers>
#include <set>
#include <sstream>

#include <nlohmann/json.hpp>

#include "tests/support/recording_transport.hpp"
#include "core/pipeline.hpp"
#include "core/sensor/datasheet.hpp"
#include "core/sensor/sensor_model.hpp"
#include "core/signal_chain/signal_chain.hpp"
#include "core/so3.hpp"
#include "daemon/device/device.hpp"
#include "daemon/engine/emission.hpp"
#include "daemon/scene/error_model_config.hpp"
#include "daemon/scene/scene_check.hpp"
#include "daemon/scene/scene_config.hpp"
#include "daemon/scene/scene_runner.hpp"
#include "core/reference_motion.hpp"
#include "drivers/protocols/can_protocols.hpp"
#include "drivers/protocols/stream_protocols.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_scene_test_sensor_integration {
namespace imuemu { using namespace ::imuemu; }

namespace imuemu {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

using Recording = test_support::RecordingTransport;

std::vector<drivers::DecodedSample> decode_native(const std::vector<std::uint8_t>& bytes) {
  auto decoder = drivers::make_stream_decoder("native");
  std::vector<drivers::DecodedSample> out;
  decoder->feed(bytes, [&](const drivers::DecodedSample& s) { out.push_back(s); });
  return out;
}

struct Row {
  TimeNs t_ns;
  Vec3 gyro, accel;
  std::string status;  // stream's flag column ("exact", ...); empty for generate
};
// time_ns, 3 gyro, 3 accel[, status]: the CSVs of generate and stream.
std::vector<Row> read_rows(const std::string& path) {
  std::ifstream in(path);
  std::string line;
  std::vector<Row> rows;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] < '0' || line[0] > '9') {
      if (line.empty() || line[0] != '-') continue;
    }
    std::stringstream ss(line);
    std::string cell;
    std::vector<std::string> cells;
    while (std::getline(ss, cell, ',')) cells.push_back(cell);
    if (cells.size() < 7) continue;
    Row r{std::stoll(cells[0]), {}, {}, cells.size() > 7 ? cells[7] : std::string()};
    for (int i = 0; i < 3; ++i) {
      r.gyro[i] = std::strtod(cells[1 + i].c_str(), nullptr);
      r.accel[i] = std::strtod(cells[4 + i].c_str(), nullptr);
    }
    rows.push_back(r);
  }
  return rows;
}

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

// The scene's first device in the emission engine, as imuemud runs it, with
// its transport in memory: `ticks` ticks, all computed before the clock
// starts (counts exact on a loaded host). `adjust` changes the device first.
struct EngineRun {
  bool finished = false;
  std::vector<std::uint8_t> bytes;
  emission::EngineStats stats;
};
EngineRun run_scene_device(const scene::SceneConfig& sc, std::uint64_t ticks, const std::string& protocol,
                           const std::function<void(emission::DeviceOptions&)>& adjust = {}) {
  const scene::ImuConfig& imu = sc.imus.at(0);
  emission::DeviceOptions dev;
  dev.name = imu.name;
  dev.rate_hz = imu.rate_hz;
  dev.pipeline = scene::pipeline_options(sc, imu);
  dev.mounting = imu.mounting;
  dev.sensor_model = imu.error_model.sensor();
  dev.chain = imu.error_model.chain;
  if (adjust) adjust(dev);
  auto rec = std::make_unique<Recording>();
  Recording* recording = rec.get();
  dev.device = device::make_stream_device(drivers::make_stream_encoder(protocol), std::move(rec));
  emission::EngineOptions eo;
  eo.trajectory = scene::scene_trajectory(sc);
  eo.drop_late_ticks = false;
  eo.max_ticks_per_device = ticks;
  eo.ring_capacity = 1024;
  std::vector<emission::DeviceOptions> devices;
  devices.push_back(std::move(dev));
  emission::EmissionEngine engine(std::move(eo), std::move(devices));
  engine.start();
  EngineRun run;
  run.finished = engine.wait(std::chrono::seconds(20));
  engine.stop();
  run.bytes = recording->bytes();
  run.stats = engine.stats();
  return run;
}

class SensorIntegration : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("imuemu_sensor_" + std::to_string(::getpid()) + "_" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  // `imuemu generate --scene-file` over 4 s (its messages in out, its rows in
  // batch) and the scene's device in the emission engine (native): 800
  // samples each at 200 Hz.
  void generate_and_emit(const std::string& scene_file, const scene::SceneConfig& sc, std::string& out,
                         std::vector<Row>& batch, EngineRun& run, std::vector<drivers::DecodedSample>& wire) {
    ASSERT_EQ(run_cli("generate --scene-file " + path(scene_file) + " --max-seconds 4 --out " + path("g.csv"), &out), 0)
        << out;
    batch = read_rows(path("g.csv"));
    ASSERT_EQ(batch.size(), 800u);
    run = run_scene_device(sc, 800, "native");
    ASSERT_TRUE(run.finished);
    wire = decode_native(run.bytes);
    ASSERT_EQ(wire.size(), 800u);
  }
  fs::path dir_;
};

// The yaw rate of the built-in flat circle is 50/500 = 0.1 rad/s = 5.73 deg/s:
// a gyro range of 5.7 deg/s saturates z on most samples (white noise
// 0.15 deg/sqrt(h) at 200 Hz is 0.035 deg/s per sample).
constexpr const char* kScene = R"(
[scene]
name = "sensor-test"
physics = "flat"

[trajectory]
source = "sample:circle"
duration_s = 12
knot_interval_s = 1.0

[[imu]]
name = "imuA"
rate_hz = 200
protocol = "native"
[imu.transport]
type = "null"
[imu.error_model]
preset = "stim300"
seed = 9
[imu.error_model.gyro]
range_dps = 5.7
[imu.error_model.temperature]
start_c = 10
end_c = 40
warmup_tau_s = 5
)";

TEST_F(SensorIntegration, GenerateSceneFileAndTheEmissionEngineGiveTheSameBitsAndSaturationFlags) {
  { std::ofstream(path("s.toml")) << kScene; }
  const scene::SceneConfig sc = scene::parse_scene_file(path("s.toml"));
  const scene::ImuConfig& imu = sc.imus.front();
  ASSERT_FALSE(imu.error_model.ideal());
  EXPECT_EQ(imu.error_model.spec.seed, 9u);
  EXPECT_DOUBLE_EQ(imu.error_model.spec.gyro.range, 5.7 * std::numbers::pi / 180.0);
  EXPECT_GT(imu.error_model.spec.gyro.bias_instability.x(), 0.0);  // the preset's, kept

  // The batch reference (the CLI, as a user runs it) and what imuemud runs.
  std::string out;
  std::vector<Row> batch;
  EngineRun run;
  std::vector<drivers::DecodedSample> wire;
  generate_and_emit("s.toml", sc, out, batch, run, wire);
  if (HasFatalFailure()) return;
  EXPECT_NE(out.find("sigma = N sqrt(fs)"), std::string::npos) << out;  // the discrete sigma is printed

  // Independent saturation truth from the sensor model itself on the ideal batch.
  std::vector<Pose> knots = scene::scene_trajectory(sc);
  const BatchResult ideal = run_batch(knots, scene::pipeline_options(sc, imu));
  sensor::SensorModel model(imu.error_model.spec, 200.0, "imuA");
  std::uint64_t saturated = 0;
  for (std::size_t k = 0; k < wire.size(); ++k) {
    EXPECT_EQ(wire[k].t_ns, batch[k].t_ns);
    ASSERT_EQ(wire[k].gyro_rad_s, batch[k].gyro) << k;
    ASSERT_EQ(wire[k].accel_m_s2, batch[k].accel) << k;
    const sensor::Measurement m = model.measure(k, ideal.imu[k].gyro_rad_s, ideal.imu[k].accel_m_s2);
    ASSERT_EQ(m.gyro_rad_s, batch[k].gyro) << k;
    const bool sat = m.saturated_axes != 0;
    saturated += sat ? 1 : 0;
    EXPECT_EQ((wire[k].status & drivers::kStatusSaturated) != 0, sat) << k;
    if (sat) {
      EXPECT_EQ(std::abs(wire[k].gyro_rad_s.z()), 5.7 * (std::numbers::pi / 180.0)) << k;  // range_dps x (pi/180)
    }
  }
  EXPECT_GT(saturated, 100u);
  EXPECT_LT(saturated, 800u);
  EXPECT_EQ(run.stats.devices.front().saturated, saturated);
  EXPECT_EQ(emission::to_json(run.stats)["devices"][0]["saturated"], saturated);
  // The seed matters; the ideal path does not change.
  ASSERT_EQ(run_cli("generate --scene-file " + path("s.toml") + " --max-seconds 4 --seed 10 --quiet --out " + path("g10.csv")), 0);
  EXPECT_NE(read_rows(path("g10.csv"))[5].gyro, batch[5].gyro);
  ASSERT_EQ(run_cli("generate --scene-file " + path("s.toml") + " --max-seconds 4 --sensor ideal --quiet --out " + path("gi.csv")), 0);
  const auto ideal_rows = read_rows(path("gi.csv"));
  for (std::size_t k = 0; k < 800; ++k) ASSERT_EQ(ideal_rows[k].gyro, ideal.imu[k].gyro_rad_s) << k;
}

// Issue 16: the device's signal chain in every path. The stim300 sensor
// model runs at the icm42688p chain's internal rate (8 kHz = 40 x 200 Hz)
// before the anti-alias and UI filters and the decimation; generate and the
// emission engine (what imuemud runs) give the same bits, which are the
// chain's own on the batch trajectory; check-config prints the group delay
// (analytic: 1/(2 tan(pi fc/fs) sin(pi/4)) samples for each 2nd-order
// Butterworth, fc = 258 Hz and 100 Hz at 8 kHz: 24.9524 samples = 3.11905 ms).
TEST_F(SensorIntegration, SignalChainGivesTheSameBitsInGenerateAndTheEmissionEngineAndCheckConfigPrintsItsDelay) {
  std::string text = kScene;
  text.replace(text.find("[imu.error_model.gyro]\nrange_dps = 5.7\n"), 39, "");
  text += "[imu.error_model.signal_chain]\npreset = \"icm42688p\"\n";
  {
    std::ofstream f(path("c.toml"));
    f << text;
  }
  const scene::SceneConfig sc = scene::parse_scene_file(path("c.toml"));
  const scene::ImuConfig& imu = sc.imus.at(0);
  ASSERT_EQ(imu.error_model.chain.preset, "icm42688p");
  const std::string check = scene::to_text(scene::check_scene(sc));
  EXPECT_NE(check.find("internal rate 8000 Hz (40 x 200 Hz)"), std::string::npos) << check;
  EXPECT_NE(check.find("group delay: 3.11905 ms at DC"), std::string::npos) << check;

  std::string out;
  std::vector<Row> batch;
  EngineRun run;
  std::vector<drivers::DecodedSample> wire;
  generate_and_emit("c.toml", sc, out, batch, run, wire);
  if (HasFatalFailure()) return;
  EXPECT_NE(out.find("group delay: 3.11905 ms at DC"), std::string::npos) << out;
  EXPECT_NE(out.find("terms at 8000 Hz"), std::string::npos) << out;  // the model runs at the internal rate

  const BatchResult ideal = run_batch(scene::scene_trajectory(sc), scene::pipeline_options(sc, imu));
  signal_chain::DeviceChain chain(sc.physics, imu.error_model.sensor(), imu.error_model.chain, 200, "imuA");
  double filtered_vs_ideal = 0.0;
  for (std::size_t k = 0; k < wire.size(); ++k) {
    ASSERT_EQ(wire[k].gyro_rad_s, batch[k].gyro) << k;
    ASSERT_EQ(wire[k].accel_m_s2, batch[k].accel) << k;
    const signal_chain::ChainOutput o =
        chain.step(k, ideal.trajectory[k], ideal.imu[k], k > 0 ? &ideal.trajectory[k - 1] : nullptr, std::nullopt);
    ASSERT_EQ(o.gyro_rad_s, batch[k].gyro) << k;
    if (k >= 200) filtered_vs_ideal = std::max(filtered_vs_ideal, (o.gyro_rad_s - ideal.imu[k].gyro_rad_s).norm());
  }
  // The 100 Hz UI filter leaves the slow circle's rate (0.1 rad/s) and
  // takes most of the noise: STIM300 ARW 0.15 deg/sqrt(h) is 4.4e-5 rad/s/sqrt(Hz),
  // ~3e-3 rad/s per sample at 8 kHz, ~7e-4 rad/s within 100 Hz (x sqrt(1.1 x 100)).
  EXPECT_LT(filtered_vs_ideal, 5e-3);
  EXPECT_GT(filtered_vs_ideal, 1e-4);
}

TEST_F(SensorIntegration, StreamReplayEqualsGenerateWithTheSameSensorAndSeed) {
  ASSERT_EQ(run_cli("sample-trajectory --kind circle --duration-s 10 --period-s 0.1 --out " + path("c.csv")), 0);
  std::string out;
  ASSERT_EQ(run_cli("generate --in " + path("c.csv") + " --out " + path("g.csv") +
                        " --rate 200 --scene flat --delta 20 --sensor adis16470 --seed 77",
                    &out),
            0)
      << out;
  const auto reference = read_rows(path("g.csv"));
  ASSERT_EQ(reference.size(), 2001u);
  for (const char* speed : {"max", "20"}) {
    ASSERT_EQ(run_cli("stream --source file:" + path("c.csv") + " --speed " + std::string(speed) +
                          " --rate 200 --scene flat --knot-interval-s 0.1 --sensor adis16470 --seed 77 --out " + path("s.csv"),
                      &out),
              0)
        << out;
    const auto rows = read_rows(path("s.csv"));
    ASSERT_EQ(rows.size(), reference.size()) << speed << "\n" << out;
    // A paced replay on a slow or loaded host gets flagged (extrapolated)
    // samples where the emitter ran ahead of the knots: the live path doing
    // its job. Every sample flagged exact must be generate's to the bit, noise
    // included; only the unpaced replay (--speed max) must be exact throughout.
    const bool paced = std::string(speed) != "max";
    std::size_t exact_differing = 0, flagged = 0;
    for (std::size_t i = 0; i < rows.size(); ++i) {
      if (rows[i].status != "exact") {
        ++flagged;
        continue;
      }
      if (rows[i].gyro != reference[i].gyro || rows[i].accel != reference[i].accel || rows[i].t_ns != reference[i].t_ns)
        ++exact_differing;
    }
    EXPECT_EQ(exact_differing, 0u) << speed;
    if (paced) EXPECT_LT(flagged, rows.size()) << speed << "\n" << out;
    else EXPECT_EQ(flagged, 0u) << speed << "\n" << out;
  }
  // A sensor file of its own, with an override and a seed, is the same model.
  {
    std::ofstream(path("adis.toml")) << "preset = \"adis16470\"\nseed = 77\n[accel]\nrange_g = 40\n";
  }
  ASSERT_EQ(run_cli("generate --in " + path("c.csv") + " --out " + path("f.csv") +
                    " --rate 200 --scene flat --delta 20 --quiet --sensor " + path("adis.toml")),
            0);
  const auto from_file = read_rows(path("f.csv"));
  ASSERT_EQ(from_file.size(), reference.size());
  for (std::size_t i = 0; i < from_file.size(); ++i) ASSERT_EQ(from_file[i].gyro, reference[i].gyro) << i;
}

TEST_F(SensorIntegration, SaturatedFlagReachesTheMipOverrangeField) {
  auto encoder = drivers::make_stream_encoder("mip");
  auto decoder = drivers::make_stream_decoder("mip");
  for (std::uint32_t status : {0u, static_cast<std::uint32_t>(drivers::kStatusSaturated)}) {
    drivers::ImuFrameInput f;
    f.t_ns = 1'000'000'000;
    f.period_ns = 5'000'000;
    f.gyro_rad_s = Vec3(0.1, 0.0, 0.0);
    f.accel_m_s2 = Vec3(0.0, 0.0, -9.8);
    f.status = status;
    std::vector<std::uint8_t> bytes;
    encoder->encode(f, bytes);
    std::vector<drivers::DecodedSample> got;
    decoder->feed(bytes, [&](const drivers::DecodedSample& s) { got.push_back(s); });
    ASSERT_EQ(got.size(), 1u);
    EXPECT_EQ(got[0].status & drivers::kStatusSaturated, status);
  }
}

// Acceptance 4 on the wire: a body spinning beyond the gyro range (STIM300
// with its range set to +-100 deg/s, at 150 deg/s about z; a control run at
// 50 deg/s; both within every protocol's own field range, e.g. J1939's
// +-250 deg/s, so only the sensor's flag can mark the sample), measured by
// the sensor model, the saturated flag handed to each encoder as the emission
// engine does (daemon/engine/emission.cpp: saturated_axes != 0 -> kStatusSaturated),
// and read back from the bytes by hand, from each protocol's document:
//  * native: status word bit 1 (docs/native-protocol.md), through its decoder;
//  * MIP: the over-range field's accel/gyro bits, through its decoder;
//  * DroneCAN: uavcan.protocol.NodeStatus health = WARNING (1) in the top two
//    bits of payload byte 4 for the second that held the sample;
//  * J1939: figures of merit of ARI and ACCS (byte 7, three 2-bit fields) =
//    01 "degraded" (J1939DA SPNs 4983-4985), i.e. 0xD5 with the two undefined
//    high bits set; 0xC0 when fully functional.
// MAVLink 2 HIGHRES_IMU / HIL_SENSOR carry no saturation field (nothing to test).
TEST(SensorSaturation, TrajectoryBeyondTheRangeSetsTheStatusOnTheWireOfEveryProtocolThatHasOne) {
  const double range_rad_s = 100.0 * std::numbers::pi / 180.0;
  sensor::SensorModelSpec spec = sensor::preset_spec("stim300");
  spec.gyro.range = range_rad_s;
  for (const double rate_dps : {150.0, 50.0}) {
    SCOPED_TRACE(rate_dps);
    const bool beyond = rate_dps > 100.0;
    const reference::ConstantRate spin(Mat3::Identity(), Vec3(0.0, 0.0, rate_dps * std::numbers::pi / 180.0), 0,
                                       3 * kNsPerSecond);
    const SceneModel flat{Physics::flat};
    sensor::SensorModel model(spec, 100.0, "imu0");
    auto native = drivers::make_stream_encoder("native");
    auto mip = drivers::make_stream_encoder("mip");
    auto dronecan = drivers::make_can_encoder("dronecan");
    auto j1939 = drivers::make_can_encoder("j1939");
    std::vector<std::uint8_t> native_bytes, mip_bytes;
    std::vector<drivers::CanFrame> dronecan_frames, node_status, j1939_frames;
    std::uint64_t saturated = 0;
    for (std::uint64_t k = 0; k < 200; ++k) {
      const TimeNs t = static_cast<TimeNs>(k) * 10'000'000 + kNsPerSecond;
      const ImuSample ideal = reference::truth_imu(spin, flat, t - kNsPerSecond);
      const sensor::Measurement m = model.measure(k, ideal.gyro_rad_s, ideal.accel_m_s2);
      drivers::ImuFrameInput f;
      f.sample_counter = k;
      f.t_ns = t;
      f.period_ns = 10'000'000;
      f.gyro_rad_s = m.gyro_rad_s;
      f.accel_m_s2 = m.accel_m_s2;
      if (m.saturated_axes != 0) f.status |= drivers::kStatusSaturated;
      saturated += m.saturated_axes != 0 ? 1 : 0;
      if (beyond) {
        EXPECT_EQ(m.saturated_axes, sensor::kGyroZ) << k;
        EXPECT_EQ(m.gyro_rad_s.z(), range_rad_s) << k;  // exactly the range
      }
      native->encode(f, native_bytes);
      mip->encode(f, mip_bytes);
      j1939_frames.clear();
      j1939->encode(f, j1939_frames);
      ASSERT_EQ(j1939_frames.size(), 2u);
      for (const drivers::CanFrame& c : j1939_frames)
        EXPECT_EQ(c.data[6], beyond ? 0xD5 : 0xC0) << k << " id " << std::hex << c.id;
      dronecan->encode(f, dronecan_frames);
      dronecan->periodic(t, node_status);
    }
    EXPECT_EQ(saturated, beyond ? 200u : 0u);
    std::size_t native_seen = 0, mip_seen = 0;
    drivers::make_stream_decoder("native")->feed(native_bytes, [&](const drivers::DecodedSample& d) {
      ++native_seen;
      EXPECT_EQ((d.status & drivers::kStatusSaturated) != 0, beyond);
      if (beyond) {
        EXPECT_EQ(d.gyro_rad_s.z(), range_rad_s);
      }
    });
    drivers::make_stream_decoder("mip")->feed(mip_bytes, [&](const drivers::DecodedSample& d) {
      ++mip_seen;
      EXPECT_EQ((d.status & drivers::kStatusSaturated) != 0, beyond);
    });
    EXPECT_EQ(native_seen, 200u);
    EXPECT_EQ(mip_seen, 200u);
    // NodeStatus at t = 1 s (after sample 0) and 2 s: each reports the
    // samples encoded since the previous one.
    ASSERT_EQ(node_status.size(), 2u);
    for (std::size_t n = 0; n < node_status.size(); ++n) {
      ASSERT_EQ(node_status[n].len, 8);
      const unsigned health = node_status[n].data[4] >> 6;
      EXPECT_EQ(health, beyond ? 1u : 0u) << "NodeStatus " << n;
    }
  }
}

// Issue 15 acceptance 4, the decoding side: the ICM-42688-P preset's
// quantised output, sent in the native frame (f64, lossless:
// docs/native-protocol.md) and decoded by `imuemu listen`'s decoder, is an
// exact multiple n x LSB of the datasheet's 16-bit code (2000/32768 deg/s,
// 16000/32768 mg) on every axis, for a motion that moves through many codes.
TEST(SensorQuantisation, DecodedNativeValuesAreExactMultiplesOfTheLsb) {
  const sensor::SensorModelSpec spec = sensor::preset_spec("icm42688p");
  sensor::SensorModel model(spec, 1000.0, "imu0");
  const double gyro_lsb = (2000.0 / 32768.0) * (std::numbers::pi / 180.0);
  const double accel_lsb = (16000.0 / 32768.0) * 1e-3 * 9.80665;
  auto native = drivers::make_stream_encoder("native");
  std::vector<std::uint8_t> bytes;
  for (std::uint64_t k = 0; k < 500; ++k) {
    const double s = std::sin(0.013 * static_cast<double>(k));
    const sensor::Measurement m = model.measure(k, Vec3(0.7 * s, -0.3 * s, 0.05), Vec3(2.0 * s, 0.1, -9.8));
    drivers::ImuFrameInput f;
    f.sample_counter = k;
    f.t_ns = static_cast<TimeNs>(k) * 1'000'000;
    f.period_ns = 1'000'000;
    f.gyro_rad_s = m.gyro_rad_s;
    f.accel_m_s2 = m.accel_m_s2;
    native->encode(f, bytes);
  }
  std::size_t decoded = 0;
  std::set<long long> gyro_codes;
  drivers::make_stream_decoder("native")->feed(bytes, [&](const drivers::DecodedSample& d) {
    ++decoded;
    for (int a = 0; a < 3; ++a) {
      const double n_g = std::nearbyint(d.gyro_rad_s[a] / gyro_lsb), n_a = std::nearbyint(d.accel_m_s2[a] / accel_lsb);
      EXPECT_EQ(d.gyro_rad_s[a], n_g * gyro_lsb) << decoded << " gyro " << a;
      EXPECT_EQ(d.accel_m_s2[a], n_a * accel_lsb) << decoded << " accel " << a;
      if (a == 0) gyro_codes.insert(static_cast<long long>(n_g));
    }
  });
  EXPECT_EQ(decoded, 500u);
  EXPECT_GT(gyro_codes.size(), 500u / 4);  // many distinct codes, not one constant
}

struct BadCase {
  std::string name, table, key, what;
  std::uint32_t line;
};

// A static flat scene with one null-transport native device at rate_hz, 11
// lines: a table appended starts on line 12.
std::string scene_head(int rate_hz) {
  return "[scene]\nname = \"x\"\nphysics = \"flat\"\n[trajectory]\nsource = \"sample:static\"\n"
         "[[imu]]\nname = \"a\"\nrate_hz = " + std::to_string(rate_hz) +
         "\nprotocol = \"native\"\n[imu.transport]\ntype = \"null\"\n";
}

// Each case appended to `head` is refused naming bad.toml, its line and key.
void expect_refused(const std::string& head, const std::vector<BadCase>& cases) {
  for (const BadCase& c : cases) {
    try {
      (void)scene::parse_scene_text(head + c.table, "bad.toml", ".");
      ADD_FAILURE() << c.name << ": accepted";
    } catch (const scene::SceneError& e) {
      EXPECT_EQ(e.file(), "bad.toml") << c.name;
      EXPECT_EQ(e.key(), c.key) << c.name << ": " << e.what();
      EXPECT_EQ(e.line(), c.line) << c.name << ": " << e.what();
      EXPECT_NE(std::string(e.what()).find(c.what), std::string::npos) << c.name << ": " << e.what();
    }
  }
}

TEST(ErrorModelConfig, RefusesUnknownUnitlessAndAmbiguousKeysNamingFileLineAndKey) {
  const std::string head = scene_head(100) + "[imu.error_model]\n";  // line 12
  const std::vector<BadCase> cases = {
      {"unknown", "preset = \"adis16470\"\nnoise = 3\n", "imu[0].error_model.noise", "unknown key", 14},
      {"triad key at the top", "arw_deg_rt_h = 0.1\n", "imu[0].error_model.arw_deg_rt_h", "[imu[0].error_model.gyro]", 13},
      {"unit-less", "[imu.error_model.gyro]\nnoise_density = 0.01\n", "imu[0].error_model.gyro.noise_density",
       "has no unit; write one of noise_density_dps_rt_hz", 14},
      {"ambiguous", "[imu.error_model.gyro]\narw_deg_rt_h = 0.1\nnoise_density_dps_rt_hz = 0.01\n",
       "imu[0].error_model.gyro.noise_density_dps_rt_hz", "ambiguous", 15},
      {"accel key in gyro", "[imu.error_model.gyro]\nrange_g = 16\n", "imu[0].error_model.gyro.range_g", "unknown key", 14},
      {"bad preset", "preset = \"mpu6050\"\n", "imu[0].error_model.preset", "unknown sensor preset", 13},
      {"negative", "[imu.error_model.accel]\nvrw_m_s_rt_h = -1\n", "imu[0].error_model.accel.vrw_m_s_rt_h",
       "accel.white noise (x) -0.0166667 m/s^2/sqrt(Hz) is not in [0, 0.980665]", 14},
      {"string value", "[imu.error_model.accel]\nrange_g = \"16\"\n", "imu[0].error_model.accel.range_g", "expected a number", 14},
      {"seed", "seed = -3\n", "imu[0].error_model.seed", "integer >= 0", 13},
  };
  expect_refused(head, cases);
  // Overrides replace the preset's term (another key of the same term is not ambiguous across tables).
  const scene::SceneConfig ok = scene::parse_scene_text(
      head + "preset = \"adis16470\"\n[imu.error_model.gyro]\narw_deg_rt_h = 0.3\n", "ok.toml", ".");
  const sensor::SensorModelSpec& s = ok.imus[0].error_model.spec;
  EXPECT_NEAR(s.gyro.white_density.x(), 0.3 * std::numbers::pi / 180.0 / 60.0, 1e-18);
  EXPECT_EQ(s.gyro.bias_instability, sensor::preset_spec("adis16470").gyro.bias_instability);
  EXPECT_TRUE(scene::parse_scene_text(head, "ideal.toml", ".").imus[0].error_model.ideal());
}

// Issue 16 B: the increments on the wire are the exact ones in the
// protocol's convention. MIP (compensated: the rotation vector of the attitude
// change and the velocity change in the body frame at the period's start)
// against the closed form on the batch trajectory, written here: for the flat
// scene dtheta = log(R_{k-1}^T R_k), dv = R_{k-1}^T (v_k - v_{k-1} - g h);
// with delay compensation the time stamps move back by the group delay.
TEST_F(SensorIntegration, MipCarriesCompensatedIncrementsAndDelayCompensationMovesTheStamps) {
  const scene::SceneConfig sc = scene::parse_scene_text(kScene, "s.toml", ".");
  const scene::ImuConfig& imu = sc.imus.at(0);
  const EngineRun run = run_scene_device(sc, 400, "mip", [](emission::DeviceOptions& dev) {
    dev.sensor_model.reset();  // the ideal sensor: the increments are the motion's alone
    dev.chain.preset = "mip";  // single pole at 100 Hz, 8 kHz internal
    dev.chain.compensate_delay = true;
  });
  ASSERT_TRUE(run.finished);
  auto decoder = drivers::make_stream_decoder("mip");
  std::vector<drivers::DecodedSample> wire;
  decoder->feed(run.bytes, [&](const drivers::DecodedSample& s) { wire.push_back(s); });
  ASSERT_EQ(wire.size(), 400u);
  const BatchResult b = run_batch(scene::scene_trajectory(sc), scene::pipeline_options(sc, imu));
  const double h = 1.0 / 200.0;
  // Single pole at fc = 100 Hz, fs = 8000 Hz: DC delay 1/(2 tan(pi fc/fs)) samples.
  const TimeNs delay_ns = std::llround(1.0 / (2.0 * std::tan(std::numbers::pi * 100.0 / 8000.0)) / 8000.0 * 1e9);
  for (std::size_t k = 1; k < wire.size(); ++k) {
    const Mat3& R0 = b.trajectory[k - 1].attitude;
    const Vec3 dtheta = so3::log(R0.transpose() * b.trajectory[k].attitude);
    const Vec3 dv = R0.transpose() * (b.trajectory[k].velocity_m_s - b.trajectory[k - 1].velocity_m_s -
                                      sc.physics.flat_gravity_m_s2 * h);
    // float32 on the wire: 2^-24 relative.
    EXPECT_LT((wire[k].delta_theta_rad - dtheta).norm(), 1e-7 * dtheta.norm() + 1e-12) << k;
    EXPECT_LT((wire[k].delta_velocity_m_s - dv).norm(), 1e-7 * dv.norm() + 1e-12) << k;
    EXPECT_NEAR(static_cast<double>(b.imu[k].t_ns - wire[k].t_ns), static_cast<double>(delay_ns), 1000.0) << k;
  }
}

// [imu.error_model.signal_chain] is parsed strictly, and checked against the
// device's rate at parse time (check-config refuses what a start would).
TEST(SignalChainConfig, RefusesUnknownKeysAndChainsTheRateCannotRunNamingFileLineAndKey) {
  const std::string head = scene_head(300) + "[imu.error_model.signal_chain]\n";  // line 12
  const std::vector<BadCase> cases = {
      {"unknown key", "preset = \"mip\"\ncutoff = 3\n", "imu[0].error_model.signal_chain.cutoff", "unknown key", 14},
      {"unknown preset", "preset = \"bmi088\"\n", "imu[0].error_model.signal_chain.preset", "unknown signal chain preset", 13},
      {"oversampling", "oversampling = 0\n", "imu[0].error_model.signal_chain.oversampling", "1..1024", 13},
      {"adis at 300 Hz", "preset = \"adis16470\"\n", "imu[0].error_model.signal_chain",
       "does not divide 2000 (at rate_hz 300)", 12},
      {"beyond half the internal rate", "oversampling = 2\n[[imu.error_model.signal_chain.stage]]\nkind = \"butterworth\"\nfrequency_hz = 400\n",
       "imu[0].error_model.signal_chain.stage[0].frequency_hz", "stage 1 (butterworth): frequency_hz 400", 16},
      {"stage kind", "[[imu.error_model.signal_chain.stage]]\nkind = \"kalman\"\n",
       "imu[0].error_model.signal_chain.stage[0].kind", "unknown filter kind 'kalman'", 14},
      {"vibration key", "[imu.error_model.signal_chain.vibration]\nbump = 1\n",
       "imu[0].error_model.signal_chain.vibration.bump", "unknown key 'bump'; allowed: sinusoid, random, random_angular, rotor, shock", 14},
      {"shock shape", "[[imu.error_model.signal_chain.vibration.shock]]\ntime_s = 2\npeak_g = [0, 0, 20]\nduration_ms = 11\n"
       "shape = \"square\"\n",
       "imu[0].error_model.signal_chain.vibration.shock[0].shape", "expected \"half_sine\" or \"sawtooth\"", 17},
      {"shock missing peak", "[[imu.error_model.signal_chain.vibration.shock]]\ntime_s = 2\nduration_ms = 11\n",
       "imu[0].error_model.signal_chain.vibration.shock[0]", "missing 'peak_g' (linear) or 'angular_peak_deg_s2'", 13},
      {"angular psd key", "[imu.error_model.signal_chain.vibration.random_angular]\npsd_g2_per_hz = [[20, 0.01], [500, 0.01]]\n",
       "imu[0].error_model.signal_chain.vibration.random_angular.psd_g2_per_hz", "unknown key 'psd_g2_per_hz'", 14},
      {"amplitude scale order", "[imu.error_model.signal_chain.vibration.random]\npsd_g2_per_hz = [[20, 0.01], [500, 0.01]]\n"
       "amplitude_scale = [[5, 1], [2, 3]]\n",
       "imu[0].error_model.signal_chain.vibration.random.amplitude_scale[1]",
       "amplitude_scale point 2 must have a time after the previous one", 15},
      {"shock duration", "[[imu.error_model.signal_chain.vibration.shock]]\ntime_s = 2\npeak_g = [0, 0, 20]\nduration_ms = 0\n",
       "imu[0].error_model.signal_chain.vibration.shock[0].duration_ms", "shock 1: duration_s 0 s is not in [1e-05, 10] s", 16},
      {"rotor speed order", "[[imu.error_model.signal_chain.vibration.rotor]]\nspeed_rpm = [[0, 3000], [0, 4000]]\n"
       "[[imu.error_model.signal_chain.vibration.rotor.harmonic]]\norder = 1\n",
       "imu[0].error_model.signal_chain.vibration.rotor[0].speed_rpm[1]",
       "rotor 1: speed point 2 must have a time after the previous one", 14},
      {"rotor harmonic key", "[[imu.error_model.signal_chain.vibration.rotor]]\nspeed_rpm = 6000\n"
       "[[imu.error_model.signal_chain.vibration.rotor.harmonic]]\norder = 2\namplitude = 1\n",
       "imu[0].error_model.signal_chain.vibration.rotor[0].harmonic[0].amplitude", "unknown key 'amplitude'", 17},
      {"rotor without harmonics", "[[imu.error_model.signal_chain.vibration.rotor]]\nspeed_rpm = 6000\n",
       "imu[0].error_model.signal_chain.vibration.rotor[0].harmonic", "expected [[...harmonic]] tables", 13},
      {"rotor jitter", "[[imu.error_model.signal_chain.vibration.rotor]]\nspeed_rpm = 600\njitter_rpm = 100\n"
       "[[imu.error_model.signal_chain.vibration.rotor.harmonic]]\norder = 1\n",
       "imu[0].error_model.signal_chain.vibration.rotor[0].jitter_rpm", "rotor 1: jitter_rpm 100", 15},
      {"psd order", "[imu.error_model.signal_chain.vibration.random]\npsd_g2_per_hz = [[100, 0.01], [50, 0.02]]\n",
       "imu[0].error_model.signal_chain.vibration.random.psd_g2_per_hz[1]",
       "PSD point 2 must have a frequency above the previous one", 14},
  };
  expect_refused(head, cases);
  const scene::SceneConfig ok = scene::parse_scene_text(
      head + "oversampling = 4\ncompensate_delay = true\n[[imu.error_model.signal_chain.stage]]\nkind = \"notch\"\n"
             "frequency_hz = 250\nq = 4\n",
      "ok.toml", ".");
  const signal_chain::ChainSpec& c = ok.imus[0].error_model.chain;
  EXPECT_FALSE(ok.imus[0].error_model.ideal());
  EXPECT_FALSE(ok.imus[0].error_model.sensor().has_value());
  ASSERT_TRUE(c.stages && c.stages->size() == 1);
  EXPECT_EQ((*c.stages)[0].kind, signal_chain::StageKind::notch);
  EXPECT_EQ(c.oversampling, 4);
  EXPECT_TRUE(c.compensate_delay);
  // Vibration in body axes, reaching the sensor through its mounting.
  const std::string shaken =
      scene_head(400) + "[imu.mounting]\nlever_arm_m = [0.3, 0.0, -0.1]\n"
      "[[imu.error_model.signal_chain.vibration.sinusoid]]\nfrequency_hz = 120\nlinear_m_s2 = [0, 0, 3]\n"
      "angular_deg_s = [0, 2, 0]\n"
      "[imu.error_model.signal_chain.vibration.random]\npsd_g2_per_hz = [[20, 0.01], [500, 0.01]]\nseed = 4\n"
      "amplitude_scale = [[10, 1], [20, 2]]\n"
      "[[imu.error_model.signal_chain.vibration.rotor]]\nspeed_rpm = [[0, 3000], [10, 6000]]\njitter_rpm = 5\nseed = 3\n"
      "[[imu.error_model.signal_chain.vibration.rotor.harmonic]]\norder = 2\nangular_deg_s = [1, 0, 0]\nphase_deg = [90, 0, 0]\n"
      "[[imu.error_model.signal_chain.vibration.shock]]\ntime_s = 2.5\nshape = \"sawtooth\"\npeak_g = [0, 0, 20]\n"
      "duration_ms = 11\nreturn_ms = 300\n"
      "[[imu.error_model.signal_chain.vibration.shock]]\ntime_s = 4\nangular_peak_deg_s2 = [0, 0, 9000]\nduration_ms = 5\n"
      "[imu.error_model.signal_chain.vibration.random_angular]\npsd_rad2_s4_per_hz = [[20, 0.5], [300, 2]]\n"
      "axis_scale = [1, 0, 0]\nseed = 8\n";
  const scene::SceneConfig v = scene::parse_scene_text(shaken, "v.toml", ".");
  const signal_chain::VibrationSpec& vib = v.imus[0].error_model.chain.vibration;
  ASSERT_EQ(vib.sinusoids.size(), 1u);
  EXPECT_EQ(vib.sinusoids[0].linear_m_s2, Vec3(0.0, 0.0, 3.0));
  EXPECT_DOUBLE_EQ(vib.sinusoids[0].angular_rad_s.y(), 2.0 * std::numbers::pi / 180.0);
  ASSERT_TRUE(vib.random_linear.has_value());
  EXPECT_EQ(vib.random_linear->seed, 4u);
  ASSERT_EQ(vib.random_linear->amplitude_scale.size(), 2u);
  EXPECT_EQ(vib.random_linear->amplitude_scale[1].time_s, 20.0);
  EXPECT_EQ(vib.random_linear->amplitude_scale[1].scale, 2.0);
  ASSERT_EQ(vib.rotors.size(), 1u);
  ASSERT_EQ(vib.rotors[0].speed.size(), 2u);
  EXPECT_EQ(vib.rotors[0].speed[1].time_s, 10.0);
  EXPECT_EQ(vib.rotors[0].speed[1].rpm, 6000.0);
  EXPECT_EQ(vib.rotors[0].jitter_rpm, 5.0);
  EXPECT_EQ(vib.rotors[0].seed, 3u);
  ASSERT_EQ(vib.rotors[0].harmonics.size(), 1u);
  EXPECT_EQ(vib.rotors[0].harmonics[0].order, 2.0);
  EXPECT_DOUBLE_EQ(vib.rotors[0].harmonics[0].phase_rad.x(), std::numbers::pi / 2.0);
  ASSERT_GE(vib.shocks.size(), 1u);
  EXPECT_EQ(vib.shocks[0].time_s, 2.5);
  EXPECT_EQ(vib.shocks[0].shape, signal_chain::ShockShape::sawtooth);
  EXPECT_DOUBLE_EQ(vib.shocks[0].peak_m_s2.z(), 20.0 * 9.80665);
  EXPECT_DOUBLE_EQ(vib.shocks[0].duration_s, 0.011);
  EXPECT_DOUBLE_EQ(vib.shocks[0].return_s, 0.3);
  ASSERT_EQ(vib.shocks.size(), 2u);
  EXPECT_EQ(vib.shocks[1].peak_m_s2, Vec3::Zero());
  EXPECT_DOUBLE_EQ(vib.shocks[1].angular_peak_rad_s2.z(), 9000.0 * std::numbers::pi / 180.0);
  ASSERT_TRUE(vib.random_angular.has_value());
  ASSERT_EQ(vib.random_angular->psd.size(), 2u);
  EXPECT_EQ(vib.random_angular->psd[1].frequency_hz, 300.0);
  EXPECT_EQ(vib.random_angular->psd[1].rad2_s4_per_hz, 2.0);
  EXPECT_EQ(vib.random_angular->axis_scale, Vec3(1.0, 0.0, 0.0));
  EXPECT_EQ(vib.random_angular->seed, 8u);
  EXPECT_EQ(vib.lever_arm_m, Vec3(0.3, 0.0, -0.1));
  EXPECT_FALSE(v.imus[0].error_model.ideal());
}

}  // namespace
}  // namespace imuemu
}  // namespace unity_scene_test_sensor_integration
