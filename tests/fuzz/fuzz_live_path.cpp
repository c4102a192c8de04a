// libFuzzer target: the live path end to end, in process (issue 13: "fuzz
// the live path end to end, datagram sequences, not only single datagrams").
// A sequence of datagrams goes through what imuemud does with a UDP scene
// (io/pose_source_net.cpp UdpPoseSource::handle, then
// daemon/engine/emission.cpp take_live_input and produce), without sockets or
// clocks: decode (docs/pose-wire-format.md §2) -> admission (ordering, scene
// conversion, attitude and chart rules, the live-time acquisition and
// resynchronisation rule) -> StreamPipeline::push (a refused knot counted,
// never fatal) -> LiveEmitter at every output tick that real time has made
// due (the first pose maps to "now"; tick t is due emit_delay after it) ->
// the sample that would go on the wire.
//
// Invariants (a violation traps):
//   * no exception escapes (libFuzzer reports an uncaught one as a crash);
//   * every datagram ends counted: received == ignored + accepted + rejected
//     + held, and every accepted pose is pushed or refused exactly once;
//   * accepted poses are finite and strictly later than the previous one;
//   * a knot the engine refuses changes nothing in it (strong guarantee of
//     StreamPipeline::push: knots_pushed, last knot, ready samples);
//   * every sample the emitter hands out is finite and stamped with its tick;
//   * the emitter's tick counters sum to its ticks.
//
// Input: byte 0 is flags (bit 0: recompute each datagram's CRC so the fuzzer
// reaches the checks behind it; bit 1: write magic and version 1; bit 2: the
// ecef scene, otherwise flat; bit 3: underrun policy pause instead of
// extrapolate; bit 4: the scene default's kernel oversampling; bit 5: the
// input ends, finish()). Then records of [length code][advance][bytes]: length code
// >= 128 means a full 84-byte datagram, otherwise that many bytes (a short or
// long datagram; what is left of the input if less); advance is the real
// time, in milliseconds, that passes before this datagram arrives (ticks
// falling due meanwhile are emitted first).
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <vector>

#include "core/live_emitter.hpp"
#include "core/stream.hpp"
#include "core/time_arith.hpp"
#include "io/pose_admission.hpp"
#include "io/pose_wire.hpp"
#include "tests/fuzz/reseal_datagram.hpp"

namespace {

using namespace imuemu;
using namespace imuemu::io;

// The live-udp example scene's engine (config/live-udp.toml), at a lower
// rate so that one input runs fast: 50 Hz knots, 0.05 s window, split at
// gaps over 1 s, 100 Hz output.
constexpr std::int64_t kRateHz = 100;
constexpr TimeNs kKnotIntervalNs = 20'000'000;
constexpr TimeNs kMarginNs = 50'000'000;
// Ticks emitted after the input ended (finish()): bounds the run when the
// last knot is far ahead of the emission clock.
constexpr std::uint64_t kMaxTailTicks = 2000;

bool finite(const Kinematics& k) {
  return k.position_m.allFinite() && k.velocity_m_s.allFinite() && k.acceleration_m_s2.allFinite() &&
         k.attitude.allFinite() && k.angular_rate_rad_s.allFinite();
}

// daemon/engine/emission.cpp grid_ns: t0 + floor(k * 1e9 / rate) without overflow.
TimeNs grid_ns(TimeNs t0_ns, std::uint64_t k) {
  const auto r = static_cast<std::uint64_t>(kRateHz);
  const auto offset = static_cast<TimeNs>((k / r) * static_cast<std::uint64_t>(kNsPerSecond) +
                                          (k % r) * static_cast<std::uint64_t>(kNsPerSecond) / r);
  return saturating_add_ns(t0_ns, offset);
}

struct LivePath {
  explicit LivePath(std::uint8_t flags) : admission(source_options(flags)), engine(pipeline_options(flags)),
        emitter(emitter_options(flags)), samples(engine) {
    emit_delay_ns = StreamPipeline::lookahead_ns(pipeline_options(flags), kKnotIntervalNs) + kMarginNs;
  }

  static PoseSourceOptions source_options(std::uint8_t flags) {
    PoseSourceOptions o;
    o.physics = (flags & 4) != 0 ? Physics::ecef : Physics::flat;
    o.log = [](std::string_view) {};
    o.max_gap_ns = kNsPerSecond;  // the engine's gap limit (po.max_gap_s below), as imuemud sets it
    return o;
  }
  static PipelineOptions pipeline_options(std::uint8_t flags) {
    PipelineOptions po;
    po.scene.physics = (flags & 4) != 0 ? Physics::ecef : Physics::flat;
    po.rate_hz = kRateHz;
    po.gap_policy = GapPolicy::split;
    po.max_gap_s = 1.0;
    po.kernel.delta = 5;  // 0.05 s at 100 Hz
    // Bit 4: the scene default's oversampling of short kernels (m = 20 here),
    // 20x the numerical work per sample; off by default so that the fuzzer
    // spends its time on the sequences, not on Eq. 3.68 sums.
    po.min_kernel_samples = (flags & 16) != 0 ? 100 : 0;
    return po;
  }
  static live::LiveEmitterOptions emitter_options(std::uint8_t flags) {
    live::LiveEmitterOptions lo;
    lo.scene = pipeline_options(flags).scene;
    lo.underrun = (flags & 8) != 0 ? live::UnderrunPolicy::pause : live::UnderrunPolicy::extrapolate;
    lo.blend_ns = 200'000'000;
    return lo;
  }

  // A released pose into the engine, as take_live_input does.
  void push(const SourcedPose& released) {
    const Pose& p = released.pose;
    if (!p.position_m.allFinite() || !p.attitude.allFinite()) __builtin_trap();
    if (previous_accepted && !(p.t_ns > *previous_accepted)) __builtin_trap();
    if (!released.sequence) __builtin_trap();
    previous_accepted = p.t_ns;
    ++accepted;
    const std::size_t knots_before = engine.knots_pushed();
    const TimeNs last_before = engine.last_knot_ns();
    const std::size_t ready_before = engine.ready();
    try {
      engine.push(p);
      ++pushed;
    } catch (const std::exception&) {
      ++refused;  // counted, never fatal (daemon/engine/emission.cpp)
      if (engine.knots_pushed() != knots_before || engine.last_knot_ns() != last_before ||
          engine.ready() != ready_before)
        __builtin_trap();  // a refused knot must change nothing
    }
    if (!t0_ns && engine.knots_pushed() > 0) {
      // The first pose fixes the grid and the clock (TimeMapping::start_now).
      t0_ns = engine.first_knot_ns();
      mapping_now_ns = now_ns;
    }
  }

  void emit(TimeNs tick_ns) {
    const live::Emission e = emitter.emit(tick_ns, samples);
    if (e.has_sample()) {
      if (!finite(e.kinematics) || !e.imu.gyro_rad_s.allFinite() || !e.imu.accel_m_s2.allFinite()) __builtin_trap();
      if (e.imu.t_ns != tick_ns || e.kinematics.t_ns != tick_ns) __builtin_trap();
      ++sent;
    }
    ++next_tick;
  }

  // Emits every tick whose deadline (tick time + emit delay on the clock
  // that started at the first pose) is not after now.
  void emit_due() {
    if (!t0_ns) return;
    const TimeNs elapsed_ns = saturating_sub_ns(now_ns, mapping_now_ns);
    const TimeNs due_until_ns = saturating_add_ns(*t0_ns, saturating_sub_ns(elapsed_ns, emit_delay_ns));
    for (TimeNs tick = grid_ns(*t0_ns, next_tick); tick <= due_until_ns; tick = grid_ns(*t0_ns, next_tick)) emit(tick);
  }

  PoseAdmission admission;
  StreamPipeline engine;
  live::LiveEmitter emitter;
  live::StreamSampleSource samples;
  TimeNs emit_delay_ns = 0;
  TimeNs now_ns = kNsPerSecond;  // CLOCK_MONOTONIC of the simulated host
  std::optional<TimeNs> t0_ns;
  TimeNs mapping_now_ns = 0;
  std::uint64_t next_tick = 0;
  std::optional<TimeNs> previous_accepted;
  std::uint64_t accepted = 0, pushed = 0, refused = 0, sent = 0;
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  const std::uint8_t flags = data[0];
  LivePath path(flags);
  std::size_t at = 1;
  std::uint64_t datagrams = 0;
  while (at + 2 <= size) {
    const std::uint8_t length_code = data[at];
    const std::uint8_t advance_ms = data[at + 1];
    at += 2;
    const std::size_t want = length_code >= 128 ? kPoseDatagramV1Size : length_code;
    const std::size_t n = std::min(want, size - at);
    std::vector<std::uint8_t> d(data + at, data + at + n);
    at += n;
    fuzz::reseal_datagram(d, flags);

    // Real time passes; what fell due meanwhile goes out first.
    path.now_ns += static_cast<TimeNs>(advance_ms) * 1'000'000;
    path.emit_due();
    SourcedPose out;
    if (path.admission.receive_datagram(d, path.now_ns, "fuzz", out)) {
      do path.push(out);
      while (path.admission.take_released(out));  // an acquisition releases the held poses too
    }
    ++datagrams;
    const PoseSourceCounters c = path.admission.counters();
    if (c.received != datagrams) __builtin_trap();
    if (c.received != c.ignored + c.accepted + c.rejected() + c.held) __builtin_trap();
    if (c.accepted != path.accepted || path.pushed + path.refused != path.accepted) __builtin_trap();
    if (c.late > c.sequence_gaps) __builtin_trap();
  }

  // Bit 5: the input ends (as a finite stdin stream does; a UDP source never
  // ends): the engine computes its end and the remaining ticks up to the
  // last knot go out (bounded). Off by default: finish()'s end extrapolation
  // costs more than the whole sequence before it.
  if ((flags & 32) != 0 && path.engine.knots_pushed() >= 2) {
    try {
      path.engine.finish();
    } catch (const std::exception&) {
      // A last run of a single knot: counted by the daemon, never fatal.
    }
    const std::uint64_t tail_end = path.next_tick + kMaxTailTicks;
    while (path.t0_ns && path.next_tick < tail_end) {
      const TimeNs tick = grid_ns(*path.t0_ns, path.next_tick);
      if (tick > path.engine.last_knot_ns()) break;
      path.emit(tick);
    }
  }
  const live::LiveCounters& lc = path.emitter.counters();
  if (lc.ticks != path.next_tick) __builtin_trap();
  if (lc.exact + lc.extrapolated + lc.blending + lc.paused + lc.waiting + lc.gap != lc.ticks) __builtin_trap();
  if (lc.exact + lc.extrapolated + lc.blending != path.sent) __builtin_trap();
  return 0;
}
