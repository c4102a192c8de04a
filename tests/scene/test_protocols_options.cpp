// The one protocol option table (drivers/protocols/protocol_options.hpp):
// the scene parser and `imuemu emit` read it, so every option means the same
// on both paths. Checked on the wire: the bytes / CAN frames the encoders
// produce from a scene file and from command-line text are identical, each
// option changes them, and each documented default is the real default.
#include <gtest/gtest.h>

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <thread>
#include <map>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include "tests/support/spawn.hpp"
#include "daemon/scene/scene_config.hpp"
#include "drivers/byte_stream_reader.hpp"
#include "drivers/protocols/protocol_options.hpp"
#include "drivers/transport.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_scene_test_protocols_options {
namespace imuemu { using namespace ::imuemu; }

using namespace imuemu;
using namespace imuemu::drivers;

namespace {

constexpr std::int64_t kRateHz = 100;

bool is_can(const std::string& protocol) { return protocol == "dronecan" || protocol == "j1939"; }

// Collects a device's replies.
class CollectingReplySink final : public ReplySink {
 public:
  bool reply(std::span<const std::uint8_t> bytes) override {
    bytes_.insert(bytes_.end(), bytes.begin(), bytes.end());
    return true;
  }
  void change_baud_after_replies(std::uint32_t) override {}
  std::vector<std::uint8_t>& bytes() { return bytes_; }

 private:
  std::vector<std::uint8_t> bytes_;
};

// What a driver asks a device that answers commands after streaming: its
// identity and the settings the table can set (written here from the
// protocol documents; CRCs and checksums the protocols' own, or a wildcard).
std::vector<std::uint8_t> identity_probe(const std::string& protocol) {
  std::string text;
  if (protocol == "vectornav")  // [U] register reads: model, serial, serial port settings, binary output 1
    text = "$VNRRG,01*XX\r\n$VNRRG,03*XX\r\n$VNRRG,05*XX\r\n$VNRRG,06*XX\r\n$VNRRG,75*XX\r\n";
  std::vector<std::uint8_t> probe(text.begin(), text.end());
  if (protocol == "sbg") probe = {0xFF, 0x5A, 0x04, 0x10, 0x00, 0x00, 0x00, 0x00, 0x33};  // CMD_INFO, CRC below
  if (protocol == "sbg") {
    std::uint16_t crc = 0;  // CRC-16/KERMIT over id, class, length (sbgECom's sbgCrc16Compute)
    for (std::size_t i = 2; i < 6; ++i) {
      crc = static_cast<std::uint16_t>(crc ^ probe[i]);
      for (int b = 0; b < 8; ++b) crc = static_cast<std::uint16_t>((crc & 1u) != 0 ? (crc >> 1) ^ 0x8408 : crc >> 1);
    }
    probe[6] = static_cast<std::uint8_t>(crc & 0xFF), probe[7] = static_cast<std::uint8_t>(crc >> 8);
  }
  if (protocol == "xsens")  // Xbus GotoConfig, ReqDID, ReqProductCode (checksum: the bytes after FA sum to 0)
    probe = {0xFA, 0xFF, 0x30, 0x00, 0xD1, 0xFA, 0xFF, 0x00, 0x00, 0x01, 0xFA, 0xFF, 0x1C, 0x00, 0xE5};
  return probe;
}

// Everything an encoder puts on the wire for 3 s of a slowly turning, tilted
// sensor at 100 Hz (periodic traffic included), as one byte string: stream
// bytes, or each CAN frame as id, length and data.
std::vector<std::uint8_t> wire_of(const std::string& protocol, const StreamEncoderOptions& stream,
                                  const CanEncoderOptions& can) {
  std::vector<std::uint8_t> wire;
  std::unique_ptr<StreamEncoder> s;
  std::unique_ptr<CanEncoder> c;
  if (is_can(protocol))
    c = make_can_encoder(protocol, can);
  else
    s = make_stream_encoder(protocol, stream);
  for (std::uint64_t k = 0; k < 3 * kRateHz; ++k) {
    ImuFrameInput f;
    f.sample_counter = k;
    f.t_ns = static_cast<TimeNs>(k) * 10'000'000;
    f.period_ns = 10'000'000;
    f.gyro_rad_s = Vec3(0.01, -0.02, 0.03 + 1e-4 * static_cast<double>(k));
    f.accel_m_s2 = Vec3(0.5, -0.25, -9.8);
    f.delta_theta_rad = f.gyro_rad_s * 0.01;
    f.delta_velocity_m_s = f.accel_m_s2 * 0.01;
    f.has_level_attitude = true;
    f.pitch_rad = 0.05;
    f.roll_rad = -0.02;
    // A GNSS receiver's fix (nmea, ubx; the IMU protocols ignore it).
    f.has_navigation = true;
    f.latitude_rad = 0.8;
    f.longitude_rad = 0.2;
    f.height_m = 300.0;
    f.velocity_ned_m_s = Vec3(3.0, 4.0, -0.5);
    if (s) {
      s->encode(f, wire);
      s->periodic(f.t_ns, wire);
    } else {
      std::vector<CanFrame> frames;
      c->encode(f, frames);
      c->periodic(f.t_ns, frames);
      for (const CanFrame& frame : frames) {
        for (int i = 0; i < 4; ++i) wire.push_back(static_cast<std::uint8_t>(frame.id >> (8 * i)));
        wire.push_back(frame.len);
        wire.insert(wire.end(), frame.data.begin(), frame.data.begin() + frame.len);
      }
    }
  }
  // A device's identity and settings reach the wire in its replies.
  if (s && s->command_responder() != nullptr) {
    CollectingReplySink replies;
    const std::vector<std::uint8_t> probe = identity_probe(protocol);
    s->command_responder()->on_input(probe, replies);
    wire.insert(wire.end(), replies.bytes().begin(), replies.bytes().end());
  }
  return wire;
}

std::vector<std::uint8_t> wire_of(const std::string& protocol, const ProtocolOptions& o) {
  return wire_of(protocol, o.stream, o.can);
}

// A value other than the default, as command-line text and as TOML.
struct OtherValue {
  std::string text;
  std::string toml;
};
OtherValue other_value(const ProtocolOption& o) {
  switch (o.type) {
    case OptionType::boolean: {
      const std::string v = o.default_text == "true" ? "false" : "true";
      return {v, v};
    }
    case OptionType::integer: {
      const std::int64_t v = std::to_string(o.integer_max) == o.default_text ? o.integer_min : o.integer_max;
      return {std::to_string(v), std::to_string(v)};
    }
    case OptionType::number: {
      const double v = o.default_text == "1.0" && o.number_max == 1.0 ? 0.5 * (o.number_min + o.number_max) : o.number_max;
      char buffer[64];
      std::snprintf(buffer, sizeof buffer, "%.17g", v);
      std::string toml = buffer;
      if (toml.find_first_of(".e") == std::string::npos) toml += ".0";
      return {buffer, toml};
    }
    case OptionType::choice:
      return {o.choices.back(), "\"" + o.choices.back() + "\""};
    case OptionType::text:
      return {o.text_example, "\"" + o.text_example + "\""};
  }
  return {};
}

// Options a row needs beside it to be valid on its own (cross-key rules).
std::map<std::string, OtherValue> companions_of(const ProtocolOption& o) {
  if (o.protocol == "mavlink2" && o.key == "hil_sensor") return {{"highres_imu", {"true", "true"}}};
  // The barometer's, magnetometer's and HIL_GPS's figures act only with them on.
  if (o.protocol == "mavlink2" && (o.key == "baro_noise_rms_pa" || o.key == "baro_bias_pa" || o.key == "geoid_undulation_m"))
    return {{"baro", {"true", "true"}}};
  if (o.protocol == "mavlink2" && (o.key == "mag_noise_rms_ut" || o.key == "date_at_t0_year"))
    return {{"mag", {"true", "true"}}};
  if (o.protocol == "mavlink2" && o.key.rfind("gps_", 0) == 0) return {{"hil_gps_rate_hz", {"5", "5"}}};
  if (o.protocol == "mip" && o.key == "gps_minus_utc_s") return {{"time_base", {"utc", "\"utc\""}}};
  // A VectorNav on its port 2 sends binary output 1 only if its async mode has port 2's bit.
  if (o.protocol == "vectornav" && o.key == "port") return {{"saved_registers", {"75,1,4,01,0121", "\"75,1,4,01,0121\""}}};
  // The MIP device's GNSS and filter figures act only with those sets on.
  if (o.protocol == "mip" && (o.key.rfind("gnss_", 0) == 0 || o.key.rfind("filter_", 0) == 0) &&
      o.key != "gnss_rate_hz" && o.key != "filter_rate_hz")
    return {{"gnss_rate_hz", {"10", "10"}}, {"filter_rate_hz", {"50", "50"}}};
  // A GNSS receiver's error correlation time and seed act on an error term.
  if (is_gnss_protocol(o.protocol) && (o.key == "horizontal_gm_tau_s" || o.key == "seed"))
    return {{"horizontal_gm_sigma_m", {"2", "2.0"}}};
  if (is_gnss_protocol(o.protocol) && o.key == "vertical_gm_tau_s") return {{"vertical_gm_sigma_m", {"2", "2.0"}}};
  return {};
}

std::string scene_with(const std::string& protocol, const std::string& table_body) {
  // A GNSS receiver needs an ecef scene (geodetic positions).
  return "[scene]\nname = \"t\"\nphysics = \"" + std::string(is_gnss_protocol(protocol) ? "ecef" : "flat") +
         "\"\n[trajectory]\nsource = \"sample:static\"\n"
         "[[imu]]\nname = \"a\"\nrate_hz = " +
         std::to_string(is_gnss_protocol(protocol) ? kMaxGnssRateHz : kRateHz) + "\nprotocol = \"" + protocol + "\"\n[imu.transport]\ntype = \"null\"\n[imu." +
         protocol_option_table_name(protocol) + "]\n" + table_body;
}

}  // namespace

TEST(ProtocolOptionTable, EveryProtocolHasItsRowsOnceWithFlagsAndHelp) {
  std::set<std::string> flags;
  std::set<std::string> protocols;
  for (const ProtocolOption& o : protocol_option_table()) {
    SCOPED_TRACE(o.protocol + "." + o.key);
    EXPECT_TRUE(flags.insert(command_line_flag(o)).second) << "duplicate flag " << command_line_flag(o);
    EXPECT_FALSE(o.help.empty());
    EXPECT_FALSE(o.default_text.empty());
    EXPECT_TRUE(static_cast<bool>(o.apply));
    protocols.insert(o.protocol);
  }
  for (const std::string& p : stream_protocol_names()) EXPECT_TRUE(protocols.count(p)) << p;
  for (const std::string& p : can_protocol_names()) EXPECT_TRUE(protocols.count(p)) << p;
  EXPECT_EQ(command_line_flag(*protocol_options_of("mavlink2").front()), "--mavlink-system-id");
}

// The table's default column is what the encoders really default to: applying
// it (where it is a value, not "not sent") leaves the wire unchanged.
TEST(ProtocolOptionTable, DocumentedDefaultsAreTheEncodersDefaults) {
  int checked = 0;
  for (const ProtocolOption& o : protocol_option_table()) {
    SCOPED_TRACE(o.protocol + "." + o.key + " = " + o.default_text);
    OptionValue v;
    try {
      // A text row's default "" is the empty text (the model's preset, nothing saved).
      v = o.type == OptionType::text && o.default_text == "\"\"" ? OptionValue(std::string())
                                                                 : parse_option_text(o, o.default_text);
    } catch (const std::invalid_argument&) {
      continue;  // "not sent", "not available", "leap-second table ...": no value
    }
    ProtocolOptions with = default_protocol_options(kRateHz);
    o.apply(with, v);
    EXPECT_EQ(wire_of(o.protocol, with), wire_of(o.protocol, default_protocol_options(kRateHz)));
    ++checked;
  }
  EXPECT_GE(checked, 20);
}

// Each option, set to a non-default value once in a scene file and once as
// command-line text: the same wire bytes both ways, and not the default's.
TEST(ProtocolOptionTable, SceneFileAndCommandLineGiveTheSameWire) {
  for (const ProtocolOption& o : protocol_option_table()) {
    const OtherValue value = other_value(o);
    SCOPED_TRACE(o.protocol + "." + o.key + " = " + value.text);
    std::map<std::string, OtherValue> all = companions_of(o);
    all[o.key] = value;

    // emit's path: text through the table.
    ProtocolOptions cli = default_protocol_options(kRateHz);
    std::set<std::string> given;
    for (const auto& [key, v] : all) {
      for (const ProtocolOption* row : protocol_options_of(o.protocol))
        if (row->key == key) row->apply(cli, parse_option_text(*row, v.text));
      given.insert(key);
    }
    ASSERT_FALSE(finish_protocol_options(o.protocol, cli, given));

    // The scene's path: TOML through the scene parser.
    std::string body;
    for (const auto& [key, v] : all) body += key + " = " + v.toml + "\n";
    const scene::SceneConfig s = scene::parse_scene_text(scene_with(o.protocol, body), "options.toml", ".");
    ASSERT_EQ(s.imus.size(), 1u);

    // Not protocol options: the random terms' key (the device's name and
    // its error model's seed) comes from the scene's [[imu]], and a GNSS
    // receiver's rate (its error model's step).
    cli.stream.device_name = s.imus[0].stream_options.device_name;
    cli.stream.aiding_seed = s.imus[0].stream_options.aiding_seed;
    cli.stream.nominal_sample_rate_hz = s.imus[0].stream_options.nominal_sample_rate_hz;
    const std::vector<std::uint8_t> from_cli = wire_of(o.protocol, cli);
    EXPECT_EQ(wire_of(o.protocol, s.imus[0].stream_options, s.imus[0].can_options), from_cli);
    EXPECT_NE(from_cli, wire_of(o.protocol, default_protocol_options(kRateHz))) << "the option has no effect";
  }
}

TEST(ProtocolOptionTable, SceneErrorsStillNameFileLineKeyAndWhatIsAllowed) {
  struct Case {
    std::string protocol, body;
    std::uint32_t line;
    std::string key, says;
  };
  // The [imu.<table>] header is line 12; its first key line 13.
  const std::vector<Case> cases = {
      {"mavlink2", "system_id = 0\n", 13, "imu[0].mavlink.system_id", "0 is out of range; expected an integer in 1..255"},
      {"mavlink2", "system_idd = 3\n", 13, "imu[0].mavlink.system_idd", "allowed keys in imu[0].mavlink: system_id"},
      {"mavlink2", "hil_sensor = false\n", 13, "imu[0].mavlink.hil_sensor", "enable at least one"},
      {"mip", "time_base = \"tai\"\n", 13, "imu[0].mip.time_base", "expected one of unknown, gps or utc"},
      {"mip", "time_base = \"utc\"\ngps_time_at_t0_ns = 5\n", 14, "imu[0].mip.gps_time_at_t0_ns",
       "applies to time_base = \"gps\" only"},
      {"mip", "gps_minus_utc_s = 18\n", 13, "imu[0].mip.gps_minus_utc_s", "applies to time_base = \"utc\" only"},
      {"dronecan", "node_status_period_s = 0\n", 13, "imu[0].dronecan.node_status_period_s",
       "expected a number in (0, 1]"},
      {"j1939", "axes = \"iso\"\n", 13, "imu[0].j1939.axes", "expected one of j1939da, iso8855 or sae-j670e"},
      {"j1939", "send_angular_rate = false\nsend_acceleration = false\n", 13, "imu[0].j1939.send_angular_rate",
       "nothing would be sent"},
      {"j1939", "source_address = \"x\"\n", 13, "imu[0].j1939.source_address", "expected an integer in 0..253, got a string"},
      // The devices' saved settings, checked as the device checks the write
      // (VectorNav: a binary output on a port with rate divisor 0 is
      // VNERR 07; SBG: IMU_SHORT has no 3 ms rate).
      {"vectornav", "saved_registers = \"6,0;75,1,0,01,0121\"\n", 13, "imu[0].vectornav.saved_registers",
       "saved register write '75,1,0,01,0121': the device refuses it ($VNERR,07, invalid parameter)"},
      {"sbg", "saved_outputs = \"imuShort=3ms\"\n", 13, "imu[0].sbg.saved_outputs", "'3ms' is not a rate imuShort takes"},
      {"sbg", "product_code = \"ELLIPSE N\"\n", 13, "imu[0].sbg.product_code", "without spaces"},
      {"xsens", "product_code = \"MTi-630-8A1G6-TOO-LONG\"\n", 13, "imu[0].xsens.product_code",
       "more than 20; expected a product code, at most 20 printable characters"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.protocol + ": " + c.body);
    try {
      (void)scene::parse_scene_text(scene_with(c.protocol, c.body), "options.toml", ".");
      ADD_FAILURE() << "accepted";
    } catch (const scene::SceneError& e) {
      const std::string message = e.what();
      EXPECT_EQ(e.line(), c.line) << message;
      EXPECT_EQ(e.key(), c.key) << message;
      EXPECT_EQ(message.rfind("options.toml:" + std::to_string(c.line) + ":", 0), 0u) << message;
      EXPECT_NE(message.find(c.says), std::string::npos) << message;
    }
  }
  // The old implied rule stays: gps_time_at_t0_ns alone means a GPS time base.
  const scene::SceneConfig s =
      scene::parse_scene_text(scene_with("mip", "gps_time_at_t0_ns = 1000\n"), "options.toml", ".");
  EXPECT_EQ(s.imus[0].stream_options.mip_time_base, MipTimeBase::gps);
  EXPECT_EQ(s.imus[0].stream_options.mip_gps_time_at_t0_ns, 1000);
}

TEST(ProtocolOptionTable, CommandLineTextIsCheckedByTheTable) {
  auto row = [](const std::string& protocol, const std::string& key) {
    for (const ProtocolOption* o : protocol_options_of(protocol))
      if (o->key == key) return o;
    throw std::logic_error("no row " + key);
  };
  EXPECT_EQ(std::get<std::int64_t>(parse_option_text(*row("mavlink2", "system_id"), "7")), 7);
  EXPECT_EQ(std::get<bool>(parse_option_text(*row("mavlink2", "highres_imu"), "true")), true);
  EXPECT_EQ(std::get<double>(parse_option_text(*row("j1939", "measurement_latency_ms"), "2.5")), 2.5);
  EXPECT_EQ(std::get<std::string>(parse_option_text(*row("j1939", "axes"), "iso8855")), "iso8855");
  auto says = [](const ProtocolOption* o, const std::string& text) {
    try {
      (void)parse_option_text(*o, text);
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  EXPECT_EQ(says(row("mavlink2", "system_id"), "256"), "'256' is out of range; expected an integer in 1..255");
  EXPECT_EQ(says(row("mavlink2", "system_id"), "3x"), "'3x' is not an integer; expected an integer in 1..255");
  EXPECT_EQ(says(row("mavlink2", "heartbeat"), "maybe"), "'maybe' is not a boolean; expected true or false");
  EXPECT_EQ(says(row("dronecan", "node_status_period_s"), "0"),
            "'0' is out of range; expected a number in (0, 1]");
  EXPECT_EQ(says(row("mip", "time_base"), "tai"), "'tai' is not allowed; expected one of unknown, gps or utc");
}

// `imuemu emit` end to end: the table's flags reach the encoder. MAVLink 2
// with system 7, component 9, HIGHRES_IMU instead of HIL_SENSOR, read from
// the pty: every packet's header carries 7 / 9 (MAVLink 2 header bytes 5, 6)
// and the messages are #105 and #0 only.
TEST(ProtocolOptionTable, EmitFlagsReachTheWire) {
  char tmpl[] = "/tmp/imuemu-test-options-XXXXXX";
  ASSERT_NE(::mkdtemp(tmpl), nullptr);
  const std::string dir = tmpl;
  const std::string tty = dir + "/tty", log_path = dir + "/emit.log";
  const std::vector<std::string> args = {"emit", "--sample", "static", "--scene", "flat", "--rate", "50",
                                         "--protocol", "mavlink2", "--mavlink-system-id", "7",
                                         "--mavlink-component-id", "9", "--mavlink-hil-sensor", "false",
                                         "--mavlink-highres-imu", "true", "--device", "pty:" + tty};
  const pid_t pid = imuemu::test::spawn_logged(IMUEMU_CLI_PATH, args, log_path);
  ASSERT_GT(pid, 0);
  using namespace std::chrono_literals;
  for (int i = 0; i < 3000 && ::access(tty.c_str(), F_OK) != 0; ++i) std::this_thread::sleep_for(10ms);
  std::vector<std::uint8_t> wire;
  StreamEncoderOptions o;
  o.mavlink_hil_sensor = false;
  o.mavlink_highres_imu = true;
  auto decoder = make_stream_decoder("mavlink2", o);
  std::uint64_t samples = 0;
  {
    ByteStreamReader reader(tty);
    std::vector<std::uint8_t> buffer(4096);
    // Until a few samples are in (a slow host only takes longer).
    const auto until = std::chrono::steady_clock::now() + 60s;
    while (samples < 5 && std::chrono::steady_clock::now() < until) {
      const ReadResult r = reader.read_some(buffer, 100ms);
      if (r.end_of_stream) break;
      wire.insert(wire.end(), buffer.begin(), buffer.begin() + static_cast<std::ptrdiff_t>(r.bytes));
      decoder->feed(std::span<const std::uint8_t>(buffer.data(), r.bytes), [&](const DecodedSample&) { ++samples; });
    }
  }
  ::kill(pid, SIGTERM);
  int status = 0;
  ::waitpid(pid, &status, 0);
  std::system(("rm -rf " + dir).c_str());
  EXPECT_GE(samples, 5u);
  EXPECT_EQ(decoder->counters().checksum_errors, 0u);
  // Walk the packets (the decoder has checked their CRCs): magic FD, len,
  // flags, seq, sysid, compid, msgid[3], payload, CRC. From the first FD that
  // starts a chain of packets (the stream may begin inside one).
  std::size_t packets = 0;
  for (std::size_t start = 0; start < std::min<std::size_t>(wire.size(), 300) && packets < 5; ++start) {
    packets = 0;
    for (std::size_t at = start; at + 12 <= wire.size() && wire[at] == 0xFD; at += 12 + wire[at + 1]) ++packets;
    if (packets < 5) continue;
    for (std::size_t at = start; at + 12 <= wire.size() && wire[at] == 0xFD; at += 12 + wire[at + 1]) {
      EXPECT_EQ(wire[at + 5], 7) << "system id";
      EXPECT_EQ(wire[at + 6], 9) << "component id";
      const std::uint32_t msgid = wire[at + 7] | wire[at + 8] << 8 | wire[at + 9] << 16;
      EXPECT_TRUE(msgid == 105 || msgid == 0) << "message " << msgid;
    }
  }
  EXPECT_GE(packets, 5u);

  // A flag of another protocol is a usage error naming it.
  const std::string wrong = std::string(IMUEMU_CLI_PATH) +
                            " emit --sample static --protocol mip --mavlink-system-id 3 --device pty:/tmp/unused 2>&1";
  FILE* p = ::popen(wrong.c_str(), "r");
  ASSERT_NE(p, nullptr);
  std::string out;
  char line[512];
  while (std::fgets(line, sizeof line, p) != nullptr) out += line;
  EXPECT_EQ(WEXITSTATUS(::pclose(p)), 2);
  EXPECT_NE(out.find("--mavlink-system-id: applies to --protocol mavlink2, not mip"), std::string::npos) << out;
}
}  // namespace unity_scene_test_protocols_options
