// Live pose sources (GitHub issue "Streaming engine", pose-source part):
// file replay, UDP datagrams, a TCP line stream and stdin, behind one
// interface. Each runs on its own thread, validates what arrives
// (docs/pose-wire-format.md), converts it to a scene-frame Pose and hands it
// to a bounded PoseQueue that the consumer (the streaming engine's thread)
// drains without ever waiting for data.
//
// Every unit that arrives (a datagram, a line, a file record) is counted as
// received and ends in exactly one of: ignored (blank/comment/version/header
// line), accepted, or one rejection counter:
//   received == ignored + accepted + rejected()
// Rejected units are dropped and logged (rate limited); the stream goes on.
#pragma once

#include <array>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <numbers>
#include <optional>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "core/interpolation.hpp"
#include "core/pipeline.hpp"
#include "core/trajectory.hpp"
#include "io/pose_wire.hpp"

namespace imuemu::io {

// CLOCK_MONOTONIC in int64 nanoseconds: the receive time of every pose.
TimeNs monotonic_now_ns() noexcept;

// What a source delivers: a validated pose, already in the scene frame.
struct SourcedPose {
  Pose pose;                              // scene frame (io/scene_poses.hpp)
  std::optional<std::uint64_t> sequence;  // the datagram's sequence number (datagrams only)
  TimeNs receive_ns = 0;                  // CLOCK_MONOTONIC when its bytes arrived (UDP: the kernel's receive
                                          // time stamp; TCP, stdin: read; file replay: released)
  std::size_t line = 0;                   // line in the file or stream (per TCP connection); 0 for datagrams
  PoseRates rates;                        // derivatives the input carried, scene frame (datagram v2, MAVLink)
};

// Bounded single-producer single-consumer hand-off. A mutex guards a
// preallocated ring; it is held only to copy one item, so try_pop/drain
// return at once and never allocate (drain appends to the caller's vector).
// A consumer with nothing else to do until a deadline sleeps in
// wait_for_items_until: every push wakes it (issue 17: the emission
// engine's producer takes a pose when it arrives instead of at its next
// 1 ms poll), and so does wake_consumer() (stop, end of input).
class PoseQueue {
 public:
  explicit PoseQueue(std::size_t capacity);  // capacity >= 1

  // Producer side.
  bool try_push(const SourcedPose& item);                 // false (nothing queued) when full
  bool push_or_drop_oldest(const SourcedPose& item);      // always queues; true if the oldest was dropped
  bool wait_for_space(std::chrono::nanoseconds timeout);  // true once not full

  // Consumer side.
  bool try_pop(SourcedPose& out);
  std::size_t drain(std::vector<SourcedPose>& out, std::size_t max_items = SIZE_MAX);
  // Sleeps until an item is queued, wake_consumer() is called, or
  // CLOCK_MONOTONIC reaches deadline_ns (io::monotonic_now_ns()), whichever
  // comes first; returns at once if an item is already queued. True when
  // items are queued on return. Counts its returns (wait_counters()).
  bool wait_for_items_until(TimeNs deadline_ns);
  // Ends the consumer's current (or next) wait_for_items_until early.
  void wake_consumer();

  // How the consumer's waits ended: items were there on entry (no sleep); a
  // push ended the sleep before the deadline; the deadline passed (items may
  // have come meanwhile); wake_consumer() with nothing queued.
  struct WaitCounters {
    std::uint64_t items_on_entry = 0, woken_by_push = 0, deadline = 0, woken = 0;
    std::uint64_t total() const noexcept { return items_on_entry + woken_by_push + deadline + woken; }
  };
  WaitCounters wait_counters() const;

  std::size_t size() const;
  std::size_t capacity() const noexcept { return ring_.size(); }
  std::uint64_t popped() const noexcept { return popped_.load(std::memory_order_relaxed); }

 private:
  mutable std::mutex mutex_;
  std::condition_variable space_;
  std::condition_variable items_;  // the consumer's wait_for_items_until
  bool wake_requested_ = false;    // under mutex_
  WaitCounters waits_;             // under mutex_
  std::vector<SourcedPose> ring_;
  std::size_t head_ = 0;   // oldest item
  std::size_t count_ = 0;
  std::atomic<std::uint64_t> popped_{0};
};

// A snapshot of a source's counters (definitions in docs/pose-wire-format.md §3).
// The source's thread publishes one snapshot per unit, once the unit is
// classified (UDP: once its pose is queued), so the counters of one snapshot
// are consistent with each other: received == ignored + accepted +
// rejected() + held.
struct PoseSourceCounters {
  std::uint64_t received = 0;  // datagrams / lines (incl. blank, comment, header) / file records
  std::uint64_t ignored = 0;   // blank, comment, version and header lines
  std::uint64_t accepted = 0;  // passed every check and handed to the queue
  std::array<std::uint64_t, kLineErrorCount> line_errors{};          // by LineError
  std::array<std::uint64_t, kDatagramErrorCount> datagram_errors{};  // by DatagramError
  std::uint64_t scene_refused = 0;   // valid record without a finite pose in the scene (ScenePoseConverter)
  std::uint64_t duplicate = 0;       // time equal to the last accepted pose's
  std::uint64_t out_of_order = 0;    // time before the last accepted pose's
  std::uint64_t attitude_step = 0;   // rotation from the last accepted pose >= max_attitude_step_rad
  std::uint64_t chart_span = 0;      // rotation from the last accepted pose > max_chart_angle_rad (a glitch)
  std::uint64_t time_out_of_range = 0;  // |t| > kMaxPoseTimeNs
  std::uint64_t time_jump = 0;       // more than max_time_step_ns from the stream and never confirmed (stray)
  std::uint64_t other_sender = 0;    // MAVLink: intact HIL_STATE_QUATERNION of a sender other than the one taken
  std::uint64_t held = 0;            // now: poses waiting for resync_poses consistent ones (a gauge)
  std::uint64_t resyncs = 0;         // the stream re-acquired after a jump or restart of its times

  std::uint64_t overflow_dropped = 0;     // accepted, then dropped as the oldest queued (UDP burst)
  std::uint64_t backpressure_events = 0;  // times reading stopped because the queue was full (TCP, stdin, file)

  // Datagram arrival statistics over intact datagrams (checksum ok):
  std::uint64_t sequence_gaps = 0;      // sequence numbers skipped by forward jumps
  std::uint64_t late = 0;               // skipped numbers that arrived afterwards (within kSequenceWindow)
  std::uint64_t stale = 0;              // arrived more than kSequenceWindow below the highest seen
  std::uint64_t sequence_restarts = 0;  // sender restarts: number not above the highest with a later time, or
                                        // resync_poses consecutive numbers outside the plausibility window

  std::uint64_t connections = 0;          // TCP clients served
  std::uint64_t connections_refused = 0;  // TCP clients closed at once because one was connected
  std::uint64_t connections_idle_closed = 0;  // TCP clients closed after tcp_idle_timeout_ns of silence
  std::uint64_t connections_replaced = 0;     // idle TCP clients closed for a new client (tcp_takeover_idle_ns)

  std::uint64_t rejected() const noexcept;  // every rejection counter above (wire + admission + other_sender)
  // Datagrams that never arrived intact (exact when reordering stays within kSequenceWindow).
  std::uint64_t lost() const noexcept { return sequence_gaps - late; }
};

inline constexpr std::uint64_t kSequenceWindow = 1024;
// A forward sequence jump beyond this is not a loss but a discontinuity (a
// stray or a restarted sender): docs/pose-wire-format.md §3.2.
inline constexpr std::uint64_t kMaxSequenceJump = 1'000'000;
// Pose times beyond +-2^62 ns (+-146 years around the epoch) are refused:
// every sum of a pose time and a bounded offset then stays inside int64.
inline constexpr TimeNs kMaxPoseTimeNs = TimeNs{1} << 62;

struct PoseSourceOptions {
  std::string name;  // in messages and log lines; empty: a default like "udp 127.0.0.1:5005"
  Physics physics = Physics::flat;
  std::size_t queue_capacity = 1024;
  // Relative rotation between consecutive accepted poses at or above which a
  // pose is rejected (attitude_step): the interpolation's own limit, where
  // the geodesic between two knots stops being unique (core/interpolation.hpp).
  double max_attitude_step_rad = std::numbers::pi - interp::kAntipodalMarginRad;
  // The smoother's chart rule (core/pipeline.hpp kMaxChartAngleRad, checked by
  // StreamPipeline::push for knots within one smoothing half-window): a pose
  // rotated more than this from the last accepted one is a glitch (chart_span).
  double max_chart_angle_rad = kMaxChartAngleRad;
  // Live time resynchronisation (docs/streaming.md "Live time"): a pose more
  // than max_time_step_ns away (either way) from the last accepted one is a
  // time jump; resync_poses consecutive consistent poses (each 0 < step <=
  // max_time_step_ns after the previous, attitude rules met) are needed to
  // acquire a stream at the start and to re-acquire it after a jump. The
  // default step equals the smoother's default gap limit (max_gap_s = 10 s).
  TimeNs max_time_step_ns = 10 * kNsPerSecond;
  std::size_t resync_poses = 2;
  // The engine's gap limit (the scene's smoothing.max_gap_s; StreamPipeline
  // with gap_policy split starts a new segment after a longer knot interval).
  // A re-acquired stream is placed just beyond it after the last accepted
  // pose (or later, if more real time elapsed), so the smoother never
  // interpolates across the discontinuity and output resumes about this long
  // after a sender restart, not max_time_step_ns later.
  TimeNs max_gap_ns = 10 * kNsPerSecond;
  // MAVLink sources: the one sender taken (issue 26 N4; docs/pose-wire-format.md
  // §4.5). Empty: the first intact HIL_STATE_QUATERNION's system (component);
  // either may be set alone. Other senders' packets count other_sender.
  std::optional<std::uint8_t> mavlink_system_id, mavlink_component_id;
  // Receives each log line (without '\n'); empty: written to stderr.
  std::function<void(std::string_view)> log;
  // At most one log line per rejection reason per interval; the next line
  // says how many were suppressed.
  TimeNs log_interval_ns = kNsPerSecond;
};

class PoseAdmission;

// One live pose source. start() launches its thread; stop() (also in the
// destructor) ends it. Counters and the queue may be used from any thread.
class PoseSource {
 public:
  virtual ~PoseSource();
  PoseSource(const PoseSource&) = delete;
  PoseSource& operator=(const PoseSource&) = delete;

  void start();  // once
  void stop();   // idempotent; joins the thread, then logs suppressed counts
  // After start(): runs the source's thread under SCHED_FIFO at this
  // priority (1..99), so a pose is read and queued when it arrives however
  // busy the host (issue 17). "" when granted, else why not (the thread
  // keeps its scheduling).
  std::string set_realtime_priority(int priority);

  PoseQueue& queue() noexcept { return queue_; }
  PoseSourceCounters counters() const;
  const std::string& name() const noexcept { return name_; }
  // The input ended (file, stdin: end of input or a read error) and every
  // accepted pose is in the queue; nothing more will come.
  bool finished() const noexcept { return finished_.load(std::memory_order_acquire); }
  // The source's thread ended with an exception (caught there: it never
  // leaves the thread): what it said; empty otherwise. finished() is then true.
  std::string failure() const;
  // The bound port (UDP, TCP; useful with port 0), 0 for the others.
  virtual std::uint16_t local_port() const noexcept { return 0; }

 protected:
  explicit PoseSource(PoseSourceOptions options);

  virtual void run() = 0;   // the source's thread body; returns when stopping or at end of input
  virtual void wake() = 0;  // makes run() notice stop_requested() promptly

  bool stop_requested() const noexcept { return stop_requested_.load(std::memory_order_acquire); }
  // The consumer waiting on the queue is woken too: it sees the end at once.
  void mark_finished() noexcept;
  // Blocking push for sources that apply backpressure from their own thread
  // (file, stdin): counts one backpressure event per stall. False if stopping.
  bool push_with_backpressure(const SourcedPose& item);
  // Sleeps until CLOCK_MONOTONIC reaches due_ns; false if stopping.
  bool sleep_until(TimeNs due_ns);
  void notify_sleepers();
  void set_name(std::string name);  // before start()

  std::string name_;
  PoseQueue queue_;
  std::unique_ptr<PoseAdmission> admission_;

 private:
  std::thread thread_;
  std::atomic<bool> stop_requested_{false};
  std::atomic<bool> finished_{false};
  std::atomic<bool> failed_{false};
  mutable std::mutex failure_mutex_;
  std::string failure_;
  std::function<void(std::string_view)> log_;
  std::mutex sleep_mutex_;
  std::condition_variable sleep_cv_;
};

// Replays a trajectory CSV file (docs/trajectory-format.md). The whole file is
// read and validated first: a bad file throws TrajectoryFormatError from the
// factory, as does a file whose records have no meaning in the scene.
struct FileReplayOptions {
  // Records are released at first_release + (t - t_first) / speed (CLOCK_MONOTONIC);
  // a finite speed > 0. A release that falls behind (backpressure) is not
  // caught up by bursting: the next records keep their own due times.
  double speed = 1.0;
  bool as_fast_as_possible = false;  // ignore speed; only backpressure paces
};
std::unique_ptr<PoseSource> make_file_replay_source(const std::string& path, const FileReplayOptions& replay,
                                                    PoseSourceOptions options);

struct NetEndpoint {
  std::string address = "0.0.0.0";  // IPv4 or IPv6 literal to bind
  std::uint16_t port = 0;           // 0: an ephemeral port (see local_port())
  int receive_buffer_bytes = 0;     // SO_RCVBUF for UDP; 0 keeps the system default
  // TCP only (the one-client slot, issue 13 H1). A client from which nothing
  // arrived for tcp_idle_timeout_ns while the source waited for its bytes is
  // closed (connections_idle_closed); 0 never closes a silent client. A
  // backpressure stall (the source not reading) is not idleness.
  TimeNs tcp_idle_timeout_ns = 5 * kNsPerSecond;
  // A new client replaces the connected one when the connected one has been
  // idle (as above) for at least this long (connections_replaced), and is
  // refused otherwise: a sender streaming at >= 1 Hz keeps its slot, while a
  // sender reconnecting after its old connection went half-open (peer gone
  // without a FIN, so nothing more arrives on it) gets the slot back within
  // this time instead of waiting for the idle timeout or forever.
  TimeNs tcp_takeover_idle_ns = kNsPerSecond;
  // SO_KEEPALIVE with probes after 2 s of silence, every 1 s, 3 unanswered:
  // a peer that vanished is detected in ~5 s even with the idle timeout off.
  bool tcp_keepalive = true;
};
// Pose datagrams v1 (docs/pose-wire-format.md §2) on a bound UDP socket. A
// burst beyond the queue drops the oldest queued pose (overflow_dropped):
// the freshest poses matter most to a live stream. Throws std::runtime_error
// if the address cannot be bound.
std::unique_ptr<PoseSource> make_udp_pose_source(const NetEndpoint& endpoint, PoseSourceOptions options);
// MAVLink 2 HIL_STATE_QUATERNION datagrams (docs/pose-wire-format.md §4),
// otherwise as make_udp_pose_source: the simulator bridges' own message.
std::unique_ptr<PoseSource> make_mavlink_udp_pose_source(const NetEndpoint& endpoint, PoseSourceOptions options);
// Pose lines (docs/pose-wire-format.md §1) from one TCP client at a time;
// other clients are closed at once while one is connected and active (see
// NetEndpoint::tcp_takeover_idle_ns for when a new client replaces it, and
// tcp_idle_timeout_ns for when a silent one is closed). While the queue is
// full the source stops reading, so TCP flow control slows the sender.
std::unique_ptr<PoseSource> make_tcp_pose_source(const NetEndpoint& endpoint, PoseSourceOptions options);
// Pose lines from a file descriptor (stdin: 0; a pipe, a tty or a regular
// file), not owned. Backpressure as for TCP. finished() at end of input
// (or a read error, which is logged).
std::unique_ptr<PoseSource> make_fd_pose_source(int fd, PoseSourceOptions options);

}  // namespace imuemu::io
