// The MAVLink component's command side (issue 27). Sources (read, nothing
// copied):
//  [G] MAVLink developer guide, "Packet Serialization": v1/v2 frames,
//      CRC_EXTRA, truncation, incompat flags.
//  [C] "Command Protocol" (mavlink.io/en/services/command.html): COMMAND_LONG
//      / COMMAND_INT answered by COMMAND_ACK; target 0 = broadcast.
//  [R] "Requesting messages" / "Message interval" (mavlink.io/en/mavgen_c/..,
//      services/message_interval.html): MAV_CMD_REQUEST_MESSAGE (512) is
//      ACKed, then the message is sent; MAV_CMD_SET_MESSAGE_INTERVAL (511)
//      param2 interval in us, -1 disables, 0 restores the default rate.
//  [P] "Parameter Protocol" (services/parameter.html): PARAM_REQUEST_LIST
//      -> a PARAM_VALUE per parameter with param_count and param_index;
//      PARAM_REQUEST_READ by id (param_index -1) or index; PARAM_SET on a
//      parameter that cannot be set -> PARAM_VALUE with the current value.
//  [X] common.xml: the messages' fields, MAV_CMD, MAV_RESULT (DENIED = "is
//      supported but has invalid parameters", UNSUPPORTED = "not supported").
#include "drivers/protocols/mavlink_device.hpp"

#include <algorithm>
#include <array>
#include <boost/crc.hpp>
#include <cmath>
#include <cstring>

#include "drivers/protocols/wire_bytes.hpp"

namespace imuemu::drivers::mavlink2 {

namespace {

using X25Engine = boost::crc_optimal<16, 0x1021, 0xFFFF, 0, true, true>;

}  // namespace

const MessageSpec* FrameParser::spec_of(std::uint32_t id) const {
  for (const MessageSpec* m : known_)
    if (m->id == id) return m;
  return nullptr;
}

void FrameParser::feed(std::span<const std::uint8_t> bytes, std::chrono::steady_clock::time_point now,
                       const std::function<void(const InboundPacket&)>& on_packet) {
  // A candidate left waiting by the previous call, too old: its first byte
  // is given up (the scan below restarts right after it).
  std::size_t pos = 0;
  const bool was_empty = buffer_.empty();
  if (!was_empty && now - candidate_since_ > kStaleAfter) {
    ++skipped_;
    pos = 1;
  }
  buffer_.insert(buffer_.end(), bytes.begin(), bytes.end());
  const std::size_t n = buffer_.size();
  std::array<std::uint8_t, 255> payload{};
  while (pos < n) {
    const std::uint8_t stx = buffer_[pos];
    if (stx != kMagic && stx != kMagicV1) {
      ++skipped_;
      ++pos;
      continue;
    }
    const bool v2 = stx == kMagic;
    const std::size_t header = v2 ? kHeaderBytes : kHeaderBytesV1;
    const std::size_t avail = n - pos;
    if (avail < header) break;  // wait for the rest of the header
    const std::uint8_t* c = buffer_.data() + pos;
    const std::size_t len = c[1];
    std::uint32_t msgid = 0;
    bool ok = true;
    std::size_t total = header + len + kChecksumBytes;
    if (v2) {
      // [G] an incompat flag we do not understand: the packet is dropped.
      if ((c[2] & ~kIncompatSigned) != 0) ok = false;
      if ((c[2] & kIncompatSigned) != 0) total += kSignatureBytes;
      msgid = std::uint32_t{c[7]} | std::uint32_t{c[8]} << 8 | std::uint32_t{c[9]} << 16;
    } else {
      msgid = c[5];
    }
    const MessageSpec* spec = ok ? spec_of(msgid) : nullptr;
    if (spec == nullptr) {  // cannot be checked: one byte, scan on
      ++skipped_;
      ++pos;
      continue;
    }
    if (avail < total) break;  // split across reads: wait
    X25Engine crc;
    crc.process_bytes(c + 1, header - 1 + len);
    crc.process_byte(spec->crc_extra);
    if (crc.checksum() != wire::get_le<std::uint16_t>(c + header + len)) {
      ++skipped_;
      ++pos;
      continue;
    }
    // [G] truncated trailing zeros: zero-extend; longer than known: newer
    // extensions, ignored.
    payload.fill(0);
    std::copy_n(c + header, std::min<std::size_t>(len, payload.size()), payload.begin());
    InboundPacket p;
    p.version = v2 ? 2 : 1;
    p.seq = v2 ? c[4] : c[2];
    p.system_id = v2 ? c[5] : c[3];
    p.component_id = v2 ? c[6] : c[4];
    p.message_id = msgid;
    p.payload = std::span<const std::uint8_t>(payload.data(), spec->payload_bytes);
    p.frame_bytes = total;
    ++packets_;
    on_packet(p);
    pos += total;
  }
  buffer_.erase(buffer_.begin(), buffer_.begin() + static_cast<std::ptrdiff_t>(pos));
  // The waiting candidate's age starts when it became the first byte.
  if (was_empty || pos != 0) candidate_since_ = now;
}

Device::Device(const StreamEncoderOptions& options)
    : options_(options), imu_id_(options.mavlink_hil_sensor ? kHilSensor.id : kHighresImu.id) {
  // The read-only parameters (names at most 16 characters, [X] param_id):
  // the sample rate the device streams at and the `id` its IMU messages
  // carry. Read-only because the scene sets them; a MAVLink rate change is
  // SET_MESSAGE_INTERVAL, not a parameter.
  DeviceParam rate{"IMU_RATE_HZ", static_cast<float>(options.nominal_sample_rate_hz)};
  DeviceParam id{"IMU_SENSOR_ID", static_cast<float>(options.mavlink_sensor_id)};
  params_ = {rate, id};
  // Always streaming: MAVLink has no idle mode; no baud rate of its own.
  status_.set_mode_and_format("streaming", std::string(options.mavlink_hil_sensor ? "HIL_SENSOR" : "HIGHRES_IMU") +
                                                " every sample");
}

CommandCounters Device::command_counters() const { return status_.counters(); }

void Device::set_log(std::function<void(std::string_view)> log) { status_.set_log(std::move(log)); }

void Device::on_input(std::span<const std::uint8_t> bytes, ReplySink& replies) {
  (void)replies;  // see the header: replies are serialised by the encoder
  on_input_at(bytes, std::chrono::steady_clock::now());
}

void Device::on_input_at(std::span<const std::uint8_t> bytes, std::chrono::steady_clock::time_point now) {
  const std::uint64_t skipped_before = parser_.skipped_bytes();
  parser_.feed(bytes, now, [&](const InboundPacket& p) { handle(p); });
  status_.not_command_bytes.fetch_add(parser_.skipped_bytes() - skipped_before, std::memory_order_relaxed);
}

bool Device::addressed_to_us(std::uint8_t target_system, std::uint8_t target_component) const noexcept {
  // [C] 0 is broadcast, for the system and for the component.
  return (target_system == 0 || target_system == options_.mavlink_system_id) &&
         (target_component == 0 || target_component == options_.mavlink_component_id);
}

bool Device::queue(const ReplyItem& item) {
  if (ring_.push(item)) return true;
  status_.replies_dropped.fetch_add(1, std::memory_order_relaxed);
  return false;
}

void Device::ack(std::uint16_t cmd, std::uint8_t result, const InboundPacket& p) {
  ReplyItem a;
  a.kind = ReplyItem::Kind::ack;
  a.command = cmd;
  a.result = result;
  a.target_system = p.system_id;
  a.target_component = p.component_id;
  (void)queue(a);
}

int Device::param_by_id(std::span<const std::uint8_t> id16) const {
  // [X] param_id: "Terminated by NULL if the length is less than 16
  // human-readable chars and WITHOUT null termination if the length is
  // exactly 16".
  std::string id(reinterpret_cast<const char*>(id16.data()), 16);
  id.resize(std::strlen(id.c_str()));
  for (std::size_t i = 0; i < params_.size(); ++i)
    if (id == params_[i].id) return static_cast<int>(i);
  return -1;
}

void Device::handle(const InboundPacket& p) {
  const std::uint8_t* d = p.payload.data();
  switch (p.message_id) {
    case kCommandLong.id:
    case kCommandInt.id: {
      // COMMAND_LONG wire order: param1..7 (f32), command u16, target
      // system, target component, confirmation. COMMAND_INT: param1..4
      // (f32), x, y (i32), z (f32), command u16, target system/component,
      // frame, current, autocontinue.
      const bool is_long = p.message_id == kCommandLong.id;
      float param[7];
      for (int i = 0; i < 7; ++i) param[i] = wire::get_le<float>(d + 4 * i);
      if (!is_long) {
        param[4] = static_cast<float>(wire::get_le<std::int32_t>(d + 16));
        param[5] = static_cast<float>(wire::get_le<std::int32_t>(d + 20));
      }
      const std::uint16_t cmd = wire::get_le<std::uint16_t>(d + 28);
      if (!addressed_to_us(d[30], d[31])) {
        status_.not_command_bytes.fetch_add(p.frame_bytes, std::memory_order_relaxed);
        return;
      }
      status_.received.fetch_add(1, std::memory_order_relaxed);
      command(cmd, param, d[30], d[31], p);
      return;
    }
    case kParamRequestList.id: {
      if (!addressed_to_us(d[0], d[1])) break;
      status_.received.fetch_add(1, std::memory_order_relaxed);
      bool all = true;
      for (std::size_t i = 0; i < params_.size(); ++i) {
        ReplyItem v;
        v.kind = ReplyItem::Kind::param_value;
        v.param_index = static_cast<std::uint16_t>(i);
        all = queue(v) && all;
      }
      if (all) status_.answered.fetch_add(1, std::memory_order_relaxed);
      return;
    }
    case kParamRequestRead.id: {
      // param_index i16, target system, target component, param_id[16].
      if (!addressed_to_us(d[2], d[3])) break;
      status_.received.fetch_add(1, std::memory_order_relaxed);
      const auto index = wire::get_le<std::int16_t>(d);
      const int i = index < 0 ? param_by_id(std::span<const std::uint8_t>(d + 4, 16)) : index;
      if (i < 0 || i >= static_cast<int>(params_.size())) {
        // [P]: no such parameter - the protocol has no reply for it (the
        // requester times out); counted as refused.
        status_.nacked.fetch_add(1, std::memory_order_relaxed);
        log("PARAM_REQUEST_READ of an unknown parameter: no reply (parameter protocol)");
        return;
      }
      ReplyItem v;
      v.kind = ReplyItem::Kind::param_value;
      v.param_index = static_cast<std::uint16_t>(i);
      if (queue(v)) status_.answered.fetch_add(1, std::memory_order_relaxed);
      return;
    }
    case kParamSet.id: {
      // param_value f32, target system, target component, param_id[16], type.
      if (!addressed_to_us(d[4], d[5])) break;
      status_.received.fetch_add(1, std::memory_order_relaxed);
      const int i = param_by_id(std::span<const std::uint8_t>(d + 6, 16));
      status_.nacked.fetch_add(1, std::memory_order_relaxed);
      if (i < 0) {
        log("PARAM_SET of an unknown parameter: ignored");
        return;
      }
      // [P] a parameter that cannot be changed: PARAM_VALUE with the
      // current value, so the ground station sees the set failed.
      log(std::string("PARAM_SET ") + params_[static_cast<std::size_t>(i)].id + " refused: read-only");
      ReplyItem v;
      v.kind = ReplyItem::Kind::param_value;
      v.param_index = static_cast<std::uint16_t>(i);
      (void)queue(v);
      return;
    }
    default:
      break;
  }
  // A peer's HEARTBEAT, or a request for another component: not a command
  // to this device.
  status_.not_command_bytes.fetch_add(p.frame_bytes, std::memory_order_relaxed);
}

void Device::command(std::uint16_t cmd, const float* param, std::uint8_t target_system,
                     std::uint8_t target_component, const InboundPacket& p) {
  (void)target_system;
  (void)target_component;
  const auto refuse = [&](std::uint8_t result, const std::string& why) {
    status_.nacked.fetch_add(1, std::memory_order_relaxed);
    log("command " + std::to_string(cmd) + " refused (MAV_RESULT " + std::to_string(result) + "): " + why);
    ack(cmd, result, p);
  };
  const float message_param = param[0];
  const auto message_id = static_cast<std::uint32_t>(std::lround(message_param));
  if (cmd == kCmdRequestMessage) {
    ReplyItem m;
    if (message_id == kHeartbeat.id && options_.mavlink_heartbeat) m.kind = ReplyItem::Kind::heartbeat;
    else if (message_id == imu_id_) m.kind = ReplyItem::Kind::imu_message;
    else return refuse(kResultDenied, "REQUEST_MESSAGE for message " + std::to_string(message_id) + ", which this device does not send");
    // [R] the ACK first, then the message; one ring slot carries both so
    // they leave together.
    m.command = cmd;
    m.result = kResultAccepted;
    m.target_system = p.system_id;
    m.target_component = p.component_id;
    if (queue(m)) status_.answered.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  if (cmd == kCmdSetMessageInterval) {
    if (message_id != imu_id_)
      return refuse(kResultDenied, "SET_MESSAGE_INTERVAL for message " + std::to_string(message_id) +
                                       (message_id == kHeartbeat.id ? " (HEARTBEAT stays at 1 Hz)" : ", which this device does not stream"));
    const double interval_us = param[1];
    const TimeNs nominal = options_.nominal_sample_rate_hz > 0.0
                               ? static_cast<TimeNs>(std::llround(1e9 / options_.nominal_sample_rate_hz))
                               : period_ns_.load(std::memory_order_relaxed);
    std::uint32_t decimation = 1;
    if (interval_us == -1.0) {
      decimation = 0;  // [R] -1: disabled
    } else if (interval_us == 0.0) {
      decimation = 1;  // [R] 0: the default rate
    } else if (interval_us < 0.0 || !std::isfinite(interval_us)) {
      return refuse(kResultDenied, "interval " + std::to_string(interval_us) + " us is not -1, 0 or positive");
    } else if (nominal <= 0) {
      return refuse(kResultDenied, "the sample period is not known yet");
    } else {
      // The message goes out on the sample grid: the nearest whole number
      // of sample periods, at least one (the device cannot stream faster
      // than it samples).
      const double d = std::round(interval_us * 1000.0 / static_cast<double>(nominal));
      if (d > 1e6) return refuse(kResultDenied, "interval longer than a million samples");
      decimation = static_cast<std::uint32_t>(std::max(1.0, d));
    }
    decimation_.store(decimation, std::memory_order_release);
    const std::string name = options_.mavlink_hil_sensor ? "HIL_SENSOR" : "HIGHRES_IMU";
    const std::string format = decimation == 0 ? name + " off" : name + " every " + std::to_string(decimation) + " samples";
    status_.set_format(format);
    log("SET_MESSAGE_INTERVAL: " + format);
    ack(cmd, kResultAccepted, p);
    status_.answered.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  refuse(kResultUnsupported, "not supported by this device");
}

}  // namespace imuemu::drivers::mavlink2
