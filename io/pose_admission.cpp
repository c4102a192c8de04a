#include "io/pose_admission.hpp"

#include <algorithm>
#include <utility>

#include "core/so3.hpp"
#include "core/time_arith.hpp"
#include "log/log.hpp"
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
  // Distances modulo 2^64: ahead = s - highest, behind = highest - s.
  const std::uint64_t ahead = s - highest_, behind = highest_ - s;
  if (ahead != 0 && ahead <= kMaxSequenceJump) {
    candidate_run_ = 0;
    const std::uint64_t skipped = ahead - 1;
    gaps_ += skipped;
    // The numbers entering the window (highest, s] are unseen, except s.
    if (skipped + 1 >= kSequenceWindow) {
      seen_.reset();
    } else {
      for (std::uint64_t k = 1; k < ahead; ++k) seen_.reset((highest_ + k) % kSequenceWindow);
    }
    seen_.set(s % kSequenceWindow);
    highest_ = s;
    highest_t_ns_ = t_ns;
    return skipped == 0 ? Arrival::next : Arrival::jump;
  }
  if (behind < kSequenceWindow) {
    // Not above the highest. A sender's times grow with its numbers, so a
    // later time means the sender started counting again
    // (docs/pose-wire-format.md §3.2).
    if (!(t_ns > highest_t_ns_)) {
      candidate_run_ = 0;
        if (seen_.test(s % kSequenceWindow)) return Arrival::repeat;
      seen_.set(s % kSequenceWindow);
      ++late_;
      return Arrival::late;
    }
  }
  // Outside the plausibility window, or not above the highest with a later
  // time: one stray number (2^64 - 1, or one from another sender) must not
  // count 1.8e19 losses nor move the stream; a run of confirm_run
  // consecutive such numbers is a restarted sender.
  candidate_run_ = candidate_run_ > 0 && s == candidate_ + 1 ? candidate_run_ + 1 : 1;
  candidate_ = s;
  if (candidate_run_ >= confirm_run_) {
    stale_ -= candidate_run_ - 1;  // counted stale while unconfirmed: they were the restart's first numbers
    ++restarts_;
    candidate_run_ = 0;
    begin(s, t_ns);
    return Arrival::restart;
  }
  ++stale_;
  return Arrival::stale;
}

// ---------------------------------------------------------------- logging

RateLimitedLog::RateLimitedLog(std::function<void(std::string_view)> sink, TimeNs interval_ns)
    : sink_(std::move(sink)), interval_ns_(interval_ns) {}

void RateLimitedLog::emit(std::string_view line) {
  if (sink_) {
    sink_(line);
  } else {
    // No sink: the project's log line (sd-daemon priority prefix, one write(2),
    // bounded): a refused pose is a warning in a daemon's journal.
    service::log_warning(line);
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
      sequence_(options.resync_poses),
      log_(options.log, options.log_interval_ns),
      max_chart_angle_rad_(options.max_chart_angle_rad),
      max_time_step_ns_(std::max<TimeNs>(1, options.max_time_step_ns)),
      max_gap_ns_(std::max<TimeNs>(0, options.max_gap_ns)),
      resync_poses_(std::max<std::size_t>(1, options.resync_poses)),
      mavlink_sender_(options.mavlink_system_id, options.mavlink_component_id) {}

void PoseAdmission::publish() noexcept {
  const std::lock_guard lock(published_mutex_);
  published_ = counting_;
}

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
  const Unit unit(*this);
  add(kLineErrorsFirst + static_cast<std::size_t>(reason));
  log(to_string(reason), "dropped line (" + std::string(to_string(reason)) + "): " + std::string(message));
}

void PoseAdmission::reject_datagram(DatagramError reason, std::string_view message) {
  const Unit unit(*this);
  add(kDatagramErrorsFirst + static_cast<std::size_t>(reason));
  log(to_string(reason), "dropped datagram (" + std::string(to_string(reason)) + "): " + std::string(message));
}

void PoseAdmission::observe_sequence(std::uint64_t sequence, TimeNs t_ns) {
  const std::uint64_t highest_before = sequence_.highest();
  const SequenceTracker::Arrival arrival = sequence_.observe(sequence, t_ns);
  set(kSequenceGaps, sequence_.gaps());
  set(kLate, sequence_.late());
  set(kStale, sequence_.stale());
  set(kSequenceRestarts, sequence_.restarts());
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
  const Unit unit(*this);
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

bool PoseAdmission::receive_mavlink_datagram(std::span<const std::uint8_t> bytes, TimeNs receive_ns,
                                             std::string_view from, SourcedPose& out) {
  const Unit unit(*this);
  received();
  mavlink::HilStateQuaternion message;
  mavlink::PacketInfo info;
  DatagramDecodeError error;
  const mavlink::Outcome outcome = mavlink::decode_datagram(bytes, message, info, error);
  if (outcome == mavlink::Outcome::other) {
    ignored();  // HEARTBEAT, HIL_SENSOR, ... from the same bridge: not poses
    return false;
  }
  if (outcome == mavlink::Outcome::refused) {
    reject_datagram(error.reason, "from " + std::string(from) + ": " + error.message);
    return false;
  }
  // The checksum matched: the header is the sender's own. One vehicle per
  // source (mavlink::SenderFilter); another sender's packet is counted and
  // logged, and enters neither the stream nor its loss statistics.
  switch (mavlink_sender_.judge(info)) {
    case mavlink::SenderFilter::Verdict::taken: break;
    case mavlink::SenderFilter::Verdict::taken_now:
      log("mavlink_sender",
          "takes sysid " + std::to_string(info.system_id) + " compid " + std::to_string(info.component_id) + " (from " +
              std::string(from) +
              (mavlink_sender_.configured() ? ": the configured sender)"
                                            : ": the first HIL_STATE_QUATERNION sender; [trajectory] mavlink_system_id "
                                              "and mavlink_component_id choose one); other senders are not used"));
      break;
    case mavlink::SenderFilter::Verdict::other: other_sender(info, from); return false;
  }
  // The packet arrived intact and counts for the loss statistics even if its
  // values are refused.
  const std::uint64_t sequence = mavlink_sequences_.widen(info);
  TrajectoryRecord record;
  const bool valid = mavlink::to_record(message, record, error);
  observe_sequence(sequence, valid ? record.t_ns : 0);
  if (!valid) {
    reject_datagram(error.reason, "from " + std::string(from) + ": HIL_STATE_QUATERNION " + error.message);
    return false;
  }
  return admit(record, sequence, receive_ns, out);
}

void PoseAdmission::other_sender(const mavlink::PacketInfo& info, std::string_view from) {
  add(kOtherSender);
  // One log key per sender, so each is named at least once a second; the
  // first few only, so a flood of forged ids cannot grow the log's key map.
  constexpr std::size_t kNamedOtherSenders = 16;
  const auto id = static_cast<std::uint16_t>(std::uint16_t{info.system_id} << 8 | info.component_id);
  const std::string sender = "sysid " + std::to_string(info.system_id) + " compid " + std::to_string(info.component_id);
  const bool named = named_other_senders_.count(id) != 0 ||
                     (named_other_senders_.size() < kNamedOtherSenders && named_other_senders_.insert(id).second);
  std::string message = "dropped HIL_STATE_QUATERNION of another sender, " + sender + " from " + std::string(from) +
                        ": this source takes ";
  if (const auto& taken = mavlink_sender_.taken())
    message += "sysid " + std::to_string(taken->system_id) + " compid " + std::to_string(taken->component_id);
  else
    message += "the configured sender (none seen yet)";
  log(named ? "other_sender " + sender : std::string("other_sender"), message);
}

namespace {

std::string where(std::size_t line, std::optional<std::uint64_t> sequence) {
  if (sequence) return "sequence " + std::to_string(*sequence);
  return "line " + std::to_string(line);
}

}  // namespace

bool PoseAdmission::consistent(const Pose& from, const Pose& to) const {
  if (!(to.t_ns > from.t_ns) || ns_between(from.t_ns, to.t_ns) > static_cast<std::uint64_t>(max_time_step_ns_))
    return false;
  const double step_rad = so3::angle(from.attitude.transpose() * to.attitude);
  return step_rad < max_attitude_step_rad_ && !(step_rad > max_chart_angle_rad_);
}

// Candidates that never made a stream: strays.
void PoseAdmission::drop_candidates() {
  if (candidates_.empty()) return;
  add(kTimeJump, candidates_.size());
  set(kHeld, 0);
  candidates_.clear();
}

void PoseAdmission::release(const Pose& pose, std::optional<std::uint64_t> sequence, TimeNs receive_ns,
                            std::size_t line, const PoseRates& rates) {
  SourcedPose item;
  item.pose = pose;
  item.rates = rates;
  item.sequence = sequence;
  item.receive_ns = receive_ns;
  item.line = line;
  released_.push_back(item);
  last_accepted_ = pose;
  last_receive_ns_ = receive_ns;
  add(kAccepted);
}

// The candidates become the stream, shifted by offset_ns (a stream acquired
// at the start keeps its times: offset 0).
bool PoseAdmission::release_candidates(TimeNs offset_ns, SourcedPose& out) {
  for (const Candidate& c : candidates_) {
    if (!checked_add_ns(c.pose.t_ns, offset_ns)) {  // cannot happen within kMaxPoseTimeNs; refuse, never wrap
      drop_candidates();
      return false;
    }
  }
  offset_ns_ = offset_ns;
  locked_ = true;
  for (const Candidate& c : candidates_) {
    Pose p = c.pose;
    p.t_ns += offset_ns;
    release(p, c.sequence, c.receive_ns, c.line, c.rates);
  }
  last_sender_ns_ = candidates_.back().pose.t_ns;
  candidates_.clear();
  set(kHeld, 0);
  return take_released(out);
}

bool PoseAdmission::take_released(SourcedPose& out) {
  if (released_.empty()) return false;
  out = released_.front();
  released_.pop_front();
  return true;
}

bool PoseAdmission::admit(const TrajectoryRecord& record, std::optional<std::uint64_t> sequence, TimeNs receive_ns,
                          SourcedPose& out) {
  const Unit unit(*this);
  // A time the live path cannot map (time 0 is fine; INT64_MIN or near
  // INT64_MAX is not): refused before any work on it.
  if (record.t_ns > kMaxPoseTimeNs || record.t_ns < -kMaxPoseTimeNs) {
    reject(kTimeRange, "time_out_of_range",
           where(record.line, sequence) + ": time " + format_decimal_seconds(record.t_ns) +
               " s is outside +-2^62 ns (+-146 years around the epoch)");
    return false;
  }
  // Ordering within the stream first: a late or repeated pose is dropped
  // before any work on it. Beyond max_time_step_ns either way it is not
  // reordering but a jump of the sender's times (below).
  const bool near_stream = locked_ && ns_between(std::min(record.t_ns, last_sender_ns_),
                                                 std::max(record.t_ns, last_sender_ns_)) <=
                                          static_cast<std::uint64_t>(max_time_step_ns_);
  if (near_stream && record.t_ns <= last_sender_ns_) {
    const bool equal = record.t_ns == last_sender_ns_;
    reject(equal ? kDuplicate : kOutOfOrder, equal ? "duplicate" : "out_of_order",
           where(record.line, sequence) + ": time " + format_decimal_seconds(record.t_ns) + " s is " +
               (equal ? "equal to" : "before") + " the last accepted pose's " +
               format_decimal_seconds(last_sender_ns_) + " s");
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
  const PoseRates rates = converter_.convert_rates(record);
  const auto finite = [](const std::optional<Vec3>& v) { return !v || v->allFinite(); };
  if (!pose.position_m.allFinite() || !pose.attitude.allFinite() || !finite(rates.velocity_m_s) ||
      !finite(rates.angular_rate_rad_s) || !finite(rates.acceleration_m_s2)) {
    reject(kSceneRefused, "scene_refused", where(record.line, sequence) + ": the pose is not finite in the scene frame");
    return false;
  }
  if (near_stream) {
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
    // The smoother's chart rule (StreamPipeline::push): more rotation from
    // the previous knot than a smoothing chart holds is a glitch.
    if (step_rad > max_chart_angle_rad_) {
      reject(kChartSpan, "chart_span",
             where(record.line, sequence) + ": attitude step of " + detail::format_double(step_rad) +
                 " rad from the last accepted pose is more than a smoothing chart holds (" +
                 detail::format_double(max_chart_angle_rad_) + " rad): a glitch");
      return false;
    }
    drop_candidates();  // a stray that did not start a stream
    last_sender_ns_ = record.t_ns;
    Pose shifted = pose;
    shifted.t_ns += offset_ns_;  // |t| <= 2^62 and the offset is bounded the same way (release_candidates)
    release(shifted, sequence, receive_ns, record.line, rates);
    return take_released(out);
  }
  // Not part of the locked stream (or none yet): a candidate for a new one.
  Pose sender_pose = pose;
  sender_pose.t_ns = record.t_ns;
  if (!candidates_.empty() && !consistent(candidates_.back().pose, sender_pose)) drop_candidates();
  candidates_.push_back({sender_pose, sequence, receive_ns, record.line, rates});
  set(kHeld, candidates_.size());
  if (candidates_.size() < resync_poses_) {
    if (locked_)
      log("time_jump", where(record.line, sequence) + ": time " + format_decimal_seconds(record.t_ns) +
                           " s is more than " + format_decimal_seconds(max_time_step_ns_) +
                           " s from the stream's " + format_decimal_seconds(last_sender_ns_) +
                           " s: held until " + std::to_string(resync_poses_) + " consistent poses re-acquire it");
    return false;
  }
  if (!locked_) return release_candidates(0, out);  // acquired: the sender's own times
  // Re-acquisition: the new stream continues the output timeline where real
  // time says it should (the receive time elapsed since the last accepted
  // pose), and just beyond the engine's gap limit (max_gap_ns, the scene's
  // max_gap_s), so that the smoother starts a new segment instead of
  // interpolating across the discontinuity. Not max_time_step_ns: output
  // would then stay silent that long (10 s) after every sender restart.
  const TimeNs elapsed_ns = std::max<TimeNs>(saturating_sub_ns(candidates_.front().receive_ns, last_receive_ns_), 0);
  const TimeNs first_out_ns =
      saturating_add_ns(last_accepted_->t_ns, std::max(elapsed_ns, saturating_add_ns(max_gap_ns_, 1)));
  const std::optional<TimeNs> offset_ns = checked_sub_ns(first_out_ns, candidates_.front().pose.t_ns);
  const TimeNs from_ns = last_sender_ns_, to_ns = candidates_.front().pose.t_ns;
  if (!offset_ns) {
    drop_candidates();
    return false;
  }
  add(kResyncs);
  log("resync", "times jumped from " + format_decimal_seconds(from_ns) + " s to " + format_decimal_seconds(to_ns) +
                    " s (" + std::to_string(resync_poses_) + " consistent poses): stream re-acquired, its times "
                    "shifted by " + format_decimal_seconds(*offset_ns) + " s onto the running timeline");
  return release_candidates(*offset_ns, out);
}

PoseSourceCounters PoseAdmission::counters() const noexcept {
  std::array<std::uint64_t, kSlotCount> snapshot;
  {
    const std::lock_guard lock(published_mutex_);
    snapshot = published_;
  }
  auto get = [&snapshot](std::size_t slot) { return snapshot[slot]; };
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
  c.chart_span = get(kChartSpan);
  c.time_out_of_range = get(kTimeRange);
  c.time_jump = get(kTimeJump);
  c.other_sender = get(kOtherSender);
  c.held = get(kHeld);
  c.resyncs = get(kResyncs);
  c.overflow_dropped = get(kOverflowDropped);
  c.backpressure_events = get(kBackpressureEvents);
  c.sequence_gaps = get(kSequenceGaps);
  c.late = get(kLate);
  c.stale = get(kStale);
  c.sequence_restarts = get(kSequenceRestarts);
  c.connections = get(kConnections);
  c.connections_refused = get(kConnectionsRefused);
  c.connections_idle_closed = get(kConnectionsIdleClosed);
  c.connections_replaced = get(kConnectionsReplaced);
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
  if (admission_.take_released(out)) return true;  // held poses a (re-)acquisition released
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
