// The VectorNav device's command side: sentence framing, the $VN commands,
// the registers, and the hand-over to the encoder. Sources in
// vectornav_device.hpp.
#include "drivers/protocols/vectornav_device.hpp"

#include <algorithm>
#include <charconv>
#include <stdexcept>
#include <cstdio>
#include <utility>

namespace imuemu::drivers::vectornav {

namespace {

// A sentence longer than this without its line end is not a command (the
// device's input buffer; the longest write, a binary output register with
// every group, is under 60 characters).
constexpr std::size_t kMaxSentenceBytes = 256;
// [R] register 5's rates.
constexpr std::array<std::uint32_t, 9> kBaudRates{9600, 19200, 38400, 57600, 115200, 128000, 230400, 460800, 921600};

std::optional<std::uint32_t> parse_decimal(std::string_view s) {
  std::uint32_t v = 0;
  if (s.empty() || s.size() > 10) return std::nullopt;
  const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), v, 10);
  if (ec != std::errc() || ptr != s.data() + s.size()) return std::nullopt;
  return v;
}
std::optional<std::uint32_t> parse_hex(std::string_view s) {
  std::uint32_t v = 0;
  if (s.empty() || s.size() > 8) return std::nullopt;
  const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), v, 16);
  if (ec != std::errc() || ptr != s.data() + s.size()) return std::nullopt;
  return v;
}
std::vector<std::string_view> split(std::string_view body) {
  std::vector<std::string_view> t;
  std::size_t start = 0;
  for (;;) {
    const std::size_t comma = body.find(',', start);
    t.push_back(body.substr(start, comma == std::string_view::npos ? std::string_view::npos : comma - start));
    if (comma == std::string_view::npos) return t;
    start = comma + 1;
  }
}
// [U] the error codes' names, for messages.
const char* error_name(ErrorCode code) {
  switch (code) {
    case ErrorCode::hard_fault: return "hard fault";
    case ErrorCode::serial_buffer_overflow: return "serial buffer overflow";
    case ErrorCode::invalid_checksum: return "invalid checksum";
    case ErrorCode::invalid_command: return "invalid command";
    case ErrorCode::not_enough_parameters: return "not enough parameters";
    case ErrorCode::too_many_parameters: return "too many parameters";
    case ErrorCode::invalid_parameter: return "invalid parameter";
    case ErrorCode::invalid_register: return "invalid register";
    case ErrorCode::unauthorized_access: return "unauthorized access";
    case ErrorCode::watchdog_reset: return "watchdog reset";
    case ErrorCode::output_buffer_overflow: return "output buffer overflow";
    case ErrorCode::insufficient_baud_rate: return "insufficient baud rate";
  }
  return "error";
}
std::string two_digits(int id) {
  char b[8];
  std::snprintf(b, sizeof b, "%02d", id);
  return b;
}
std::string binary_text(const BinaryOutput& o) {
  char b[96];
  int n = std::snprintf(b, sizeof b, "%u,%u,%02X", static_cast<unsigned>(o.async_mode),
                        static_cast<unsigned>(o.rate_divisor), static_cast<unsigned>(o.groups));
  std::string s(b, static_cast<std::size_t>(n));
  for (int g = 0; g < kGroupCount; ++g) {
    if ((o.groups & (1u << g)) == 0) continue;
    n = std::snprintf(b, sizeof b, ",%04X", static_cast<unsigned>(o.fields[static_cast<std::size_t>(g)]));
    s.append(b, static_cast<std::size_t>(n));
  }
  return s;
}
template <std::size_t N>
std::string list_text(const std::array<std::uint32_t, N>& v) {
  std::string s;
  for (const std::uint32_t x : v) s += (s.empty() ? "" : ",") + std::to_string(x);
  return s;
}
}  // namespace

std::string model_number_of(const VectorNavDeviceConfig& config) {
  if (!config.model_number.empty()) return config.model_number;
  switch (config.model) {
    case VectorNavModel::vn100: return "VN-100T-CR";
    case VectorNavModel::vn200: return "VN-200T-CR";
    case VectorNavModel::vn300: return "VN-300T-CR";
  }
  return "VN-100T-CR";
}

std::string firmware_version_of(const VectorNavDeviceConfig& config) {
  return config.firmware_version.empty() ? "2.1.0.0" : config.firmware_version;
}

Device::Device(const VectorNavDeviceConfig& config, const ModelTraits& traits)
    : config_(config),
      traits_(traits),
      model_number_(model_number_of(config)),
      firmware_(firmware_version_of(config)),
      published_(EmitConfig{}),
      latest_(Measurements{}) {
  const StreamConfig power_up = Encoder::power_up_config(config);
  defaults_.user_tag = config.user_tag;
  for (PortSettings& p : defaults_.ports) {
    p.ador = power_up.ador;
    p.adof_hz = power_up.adof_hz;
  }
  current_ = saved_ = defaults_;
  apply_saved_registers();
  publish();
}

void Device::apply_saved_registers() {
  std::string_view rest = config_.saved_registers;
  while (!rest.empty()) {
    const std::size_t semicolon = rest.find(';');
    const std::string_view item = rest.substr(0, semicolon);
    rest = semicolon == std::string_view::npos ? std::string_view() : rest.substr(semicolon + 1);
    if (item.empty()) continue;
    std::vector<std::string_view> tokens{"VNWRG"};
    for (const std::string_view t : split(item)) tokens.push_back(t);
    const Outcome o = write_register(tokens);
    if (o.error) {
      char code[8];
      std::snprintf(code, sizeof code, "%02X", static_cast<unsigned>(*o.error));
      throw std::invalid_argument("saved register write '" + std::string(item) +
                                  "': the device refuses it ($VNERR," + code + ", " + error_name(*o.error) + ")");
    }
  }
  saved_ = current_;  // $VNWNV
}

std::optional<std::string> saved_registers_problem(const VectorNavDeviceConfig& config) {
  try {
    const Device device(config, traits_of(config.model));
  } catch (const std::invalid_argument& e) {
    return std::string(e.what());
  }
  return std::nullopt;
}

void Device::set_log(std::function<void(std::string_view)> log) { status_.set_log(std::move(log)); }

CommandCounters Device::command_counters() const { return status_.counters(); }

std::string Device::format_text() const {
  std::string s;
  const PortSettings& p = own_port();
  const char* h = ador_header(p.ador);
  s = h != nullptr ? std::string("VN") + h + " at " + std::to_string(p.adof_hz) + " Hz" : std::string("no ASCII output");
  const std::uint8_t port_bit = static_cast<std::uint8_t>(1u << (config_.port - 1));
  for (std::size_t i = 0; i < current_.binary.size(); ++i) {
    const BinaryOutput& o = current_.binary[i];
    if ((o.async_mode & port_bit) == 0 || o.groups == 0) continue;
    s += "; binary " + std::to_string(i + 1) + " " + binary_text(o);
  }
  return s;
}

void Device::publish() {
  EmitConfig e;
  auto fill = [&](StreamConfig& c, const Settings& s, bool enabled) {
    const PortSettings& p = s.ports[static_cast<std::size_t>(config_.port - 1)];
    c.async_enabled = enabled;
    c.ador = p.ador;
    c.adof_hz = p.adof_hz;
    c.crc16_mode = s.protocol_control[4] == 2;
    c.binary = s.binary;
    c.sync_out_mode = static_cast<std::uint8_t>(s.sync_control[4]);
    c.sync_out_positive = s.sync_control[5] == 1;
    c.sync_out_skip = static_cast<std::uint16_t>(s.sync_control[6]);
    c.sync_out_width_ns = s.sync_control[7];
  };
  fill(e, current_, async_enabled_);
  fill(e.startup, saved_, true);
  e.restarts_handled = restarts_handled_;
  published_.publish(e);
  status_.set_mode_and_format(async_enabled_ ? "streaming" : "paused ($VNASY,0)", format_text());
  status_.set_baud(own_port().baud);
}

void Device::take_restarts() {
  const std::uint64_t r = restarts_.load(std::memory_order_acquire);
  if (r == restarts_handled_) return;
  restarts_handled_ = r;
  current_ = saved_;
  async_enabled_ = true;
  publish();
  log("restarted: saved settings, " + format_text());
}

void Device::on_input(std::span<const std::uint8_t> bytes, ReplySink& replies) {
  take_restarts();
  std::uint64_t stray = 0;
  for (const std::uint8_t b : bytes) {
    if (b == '$') {
      stray += pending_.size();  // a sentence cut short by the next one
      pending_.assign(1, '$');
      continue;
    }
    if (pending_.empty()) {
      if (b != '\r' && b != '\n') ++stray;
      continue;
    }
    if (b == '\r' || b == '\n') {
      const std::string text = std::move(pending_);
      pending_.clear();
      sentence(text, replies);
      continue;
    }
    pending_.push_back(static_cast<char>(b));
    if (pending_.size() > kMaxSentenceBytes) {
      stray += pending_.size();
      pending_.clear();
    }
  }
  if (stray != 0) status_.not_command_bytes.fetch_add(stray, std::memory_order_relaxed);
}

void Device::reply_text(const std::string& body, ReplySink& replies) {
  char buf[kMaxSentenceBytes + 16];
  if (body.size() + 1 > kMaxSentenceBytes) return;
  buf[0] = '$';
  std::copy(body.begin(), body.end(), buf + 1);
  const std::size_t n = finish_sentence(buf, body.size() + 1, sizeof buf, current_.protocol_control[4] == 2);
  if (n == 0) return;
  if (!replies.reply(std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(buf), n)))
    status_.replies_dropped.fetch_add(1, std::memory_order_relaxed);
}

void Device::sentence(std::string_view text, ReplySink& replies) {
  // text = "$" body ["*" checksum]
  const std::size_t star = text.find('*');
  const std::string_view body = text.substr(1, star == std::string_view::npos ? std::string_view::npos : star - 1);
  if (body.size() < 5 || body.substr(0, 2) != "VN") {
    status_.not_command_bytes.fetch_add(text.size(), std::memory_order_relaxed);  // not addressed to a VectorNav device
    return;
  }
  status_.received.fetch_add(1, std::memory_order_relaxed);
  Outcome o;
  bool checksum_ok = true;
  if (star != std::string_view::npos) {
    const std::string_view sum = text.substr(star + 1);
    const bool skip = (sum.size() == 2 || sum.size() == 4) &&
                      std::all_of(sum.begin(), sum.end(), [](char c) { return c == 'X' || c == 'x'; });
    if (!skip) {
      const std::optional<std::uint32_t> v = parse_hex(sum);
      const auto bytes = std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(body.data()), body.size());
      checksum_ok = v && ((sum.size() == 2 && *v == checksum8(body)) || (sum.size() == 4 && *v == crc16(bytes)));
    }
  }
  if (!checksum_ok) o.error = ErrorCode::invalid_checksum;
  else o = command(split(body));

  if (o.error) {
    status_.nacked.fetch_add(1, std::memory_order_relaxed);
    const std::uint32_t error_mode = current_.protocol_control[6];
    if (error_mode == 0) return;  // [R] register 30 error mode 0: errors ignored, no reply
    char b[16];
    std::snprintf(b, sizeof b, "VNERR,%02X", static_cast<unsigned>(*o.error));
    reply_text(b, replies);
    if (error_mode == 2 && own_port().ador != kAdorOff) {  // error mode 2: the async output goes off
      own_port().ador = kAdorOff;
      publish();
    }
    return;
  }
  status_.answered.fetch_add(1, std::memory_order_relaxed);
  if (!o.binary.empty()) {
    if (!replies.reply(o.binary)) status_.replies_dropped.fetch_add(1, std::memory_order_relaxed);
  } else {
    reply_text(o.body, replies);
  }
  if (o.baud_after) {
    // The reply leaves at the old rate; the line changes after it (the sink
    // applies it once every reply queued so far has gone).
    replies.change_baud_after_replies(*o.baud_after);
    log("baud " + std::to_string(*o.baud_after) + " after this reply");
    status_.set_baud(*o.baud_after);
  }
}

Device::Outcome Device::command(const std::vector<std::string_view>& t) {
  Outcome o;
  const std::string_view name = t[0].substr(2);
  auto error = [&](ErrorCode c) {
    o.error = c;
    return o;
  };
  const std::uint32_t old_baud = own_port().baud;
  if (name == "RRG") return read_register(t);
  if (name == "WRG") return write_register(t);
  if (name == "ASY") {  // pause (0) / resume (1) every async output
    if (t.size() < 2) return error(ErrorCode::not_enough_parameters);
    if (t.size() > 2) return error(ErrorCode::too_many_parameters);
    const std::optional<std::uint32_t> v = parse_decimal(t[1]);
    if (!v || *v > 1) return error(ErrorCode::invalid_parameter);
    if (async_enabled_ != (*v == 1)) {
      async_enabled_ = *v == 1;
      publish();
      log(async_enabled_ ? "async outputs resumed ($VNASY,1)" : "async outputs paused ($VNASY,0)");
    }
    o.body = "VNASY," + std::to_string(*v);
    return o;
  }
  if (name == "WNV" || name == "RFS" || name == "RST") {
    if (t.size() > 1) return error(ErrorCode::too_many_parameters);
    if (name == "WNV") {
      saved_ = current_;
    } else {
      if (name == "RFS") saved_ = defaults_;
      current_ = name == "RFS" ? defaults_ : saved_;
      if (name == "RST") async_enabled_ = true;
      publish();
      log(std::string(name == "RFS" ? "factory settings restored: " : "reset: ") + format_text());
      if (own_port().baud != old_baud) o.baud_after = own_port().baud;
    }
    o.body = "VN" + std::string(name);
    return o;
  }
  if (name == "BOM") {  // poll binary output n: its packet with the latest sample
    if (t.size() < 2) return error(ErrorCode::not_enough_parameters);
    if (t.size() > 2) return error(ErrorCode::too_many_parameters);
    const std::optional<std::uint32_t> n = parse_decimal(t[1]);
    if (!n || *n < 1 || *n > 3 || current_.binary[*n - 1].groups == 0) return error(ErrorCode::invalid_parameter);
    append_binary_packet(current_.binary[*n - 1], latest_.read(), o.binary);
    return o;
  }
  return error(ErrorCode::invalid_command);
}

std::optional<std::string> Device::register_text(int id, std::optional<int> port) const {
  auto with_port = [&](std::uint32_t v) {
    std::string s = std::to_string(v);
    if (port) s += "," + std::to_string(*port);
    return s;
  };
  const std::size_t p = static_cast<std::size_t>(port.value_or(config_.port) - 1);
  std::uint8_t ador = 0;
  switch (id) {
    case 0: return current_.user_tag;
    case 1: return model_number_;
    case 2: return std::to_string(config_.hardware_revision);
    case 3: return std::to_string(config_.serial_number);
    case 4: return firmware_;
    case 5: return with_port(current_.ports[p].baud);
    case 6: return with_port(current_.ports[p].ador);
    case 7: return with_port(current_.ports[p].adof_hz);
    case 30: return list_text(current_.protocol_control);
    case 32: return list_text(current_.sync_control);
    case 35: return list_text(current_.vpe_basic);
    case 75: case 76: case 77: return binary_text(current_.binary[static_cast<std::size_t>(id - 75)]);
    case 8: ador = kAdorYpr; break;
    case 9: ador = kAdorQtn; break;
    case 15: ador = kAdorQmr; break;
    case 17: ador = kAdorMag; break;
    case 18: ador = kAdorAcc; break;
    case 19: ador = kAdorGyr; break;
    case 20: ador = kAdorMar; break;
    case 27: ador = kAdorYmr; break;
    default: return std::nullopt;
  }
  // A measurement register: the latest sample, formatted as its async output.
  char buf[kMaxSentenceBytes];
  const std::size_t n = format_ascii_fields(ador, latest_.read(), buf, sizeof buf);
  return std::string(buf, n);
}

Device::Outcome Device::read_register(const std::vector<std::string_view>& t) {
  Outcome o;
  if (t.size() < 2) {
    o.error = ErrorCode::not_enough_parameters;
    return o;
  }
  const std::optional<std::uint32_t> id = parse_decimal(t[1]);
  if (!id || *id > 255) {
    o.error = ErrorCode::invalid_register;
    return o;
  }
  std::optional<int> port;
  const bool has_port_field = *id >= 5 && *id <= 7;
  if (t.size() > (has_port_field ? 3u : 2u)) {
    o.error = ErrorCode::too_many_parameters;
    return o;
  }
  if (t.size() == 3) {
    // [R] "?" asks for the port the command came in on.
    if (t[2] == "?") port = config_.port;
    else if (t[2] == "1" || t[2] == "2") port = t[2][0] - '0';
    else {
      o.error = ErrorCode::invalid_parameter;
      return o;
    }
  }
  const std::optional<std::string> text = register_text(static_cast<int>(*id), port);
  if (!text) {
    o.error = ErrorCode::invalid_register;
    return o;
  }
  o.body = "VNRRG," + two_digits(static_cast<int>(*id)) + "," + *text;
  return o;
}

Device::Outcome Device::write_register(const std::vector<std::string_view>& t) {
  Outcome o;
  auto error = [&](ErrorCode c) {
    o.error = c;
    return o;
  };
  if (t.size() < 3) return error(ErrorCode::not_enough_parameters);
  const std::optional<std::uint32_t> id_value = parse_decimal(t[1]);
  if (!id_value || *id_value > 255) return error(ErrorCode::invalid_register);
  const int id = static_cast<int>(*id_value);
  const std::size_t values = t.size() - 2;
  auto value = [&](std::size_t i) { return parse_decimal(t[2 + i]); };
  Settings next = current_;
  std::optional<int> port;  // registers 5-7: the port the write names
  switch (id) {
    case 0: {
      if (values > 1) return error(ErrorCode::too_many_parameters);
      const std::string_view tag = t[2];
      const bool printable = std::all_of(tag.begin(), tag.end(), [](char c) { return c >= ' ' && c <= '~' && c != '$'; });
      if (tag.size() > 20 || !printable) return error(ErrorCode::invalid_parameter);
      next.user_tag = std::string(tag);
      break;
    }
    case 1: case 2: case 3: case 4: case 8: case 9: case 15: case 17: case 18: case 19: case 20: case 27:
      return error(ErrorCode::unauthorized_access);  // read-only
    case 5: case 6: case 7: {
      if (values > 2) return error(ErrorCode::too_many_parameters);
      if (values == 2) {
        if (t[3] != "1" && t[3] != "2") return error(ErrorCode::invalid_parameter);
        port = t[3][0] - '0';
      }
      const std::optional<std::uint32_t> v = value(0);
      PortSettings& p = next.ports[static_cast<std::size_t>(port.value_or(config_.port) - 1)];
      if (!v) return error(ErrorCode::invalid_parameter);
      if (id == 5) {
        if (std::find(kBaudRates.begin(), kBaudRates.end(), *v) == kBaudRates.end())
          return error(ErrorCode::invalid_parameter);
        p.baud = *v;
      } else if (id == 6) {
        const bool known = *v == kAdorOff || (ador_header(static_cast<std::uint8_t>(*v)) != nullptr && *v <= 255);
        if (!known || (*v == kAdorIns && !traits_.ins)) return error(ErrorCode::invalid_parameter);
        p.ador = static_cast<std::uint8_t>(*v);
      } else {
        if (std::find(kAdofRates.begin(), kAdofRates.end(), *v) == kAdofRates.end())
          return error(ErrorCode::invalid_parameter);
        p.adof_hz = static_cast<std::uint16_t>(*v);
      }
      break;
    }
    case 30: {
      if (values < 7) return error(ErrorCode::not_enough_parameters);
      if (values > 7) return error(ErrorCode::too_many_parameters);
      for (std::size_t i = 0; i < 7; ++i) {
        const std::optional<std::uint32_t> v = value(i);
        if (!v) return error(ErrorCode::invalid_parameter);
        next.protocol_control[i] = *v;
      }
      const auto& pc = next.protocol_control;
      // The serial count / status appends are not emulated: only 0 (none)
      // is taken; SPI's are kept as written (no SPI port).
      if (pc[0] != 0 || pc[1] != 0 || pc[4] < 1 || pc[4] > 2 || pc[5] > 2 || pc[6] > 2 || pc[2] > 6 || pc[3] > 5)
        return error(ErrorCode::invalid_parameter);
      break;
    }
    case 32: case 35: {
      const std::size_t want = id == 32 ? 9 : 4;
      if (values < want) return error(ErrorCode::not_enough_parameters);
      if (values > want) return error(ErrorCode::too_many_parameters);
      for (std::size_t i = 0; i < want; ++i) {
        const std::optional<std::uint32_t> v = value(i);
        if (!v) return error(ErrorCode::invalid_parameter);
        if (id == 32) next.sync_control[i] = *v;
        else if (*v > 255) return error(ErrorCode::invalid_parameter);
        else next.vpe_basic[i] = *v;
      }
      if (id == 32) {
        // [U] SyncOutMode 0 none, 1 ItStart, 2 ImuReady, 3 Ins, 6 GpsPps (a
        // GNSS model's); polarity 0 / 1; the skip factor a uint16.
        const auto& sc = next.sync_control;
        const bool mode_ok = sc[4] <= kSyncOutIns || (sc[4] == kSyncOutGpsPps && traits_.ins);
        if (!mode_ok || sc[5] > 1 || sc[6] > 0xFFFF) return error(ErrorCode::invalid_parameter);
      }
      break;
    }
    case 75: case 76: case 77: {
      if (values < 3) return error(ErrorCode::not_enough_parameters);
      const std::optional<std::uint32_t> mode = parse_hex(t[2]);
      const std::optional<std::uint32_t> divisor = value(1);
      const std::optional<std::uint32_t> groups = parse_hex(t[4]);
      if (!mode || *mode > 3 || !divisor || *divisor > 65535 || !groups) return error(ErrorCode::invalid_parameter);
      // No extension groups (bit 7) and only the groups this model has.
      if (*groups > 0x7F || (*groups & ~std::uint32_t{traits_.groups}) != 0) return error(ErrorCode::invalid_parameter);
      BinaryOutput b;
      b.async_mode = static_cast<std::uint8_t>(*mode);
      b.rate_divisor = static_cast<std::uint16_t>(*divisor);
      b.groups = static_cast<std::uint8_t>(*groups);
      std::size_t at = 5;
      for (int g = 0; g < kGroupCount; ++g) {
        if ((b.groups & (1u << g)) == 0) continue;
        if (at >= t.size()) return error(ErrorCode::not_enough_parameters);
        const std::optional<std::uint32_t> f = parse_hex(t[at++]);
        if (!f || *f == 0 || *f > 0xFFFF) return error(ErrorCode::invalid_parameter);
        for (int bit = 0; bit < 16; ++bit)
          if ((*f & (1u << bit)) != 0 && field_bytes(g, bit) == 0) return error(ErrorCode::invalid_parameter);
        b.fields[static_cast<std::size_t>(g)] = static_cast<std::uint16_t>(*f);
      }
      if (at != t.size()) return error(ErrorCode::too_many_parameters);
      if (b.async_mode != 0 && b.groups != 0 && b.rate_divisor == 0) return error(ErrorCode::invalid_parameter);
      next.binary[static_cast<std::size_t>(id - 75)] = b;
      break;
    }
    default: return error(ErrorCode::invalid_register);
  }
  // [U] a configuration whose binary outputs need more than a port's line
  // rate carries (10 bits per byte) is refused: insufficient baud rate.
  for (int p = 1; p <= 2; ++p) {
    double bits_per_s = 0.0;
    for (const BinaryOutput& b : next.binary) {
      if ((b.async_mode & (1u << (p - 1))) == 0 || b.groups == 0 || b.rate_divisor == 0) continue;
      bits_per_s += 10.0 * static_cast<double>(packet_bytes(b)) * traits_.imu_rate_hz / b.rate_divisor;
    }
    if (bits_per_s > static_cast<double>(next.ports[static_cast<std::size_t>(p - 1)].baud))
      return error(ErrorCode::insufficient_baud_rate);
  }
  const std::uint32_t old_baud = own_port().baud;
  current_ = std::move(next);
  if (id != 0) {
    publish();
    log("register " + std::to_string(id) + " written: " + format_text());
  }
  if (own_port().baud != old_baud) o.baud_after = own_port().baud;
  o.body = "VNWRG," + two_digits(id) + "," + *register_text(id, port);
  return o;
}

}  // namespace imuemu::drivers::vectornav
