// A device's own signal chain (issue 16): what happens between the motion and
// the output register of a real IMU, per output tick k.
//
//   continuous trajectory over (t_{k-1}, t_k]  (IntervalMotion: the pipeline's
//   smoothed trajectory, Hermite-interpolated between output samples)
//     -> ideal (omega_ib^b, f^b) at the internal rate M r (M = oversampling)
//     -> sensor model at M r (core/sensor: a noise density then means what a
//        datasheet means, sigma = N sqrt(M r))
//     -> filter chain at M r (core/signal_chain/filters.hpp)
//     -> decimation: the output is the filtered value at t_k (internal sample M k)
//   increments over the interval (increments.hpp) in the protocol's convention:
//     exact for the ideal motion (closed form / quadrature) plus the integral
//     of the sensor's error at the internal rate (sum of (measured - ideal) dt).
//     They integrate the sensed signal before the output filter.
//
// The ideal chain (M = 1, no stage, no compensation) with the ideal sensor is
// the default: step() then returns the ideal sample untouched (no loop, no
// filter), and only the increments cost anything. With M = 1 and no stage the
// sensor model sees exactly what it saw before this room existed (sample k,
// the ideal value at t_k): same bits for one seed.
//
// Pure maths, no I/O, no allocation per sample.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/imu_model.hpp"
#include "core/sensor/sensor_model.hpp"
#include "core/signal_chain/filters.hpp"
#include "core/signal_chain/increments.hpp"
#include "core/signal_chain/vibration.hpp"

namespace imuemu::signal_chain {

// As configured ([imu.error_model.signal_chain]); resolved against the
// output rate by resolve().
struct ChainSpec {
  std::string preset = "ideal";     // chain_presets(); "ideal": no stage
  std::optional<int> oversampling;  // internal rate = oversampling x output rate; empty: the preset's (ideal: 1)
  std::optional<std::vector<Stage>> stages;  // replaces the preset's stages
  bool compensate_delay = false;    // stamp outputs t_k - group delay at DC
  // Vibration as rigid-body motion on top of the smoothed trajectory
  // (vibration.hpp); its lever_arm_m / sensor_to_body are the device's mounting.
  VibrationSpec vibration;
  bool is_ideal() const {
    return preset == "ideal" && (!oversampling || *oversampling == 1) && (!stages || stages->empty()) &&
           !compensate_delay && vibration.empty();
  }
};

inline constexpr int kMaxOversampling = 1024;
// The longest group delay compensate_delay stamps away (issue 26, N6: a
// 1e-12 Hz low-pass stamped every sample INT64_MAX). The slowest datasheet
// chain, the ADIS16470's decimation at DEC_RATE 1999 (2000 SPS to 1 Hz),
// delays by 0.5 s; a compensation beyond 10 s would stamp samples before
// any pose the look-ahead holds.
inline constexpr double kMaxCompensatedDelayS = 10.0;

// A chain at one output rate.
struct ResolvedChain {
  std::string preset;
  int oversampling = 1;
  std::int64_t internal_rate_hz = 0;
  std::vector<Stage> stages;
  Design design;
  bool compensate_delay = false;
  double group_delay_s = 0.0;  // at DC, analytic (filters.hpp group_delay_samples)
  bool has_vibration = false;
  bool is_ideal() const { return oversampling == 1 && design.empty() && !compensate_delay && !has_vibration; }
};

// Names of the presets: ideal, icm42688p, adis16470, stim300, mip.
std::vector<std::string> chain_presets();
// Throws std::invalid_argument (unknown preset, oversampling out of
// 1..kMaxOversampling, a stage the design refuses, a preset that cannot run
// at this output rate, e.g. adis16470 needs 2000 / rate to be an integer, a
// compensated group delay beyond kMaxCompensatedDelayS); SettingError
// (core/setting_error.hpp) where one key is at fault: "oversampling",
// "stage[i].field", "compensate_delay".
ResolvedChain resolve(const ChainSpec& spec, std::int64_t output_rate_hz);

// One line per fact for check-config / generate: internal rate, each stage,
// group delay at DC (and at a quarter of the output rate), compensation.
std::vector<std::string> describe(const ResolvedChain& chain, std::int64_t output_rate_hz);

// The work of output ticks (issue 26, N9: a chain estimated at 12 % of a
// core fell behind), in units of known CPU cost (measured in
// daemon/scene/scene_check.hpp, kCpuSecondsPer*): what DeviceChain counts
// as it runs, and what predict_work() expects of contiguous ticks.
struct ChainWork {
  double ticks = 0.0;
  // Samples at the internal rate through the motion, the sensor model and
  // the filters (0 for the ideal chain with the ideal sensor: it passes the
  // sample through).
  double internal_samples = 0.0;
  // Quadrature nodes of the increments: the raw integrals' 4 motion
  // evaluations, the ecef gravitation's 3 positions.
  double increment_nodes = 0.0;
  // Random vibration components advanced by a rotation (on the internal
  // grid) and evaluated by a sine and a cosine (the raw increments' nodes
  // between grid instants, a resynchronisation, a start or a gap).
  double vibration_rotations = 0.0;
  double vibration_direct = 0.0;
};
// Per contiguous tick: M internal samples (M = oversampling) unless the chain
// and the sensor are both ideal; 4 nodes for raw increments, 3 for
// compensated ones in ecef; per random component M grid evaluations, one in
// Vibration::kResyncSteps + 1 of them direct, plus the 4 raw nodes direct.
ChainWork predict_work(const ResolvedChain& chain, bool sensor, std::size_t random_components,
                       std::optional<IncrementConvention> increments, Physics physics);

struct ChainOutput {
  Vec3 gyro_rad_s = Vec3::Zero();
  Vec3 accel_m_s2 = Vec3::Zero();
  Vec3 delta_theta_rad = Vec3::Zero();
  Vec3 delta_velocity_m_s = Vec3::Zero();
  // Any internal sample of the interval saturated, or the filtered output
  // reached the sensor's full scale (sensor::SaturatedAxis bits).
  std::uint8_t saturated_axes = 0;
  bool has_temperature = false;     // a sensor model runs
  double temperature_c = 0.0;
  TimeNs stamp_shift_ns = 0;        // delay compensation: the sample represents t_k - stamp_shift_ns
};

class DeviceChain {
 public:
  // sensor: empty or ideal for no sensor errors. Throws std::invalid_argument
  // (resolve, sensor::validate).
  DeviceChain(const SceneModel& scene, const std::optional<sensor::SensorModelSpec>& sensor, const ChainSpec& chain,
              std::int64_t output_rate_hz, const std::string& device);

  // Output tick k (k never decreases). now / ideal_now: the kinematics and the
  // ideal IMU at t_k; previous: tick k - 1's kinematics, or nullptr when there
  // is none (the first tick, a tick skipped before: the interval is then held
  // at ideal_now and the increments are ideal_now h); motion: the trajectory
  // over the interval, or nullptr for the Hermite interpolant of previous and
  // now. Increments are computed only if `increments` is set.
  ChainOutput step(std::uint64_t k, const Kinematics& now, const ImuSample& ideal_now, const Kinematics* previous,
                   std::optional<IncrementConvention> increments, const IntervalMotion* motion = nullptr);

  // No sensor errors and the ideal chain: outputs are the ideal samples.
  bool ideal() const { return !sensor_ && chain_.is_ideal(); }
  const ResolvedChain& chain() const { return chain_; }
  // The work done so far (counted in step(): no allocation, no lock).
  ChainWork work() const;
  std::size_t random_components() const { return vibration_ ? vibration_->random_components() : 0; }

 private:
  SceneModel scene_;
  ResolvedChain chain_;
  double period_s_ = 0.0;
  std::optional<sensor::SensorModel> sensor_;
  std::optional<Vibration> vibration_;
  Filter filter_;
  bool have_last_ = false;
  std::uint64_t last_k_ = 0;
  TimeNs stamp_shift_ns_ = 0;
  std::uint64_t ticks_ = 0, internal_samples_ = 0, increment_nodes_ = 0;
  double gyro_range_ = 0.0, accel_range_ = 0.0;  // the sensor's full scale (0: none)
};

}  // namespace imuemu::signal_chain
