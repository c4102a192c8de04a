// The driver's side of a start-up: see handshake.hpp.
#include "drivers/protocols/handshake.hpp"

#include <algorithm>
#include <array>
#include <cstdio>
#include <cstring>
#include <string_view>

#include "drivers/protocols/mavlink2.hpp"
#include "drivers/protocols/mavlink_device.hpp"
#include "drivers/protocols/mip_device.hpp"
#include "drivers/protocols/vectornav.hpp"
#include "drivers/protocols/sbg.hpp"
#include "drivers/protocols/xsens.hpp"
#include "drivers/protocols/wire_bytes.hpp"

namespace imuemu::drivers::handshake {
namespace {

std::string hex2(unsigned x) {
  char b[8];
  std::snprintf(b, sizeof b, "0x%02X", x & 0xFFu);
  return b;
}

// ---------------------------------------------------------------- MIP

// [DCP] ACK/NACK error codes.
std::string mip_ack_text(std::uint8_t code) {
  switch (code) {
    case 0x00: return "ACK";
    case 0x01: return "NACK 0x01 (unknown command)";
    case 0x02: return "NACK 0x02 (invalid checksum)";
    case 0x03: return "NACK 0x03 (invalid parameter)";
    case 0x04: return "NACK 0x04 (command failed)";
    case 0x05: return "NACK 0x05 (command timed out)";
    default: return "NACK " + hex2(code);
  }
}

// A 16-character [DCP] string field, its padding (spaces or NULs) removed.
std::string mip_string16(std::span<const std::uint8_t> data, std::size_t at) {
  if (data.size() < at + 16) return "?";
  std::string s(reinterpret_cast<const char*>(data.data() + at), 16);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\0')) s.pop_back();
  while (!s.empty() && s.front() == ' ') s.erase(s.begin());
  return s;
}

struct MipStep {
  const char* name;
  std::uint8_t descriptor_set;
  std::vector<std::uint8_t> field;  // descriptor, then data
};

class MipClient final : public Client {
 public:
  MipClient()
      : steps_{{"Ping (0x01,0x01)", 0x01, {0x01}},
               {"Set To Idle (0x01,0x02)", 0x01, {0x02}},
               {"Get Device Information (0x01,0x03)", 0x01, {0x03}},
               {"Get Device Descriptors (0x01,0x04)", 0x01, {0x04}},
               {"Get Base Rate of 0x80 (0x0C,0x0E)", 0x0C, {0x0E, 0x80}},
               {"Read Message Format of 0x80 (0x0C,0x0F)", 0x0C, {0x0F, 0x02, 0x80}},
               {"Resume (0x01,0x06)", 0x01, {0x06}}} {}

  std::size_t step_count() const override { return steps_.size(); }
  std::string step_name(std::size_t step) const override { return steps_.at(step).name; }
  std::vector<std::uint8_t> request(std::size_t step) override {
    const MipStep& s = steps_.at(step);
    const std::array<std::vector<std::uint8_t>, 1> fields{s.field};
    return mip::make_packet(s.descriptor_set, fields);
  }

  bool feed(std::size_t step, std::span<const std::uint8_t> bytes, StepResult& result) override {
    const MipStep& s = steps_.at(step);
    bool done = false;
    parser_.feed(bytes, std::chrono::steady_clock::now(),
                 [&](std::uint8_t set, std::span<const std::uint8_t> payload) {
                   if (done || set != s.descriptor_set) return;  // stream data, or another set's reply
                   done = read_reply(s, payload, result);
                 });
    return done;
  }

 private:
  // A reply packet: an ACK/NACK field (0xF1: command echo, error code) for
  // this step's command, then its data fields.
  static bool read_reply(const MipStep& s, std::span<const std::uint8_t> payload, StepResult& result) {
    bool ours = false;
    std::string text;
    for (std::size_t at = 0; at + 2 <= payload.size();) {
      const std::size_t len = payload[at];
      if (len < 2 || at + len > payload.size()) break;
      const std::uint8_t descriptor = payload[at + 1];
      const std::span<const std::uint8_t> data = payload.subspan(at + 2, len - 2);
      at += len;
      if (descriptor == 0xF1 && data.size() >= 2) {
        if (data[0] != s.field[0]) return false;  // the ACK of another command
        ours = true;
        result.accepted = data[1] == 0x00;
        text = mip_ack_text(data[1]);
      } else if (ours) {
        text += "; " + describe_field(descriptor, data);
      }
    }
    if (!ours) return false;
    result.answered = true;
    result.reply = text;
    return true;
  }

  static std::string describe_field(std::uint8_t descriptor, std::span<const std::uint8_t> data) {
    switch (descriptor) {
      case 0x81:  // Device Information [DCP 0x01,0x03]: u16 firmware, five 16-char strings
        if (data.size() >= 2 + 5 * 16) {
          const unsigned fw = wire::get_be<std::uint16_t>(data.data());
          char firmware[32];
          // mip_sdk prints version v as v/1000 . v/100%10 . v%100 (1108 -> 1.1.08).
          std::snprintf(firmware, sizeof firmware, "%u.%u.%02u", fw / 1000, fw / 100 % 10, fw % 100);
          return "model '" + mip_string16(data, 2) + "', model number '" + mip_string16(data, 18) + "', serial '" +
                 mip_string16(data, 34) + "', lot '" + mip_string16(data, 50) + "', options '" +
                 mip_string16(data, 66) + "', firmware " + firmware;
        }
        break;
      case 0x82:  // Device Descriptors: u16 each
        return std::to_string(data.size() / 2) + " descriptors";
      case 0x8E:  // Base Rate: set, u16 Hz
        if (data.size() >= 3)
          return "base rate of " + hex2(data[0]) + ": " + std::to_string(wire::get_be<std::uint16_t>(data.data() + 1)) +
                 " Hz";
        break;
      case 0x8F: {  // Message Format: set, count, (field, u16 decimation) each
        if (data.size() < 2) break;
        std::string s = "format of " + hex2(data[0]) + ":";
        const std::size_t n = data[1];
        if (n == 0) s += " no fields";
        for (std::size_t i = 0; i < n && 2 + 3 * i + 3 <= data.size(); ++i) {
          const std::uint8_t* f = data.data() + 2 + 3 * i;
          s += " " + hex2(f[0]) + "/" + std::to_string(wire::get_be<std::uint16_t>(f + 1));
        }
        return s + " (field/decimation)";
      }
      default: break;
    }
    return "field " + hex2(descriptor) + " (" + std::to_string(data.size()) + " bytes)";
  }

  std::vector<MipStep> steps_;
  mip::CommandParser parser_;
};

// ---------------------------------------------------------------- MAVLink

// [X] common.xml messages the ground station side writes or reads.
constexpr std::uint32_t kAutopilotVersionMessageId = 148;  // [X] AUTOPILOT_VERSION
constexpr std::uint8_t kGcsSystemId = 255, kGcsComponentId = 190;  // QGC's defaults
constexpr std::uint8_t kMavTypeGcs = 6, kMavAutopilotInvalid = 8;
constexpr std::array<const mavlink2::MessageSpec*, 3> kGroundStationInbound{
    &mavlink2::kHeartbeat, &mavlink2::kCommandAck, &mavlink2::kParamValue};

std::string mav_result_text(std::uint8_t r) {
  static constexpr std::array<const char*, 7> kNames{"ACCEPTED", "TEMPORARILY_REJECTED", "DENIED", "UNSUPPORTED",
                                                     "FAILED",   "IN_PROGRESS",          "CANCELLED"};
  return r < kNames.size() ? std::string("MAV_RESULT_") + kNames[r] : "MAV_RESULT " + std::to_string(r);
}

class MavlinkClient final : public Client {
 public:
  MavlinkClient() : parser_(kGroundStationInbound) {}

  std::size_t step_count() const override { return 3; }
  std::string step_name(std::size_t step) const override {
    static constexpr std::array<const char*, 3> kNames{
        "HEARTBEAT (ground station) -> the component's HEARTBEAT",
        "COMMAND_LONG REQUEST_MESSAGE (512) AUTOPILOT_VERSION (148)", "PARAM_REQUEST_LIST (21)"};
    return kNames.at(step);
  }

  std::vector<std::uint8_t> request(std::size_t step) override {
    switch (step) {
      case 0: {  // [X] HEARTBEAT, fields in wire order (by size)
        std::array<std::uint8_t, 9> p{};
        p[4] = kMavTypeGcs;
        p[5] = kMavAutopilotInvalid;
        p[8] = 3;  // mavlink_version
        return frame(mavlink2::kHeartbeat, p);
      }
      case 1: {  // COMMAND_LONG: param1..7 (f32), command, target system/component, confirmation
        std::array<std::uint8_t, 33> p{};
        wire::put_le<float>(p.data(), static_cast<float>(kAutopilotVersionMessageId));
        wire::put_le<std::uint16_t>(p.data() + 28, mavlink2::kCmdRequestMessage);
        p[30] = target_system_;
        p[31] = target_component_;
        return frame(mavlink2::kCommandLong, p);
      }
      default: {  // PARAM_REQUEST_LIST: target system, component
        const std::array<std::uint8_t, 2> p{target_system_, target_component_};
        params_seen_.clear();
        param_count_ = -1;
        return frame(mavlink2::kParamRequestList, p);
      }
    }
  }

  bool feed(std::size_t step, std::span<const std::uint8_t> bytes, StepResult& result) override {
    bool done = false;
    parser_.feed(bytes, std::chrono::steady_clock::now(), [&](const mavlink2::InboundPacket& p) {
      if (done) return;
      if (step == 0 && p.message_id == mavlink2::kHeartbeat.id) {
        target_system_ = p.system_id;
        target_component_ = p.component_id;
        result.answered = result.accepted = true;
        result.reply = "HEARTBEAT from system " + std::to_string(p.system_id) + " component " +
                       std::to_string(p.component_id) + ", MAV_TYPE " + std::to_string(p.payload[4]) +
                       ", system status " + std::to_string(p.payload[7]);
        done = true;
      } else if (step == 1 && p.message_id == mavlink2::kCommandAck.id) {
        if (wire::get_le<std::uint16_t>(p.payload.data()) != mavlink2::kCmdRequestMessage) return;
        const std::uint8_t r = p.payload[2];
        result.answered = true;
        result.accepted = r == mavlink2::kResultAccepted;
        result.reply = "COMMAND_ACK " + mav_result_text(r);
        done = true;
      } else if (step == 2 && p.message_id == mavlink2::kParamValue.id) {
        const float value = wire::get_le<float>(p.payload.data());
        param_count_ = wire::get_le<std::uint16_t>(p.payload.data() + 4);
        const std::uint16_t index = wire::get_le<std::uint16_t>(p.payload.data() + 6);
        char id[17] = {};
        std::memcpy(id, p.payload.data() + 8, 16);
        char line[96];
        std::snprintf(line, sizeof line, "%s%s = %g [%u]", params_seen_.empty() ? "" : ", ", id,
                      static_cast<double>(value), static_cast<unsigned>(index));
        if (params_seen_.size() <= index) params_seen_.resize(index + 1u, false);
        if (!params_seen_[index]) {
          params_seen_[index] = true;
          params_text_ += line;
        }
        if (seen() >= static_cast<std::size_t>(param_count_)) {
          result.answered = result.accepted = true;
          result.reply = std::to_string(param_count_) + " parameter(s): " + params_text_;
          done = true;
        }
      }
    });
    return done;
  }

  void timed_out(std::size_t step, StepResult& result) override {
    if (step == 2 && param_count_ >= 0) {
      result.answered = true;
      result.reply = std::to_string(seen()) + " of " + std::to_string(param_count_) + " parameter(s): " + params_text_;
    }
  }

 private:
  std::size_t seen() const {
    std::size_t n = 0;
    for (const bool b : params_seen_) n += b ? 1 : 0;
    return n;
  }

  // [G] a MAVLink 2 frame (unsigned, no payload truncation needed: the
  // receiver zero-extends either way).
  std::vector<std::uint8_t> frame(const mavlink2::MessageSpec& m, std::span<const std::uint8_t> payload) {
    const std::size_t len = payload.size();
    std::vector<std::uint8_t> f(mavlink2::kHeaderBytes + len + mavlink2::kChecksumBytes + 1, 0);
    f[0] = mavlink2::kMagic;
    f[1] = static_cast<std::uint8_t>(len);
    f[4] = sequence_++;  // [2], [3]: incompat and compat flags, none
    f[5] = kGcsSystemId;
    f[6] = kGcsComponentId;
    f[7] = static_cast<std::uint8_t>(m.id);
    f[8] = static_cast<std::uint8_t>(m.id >> 8);
    f[9] = static_cast<std::uint8_t>(m.id >> 16);
    std::copy(payload.begin(), payload.end(), f.begin() + mavlink2::kHeaderBytes);
    // [G] the checksum covers everything after the magic, then CRC_EXTRA
    // (put where the checksum goes, then overwritten).
    const std::size_t crc_at = mavlink2::kHeaderBytes + len;
    f[crc_at] = m.crc_extra;
    const std::uint16_t crc = mavlink2::crc16_mcrf4xx(std::span<const std::uint8_t>(f.data() + 1, crc_at));
    f[crc_at] = static_cast<std::uint8_t>(crc);
    f[crc_at + 1] = static_cast<std::uint8_t>(crc >> 8);
    f.pop_back();
    return f;
  }

  mavlink2::FrameParser parser_;
  std::uint8_t sequence_ = 0;
  std::uint8_t target_system_ = 0, target_component_ = 0;  // 0: broadcast until a HEARTBEAT names them
  int param_count_ = -1;
  std::vector<bool> params_seen_;
  std::string params_text_;
};


// [VN] VectorNav user manuals, "Serial ASCII": what the VectorNav SDK's
// connect and PX4's vectornav init() read (model, hardware revision, serial
// number, firmware), then the async output and binary output registers, all
// reads: the device keeps streaming what it was configured with, which
// `listen` then decodes. 8-bit checksums, as libvnc sends them.
class VectorNavClient final : public Client {
 public:
  std::size_t step_count() const override { return kSteps.size(); }
  std::string step_name(std::size_t step) const override { return kSteps[step].name; }
  std::vector<std::uint8_t> request(std::size_t step) override {
    const std::string body = std::string("VNRRG,") + kSteps[step].reg;
    char sum[8];
    std::snprintf(sum, sizeof sum, "*%02X\r\n", static_cast<unsigned>(vectornav::checksum8(body)));
    const std::string s = "$" + body + sum;
    line_.clear();
    return {s.begin(), s.end()};
  }
  bool feed(std::size_t step, std::span<const std::uint8_t> bytes, StepResult& result) override {
    const std::string want = std::string("$VNRRG,") + kSteps[step].reg + ",";
    for (const std::uint8_t b : bytes) {
      if (b == '$') line_.assign(1, '$');
      else if (!line_.empty() && b != '\r' && b != '\n' && line_.size() < 256) line_.push_back(static_cast<char>(b));
      if ((b != '\n' && b != '\r') || line_.empty()) continue;
      const std::string line = line_;
      line_.clear();
      const std::size_t star = line.find('*');
      if (star == std::string::npos) continue;
      // [VN] the reply's checksum: two hex digits (8-bit XOR) or four (CRC-16).
      const std::string_view body(line.data() + 1, star - 1);
      const std::string sum = line.substr(star + 1);
      unsigned value = 0;
      if (std::sscanf(sum.c_str(), "%x", &value) != 1) continue;
      const bool ok = (sum.size() == 2 && value == vectornav::checksum8(body)) ||
                      (sum.size() == 4 && value == vectornav::crc16(std::span<const std::uint8_t>(
                                                        reinterpret_cast<const std::uint8_t*>(body.data()), body.size())));
      if (!ok) continue;
      if (line.rfind("$VNERR,", 0) == 0) {
        result.answered = true;
        result.reply = "VNERR " + std::string(body.substr(6));
        return true;
      }
      if (line.rfind(want, 0) == 0) {
        result.answered = result.accepted = true;
        result.reply = line.substr(want.size(), star - want.size());
        return true;
      }
    }
    return false;
  }

 private:
  struct Step {
    const char* name;
    const char* reg;
  };
  static constexpr std::array<Step, 8> kSteps{{{"Model number (register 1)", "01"},
                                               {"Hardware revision (register 2)", "02"},
                                               {"Serial number (register 3)", "03"},
                                               {"Firmware version (register 4)", "04"},
                                               {"Async data output type (register 6)", "06"},
                                               {"Binary output 1 (register 75)", "75"},
                                               {"Binary output 2 (register 76)", "76"},
                                               {"Binary output 3 (register 77)", "77"}}};
  std::string line_;
};

// [SBG] sbgECom (sbg.hpp [L]): what sbgEComExample asks first (API_GET
// /api/v1/info, class 0x10 id 48: status code + JSON), then what
// ellipseLegacy, PX4's sbgecom and ArduPilot ask (CMD_INFO, id 4), then
// the output configuration of IMU_SHORT on port A (OUTPUT_CONF get): all
// reads, the device keeps streaming what it was configured with.
class SbgClient final : public Client {
 public:
  std::size_t step_count() const override { return 3; }
  std::string step_name(std::size_t step) const override {
    static constexpr std::array<const char*, 3> kNames{
        "GET /api/v1/info (CMD_0, 48)", "Device info (CMD_INFO, 4)", "Output conf of IMU_SHORT, port A (OUTPUT_CONF, 30)"};
    return kNames[step];
  }
  std::vector<std::uint8_t> request(std::size_t step) override {
    pending_.clear();
    std::vector<std::uint8_t> payload;
    std::uint8_t id = sbg::kCmdApiGet;
    if (step == 0) {
      const std::string path = "/api/v1/info";
      payload.assign(path.begin(), path.end());
      payload.push_back(0);
      payload.push_back(0);  // empty query
    } else if (step == 1) {
      id = sbg::kCmdInfo;
    } else {
      id = sbg::kCmdOutputConf;
      payload = {sbg::kPortA, sbg::kLogImuShort, sbg::kClassLog0};
    }
    std::vector<std::uint8_t> out;
    sbg::append_frame(id, sbg::kClassCmd0, payload, out);
    return out;
  }
  bool feed(std::size_t step, std::span<const std::uint8_t> bytes, StepResult& result) override {
    pending_.insert(pending_.end(), bytes.begin(), bytes.end());
    const std::uint8_t want = step == 0 ? sbg::kCmdApiGet : step == 1 ? sbg::kCmdInfo : sbg::kCmdOutputConf;
    std::size_t pos = 0;
    bool done = false;
    while (!done && pos + sbg::kFrameOverheadBytes <= pending_.size()) {
      const std::uint8_t* f = pending_.data() + pos;
      if (f[0] != sbg::kSync1 || f[1] != sbg::kSync2) {
        ++pos;
        continue;
      }
      const std::size_t len = wire::get_le<std::uint16_t>(f + 4);
      if (len > sbg::kMaxPayloadBytes) {
        ++pos;
        continue;
      }
      if (pos + len + sbg::kFrameOverheadBytes > pending_.size()) break;
      if (f[8 + len] != sbg::kEtx ||
          sbg::crc16(std::span<const std::uint8_t>(f + 2, len + 4)) != wire::get_le<std::uint16_t>(f + 6 + len)) {
        ++pos;
        continue;
      }
      const std::uint8_t* p = f + 6;
      if (f[3] == sbg::kClassCmd0 && f[2] == sbg::kCmdAck && len >= 4 && p[0] == want) {
        result.answered = true;
        result.reply = "ACK error " + std::to_string(wire::get_le<std::uint16_t>(p + 2));
        done = true;
      } else if (f[3] == sbg::kClassCmd0 && f[2] == want) {
        result.answered = true;
        if (want == sbg::kCmdApiGet && len >= 3) {
          const auto code = wire::get_le<std::uint16_t>(p);
          result.accepted = code == 200;
          result.reply = std::to_string(code) + " " + std::string(reinterpret_cast<const char*>(p + 2), len - 3);
        } else if (want == sbg::kCmdInfo && len >= 52) {
          result.accepted = true;
          char text[96];
          std::snprintf(text, sizeof text, "%.32s, serial %u", reinterpret_cast<const char*>(p),
                        static_cast<unsigned>(wire::get_le<std::uint32_t>(p + 32)));
          result.reply = text;
        } else if (want == sbg::kCmdOutputConf && len >= 5) {
          result.accepted = true;
          result.reply = "mode " + std::to_string(wire::get_le<std::uint16_t>(p + 3));
        } else {
          result.reply = "short reply (" + std::to_string(len) + " bytes)";
        }
        done = true;
      }
      pos += len + sbg::kFrameOverheadBytes;
    }
    pending_.erase(pending_.begin(), pending_.begin() + static_cast<std::ptrdiff_t>(pos));
    if (pending_.size() > 2 * (sbg::kMaxPayloadBytes + sbg::kFrameOverheadBytes)) pending_.clear();
    return done;
  }

 private:
  std::vector<std::uint8_t> pending_;
};

// Xsens MTi: the sequence xspublic (Xsens' ROS driver's XDA) and ArduPilot's
// AP_ExternalAHRS_Xsens send before data flow, each waiting for its
// acknowledgement (MID + 1) or an Error (0x42). Frames from [L] (xsens.hpp).
class XsensClient final : public Client {
 public:
  std::size_t step_count() const override { return kSteps.size(); }
  std::string step_name(std::size_t step) const override { return kSteps[step].name; }
  std::vector<std::uint8_t> request(std::size_t step) override {
    buffer_.clear();
    std::vector<std::uint8_t> data;
    if (kSteps[step].mid == xsens::mid::kOutputConfiguration) {
      // PacketCounter, SampleTimeFine (every packet), Quaternion,
      // Acceleration, RateOfTurn, StatusWord at 100 Hz.
      for (const auto& [id, rate] : std::array<std::pair<std::uint16_t, std::uint16_t>, 6>{
               {{xsens::xdi::kPacketCounter, 0xFFFF},
                {xsens::xdi::kSampleTimeFine, 0xFFFF},
                {xsens::xdi::kQuaternion, 100},
                {xsens::xdi::kAcceleration, 100},
                {xsens::xdi::kRateOfTurn, 100},
                {xsens::xdi::kStatusWord, 100}}}) {
        for (const std::uint16_t v : {id, rate}) {
          data.push_back(static_cast<std::uint8_t>(v >> 8));
          data.push_back(static_cast<std::uint8_t>(v & 0xFF));
        }
      }
    }
    return xsens::message(kSteps[step].mid, data);
  }
  bool feed(std::size_t step, std::span<const std::uint8_t> bytes, StepResult& result) override {
    buffer_.insert(buffer_.end(), bytes.begin(), bytes.end());
    std::size_t pos = 0;
    bool done = false;
    while (!done && pos < buffer_.size()) {
      if (buffer_[pos] != xsens::kPreamble) {
        ++pos;
        continue;
      }
      if (pos + 4 > buffer_.size()) break;
      std::size_t header = 4, length = buffer_[pos + 3];
      if (length == xsens::kExtendedLength) {
        if (pos + 6 > buffer_.size()) break;
        header = 6;
        length = (std::size_t{buffer_[pos + 4]} << 8) | buffer_[pos + 5];
      }
      if (pos + header + length + 1 > buffer_.size()) break;
      unsigned sum = 0;
      for (std::size_t i = pos + 1; i < pos + header + length + 1; ++i) sum += buffer_[i];
      if (buffer_[pos + 1] != xsens::kMasterBusId || (sum & 0xFF) != 0) {
        ++pos;
        continue;
      }
      const std::uint8_t m = buffer_[pos + 2];
      const std::span<const std::uint8_t> data(buffer_.data() + pos + header, length);
      if (m == xsens::mid::kError) {
        char text[32];
        std::snprintf(text, sizeof text, "Error 0x%02X", data.empty() ? 0u : static_cast<unsigned>(data[0]));
        result.answered = true;
        result.reply = text;
        done = true;
      } else if (m == static_cast<std::uint8_t>(kSteps[step].mid + 1)) {
        result.answered = result.accepted = true;
        result.reply = describe(kSteps[step].mid, data);
        done = true;
      }
      pos += header + length + 1;
    }
    buffer_.erase(buffer_.begin(), buffer_.begin() + static_cast<std::ptrdiff_t>(pos));
    return done;
  }

 private:
  static std::string describe(std::uint8_t request, std::span<const std::uint8_t> d) {
    char text[96];
    switch (request) {
      case xsens::mid::kReqDid: {
        std::uint64_t id = 0;
        for (const std::uint8_t b : d) id = id << 8 | b;
        std::snprintf(text, sizeof text, "device id %0*llX", d.size() == 8 ? 10 : 8, static_cast<unsigned long long>(id));
        return text;
      }
      case xsens::mid::kReqProductCode: {
        std::string code(d.begin(), d.end());
        code = code.substr(0, code.find(' '));  // [L] padded with spaces to 20
        return "product code " + code;
      }
      case xsens::mid::kReqHardwareVersion:
        if (d.size() < 2) return "hardware version (short)";
        std::snprintf(text, sizeof text, "hardware %u.%u", static_cast<unsigned>(d[0]), static_cast<unsigned>(d[1]));
        return text;
      case xsens::mid::kReqFwRev:
        if (d.size() < 3) return "firmware (short)";
        std::snprintf(text, sizeof text, "firmware %u.%u.%u", static_cast<unsigned>(d[0]), static_cast<unsigned>(d[1]),
                      static_cast<unsigned>(d[2]));
        if (d.size() >= 11)
          std::snprintf(text + std::strlen(text), sizeof text - std::strlen(text), " build %u svn %u",
                        static_cast<unsigned>((d[3] << 24) | (d[4] << 16) | (d[5] << 8) | d[6]),
                        static_cast<unsigned>((d[7] << 24) | (d[8] << 16) | (d[9] << 8) | d[10]));
        return text;
      case xsens::mid::kOutputConfiguration: {
        std::string s = "applied";
        for (std::size_t i = 0; i + 4 <= d.size(); i += 4) {
          const unsigned id = (d[i] << 8) | d[i + 1], rate = (d[i + 2] << 8) | d[i + 3];
          std::snprintf(text, sizeof text, " %04X@%u", id, rate);
          s += text;
        }
        return s;
      }
      default: return "ACK";
    }
  }
  struct Step {
    const char* name;
    std::uint8_t mid;
  };
  static constexpr std::array<Step, 7> kSteps{{{"GotoConfig (0x30)", xsens::mid::kGotoConfig},
                                               {"ReqDID (0x00)", xsens::mid::kReqDid},
                                               {"ReqProductCode (0x1C)", xsens::mid::kReqProductCode},
                                               {"ReqHardwareVersion (0x1E)", xsens::mid::kReqHardwareVersion},
                                               {"ReqFWRev (0x12)", xsens::mid::kReqFwRev},
                                               {"SetOutputConfiguration (0xC0)", xsens::mid::kOutputConfiguration},
                                               {"GotoMeasurement (0x10)", xsens::mid::kGotoMeasurement}}};
  std::vector<std::uint8_t> buffer_;
};
}  // namespace

std::unique_ptr<Client> make_client(const std::string& protocol) {
  if (protocol == "mip") return std::make_unique<MipClient>();
  if (protocol == "mavlink2") return std::make_unique<MavlinkClient>();
  if (protocol == "vectornav") return std::make_unique<VectorNavClient>();
  if (protocol == "sbg") return std::make_unique<SbgClient>();
  if (protocol == "xsens") return std::make_unique<XsensClient>();
  return nullptr;
}

}  // namespace imuemu::drivers::handshake
