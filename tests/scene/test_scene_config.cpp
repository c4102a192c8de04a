// Scene files (daemon/scene/scene_config.hpp, docs/scene-format.md): every example
// in config/ parses and passes --check-config; bad scenes fail with the file,
// the line and the dotted key of the offending value; the embedded default is
// config/default.toml; and the mounting (core/mounting.hpp) turns the body's
// trajectory into the sensor's so that the emitted IMU carries the lever-arm
// and axis-rotation effects an analytic rigid body predicts.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <numbers>
#include <sstream>

#include "core/limits.hpp"
#include "core/mounting.hpp"
#include "core/pipeline.hpp"
#include "core/reference_motion.hpp"
#include "daemon/scene/default_scene.hpp"
#include "daemon/scene/scene_check.hpp"
#include "daemon/scene/scene_config.hpp"
#include "daemon/scene/scene_runner.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_scene_test_scene_config {
namespace imuemu { using namespace ::imuemu; }

using namespace imuemu;
using namespace imuemu::scene;

namespace {

const std::filesystem::path kConfigDir = std::filesystem::path(IMUEMU_SOURCE_DIR) / "config";

std::string read_text(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// A private directory for the scene files a test writes.
class TempDir {
 public:
  TempDir() {
    path_ = std::filesystem::temp_directory_path() /
            ("imuemu_scene_test_" + std::to_string(::testing::UnitTest::GetInstance()->random_seed()) + "_" +
             ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::remove_all(path_);
    std::filesystem::create_directories(path_);
  }
  ~TempDir() { std::filesystem::remove_all(path_); }
  std::string write(const std::string& name, const std::string& text) const {
    const std::filesystem::path p = path_ / name;
    std::ofstream(p, std::ios::binary) << text;
    return p.string();
  }
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

}  // namespace

// ---- the examples ----

TEST(SceneExamples, EveryExampleParsesAndPassesTheCheck) {
  std::size_t examples = 0;
  for (const auto& entry : std::filesystem::directory_iterator(kConfigDir)) {
    if (entry.path().extension() != ".toml") continue;
    ++examples;
    SCOPED_TRACE(entry.path().string());
    SceneConfig scene;
    ASSERT_NO_THROW(scene = parse_scene_file(entry.path().string()));
    EXPECT_EQ(scene.name, entry.path().stem().string()) << "each example is named after its file";
    ASSERT_FALSE(scene.imus.empty());
    const SceneCheck check = check_scene(scene);
    EXPECT_FALSE(check.refused) << to_text(check);
    ASSERT_EQ(check.imus.size(), scene.imus.size());
    double cpu = 0.0;
    for (std::size_t i = 0; i < scene.imus.size(); ++i) {
      const ImuCheck& c = check.imus[i];
      // The engine must see at least its own window ahead (Delta samples),
      // and the emitter adds the margin on top.
      const double window_s = static_cast<double>(c.delta_samples) / static_cast<double>(c.rate_hz);
      EXPECT_GE(static_cast<double>(c.lookahead_ns) * 1e-9, window_s - 1e-9);
      // Live input: emitted the look-ahead + margin after the pose; a file or
      // sample source is read ahead, no delay (as the engine and `status` say, issue 26).
      if (is_live(scene.trajectory.kind))
        EXPECT_EQ(c.emission_delay_ns - c.lookahead_ns, std::llround(scene.live.margin_s * 1e9));
      else
        EXPECT_EQ(c.emission_delay_ns, 0);
      // Stated basis: 1 us per sample per device plus the chain's work
      // (increment nodes; internal samples with a sensor model or a chain;
      // random vibration components).
      EXPECT_DOUBLE_EQ(c.cpu_fraction, static_cast<double>(scene.imus[i].rate_hz) * (1e-6 + chain_cpu_seconds(c.work)));
      if (scene.imus[i].error_model.chain.is_ideal()) {
        EXPECT_EQ(c.work.vibration_rotations + c.work.vibration_direct, 0.0);
      } else {
        EXPECT_GT(c.oversampling, 1);
        EXPECT_GT(c.cpu_fraction, static_cast<double>(scene.imus[i].rate_hz) * 1e-6 * c.oversampling * 0.3);
      }
      cpu += c.cpu_fraction;
    }
    EXPECT_DOUBLE_EQ(check.total_cpu_fraction, cpu);
    const std::string text = to_text(check);
    std::cout << text;
    for (const ImuConfig& imu : scene.imus) EXPECT_NE(text.find(imu.name), std::string::npos) << text;
    EXPECT_NE(to_json(check).find("\"total_cpu_fraction\""), std::string::npos);
  }
  EXPECT_EQ(examples, 6u) << "bench-static, car-urban, aircraft-ecef-4h, live-udp, multirotor-vibration, default";
}

TEST(SceneExamples, ValuesAreReadAsWritten) {
  const SceneConfig car = parse_scene_file((kConfigDir / "car-urban.toml").string());
  EXPECT_EQ(car.physics.physics, Physics::flat);
  EXPECT_EQ(car.trajectory.kind, SourceKind::file);
  // Relative to the scene file's directory, not to the working directory.
  EXPECT_EQ(std::filesystem::path(car.trajectory.file_path),
            (kConfigDir / "data" / "car-urban.csv").lexically_normal());
  EXPECT_TRUE(car.trajectory.loop);
  EXPECT_EQ(car.imus[0].protocol, "mavlink2");
  EXPECT_TRUE(car.imus[0].stream_options.mavlink_highres_imu);
  EXPECT_EQ(car.imus[0].mounting.lever_arm_b_m, Vec3(1.2, 0.0, -0.4));
  EXPECT_EQ(car.imus[0].transport.pty.mode, 0660u);
  // window_s 0.1 at 250 Hz: Delta = 25 samples.
  EXPECT_EQ(pipeline_options(car, car.imus[0]).kernel.delta, 25);

  const SceneConfig air = parse_scene_file((kConfigDir / "aircraft-ecef-4h.toml").string());
  EXPECT_EQ(air.physics.physics, Physics::ecef);
  EXPECT_EQ(air.trajectory.kind, SourceKind::sample);
  EXPECT_EQ(air.trajectory.sample, SampleMotion::flight);
  EXPECT_DOUBLE_EQ(air.trajectory.duration_s, 4.0 * 3600.0);
  ASSERT_EQ(air.imus.size(), 2u);
  EXPECT_EQ(air.imus[0].protocol, "mip");
  EXPECT_EQ(air.imus[1].transport.type, TransportType::can);
  EXPECT_EQ(air.imus[1].transport.can.interface, "vcan0");
  // heading 90 deg: the sensor's x axis is the body's right axis (y).
  EXPECT_LT((air.imus[1].mounting.sensor_to_body * Vec3::UnitX() - Vec3::UnitY()).norm(), 1e-15);
  EXPECT_EQ(air.daemon.device_missing, DeviceMissingPolicy::wait);
  EXPECT_EQ(air.daemon.realtime_priority, 50);
  // Default control socket from the scene name.
  EXPECT_EQ(air.daemon.control_socket, "/run/imuemu/aircraft-ecef-4h.sock");

  // DroneCAN RawIMU is a 7-frame transfer per sample, NodeStatus one frame a
  // second (drivers/protocols/dronecan.hpp): 100 Hz -> 701 frames/s.
  const SceneCheck check = check_scene(air);
  ASSERT_TRUE(check.imus[1].can_frames_per_second.has_value());
  EXPECT_NEAR(*check.imus[1].can_frames_per_second, 701.0, 1e-9);
  ASSERT_TRUE(check.imus[1].link.has_value());
  EXPECT_GT(check.imus[1].link->load_fraction, 0.0);
  EXPECT_FALSE(check.imus[0].link.has_value()) << "a pty has no line rate";

  const SceneConfig udp = parse_scene_file((kConfigDir / "live-udp.toml").string());
  EXPECT_EQ(udp.trajectory.kind, SourceKind::udp);
  EXPECT_EQ(udp.trajectory.address, "0.0.0.0");
  EXPECT_EQ(udp.trajectory.port, 5005);
}

TEST(SceneExamples, EmbeddedDefaultIsConfigDefaultToml) {
  EXPECT_EQ(std::string(default_scene_toml()), read_text(kConfigDir / "default.toml"))
      << "daemon/scene/default_scene.cpp must hold config/default.toml verbatim";
  const SceneConfig scene = default_scene();
  EXPECT_EQ(scene.name, "default");
  EXPECT_EQ(scene.file, kDefaultSceneName);
  ASSERT_EQ(scene.imus.size(), 1u);
  // No hardware: a pty, and paths an unprivileged user can create.
  EXPECT_EQ(scene.imus[0].transport.type, TransportType::pty);
  EXPECT_EQ(scene.imus[0].transport.pty.link.rfind("/tmp/", 0), 0u);
  EXPECT_EQ(scene.daemon.control_socket.rfind("/tmp/", 0), 0u);
  EXPECT_EQ(scene.trajectory.kind, SourceKind::sample);
}

// ---- bad scenes ----

namespace {

// A valid scene; the cases below change one line or append lines.
const std::vector<std::string> kBaseLines = {
    "[scene]",                       // 1
    "name = \"t\"",                  // 2
    "physics = \"flat\"",            // 3
    "",                              // 4
    "[trajectory]",                  // 5
    "source = \"sample:static\"",    // 6
    "",                              // 7
    "[[imu]]",                       // 8
    "name = \"a\"",                  // 9
    "rate_hz = 100",                 // 10
    "protocol = \"native\"",         // 11
    "[imu.transport]",               // 12
    "type = \"pty\"",                // 13
    "link = \"/tmp/imuemu-t/a\"",    // 14
};

struct BadScene {
  std::string label;
  // Lines of kBaseLines replaced (1-based line, new text; the text may hold
  // several lines, "" empties the line).
  std::vector<std::pair<int, std::string>> edits;
  std::string appended;     // lines after the base
  std::uint32_t line;       // where the error must point
  std::string key;          // dotted key it must name
  std::string says;         // and a phrase of what is allowed
};

std::string scene_text(const BadScene& c) {
  std::string text;
  for (std::size_t i = 0; i < kBaseLines.size(); ++i) {
    std::string line = kBaseLines[i];
    for (const auto& [number, replacement] : c.edits)
      if (number == static_cast<int>(i + 1)) line = replacement;
    text += line + "\n";
  }
  return text + c.appended;
}

const std::string kSecondImu =
    "[[imu]]\n"              // 15
    "name = \"b\"\n"         // 16
    "rate_hz = 200\n"        // 17
    "protocol = \"native\"\n"  // 18
    "[imu.transport]\n"      // 19
    "type = \"pty\"\n"       // 20
    "link = \"/tmp/imuemu-t/b\"\n";  // 21

std::string second_imu_with(const std::string& from, const std::string& to) {
  std::string s = kSecondImu;
  s.replace(s.find(from), from.size(), to);
  return s;
}

}  // namespace

TEST(SceneErrors, BaseSceneIsValid) {
  TempDir dir;
  const BadScene none{"none", {}, "", 0, "", ""};
  const SceneConfig s = parse_scene_file(dir.write("base.toml", scene_text(none)));
  EXPECT_EQ(s.imus.size(), 1u);
  const SceneConfig two = parse_scene_file(dir.write("two.toml", scene_text({"two", {}, kSecondImu, 0, "", ""})));
  EXPECT_EQ(two.imus.size(), 2u);
}

TEST(SceneErrors, EachNamesFileLineKeyAndWhatIsAllowed) {
  const std::vector<BadScene> cases = {
      {"typo key", {{10, "rate_hx = 100"}}, "", 10, "imu[0].rate_hx", "allowed keys in imu[0]: name, rate_hz"},
      {"typo table", {}, "[smoothin]\nwindow_s = 1\n", 15, "smoothin", "allowed keys in the top level: scene"},
      {"typo in transport", {{14, "lnk = \"/tmp/x\""}}, "", 14, "imu[0].transport.lnk", "(type pty): type, link, mode"},
      {"wrong type", {{10, "rate_hz = \"100\""}}, "", 10, "imu[0].rate_hz", "expected an integer in 1..100000, got a string"},
      {"float for integer", {{10, "rate_hz = 100.0"}}, "", 10, "imu[0].rate_hz", "got a floating-point number"},
      {"rate out of range", {{10, "rate_hz = 200000"}}, "", 10, "imu[0].rate_hz", "expected an integer in 1..100000"},
      {"GNSS receiver rate", {{10, "rate_hz = 20"}, {11, "protocol = \"nmea\""}}, "", 10, "imu[0].rate_hz",
       "protocol nmea is a GNSS receiver: its navigation rate is 1..10 Hz, not 20"},
      {"GNSS receiver in a flat scene", {{10, "rate_hz = 5"}, {11, "protocol = \"ubx\""}}, "", 11, "imu[0].protocol",
       "reports WGS84 positions, which a flat scene does not have"},
      {"unknown protocol", {{11, "protocol = \"sirf\""}}, "", 11, "imu[0].protocol",
       "expected one of native, mavlink2, mip, nmea, ubx, vectornav, sbg, xsens, dronecan or j1939"},
      {"unknown physics", {{3, "physics = \"ned\""}}, "", 3, "scene.physics", "expected one of flat or ecef"},
      {"missing link", {{14, ""}}, "", 12, "imu[0].transport.link", "missing required key"},
      {"missing rate", {{10, ""}}, "", 8, "imu[0].rate_hz", "missing required key"},
      {"missing scene name", {{2, ""}}, "", 1, "scene.name", "missing required key"},
      {"baud zero", {{13, "type = \"serial\"\nport = \"/dev/ttyUSB0\""}, {14, "baud = 0"}}, "", 15, "imu[0].transport.baud",
       "expected an integer in 1..100000000"},
      {"parity", {{13, "type = \"serial\"\nport = \"/dev/ttyUSB0\""}, {14, "parity = \"evn\""}}, "", 15, "imu[0].transport.parity",
       "expected one of none, odd, even, mark or space"},
      {"same name", {}, second_imu_with("name = \"b\"", "name = \"a\""), 16, "imu[1].name",
       "already used by imu[0] (a)"},
      {"same pty link", {}, second_imu_with("/tmp/imuemu-t/b", "/tmp/imuemu-t/a"), 21, "imu[1].transport.link",
       "pty link /tmp/imuemu-t/a is already used by imu[0] (a)"},
      {"priority", {}, "[daemon]\nrealtime_priority = 100\n", 16, "daemon.realtime_priority", "0..99"},
      {"quaternion not unit", {}, "[imu.mounting]\nquaternion = [1.0, 0.1, 0.0, 0.0]\n", 16,
       "imu[0].mounting.quaternion", "not a unit quaternion"},
      {"lever arm length", {}, "[imu.mounting]\nlever_arm_m = [1.0, 2.0]\n", 16, "imu[0].mounting.lever_arm_m",
       "expected an array of 3 numbers"},
      {"options of another protocol", {}, "[imu.mavlink]\nsystem_id = 3\n", 15, "imu[0].mavlink",
       "options for protocol mavlink2, but this device's protocol is native"},
      {"can protocol on a pty", {{11, "protocol = \"dronecan\""}}, "", 13, "imu[0].transport.type",
       "needs transport type can or null"},
      {"error model", {}, "[imu.error_model]\nmodel = \"noisy\"\n", 16, "imu[0].error_model.model",
       "unknown key 'model'"},
      {"circle in ecef", {{3, "physics = \"ecef\""}, {6, "source = \"sample:circle\""}}, "", 6, "trajectory.source", "flat-scene motion"},
      {"gravity in ecef", {{3, "physics = \"ecef\"\ngravity_m_s2 = 9.8"}}, "", 4, "scene.gravity_m_s2",
       "applies to physics = \"flat\" only"},
      {"speed on udp", {{6, "source = \"udp:127.0.0.1:5005\"\nspeed = 2"}}, "", 7, "trajectory.speed",
       "applies to file: and sample: sources only"},
      {"bad speed", {{6, "source = \"sample:static\"\nspeed = \"fast\""}}, "", 7, "trajectory.speed", "fast"},
      {"missing file", {{6, "source = \"file:no-such.csv\""}}, "", 6, "trajectory.source", "does not exist"},
      {"bad port", {{6, "source = \"udp:127.0.0.1:70000\""}}, "", 6, "trajectory.source", "port '70000' is not 1..65535"},
      {"delta and window", {}, "[smoothing]\ndelta = 10\nwindow_s = 0.1\n", 17, "smoothing.window_s", "not both"},
      {"pulse overlaps", {}, "[imu.sync]\nchip = \"gpiochip0\"\nline = 3\nwidth_us = 20000\n", 18,
       "imu[0].sync.width_us", "overlaps the next one"},
      {"window too wide", {{10, "rate_hz = 100000"}}, "[smoothing]\nwindow_s = 100\n", 8, "imu[0]",
       "10000000 samples at 100000 Hz"},
      {"imu not an array", {{8, "[imu]"}}, "", 8, "imu", "expected one or more [[imu]] tables, got a table"},
      {"too many sample knots", {{6, "source = \"sample:static\"\nduration_s = 86400\nknot_interval_s = 0.001"}}, "", 8,
       "trajectory.knot_interval_s", "more than 10 million built-in knots"},
      {"toml syntax", {{10, "rate_hz = = 100"}}, "", 10, "", "TOML syntax"},
  };
  TempDir dir;
  for (const BadScene& c : cases) {
    SCOPED_TRACE(c.label);
    std::string file_name = c.label;
    for (char& ch : file_name)
      if (ch == ' ') ch = '_';
    const std::string path = dir.write(file_name + ".toml", scene_text(c));
    try {
      (void)parse_scene_file(path);
      ADD_FAILURE() << "accepted:\n" << scene_text(c);
    } catch (const SceneError& e) {
      const std::string message = e.what();
      std::cout << "  " << c.label << ": " << message.substr(dir.path().string().size() + 1) << "\n";
      EXPECT_EQ(e.file(), path);
      EXPECT_EQ(e.line(), c.line) << message;
      EXPECT_EQ(e.key(), c.key) << message;
      EXPECT_EQ(message.rfind(path + ":" + std::to_string(c.line) + ":", 0), 0u) << message;
      if (!c.key.empty()) {
        EXPECT_NE(message.find(c.key), std::string::npos) << message;
      }
      EXPECT_NE(message.find(c.says), std::string::npos) << message;
    }
  }
}

TEST(SceneErrors, MissingFileNamesIt) {
  try {
    (void)parse_scene_file("/nonexistent/scene.toml");
    ADD_FAILURE();
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/scene.toml"), std::string::npos);
  }
}

TEST(SceneConfigValues, WindowAndMountingForms) {
  TempDir dir;
  const BadScene base{"", {}, "", 0, "", ""};
  // Window: one knot interval by default; window_s 0.05 at 100 Hz: Delta 5.
  SceneConfig s = parse_scene_file(dir.write("w.toml", scene_text(base)));
  EXPECT_EQ(pipeline_options(s, s.imus[0]).kernel.delta, 100) << "default window: one knot interval (1 s) at 100 Hz";
  std::string text = scene_text(base);
  text.insert(text.find("[[imu]]"), "[smoothing]\nwindow_s = 0.05\n\n");
  s = parse_scene_file(dir.write("w2.toml", text));
  EXPECT_EQ(pipeline_options(s, s.imus[0]).kernel.delta, 5);

  // The same mounting as heading 90 deg and as the quaternion of a 90 deg
  // turn about z: (cos 45, 0, 0, sin 45).
  const double h = std::sqrt(0.5);
  const SceneConfig a =
      parse_scene_file(dir.write("a.toml", scene_text(base) + "[imu.mounting]\nheading_deg = 90\n"));
  std::ostringstream q;
  q.precision(17);
  q << "[imu.mounting]\nquaternion = [" << h << ", 0, 0, " << h << "]\n";
  const SceneConfig b = parse_scene_file(dir.write("b.toml", scene_text(base) + q.str()));
  EXPECT_LT((a.imus[0].mounting.sensor_to_body - b.imus[0].mounting.sensor_to_body).cwiseAbs().maxCoeff(), 1e-15);
  Mat3 expected;
  expected << 0, -1, 0, 1, 0, 0, 0, 0, 1;  // columns: sensor x = body y, sensor y = -body x
  EXPECT_LT((a.imus[0].mounting.sensor_to_body - expected).cwiseAbs().maxCoeff(), 1e-15);
}

// ---- mounting against analytic truth ----

namespace {

PipelineOptions flat_options(std::int64_t rate_hz, int delta) {
  PipelineOptions po;
  po.scene.physics = Physics::flat;
  po.rate_hz = rate_hz;
  po.kernel.delta = delta;
  return po;
}

std::vector<Pose> mounted(const std::vector<Pose>& body, const Mounting& m) {
  std::vector<Pose> out;
  for (const Pose& p : body) out.push_back(sensor_pose(p, m));
  return out;
}

}  // namespace

TEST(Mounting, SensorPoseIsTheRigidBodyPoint) {
  // Body at (10, 20, -5) headed east (R = R_z(90 deg)); a sensor 2 m forward
  // is 2 m east of the reference point, and its forward axis points east.
  Pose body;
  body.t_ns = 123;
  body.position_m = Vec3(10, 20, -5);
  body.attitude << 0, -1, 0, 1, 0, 0, 0, 0, 1;
  Mounting m;
  m.lever_arm_b_m = Vec3(2, 0, 0);
  const Pose s = sensor_pose(body, m);
  EXPECT_EQ(s.t_ns, 123);
  EXPECT_LT((s.position_m - Vec3(10, 22, -5)).norm(), 1e-15);
  EXPECT_LT((s.attitude * Vec3::UnitX() - Vec3::UnitY()).norm(), 1e-15);
  EXPECT_TRUE(is_rotation(s.attitude));
}

// A body spinning at constant rate w about its down axis (fixed at the NED
// origin, flat scene). A sensor at lever arm r moves on a circle: its specific
// force in its own (body-parallel) axes is the centripetal -w^2 (r_x, r_y, 0)
// minus gravity (0, 0, g); its gyro is (0, 0, w). Poses at 20 Hz -> 100 Hz IMU
// (the remaining error is the spline's on a 0.025 rad knot step).
TEST(Mounting, LeverArmOnASpinningBodyGivesTheCentripetalForce) {
  const double w = 0.5;  // rad/s
  const double g = 9.80665;
  const reference::ConstantRate body(Mat3::Identity(), Vec3(0, 0, w), 0, 40 * kNsPerSecond);
  const std::vector<Pose> knots = reference::sample_knots(body, kNsPerSecond / 20);
  Mounting m;
  m.lever_arm_b_m = Vec3(2.0, 0.5, -0.3);
  const BatchResult result = run_batch(mounted(knots, m), flat_options(100, 10));
  ASSERT_GT(result.imu.size(), 3000u);
  const Vec3 expected_accel(-w * w * 2.0, -w * w * 0.5, -g);
  const Vec3 expected_gyro(0, 0, w);
  double worst_accel = 0.0, worst_gyro = 0.0;
  for (const ImuSample& s : result.imu) {
    const double t = seconds_between(0, s.t_ns);
    if (t < 2.0 || t > 38.0) continue;  // away from the ends' extrapolated windows
    worst_accel = std::max(worst_accel, (s.accel_m_s2 - expected_accel).norm());
    worst_gyro = std::max(worst_gyro, (s.gyro_rad_s - expected_gyro).norm());
  }
  std::cout << "lever arm on spinning body: worst accel error " << worst_accel << " m/s^2 (centripetal "
            << w * w * Vec3(2.0, 0.5, 0).norm() << "), gyro " << worst_gyro << " rad/s\n";
  EXPECT_LT(worst_accel, 1e-4);
  EXPECT_LT(worst_gyro, 1e-6);
  // Without the mounting the body origin feels no centripetal force: the
  // lever arm is what makes the difference.
  const BatchResult origin = run_batch(knots, flat_options(100, 10));
  EXPECT_LT((origin.imu[2000].accel_m_s2 - Vec3(0, 0, -g)).norm(), 1e-6);
}

// A pure rotation mounting permutes (and signs) the axes: with the sensor
// turned 90 deg about down (sensor x = body y, sensor y = -body x), the
// sensor reads gyro (w_y, -w_x, w_z) and accel (f_y, -f_x, f_z) of the body's
// own ideal IMU (reference::truth_imu, analytic).
TEST(Mounting, RotationMountingPermutesTheAxes) {
  const Vec3 omega_b(0.1, -0.2, 0.3);
  const Mat3 R0 = attitude::rotation_from_hpr({0.3, 0.2, -0.1});
  const reference::ConstantRate body(R0, omega_b, 0, 30 * kNsPerSecond);
  const std::vector<Pose> knots = reference::sample_knots(body, kNsPerSecond / 10);
  Mounting m;
  m.sensor_to_body << 0, -1, 0, 1, 0, 0, 0, 0, 1;
  const PipelineOptions po = flat_options(100, 10);
  const BatchResult result = run_batch(mounted(knots, m), po);
  double worst_gyro = 0.0, worst_accel = 0.0;
  std::size_t compared = 0;
  for (const ImuSample& s : result.imu) {
    const double t = seconds_between(0, s.t_ns);
    if (t < 2.0 || t > 28.0) continue;
    const ImuSample truth = reference::truth_imu(body, po.scene, s.t_ns);
    const Vec3 gyro_expected(truth.gyro_rad_s.y(), -truth.gyro_rad_s.x(), truth.gyro_rad_s.z());
    const Vec3 accel_expected(truth.accel_m_s2.y(), -truth.accel_m_s2.x(), truth.accel_m_s2.z());
    worst_gyro = std::max(worst_gyro, (s.gyro_rad_s - gyro_expected).norm());
    worst_accel = std::max(worst_accel, (s.accel_m_s2 - accel_expected).norm());
    ++compared;
  }
  ASSERT_GT(compared, 2000u);
  EXPECT_LT(worst_gyro, 1e-6);
  EXPECT_LT(worst_accel, 1e-5);
}

// ---- --check-config figures ----

TEST(SceneCheck, UartBudgetRefusesALinkTooSlowForTheRate) {
  TempDir dir;
  auto scene_with_baud = [&](int baud) {
    std::string text = scene_text({"", {}, "", 0, "", ""});
    const std::string rate = "rate_hz = 100", pty = "type = \"pty\"\nlink = \"/tmp/imuemu-t/a\"";
    text.replace(text.find(rate), rate.size(), "rate_hz = 400");
    text.replace(text.find(pty), pty.size(),
                 "type = \"serial\"\nport = \"/dev/ttyUSB7\"\nbaud = " + std::to_string(baud));
    return parse_scene_file(dir.write("serial" + std::to_string(baud) + ".toml", text));
  };
  // 8N1: 10 line bits per byte (1 start + 8 data + 1 stop).
  const SceneCheck slow = check_scene(scene_with_baud(115200));
  ASSERT_TRUE(slow.imus[0].link.has_value() && slow.imus[0].bytes_per_second.has_value());
  EXPECT_NEAR(slow.imus[0].link->load_fraction, *slow.imus[0].bytes_per_second * 10.0 / 115200.0, 1e-12);
  EXPECT_GT(slow.imus[0].link->load_fraction, 1.0);
  EXPECT_TRUE(slow.refused);
  EXPECT_NE(to_text(slow).find("REFUSED"), std::string::npos);
  const SceneCheck fast = check_scene(scene_with_baud(921600));
  EXPECT_NEAR(fast.imus[0].link->load_fraction, *fast.imus[0].bytes_per_second * 10.0 / 921600.0, 1e-12);
  EXPECT_FALSE(fast.refused) << to_text(fast);
}

// Issue 18: check-config prints each scene fault, and refuses what a start
// would: a link fault the device's protocol has no field for (MIP has no
// sequence counter), naming the type, the device and the protocol.
TEST(SceneCheck, FaultsArePrintedAndAFaultTheProtocolCannotShowIsRefused) {
  TempDir dir;
  const std::string mip = second_imu_with("protocol = \"native\"", "protocol = \"mip\"");
  auto check_with = [&](const std::string& name, const std::string& fault) {
    return check_scene(parse_scene_file(dir.write(name, scene_text({"", {}, "", 0, "", ""}) + mip + fault)));
  };
  const SceneCheck ok = check_with("ok.toml", "[[imu.fault]]\ntype = \"bad_checksum\"\nafter_s = 2\nduration_s = 1\n");
  EXPECT_FALSE(ok.refused) << to_text(ok);
  ASSERT_EQ(ok.imus.size(), 2u);
  EXPECT_TRUE(ok.imus[0].faults.empty());
  ASSERT_EQ(ok.imus[1].faults.size(), 1u);
  EXPECT_NE(ok.imus[1].faults[0].find("bad_checksum"), std::string::npos) << ok.imus[1].faults[0];
  EXPECT_NE(to_text(ok).find("    fault: "), std::string::npos) << to_text(ok);
  const SceneCheck refused =
      check_with("seq.toml", "[[imu.fault]]\ntype = \"sequence_jump\"\nafter_s = 2\nsequence_step = 5\n");
  EXPECT_TRUE(refused.refused);
  const std::string text = to_text(refused);
  EXPECT_NE(text.find("fault refused: fault type sequence_jump on imu 'b' (mip): the protocol has no sequence counter"),
            std::string::npos)
      << text;
  EXPECT_NE(text.find("REFUSED"), std::string::npos);
}

TEST(SceneCheck, DevicesOnOneCanInterfaceShareItsBudget) {
  TempDir dir;
  std::string text = scene_text({"", {}, "", 0, "", ""});
  text.erase(text.find("[[imu]]"));
  for (int node : {10, 11}) {
    text += "[[imu]]\nname = \"can" + std::to_string(node) + "\"\nrate_hz = 400\nprotocol = \"dronecan\"\n"
            "dronecan.node_id = " + std::to_string(node) + "\n[imu.transport]\ntype = \"can\"\ninterface = \"vcan0\"\n";
  }
  const SceneCheck check = check_scene(parse_scene_file(dir.write("bus.toml", text)));
  ASSERT_EQ(check.shared_links.size(), 1u);
  EXPECT_EQ(check.shared_links[0].link, "can vcan0");
  // Same traffic twice: the bus carries the sum of both devices' loads.
  EXPECT_NEAR(check.shared_links[0].budget.load_fraction,
              check.imus[0].link->load_fraction + check.imus[1].link->load_fraction, 1e-12);
  EXPECT_NEAR(*check.imus[0].can_frames_per_second, 7.0 * 400 + 1, 1e-9);

  // The same node id twice on one bus is an error at the second device.
  std::string clash = text;
  const std::string second_id = "dronecan.node_id = 11";
  clash.replace(clash.find(second_id), second_id.size(), "dronecan.node_id = 10");
  try {
    (void)parse_scene_file(dir.write("clash.toml", clash));
    ADD_FAILURE() << "accepted two DroneCAN nodes with id 10 on vcan0";
  } catch (const SceneError& e) {
    EXPECT_EQ(e.key(), "imu[1].dronecan.node_id") << e.what();
    EXPECT_NE(std::string(e.what()).find("DroneCAN node id 10 on vcan0 is already used by imu[0] (can10)"),
              std::string::npos)
        << e.what();
  }
}

// ---- issue 13: --check-config checks what a start would refuse ----

namespace {

std::string file_scene(const std::string& trajectory, const std::string& link, const std::string& extra_imu = "",
                       const std::string& trajectory_keys = "") {
  return "[scene]\nname = \"chk\"\nphysics = \"flat\"\n[trajectory]\nsource = \"file:" + trajectory + "\"\n" +
         trajectory_keys + "[[imu]]\nname = \"a\"\nprotocol = \"native\"\nrate_hz = 100\n[imu.transport]\ntype = \"pty\"\nlink = \"" +
         link + "\"\n" + extra_imu;
}

std::string second_imu(const std::string& link) {
  return "[[imu]]\nname = \"b\"\nprotocol = \"native\"\nrate_hz = 100\n[imu.transport]\ntype = \"pty\"\nlink = \"" + link + "\"\n";
}

const char* const kHeader = "time_s,north_m,east_m,down_m,heading_deg,pitch_deg,roll_deg\n";

// The message check_startable throws for a scene, or "" if it accepts it.
std::string startable_error(const std::string& scene_path, const std::string& pty_link_dir = "") {
  RunnerOptions options;
  options.pty_link_dir = pty_link_dir;
  try {
    check_startable(parse_scene_file(scene_path), options);
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST(CheckStartable, RefusesWhatAStartWouldRefuse) {
  TempDir dir;
  const std::string d = dir.path().string();
  dir.write("good.csv", std::string(kHeader) + "0,0,0,0,0,0,0\n1,1,0,0,0,0,0\n2,2,0,0,0,0,0\n");
  EXPECT_EQ(startable_error(dir.write("ok.toml", file_scene(d + "/good.csv", d + "/tty0"))), "");

  // Malformed trajectory content: file:line.
  dir.write("bad.csv", std::string(kHeader) + "0,0,0,0,0,0,0\n1,1,0,zz,0,0,0\n");
  std::string e = startable_error(dir.write("bad.toml", file_scene(d + "/bad.csv", d + "/tty0")));
  EXPECT_NE(e.find("bad.csv:3"), std::string::npos) << e;

  // Knots the engine refuses: a 179-degree heading glitch within a window.
  dir.write("glitch.csv", std::string(kHeader) + "0,0,0,0,0,0,0\n0.5,1,0,0,179,0,0\n1,2,0,0,0,0,0\n2,3,0,0,0,0,0\n");
  e = startable_error(dir.write("glitch.toml", file_scene(d + "/glitch.csv", d + "/tty0")));
  EXPECT_NE(e.find("imu 'a'"), std::string::npos) << e;
  EXPECT_NE(e.find("knot 1"), std::string::npos) << e;

  // Pty links that cannot be published.
  e = startable_error(dir.write("root.toml", file_scene(d + "/good.csv", "/")));
  EXPECT_NE(e.find("names a directory"), std::string::npos) << e;
  e = startable_error(dir.write("dir.toml", file_scene(d + "/good.csv", d)));
  EXPECT_NE(e.find("existing directory"), std::string::npos) << e;
  e = startable_error(dir.write("long.toml", file_scene(d + "/good.csv", d + "/" + std::string(300, 'x'))));
  EXPECT_NE(e.find("NAME_MAX"), std::string::npos) << e;

  // Aliases of one link: "./x" and "//x" forms, and the same file name in
  // two directories under --pty-link-dir.
  e = startable_error(dir.write("alias.toml", file_scene(d + "/good.csv", d + "/tty0", second_imu(d + "/./tty0"))));
  EXPECT_NE(e.find("same path"), std::string::npos) << e;
  e = startable_error(dir.write("alias2.toml", file_scene(d + "/good.csv", d + "/tty0", second_imu("/" + d + "/tty0"))));
  EXPECT_NE(e.find("same path"), std::string::npos) << e;
  const std::string two_dirs = dir.write("two.toml", file_scene(d + "/good.csv", d + "/one/tty0", second_imu(d + "/two/tty0")));
  EXPECT_EQ(startable_error(two_dirs), "");
  e = startable_error(two_dirs, d + "/links");
  EXPECT_NE(e.find("same path"), std::string::npos) << e;

  // A control socket whose directory cannot be made (its parent is a file).
  e = startable_error(dir.write("sock.toml", file_scene(d + "/good.csv", d + "/tty0") +
                                                 "[daemon]\ncontrol_socket = \"" + d + "/good.csv/sub/s.sock\"\n"));
  EXPECT_NE(e.find("control socket"), std::string::npos) << e;
}

// A 100 KB name is not echoed whole.
TEST(SceneErrors, EchoedInputIsBounded) {
  const std::string name(100000, 'n');
  const std::string text = "[scene]\nname = \"" + name + "\"\n";
  try {
    (void)parse_scene_text(text, "big.toml", ".");
    ADD_FAILURE();
  } catch (const SceneError& e) {
    EXPECT_LT(std::string(e.what()).size(), 4000u) << std::string(e.what()).substr(0, 300);
  }
}

// Issue 13: loop = true held 24 h of copies whatever the trajectory's size:
// 20 000 knots 1 ms apart (a 20 s flight) made 4115 copies, 82 M poses
// (~9 GB). The copies are capped at limits::kMaxLoopKnots knots in all (the
// run restarts after them, as after 24 h); each copy is the flight shifted by
// its span plus max_gap_s plus one knot interval (the silent seam).
TEST(SceneLoop, LoopedCopiesAreCappedInKnots) {
  SceneConfig scene = parse_scene_text(
      "[scene]\nname = \"loop\"\nphysics = \"flat\"\n[trajectory]\nsource = \"sample:flight\"\nloop = true\n"
      "knot_interval_s = 0.001\n[smoothing]\nmax_gap_s = 1.0\n[[imu]]\nname = \"a\"\nprotocol = \"native\"\n"
      "rate_hz = 100\n[imu.transport]\ntype = \"null\"\n",
      "loop.toml", ".");
  std::vector<Pose> once(20'000);
  for (std::size_t i = 0; i < once.size(); ++i) {
    once[i].t_ns = static_cast<TimeNs>(i) * 1'000'000;
    once[i].position_m = Vec3(static_cast<double>(i), 0.0, 0.0);
    once[i].attitude = Mat3::Identity();
  }
  const std::vector<Pose> loop = looped(once, scene, kLoopSpanNs);
  ASSERT_LE(loop.size(), limits::kMaxLoopKnots);
  ASSERT_EQ(loop.size() % once.size(), 0u);
  const std::size_t copies = loop.size() / once.size();
  EXPECT_EQ(copies, limits::kMaxLoopKnots / once.size());  // 50
  const TimeNs shift_ns = 19'999'000'000 + 1'000'000'000 + 1'000'000;  // span + max_gap_s + knot interval
  for (std::size_t c = 0; c < copies; ++c) {
    ASSERT_EQ(loop[c * once.size()].t_ns, static_cast<TimeNs>(c) * shift_ns) << c;
    ASSERT_EQ(loop[c * once.size() + once.size() - 1].t_ns, static_cast<TimeNs>(c) * shift_ns + 19'999'000'000) << c;
  }
  // A short trajectory still covers the 24 h.
  const std::vector<Pose> few(once.begin(), once.begin() + 2);
  const std::vector<Pose> day = looped(few, scene, kLoopSpanNs);
  const TimeNs few_shift_ns = 1'000'000 + 1'000'000'000 + 1'000'000;
  EXPECT_EQ(day.size(), 2u * static_cast<std::size_t>((kLoopSpanNs + few_shift_ns - 1) / few_shift_ns));
  EXPECT_GE(day.back().t_ns, kLoopSpanNs - few_shift_ns);
}
}  // namespace unity_scene_test_scene_config
