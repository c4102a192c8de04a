#include "io/pose_admission.hpp"

#include <algorithm>
#include <cstdio>
#include <utility>

#include "core/so3.hpp"
#include "io/decimal_time.hpp"

namespace imuemu::io {

// ---------------------------------------------------------------- sequence numbers

void SequenceTracker::begin(std::uint64_t sequence, TimeNs t_ns) noexcept {
  started_ = true;
  highest_ = sequence;
  highest_t_ns_ = t_ns;
  // Nothing below the start was ever counted as a gap, so nothing below it
  // may count as late: the whole window starts out "seen".
  seen_.set();
}

SequenceTracker::Arrival SequenceTracker::observe(std::uint64_t s, TimeNs t_ns) noexcept {
  if (!started_) {
    begin(s, t_ns);
    return Arrival::first;
  }
  if (s > highest_) {
    const std::uint64_t skipped = s - highest_ - 1;
    gaps_ += skipped;
    // The numbers entering the window (highest, s] are unseen, except s.
    if (skipped + 1 >= kSequenceWindow) {
      seen_.reset();
    } else {
      for (std::uint64_t k = highest_ + 1; k < s; ++k) seen_.reset(k % kSequenceWindow);
    }
    seen_.set(s % kSequenceWindow);
    highest_ = s;
    highest_t_ns_ = t_ns;
    return skipped == 0 ? Arrival::next : Arrival::jump;
  }
  // Not above the highest. A sender's times grow with its numbers, so a later
  // time means the sender started counting again (docs/pose-wire-format.md §3.2).
  if (t_ns > highest_t_ns_) {
    ++restarts_;
    begin(s, t_ns);
    return Arrival::restart;
  }
  if (highest_ - s >= kSequenceWindow) {
    ++stale_;
    return Arrival::stale;
  }
  if (seen_.test(s % kSequenceWindow)) return Arrival::repeat;
  seen_.set(s % kSequenceWindow);
  ++late_;
  return Arrival::late;
}

// ---------------------------------------------------------------- logging

RateLimitedLog::RateLimitedLog(std::function<void(std::string_view)> sink, TimeNs interval_ns)
    : sink_(std::move(sink)), interval_ns_(interval_ns) {}

void RateLimitedLog::emit(std::string_view line) {
  if (sink_) {
    sink_(line);
  } else {
    std::fprintf(stderr, "%.*s\n", static_cast<int>(line.size()), line.data());
  }
}

void RateLimitedLog::log(std::string_view key, std::string_view message, TimeNs now_ns) {
  auto it = keys_.find(key);
  if (it == keys_.end()) {
    it = keys_.emplace(std::string(key), KeyState{}).first;
  } else if (now_ns - it->second.last_ns < interval_ns_) {
    ++it->second.suppressed;
    return;
  }
  KeyState& state = it->second;
  std::string line(message);
  if (state.suppressed != 0) {
    line += " [" + std::to_string(state.suppressed) + " more '" + std::string(key) + "' suppressed]";
  }
  state.last_ns = now_ns;
  state.suppressed = 0;
  emit(line);
}

void RateLimitedLog::flush() {
  for (auto& [key, state] : keys_) {
    if (state.suppressed == 0) continue;
    emit(std::to_string(state.suppressed) + " more '" + key + "' suppressed");
    state.suppressed = 0;
  }
}

// ---------------------------------------------------------------- line framing

void LineFramer::append(const char* data, std::size_t size) {
  // Drop what was read; what is left is at most one partial line.
  if (pos_ != 0) {
    buffer_.erase(0, pos_);
    pos_ = 0;
  }
  buffer_.append(data, size);
}

LineFramer::Next LineFramer::next(std::string_view& line) {
  const std::size_t newline = buffer_.find('\n', pos_);
  if (discarding_) {
    if (newline == std::string::npos) {
      buffer_.clear();
      pos_ = 0;
      return Next::none;
    }
    discarding_ = false;
    pos_ = newline + 1;
    // Fall through to look for the following line.
    return next(line);
  }
  if (newline == std::string::npos) {
    if (buffer_.size() - pos_ > kMaxPoseLineBytes) {
      discarding_ = true;
      buffer_.clear();
      pos_ = 0;
      return Next::too_long;
    }
    return Next::none;
  }
  const std::size_t length = newline - pos_;
  const std::size_t begin = pos_;
  pos_ = newline + 1;
  if (length > kMaxPoseLineBytes) return Next::too_long;
  line = std::string_view(buffer_).substr(begin, length);
  return Next::line;
}

bool LineFramer::finish() {
  const bool unterminated = !discarding_ && buffer_.size() > pos_;
  reset();
  return unterminated;
}

void LineFramer::reset() {
  buffer_.clear();
  pos_ = 0;
  discarding_ = false;
}

// ---------------------------------------------------------------- admission

PoseAdmission::PoseAdmission(const PoseSourceOptions& options)
    : name_(options.name),
      max_attitude_step_rad_(options.max_attitude_step_rad),
      converter_(options.physics),
      log_(options.log, options.log_interval_ns) {}

void PoseAdmission::log(std::string_view key, std::string_view message) {
  std::string line = name_;
  line += ": ";
  line += message;
  log_.log(key, line, monotonic_now_ns());
}

void PoseAdmission::reject(Slot slot, std::string_view key, const std::string& message) {
  add(slot);
  log(key, "dropped (" + std::string(key) + "): " + message);
}

void PoseAdmission::reject_line(LineError reason, std::string_view message) {
  add(kLineErrorsFirst + static_cast<std::size_t>(reason));
  log(to_string(reason), "dropped line (" + std::string(to_string(reason)) + "): " + std::string(message));
}

void PoseAdmission::reject_datagram(DatagramError reason, std::string_view message) {
  add(kDatagramErrorsFirst + static_cast<std::size_t>(reason));
  log(to_string(reason), "dropped datagram (" + std::string(to_string(reason)) + "): " + std::string(message));
}

void PoseAdmission::observe_sequence(std::uint64_t sequence, TimeNs t_ns) {
  const std::uint64_t highest_before = sequence_.highest();
  const SequenceTracker::Arrival arrival = sequence_.observe(sequence, t_ns);
  counters_[kSequenceGaps].store(sequence_.gaps(), std::memory_order_relaxed);
  counters_[kLate].store(sequence_.late(), std::memory_order_relaxed);
  counters_[kStale].store(sequence_.stale(), std::memory_order_relaxed);
  counters_[kSequenceRestarts].store(sequence_.restarts(), std::memory_order_relaxed);
  if (arrival == SequenceTracker::Arrival::jump) {
    log("sequence_gap", std::to_string(sequence - highest_before - 1) + " datagram(s) missing before sequence " +
                            std::to_string(sequence));
  } else if (arrival == SequenceTracker::Arrival::restart) {
    log("sequence_restart", "sender restarted: sequence " + std::to_string(sequence) + " after " +
                                std::to_string(highest_before) + " with a later time");
  }
}

bool PoseAdmission::receive_datagram(std::span<const std::uint8_t> bytes, TimeNs receive_ns, std::string_view from,
                                     SourcedPose& out) {
  received();
  PoseDatagram datagram;
  DatagramDecodeError error;
  if (!decode_pose_datagram(bytes, datagram, error)) {
    // An intact datagram arrived even if its values are refused: it is not
    // lost (docs/pose-wire-format.md §3.2).
    if (error.intact) observe_sequence(datagram.sequence, datagram.record.t_ns);
    reject_datagram(error.reason, "from " + std::string(from) + ": " + error.message);
    return false;
  }
  observe_sequence(datagram.sequence, datagram.record.t_ns);
  return admit(datagram.record, datagram.sequence, receive_ns, out);
}

namespace {

std::string where(std::size_t line, std::optional<std::uint64_t> sequence) {
  if (sequence) return "sequence " + std::to_string(*sequence);
  return "line " + std::to_string(line);
}

}  // namespace

bool PoseAdmission::admit(const TrajectoryRecord& record, std::optional<std::uint64_t> sequence, TimeNs receive_ns,
                          SourcedPose& out) {
  // Ordering first: a late or repeated pose is dropped before any work on it.
  if (last_accepted_ && record.t_ns <= last_accepted_->t_ns) {
    const bool equal = record.t_ns == last_accepted_->t_ns;
    reject(equal ? kDuplicate : kOutOfOrder, equal ? "duplicate" : "out_of_order",
           where(record.line, sequence) + ": time " + format_decimal_seconds(record.t_ns) + " s is " +
               (equal ? "equal to" : "before") + " the last accepted pose's " +
               format_decimal_seconds(last_accepted_->t_ns) + " s");
    return false;
  }
  Pose pose;
  try {
    pose = converter_.convert(record, name_);
  } catch (const TrajectoryFormatError& e) {
    reject(kSceneRefused, "scene_refused", e.what());
    return false;
  }
  // Finite inputs can still overflow (an ECEF coordinate near 1e308 moved
  // to the tangent frame): the engine must never see a non-finite pose.
  if (!pose.position_m.allFinite() || !pose.attitude.allFinite()) {
    reject(kSceneRefused, "scene_refused", where(record.line, sequence) + ": the pose is not finite in the scene frame");
    return false;
  }
  if (last_accepted_) {
    // The interpolation needs a unique geodesic between consecutive knots
    // (thesis §3.6.1: Tr(R_{i-1}^T R_i) != -1); core/interpolation refuses
    // the same steps, so refusing them here keeps the stream going.
    const double step_rad = so3::angle(last_accepted_->attitude.transpose() * pose.attitude);
    if (!(step_rad < max_attitude_step_rad_)) {
      reject(kAttitudeStep, "attitude_step",
             where(record.line, sequence) + ": attitude step of " + detail::format_double(step_rad) +
                 " rad from the last accepted pose is not below " + detail::format_double(max_attitude_step_rad_) +
                 " rad (not representable at the knot rate)");
      return false;
    }
  }
  last_accepted_ = pose;
  out.pose = pose;
  out.sequence = sequence;
  out.receive_ns = receive_ns;
  out.line = record.line;
  add(kAccepted);
  return true;
}

PoseSourceCounters PoseAdmission::counters() const noexcept {
  auto get = [this](std::size_t slot) { return counters_[slot].load(std::memory_order_relaxed); };
  PoseSourceCounters c;
  c.received = get(kReceived);
  c.ignored = get(kIgnored);
  c.accepted = get(kAccepted);
  for (std::size_t i = 0; i < kLineErrorCount; ++i) c.line_errors[i] = get(kLineErrorsFirst + i);
  for (std::size_t i = 0; i < kDatagramErrorCount; ++i) c.datagram_errors[i] = get(kDatagramErrorsFirst + i);
  c.scene_refused = get(kSceneRefused);
  c.duplicate = get(kDuplicate);
  c.out_of_order = get(kOutOfOrder);
  c.attitude_step = get(kAttitudeStep);
  c.overflow_dropped = get(kOverflowDropped);
  c.backpressure_events = get(kBackpressureEvents);
  c.sequence_gaps = get(kSequenceGaps);
  c.late = get(kLate);
  c.stale = get(kStale);
  c.sequence_restarts = get(kSequenceRestarts);
  c.connections = get(kConnections);
  c.connections_refused = get(kConnectionsRefused);
  return c;
}

// ---------------------------------------------------------------- line streams

PoseLineStream::PoseLineStream(PoseAdmission& admission, std::string stream_name)
    : admission_(admission), stream_name_(stream_name), decoder_(std::move(stream_name)) {}

void PoseLineStream::append(const char* data, std::size_t size, TimeNs receive_ns) {
  framer_.append(data, size);
  receive_ns_ = receive_ns;
}

bool PoseLineStream::next(SourcedPose& out) {
  TrajectoryRecord record;
  LineError error = LineError::bad_record;
  std::string message;
  std::string_view line;
  for (;;) {
    switch (framer_.next(line)) {
      case LineFramer::Next::none: return false;
      case LineFramer::Next::too_long:
        admission_.received();
        decoder_.skip_line();
        admission_.reject_line(LineError::line_too_long, stream_name_ + ":" +
                                                             std::to_string(decoder_.line_number()) +
                                                             ": line longer than " +
                                                             std::to_string(kMaxPoseLineBytes) + " bytes");
        continue;
      case LineFramer::Next::line: break;
    }
    admission_.received();
    switch (decoder_.decode(line, record, error, message)) {
      case PoseLineDecoder::Outcome::ignored: admission_.ignored(); continue;
      case PoseLineDecoder::Outcome::error: admission_.reject_line(error, message); continue;
      case PoseLineDecoder::Outcome::record:
        if (admission_.admit(record, std::nullopt, receive_ns_, out)) return true;
        continue;
    }
  }
}

void PoseLineStream::finish() {
  if (framer_.finish()) {
    admission_.received();
    admission_.reject_line(LineError::unterminated_line,
                           stream_name_ + ":" + std::to_string(decoder_.line_number() + 1) +
                               ": the stream ended inside this line (no final newline); a partial record is not used");
  }
}

}  // namespace imuemu::io
