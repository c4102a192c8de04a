// Trajectory time <-> the emitter's CLOCK_MONOTONIC, exactly in integers.
//
// Live emission sends the output sample of trajectory tick t at the monotonic
// instant the mapping assigns to t. The mapping is the affine line through one
// anchor pair (t0, m0) with a rational replay speed p/q (trajectory ns per
// monotonic ns):
//   m(t) = m0 + (t - t0) q / p,        t(m) = t0 + (m - m0) p / q.
// Both directions are evaluated in 128-bit integers (time is int64 ns end to
// end, core/types.hpp; no double seconds since epoch), so they are exact for
// any int64 inputs, including |t| up to 2^62 ns with anchors of either sign;
// a result that does not fit int64 is reported, never wrapped.
//
// The two integer maps round in opposite directions so that they form an exact
// pair (a Galois connection) whatever the speed:
//   monotonic_at(t)  = ceil(m(t))   the first monotonic ns not before t's instant
//   trajectory_at(m) = floor(t(m))  the last trajectory ns whose instant has come
// and trajectory_at(m) >= t  <=>  m >= monotonic_at(t): "tick t is due at m"
// reads the same from both sides. Round trips:
//   speed <= 1: trajectory_at(monotonic_at(t)) == t for every t;
//   speed >= 1: monotonic_at(trajectory_at(m)) == m for every m;
// (speed 1 both; the other direction can only lose the sub-ns fraction).
//
// Pure: the clocks are read by the caller and passed in.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

#include "core/types.hpp"

namespace imuemu::live {

// Replay speed numerator/denominator: trajectory time advances p/q ns per
// monotonic ns (2.5 -> 5/2 plays 2.5x faster, 1/3 three times slower).
// Always reduced, 1 <= p, q <= kMaxSpeedTerm.
struct SpeedFactor {
  std::int64_t numerator = 1;
  std::int64_t denominator = 1;
  friend bool operator==(const SpeedFactor&, const SpeedFactor&) = default;
};

// Bound on p and q: keeps (int64 difference) * q inside 2^127 with a wide margin
// and is far finer than any useful replay speed (a 12-digit decimal).
inline constexpr std::int64_t kMaxSpeedTerm = 1'000'000'000'000;

// Reduces p/q; throws std::invalid_argument unless 1 <= p, q and both reduce to
// at most kMaxSpeedTerm.
SpeedFactor make_speed_factor(std::int64_t numerator, std::int64_t denominator);

// Parses "2.5", "3", "0.125" (exact decimal, up to 12 fraction digits) or a
// fraction "1/3" into a reduced SpeedFactor. Throws std::invalid_argument
// naming the text and what was expected (positive decimal or p/q).
SpeedFactor parse_speed_factor(std::string_view text);

// "5/2", or "3" for a whole speed.
std::string to_string(const SpeedFactor& speed);

class TimeMapping {
 public:
  // General anchor: trajectory time anchor_trajectory_ns is due exactly at
  // monotonic anchor_monotonic_ns. With anchor (0, 0) and speed 1 the
  // trajectory is already stamped in the emitter's CLOCK_MONOTONIC.
  TimeMapping(TimeNs anchor_trajectory_ns, TimeNs anchor_monotonic_ns, SpeedFactor speed = {});

  // Alignment "start now": trajectory time start_trajectory_ns is due at
  // monotonic_now_ns, i.e. emission begins at once. start_trajectory_ns is the
  // stream's first output tick for a plain start, or the trajectory time the
  // user asked to start from ("start at a given trajectory time"): earlier
  // ticks then map to instants already past and the caller skips them.
  static TimeMapping start_now(TimeNs start_trajectory_ns, TimeNs monotonic_now_ns, SpeedFactor speed = {});

  // Alignment "start at the next whole second of CLOCK_REALTIME" (PPS): the
  // clocks are read together by the caller (realtime_now_ns ~ monotonic_now_ns,
  // both int64 ns, realtime since the Unix epoch). start_trajectory_ns becomes
  // due at the monotonic instant of the first whole realtime second S that is
  // strictly after realtime_now_ns and at least min_lead_ns (>= 0) after it:
  //   S = max((floor(realtime_now / 1 s) + 1) s, ceil((realtime_now + min_lead) / 1 s) s),
  //   anchor monotonic = monotonic_now + (S - realtime_now).
  // min_lead_ns leaves the caller time to prepare the first sample; a reading
  // exactly on a whole second waits for the next one (the current edge has
  // passed by the time anything can be sent). The mapping
  // is in monotonic time from then on: a later step of CLOCK_REALTIME (NTP)
  // does not move it, a slew makes the two drift apart by the slew rate.
  static TimeMapping start_at_next_realtime_second(TimeNs start_trajectory_ns, TimeNs monotonic_now_ns,
                                                   TimeNs realtime_now_ns, TimeNs min_lead_ns = 0,
                                                   SpeedFactor speed = {});

  // ceil(m0 + (t - t0) q / p): when trajectory tick t is due. Throws
  // std::overflow_error if that instant does not fit int64.
  TimeNs monotonic_at(TimeNs trajectory_ns) const;
  // floor(t0 + (m - m0) p / q): the latest trajectory time due at monotonic m.
  // Throws std::overflow_error if it does not fit int64.
  TimeNs trajectory_at(TimeNs monotonic_ns) const;

  TimeNs anchor_trajectory_ns() const { return anchor_trajectory_ns_; }
  TimeNs anchor_monotonic_ns() const { return anchor_monotonic_ns_; }
  SpeedFactor speed() const { return speed_; }

 private:
  TimeNs anchor_trajectory_ns_;
  TimeNs anchor_monotonic_ns_;
  SpeedFactor speed_;
};

}  // namespace imuemu::live
