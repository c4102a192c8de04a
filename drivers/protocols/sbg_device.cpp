// The SBG device's command side: frame scanning, CMD_0 commands, the REST
// API, aiding inputs, and the hand-over to the encoder. Sources in
// sbg_device.hpp.
#include "drivers/protocols/sbg_device.hpp"

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <optional>
#include <utility>

#include "drivers/protocols/wire_bytes.hpp"

namespace imuemu::drivers::sbg {

namespace {

// The largest input kept while a frame is incomplete (one whole frame).
constexpr std::size_t kMaxPendingBytes = kMaxPayloadBytes + kFrameOverheadBytes;

// ---- a small JSON reader for POST /api/v1/settings bodies: validates the
// whole text, and hands every string value with its key path to `visit`.
class JsonReader {
 public:
  using Visit = std::function<bool(const std::vector<std::string>& path, std::string_view value)>;
  JsonReader(std::string_view text, Visit visit) : s_(text), visit_(std::move(visit)) {}
  // True when the text is one JSON value and every visit accepted its string.
  bool read(std::string& error) {
    skip();
    if (!value()) {
      error = error_.empty() ? "malformed JSON at offset " + std::to_string(i_) : error_;
      return false;
    }
    skip();
    if (i_ != s_.size()) {
      error = "trailing characters at offset " + std::to_string(i_);
      return false;
    }
    return true;
  }

 private:
  void skip() {
    while (i_ < s_.size() && (s_[i_] == ' ' || s_[i_] == '\t' || s_[i_] == '\n' || s_[i_] == '\r')) ++i_;
  }
  bool string(std::string& out) {
    if (i_ >= s_.size() || s_[i_] != '"') return false;
    ++i_;
    while (i_ < s_.size() && s_[i_] != '"') {
      if (s_[i_] == '\\') {
        if (++i_ >= s_.size()) return false;
        const char e = s_[i_];
        if (e == 'u') {
          if (i_ + 4 >= s_.size()) return false;
          out += '?';
          i_ += 4;
        } else {
          out += e == 'n' ? '\n' : e == 't' ? '\t' : e;
        }
      } else if (static_cast<unsigned char>(s_[i_]) < 0x20) {
        return false;
      } else {
        out += s_[i_];
      }
      ++i_;
    }
    if (i_ >= s_.size()) return false;
    ++i_;
    return true;
  }
  bool literal(std::string_view word) {
    if (s_.substr(i_, word.size()) != word) return false;
    i_ += word.size();
    return true;
  }
  bool number() {
    const std::size_t start = i_;
    if (i_ < s_.size() && s_[i_] == '-') ++i_;
    while (i_ < s_.size() && ((s_[i_] >= '0' && s_[i_] <= '9') || s_[i_] == '.' || s_[i_] == 'e' || s_[i_] == 'E' ||
                              s_[i_] == '+' || s_[i_] == '-'))
      ++i_;
    return i_ > start && s_[i_ - 1] >= '0' && s_[i_ - 1] <= '9';
  }
  bool value() {
    if (++depth_ > 32) return false;
    skip();
    if (i_ >= s_.size()) return false;
    bool ok = false;
    const char c = s_[i_];
    if (c == '{') {
      ++i_;
      skip();
      ok = true;
      if (i_ < s_.size() && s_[i_] == '}') {
        ++i_;
      } else {
        for (;;) {
          skip();
          std::string key;
          if (!string(key)) return false;
          skip();
          if (i_ >= s_.size() || s_[i_] != ':') return false;
          ++i_;
          path_.push_back(std::move(key));
          if (!value()) return false;
          path_.pop_back();
          skip();
          if (i_ < s_.size() && s_[i_] == ',') {
            ++i_;
            continue;
          }
          if (i_ < s_.size() && s_[i_] == '}') {
            ++i_;
            break;
          }
          return false;
        }
      }
    } else if (c == '[') {
      ++i_;
      skip();
      ok = true;
      if (i_ < s_.size() && s_[i_] == ']') {
        ++i_;
      } else {
        for (;;) {
          path_.emplace_back("[]");
          if (!value()) return false;
          path_.pop_back();
          skip();
          if (i_ < s_.size() && s_[i_] == ',') {
            ++i_;
            continue;
          }
          if (i_ < s_.size() && s_[i_] == ']') {
            ++i_;
            break;
          }
          return false;
        }
      }
    } else if (c == '"') {
      std::string v;
      ok = string(v);
      if (ok && !visit_(path_, v)) {
        error_ = "invalid value \"" + v + "\" for " + joined();
        ok = false;
      }
    } else if (c == 't') {
      ok = literal("true");
    } else if (c == 'f') {
      ok = literal("false");
    } else if (c == 'n') {
      ok = literal("null");
    } else {
      ok = number();
    }
    --depth_;
    return ok;
  }
  std::string joined() const {
    std::string s;
    for (const std::string& p : path_) s += (s.empty() ? "" : "/") + p;
    return s;
  }
  std::string_view s_;
  Visit visit_;
  std::size_t i_ = 0;
  int depth_ = 0;
  std::vector<std::string> path_;
  std::string error_;
};

std::string json_error(int status, const char* title, const std::string& detail) {
  std::string d;
  for (const char c : detail) {
    if (c == '"' || c == '\\') d += '\\';
    if (static_cast<unsigned char>(c) >= 0x20) d += c;
  }
  return "{\"status\":" + std::to_string(status) + ",\"title\":\"" + title + "\",\"detail\":\"" + d + "\"}";
}

int port_index(std::string_view name) {
  if (name == "comA") return 0;
  if (name == "comC") return 1;
  return -1;
}
int port_index(std::uint8_t port) {
  if (port == kPortA) return 0;
  if (port == kPortC) return 1;
  return -1;
}
}  // namespace

std::string product_code_of(const SbgDeviceConfig& config) {
  if (!config.product_code.empty()) return config.product_code;
  switch (config.model) {
    case SbgModel::ellipse_a: return "ELLIPSE-A-G4A3-B1";
    case SbgModel::ellipse_n: return "ELLIPSE-N-G4A3-B1";
    case SbgModel::ellipse_d: return "ELLIPSE-D-G4A3-B1";
  }
  return "ELLIPSE-N-G4A3-B1";
}

Device::Device(const SbgDeviceConfig& config)
    : config_(config), product_code_(product_code_of(config)), published_(EmitConfig{}), latest_(Measurements{}) {
  defaults_.ports[0] = factory_config(config);
  current_ = saved_ = defaults_;
  saved_.ports[0] = current_.ports[0] = power_up_config(config);
  publish();
}

void Device::set_log(std::function<void(std::string_view)> log) { status_.set_log(std::move(log)); }

CommandCounters Device::command_counters() const { return status_.counters(); }

AidingInputs Device::aiding_inputs() const {
  std::lock_guard<std::mutex> lock(aiding_mutex_);
  return aiding_;
}

std::string Device::format_text() const {
  std::string s;
  const StreamConfig& a = current_.ports[0];
  for (int i = 0; i < kOutputCount; ++i) {
    const std::uint16_t mode = a.modes[static_cast<std::size_t>(i)];
    if (mode == kModeDisabled || !model_has(config_.model, i)) continue;
    const char* rate = rest_rate_name(mode);
    s += (s.empty() ? "" : ", ") + std::string(output_info(i).rest_name) + " " +
         (rate != nullptr ? std::string(rate) : "mode " + std::to_string(mode));
  }
  return s.empty() ? "no logs" : s;
}

void Device::publish() {
  EmitConfig e;
  static_cast<StreamConfig&>(e) = current_.ports[0];
  e.startup = saved_.ports[0];
  e.restarts_handled = restarts_handled_;
  published_.publish(e);
  status_.set_mode_and_format("streaming", format_text());
}

void Device::take_restarts() {
  const std::uint64_t r = restarts_.load(std::memory_order_acquire);
  if (r == restarts_handled_) return;
  restarts_handled_ = r;
  current_ = saved_;
  publish();
  log("restarted: saved settings, " + format_text());
}

void Device::reboot() {
  current_ = saved_;
  publish();
  log("reboot: saved settings, " + format_text());
}

void Device::on_input(std::span<const std::uint8_t> bytes, ReplySink& replies) {
  take_restarts();
  pending_.insert(pending_.end(), bytes.begin(), bytes.end());
  std::uint64_t stray = 0;
  std::size_t pos = 0;
  const std::size_t n = pending_.size();
  while (pos < n) {
    if (pending_[pos] != kSync1 || (pos + 1 < n && pending_[pos + 1] != kSync2)) {
      ++stray, ++pos;
      continue;
    }
    if (pos + 6 > n) break;
    const std::size_t len = wire::get_le<std::uint16_t>(pending_.data() + pos + 4);
    const std::uint8_t cls = pending_[pos + 3];
    if (len > kMaxPayloadBytes || (cls & 0x80) != 0) {  // not a standard frame this device takes
      ++stray, ++pos;
      continue;
    }
    if (pos + len + kFrameOverheadBytes > n) break;
    const std::uint8_t* f = pending_.data() + pos;
    if (f[8 + len] != kEtx ||
        crc16(std::span<const std::uint8_t>(f + 2, len + 4)) != wire::get_le<std::uint16_t>(f + 6 + len)) {
      ++stray, ++pos;  // a corrupted frame is not a command: no answer ([F])
      continue;
    }
    // Copy: handling may reply, and the buffer is compacted below.
    const std::vector<std::uint8_t> payload(f + 6, f + 6 + len);
    const std::uint8_t msg = f[2];
    pos += len + kFrameOverheadBytes;
    frame(msg, cls, payload, replies);
  }
  pending_.erase(pending_.begin(), pending_.begin() + static_cast<std::ptrdiff_t>(pos));
  if (pending_.size() > kMaxPendingBytes) {
    stray += pending_.size();
    pending_.clear();
  }
  if (stray != 0) status_.not_command_bytes.fetch_add(stray, std::memory_order_relaxed);
}

void Device::frame(std::uint8_t msg, std::uint8_t cls, std::span<const std::uint8_t> payload, ReplySink& replies) {
  if (cls == kClassCmd0) {
    status_.received.fetch_add(1, std::memory_order_relaxed);
    command(msg, payload, replies);
    return;
  }
  if (cls == kClassLog0 && (msg == kLogAirData || msg == kLogMag)) {
    status_.received.fetch_add(1, std::memory_order_relaxed);
    aiding_input(msg, payload);
    return;
  }
  // Any other log or class: valid framing, nothing this device takes.
  status_.not_command_bytes.fetch_add(payload.size() + kFrameOverheadBytes, std::memory_order_relaxed);
}

void Device::aiding_input(std::uint8_t msg, std::span<const std::uint8_t> p) {
  std::lock_guard<std::mutex> lock(aiding_mutex_);
  // [L] sbgEComLogAirData.c: time stamp u32, status u16, absolute pressure
  // Pa, altitude m (then, when present, differential pressure Pa, true
  // airspeed m/s, air temperature degC); sbgEComLogMag.c: time stamp,
  // status, magnetometers, accelerometers.
  if (msg == kLogAirData && p.size() >= 14) {
    ++aiding_.air_data_frames;
    aiding_.air_data_status = wire::get_le<std::uint16_t>(p.data() + 4);
    aiding_.pressure_abs_pa = wire::get_le<float>(p.data() + 6);
    aiding_.altitude_m = wire::get_le<float>(p.data() + 10);
    if (p.size() >= 26) {
      aiding_.pressure_diff_pa = wire::get_le<float>(p.data() + 14);
      aiding_.true_airspeed_m_s = wire::get_le<float>(p.data() + 18);
      aiding_.air_temperature_c = wire::get_le<float>(p.data() + 22);
    }
    if (aiding_.air_data_frames == 1) log("AIR_DATA input from the driver: aiding taken");
  } else if (msg == kLogMag && p.size() >= 18) {
    ++aiding_.mag_frames;
    for (int i = 0; i < 3; ++i) aiding_.mag[i] = wire::get_le<float>(p.data() + 6 + 4 * i);
    if (aiding_.mag_frames == 1) log("MAG input from the driver: aiding taken");
  }
}

void Device::send(std::uint8_t msg, std::span<const std::uint8_t> payload, ReplySink& replies) {
  std::vector<std::uint8_t> out;
  out.reserve(payload.size() + kFrameOverheadBytes);
  append_frame(msg, kClassCmd0, payload, out);
  if (!replies.reply(out)) status_.replies_dropped.fetch_add(1, std::memory_order_relaxed);
}

void Device::ack(std::uint8_t msg, ErrorCode code, ReplySink& replies) {
  std::uint8_t p[4] = {msg, kClassCmd0, 0, 0};
  wire::put_le<std::uint16_t>(p + 2, static_cast<std::uint16_t>(code));
  if (code == ErrorCode::no_error) status_.answered.fetch_add(1, std::memory_order_relaxed);
  else status_.nacked.fetch_add(1, std::memory_order_relaxed);
  send(kCmdAck, p, replies);
}

void Device::command(std::uint8_t msg, std::span<const std::uint8_t> p, ReplySink& replies) {
  switch (msg) {
    case kCmdInfo: {
      if (!p.empty()) return ack(msg, ErrorCode::invalid_frame, replies);
      std::array<std::uint8_t, 52> r{};
      std::memcpy(r.data(), product_code_.data(), std::min<std::size_t>(product_code_.size(), 31));
      wire::put_le<std::uint32_t>(r.data() + 32, config_.serial_number);
      wire::put_le<std::uint32_t>(r.data() + 36, kCalibrationRevision);
      wire::put_le<std::uint16_t>(r.data() + 40, 2026);
      r[42] = 11;  // calibration month
      r[43] = 20;  // calibration day
      wire::put_le<std::uint32_t>(r.data() + 44, kHardwareRevision);
      wire::put_le<std::uint32_t>(r.data() + 48, kFirmwareRevision);
      status_.answered.fetch_add(1, std::memory_order_relaxed);
      return send(msg, r, replies);
    }
    case kCmdOutputConf: {
      if (p.size() != 3 && p.size() != 5) return ack(msg, ErrorCode::invalid_frame, replies);
      const int port = port_index(p[0]);
      const int output = output_of(p[2], p[1]);
      if (port < 0 || output < 0 || !model_has(config_.model, output))
        return ack(msg, ErrorCode::invalid_parameter, replies);
      std::uint16_t& mode = current_.ports[static_cast<std::size_t>(port)].modes[static_cast<std::size_t>(output)];
      if (p.size() == 3) {
        std::uint8_t r[5] = {p[0], p[1], p[2], 0, 0};
        wire::put_le<std::uint16_t>(r + 3, mode);
        status_.answered.fetch_add(1, std::memory_order_relaxed);
        return send(msg, r, replies);
      }
      const std::uint16_t wanted = wire::get_le<std::uint16_t>(p.data() + 3);
      // [L] 20001 (the 1 kHz loop) is FAST_IMU_DATA's only mode besides disabled.
      const bool fast = output == kOutFastImu;
      if (!valid_output_mode(wanted) || (fast && wanted != kModeDisabled && wanted != kModeHighFreqLoop) ||
          (!fast && wanted == kModeHighFreqLoop))
        return ack(msg, ErrorCode::invalid_parameter, replies);
      if (mode != wanted) {
        mode = wanted;
        publish();
        log(std::string("output ") + output_info(output).rest_name + " mode " + std::to_string(wanted) + ": " +
            format_text());
      }
      return ack(msg, ErrorCode::no_error, replies);
    }
    case kCmdSettingsAction: {
      if (p.size() != 1) return ack(msg, ErrorCode::invalid_frame, replies);
      if (p[0] > kActionRestoreDefaults) return ack(msg, ErrorCode::invalid_parameter, replies);
      ack(msg, ErrorCode::no_error, replies);  // [S] the ACK leaves before the reboot
      if (p[0] == kActionSaveSettings) saved_ = current_;
      if (p[0] == kActionRestoreDefaults) saved_ = defaults_;
      reboot();
      return;
    }
    case kCmdApiGet:
    case kCmdApiPost: {
      // [R] NUL-terminated path, query and (POST) body.
      std::array<std::string_view, 3> parts;
      const std::size_t want = msg == kCmdApiPost ? 3 : 2;
      std::size_t at = 0;
      for (std::size_t i = 0; i < want; ++i) {
        if (at >= p.size()) return ack(msg, ErrorCode::invalid_frame, replies);
        const auto* start = p.data() + at;
        const auto* end = static_cast<const std::uint8_t*>(std::memchr(start, 0, p.size() - at));
        if (end == nullptr) return ack(msg, ErrorCode::invalid_frame, replies);
        parts[i] = std::string_view(reinterpret_cast<const char*>(start), static_cast<std::size_t>(end - start));
        at += parts[i].size() + 1;
      }
      if (at != p.size()) return ack(msg, ErrorCode::invalid_frame, replies);
      const auto [code, body] = rest(msg == kCmdApiPost, parts[0], parts[2]);
      std::vector<std::uint8_t> r(2 + body.size() + 1, 0);
      wire::put_le<std::uint16_t>(r.data(), code);
      std::memcpy(r.data() + 2, body.data(), body.size());
      if (r.size() > kMaxPayloadBytes) return ack(msg, ErrorCode::buffer_overflow, replies);
      if (code == 200) status_.answered.fetch_add(1, std::memory_order_relaxed);
      else status_.nacked.fetch_add(1, std::memory_order_relaxed);
      return send(msg, r, replies);
    }
    default:
      // A command this device does not implement: refused, nothing changes.
      return ack(msg, ErrorCode::invalid_frame, replies);
  }
}

std::pair<std::uint16_t, std::string> Device::rest(bool post, std::string_view path, std::string_view body) {
  auto method_not_allowed = [&] {
    return std::pair<std::uint16_t, std::string>{
        405, json_error(405, "Method Not Allowed", std::string(post ? "POST" : "GET") + " " + std::string(path))};
  };
  const std::string_view messages_prefix = "/api/v1/settings/output/";
  if (path == "/api/v1/info") {
    if (post) return method_not_allowed();
    char serial[16];
    std::snprintf(serial, sizeof serial, "%09u", static_cast<unsigned>(config_.serial_number));
    return {200, "{\"productCode\":\"" + product_code_ + "\",\"serialNumber\":\"" + serial + "\",\"hwRevision\":\"" +
                     kHardwareText + "\",\"mnfVersion\":\"" + kCalibrationText + "\",\"fmwVersion\":\"" +
                     kFirmwareText + "\",\"btVersion\":\"" + kBootloaderText + "\"}"};
  }
  if (path.substr(0, messages_prefix.size()) == messages_prefix) {
    const std::string_view rest_path = path.substr(messages_prefix.size());  // comA/messages[/name]
    const std::size_t slash = rest_path.find('/');
    const int port = port_index(rest_path.substr(0, slash));
    const std::string_view after = slash == std::string_view::npos ? std::string_view() : rest_path.substr(slash);
    if (port >= 0 && (after == "/messages" || after.substr(0, 10) == "/messages/"))
      return rest_messages(post, port, after.substr(9), body);
    return {404, json_error(404, "Not Found", std::string(path))};
  }
  if (path == "/api/v1/settings") {
    if (!post) return method_not_allowed();
    // Apply output.<port>.messages.<name> rates; refuse the whole body (nothing
    // applied) when one of them is not valid.
    Settings next = current_;
    std::string error;
    JsonReader reader(body, [&](const std::vector<std::string>& key, std::string_view value) {
      if (key.size() != 4 || key[0] != "output" || key[2] != "messages") return true;
      const int port = port_index(std::string_view(key[1]));
      const int output = output_named(key[3]);
      const int mode = output < 0 ? -1 : rest_mode_of(output, value);
      if (port < 0 || output < 0 || !model_has(config_.model, output) || mode < 0) return false;
      next.ports[static_cast<std::size_t>(port)].modes[static_cast<std::size_t>(output)] = static_cast<std::uint16_t>(mode);
      return true;
    });
    if (!reader.read(error)) return {400, json_error(400, "Bad Request", error)};
    if (!(next == current_)) {
      current_ = next;
      publish();
      log("settings posted: " + format_text());
    }
    return {200, "{\"needReboot\":false}"};
  }
  if (path == "/api/v1/settings/save" || path == "/api/v1/settings/default" || path == "/api/v1/system/reboot") {
    if (!post) return method_not_allowed();
    if (path == "/api/v1/settings/save") {
      saved_ = current_;
      log("settings saved: " + format_text());
      return {200, "{\"needReboot\":false}"};
    }
    if (path == "/api/v1/settings/default") {
      current_ = defaults_;
      publish();
      log("factory settings: " + format_text());
      return {200, "{\"needReboot\":false}"};
    }
    // The reply goes out first; the device then restarts on its saved settings.
    reboot();
    return {200, "{}"};
  }
  return {404, json_error(404, "Not Found", std::string(path))};
}

std::pair<std::uint16_t, std::string> Device::rest_messages(bool post, int port, std::string_view name_path,
                                                             std::string_view body) {
  StreamConfig& c = current_.ports[static_cast<std::size_t>(port)];
  if (name_path.empty()) {  // the whole list
    if (post) return {405, json_error(405, "Method Not Allowed", "POST a message's own path")};
    std::string s = "{";
    for (int i = 0; i < kOutputCount; ++i) {
      if (!model_has(config_.model, i)) continue;
      const char* rate = rest_rate_of(i, c.modes[static_cast<std::size_t>(i)]);
      s += std::string(s.size() > 1 ? "," : "") + "\"" + output_info(i).rest_name + "\":\"" +
           (rate != nullptr ? rate : "disabled") + "\"";
    }
    return {200, s + "}"};
  }
  const std::string_view name = name_path.substr(1);
  const int output = output_named(name);
  if (output < 0 || !model_has(config_.model, output))
    return {404, json_error(404, "Not Found", "no output message '" + std::string(name) + "' on this model")};
  std::uint16_t& mode = c.modes[static_cast<std::size_t>(output)];
  if (!post) {
    const char* rate = rest_rate_of(output, mode);
    return {200, "\"" + std::string(rate != nullptr ? rate : "disabled") + "\""};
  }
  std::string_view v = body;
  while (!v.empty() && (v.front() == ' ' || v.front() == '\n')) v.remove_prefix(1);
  while (!v.empty() && (v.back() == ' ' || v.back() == '\n')) v.remove_suffix(1);
  const int wanted = v.size() >= 2 && v.front() == '"' && v.back() == '"' ? rest_mode_of(output, v.substr(1, v.size() - 2)) : -1;
  if (wanted < 0)
    return {400, json_error(400, "Bad Request",
                            "'" + std::string(body) + "' is not a rate of " + std::string(name) +
                                " (\"disabled\", \"newData\", \"1ms\" .. \"1000ms\")")};
  if (mode != wanted) {
    mode = static_cast<std::uint16_t>(wanted);
    publish();
    log(std::string("output ") + output_info(output).rest_name + " " + rest_rate_of(output, mode) + ": " + format_text());
  }
  return {200, "{\"needReboot\":false}"};
}

}  // namespace imuemu::drivers::sbg
