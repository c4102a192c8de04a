// The MIP device's command side: framing, the base / 3DM / filter commands,
// settings, and the hand-over to the encoder. Sources in mip_device.hpp.
#include "drivers/protocols/mip_device.hpp"

#include <algorithm>
#include <cstdio>
#include <utility>

#include "drivers/protocols/mip.hpp"

namespace imuemu::drivers::mip {

namespace {

// [B]/[T] function selectors of the settings commands.
constexpr std::uint8_t kFunctionWrite = 0x01;
constexpr std::uint8_t kFunctionRead = 0x02;
constexpr std::uint8_t kFunctionSave = 0x03;
constexpr std::uint8_t kFunctionLoad = 0x04;
constexpr std::uint8_t kFunctionDefault = 0x05;

// The serial rates the 3DM-CV7 / 3DM-GX5 main port accepts (user manuals,
// "Baud rate"); anything else is NACKed invalid parameter.
constexpr std::array<std::uint32_t, 8> kBaudRates{9600, 19200, 38400, 57600, 115200, 230400, 460800, 921600};

std::uint16_t get_u16(const std::uint8_t* p) { return static_cast<std::uint16_t>(p[0] << 8 | p[1]); }
std::uint32_t get_u32(const std::uint8_t* p) {
  return std::uint32_t{p[0]} << 24 | std::uint32_t{p[1]} << 16 | std::uint32_t{p[2]} << 8 | p[3];
}
void put_u16(std::vector<std::uint8_t>& v, std::uint16_t x) {
  v.push_back(static_cast<std::uint8_t>(x >> 8));
  v.push_back(static_cast<std::uint8_t>(x));
}
void put_u32(std::vector<std::uint8_t>& v, std::uint32_t x) {
  for (int shift = 24; shift >= 0; shift -= 8) v.push_back(static_cast<std::uint8_t>(x >> shift));
}
// A 16-character string field, padded with spaces [B 0x81].
void put_string16(std::vector<std::uint8_t>& v, const std::string& s) {
  for (std::size_t i = 0; i < 16; ++i) v.push_back(i < s.size() ? static_cast<std::uint8_t>(s[i]) : ' ');
}
// A reply field: descriptor then data (make_packet adds the length byte).
std::vector<std::uint8_t> field(std::uint8_t descriptor, const std::vector<std::uint8_t>& data = {}) {
  std::vector<std::uint8_t> f(data.size() + 1);
  f[0] = descriptor;
  std::copy(data.begin(), data.end(), f.begin() + 1);
  return f;
}
std::string hex2(unsigned x) {
  char b[8];
  std::snprintf(b, sizeof b, "0x%02X", x & 0xFFu);
  return b;
}
bool valid_function(std::uint8_t f) { return f >= kFunctionWrite && f <= kFunctionDefault; }

}  // namespace

std::vector<std::uint8_t> make_packet(std::uint8_t descriptor_set, std::span<const std::vector<std::uint8_t>> fields) {
  std::vector<std::uint8_t> p{kSync1, kSync2, descriptor_set, 0};
  for (const std::vector<std::uint8_t>& f : fields) {
    // Each field: its length (length byte + descriptor + data), descriptor, data.
    p.push_back(static_cast<std::uint8_t>(f.size() + 1));
    p.insert(p.end(), f.begin(), f.end());
  }
  p[3] = static_cast<std::uint8_t>(p.size() - kHeaderBytes);
  const std::uint16_t c = fletcher_checksum(p);
  p.push_back(static_cast<std::uint8_t>(c >> 8));
  p.push_back(static_cast<std::uint8_t>(c));
  return p;
}

void CommandParser::feed(std::span<const std::uint8_t> bytes, std::chrono::steady_clock::time_point now,
                         const std::function<void(std::uint8_t, std::span<const std::uint8_t>)>& on_packet) {
  // A candidate that has waited too long for its remaining bytes: drop its
  // first byte so the scan looks past it.
  if (!buffer_.empty() && !bytes.empty() && now - candidate_since_ > kStaleAfter) {
    buffer_.erase(buffer_.begin());
    ++not_command_bytes_;
  }
  buffer_.insert(buffer_.end(), bytes.begin(), bytes.end());
  std::size_t at = 0;
  for (;;) {
    // The next sync pair; bytes before it are not commands.
    std::size_t sync = at;
    while (sync + 1 < buffer_.size() && !(buffer_[sync] == kSync1 && buffer_[sync + 1] == kSync2)) ++sync;
    if (sync + 1 >= buffer_.size()) {
      // Keep a trailing 0x75 (the first half of a sync split across reads).
      const std::size_t keep = !buffer_.empty() && sync < buffer_.size() && buffer_[sync] == kSync1 ? 1 : 0;
      const std::size_t drop = buffer_.size() - keep;
      not_command_bytes_ += drop - at;
      buffer_.erase(buffer_.begin(), buffer_.begin() + static_cast<std::ptrdiff_t>(drop));
      if (keep != 0) candidate_since_ = now;
      return;
    }
    not_command_bytes_ += sync - at;
    at = sync;
    if (buffer_.size() - at < kHeaderBytes) break;
    const std::size_t payload = buffer_[at + 3];
    const std::size_t total = kHeaderBytes + payload + kChecksumBytes;
    if (buffer_.size() - at < total) break;
    const std::span<const std::uint8_t> packet(buffer_.data() + at, total);
    const std::uint16_t sent = get_u16(packet.data() + kHeaderBytes + payload);
    if (fletcher_checksum(packet.first(kHeaderBytes + payload)) != sent) {
      ++not_command_bytes_;  // not a packet after all: look again from the next byte
      ++at;
      continue;
    }
    ++packets_;
    on_packet(packet[2], packet.subspan(kHeaderBytes, payload));
    at += total;
  }
  // A partial candidate at `at`: keep it (and remember since when it waits).
  if (at != 0) {
    buffer_.erase(buffer_.begin(), buffer_.begin() + static_cast<std::ptrdiff_t>(at));
    candidate_since_ = now;
  } else if (!bytes.empty() && buffer_.size() == bytes.size()) {
    candidate_since_ = now;
  }
}

Device::Device(const MipDeviceConfig& config, std::vector<std::uint8_t> sensor_fields, std::uint16_t base_rate_hz,
               NavFields nav)
    : config_(config),
      sensor_fields_(std::move(sensor_fields)),
      base_rate_hz_(base_rate_hz),
      nav_(std::move(nav)),
      published_(EmitConfig{}) {
  for (const std::uint8_t f : sensor_fields_) defaults_.sensor_format.push_back({f, 1});
  defaults_.gnss_format = nav_.gnss_power_up;
  defaults_.filter_format = nav_.filter_power_up;
  current_ = saved_ = defaults_;
  status_.set_baud(current_.baud);
  streaming_ = !config_.power_up_idle;
  // What Get Device Descriptors reports: the commands answered below and the
  // data fields the device can stream.
  for (const int d : {0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, 0x09})
    descriptors_.push_back(static_cast<std::uint16_t>(kBaseCommandSet << 8 | d));
  for (const int d : {0x06, 0x08, 0x0A, 0x0B, 0x0E, 0x0F, 0x11, 0x30, 0x40})
    descriptors_.push_back(static_cast<std::uint16_t>(k3dmCommandSet << 8 | d));
  if (has_gnss())  // [N] Get GNSS Base Rate, GNSS Message Format
    for (const int d : {0x07, 0x09}) descriptors_.push_back(static_cast<std::uint16_t>(k3dmCommandSet << 8 | d));
  descriptors_.push_back(static_cast<std::uint16_t>(kFilterCommandSet << 8 | 0x01));
  for (const std::uint8_t f : sensor_fields_) descriptors_.push_back(static_cast<std::uint16_t>(kSensorDataSet << 8 | f));
  for (const std::uint8_t f : nav_.gnss) descriptors_.push_back(static_cast<std::uint16_t>(kGnssSet << 8 | f));
  for (const std::uint8_t f : nav_.filter) descriptors_.push_back(static_cast<std::uint16_t>(kFilterDataSet << 8 | f));
  publish();
}

void Device::set_log(std::function<void(std::string_view)> log) { status_.set_log(std::move(log)); }

std::string Device::format_text() const {
  auto list = [&](const std::vector<FieldRate>& f) {
    std::string s;
    for (const FieldRate& r : f) {
      if (!s.empty()) s.push_back(' ');
      s.append(hex2(r.descriptor));
      s.push_back('/');
      s.append(std::to_string(r.decimation));
    }
    return s.empty() ? std::string("none") : s;
  };
  std::string s = "0x80 [" + list(current_.sensor_format) + "]" + (current_.sensor_stream ? "" : " (stream off)") +
                  " at base " + std::to_string(base_rate_hz_) + " Hz; 0x82 [" + list(current_.filter_format) + "]";
  if (!nav_.filter.empty() && !current_.filter_stream) s += " (stream off)";
  if (has_gnss()) s += "; 0x81 [" + list(current_.gnss_format) + "]" + (current_.gnss_stream ? "" : " (stream off)");
  return s;
}

void Device::publish() {
  auto stream_of = [&](const Settings& s, bool streaming) {
    StreamConfig c;
    c.send = streaming && s.sensor_stream && !s.sensor_format.empty();
    c.scene_format = s.sensor_format == defaults_.sensor_format;
    c.count = static_cast<std::uint8_t>(std::min(s.sensor_format.size(), kMaxFormatFields));
    for (std::size_t i = 0; i < c.count; ++i) c.fields[i] = s.sensor_format[i];
    auto set_format = [&](const std::vector<FieldRate>& f, bool stream_on) {
      SetFormat x;
      x.send = streaming && stream_on && !f.empty();
      x.count = static_cast<std::uint8_t>(std::min(f.size(), kMaxFormatFields));
      for (std::size_t i = 0; i < x.count; ++i) x.fields[i] = f[i];
      return x;
    };
    c.gnss = set_format(s.gnss_format, s.gnss_stream);
    c.filter = set_format(s.filter_format, s.filter_stream);
    return c;
  };
  EmitConfig c;
  static_cast<StreamConfig&>(c) = stream_of(current_, streaming_);
  c.startup = stream_of(saved_, !config_.power_up_idle);
  c.restarts_handled = restarts_handled_;
  published_.publish(c);
  status_.set_mode_and_format(streaming_ ? "streaming" : "idle", format_text());
}

CommandCounters Device::command_counters() const {
  // (A restart not yet taken in by the io thread shows at its next input.)
  return status_.counters();
}

void Device::take_restarts() {
  const std::uint64_t r = restarts_.load(std::memory_order_acquire);
  if (r == restarts_handled_) return;
  restarts_handled_ = r;
  // A power cycle: the saved startup settings and the power-up mode. The
  // line rate stays (the transport keeps its own; a real device would come
  // up at its saved rate, which is this one unless the driver saved another).
  const std::uint32_t baud = current_.baud;
  current_ = saved_;
  current_.baud = baud;
  streaming_ = !config_.power_up_idle;
  publish();
  log("restarted (fault): startup settings, " + std::string(streaming_ ? "streaming " : "idle, ") + format_text());
}

void Device::on_input(std::span<const std::uint8_t> bytes, ReplySink& replies) {
  take_restarts();
  parser_.feed(bytes, std::chrono::steady_clock::now(), [&](std::uint8_t set, std::span<const std::uint8_t> payload) {
    // Descriptor sets 0x80 and above carry data, not commands [P]: a driver
    // never sends them; not commands.
    if (set >= 0x80) {
      parser_.count_not_command(payload.size() + kHeaderBytes + kChecksumBytes);
      return;
    }
    // The fields must tile the payload exactly. A field descriptor of 0x80
    // or more is a reply field (ACK/NACK 0xF1, reply data), never a command
    // [P]: a packet carrying one is a reply (ours, echoed back by a reader
    // whose tty echoes), and answering it would answer our own replies.
    std::size_t at = 0;
    bool reply_field = false;
    while (at < payload.size()) {
      const std::size_t len = payload[at];
      if (len < 2 || at + len > payload.size()) break;
      reply_field = reply_field || payload[at + 1] >= 0x80;
      at += len;
    }
    if (at != payload.size() || payload.empty() || reply_field) {
      parser_.count_not_command(payload.size() + kHeaderBytes + kChecksumBytes);
      return;
    }
    std::vector<std::vector<std::uint8_t>> out;
    for (at = 0; at < payload.size(); at += payload[at]) {
      status_.received.fetch_add(1, std::memory_order_relaxed);
      handle(set, payload[at + 1], payload.subspan(at + 2, payload[at] - 2u), out, replies);
    }
    if (!replies.reply(make_packet(set, out))) status_.replies_dropped.fetch_add(1, std::memory_order_relaxed);
  });
  status_.not_command_bytes.store(parser_.not_command_bytes(), std::memory_order_relaxed);
}

void Device::handle(std::uint8_t set, std::uint8_t descriptor, std::span<const std::uint8_t> data,
                    std::vector<std::vector<std::uint8_t>>& out, ReplySink& replies) {
  // The ACK/NACK goes first, the reply data after it: collected apart.
  std::vector<std::vector<std::uint8_t>> reply_data;
  AckCode code = AckCode::unknown_command;
  switch (set) {
    case kBaseCommandSet: code = base_command(descriptor, data, reply_data, replies); break;
    case k3dmCommandSet: code = three_dm_command(descriptor, data, reply_data, replies); break;
    case kFilterCommandSet: code = filter_command(descriptor, data); break;
    default: break;  // a command set this device does not have: unknown command
  }
  out.push_back(field(kAckNackField, {descriptor, static_cast<std::uint8_t>(code)}));
  if (code == AckCode::ok) {
    status_.answered.fetch_add(1, std::memory_order_relaxed);
    for (auto& f : reply_data) out.push_back(std::move(f));
  } else {
    status_.nacked.fetch_add(1, std::memory_order_relaxed);
  }
}

AckCode Device::base_command(std::uint8_t descriptor, std::span<const std::uint8_t> data,
                             std::vector<std::vector<std::uint8_t>>& out, ReplySink& replies) {
  switch (descriptor) {
    case 0x01:  // Ping
      return data.empty() ? AckCode::ok : AckCode::invalid_parameter;
    case 0x02:  // Set To Idle
      if (!data.empty()) return AckCode::invalid_parameter;
      if (streaming_) log("idle (Set To Idle): streaming stops");
      streaming_ = false;
      publish();
      return AckCode::ok;
    case 0x06:  // Resume: back to streaming its configured messages
      if (!data.empty()) return AckCode::invalid_parameter;
      if (!streaming_) log("resumed (Resume): streaming " + format_text());
      streaming_ = true;
      publish();
      return AckCode::ok;
    case 0x03: {  // Get Device Information -> 0x81
      if (!data.empty()) return AckCode::invalid_parameter;
      std::vector<std::uint8_t> info;
      put_u16(info, config_.firmware_version);
      for (const std::string* s : {&config_.model_name, &config_.model_number, &config_.serial_number,
                                   &config_.lot_number, &config_.device_options})
        put_string16(info, *s);
      out.push_back(field(0x81, std::move(info)));
      return AckCode::ok;
    }
    case 0x04: {  // Get Device Descriptors -> 0x82
      if (!data.empty()) return AckCode::invalid_parameter;
      std::vector<std::uint8_t> list;
      for (const std::uint16_t d : descriptors_) put_u16(list, d);
      out.push_back(field(0x82, std::move(list)));
      return AckCode::ok;
    }
    case 0x07:  // Get Extended Descriptors -> 0x86: none beyond the list above
      if (!data.empty()) return AckCode::invalid_parameter;
      out.push_back(field(0x86));
      return AckCode::ok;
    case 0x05: {  // Built-In Test -> 0x83: u32, 0 = every test passed
      if (!data.empty()) return AckCode::invalid_parameter;
      std::vector<std::uint8_t> result;
      put_u32(result, 0);
      out.push_back(field(0x83, std::move(result)));
      return AckCode::ok;
    }
    case 0x09: {  // Comm Port Speed: function, port, [u32 baud]
      if (data.size() < 2 || !valid_function(data[0])) return AckCode::invalid_parameter;
      const std::uint8_t function = data[0];
      if (data[1] != 1) return AckCode::invalid_parameter;  // port 1: the main (only) port
      if (function == kFunctionWrite) {
        if (data.size() != 6) return AckCode::invalid_parameter;
        return baud_setting(function, get_u32(data.data() + 2), replies);
      }
      if (data.size() != 2) return AckCode::invalid_parameter;
      if (function == kFunctionRead) {
        std::vector<std::uint8_t> r{1};
        put_u32(r, current_.baud);
        out.push_back(field(0x89, std::move(r)));
        return AckCode::ok;
      }
      return baud_setting(function, 0, replies);
    }
    default:
      return AckCode::unknown_command;
  }
}

AckCode Device::baud_setting(std::uint8_t function, std::uint32_t baud, ReplySink& replies) {
  switch (function) {
    case kFunctionWrite:
      if (std::find(kBaudRates.begin(), kBaudRates.end(), baud) == kBaudRates.end()) return AckCode::invalid_parameter;
      apply_baud(baud, replies);
      return AckCode::ok;
    case kFunctionSave: saved_.baud = current_.baud; return AckCode::ok;
    case kFunctionLoad: apply_baud(saved_.baud, replies); return AckCode::ok;
    case kFunctionDefault: apply_baud(defaults_.baud, replies); return AckCode::ok;
    default: return AckCode::invalid_parameter;
  }
}

void Device::apply_baud(std::uint32_t baud, ReplySink& replies) {
  if (baud == current_.baud) return;
  current_.baud = baud;
  // The device answers at the old rate, then switches (the ACK is queued
  // before this reply's packet is complete: the sink applies it after every
  // reply queued so far, including this one, has left).
  replies.change_baud_after_replies(baud);
  {
    status_.set_baud(baud);
  }
  log("baud " + std::to_string(baud) + " after this reply");
}

AckCode Device::message_format(std::uint8_t set, std::uint8_t function, std::span<const std::uint8_t> list,
                               std::uint8_t reply_descriptor, bool reply_has_set,
                               std::vector<std::vector<std::uint8_t>>& out) {
  std::vector<FieldRate> Settings::*member = set == kSensorDataSet ? &Settings::sensor_format
                                            : set == kGnssSet       ? &Settings::gnss_format
                                                                    : &Settings::filter_format;
  const std::vector<std::uint8_t>& can_send = set == kSensorDataSet ? sensor_fields_
                                              : set == kGnssSet       ? nav_.gnss
                                                                      : nav_.filter;
  switch (function) {
    case kFunctionWrite: {
      if (list.empty() || list.size() != 1u + 3u * list[0]) return AckCode::invalid_parameter;
      std::vector<FieldRate> format;
      for (std::size_t i = 0; i < list[0]; ++i) {
        const FieldRate r{list[1 + 3 * i], get_u16(list.data() + 2 + 3 * i)};
        // A field this device cannot send (in this set), decimation 0 or a
        // field twice: invalid parameter, nothing changed.
        const bool known = std::find(can_send.begin(), can_send.end(), r.descriptor) != can_send.end();
        const bool twice = std::any_of(format.begin(), format.end(),
                                       [&](const FieldRate& f) { return f.descriptor == r.descriptor; });
        if (!known || r.decimation == 0 || twice || format.size() >= kMaxFormatFields) return AckCode::invalid_parameter;
        format.push_back(r);
      }
      current_.*member = std::move(format);
      break;
    }
    case kFunctionRead: {
      if (list.size() != 0) return AckCode::invalid_parameter;
      std::vector<std::uint8_t> r;
      if (reply_has_set) r.push_back(set);
      const std::vector<FieldRate>& f = current_.*member;
      r.push_back(static_cast<std::uint8_t>(f.size()));
      for (const FieldRate& x : f) {
        r.push_back(x.descriptor);
        put_u16(r, x.decimation);
      }
      out.push_back(field(reply_descriptor, std::move(r)));
      return AckCode::ok;
    }
    case kFunctionSave:
      if (list.size() != 0) return AckCode::invalid_parameter;
      saved_.*member = current_.*member;
      return AckCode::ok;
    case kFunctionLoad:
      if (list.size() != 0) return AckCode::invalid_parameter;
      current_.*member = saved_.*member;
      break;
    case kFunctionDefault:
      if (list.size() != 0) return AckCode::invalid_parameter;
      current_.*member = defaults_.*member;
      break;
    default: return AckCode::invalid_parameter;
  }
  publish();
  log("message format " + hex2(set) + ": " + format_text());
  return AckCode::ok;
}

AckCode Device::three_dm_command(std::uint8_t descriptor, std::span<const std::uint8_t> data,
                                 std::vector<std::vector<std::uint8_t>>& out, ReplySink& replies) {
  switch (descriptor) {
    case 0x06:    // Get IMU Base Rate -> 0x83
    case 0x0B: {  // Get Filter Base Rate -> 0x8A
      if (!data.empty()) return AckCode::invalid_parameter;
      std::vector<std::uint8_t> r;
      put_u16(r, base_rate_hz_);
      out.push_back(field(descriptor == 0x06 ? 0x83 : 0x8A, std::move(r)));
      return AckCode::ok;
    }
    case 0x07:  // [N] Get GNSS Base Rate -> 0x84 (a device with a GNSS receiver)
    case 0x09:  // [N] GNSS Message Format -> 0x81
      if (!has_gnss()) return AckCode::unknown_command;
      if (descriptor == 0x07) {
        if (!data.empty()) return AckCode::invalid_parameter;
        std::vector<std::uint8_t> r;
        put_u16(r, base_rate_hz_);
        out.push_back(field(0x84, std::move(r)));
        return AckCode::ok;
      }
      if (data.empty()) return AckCode::invalid_parameter;
      return message_format(kGnssSet, data[0], data.subspan(1), 0x81, false, out);
    case 0x0E: {  // Get Base Rate (descriptor set) -> 0x8E
      if (data.size() != 1 || !known_set(data[0])) return AckCode::invalid_parameter;
      std::vector<std::uint8_t> r{data[0]};
      put_u16(r, base_rate_hz_);
      out.push_back(field(0x8E, std::move(r)));
      return AckCode::ok;
    }
    case 0x08:  // IMU Message Format -> 0x80
    case 0x0A:  // Filter Message Format -> 0x82
      if (data.empty()) return AckCode::invalid_parameter;
      return message_format(descriptor == 0x08 ? kSensorDataSet : kFilterDataSet, data[0], data.subspan(1),
                            descriptor == 0x08 ? 0x80 : 0x82, false, out);
    case 0x0F:  // Message Format (descriptor set) -> 0x8F
      if (data.size() < 2 || !known_set(data[1])) return AckCode::invalid_parameter;
      return message_format(data[1], data[0], data.subspan(2), 0x8F, true, out);
    case 0x11: {  // Datastream Control: function, set (0: all), [enable]
      if (data.size() < 2) return AckCode::invalid_parameter;
      const std::uint8_t function = data[0], set = data[1];
      if (set != 0 && !known_set(set)) return AckCode::invalid_parameter;
      auto apply = [&](const Settings& from) {
        if (set == 0 || set == kSensorDataSet) current_.sensor_stream = from.sensor_stream;
        if (set == 0 || set == kFilterDataSet) current_.filter_stream = from.filter_stream;
        if (set == 0 || set == kGnssSet) current_.gnss_stream = from.gnss_stream;
      };
      switch (function) {
        case kFunctionWrite: {
          if (data.size() != 3 || data[2] > 1) return AckCode::invalid_parameter;
          Settings s = current_;
          s.sensor_stream = s.filter_stream = s.gnss_stream = data[2] != 0;
          apply(s);
          break;
        }
        case kFunctionRead: {
          if (data.size() != 2 || set == 0) return AckCode::invalid_parameter;
          const bool on = set == kSensorDataSet ? current_.sensor_stream
                          : set == kGnssSet       ? current_.gnss_stream
                                                  : current_.filter_stream;
          out.push_back(field(0x85, {set, static_cast<std::uint8_t>(on ? 1 : 0)}));
          return AckCode::ok;
        }
        case kFunctionSave:
          if (data.size() != 2) return AckCode::invalid_parameter;
          if (set == 0 || set == kSensorDataSet) saved_.sensor_stream = current_.sensor_stream;
          if (set == 0 || set == kFilterDataSet) saved_.filter_stream = current_.filter_stream;
          if (set == 0 || set == kGnssSet) saved_.gnss_stream = current_.gnss_stream;
          return AckCode::ok;
        case kFunctionLoad:
          if (data.size() != 2) return AckCode::invalid_parameter;
          apply(saved_);
          break;
        case kFunctionDefault:
          if (data.size() != 2) return AckCode::invalid_parameter;
          apply(defaults_);
          break;
        default: return AckCode::invalid_parameter;
      }
      publish();
      log("datastream control: " + format_text());
      return AckCode::ok;
    }
    case 0x30: {  // Device Settings: save / load saved / load default, all settings at once
      if (data.size() != 1) return AckCode::invalid_parameter;
      switch (data[0]) {
        case kFunctionSave: saved_ = current_; return AckCode::ok;
        case kFunctionLoad:
        case kFunctionDefault: {
          const Settings& from = data[0] == kFunctionLoad ? saved_ : defaults_;
          const std::uint32_t old_baud = current_.baud;
          current_ = from;
          current_.baud = old_baud;
          apply_baud(from.baud, replies);  // after this ACK, as the device does
          publish();
          log(std::string(data[0] == kFunctionLoad ? "saved" : "default") + " settings loaded: " + format_text());
          return AckCode::ok;
        }
        default: return AckCode::invalid_parameter;  // write/read have no meaning here
      }
    }
    case 0x40: {  // UART Baudrate: function, [u32 baud] -> 0x87
      if (data.empty() || !valid_function(data[0])) return AckCode::invalid_parameter;
      if (data[0] == kFunctionWrite) {
        if (data.size() != 5) return AckCode::invalid_parameter;
        return baud_setting(kFunctionWrite, get_u32(data.data() + 1), replies);
      }
      if (data.size() != 1) return AckCode::invalid_parameter;
      if (data[0] == kFunctionRead) {
        std::vector<std::uint8_t> r;
        put_u32(r, current_.baud);
        out.push_back(field(0x87, std::move(r)));
        return AckCode::ok;
      }
      return baud_setting(data[0], 0, replies);
    }
    default:
      return AckCode::unknown_command;
  }
}

AckCode Device::filter_command(std::uint8_t descriptor, std::span<const std::uint8_t> data) {
  switch (descriptor) {
    case 0x01:  // Reset Filter: the emulated filter is a function of time since power-up; nothing to restart
      return data.empty() ? AckCode::ok : AckCode::invalid_parameter;
    default:
      return AckCode::unknown_command;
  }
}

}  // namespace imuemu::drivers::mip
