// The fault timeline of one device (issue 18): which faults act on output
// sample k, what they do to it, and the ground truth of when they acted.
//
//   FaultTimeline timeline(options);            // scene faults, random faults, device context
//   per output sample k at trajectory time t_k (k increasing):
//     SampleValues v{gyro, accel, dtheta, dvel, period};
//     SampleFaults f = timeline.step(k, t_k, v);  // v now holds the faulted sample
//     status |= map(f.flags); link actions <- f.link; protocol time <- f.link.protocol_time_ns
//   timeline.drain_events(events)               // FaultEvents: start / end, caller-drained
//   timeline.finish()                           // end of run: open faults end at the last sample
//   run time: inject(spec) -> id, clear(id), clear_all(), list()
//
// When. A fault acts on the samples with start <= t_k < start + duration
// (duration 0: until cleared or the end of the run). Clock::trajectory:
// start is trajectory time; Clock::since_start: start is measured from the
// device's first sample t_0 (the first step()). A fault injected with its
// start at or before the last sample produced starts at the next sample
// (its duration counts from there). A fault whose interval holds no sample
// affects nothing and logs nothing.
//
// Random faults: `per_hour` faults per hour on average (a Poisson process on
// the time since start), each of a kind drawn uniformly from `kinds`, with
// the parameters of `parameters` and `duration_ns`. They are drawn per
// window of kRandomWindowNs as the run reaches it (memory stays bounded
// however long the run), from (seed, device name, window): one seed gives
// the same faults on the same samples run after run.
//
// Random terms (garbage, noise_gain, spikes, drop, duplicate, ...) are
// counter-based: each draw is a function of (spec.seed, the fault's stream,
// sample k, what is drawn) only (SplitMix64 finaliser, then the sensor
// model's Stream for uniform/Gaussian): bit-reproducible, independent of
// which samples were asked for, of timing and of other faults. The stream
// is the scene index for scene faults, (window, index) for random ones and
// the id for injected ones.
//
// No fault leaves state behind: stuck/slow hold values and the drop-burst
// pattern live only while the fault acts, and the delay history records
// the unfaulted input every sample. After clear() (or the end of a fault)
// the output is bit for bit that of a run that never had the fault.
//
// Not thread-safe: the caller serialises step()/finish() with
// inject()/clear()/list()/drain_events() (imuemud: the producer thread and
// the control socket under one mutex). step() allocates nothing, except the
// first time an event slot holds a long device name and when a random
// window is drawn (at most once per kRandomWindowNs).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "core/fault/fault.hpp"
#include "core/sensor/sensor_model.hpp"
#include "core/types.hpp"

namespace imuemu::fault {

// Status the faults raise, for the caller to map onto its protocol's bits
// (imuemud: kFlagFault -> drivers::kStatusFault, kFlagSaturated ->
// drivers::kStatusSaturated). Core does not know the drivers.
enum FaultFlag : std::uint32_t {
  // A value at the range: a saturation fault forced it there, or a fault that
  // adds or scales (bias_step, bias_ramp, plausible_drift, scale_step,
  // noise_gain, spikes) moved it beyond and it saturated (also with
  // kFlagFault: a non-finite input sent as 0).
  kFlagSaturated = 1u << 0,
  kFlagFault = 1u << 1,      // an active fault with flag_status
};

// garbage and saturation act within the sensor's range, and the faults that
// add or scale saturate at it: the sensor model's range where it has one,
// else these (a common MEMS IMU's widest setting, e.g. ICM-42688-P:
// +-2000 deg/s, +-16 g).
inline constexpr double kDefaultGyroRangeRadS = 2000.0 * 3.14159265358979323846 / 180.0;
inline constexpr double kDefaultAccelRangeMS2 = 16.0 * 9.80665;

// What the sensor faults need to know about the device.
struct DeviceContext {
  std::string device;                       // the [[imu]] name (random faults' draws, FaultSpec::device)
  std::int64_t rate_hz = 400;               // output rate: the nominal period, delay in samples
  double gyro_range_rad_s = kDefaultGyroRangeRadS;
  double accel_range_m_s2 = kDefaultAccelRangeMS2;
  // noise_gain adds independent white noise of sigma N sqrt(rate) sqrt(k^2 - 1)
  // per axis, N the sensor model's white-noise density (the white noise of
  // an unfiltered sensor at the output rate becomes k-fold). N = 0 (ideal
  // sensor): noise_gain adds nothing.
  Vec3 gyro_noise_density = Vec3::Zero();   // rad/s/sqrt(Hz)
  Vec3 accel_noise_density = Vec3::Zero();  // m/s^2/sqrt(Hz)
};
// The context from the device's sensor model (ranges, densities), defaults
// where it has none.
DeviceContext device_context(const std::string& device, std::int64_t rate_hz,
                             const std::optional<sensor::SensorModelSpec>& sensor);

// The parameters every random fault gets unless the scene gives them
// (docs/faults.md): bias 1 deg/s and 50 mg, ramp 0.01 deg/s per s and
// 1 mg/s, scale 10000 ppm, noise x10, spikes 1 /s of the bias's amplitude,
// slow /10, intermittent 100 ms on / 100 ms off, delay 50 ms, probability
// 0.1, drop bursts of 5 samples at 1 /s when burst_samples is given, bit
// error rate 1e-4, truncate 4 bytes, sequence step 100, time step 100 ms,
// babble 3, CAN id 0x123. A random plausible_drift always takes its own
// defaults (fault.hpp), whatever the bias and ramp parameters say.
FaultSpec random_fault_parameters();

// The longest `delayed` fault a device at rate_hz takes: kMaxDelayNs, or
// less above kMaxDelaySamples / 1 s (the history ring's size).
TimeNs max_delay_ns_at(std::int64_t rate_hz);

inline constexpr TimeNs kRandomWindowNs = 60 * kNsPerSecond;
inline constexpr double kMaxRandomPerHour = 1800.0;
inline constexpr std::uint32_t kMaxRandomPerWindow = 64;

struct RandomFaults {
  double per_hour = 0.0;               // 0: none
  std::vector<Kind> kinds;             // drawn uniformly
  TimeNs duration_ns = 10 * kNsPerSecond;
  std::uint64_t seed = 0;              // the scene's error-model seed unless given
  FaultSpec parameters = random_fault_parameters();  // triad, axes, parameters, flag_status of every random fault
};
// Throws std::invalid_argument (per_hour outside [0, kMaxRandomPerHour],
// no kinds, duration <= 0, a kind the parameters do not fit).
void validate(const RandomFaults& random);

// The per-sample link decision (the same fields as drivers::LinkActions,
// which the daemon fills from it; core does not include drivers/).
struct LinkDecision {
  bool silence = false;            // silence, or restart's off time
  bool drop = false;
  std::uint8_t copies = 1;         // 2: duplicate; N > 2: babble
  bool corrupt_checksum = false;
  double bit_error_rate = 0.0;     // bit_errors: per bit; the applier draws the count (bit_flip_count)...
  std::uint64_t bit_error_seed = 0;  // ...and the positions from this seed
  std::uint32_t truncate_bytes = 0;
  bool bad_length = false;
  std::int64_t sequence_step = 0;  // once, at the fault's first sample
  bool sequence_reset = false;     // once, at the fault's first sample
  bool restart = false;            // on the first sample after a restart fault's off time
  bool can_wrong_id = false;
  std::uint32_t can_id = 0;
  bool can_missing_frame = false;
  // time_jump / time_freeze: the time the encoder must put in the sample's
  // protocol time field instead of its own (the sample's values are those
  // of t_k; only the stamp lies).
  std::optional<TimeNs> protocol_time_ns;
  bool any() const {
    return silence || drop || copies != 1 || corrupt_checksum || bit_error_rate > 0.0 || truncate_bytes != 0 ||
           bad_length || sequence_step != 0 || sequence_reset || restart || can_wrong_id || can_missing_frame ||
           protocol_time_ns.has_value();
  }
};

// The number of bits to flip in a frame of frame_bits bits at bit_error_rate:
// binomial(frame_bits, rate), drawn from seed (Poisson by inversion below a
// mean of 30, else the normal approximation, rounded and clamped).
std::uint32_t bit_flip_count(double bit_error_rate, std::size_t frame_bits, std::uint64_t seed) noexcept;

// One output sample as the sensor chain made it (SI, body axes of the
// sensor; the increments over the period ending at t_k). period_ns 0: the
// nominal 1e9 / rate_hz.
struct SampleValues {
  Vec3 gyro_rad_s = Vec3::Zero();
  Vec3 accel_m_s2 = Vec3::Zero();
  Vec3 delta_theta_rad = Vec3::Zero();
  Vec3 delta_velocity_m_s = Vec3::Zero();
  TimeNs period_ns = 0;
};

struct SampleFaults {
  std::uint32_t flags = 0;  // FaultFlag bits
  LinkDecision link;
  std::uint32_t active = 0;  // faults acting on this sample
};

struct FaultInfo {
  std::uint64_t id = 0;
  FaultSpec spec;
  bool started = false;             // has acted on a sample
  std::uint64_t first_sample = 0;   // when started
  TimeNs first_t_ns = 0;
};

struct TimelineCounters {
  std::uint64_t started = 0, ended = 0;   // events produced
  std::uint64_t events_overflowed = 0;    // events lost: the buffer was full (drain more often)
  std::uint64_t random_drawn = 0;         // random faults scheduled
  std::uint64_t random_refused = 0;       // random faults beyond max_faults (not scheduled)
};

struct TimelineOptions {
  DeviceContext context;
  std::vector<FaultSpec> faults;        // the scene's
  RandomFaults random;
  std::size_t max_faults = 256;         // scheduled or acting at once (scene + random + injected)
  std::size_t event_capacity = 1024;    // events held until drained
};

class FaultTimeline {
 public:
  // Throws std::invalid_argument (a spec validate() refuses, with its index;
  // more faults than max_faults; a delay beyond this device's history; the
  // random settings; rate_hz not in 1..1e6).
  explicit FaultTimeline(TimelineOptions options);

  // Output sample k at trajectory time t_ns (k increasing; gaps allowed):
  // advances the timeline, applies the active sensor faults to `values` in
  // place and returns the flags and the link decision. Never NaN/Inf out of
  // finite input.
  SampleFaults step(std::uint64_t k, TimeNs t_ns, SampleValues& values) noexcept;

  // Run time. inject: validates (std::invalid_argument naming the field;
  // also for too many faults or a delay beyond the history) and schedules;
  // a refused spec changes nothing. spec.device is set to this device and
  // an empty or "scene" source to "control". Returns the fault's id.
  std::uint64_t inject(FaultSpec spec);
  // Ends a fault now: an acting one logs its end at the last sample it
  // acted on. false: no such fault (nothing changes).
  bool clear(std::uint64_t id);
  std::size_t clear_all();  // every scheduled or acting fault; returns how many
  std::vector<FaultInfo> list() const;

  // End of run: every acting fault ends at the last sample produced.
  void finish();

  // Appends the buffered events to `out` and empties the buffer.
  void drain_events(std::vector<FaultEvent>& out);
  bool pop_event(FaultEvent& out);
  std::size_t pending_events() const { return event_count_; }

  const TimelineCounters& counters() const { return counters_; }
  const DeviceContext& context() const { return options_.context; }
  // The longest delay this device takes (its history ring).
  TimeNs max_delay_ns() const;

 private:
  struct Entry {
    std::uint64_t id = 0;
    std::uint64_t stream = 0;
    FaultSpec spec;
    bool resolved = false;       // start/end in trajectory time known
    bool start_at_next = false;  // injected in the past: starts at the next sample
    TimeNs start_t = 0, end_t = 0;
    bool started = false;
    std::uint64_t first_k = 0, last_k = 0;
    TimeNs first_t = 0, last_t = 0;
    // stuck / slow: the held sample
    Vec3 held[4] = {Vec3::Zero(), Vec3::Zero(), Vec3::Zero(), Vec3::Zero()};
  };
  struct History {
    std::uint64_t k = 0;
    Vec3 v[4];
  };
  void resolve(Entry& e) const noexcept;
  void draw_random_window(std::uint64_t window);
  void push_event(FaultEvent::Phase phase, const Entry& e, std::uint64_t k, TimeNs t) noexcept;
  void check_fits(const FaultSpec& spec) const;
  // A fault that adds or scales saturates the values it moved at the range.
  void apply_sensor(Entry& e, std::uint64_t k, TimeNs t, double h_s, Vec3 (&v)[4], std::uint32_t& flags) noexcept;
  void decide_link(const Entry& e, std::uint64_t k, TimeNs t, double h_s, LinkDecision& d) const noexcept;
  const History* delayed(std::uint64_t k_wanted) const noexcept;

  TimelineOptions options_;
  std::vector<Entry> entries_;  // in id order; capacity max_faults
  std::uint64_t next_id_ = 1;
  bool have_t0_ = false, have_last_ = false, finished_ = false;
  TimeNs t0_ = 0, last_t_ = 0;
  std::uint64_t last_k_ = 0;
  Vec3 last_out_[4] = {Vec3::Zero(), Vec3::Zero(), Vec3::Zero(), Vec3::Zero()};
  std::uint64_t next_window_ = 0;
  bool pending_restart_ = false;
  std::uint64_t device_hash_ = 0;
  // Delay history: the unfaulted input of the last history_.size() samples.
  std::vector<History> history_;
  std::size_t history_next_ = 0, history_count_ = 0;
  // Events: a ring of event_capacity slots.
  std::vector<FaultEvent> events_;
  std::size_t event_head_ = 0, event_count_ = 0;
  TimelineCounters counters_;
};

}  // namespace imuemu::fault
