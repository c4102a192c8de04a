// The checks and counters every pose source shares (io/pose_source.hpp):
// ordering, scene conversion, attitude step, datagram sequence statistics,
// rate-limited logging and line framing. Pure logic without threads or
// sockets, so tests and fuzzers drive it directly.
#pragma once

#include <array>
#include <bitset>
#include <deque>
#include <vector>
#include <cstddef>
#include <cstdint>
#include <map>
#include <mutex>
#include <set>
#include <optional>
#include <span>
#include <string>
#include <string_view>

#include "io/mavlink_pose.hpp"
#include "io/pose_source.hpp"
#include "io/scene_poses.hpp"

namespace imuemu::io {

// Loss statistics of a datagram stream from the sequence numbers of intact
// datagrams (docs/pose-wire-format.md §3.2).
class SequenceTracker {
 public:
  enum class Arrival {
    first,    // the first datagram (or the first after a restart)
    next,     // highest + 1
    jump,     // above highest + 1: the numbers in between counted as gaps
    late,     // a gap member arriving afterwards, within kSequenceWindow
    repeat,   // already seen (a network duplicate), or below the start
    stale,    // more than kSequenceWindow below the highest: unknown whether seen
    restart,  // not above the highest but with a later time: the sender restarted
  };
  // Numbers compare modulo 2^64 (highest + 1 after 2^64 - 1 is 0). A number
  // more than kMaxSequenceJump ahead or kSequenceWindow behind is a
  // discontinuity: counted stale and nothing else until confirm_run
  // consecutive numbers follow it, which then count as a restart (no gaps).
  explicit SequenceTracker(std::size_t confirm_run = 2) : confirm_run_(confirm_run < 1 ? 1 : confirm_run) {}
  Arrival observe(std::uint64_t sequence, TimeNs t_ns) noexcept;

  std::uint64_t gaps() const noexcept { return gaps_; }
  std::uint64_t late() const noexcept { return late_; }
  std::uint64_t stale() const noexcept { return stale_; }
  std::uint64_t restarts() const noexcept { return restarts_; }
  std::uint64_t highest() const noexcept { return highest_; }

 private:
  void begin(std::uint64_t sequence, TimeNs t_ns) noexcept;

  bool started_ = false;
  // A discontinuity being confirmed: the last number of the run of
  // consecutive numbers outside the window, and its length.
  std::uint64_t candidate_ = 0;
  std::size_t candidate_run_ = 0;
  std::uint64_t highest_ = 0;
  TimeNs highest_t_ns_ = 0;
  std::bitset<kSequenceWindow> seen_;  // bit s % window: s in (highest - window, highest] arrived
  std::uint64_t gaps_ = 0, late_ = 0, stale_ = 0, restarts_ = 0;
  std::size_t confirm_run_;
};

// At most one line per key per interval; the next line of a key reports how
// many of its lines were suppressed in between.
class RateLimitedLog {
 public:
  RateLimitedLog(std::function<void(std::string_view)> sink, TimeNs interval_ns);
  void log(std::string_view key, std::string_view message, TimeNs now_ns);
  void flush();  // one line per key with suppressed lines left
 private:
  struct KeyState {
    TimeNs last_ns = 0;
    std::uint64_t suppressed = 0;
  };
  void emit(std::string_view line);
  std::function<void(std::string_view)> sink_;
  TimeNs interval_ns_;
  std::map<std::string, KeyState, std::less<>> keys_;
};

// Splits a byte stream into lines of at most kMaxPoseLineBytes. Pull-based,
// so a source under backpressure can stop taking lines and resume later.
class LineFramer {
 public:
  void append(const char* data, std::size_t size);
  enum class Next { none, line, too_long };
  // line: `line` is the next complete line (without '\n'), valid until the
  // next append(). too_long: a line exceeded kMaxPoseLineBytes; its bytes are
  // discarded up to its '\n' (reported once, when the limit is crossed).
  Next next(std::string_view& line);
  // The stream ended: true if bytes of an unterminated line were left (they
  // are dropped). Resets the framer.
  bool finish();
  void reset();

 private:
  std::string buffer_;
  std::size_t pos_ = 0;     // start of the unread part
  bool discarding_ = false;  // inside a too-long line
};

// The shared admission rules and the counters of one source.
class PoseAdmission {
 public:
  explicit PoseAdmission(const PoseSourceOptions& options);

  // Every unit that arrives is counted received, then ends in exactly one of
  // ignored(), admit() (accepted, rejected or held) or a reject_*(). The
  // counters are published (counters()) when the unit ends, never between
  // received() and its classification: see Unit.
  void received() noexcept { add(kReceived); }
  void ignored() noexcept {
    const Unit unit(*this);
    add(kIgnored);
  }
  void reject_line(LineError reason, std::string_view message);
  void reject_datagram(DatagramError reason, std::string_view message);

  // Time range (time_out_of_range), scene conversion (scene_refused), live
  // time acquisition and resynchronisation (time_jump, resyncs; see
  // PoseSourceOptions::resync_poses), ordering (duplicate, out_of_order),
  // attitude step and chart rules against the last accepted pose. True: `out`
  // holds the first pose to queue, counted accepted; a (re-)acquisition
  // releases the held poses too: take them with take_released() until false.
  bool admit(const TrajectoryRecord& record, std::optional<std::uint64_t> sequence, TimeNs receive_ns,
             SourcedPose& out);
  bool take_released(SourcedPose& out);

  // Loss statistics of an intact datagram (call before admit()).
  void observe_sequence(std::uint64_t sequence, TimeNs t_ns);

  // One datagram through all of the above: counted received, decoded
  // (docs/pose-wire-format.md §2), its sequence observed, admitted. True:
  // `out` holds the pose to queue. `from` names the sender in log lines.
  bool receive_datagram(std::span<const std::uint8_t> bytes, TimeNs receive_ns, std::string_view from,
                        SourcedPose& out);

  // The same for a datagram of MAVLink 2 packets (docs/pose-wire-format.md
  // §4): its HIL_STATE_QUATERNION is the pose, its 8-bit sequence widened per
  // sender; a datagram of other messages only is counted ignored.
  bool receive_mavlink_datagram(std::span<const std::uint8_t> bytes, TimeNs receive_ns, std::string_view from,
                                SourcedPose& out);

  void overflow_dropped() noexcept { count_now(kOverflowDropped); }
  void backpressure_event() noexcept { count_now(kBackpressureEvents); }
  void connection() noexcept { count_now(kConnections); }
  void connection_refused() noexcept { count_now(kConnectionsRefused); }
  void connection_idle_closed() noexcept { count_now(kConnectionsIdleClosed); }
  void connection_replaced() noexcept { count_now(kConnectionsReplaced); }

  // While a Unit lives, counting is not published; the last one to end
  // publishes one snapshot of everything counted (issue 26: a reader saw
  // `received` of a datagram before its classification, so `accepted` one
  // short). Every public counting call holds one; the UDP source holds one
  // across a datagram and the queueing of its pose, so a snapshot's
  // accepted poses are all queued. Single-threaded: the source's thread.
  class Unit {
   public:
    explicit Unit(PoseAdmission& admission) noexcept : admission_(admission) { ++admission_.open_units_; }
    ~Unit() {
      if (--admission_.open_units_ == 0) admission_.publish();
    }
    Unit(const Unit&) = delete;
    Unit& operator=(const Unit&) = delete;

   private:
    PoseAdmission& admission_;
  };

  void log(std::string_view key, std::string_view message);  // rate limited, prefixed with the source name
  void flush_log() { log_.flush(); }

  // The last published snapshot (any thread; a mutex held for one copy).
  PoseSourceCounters counters() const noexcept;
  const std::string& name() const noexcept { return name_; }
  void set_name(std::string name) { name_ = std::move(name); }

 private:
  enum Slot : std::size_t {
    kReceived,
    kIgnored,
    kAccepted,
    kSceneRefused,
    kDuplicate,
    kOutOfOrder,
    kAttitudeStep,
    kChartSpan,
    kTimeRange,
    kTimeJump,
    kOtherSender,
    kHeld,
    kResyncs,
    kOverflowDropped,
    kBackpressureEvents,
    kSequenceGaps,
    kLate,
    kStale,
    kSequenceRestarts,
    kConnections,
    kConnectionsRefused,
    kConnectionsIdleClosed,
    kConnectionsReplaced,
    kLineErrorsFirst,
    kDatagramErrorsFirst = kLineErrorsFirst + kLineErrorCount,
    kSlotCount = kDatagramErrorsFirst + kDatagramErrorCount,
  };
  void add(std::size_t slot, std::uint64_t n = 1) noexcept { counting_[slot] += n; }
  void set(std::size_t slot, std::uint64_t value) noexcept { counting_[slot] = value; }
  void count_now(std::size_t slot) noexcept {
    const Unit unit(*this);
    add(slot);
  }
  void publish() noexcept;
  void reject(Slot slot, std::string_view key, const std::string& message);
  void other_sender(const mavlink::PacketInfo& info, std::string_view from);

  std::string name_;
  double max_attitude_step_rad_;
  ScenePoseConverter converter_;
  SequenceTracker sequence_;
  RateLimitedLog log_;
  // Live time (admit): the stream is locked once resync_poses consistent
  // poses arrived; candidates_ are poses of a possible new stream (held).
  struct Candidate {
    Pose pose;  // sender time
    std::optional<std::uint64_t> sequence;
    TimeNs receive_ns;
    std::size_t line;
    PoseRates rates;
  };
  bool consistent(const Pose& from, const Pose& to) const;
  void drop_candidates();
  bool release_candidates(TimeNs offset_ns, SourcedPose& out);
  void release(const Pose& pose, std::optional<std::uint64_t> sequence, TimeNs receive_ns, std::size_t line,
               const PoseRates& rates);

  double max_chart_angle_rad_;
  TimeNs max_time_step_ns_;
  TimeNs max_gap_ns_;  // the engine's gap limit: where a re-acquired stream is placed
  std::size_t resync_poses_;
  bool locked_ = false;
  TimeNs offset_ns_ = 0;        // output time = sender time + offset (changed by a resync)
  TimeNs last_sender_ns_ = 0;   // sender time of the last accepted pose
  TimeNs last_receive_ns_ = 0;  // its receive time
  std::vector<Candidate> candidates_;
  std::deque<SourcedPose> released_;
  std::optional<Pose> last_accepted_;  // output time
  // Counted by the source's thread (counting_), published for readers
  // (published_, under published_mutex_) when the outermost Unit ends.
  std::array<std::uint64_t, kSlotCount> counting_{};
  int open_units_ = 0;
  mutable std::mutex published_mutex_;
  std::array<std::uint64_t, kSlotCount> published_{};
  mavlink::SequenceWidener mavlink_sequences_;
  mavlink::SenderFilter mavlink_sender_;
  std::set<std::uint16_t> named_other_senders_;  // with their own log key (at most kNamedOtherSenders)
};

// One line stream (a TCP connection, stdin) through framer, decoder and
// admission: bytes in, poses ready to queue out.
class PoseLineStream {
 public:
  // stream_name: used in messages with line numbers ("tcp ... connection 2:17: ...").
  PoseLineStream(PoseAdmission& admission, std::string stream_name);
  // Bytes read at receive_ns (CLOCK_MONOTONIC). Call only once next() has
  // returned false: the lines of earlier bytes are then all taken.
  void append(const char* data, std::size_t size, TimeNs receive_ns);
  // The next accepted pose of the buffered lines (counting and logging every
  // line on the way); false when no complete line is left.
  bool next(SourcedPose& out);
  // End of the stream: counts an unterminated last line (unterminated_line).
  void finish();

 private:
  PoseAdmission& admission_;
  std::string stream_name_;
  PoseLineDecoder decoder_;
  LineFramer framer_;
  TimeNs receive_ns_ = 0;
};

}  // namespace imuemu::io
