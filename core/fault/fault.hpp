// Fault injection (issue 18): what a failing sensor or a broken link does, and
// when. This header is the contract between the rooms that apply faults:
//   - core/fault (this room): the fault specs, the timeline (scene entries,
//     random faults from the scene seed, run-time inject/clear), the sensor
//     faults applied to the sensor model's output (SensorFaults), and the
//     ground truth (FaultEvent: first and last sample of every fault);
//   - drivers/link_fault.hpp: the link and protocol faults applied at the
//     encoder/transport edge, from the per-sample LinkActions decided here;
//   - daemon: scene parsing ([[imu.fault]]), the control socket
//     (`imuemu fault inject|list|clear`), the fault log (JSON lines), status.
// Pure maths: no I/O, no allocation per sample once built.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/types.hpp"

namespace imuemu::fault {

enum class Kind : std::uint8_t {
  // Sensor faults: act on the sensor model's output (gyro / accel triads and
  // the increments that integrate them).
  stuck,           // the value frozen at its last good sample
  dead,            // zero
  garbage,         // uniform random within the sensor's range
  bias_step,       // + a constant bias
  bias_ramp,       // + a bias growing linearly from the fault's start
  scale_step,      // x (1 + scale_ppm 1e-6)
  noise_gain,      // white noise k-fold (adds independent noise, sigma sqrt(k^2-1) times the device's)
  spikes,          // isolated spikes at a rate, of an amplitude
  saturation,      // forced to the range's limit (sign of the true value), saturated status
  slow,            // a lower output rate: the value changes only every `divisor`-th sample
  intermittent,    // on/off pattern (on_ns, off_ns) from the start: dead while on, untouched while off
  delayed,         // the value of delay_ns earlier (bounded history)
  plausible_drift, // a slowly growing bias below usual detection thresholds
  // Link and protocol faults: act on the encoder and the transport.
  drop,             // packets dropped (probability, or bursts of burst_samples)
  duplicate,        // each affected packet sent twice
  bad_checksum,     // checksum / CRC corrupted
  bit_errors,       // random bit flips at bit_error_rate over the frame's bytes
  truncate,         // frame cut short by truncate_bytes
  bad_length,       // the length field disagrees with the payload
  sequence_jump,    // the protocol's counter jumps by sequence_step once
  sequence_reset,   // the protocol's counter restarts at 0
  time_jump,        // the protocol's time field jumps by time_step_ns (stays shifted while the fault acts)
  time_freeze,      // the protocol's time field frozen at the fault's first sample's
  babble,           // babble_factor frames per tick instead of one (bursts faster than the rate)
  silence,          // nothing sent (device off)
  restart,          // device restart: silence for duration, then the start-up sequence, counters reset (duration > 0)
  can_wrong_id,     // CAN: frames under a wrong identifier (can_id)
  can_missing_frame // CAN: one frame of a multi-frame transfer missing
};

bool is_sensor_fault(Kind kind);
bool is_link_fault(Kind kind);
bool is_can_only(Kind kind);
std::string_view kind_name(Kind kind);                    // "bias_step", ...
std::optional<Kind> kind_from_name(std::string_view name);  // nullopt: not a kind
std::vector<std::string_view> kind_names();

enum class Triad : std::uint8_t { gyro = 1, accel = 2, both = 3 };

// When a fault's start is measured from.
enum class Clock : std::uint8_t {
  trajectory,   // the sample's trajectory time t_k
  since_start,  // time since the device's first sample (t_k - t_0)
};

// One fault, in SI units (the scene and the control socket take datasheet
// units with the unit in the key and convert). Only the fields of its kind
// are read; validate() says which are missing or out of range.
struct FaultSpec {
  Kind kind = Kind::stuck;
  std::string device;                 // the [[imu]] name
  Triad triad = Triad::both;          // sensor faults
  std::uint8_t axes = 0b111;          // bit 0 x, 1 y, 2 z (sensor faults)
  Clock clock = Clock::since_start;
  TimeNs start_ns = 0;
  TimeNs duration_ns = 0;             // 0: until cleared (or the end of the run)
  // Parameters (by kind).
  double gyro_bias_rad_s = 0.0;       // bias_step, plausible_drift (final), spikes amplitude
  double accel_bias_m_s2 = 0.0;
  double gyro_ramp_rad_s2 = 0.0;      // bias_ramp, plausible_drift
  double accel_ramp_m_s3 = 0.0;
  double scale_ppm = 0.0;             // scale_step
  double noise_factor = 1.0;          // noise_gain (k)
  double rate_hz = 0.0;               // spikes per second; drop: bursts per second
  double probability = 0.0;           // drop / duplicate / bit_errors ...: per packet
  double bit_error_rate = 0.0;        // bit_errors: per bit
  std::uint32_t divisor = 1;          // slow
  TimeNs on_ns = 0, off_ns = 0;       // intermittent
  TimeNs delay_ns = 0;                // delayed
  std::uint32_t burst_samples = 0;    // drop bursts
  std::uint32_t truncate_bytes = 0;   // truncate
  std::int64_t sequence_step = 0;     // sequence_jump
  TimeNs time_step_ns = 0;            // time_jump
  std::uint32_t babble_factor = 0;    // babble
  std::uint32_t can_id = 0;           // can_wrong_id
  // The device reports the fault in its status/health fields where the
  // protocol has them (native status bits, MIP status flags, DroneCAN
  // NodeStatus health); false: a silent fault, only the data shows it.
  bool flag_status = false;
  std::uint64_t seed = 0;             // the random terms of this fault (from the scene seed unless given)
  std::string source = "scene";       // scene | random | control (ground truth says where it came from)
};

// The longest `delayed` fault any device takes (the history ring is sized
// from it at construction: ceil(kMaxDelayNs x rate) samples, at most
// kMaxDelaySamples; a faster device takes a proportionally shorter delay).
inline constexpr TimeNs kMaxDelayNs = kNsPerSecond;
inline constexpr std::uint32_t kMaxDelaySamples = 65'536;
// Bounds validate() enforces (each keeps the per-sample cost bounded).
inline constexpr std::uint32_t kMaxBurstSamples = 1000;   // drop bursts
inline constexpr std::uint32_t kMaxBabbleFactor = 16;     // frames per tick
inline constexpr std::uint32_t kMaxDivisor = 1'000'000;   // slow
inline constexpr double kMaxNoiseFactor = 1000.0;         // noise_gain
inline constexpr double kMaxSpikeRateHz = 1e6;

// "plausible but wrong" defaults: a bias growing over 100 s to a value far
// below what common autopilots flag. PX4's defaults (v1.14 parameter
// reference): EKF2_GYR_B_LIM 0.15 rad/s and EKF2_ABL_LIM 0.4 m/s^2 (the
// estimator's bias limits), COM_ARM_IMU_GYR 0.25 rad/s and COM_ARM_IMU_ACC
// 0.7 m/s^2 (the inconsistency between IMUs that blocks arming). Here:
// 0.5 deg/s (0.0087 rad/s, 17x below the smallest) and 20 mg (0.196 m/s^2,
// 2x below), reached at 0.005 deg/s per s and 0.2 mg/s.
inline constexpr double kPlausibleGyroBiasRadS = 0.5 * 3.14159265358979323846 / 180.0;
inline constexpr double kPlausibleGyroRampRadS2 = 0.005 * 3.14159265358979323846 / 180.0;
inline constexpr double kPlausibleAccelBiasMS2 = 0.020 * 9.80665;
inline constexpr double kPlausibleAccelRampMS3 = 0.0002 * 9.80665;

// A spec of `kind` with that kind's defaults filled in (what the scene and
// the control socket start from before their keys override): probability 1
// for the per-packet link faults (every packet of the fault's interval),
// the plausible_drift numbers above, divisor 2, noise_factor 1, babble 2.
FaultSpec default_spec(Kind kind);

// Throws std::invalid_argument naming the field and what was expected.
void validate(const FaultSpec& spec);

// One line per fault for check-config, `imuemu fault list` and logs:
// "bias_step gyro xyz at 10 s since start for 5 s: bias 0.01745 rad/s ...".
std::string describe(const FaultSpec& spec);

// The ground truth: a fault's first and last affected sample. Written as one
// JSON line per event by the daemon (docs/faults.md).
struct FaultEvent {
  enum class Phase : std::uint8_t { start, end } phase = Phase::start;
  std::uint64_t fault_id = 0;         // unique per device and run
  FaultSpec spec;
  std::uint64_t sample_counter = 0;   // start: first affected sample; end: last affected sample
  TimeNs t_ns = 0;                    // that sample's time
};

}  // namespace imuemu::fault
