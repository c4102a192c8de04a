// The Xsens MTi device's command side: Xbus framing of the host's messages,
// the commands, the settings, and the hand-over to the encoder. Sources in
// xsens_device.hpp.
#include "drivers/protocols/xsens_device.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <utility>

#include "drivers/protocols/wire_bytes.hpp"

namespace imuemu::drivers::xsens {

namespace {

// ReqEmts / EmtsData: not in [L]'s message list (the EMTS, the device's
// extended settings, are Xsens-internal); the ids and the request's two
// bytes (first page, page count) as xspublic's XsDevice::
// readEmtsAndDeviceConfiguration sends them. Kept here, not in xsens.hpp's
// table of documented messages.
constexpr std::uint8_t kReqEmts = 0x90;

template <class T>
void put(std::vector<std::uint8_t>& out, T v) {
  std::uint8_t b[sizeof(T)];
  wire::put_be<T>(b, v);
  out.insert(out.end(), b, b + sizeof(T));
}

std::string hex4(std::uint16_t v) {
  char b[8];
  std::snprintf(b, sizeof b, "%04X", static_cast<unsigned>(v));
  return b;
}

const char* message_name(std::uint8_t m) {
  switch (m) {
    case mid::kReqDid: return "ReqDID";
    case mid::kGotoConfig: return "GotoConfig";
    case mid::kGotoMeasurement: return "GotoMeasurement";
    case mid::kReqProductCode: return "ReqProductCode";
    case mid::kReqHardwareVersion: return "ReqHardwareVersion";
    case mid::kReqFwRev: return "ReqFWRev";
    case mid::kBaudrate: return "Req/SetBaudrate";
    case mid::kOutputConfiguration: return "Req/SetOutputConfiguration";
    case mid::kAlignmentRotation: return "Req/SetAlignmentRotation";
    case mid::kReset: return "Reset";
    case mid::kWakeUpAck: return "WakeUpAck";
    default: return "message";
  }
}

}  // namespace

Identity identity_of(const XsensDeviceConfig& config) {
  Identity id;
  // Presets: product codes as the parts print them, device ids in each
  // product class's range (legacy 32-bit ids: the class in bits 27..20;
  // MTi-600 series: 64-bit ids, the class in the product code), firmware as
  // the parts report it with current releases.
  switch (config.model) {
    case XsensModel::mti3:
      id.device_id = 0x03801A2B, id.product_code = "MTi-3-8A7G6";
      id.hardware_major = 3, id.hardware_minor = 1;
      id.firmware_major = 1, id.firmware_minor = 10, id.firmware_revision = 2;
      id.firmware_build = 59, id.firmware_svn = 117645;
      break;
    case XsensModel::mti7:
      id.device_id = 0x07801A2C, id.product_code = "MTi-7-8A7G6";
      id.hardware_major = 3, id.hardware_minor = 1;
      id.firmware_major = 1, id.firmware_minor = 10, id.firmware_revision = 2;
      id.firmware_build = 59, id.firmware_svn = 117645;
      break;
    case XsensModel::mti630:
      id.device_id = 0x0080001A2D, id.device_id_64bit = true, id.product_code = "MTi-630-8A1G6";
      id.hardware_major = 2, id.hardware_minor = 0;
      id.firmware_major = 1, id.firmware_minor = 12, id.firmware_revision = 0;
      id.firmware_build = 102, id.firmware_svn = 124587;
      break;
    case XsensModel::mti680g:
      id.device_id = 0x0080001A2E, id.device_id_64bit = true, id.product_code = "MTi-680G-8A1G6";
      id.hardware_major = 2, id.hardware_minor = 0;
      id.firmware_major = 1, id.firmware_minor = 12, id.firmware_revision = 0;
      id.firmware_build = 102, id.firmware_svn = 124587;
      break;
    case XsensModel::mti_g710:
      id.device_id = 0x07701A2F, id.product_code = "MTi-G-710-2A8G4";
      id.hardware_major = 2, id.hardware_minor = 5;
      id.firmware_major = 1, id.firmware_minor = 9, id.firmware_revision = 2;
      id.firmware_build = 41, id.firmware_svn = 91567;
      break;
  }
  if (config.device_id != 0) id.device_id = id.device_id_64bit ? (0x80000000ULL | config.device_id) : config.device_id;
  if (!config.product_code.empty()) id.product_code = config.product_code;
  if (!config.firmware_version.empty()) {
    unsigned a = 0, b = 0, c = 0;
    if (std::sscanf(config.firmware_version.c_str(), "%u.%u.%u", &a, &b, &c) == 3) {
      id.firmware_major = static_cast<std::uint8_t>(a);
      id.firmware_minor = static_cast<std::uint8_t>(b);
      id.firmware_revision = static_cast<std::uint8_t>(c);
    }
  }
  if (config.firmware_build != 0) id.firmware_build = config.firmware_build;
  if (config.firmware_svn != 0) id.firmware_svn = config.firmware_svn;
  return id;
}

std::uint32_t baud_of_code(std::uint8_t code) noexcept {
  switch (code) {
    case 0x00: return 460800;
    case 0x01: return 230400;
    case 0x02: return 115200;
    case 0x03: return 76800;
    case 0x04: return 57600;
    case 0x05: return 38400;
    case 0x06: return 28800;
    case 0x07: return 19200;
    case 0x08: return 14400;
    case 0x09: return 9600;
    case 0x0A: return 921600;
    case 0x0B: return 4800;
    case 0x0C: return 2000000;
    case 0x80: return 921600;
    default: return 0;
  }
}

std::optional<std::uint8_t> code_of_baud(std::uint32_t baud) noexcept {
  for (unsigned c = 0; c <= 0x0C; ++c)
    if (baud_of_code(static_cast<std::uint8_t>(c)) == baud) return static_cast<std::uint8_t>(c);
  return std::nullopt;
}

Device::Device(const XsensDeviceConfig& config, const ModelTraits& traits)
    : config_(config),
      traits_(traits),
      identity_(identity_of(config)),
      line_baud_(config.baud),
      published_(EmitConfig{}),
      latest_(Measurements{}) {
  defaults_.output = default_output_configuration(traits_);
  defaults_.baud_code = code_of_baud(config.baud).value_or(0x02);
  current_ = defaults_;
  publish();
}

void Device::set_log(std::function<void(std::string_view)> log) { status_.set_log(std::move(log)); }

CommandCounters Device::command_counters() const { return status_.counters(); }

std::string Device::format_text() const {
  std::string s = "MTData2";
  for (std::size_t i = 0; i < current_.output.count; ++i) {
    const OutputItem& it = current_.output.items[i];
    s += (i == 0 ? " " : ", ") + hex4(it.id) + "@" +
         (it.rate_hz == xdi::kEveryPacket ? std::string("every packet") : std::to_string(it.rate_hz) + " Hz");
  }
  return s;
}

void Device::publish() {
  EmitConfig e;
  e.measurement = measurement_;
  e.output = current_.output;
  e.rot_sensor_wxyz = current_.rot_sensor_wxyz;
  e.rot_local_wxyz = current_.rot_local_wxyz;
  e.restarts_handled = restarts_handled_;
  published_.publish(e);
  status_.set_mode_and_format(measurement_ ? "measurement" : "config", format_text());
  status_.set_baud(line_baud_);
}

void Device::take_restarts() {
  const std::uint64_t r = restarts_.load(std::memory_order_acquire);
  if (r == restarts_handled_) return;
  restarts_handled_ = r;
  measurement_ = true;  // [S] after power-up: measurement with the kept settings
  pending_.clear();
  publish();
  log("restarted: measurement, " + format_text());
}

std::vector<std::uint8_t> Device::output_configuration_data(const OutputConfiguration& c) const {
  std::vector<std::uint8_t> d;
  for (std::size_t i = 0; i < c.count; ++i) {
    put<std::uint16_t>(d, c.items[i].id);
    put<std::uint16_t>(d, c.items[i].rate_hz);
  }
  return d;
}

void Device::frame(std::uint8_t message_id, std::span<const std::uint8_t> data, ReplySink& replies) {
  status_.received.fetch_add(1, std::memory_order_relaxed);
  Outcome o = command(message_id, data);
  std::vector<std::uint8_t> bytes;
  if (o.error) {
    status_.nacked.fetch_add(1, std::memory_order_relaxed);
    const std::uint8_t code = static_cast<std::uint8_t>(*o.error);
    append_message(mid::kError, std::span<const std::uint8_t>(&code, 1), bytes);
    char line[96];
    std::snprintf(line, sizeof line, "refused MID 0x%02X (%s): error 0x%02X", message_id, message_name(message_id), code);
    log(line);
  } else if (!o.no_reply) {
    status_.answered.fetch_add(1, std::memory_order_relaxed);
    append_message(o.reply_mid, o.data, bytes);
    if (o.then_wake_up) append_message(mid::kWakeUp, {}, bytes);
  } else {
    status_.answered.fetch_add(1, std::memory_order_relaxed);
  }
  if (!bytes.empty() && !replies.reply(bytes)) status_.replies_dropped.fetch_add(1, std::memory_order_relaxed);
  if (o.baud_after) {
    replies.change_baud_after_replies(*o.baud_after);
    line_baud_ = *o.baud_after;
    status_.set_baud(line_baud_);
  }
}

Device::Outcome Device::command(std::uint8_t m, std::span<const std::uint8_t> data) {
  Outcome o;
  o.reply_mid = static_cast<std::uint8_t>(m + 1);
  auto refuse = [&](ErrorCode e) {
    o.error = e;
    return o;
  };
  const bool config_only = m == mid::kBaudrate || m == mid::kOutputConfiguration || m == mid::kAlignmentRotation ||
                           m == mid::kRestoreFactoryDef || m == mid::kReqConfiguration || m == mid::kOptionFlags ||
                           m == mid::kLocationId || m == mid::kFilterProfile || m == mid::kAvailableFilterProfiles ||
                           m == mid::kGnssPlatform || m == mid::kGnssLeverArm || m == mid::kStringOutputType ||
                           m == kReqEmts;
  if (config_only && measurement_) return refuse(ErrorCode::invalid_message);
  switch (m) {
    case mid::kWakeUpAck:
      o.no_reply = true;
      if (measurement_) {
        measurement_ = false;
        publish();
        log("WakeUpAck: config state");
      }
      return o;
    case mid::kGotoConfig:
      if (measurement_) {
        measurement_ = false;
        publish();
        log("config state");
      }
      return o;
    case mid::kGotoMeasurement:
      if (!measurement_) {
        measurement_ = true;
        publish();
        log("measurement state: " + format_text());
      }
      return o;
    case mid::kReqDid:
      if (identity_.device_id_64bit) put<std::uint64_t>(o.data, identity_.device_id);
      else put<std::uint32_t>(o.data, static_cast<std::uint32_t>(identity_.device_id));
      return o;
    case mid::kInitBus:
      // [L] InitBus: InitBusResults with the id of each device on the bus (this one).
      if (identity_.device_id_64bit) put<std::uint64_t>(o.data, identity_.device_id);
      else put<std::uint32_t>(o.data, static_cast<std::uint32_t>(identity_.device_id));
      return o;
    case mid::kReqProductCode: {
      // [L] ProductCode: 20 ASCII characters, padded with spaces (xspublic's
      // MtDevice::productCode reads 20 bytes and cuts at the first space).
      std::string padded = identity_.product_code;
      padded.resize(20, ' ');
      o.data.assign(padded.begin(), padded.end());
      return o;
    }
    case mid::kReqHardwareVersion:
      o.data = {identity_.hardware_major, identity_.hardware_minor};
      return o;
    case mid::kReqFwRev:
      o.data = {identity_.firmware_major, identity_.firmware_minor, identity_.firmware_revision};
      put<std::uint32_t>(o.data, identity_.firmware_build);
      put<std::uint32_t>(o.data, identity_.firmware_svn);
      return o;
    case mid::kSetNoRotation:
      if (data.size() != 2) return refuse(ErrorCode::invalid_parameter);
      log("SetNoRotation " + std::to_string(wire::get_be<std::uint16_t>(data.data())) + " s (acknowledged)");
      return o;
    case mid::kReqData: {
      // [L] ReqData: the device answers with the last measured data.
      const Measurements latest = latest_.read();
      std::vector<std::uint8_t> bytes;
      StreamConfig frames;
      frames.output = current_.output;
      frames.rot_sensor_wxyz = current_.rot_sensor_wxyz;
      frames.rot_local_wxyz = current_.rot_local_wxyz;
      o.reply_mid = mid::kMtData2;
      std::uint32_t clipped = 0;
      for (std::size_t i = 0; i < current_.output.count; ++i) {
        const std::uint16_t id = current_.output.items[i].id;
        put<std::uint16_t>(o.data, id);
        o.data.push_back(static_cast<std::uint8_t>(data_bytes(id)));
        append_item_data(id, frames, latest, 0, o.data, clipped);
      }
      return o;
    }
    case mid::kReset: {
      if (current_.baud_code != code_of_baud(line_baud_).value_or(0xFF)) o.baud_after = baud_of_code(current_.baud_code);
      o.then_wake_up = true;
      measurement_ = true;
      publish();
      log("reset: WakeUp, measurement state");
      return o;
    }
    case mid::kBaudrate:
      if (data.empty()) {
        o.data = {current_.baud_code};
        return o;
      }
      if (data.size() != 1 || baud_of_code(data[0]) == 0) return refuse(ErrorCode::invalid_baudrate);
      current_.baud_code = data[0];
      publish();
      log("baud rate " + std::to_string(baud_of_code(data[0])) + " after the next reset");
      return o;
    case mid::kOutputConfiguration: {
      if (data.empty()) {
        o.data = output_configuration_data(current_.output);
        return o;
      }
      if (data.size() % 4 != 0) return refuse(ErrorCode::invalid_parameter);
      std::vector<OutputItem> requested;
      for (std::size_t i = 0; i < data.size(); i += 4)
        requested.push_back({wire::get_be<std::uint16_t>(data.data() + i), wire::get_be<std::uint16_t>(data.data() + i + 2)});
      const std::optional<OutputConfiguration> applied = apply_output_configuration(traits_, requested);
      if (!applied) return refuse(ErrorCode::invalid_parameter);
      current_.output = *applied;
      publish();
      o.data = output_configuration_data(current_.output);
      log("output configuration: " + format_text());
      return o;
    }
    case mid::kAlignmentRotation: {
      if (data.size() == 1) {
        if (data[0] > 1) return refuse(ErrorCode::invalid_parameter);
        const auto& q = data[0] == 0 ? current_.rot_sensor_wxyz : current_.rot_local_wxyz;
        o.data = {data[0]};
        for (const double c : q) put<float>(o.data, static_cast<float>(c));
        return o;
      }
      if (data.size() != 17 || data[0] > 1) return refuse(ErrorCode::invalid_parameter);
      std::array<double, 4> q{};
      double norm2 = 0.0;
      for (std::size_t i = 0; i < 4; ++i) {
        q[i] = wire::get_be<float>(data.data() + 1 + 4 * i);
        norm2 += q[i] * q[i];
      }
      // A unit quaternion (float32 rounding allowed).
      if (!std::isfinite(norm2) || std::fabs(norm2 - 1.0) > 1e-3) return refuse(ErrorCode::invalid_parameter);
      (data[0] == 0 ? current_.rot_sensor_wxyz : current_.rot_local_wxyz) = q;
      publish();
      char line[128];
      std::snprintf(line, sizeof line, "alignment %s q = (%.7g, %.7g, %.7g, %.7g)", data[0] == 0 ? "RotSensor" : "RotLocal",
                    q[0], q[1], q[2], q[3]);
      log(line);
      return o;
    }
    case mid::kRestoreFactoryDef:
      current_ = defaults_;
      publish();
      log("factory defaults: " + format_text());
      return o;
    case mid::kReqConfiguration: {
      // [L] Configuration: 118 bytes (master part, one device's part).
      o.data.assign(118, 0);
      const auto low = static_cast<std::uint32_t>(identity_.device_id & 0xFFFFFFFFu);
      wire::put_be<std::uint32_t>(o.data.data(), low);
      if (identity_.device_id_64bit) {
        wire::put_be<std::uint32_t>(o.data.data() + 4, static_cast<std::uint32_t>(identity_.device_id >> 32));
        std::memcpy(o.data.data() + 32, identity_.product_code.data(), std::min<std::size_t>(20, identity_.product_code.size()));
      } else {
        wire::put_be<std::uint16_t>(o.data.data() + 4, static_cast<std::uint16_t>(115200 / traits_.max_rate_hz));  // sampling period (1/115200 s)
        wire::put_be<std::uint16_t>(o.data.data() + 6, 0);
      }
      wire::put_be<std::uint16_t>(o.data.data() + 96, 1);  // one device
      wire::put_be<std::uint32_t>(o.data.data() + 98, low);
      if (identity_.device_id_64bit)
        wire::put_be<std::uint32_t>(o.data.data() + 102, static_cast<std::uint32_t>(identity_.device_id >> 32));
      wire::put_be<std::uint16_t>(o.data.data() + 110, traits_.gnss ? 0x00C8 : 0x0032);  // filter profile
      o.data[112] = identity_.firmware_major;
      o.data[113] = identity_.firmware_minor;
      o.data[114] = identity_.firmware_revision;
      return o;
    }
    case mid::kOptionFlags:
      if (data.empty()) {
        put<std::uint32_t>(o.data, 0);  // no option set
        return o;
      }
      if (data.size() != 8) return refuse(ErrorCode::invalid_parameter);
      return o;  // kept at none: the options (AHS, in-run compass, ...) change no emulated output
    case mid::kLocationId:
      if (data.empty()) {
        put<std::uint16_t>(o.data, 0);
        return o;
      }
      return data.size() == 2 ? o : refuse(ErrorCode::invalid_parameter);
    case mid::kFilterProfile:
      if (data.empty()) {
        put<std::uint16_t>(o.data, traits_.gnss ? 0x00C8 : 0x0032);
        return o;
      }
      return refuse(ErrorCode::invalid_parameter);  // the one profile the device has
    case mid::kAvailableFilterProfiles: {
      // [L] AvailableFilterProfiles: per profile type u8, version u8, label (20 characters).
      const std::string label = traits_.gnss ? "GeneralMag" : "Robust";
      o.data.push_back(traits_.gnss ? 0xC8 : 0x32);
      o.data.push_back(1);
      std::string padded = label;
      padded.resize(20, ' ');
      o.data.insert(o.data.end(), padded.begin(), padded.end());
      return o;
    }
    case mid::kStringOutputType:
      // [L] StringOutputType (NMEA sentences beside MTData2): none is
      // emulated, so 0 is the one value taken.
      if (data.empty()) {
        put<std::uint16_t>(o.data, 0);
        return o;
      }
      return data.size() == 2 && wire::get_be<std::uint16_t>(data.data()) == 0 ? o : refuse(ErrorCode::invalid_parameter);
    case mid::kGnssPlatform:
      if (!traits_.gnss) return refuse(ErrorCode::invalid_message);
      if (data.empty()) {
        put<std::uint16_t>(o.data, 0);  // portable
        return o;
      }
      return data.size() == 2 ? o : refuse(ErrorCode::invalid_parameter);
    case mid::kGnssLeverArm:
      if (!traits_.gnss) return refuse(ErrorCode::invalid_message);
      if (data.empty()) {
        for (int i = 0; i < 3; ++i) put<float>(o.data, 0.0f);
        return o;
      }
      return data.size() == 12 ? o : refuse(ErrorCode::invalid_parameter);
    case kReqEmts:
      // EmtsData (0x91) with no pages: the blob's layout is not public and
      // xspublic does not parse it (it keeps it for a .mtb log's header);
      // what its transaction waits for is the reply's MID.
      if (data.size() != 2) return refuse(ErrorCode::invalid_parameter);
      log("ReqEmts: EmtsData without pages");
      return o;
    default: return refuse(ErrorCode::invalid_message);
  }
}

void Device::on_input(std::span<const std::uint8_t> bytes, ReplySink& replies) {
  take_restarts();
  pending_.insert(pending_.end(), bytes.begin(), bytes.end());
  std::size_t pos = 0;
  std::uint64_t stray = 0;
  const std::size_t n = pending_.size();
  while (pos < n) {
    if (pending_[pos] != kPreamble) {
      ++stray, ++pos;
      continue;
    }
    if (pos + 4 > n) break;
    if (pending_[pos + 1] != kMasterBusId) {
      ++stray, ++pos;
      continue;
    }
    std::size_t header = 4, length = pending_[pos + 3];
    if (length == kExtendedLength) {
      if (pos + 6 > n) break;
      header = 6;
      length = (std::size_t{pending_[pos + 4]} << 8) | pending_[pos + 5];
      if (length > kMaxPayloadBytes) {
        ++stray, ++pos;
        continue;
      }
    }
    if (pos + header + length + 1 > n) break;
    unsigned sum = 0;
    for (std::size_t i = pos + 1; i < pos + header + length + 1; ++i) sum += pending_[i];
    if ((sum & 0xFF) != 0) {
      ++stray, ++pos;
      continue;
    }
    frame(pending_[pos + 2], std::span<const std::uint8_t>(pending_.data() + pos + header, length), replies);
    pos += header + length + 1;
  }
  pending_.erase(pending_.begin(), pending_.begin() + static_cast<std::ptrdiff_t>(pos));
  if (stray != 0) status_.not_command_bytes.fetch_add(stray, std::memory_order_relaxed);
}

}  // namespace imuemu::drivers::xsens
