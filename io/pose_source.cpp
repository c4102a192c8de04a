// The parts every pose source shares: the hand-off queue, the thread, the
// counters, pacing and backpressure; and the file replay source.
#include "io/pose_source.hpp"

#include <pthread.h>
#include <sched.h>
#include <time.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <utility>

#include "io/pose_admission.hpp"
#include "io/scene_poses.hpp"

namespace imuemu::io {

TimeNs monotonic_now_ns() noexcept {
  timespec ts{};
  ::clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<TimeNs>(ts.tv_sec) * kNsPerSecond + ts.tv_nsec;
}

// ---------------------------------------------------------------- queue

PoseQueue::PoseQueue(std::size_t capacity) : ring_(capacity == 0 ? 1 : capacity) {}

bool PoseQueue::try_push(const SourcedPose& item) {
  {
    const std::lock_guard lock(mutex_);
    if (count_ == ring_.size()) return false;
    ring_[(head_ + count_) % ring_.size()] = item;
    ++count_;
  }
  // Outside the lock: the woken consumer does not block on it at once. No
  // waiter: a few loads, no system call (glibc's condition variable).
  items_.notify_one();
  return true;
}

bool PoseQueue::push_or_drop_oldest(const SourcedPose& item) {
  bool drop = false;
  {
    const std::lock_guard lock(mutex_);
    drop = count_ == ring_.size();
    if (drop) {
      head_ = (head_ + 1) % ring_.size();
      --count_;
    }
    ring_[(head_ + count_) % ring_.size()] = item;
    ++count_;
  }
  items_.notify_one();
  return drop;
}

bool PoseQueue::wait_for_items_until(TimeNs deadline_ns) {
  // steady_clock is CLOCK_MONOTONIC in libstdc++ (monotonic_now_ns's clock),
  // and wait_until on it sleeps on that clock (pthread_cond_clockwait).
  const std::chrono::steady_clock::time_point deadline{std::chrono::nanoseconds(deadline_ns)};
  std::unique_lock lock(mutex_);
  wake_requested_ = wake_requested_ && count_ == 0;  // the caller looks at its state after any return
  if (count_ != 0) {
    ++waits_.items_on_entry;
    return true;
  }
  items_.wait_until(lock, deadline, [this] { return count_ != 0 || wake_requested_; });
  const bool items = count_ != 0;
  if (items && std::chrono::steady_clock::now() < deadline) ++waits_.woken_by_push;
  else if (!items && wake_requested_) ++waits_.woken;
  else ++waits_.deadline;
  wake_requested_ = false;
  return items;
}

void PoseQueue::wake_consumer() {
  {
    const std::lock_guard lock(mutex_);
    wake_requested_ = true;
  }
  items_.notify_all();
}

PoseQueue::WaitCounters PoseQueue::wait_counters() const {
  const std::lock_guard lock(mutex_);
  return waits_;
}

bool PoseQueue::wait_for_space(std::chrono::nanoseconds timeout) {
  std::unique_lock lock(mutex_);
  return space_.wait_for(lock, timeout, [this] { return count_ < ring_.size(); });
}

bool PoseQueue::try_pop(SourcedPose& out) {
  {
    const std::lock_guard lock(mutex_);
    if (count_ == 0) return false;
    out = ring_[head_];
    head_ = (head_ + 1) % ring_.size();
    --count_;
  }
  popped_.fetch_add(1, std::memory_order_relaxed);
  space_.notify_one();
  return true;
}

std::size_t PoseQueue::drain(std::vector<SourcedPose>& out, std::size_t max_items) {
  std::size_t n = 0;
  {
    const std::lock_guard lock(mutex_);
    n = std::min(count_, max_items);
    for (std::size_t k = 0; k < n; ++k) {
      out.push_back(ring_[head_]);
      head_ = (head_ + 1) % ring_.size();
    }
    count_ -= n;
  }
  if (n != 0) {
    popped_.fetch_add(n, std::memory_order_relaxed);
    space_.notify_one();
  }
  return n;
}

std::size_t PoseQueue::size() const {
  const std::lock_guard lock(mutex_);
  return count_;
}

// ---------------------------------------------------------------- counters

std::uint64_t PoseSourceCounters::rejected() const noexcept {
  return std::accumulate(line_errors.begin(), line_errors.end(), std::uint64_t{0}) +
         std::accumulate(datagram_errors.begin(), datagram_errors.end(), std::uint64_t{0}) + scene_refused +
         duplicate + out_of_order + attitude_step + chart_span + time_out_of_range + time_jump + other_sender;
}

// ---------------------------------------------------------------- source base

PoseSource::PoseSource(PoseSourceOptions options)
    : name_(options.name),
      queue_(options.queue_capacity),
      admission_(std::make_unique<PoseAdmission>(options)),
      log_(options.log) {}

PoseSource::~PoseSource() {
  // Derived destructors stop first (run() uses their members); this only
  // covers a source that was never started.
  stop();
}

void PoseSource::start() {
  if (thread_.joinable()) throw std::logic_error(name_ + ": pose source started twice");
  thread_ = std::thread([this] {
    // No exception leaves the thread (std::terminate would abort the
    // process): the source ends, says why, and its consumer sees failure().
    std::string what;
    try {
      run();
      return;
    } catch (const std::exception& e) {
      what = e.what();
    } catch (...) {
      what = "unknown exception";
    }
    try {
      {
        std::lock_guard lock(failure_mutex_);
        failure_ = what;
      }
      const std::string line = name_ + ": stopped by an error: " + what;
      if (log_) log_(line);
      else std::fprintf(stderr, "%s\n", line.c_str());
    } catch (...) {
    }
    failed_.store(true, std::memory_order_release);
    mark_finished();
  });
}

void PoseSource::mark_finished() noexcept {
  finished_.store(true, std::memory_order_release);
  try {
    queue_.wake_consumer();
  } catch (...) {  // std::system_error from the mutex: the consumer's own deadline still comes
  }
}

std::string PoseSource::set_realtime_priority(int priority) {
  if (!thread_.joinable()) return "the source is not started";
  sched_param sp{};
  sp.sched_priority = priority;
  const int rc = pthread_setschedparam(thread_.native_handle(), SCHED_FIFO, &sp);
  return rc == 0 ? std::string() : std::string(std::strerror(rc));
}

std::string PoseSource::failure() const {
  if (!failed_.load(std::memory_order_acquire)) return {};
  std::lock_guard lock(failure_mutex_);
  return failure_.empty() ? std::string("unknown error") : failure_;
}

void PoseSource::stop() {
  stop_requested_.store(true, std::memory_order_release);
  if (thread_.joinable()) {
    wake();
    notify_sleepers();
    thread_.join();
    admission_->flush_log();
  }
}

void PoseSource::set_name(std::string name) {
  admission_->set_name(name);
  name_ = std::move(name);
}

PoseSourceCounters PoseSource::counters() const { return admission_->counters(); }

bool PoseSource::push_with_backpressure(const SourcedPose& item) {
  if (queue_.try_push(item)) return true;
  admission_->backpressure_event();
  // The consumer notifies on every pop; the timeout only bounds how long a
  // stop request can go unnoticed.
  while (!stop_requested()) {
    if (queue_.wait_for_space(std::chrono::milliseconds(20)) && queue_.try_push(item)) return true;
  }
  return false;
}

bool PoseSource::sleep_until(TimeNs due_ns) {
  std::unique_lock lock(sleep_mutex_);
  for (;;) {
    if (stop_requested()) return false;
    const TimeNs now_ns = monotonic_now_ns();
    if (now_ns >= due_ns) return true;
    sleep_cv_.wait_for(lock, std::chrono::nanoseconds(due_ns - now_ns));
  }
}

void PoseSource::notify_sleepers() {
  { const std::lock_guard lock(sleep_mutex_); }
  sleep_cv_.notify_all();
}

// ---------------------------------------------------------------- file replay

namespace {

class FileReplaySource final : public PoseSource {
 public:
  FileReplaySource(Trajectory trajectory, const FileReplayOptions& replay, PoseSourceOptions options)
      : PoseSource(std::move(options)), trajectory_(std::move(trajectory)), replay_(replay) {}
  ~FileReplaySource() override { stop(); }

 private:
  void run() override {
    const TimeNs start_ns = monotonic_now_ns();
    const TimeNs first_t_ns = trajectory_.records.front().t_ns;
    for (const TrajectoryRecord& record : trajectory_.records) {
      if (!replay_.as_fast_as_possible) {
        // Exact int64 difference (times increase, so it fits in uint64),
        // scaled in double: pacing needs no nanosecond exactness.
        const auto offset_ns = static_cast<double>(static_cast<std::uint64_t>(record.t_ns) -
                                                   static_cast<std::uint64_t>(first_t_ns)) /
                               replay_.speed;
        const double kMaxOffsetNs = 1e18;  // ~31 years: keeps the sum within int64
        if (!sleep_until(start_ns + static_cast<TimeNs>(std::min(offset_ns, kMaxOffsetNs)))) return;
      } else if (stop_requested()) {
        return;
      }
      admission_->received();
      SourcedPose pose;
      if (admission_->admit(record, std::nullopt, monotonic_now_ns(), pose) && !push_with_backpressure(pose)) return;
    }
    admission_->log("end", "end of file: " + std::to_string(trajectory_.records.size()) + " records replayed");
    mark_finished();
  }
  void wake() override {}  // sleep_until and push_with_backpressure watch the stop flag

  Trajectory trajectory_;
  FileReplayOptions replay_;
};

}  // namespace

std::unique_ptr<PoseSource> make_file_replay_source(const std::string& path, const FileReplayOptions& replay,
                                                    PoseSourceOptions options) {
  if (!replay.as_fast_as_possible && !(std::isfinite(replay.speed) && replay.speed > 0.0)) {
    throw std::invalid_argument("file replay of " + path + ": speed must be a finite number > 0, got " +
                                detail::format_double(replay.speed));
  }
  if (options.name.empty()) options.name = path;
  // A validated file has one timeline (strictly increasing times, checked
  // above): no live-time acquisition or resynchronisation, its gaps are its own.
  options.resync_poses = 1;
  options.max_time_step_ns = std::numeric_limits<TimeNs>::max();
  Trajectory trajectory = read_trajectory_csv(path);
  // Every record of a file has the same kinds, so if the first has a meaning
  // in the scene, all have: refuse a mismatched file now, not record by record.
  ScenePoseConverter(options.physics).convert(trajectory.records.front(), path);
  return std::make_unique<FileReplaySource>(std::move(trajectory), replay, std::move(options));
}

}  // namespace imuemu::io
