// Settings that overflow (issue 26, N5-N12): each setting of the signal
// chain, the vibration, the sensor model and the faults that `--check-config`
// called OK but that overflowed into NaN, zeros, INT64_MAX or huge
// allocations is refused at its key (file:line:column, the dotted key) with
// the core's own message, or, for values a part can reach, saturated and
// flagged. The truth is written here from the definitions: the bounds of
// core/signal_chain/vibration.hpp, filters.hpp, signal_chain.hpp and
// core/sensor/sensor_model.hpp, the part's range of the fault context, the
// message the core throws for the same spec.
#include <gtest/gtest.h>

#include <time.h>
#include <unistd.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <numbers>
#include <string>
#include <vector>

#include "core/fault/timeline.hpp"
#include "core/sensor/datasheet.hpp"
#include "core/sensor/sensor_model.hpp"
#include "core/setting_error.hpp"
#include "core/signal_chain/filters.hpp"
#include "core/signal_chain/signal_chain.hpp"
#include "core/signal_chain/vibration.hpp"
#include "daemon/scene/scene_check.hpp"
#include "daemon/scene/scene_config.hpp"

#if defined(__SANITIZE_ADDRESS__)
#define IMUEMU_TEST_SANITIZED 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define IMUEMU_TEST_SANITIZED 1
#endif
#endif

namespace imuemu {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

// A one-device scene (flat, static, null transport) at rate_hz; its last line is 11.
std::string scene_head(int rate_hz, const std::string& protocol = "native") {
  return "[scene]\nname = \"x\"\nphysics = \"flat\"\n[trajectory]\nsource = \"sample:static\"\n"
         "[[imu]]\nname = \"a\"\nrate_hz = " +
         std::to_string(rate_hz) + "\nprotocol = \"" + protocol + "\"\n[imu.transport]\ntype = \"null\"\n";
}

// The SceneError a scene text is refused with (a failure if it is accepted).
scene::SceneError refusal(const std::string& text) {
  try {
    (void)scene::parse_scene_text(text, "bad.toml", ".");
  } catch (const scene::SceneError& e) {
    return e;
  }
  ADD_FAILURE() << "accepted:\n" << text;
  return scene::SceneError("", 0, 0, "", "");
}

// The message a core call refuses with, and its key (a failure if it accepts).
struct CoreRefusal {
  std::string key, what;
};
CoreRefusal core_refusal(const std::function<void()>& call) {
  try {
    call();
  } catch (const SettingError& e) {
    return {e.key(), e.what()};
  } catch (const std::invalid_argument& e) {
    return {"", e.what()};
  }
  ADD_FAILURE() << "the core accepted it";
  return {};
}

bool ends_with(const std::string& s, const std::string& tail) {
  return s.size() >= tail.size() && s.compare(s.size() - tail.size(), tail.size(), tail) == 0;
}

bool finite(const Vec3& v) { return v.allFinite(); }

// A stationary body in the flat scene, and the chain's output of ticks
// 0..n-1 (contiguous, each with the previous tick's kinematics).
std::vector<signal_chain::ChainOutput> run_chain(signal_chain::DeviceChain& chain, int n,
                                                 signal_chain::IncrementConvention convention) {
  SceneModel scene;
  Kinematics k;
  const ImuSample ideal = imu_from_kinematics(scene, k);
  std::vector<signal_chain::ChainOutput> out;
  for (int i = 0; i < n; ++i) out.push_back(chain.step(static_cast<std::uint64_t>(i), k, ideal, i > 0 ? &k : nullptr, convention));
  return out;
}

// ---------------------------------------------------------------- N5, filters

// N5: a low-pass at 1e-300 Hz made the chain's DC gain 0/0 (NaN; the
// wire then carried exact zeros with status 0). Refused at the stage's key,
// with the message the core's design() gives; a corner at the bound runs.
TEST(SettingBounds, N5LowPassFarBelowTheInternalRateIsRefusedAtItsKeyNotTurnedIntoNaN) {
  using signal_chain::Stage;
  using signal_chain::StageKind;
  const CoreRefusal core =
      core_refusal([] { (void)signal_chain::design({{.kind = StageKind::low_pass, .frequency_hz = 1e-300}}, 8000.0); });
  EXPECT_EQ(core.key, "stage[0].frequency_hz");
  EXPECT_EQ(core.what.rfind("stage 1 (low-pass): frequency_hz 1e-300 Hz is not in [0.08, 4000) Hz", 0), 0u) << core.what;
  const std::string text = scene_head(1000) +
                           "[imu.error_model.signal_chain]\noversampling = 8\n"  // lines 12-13
                           "[[imu.error_model.signal_chain.stage]]\nkind = \"low-pass\"\nfrequency_hz = 1e-300\n";
  const scene::SceneError e = refusal(text);
  EXPECT_EQ(e.key(), "imu[0].error_model.signal_chain.stage[0].frequency_hz");
  EXPECT_EQ(e.line(), 16u);
  EXPECT_TRUE(ends_with(e.what(), core.what + " (at rate_hz 1000)")) << e.what() << "\n" << core.what;
  // q of 1e-300 (K/q overflowed) and 1e308.
  const CoreRefusal q = core_refusal(
      [] { (void)signal_chain::design({{.kind = StageKind::anti_alias, .frequency_hz = 100.0, .q = 1e-300}}, 8000.0); });
  EXPECT_EQ(q.key, "stage[0].q");
  EXPECT_NE(q.what.find("q 1e-300 is not in [0.05, 1000]"), std::string::npos) << q.what;
  EXPECT_EQ(core_refusal([] {
              (void)signal_chain::design({{.kind = StageKind::notch, .frequency_hz = 100.0, .q = 1e308}}, 8000.0);
            }).key,
            "stage[0].q");
  const scene::SceneError eq = refusal(scene_head(1000) +
                                       "[imu.error_model.signal_chain]\noversampling = 8\n"
                                       "[[imu.error_model.signal_chain.stage]]\nkind = \"anti-alias\"\n"
                                       "frequency_hz = 100\nq = 1e-300\n");
  EXPECT_EQ(eq.key(), "imu[0].error_model.signal_chain.stage[0].q");
  EXPECT_EQ(eq.line(), 17u);
  // At the bound (1e-5 of 8 kHz) the third-order low-pass settles on a
  // constant input and passes it: the level unit reads 1 g, finite.
  signal_chain::ChainSpec spec;
  spec.oversampling = 8;
  spec.stages = std::vector<Stage>{{.kind = StageKind::low_pass, .frequency_hz = 0.08, .order = 3}};
  signal_chain::DeviceChain chain(SceneModel{}, std::nullopt, spec, 1000, "a");
  for (const signal_chain::ChainOutput& o : run_chain(chain, 50, signal_chain::IncrementConvention::raw)) {
    ASSERT_TRUE(finite(o.gyro_rad_s) && finite(o.accel_m_s2));
    EXPECT_NEAR(o.accel_m_s2.z(), -9.80665, 1e-6);
    EXPECT_EQ(o.saturated_axes, 0);
  }
}

// ---------------------------------------------------------------- N5, vibration

struct VibrationCase {
  std::string name, table;  // appended after the head (line 12 on)
  std::string key;          // the scene key refused
  std::uint32_t line;
  signal_chain::VibrationSpec spec;  // the same setting, given to the core
  std::string core_key;
};

// N5 (a sinusoid at 1e-300 or 1e308 Hz, amplitudes of 1e308, a rotor at
// 1e-300 rpm: NaN inside the chain) and every other vibration setting that
// can overflow: refused at its key with the core's message, which validate()
// throws for the same spec.
TEST(SettingBounds, N5VibrationSettingsThatMadeNaNAreRefusedAtTheirKeyWithTheCoresMessage) {
  const std::string v = "[[imu.error_model.signal_chain.vibration.";
  const std::string r = "[imu.error_model.signal_chain.vibration.";
  auto sinusoid = [](double f, Vec3 linear, Vec3 angular) {
    signal_chain::VibrationSpec s;
    s.sinusoids.push_back({.frequency_hz = f, .linear_m_s2 = linear, .angular_rad_s = angular});
    return s;
  };
  auto rotor = [](double rpm, double order, double bandwidth) {
    signal_chain::VibrationSpec s;
    signal_chain::Rotor rt;
    rt.speed = {{0.0, rpm}};
    rt.harmonics = {{.order = order, .linear_m_s2 = Vec3(0.0, 0.0, 1.0)}};
    rt.jitter_bandwidth_hz = bandwidth;
    s.rotors.push_back(rt);
    return s;
  };
  auto random = [](std::vector<signal_chain::PsdPoint> psd, double resolution) {
    signal_chain::VibrationSpec s;
    signal_chain::RandomVibration rv;
    rv.psd = std::move(psd);
    rv.resolution_hz = resolution;
    s.random_linear = rv;
    return s;
  };
  auto shock = [](double duration_s, Vec3 peak) {
    signal_chain::VibrationSpec s;
    s.shocks.push_back({.time_s = 1.0, .peak_m_s2 = peak, .duration_s = duration_s});
    return s;
  };
  const std::vector<VibrationCase> cases = {
      {"sinusoid at 1e-300 Hz", v + "sinusoid]]\nfrequency_hz = 1e-300\nlinear_m_s2 = [0, 0, 1]\n",
       "imu[0].error_model.signal_chain.vibration.sinusoid[0].frequency_hz", 13,
       sinusoid(1e-300, Vec3(0, 0, 1), Vec3::Zero()), "sinusoid[0].frequency_hz"},
      {"sinusoid at 1e308 Hz", v + "sinusoid]]\nfrequency_hz = 1e308\nlinear_m_s2 = [0, 0, 1]\n",
       "imu[0].error_model.signal_chain.vibration.sinusoid[0].frequency_hz", 13,
       sinusoid(1e308, Vec3(0, 0, 1), Vec3::Zero()), "sinusoid[0].frequency_hz"},
      {"linear amplitude 1e308", v + "sinusoid]]\nfrequency_hz = 50\nlinear_m_s2 = [0, 0, 1e308]\n",
       "imu[0].error_model.signal_chain.vibration.sinusoid[0].linear_m_s2", 14,
       sinusoid(50.0, Vec3(0, 0, 1e308), Vec3::Zero()), "sinusoid[0].linear_m_s2"},
      {"angular amplitude 1e308 deg/s", v + "sinusoid]]\nfrequency_hz = 50\nangular_deg_s = [1e308, 0, 0]\n",
       "imu[0].error_model.signal_chain.vibration.sinusoid[0].angular_deg_s", 14,
       sinusoid(50.0, Vec3::Zero(), Vec3(1e308 * kDeg, 0, 0)), "sinusoid[0].angular_rad_s"},
      {"rotor at 1e-300 rpm", v + "rotor]]\nspeed_rpm = 1e-300\n" + v + "rotor.harmonic]]\norder = 1\nlinear_m_s2 = [0, 0, 1]\n",
       "imu[0].error_model.signal_chain.vibration.rotor[0].speed_rpm", 13, rotor(1e-300, 1.0, 1.0), "rotor[0].speed[0]"},
      {"harmonic order 1e-300", v + "rotor]]\nspeed_rpm = 6000\n" + v + "rotor.harmonic]]\norder = 1e-300\nlinear_m_s2 = [0, 0, 1]\n",
       "imu[0].error_model.signal_chain.vibration.rotor[0].harmonic[0].order", 15, rotor(6000.0, 1e-300, 1.0),
       "rotor[0].harmonic[0].order"},
      {"jitter bandwidth 1e308", v + "rotor]]\nspeed_rpm = 6000\njitter_bandwidth_hz = 1e308\n" + v +
                                     "rotor.harmonic]]\norder = 1\nlinear_m_s2 = [0, 0, 1]\n",
       "imu[0].error_model.signal_chain.vibration.rotor[0].jitter_bandwidth_hz", 14, rotor(6000.0, 1.0, 1e308),
       "rotor[0].jitter_bandwidth_hz"},
      {"PSD level 1e308", r + "random]\npsd_g2_per_hz = [[20, 0.01], [500, 1e308]]\n",
       "imu[0].error_model.signal_chain.vibration.random.psd_g2_per_hz[1]", 13,
       random({{20.0, 0.01}, {500.0, 1e308}}, 0.5), "random.psd[1]"},
      {"PSD level 1e-300", r + "random]\npsd_g2_per_hz = [[20, 1e-300], [500, 0.01]]\n",
       "imu[0].error_model.signal_chain.vibration.random.psd_g2_per_hz[0]", 13,
       random({{20.0, 1e-300}, {500.0, 0.01}}, 0.5), "random.psd[0]"},
      {"shock of 1e-300 ms", v + "shock]]\ntime_s = 1\npeak_g = [0, 0, 1]\nduration_ms = 1e-300\n",
       "imu[0].error_model.signal_chain.vibration.shock[0].duration_ms", 15, shock(1e-303, Vec3(0, 0, 9.80665)),
       "shock[0].duration_s"},
      {"shock peak 1e308 g", v + "shock]]\ntime_s = 1\npeak_g = [0, 0, 1e308]\nduration_ms = 11\n",
       "imu[0].error_model.signal_chain.vibration.shock[0].peak_g", 14, shock(0.011, Vec3(0, 0, 1e308 * 9.80665)),
       "shock[0].peak_m_s2"},
  };
  for (const VibrationCase& c : cases) {
    SCOPED_TRACE(c.name);
    const CoreRefusal core = core_refusal([&] { signal_chain::validate(c.spec); });
    EXPECT_EQ(core.key, c.core_key);
    // The core's constructor refuses it too (nothing is left to NaN at run time).
    EXPECT_THROW((void)signal_chain::Vibration(c.spec, "a"), SettingError);
    const scene::SceneError e = refusal(scene_head(1000) + c.table);
    EXPECT_EQ(e.key(), c.key) << e.what();
    EXPECT_EQ(e.line(), c.line) << e.what();
    EXPECT_GT(e.column(), 0u);
    // The same message: the scene's is the core's behind file:line:column: key.
    EXPECT_TRUE(ends_with(e.what(), ": " + core.what)) << e.what() << "\n" << core.what;
  }
}

// Within the bounds every vibration the core takes computes finite motion:
// each setting at its extreme at once, through the chain at 8x with raw
// increments (the quadrature evaluates between grid instants), for 200 ticks.
TEST(SettingBounds, EveryVibrationSettingAtItsBoundsStaysFinite) {
  using namespace signal_chain;
  for (const bool high : {false, true}) {
    SCOPED_TRACE(high ? "upper bounds" : "lower bounds");
    ChainSpec spec;
    spec.oversampling = 8;
    VibrationSpec& v = spec.vibration;
    const double f = high ? kMaxVibrationHz : kMinVibrationHz;
    v.sinusoids.push_back({.frequency_hz = f, .linear_m_s2 = Vec3::Constant(kMaxVibrationAccelM_s2),
                           .angular_rad_s = Vec3::Constant(kMaxVibrationRateRad_s), .phase_rad = Vec3::Constant(1e6)});
    // One rotor at the top speed with the lowest order, one at the highest
    // order whose top harmonic is kMaxVibrationHz; low: the slowest shaft
    // with the lowest order and a jitter near its limit.
    Rotor fast, sharp;
    fast.speed = {{0.0, high ? kMaxRpm : kMinRpm}};
    fast.jitter_rpm = high ? 0.0 : kMinRpm * 0.08;  // peak sqrt(32) x 0.08 = 0.45 of the lowest speed
    fast.jitter_bandwidth_hz = high ? kMaxJitterBandwidthHz : kMinJitterBandwidthHz;
    fast.harmonics.push_back({.order = kMinHarmonicOrder, .linear_m_s2 = Vec3::Constant(kMaxVibrationAccelM_s2),
                              .angular_rad_s = Vec3::Constant(kMaxVibrationRateRad_s)});
    sharp.speed = {{-kMaxVibrationTimeS, 60.0 * kMaxVibrationHz / kMaxHarmonicOrder},
                   {-kMaxVibrationTimeS + kMinProfileSpacingS, kMinRpm}};
    sharp.harmonics.push_back({.order = kMaxHarmonicOrder, .linear_m_s2 = Vec3::Constant(kMaxVibrationAccelM_s2),
                               .angular_rad_s = Vec3::Constant(kMaxVibrationRateRad_s)});
    v.rotors = {fast, sharp};
    v.shocks.push_back({.time_s = 0.0, .peak_m_s2 = Vec3::Constant(kMaxVibrationAccelM_s2),
                        .angular_peak_rad_s2 = Vec3::Constant(kMaxShockAngularRad_s2),
                        .duration_s = high ? kMaxShockDurationS : kMinShockDurationS,
                        .return_s = high ? kMaxShockReturnS : kMinShockReturnS});
    RandomVibration rv;
    rv.psd = {{high ? kMaxVibrationHz - 100.0 : kMinVibrationHz, high ? kMaxPsdG2PerHz : kMinPsd},
              {high ? kMaxVibrationHz : kMinVibrationHz + 100.0, high ? kMinPsd : kMaxPsdG2PerHz}};
    rv.resolution_hz = 1.0;
    rv.axis_scale = Vec3::Constant(kMaxVibrationScale);
    rv.amplitude_scale = {{0.0, kMaxVibrationScale}, {kMinProfileSpacingS, 0.0}, {2 * kMinProfileSpacingS, kMaxVibrationScale}};
    v.random_linear = rv;
    RandomAngularVibration ra;
    ra.psd = {{kMinVibrationHz, kMaxPsdRad2S4PerHz}, {kMaxVibrationHz, kMaxPsdRad2S4PerHz}};
    ra.resolution_hz = kMaxResolutionHz;
    v.random_angular = ra;
    v.lever_arm_m = Vec3::Constant(high ? kMaxLeverArmM : -kMaxLeverArmM);
    ASSERT_NO_THROW(validate(v));
    DeviceChain chain(SceneModel{}, sensor::preset_spec("icm42688p"), spec, 1000, "a");
    for (const ChainOutput& o : run_chain(chain, 200, IncrementConvention::raw)) {
      ASSERT_TRUE(finite(o.gyro_rad_s) && finite(o.accel_m_s2)) << o.gyro_rad_s.transpose() << " " << o.accel_m_s2.transpose();
      ASSERT_TRUE(finite(o.delta_theta_rad) && finite(o.delta_velocity_m_s));
      // Beyond the ICM-42688-P's +-2000 deg/s and +-16 g: saturated, flagged.
      if (o.gyro_rad_s.cwiseAbs().maxCoeff() >= 2000.0 * kDeg) {
        EXPECT_NE(o.saturated_axes, 0);
      }
    }
  }
}

// Values beyond the part's range saturate and set the flag wherever they
// come from: a vibration of 3000 deg/s and 30 g on the ICM-42688-P (+-2000
// deg/s, +-16 g) through its own chain. The sensor saturates each internal
// sample; the filters' overshoot on the clipped signal (a second-order
// Butterworth's step response rises ~4 % above its final value) saturates
// again at the output register: no output beyond the full scale, and every
// output at it flagged.
TEST(SettingBounds, VibrationBeyondThePartsRangeSaturatesThroughItsFiltersAndIsFlagged) {
  using namespace signal_chain;
  ChainSpec spec;
  spec.preset = "icm42688p";
  spec.vibration.sinusoids.push_back(
      {.frequency_hz = 40.0, .linear_m_s2 = Vec3(0, 30.0 * 9.80665, 0), .angular_rad_s = Vec3(3000.0 * kDeg, 0, 0)});
  const sensor::SensorModelSpec icm = sensor::preset_spec("icm42688p");
  DeviceChain chain(SceneModel{}, icm, spec, 1000, "a");
  int saturated = 0;
  for (const ChainOutput& o : run_chain(chain, 400, IncrementConvention::raw)) {
    ASSERT_LE(std::abs(o.gyro_rad_s.x()), icm.gyro.range);
    ASSERT_LE(std::abs(o.accel_m_s2.y()), icm.accel.range);
    if (std::abs(o.gyro_rad_s.x()) == icm.gyro.range) {
      EXPECT_NE(o.saturated_axes & sensor::kGyroX, 0);
      ++saturated;
    }
    if (std::abs(o.accel_m_s2.y()) == icm.accel.range) {
      EXPECT_NE(o.saturated_axes & sensor::kAccelY, 0);
    }
  }
  EXPECT_GT(saturated, 40);  // 3000 deg/s peaks: clipped for about a third of each period
}

// ---------------------------------------------------------------- N6

// N6: compensate_delay with a 1e-12 Hz low-pass stamped every sample
// INT64_MAX. The corner is refused at its key; within the corner bound a
// chain whose group delay passes 10 s is refused at compensate_delay; one
// within it shifts the stamps by its delay exactly.
TEST(SettingBounds, N6CompensatedDelayIsRefusedBeyondTenSecondsNotStampedInt64Max) {
  using namespace signal_chain;
  const scene::SceneError tiny = refusal(scene_head(1000) +
                                         "[imu.error_model.signal_chain]\ncompensate_delay = true\noversampling = 8\n"
                                         "[[imu.error_model.signal_chain.stage]]\nkind = \"low-pass\"\nfrequency_hz = 1e-12\n");
  EXPECT_EQ(tiny.key(), "imu[0].error_model.signal_chain.stage[0].frequency_hz");
  // A 16th-order Butterworth at 2e-4 Hz on a 10 Hz device (the corner bound
  // is 1e-4 Hz there): a group delay of hours.
  ChainSpec spec;
  spec.compensate_delay = true;
  spec.stages = std::vector<Stage>{{.kind = StageKind::butterworth, .frequency_hz = 2e-4, .order = 16}};
  const CoreRefusal core = core_refusal([&] { (void)resolve(spec, 10); });
  EXPECT_EQ(core.key, "compensate_delay");
  EXPECT_NE(core.what.find("is beyond 10 s"), std::string::npos) << core.what;
  const scene::SceneError e = refusal(scene_head(10) +
                                      "[imu.error_model.signal_chain]\ncompensate_delay = true\n"  // line 13
                                      "[[imu.error_model.signal_chain.stage]]\nkind = \"butterworth\"\n"
                                      "frequency_hz = 2e-4\norder = 16\n");
  EXPECT_EQ(e.key(), "imu[0].error_model.signal_chain.compensate_delay");
  EXPECT_EQ(e.line(), 13u);
  EXPECT_TRUE(ends_with(e.what(), ": " + core.what + " (at rate_hz 10)")) << e.what();
  // Without compensation the same chain is only a lag: accepted.
  spec.compensate_delay = false;
  EXPECT_NO_THROW((void)resolve(spec, 10));
  // Within the bound: the stamp shift is the analytic delay, in int64 ns.
  ChainSpec ok;
  ok.compensate_delay = true;
  ok.oversampling = 1;
  ok.stages = std::vector<Stage>{{.kind = StageKind::low_pass, .frequency_hz = 0.05, .order = 1}};
  DeviceChain chain(SceneModel{}, std::nullopt, ok, 10, "a");
  const double delay_s = chain.chain().group_delay_s;
  // A single pole at fc, fs: DC delay 1/(2 tan(pi fc/fs)) samples of fs.
  EXPECT_NEAR(delay_s, 1.0 / (2.0 * std::tan(std::numbers::pi * 0.05 / 10.0)) / 10.0, 1e-9);
  EXPECT_LT(delay_s, kMaxCompensatedDelayS);
  EXPECT_EQ(run_chain(chain, 2, IncrementConvention::raw)[1].stamp_shift_ns, std::llround(delay_s * 1e9));
}

// ---------------------------------------------------------------- N7, N8

// N7/N8: the random vibration's bin count was a size_t cast of
// ceil((f1 - f0) / resolution): a crafted table wrapped bins x 3 past 2^64
// under the component cap and allocated until bad_alloc; resolution_hz =
// 1e-300 cast infinity to 0 bins and silently dropped the vibration. Now the
// count is a double, the resolution bounded and the cap refused by name.
TEST(SettingBounds, N7N8RandomVibrationBinCountIsCountedWithoutWrapAndCapped) {
  using namespace signal_chain;
  auto profile = [](double f0, double f1, double resolution) {
    VibrationSpec s;
    RandomVibration r;
    r.psd = {{f0, 0.01}, {f1, 0.01}};
    r.resolution_hz = resolution;
    s.random_linear = r;
    return s;
  };
  // N8: dropped silently before (0 components); refused at its key now.
  const CoreRefusal n8 = core_refusal([&] { (void)Vibration(profile(20.0, 500.0, 1e-300), "a"); });
  EXPECT_EQ(n8.key, "random.resolution_hz");
  EXPECT_NE(n8.what.find("resolution_hz 1e-300 Hz is not in [0.001, 10000] Hz"), std::string::npos) << n8.what;
  // N7: bins = ceil(2^64 / 3) made bins x 3 wrap to 2.
  const double wrap_bins = std::ceil(18446744073709551616.0 / 3.0);
  const double crafted = (1e5 - 1.0) / wrap_bins;
  EXPECT_GE(random_bins(1.0, 1e5, crafted), wrap_bins);  // a double: no wrap
  const CoreRefusal n7 = core_refusal([&] { validate(profile(1.0, 1e5, crafted)); });
  EXPECT_EQ(n7.key, "random.resolution_hz");
  // Within the resolution's bound, the cap: by name, with the count.
  const CoreRefusal cap = core_refusal([&] { validate(profile(kMinVibrationHz, kMaxVibrationHz, kMinResolutionHz)); });
  EXPECT_EQ(cap.key, "random.resolution_hz");
  EXPECT_NE(cap.what.find("1e+08 bins per axis"), std::string::npos) << cap.what;
  EXPECT_NE(cap.what.find("at most " + std::to_string(Vibration::kMaxComponents / 3)), std::string::npos) << cap.what;
  // The linear and angular profiles share the cap.
  VibrationSpec both = profile(10.0, 10.0 + 40000.0, 1.0);
  RandomAngularVibration angular;
  angular.psd = {{10.0, 1.0}, {40010.0, 1.0}};
  angular.resolution_hz = 1.0;
  both.random_angular = angular;
  EXPECT_EQ(core_refusal([&] { validate(both); }).key, "random_angular.resolution_hz");
  // At the cap exactly: built, every component there.
  const std::size_t per_axis = Vibration::kMaxComponents / 3;
  const Vibration full(profile(10.0, 10.0 + static_cast<double>(per_axis), 1.0), "a");
  EXPECT_EQ(full.random_components(), 3 * per_axis);
  // Points: a 100,000-row table (N9's) is refused by name before anything is built.
  VibrationSpec rows;
  RandomVibration many;
  for (int i = 0; i < 100'000; ++i) many.psd.push_back({10.0 + 0.01 * i, 0.01});
  rows.random_linear = many;
  const CoreRefusal points = core_refusal([&] { validate(rows); });
  EXPECT_EQ(points.key, "random.psd");
  EXPECT_NE(points.what.find("100000 PSD points; at most 10000"), std::string::npos) << points.what;
  // And the scene says so at the table's line.
  const scene::SceneError e = refusal(scene_head(1000) +
                                      "[imu.error_model.signal_chain.vibration.random]\n"
                                      "psd_g2_per_hz = [[20, 0.01], [500, 0.01]]\nresolution_hz = 1e-300\n");
  EXPECT_EQ(e.key(), "imu[0].error_model.signal_chain.vibration.random.resolution_hz");
  EXPECT_EQ(e.line(), 14u);
}

// ---------------------------------------------------------------- N9

// The chain counts its work as it runs (DeviceChain::work), in the units
// the CPU estimate prices; predict_work says what a contiguous tick costs.
// Counted and predicted agree (to the amortised resynchronisation), so the
// estimate's work is the work done, whatever the host.
TEST(SettingBounds, N9ChainWorkCountedAsItRunsIsTheWorkPredicted) {
  using namespace signal_chain;
  ChainSpec spec;
  spec.preset = "icm42688p";
  RandomVibration random;
  random.psd = {{20.0, 0.01}, {520.0, 0.01}};
  random.resolution_hz = 1.0;
  spec.vibration.random_linear = random;
  spec.vibration.sinusoids.push_back({.frequency_hz = 120.0, .linear_m_s2 = Vec3(0, 0, 1)});
  const int ticks = 1200;
  for (const IncrementConvention c : {IncrementConvention::raw, IncrementConvention::compensated}) {
    SCOPED_TRACE(to_string(c));
    DeviceChain chain(SceneModel{}, sensor::preset_spec("icm42688p"), spec, 1000, "a");
    ASSERT_EQ(chain.random_components(), 1500u);
    (void)run_chain(chain, ticks, c);
    const ChainWork done = chain.work();
    const ChainWork one = predict_work(chain.chain(), true, chain.random_components(), c, Physics::flat);
    EXPECT_EQ(done.ticks, ticks);
    // Tick 0 has one internal sample (nothing before it), the others M.
    EXPECT_EQ(done.internal_samples, one.internal_samples * (ticks - 1) + 1);
    EXPECT_EQ(done.increment_nodes, one.increment_nodes * (ticks - 1));
    // Tick 0 evaluates its one instant directly; then M grid steps per tick.
    const double predicted_rotations = one.vibration_rotations * (ticks - 1);
    const double predicted_direct = one.vibration_direct * (ticks - 1) + 1500.0;
    EXPECT_NEAR(done.vibration_rotations, predicted_rotations, 1500.0) << done.vibration_direct;
    EXPECT_NEAR(done.vibration_direct, predicted_direct, 1500.0) << done.vibration_rotations;
    EXPECT_EQ(done.vibration_rotations + done.vibration_direct,
              1500.0 * (1 + (ticks - 1) * (one.internal_samples + (c == IncrementConvention::raw ? 4 : 0))));
  }
}

double thread_cpu_s() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

// N9: check-config put a heavy random vibration on a native device (raw
// increments) at 12 % of a core and the device fell behind: the estimate
// counted every component as one rotation per internal sample, but the raw
// increments evaluate each component four more times between grid instants
// with a sine and a cosine. Host-speed independent check of the estimate:
// the ratio of two heavy chains' estimated costs (check-config's
// cpu_fraction, a native and a MIP device with the same vibration) against
// the ratio of their measured thread CPU, run interleaved so a loaded host
// slows both alike. The old estimate made the ratio 1; measured it is ~3.
TEST(SettingBounds, N9CpuEstimateOfHeavyChainsFollowsTheirMeasuredCost) {
  const std::string vibration =
      "[imu.error_model.signal_chain]\noversampling = 8\n"
      "[imu.error_model.signal_chain.vibration.random]\npsd_g2_per_hz = [[20, 0.001], [2020, 0.001]]\nresolution_hz = 1\n";
  const scene::SceneConfig raw = scene::parse_scene_text(scene_head(1000, "native") + vibration, "raw.toml", ".");
  const scene::SceneConfig compensated = scene::parse_scene_text(scene_head(1000, "mip") + vibration, "mip.toml", ".");
  const scene::SceneCheck check_raw = scene::check_scene(raw), check_compensated = scene::check_scene(compensated);
  ASSERT_EQ(check_raw.imus[0].vibration_components, 6000u);
  EXPECT_FALSE(check_raw.imus[0].compensated_increments);
  EXPECT_TRUE(check_compensated.imus[0].compensated_increments);
  const double estimated = check_raw.imus[0].cpu_fraction / check_compensated.imus[0].cpu_fraction;
  EXPECT_GT(estimated, 1.5) << "raw increments evaluate every component 4 more times per sample";
  // The 1 kHz native device is estimated beyond a core (the old estimate:
  // 30 %): check-config says it will fall behind; the MIP one is not.
  EXPECT_GT(check_raw.imus[0].cpu_fraction, 1.0);
  EXPECT_LT(check_compensated.imus[0].cpu_fraction, 1.0);
  auto falls_behind = [](const scene::SceneCheck& c) {
    for (const std::string& w : c.warnings)
      if (w.find("will fall behind") != std::string::npos) return true;
    return false;
  };
  EXPECT_TRUE(falls_behind(check_raw));
  EXPECT_FALSE(falls_behind(check_compensated));
  auto chain_of = [](const scene::SceneConfig& s) {
    const scene::ImuConfig& imu = s.imus[0];
    return signal_chain::DeviceChain(s.physics, imu.error_model.sensor(), imu.error_model.chain, imu.rate_hz, imu.name);
  };
  signal_chain::DeviceChain a = chain_of(raw), b = chain_of(compensated);
  SceneModel scene;
  Kinematics k;
  const ImuSample ideal = imu_from_kinematics(scene, k);
  double cpu_a = 0.0, cpu_b = 0.0;
  std::uint64_t tick = 0;
  for (int round = 0; round < 12; ++round) {
    const std::uint64_t first = tick;
    double t0 = thread_cpu_s();
    for (tick = first; tick < first + 15; ++tick)
      (void)a.step(tick, k, ideal, tick > 0 ? &k : nullptr, signal_chain::IncrementConvention::raw);
    cpu_a += thread_cpu_s() - t0;
    t0 = thread_cpu_s();
    for (tick = first; tick < first + 15; ++tick)
      (void)b.step(tick, k, ideal, tick > 0 ? &k : nullptr, signal_chain::IncrementConvention::compensated);
    cpu_b += thread_cpu_s() - t0;
  }
  const double measured = cpu_a / cpu_b;
  std::printf("estimated raw/compensated cost %.2f, measured %.2f (%.3f s, %.3f s of CPU); estimated %.1f %% of a core\n",
              estimated, measured, cpu_a, cpu_b, 100.0 * check_raw.imus[0].cpu_fraction);
#ifdef IMUEMU_TEST_SANITIZED
  GTEST_SKIP() << "the unit costs are Release figures; sanitizers weigh memory and libm differently";
#endif
  EXPECT_GT(measured / estimated, 1.0 / 1.6);
  EXPECT_LT(measured / estimated, 1.6);
}

// ---------------------------------------------------------------- N11

fault::SampleValues level_sample(double h) {
  fault::SampleValues v;
  v.gyro_rad_s = Vec3(0.01, -0.02, 0.03);
  v.accel_m_s2 = Vec3(0.0, 0.0, -9.80665);
  v.delta_theta_rad = v.gyro_rad_s * h;
  v.delta_velocity_m_s = v.accel_m_s2 * h;
  v.period_ns = static_cast<TimeNs>(std::llround(h * 1e9));
  return v;
}

// N11: ICM-42688-P (+-2000 deg/s) with bias_step 1e5 deg/s sent 1745 rad/s
// with no saturated bit; 256 overlapping steps added up to 7.7e6 rad/s. A
// fault that adds or scales saturates at the part's range (the rate at
// +-range, the increment at +-range h), flagged; within the range nothing
// changes.
TEST(SettingBounds, N11FaultsBeyondThePartsRangeSaturateAndSetTheFlag) {
  const sensor::SensorModelSpec icm = sensor::preset_spec("icm42688p");
  const double range = 2000.0 * kDeg, accel_range = 16.0 * 9.80665, h = 1.0 / 1000.0;
  auto timeline = [&](std::vector<fault::FaultSpec> faults) {
    fault::TimelineOptions o;
    o.context = fault::device_context("a", 1000, icm);
    o.faults = std::move(faults);
    return fault::FaultTimeline(o);
  };
  auto bias = [](double gyro_deg_s, double accel_m_s2 = 0.0) {
    fault::FaultSpec s = fault::default_spec(fault::Kind::bias_step);
    s.gyro_bias_rad_s = gyro_deg_s * kDeg;
    s.accel_bias_m_s2 = accel_m_s2;
    return s;
  };
  ASSERT_DOUBLE_EQ(fault::device_context("a", 1000, icm).gyro_range_rad_s, range);
  {
    fault::FaultTimeline t = timeline({bias(1e5)});
    fault::SampleValues v = level_sample(h);
    const fault::SampleFaults f = t.step(0, 0, v);
    for (int a = 0; a < 3; ++a) {
      EXPECT_EQ(v.gyro_rad_s[a], range) << a;
      EXPECT_EQ(v.delta_theta_rad[a], range * h) << a;
    }
    EXPECT_NE(f.flags & fault::kFlagSaturated, 0u);
  }
  {
    // 256 overlapping steps of -1e6 deg/s (the scene's largest): -range, not -7.7e6 rad/s... or more.
    fault::FaultTimeline t = timeline(std::vector<fault::FaultSpec>(256, bias(-1e6)));
    fault::SampleValues v = level_sample(h);
    const fault::SampleFaults f = t.step(0, 0, v);
    EXPECT_EQ(v.gyro_rad_s, Vec3::Constant(-range));
    EXPECT_EQ(v.delta_theta_rad, Vec3::Constant(-range * h));
    EXPECT_NE(f.flags & fault::kFlagSaturated, 0u);
    EXPECT_EQ(f.active, 256u);
  }
  {
    // Within the range: the bias added exactly, no flag.
    fault::FaultTimeline t = timeline({bias(100.0, 2.0)});
    fault::SampleValues v = level_sample(h);
    const fault::SampleValues in = v;
    const fault::SampleFaults f = t.step(0, 0, v);
    EXPECT_EQ(v.gyro_rad_s, (in.gyro_rad_s.array() + 100.0 * kDeg).matrix());
    EXPECT_EQ(v.accel_m_s2, (in.accel_m_s2.array() + 2.0).matrix());
    EXPECT_EQ(f.flags & fault::kFlagSaturated, 0u);
  }
  {
    // A scale step of x11 (1e7 ppm) on 9.8 m/s^2 stays within 16 g; on 20 m/s^2 it saturates.
    fault::FaultSpec scale = fault::default_spec(fault::Kind::scale_step);
    scale.scale_ppm = 1e7;
    scale.triad = fault::Triad::accel;
    fault::FaultTimeline t = timeline({scale});
    fault::SampleValues v = level_sample(h);
    v.accel_m_s2.x() = 20.0;
    v.delta_velocity_m_s.x() = 20.0 * h;
    const fault::SampleFaults f = t.step(0, 0, v);
    EXPECT_EQ(v.accel_m_s2.x(), accel_range);
    EXPECT_DOUBLE_EQ(v.accel_m_s2.z(), -9.80665 * 11.0);
    EXPECT_NE(f.flags & fault::kFlagSaturated, 0u);
  }
  {
    // A stuck fault holding a sample a scale step took beyond the range holds
    // it saturated, after the scale step has ended (found by fuzz_fault_table
    // when the saturation came after all faults).
    fault::FaultSpec scale = fault::default_spec(fault::Kind::scale_step);
    scale.scale_ppm = 1e7;
    scale.duration_ns = 2 * 1'000'000;  // two samples
    fault::FaultSpec stuck = fault::default_spec(fault::Kind::stuck);
    fault::FaultTimeline t = timeline({scale, stuck});
    for (std::uint64_t k = 0; k < 5; ++k) {
      fault::SampleValues v = level_sample(h);
      v.gyro_rad_s.x() = 0.5 * range;
      v.delta_theta_rad.x() = 0.5 * range * h;
      (void)t.step(k, static_cast<TimeNs>(k) * 1'000'000, v);
      EXPECT_EQ(v.gyro_rad_s.x(), range) << k;  // 5.5 x range held, saturated
      EXPECT_DOUBLE_EQ(v.delta_theta_rad.x(), range * h) << k;
    }
  }
  {
    // A non-finite input (only reachable from upstream): 0, flagged saturated and fault.
    fault::FaultTimeline t = timeline({bias(1.0)});
    fault::SampleValues v = level_sample(h);
    v.gyro_rad_s.y() = std::numeric_limits<double>::quiet_NaN();
    const fault::SampleFaults f = t.step(0, 0, v);
    EXPECT_TRUE(finite(v.gyro_rad_s));
    EXPECT_EQ(f.flags & (fault::kFlagSaturated | fault::kFlagFault), fault::kFlagSaturated | fault::kFlagFault);
  }
}

// ---------------------------------------------------------------- N12

// N12: finite settings reached the "non-finite -> 0" rule: a bias
// instability of 1e308 deg/s gave a perfect gyro, a temperature of +-1e308
// all-zero output, a noise density of 1e308 deg/s/sqrt(Hz) was accepted.
// Each is refused at its key with the message the core's validate() gives.
TEST(SettingBounds, N12SensorTermsBeyondAnyDatasheetAreRefusedAtTheirKeyWithTheCoresMessage) {
  struct Case {
    std::string name, table, key;
    std::uint32_t line;
    std::function<void(sensor::SensorModelSpec&)> set;  // the same value, SI
  };
  const std::vector<Case> cases = {
      {"bias instability 1e308 deg/s", "[imu.error_model.gyro]\nbias_instability_dps = 1e308\n",
       "imu[0].error_model.gyro.bias_instability_dps", 14,
       [](sensor::SensorModelSpec& s) { s.gyro.bias_instability = Vec3::Constant(1e308 * kDeg); }},
      {"noise density 1e308", "[imu.error_model.gyro]\nnoise_density_dps_rt_hz = 1e308\n",
       "imu[0].error_model.gyro.noise_density_dps_rt_hz", 14,
       [](sensor::SensorModelSpec& s) { s.gyro.white_density = Vec3::Constant(1e308 * kDeg); }},
      {"accel noise density 1e308 ug", "[imu.error_model.accel]\nnoise_density_ug_rt_hz = 1e308\n",
       "imu[0].error_model.accel.noise_density_ug_rt_hz", 14,
       [](sensor::SensorModelSpec& s) { s.accel.white_density = Vec3::Constant(1e308 * 1e-6 * 9.80665); }},
      {"temperature 1e308", "[imu.error_model.temperature]\nconstant_c = 1e308\n",
       "imu[0].error_model.temperature.constant_c", 14,
       [](sensor::SensorModelSpec& s) { s.temperature.start_c = s.temperature.end_c = 1e308; }},
      {"temperature -1e308", "[imu.error_model.temperature]\nstart_c = -1e308\n", "imu[0].error_model.temperature.start_c",
       14, [](sensor::SensorModelSpec& s) { s.temperature.start_c = -1e308; }},
      {"flicker tau 1e308 s", "[imu.error_model.gyro]\nbias_instability_deg_h = 5\nbias_instability_tau_max_s = 1e308\n",
       "imu[0].error_model.gyro.bias_instability_tau_max_s", 15,
       [](sensor::SensorModelSpec& s) {
         s.gyro.bias_instability = Vec3::Constant(5.0 * kDeg / 3600.0);
         s.gyro.flicker_tau_max_s = 1e308;
       }},
      {"lsb 1e-300", "[imu.error_model.gyro]\nlsb_dps = 1e-300\n", "imu[0].error_model.gyro.lsb_dps", 14,
       [](sensor::SensorModelSpec& s) { s.gyro.lsb = 1e-300 * kDeg; }},
      {"scale factor 1e308 ppm", "[imu.error_model.accel]\nscale_factor_ppm = 1e308\n",
       "imu[0].error_model.accel.scale_factor_ppm", 14,
       [](sensor::SensorModelSpec& s) { s.accel.scale_factor = Vec3::Constant(1e302); }},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    sensor::SensorModelSpec spec;
    c.set(spec);
    const CoreRefusal core = core_refusal([&] { sensor::validate(spec); });
    EXPECT_THROW((void)sensor::SensorModel(spec, 1000.0, "a"), std::invalid_argument);
    const scene::SceneError e = refusal(scene_head(100) + "[imu.error_model]\n" + c.table);
    EXPECT_EQ(e.key(), c.key) << e.what();
    EXPECT_EQ(e.line(), c.line) << e.what();
    EXPECT_TRUE(ends_with(e.what(), ": " + core.what)) << e.what() << "\n" << core.what;
  }
  // Every preset is within the bounds.
  for (const sensor::Preset& p : sensor::presets()) EXPECT_NO_THROW(sensor::validate(sensor::preset_spec(p.name))) << p.name;
}

// Within the bounds every term computes: all of them at their extremes, a
// turning, accelerating input, finite output (beyond the range: saturated).
TEST(SettingBounds, EverySensorTermAtItsBoundsStaysFinite) {
  sensor::SensorModelSpec s;
  for (const bool gyro : {true, false}) {
    sensor::TriadSpec& t = gyro ? s.gyro : s.accel;
    const sensor::TriadBounds& b = gyro ? sensor::kGyroBounds : sensor::kAccelBounds;
    t.white_density = Vec3::Constant(b.white_density);
    t.bias_instability = Vec3::Constant(b.bias);
    t.flicker_tau_min_s = sensor::kMinTauS;
    t.flicker_tau_max_s = sensor::kMinTauS * 1e9;
    t.random_walk = Vec3::Constant(b.bias);
    t.ramp = Vec3::Constant(-b.ramp);
    t.gauss_markov_sigma = Vec3::Constant(b.bias);
    t.gauss_markov_tau_s = Vec3(sensor::kMinTauS, 1.0, sensor::kMaxTauS);
    t.turn_on_bias = Vec3::Constant(b.full_scale);
    t.turn_on_bias_sigma = Vec3::Constant(b.full_scale);
    t.scale_factor = Vec3::Constant(sensor::kMaxScaleFactor);
    t.scale_factor_asymmetry = Vec3::Constant(-sensor::kMaxScaleFactor);
    t.nonlinearity = Vec3::Constant(sensor::kMaxScaleFactor);
    t.misalignment_rad = Vec3::Constant(sensor::kMaxMisalignmentRad);
    t.non_orthogonality_rad = Vec3::Constant(-sensor::kMaxMisalignmentRad);
    if (gyro) t.g_sensitivity = Mat3::Constant(sensor::kMaxGSensitivity);
    t.bias_temperature_coeff = Vec3::Constant(b.bias_temperature_coeff);
    t.scale_factor_temperature_coeff = Vec3::Constant(sensor::kMaxScaleFactorTemperatureCoeff);
    t.range = b.full_scale;
    t.lsb = sensor::kMinLsb;
  }
  s.temperature = {.reference_c = sensor::kMinTemperatureC, .start_c = sensor::kMaxTemperatureC,
                   .end_c = sensor::kMinTemperatureC, .warmup_tau_s = 1.0};
  ASSERT_NO_THROW(sensor::validate(s));
  sensor::SensorModel m(s, 1e6, "a");
  for (std::uint64_t k = 0; k < 20000; k += 7) {
    const double x = static_cast<double>(k);
    const sensor::Measurement out = m.measure(k, Vec3(1e3 * std::sin(x), -300.0, 5.0), Vec3(4000.0, -9.8, 1e-3 * x));
    ASSERT_TRUE(finite(out.gyro_rad_s) && finite(out.accel_m_s2)) << k;
    EXPECT_LE(out.gyro_rad_s.cwiseAbs().maxCoeff(), sensor::kGyroBounds.full_scale);
    EXPECT_LE(out.accel_m_s2.cwiseAbs().maxCoeff(), sensor::kAccelBounds.full_scale);
  }
}

// N5 (the flags never arrived): what the model cannot compute from its input
// is sent as 0 with the axis's saturated bit, never as a silent 0 (the
// encoders then flag it as docs/native-protocol.md section 5 says).
TEST(SettingBounds, N5SensorModelFlagsAnAxisItCannotCompute) {
  sensor::SensorModel m(sensor::preset_spec("adis16470"), 2000.0, "a");
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const sensor::Measurement out = m.measure(0, Vec3(0.0, nan, 0.0), Vec3(std::numeric_limits<double>::infinity(), 0.0, 0.0));
  EXPECT_EQ(out.gyro_rad_s.y(), 0.0);
  EXPECT_EQ(out.accel_m_s2.x(), 0.0);
  EXPECT_EQ(out.saturated_axes, sensor::kGyroY | sensor::kAccelX);
  // A finite input leaves the bits clear.
  EXPECT_EQ(m.measure(1, Vec3::Zero(), Vec3(0.0, 0.0, -9.8)).saturated_axes, 0);
}

// ---------------------------------------------------------------- check-config

// imuemud --check-config refuses what the parser refuses, with the same
// message (it was "OK" for every case above).
TEST(SettingBounds, CheckConfigRefusesWithTheParsersMessage) {
#ifndef IMUEMUD_PATH
  GTEST_SKIP() << "imuemud is not built";
#else
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / ("imuemu_bounds_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const std::string file = (dir / "bad.toml").string();
  {
    std::ofstream out(file);
    out << scene_head(1000)
        << "[[imu.error_model.signal_chain.vibration.sinusoid]]\nfrequency_hz = 1e-300\nlinear_m_s2 = [0, 0, 1]\n";
  }
  std::string parser;
  try {
    (void)scene::parse_scene_file(file);
  } catch (const scene::SceneError& e) {
    parser = e.what();
  }
  ASSERT_FALSE(parser.empty());
  const std::string command = std::string(IMUEMUD_PATH) + " --check-config " + file + " 2>&1";
  FILE* pipe = ::popen(command.c_str(), "r");
  ASSERT_NE(pipe, nullptr);
  std::string output;
  std::array<char, 4096> buffer{};
  while (std::fgets(buffer.data(), static_cast<int>(buffer.size()), pipe) != nullptr) output += buffer.data();
  const int status = ::pclose(pipe);
  std::filesystem::remove_all(dir);
  EXPECT_NE(status, 0) << output;
  EXPECT_EQ(output, parser + "\n");
  EXPECT_EQ(output.find("OK"), std::string::npos) << output;
#endif
}

}  // namespace
}  // namespace imuemu
