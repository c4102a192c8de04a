// Issue 27: the emulated MIP device answers its driver. Every request and
// expected reply below is written by hand from the MIP DCP manuals' field
// definitions (3DM-GX5-35 DCP manual 6 "MIP Packet Reference"; 3DM-CV7 DCP:
// base command set 0x01, 3DM set 0x0C, filter set 0x0D, ACK/NACK field 0xF1
// with the echoed command descriptor and the error code), not from any
// library. The checksum of a hand-written packet is the manual's Fletcher-16
// (6.4), implemented here on its own (`spec_checksum`) and pinned by the two
// packets the issue quotes (Ping and its ACK).
//
// The start-up sequences replayed are read from the clients' sources:
//  - mip_sdk (LORD-MicroStrain/mip_sdk e5a847d846f45c9c0b08d5efbe8ad4ed1d4d57cf),
//    examples/cpp/7_series/stream_imu and 5_series/stream_imu: Ping, Set To
//    Idle, Get Device Information, Device Settings load default, Get Device
//    Descriptors, Get Base Rate 0x80 (7-series: 0x0C,0x0E; 5-series:
//    0x0C,0x06), Message Format accel + gyro at base_rate / SAMPLE_RATE_HZ
//    (7-series 0x0C,0x0F; 5-series 0x0C,0x08), Resume.
//  - PX4-Autopilot 00c59fa5080c7c1d40709e72440cc264bbfb8248,
//    src/drivers/ins/microstrain/MicroStrain.cpp initializeIns() with the
//    module.yaml defaults (MS_IMU_RATE_HZ 500, MS_FILT_RATE_HZ 250, ranges -1,
//    aiding off): Set To Idle at 115200, Get Device Descriptors, Get Extended
//    Descriptors, Comm Port Speed 921600 on port 1 (0x01,0x09 because the
//    device lists it), Set To Idle at 921600, Get Base Rate 0x80, Message
//    Format 0x80 accel + gyro at decimation 2, Get Base Rate 0x82, Message
//    Format 0x82 with no field (no 0x82 field listed), Get Base Rate 0x91 and
//    0x92 (NACK tolerated: "Could not write GNSS1 message format" is not
//    fatal there), Reset Filter 0x0D,0x01, Datastream Control all streams on,
//    Resume.
#include <fcntl.h>
#include <mutex>
#include <poll.h>
#include <termios.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <functional>
#include <map>
#include <new>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "daemon/device/device.hpp"
#include "daemon/scene/scene_config.hpp"
#include "drivers/link_fault.hpp"
#include "drivers/protocols/mavlink2.hpp"
#include "drivers/protocols/mip.hpp"
#include "drivers/protocols/mip_device.hpp"
#include "drivers/protocols/stream_protocols.hpp"
#include "drivers/protocols/vectornav.hpp"
#include "drivers/protocols/sbg.hpp"
#include "drivers/protocols/xsens.hpp"
#include "drivers/pty_transport.hpp"
#include "drivers/queued_writer.hpp"

// Allocations counted per thread: the emission thread must allocate nothing
// while the io thread (which may) answers commands at the same time, so the
// process-wide counter of tests/support/allocation_counter.hpp cannot tell
// them apart.
namespace {
thread_local bool t_counting = false;
std::atomic<std::uint64_t> g_emission_allocations{0};
}  // namespace
void* operator new(std::size_t n) {
  if (t_counting) g_emission_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(n == 0 ? 1 : n)) return p;
  throw std::bad_alloc();
}
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
#endif
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
#include "tests/support/replaced_new_forms.hpp"  // the nothrow and array forms through these two
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif

namespace {

using namespace imuemu;
using Bytes = std::vector<std::uint8_t>;

// [P 6.4] Fletcher-16: two 8-bit running sums over sync1 .. last payload
// byte; sum1 is sent first.
Bytes with_checksum(Bytes p) {
  std::uint8_t a = 0, b = 0;
  for (const std::uint8_t x : p) {
    a = static_cast<std::uint8_t>(a + x);
    b = static_cast<std::uint8_t>(b + a);
  }
  p.push_back(a);
  p.push_back(b);
  return p;
}
// A packet from its descriptor set and its fields, each written in full
// (length byte, descriptor, data) as the manual tables them.
Bytes spec_packet(std::uint8_t set, std::initializer_list<Bytes> fields) {
  Bytes p{0x75, 0x65, set, 0};
  for (const Bytes& f : fields) p.insert(p.end(), f.begin(), f.end());
  p[3] = static_cast<std::uint8_t>(p.size() - 4);
  return with_checksum(p);
}
// The ACK/NACK field: length 4, 0xF1, echoed command descriptor, code.
Bytes ack(std::uint8_t command, std::uint8_t code = 0x00) { return {0x04, 0xF1, command, code}; }

struct Sink final : drivers::ReplySink {
  std::vector<Bytes> replies;
  std::optional<std::uint32_t> baud_after;
  bool reply(std::span<const std::uint8_t> b) override {
    replies.emplace_back(b.begin(), b.end());
    return true;
  }
  void change_baud_after_replies(std::uint32_t baud) override { baud_after = baud; }
};

drivers::StreamEncoderOptions options_1000hz() {
  drivers::StreamEncoderOptions o;
  o.nominal_sample_rate_hz = 1000.0;
  return o;
}

// One command, one reply packet.
Bytes ask(drivers::CommandResponder& d, const Bytes& command, Sink* sink_out = nullptr) {
  Sink sink;
  d.on_input(command, sink);
  if (sink_out != nullptr) *sink_out = sink;
  EXPECT_EQ(sink.replies.size(), 1u) << "one reply packet per command packet";
  return sink.replies.empty() ? Bytes{} : sink.replies.front();
}

// Splits a byte stream into MIP packets, checking each checksum (by the
// spec implementation above); returns {set, field descriptors} per packet
// and counts bytes outside any valid packet.
struct SeenPacket {
  std::uint8_t set = 0;
  std::vector<std::uint8_t> fields;
  Bytes bytes;
};
std::vector<SeenPacket> split_packets(const Bytes& s, std::size_t* garbage = nullptr, std::size_t* tail = nullptr) {
  std::vector<SeenPacket> out;
  std::size_t i = 0, bad = 0;
  while (i + 4 <= s.size()) {
    if (s[i] != 0x75 || s[i + 1] != 0x65) {
      ++bad;
      ++i;
      continue;
    }
    const std::size_t total = 4u + s[i + 3] + 2u;
    if (i + total > s.size()) break;
    const Bytes body(s.begin() + static_cast<std::ptrdiff_t>(i), s.begin() + static_cast<std::ptrdiff_t>(i + total - 2));
    if (with_checksum(body) != Bytes(s.begin() + static_cast<std::ptrdiff_t>(i), s.begin() + static_cast<std::ptrdiff_t>(i + total))) {
      ++bad;
      ++i;
      continue;
    }
    SeenPacket p;
    p.set = s[i + 2];
    for (std::size_t f = i + 4; f < i + total - 2; f += s[f]) {
      if (s[f] < 2) break;
      p.fields.push_back(s[f + 1]);
    }
    p.bytes.assign(s.begin() + static_cast<std::ptrdiff_t>(i), s.begin() + static_cast<std::ptrdiff_t>(i + total));
    out.push_back(std::move(p));
    i += total;
  }
  if (garbage != nullptr) *garbage = bad;
  if (tail != nullptr) *tail = s.size() - i;
  return out;
}

// Runs the encoder over counters [first, first + n): the counters that sent
// a packet and what each packet carried.
std::map<std::uint64_t, std::vector<std::uint8_t>> stream(drivers::mip::Encoder& e, std::uint64_t first, std::uint64_t n) {
  std::map<std::uint64_t, std::vector<std::uint8_t>> sent;
  for (std::uint64_t k = first; k < first + n; ++k) {
    drivers::ImuFrameInput s;
    s.sample_counter = k;
    s.t_ns = static_cast<TimeNs>(k) * 1'000'000;
    s.accel_m_s2 = Vec3(0.0, 0.0, -9.80665);
    Bytes out;
    e.encode(s, out);
    if (out.empty()) continue;
    std::size_t garbage = 0, tail = 0;
    const auto packets = split_packets(out, &garbage, &tail);
    EXPECT_EQ(packets.size(), 1u);
    EXPECT_EQ(garbage + tail, 0u);
    if (!packets.empty()) sent[k] = packets.front().fields;
  }
  return sent;
}

// ---------------------------------------------------------------- framing

TEST(MipDevice, PingGetsTheAckTheIssueQuotesByteForByte) {
  // The two packets of issue 27, also pinning spec_checksum.
  const Bytes ping{0x75, 0x65, 0x01, 0x02, 0x02, 0x01, 0xE0, 0xC6};
  const Bytes pong{0x75, 0x65, 0x01, 0x04, 0x04, 0xF1, 0x01, 0x00, 0xD5, 0x6A};
  ASSERT_EQ(spec_packet(0x01, {{0x02, 0x01}}), ping);
  ASSERT_EQ(spec_packet(0x01, {ack(0x01)}), pong);
  drivers::mip::Encoder e(options_1000hz());
  ASSERT_NE(e.command_responder(), nullptr);
  EXPECT_EQ(ask(*e.command_responder(), ping), pong);
  const drivers::CommandCounters c = e.command_responder()->command_counters();
  EXPECT_EQ(c.received, 1u);
  EXPECT_EQ(c.answered, 1u);
  EXPECT_EQ(c.nacked, 0u);
  EXPECT_EQ(c.not_command_bytes, 0u);
}

TEST(MipDevice, ResyncsOnGarbageBadChecksumsAndCommandsSplitMidFrame) {
  drivers::mip::Encoder e(options_1000hz());
  drivers::CommandResponder& d = *e.command_responder();
  const Bytes ping = spec_packet(0x01, {{0x02, 0x01}});
  Bytes bad_ping = ping;
  bad_ping.back() ^= 0xFF;
  // Garbage (with a lone sync byte and a false sync pair), a ping with a bad
  // checksum, then a good ping cut in three pieces mid-header and mid-field.
  Bytes garbage{0x00, 0x75, 0x11, 0x75, 0x65, 0x01, 0x09};  // a "packet" of 9 payload bytes that never checks
  Sink sink;
  d.on_input(garbage, sink);
  d.on_input(bad_ping, sink);
  d.on_input(Bytes(ping.begin(), ping.begin() + 3), sink);
  d.on_input(Bytes(ping.begin() + 3, ping.begin() + 5), sink);
  EXPECT_TRUE(sink.replies.empty());
  d.on_input(Bytes(ping.begin() + 5, ping.end()), sink);
  ASSERT_EQ(sink.replies.size(), 1u);
  EXPECT_EQ(sink.replies[0], spec_packet(0x01, {ack(0x01)}));
  const drivers::CommandCounters c = d.command_counters();
  EXPECT_EQ(c.received, 1u);
  // Every byte before the good ping was not a command.
  EXPECT_EQ(c.not_command_bytes, garbage.size() + bad_ping.size());
}

TEST(MipDevice, RepliesAndDataPacketsEchoedBackAreNotCommands) {
  // A reader whose tty echoes sends our own packets back: a reply (field
  // 0xF1) or a data packet (set 0x80) is never answered.
  drivers::mip::Encoder e(options_1000hz());
  Sink sink;
  const Bytes echoed_ack = spec_packet(0x01, {ack(0x01)});
  const Bytes echoed_data = spec_packet(0x80, {{0x0E, 0x04, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0}});
  e.command_responder()->on_input(echoed_ack, sink);
  e.command_responder()->on_input(echoed_data, sink);
  EXPECT_TRUE(sink.replies.empty());
  const drivers::CommandCounters c = e.command_responder()->command_counters();
  EXPECT_EQ(c.received, 0u);
  EXPECT_EQ(c.not_command_bytes, echoed_ack.size() + echoed_data.size());
}

// ------------------------------------------------------------- commands

TEST(MipDevice, DeviceInformationCarriesTheSceneIdentity) {
  drivers::StreamEncoderOptions o = options_1000hz();
  o.mip_device.model_name = "3DM-GX5-25";
  o.mip_device.model_number = "6251-4220";
  o.mip_device.serial_number = "6251.12345";
  o.mip_device.lot_number = "L7";
  o.mip_device.device_options = "5g,300dps";
  o.mip_device.firmware_version = 1203;
  drivers::mip::Encoder e(o);
  // 0x81: u16 firmware, five 16-character strings padded with spaces.
  Bytes info{0x54, 0x81, 0x04, 0xB3};
  for (const std::string s : {"3DM-GX5-25", "6251-4220", "6251.12345", "L7", "5g,300dps"}) {
    std::string padded = s + std::string(16 - s.size(), ' ');
    info.insert(info.end(), padded.begin(), padded.end());
  }
  ASSERT_EQ(info.size(), 0x54u);
  EXPECT_EQ(ask(*e.command_responder(), spec_packet(0x01, {{0x02, 0x03}})),
            spec_packet(0x01, {ack(0x03), info}));
}

TEST(MipDevice, DescriptorsListTheCommandsAnsweredAndTheFieldsStreamed) {
  drivers::mip::Encoder e(options_1000hz());
  // 0x82: u16 descriptors, set in the high byte.
  const Bytes descriptors{0x32, 0x82,
                          0x01, 0x01, 0x01, 0x02, 0x01, 0x03, 0x01, 0x04, 0x01, 0x05, 0x01, 0x06, 0x01, 0x07, 0x01, 0x09,
                          0x0C, 0x06, 0x0C, 0x08, 0x0C, 0x0A, 0x0C, 0x0B, 0x0C, 0x0E, 0x0C, 0x0F, 0x0C, 0x11, 0x0C, 0x30,
                          0x0C, 0x40, 0x0D, 0x01,
                          0x80, 0x04, 0x80, 0x05, 0x80, 0x07, 0x80, 0x08, 0x80, 0x12, 0x80, 0x18};
  ASSERT_EQ(descriptors.size(), 0x32u);
  EXPECT_EQ(ask(*e.command_responder(), spec_packet(0x01, {{0x02, 0x04}})),
            spec_packet(0x01, {ack(0x04), descriptors}));
  // Extended descriptors: none more (an empty 0x86 field).
  EXPECT_EQ(ask(*e.command_responder(), spec_packet(0x01, {{0x02, 0x07}})),
            spec_packet(0x01, {ack(0x07), {0x02, 0x86}}));
}

TEST(MipDevice, UnknownCommandsAndBadParametersAreNackedWithTheManualsCodes) {
  drivers::mip::Encoder e(options_1000hz());
  drivers::CommandResponder& d = *e.command_responder();
  // Soft Reset (0x01,0x7E) is not emulated: unknown command (0x01).
  EXPECT_EQ(ask(d, spec_packet(0x01, {{0x02, 0x7E}})), spec_packet(0x01, {ack(0x7E, 0x01)}));
  // A command set the device does not have (aiding 0x13): unknown command.
  EXPECT_EQ(ask(d, spec_packet(0x13, {{0x02, 0x21}})), spec_packet(0x13, {ack(0x21, 0x01)}));
  // A filter command other than Reset Filter (Aiding Measurement Enable 0x50).
  EXPECT_EQ(ask(d, spec_packet(0x0D, {{0x06, 0x50, 0x01, 0x00, 0x00, 0x01}})),
            spec_packet(0x0D, {ack(0x50, 0x01)}));
  // Message Format 0x80 with scaled mag (0x06, which this device has not):
  // invalid parameter (0x03), and the format is unchanged.
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x08, 0x0F, 0x01, 0x80, 0x01, 0x06, 0x00, 0x01}})),
            spec_packet(0x0C, {ack(0x0F, 0x03)}));
  // Decimation 0: invalid parameter.
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x08, 0x0F, 0x01, 0x80, 0x01, 0x04, 0x00, 0x00}})),
            spec_packet(0x0C, {ack(0x0F, 0x03)}));
  // Comm Port Speed at a rate the port has not: invalid parameter.
  EXPECT_EQ(ask(d, spec_packet(0x01, {{0x08, 0x09, 0x01, 0x01, 0x00, 0x01, 0xF4, 0x00}})),
            spec_packet(0x01, {ack(0x09, 0x03)}));
  const drivers::CommandCounters c = d.command_counters();
  EXPECT_EQ(c.received, 6u);
  EXPECT_EQ(c.nacked, 6u);
  EXPECT_EQ(c.answered, 0u);
  // Nothing refused changed what streams.
  EXPECT_EQ(stream(e, 0, 3).size(), 3u);
  EXPECT_EQ(stream(e, 0, 1).at(0), (std::vector<std::uint8_t>{0x04, 0x05, 0x07, 0x08, 0x12, 0x18}));
}

TEST(MipDevice, IdleStopsTheStreamResumeRestartsIt) {
  drivers::mip::Encoder e(options_1000hz());
  drivers::CommandResponder& d = *e.command_responder();
  EXPECT_EQ(stream(e, 0, 10).size(), 10u);  // power-up: streaming
  EXPECT_EQ(ask(d, spec_packet(0x01, {{0x02, 0x02}})), spec_packet(0x01, {ack(0x02)}));
  EXPECT_TRUE(stream(e, 10, 10).empty());
  EXPECT_EQ(d.command_counters().mode, "idle");
  EXPECT_EQ(ask(d, spec_packet(0x01, {{0x02, 0x06}})), spec_packet(0x01, {ack(0x06)}));
  EXPECT_EQ(stream(e, 20, 10).size(), 10u);
  EXPECT_EQ(d.command_counters().mode, "streaming");
}

TEST(MipDevice, PowerUpIdleIsSilentUntilResume) {
  drivers::StreamEncoderOptions o = options_1000hz();
  o.mip_device.power_up_idle = true;
  drivers::mip::Encoder e(o);
  EXPECT_TRUE(stream(e, 0, 20).empty());
  EXPECT_EQ(ask(*e.command_responder(), spec_packet(0x01, {{0x02, 0x06}})), spec_packet(0x01, {ack(0x06)}));
  EXPECT_EQ(stream(e, 20, 5).size(), 5u);
}

TEST(MipDevice, DecimationChangesStartOnMultiplesOfTheNewDecimation) {
  drivers::mip::Encoder e(options_1000hz());
  drivers::CommandResponder& d = *e.command_responder();
  // Accel every 4th sample, gyro every 6th (3DM 0x0C,0x08 IMU Message Format).
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x0A, 0x08, 0x01, 0x02, 0x04, 0x00, 0x04, 0x05, 0x00, 0x06}})),
            spec_packet(0x0C, {ack(0x08)}));
  // Applied from counter 7 on: first packets at 8 (accel), 12 (both), 16, 18, 20, 24 ...
  const auto sent = stream(e, 7, 18);
  std::map<std::uint64_t, std::vector<std::uint8_t>> expected{
      {8, {0x04}}, {12, {0x04, 0x05}}, {16, {0x04}}, {18, {0x05}}, {20, {0x04}}, {24, {0x04, 0x05}}};
  EXPECT_EQ(sent, expected);
  // Read back (function 2) -> 0x80: count, (descriptor, u16 decimation)...
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x03, 0x08, 0x02}})),
            spec_packet(0x0C, {ack(0x08), {0x09, 0x80, 0x02, 0x04, 0x00, 0x04, 0x05, 0x00, 0x06}}));
  // Load default (function 5): back to the power-up stream, every sample.
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x03, 0x08, 0x05}})), spec_packet(0x0C, {ack(0x08)}));
  EXPECT_EQ(stream(e, 25, 4).size(), 4u);
}

TEST(MipDevice, SavedSettingsComeBackOnLoadAndDefaultsOnDeviceSettingsDefault) {
  drivers::mip::Encoder e(options_1000hz());
  drivers::CommandResponder& d = *e.command_responder();
  const Bytes gyro_every_10{0x08, 0x0F, 0x01, 0x80, 0x01, 0x05, 0x00, 0x0A};
  EXPECT_EQ(ask(d, spec_packet(0x0C, {gyro_every_10})), spec_packet(0x0C, {ack(0x0F)}));
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x03, 0x30, 0x03}})), spec_packet(0x0C, {ack(0x30)}));  // save
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x03, 0x30, 0x05}})), spec_packet(0x0C, {ack(0x30)}));  // default
  EXPECT_EQ(stream(e, 0, 10).size(), 10u);
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x03, 0x30, 0x04}})), spec_packet(0x0C, {ack(0x30)}));  // load saved
  const auto sent = stream(e, 0, 30);
  EXPECT_EQ(sent.size(), 3u);
  EXPECT_EQ(sent.at(10), (std::vector<std::uint8_t>{0x05}));
  // Message Format read (0x0C,0x0F function 2, set 0x80) -> 0x8F: set, count, list.
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x04, 0x0F, 0x02, 0x80}})),
            spec_packet(0x0C, {ack(0x0F), {0x07, 0x8F, 0x80, 0x01, 0x05, 0x00, 0x0A}}));
  // Device Settings write (1) means nothing: invalid parameter.
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x03, 0x30, 0x01}})), spec_packet(0x0C, {ack(0x30, 0x03)}));
}

TEST(MipDevice, ARestartFaultBringsBackTheStartupSettingsAndPowerUpMode) {
  drivers::mip::Encoder e(options_1000hz());
  drivers::CommandResponder& d = *e.command_responder();
  // Saved startup format: accel every 10th sample; then the driver sets gyro
  // every 5th (not saved) and idles the device.
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x08, 0x0F, 0x01, 0x80, 0x01, 0x04, 0x00, 0x0A}})), spec_packet(0x0C, {ack(0x0F)}));
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x04, 0x0F, 0x03, 0x80}})), spec_packet(0x0C, {ack(0x0F)}));  // save
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x08, 0x0F, 0x01, 0x80, 0x01, 0x05, 0x00, 0x05}})), spec_packet(0x0C, {ack(0x0F)}));
  EXPECT_EQ(ask(d, spec_packet(0x01, {{0x02, 0x02}})), spec_packet(0x01, {ack(0x02)}));
  EXPECT_TRUE(stream(e, 0, 20).empty());
  // Power cycle (a restart fault, on the emission thread): the device comes
  // up streaming (power_up_mode) its saved format at once, before the io
  // thread has seen anything.
  Bytes nothing;
  e.restart(0, nothing);
  EXPECT_TRUE(nothing.empty());
  auto sent = stream(e, 20, 20);
  EXPECT_EQ(sent, (std::map<std::uint64_t, std::vector<std::uint8_t>>{{20, {0x04}}, {30, {0x04}}}));
  // The next command finds the settings reset: mode streaming, the saved format.
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x04, 0x0F, 0x02, 0x80}})),
            spec_packet(0x0C, {ack(0x0F), {0x07, 0x8F, 0x80, 0x01, 0x04, 0x00, 0x0A}}));
  EXPECT_EQ(d.command_counters().mode, "streaming");
  EXPECT_EQ(stream(e, 40, 20).size(), 2u);
}

TEST(MipDevice, DatastreamControlTurnsTheSensorStreamOffAndOn) {
  drivers::mip::Encoder e(options_1000hz());
  drivers::CommandResponder& d = *e.command_responder();
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x05, 0x11, 0x01, 0x80, 0x00}})), spec_packet(0x0C, {ack(0x11)}));
  EXPECT_TRUE(stream(e, 0, 5).empty());
  // Read (function 2) -> 0x85: set, enabled.
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x04, 0x11, 0x02, 0x80}})),
            spec_packet(0x0C, {ack(0x11), {0x04, 0x85, 0x80, 0x00}}));
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x05, 0x11, 0x01, 0x00, 0x01}})), spec_packet(0x0C, {ack(0x11)}));
  EXPECT_EQ(stream(e, 5, 5).size(), 5u);
}

TEST(MipDevice, BaudChangesAfterItsAckAndReadsBack) {
  drivers::mip::Encoder e(options_1000hz());
  drivers::CommandResponder& d = *e.command_responder();
  // Comm Port Speed (0x01,0x09): function 1, port 1, u32 921600 = 0x000E1000.
  Sink sink;
  EXPECT_EQ(ask(d, spec_packet(0x01, {{0x08, 0x09, 0x01, 0x01, 0x00, 0x0E, 0x10, 0x00}}), &sink),
            spec_packet(0x01, {ack(0x09)}));
  EXPECT_EQ(sink.baud_after, 921600u);  // applied by the transport once the ACK has left
  EXPECT_EQ(d.command_counters().baud, 921600u);
  // Read (function 2, port 1) -> 0x89: port, u32 baud.
  EXPECT_EQ(ask(d, spec_packet(0x01, {{0x04, 0x09, 0x02, 0x01}})),
            spec_packet(0x01, {ack(0x09), {0x07, 0x89, 0x01, 0x00, 0x0E, 0x10, 0x00}}));
  // UART Baudrate (0x0C,0x40) read -> 0x87: u32.
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x03, 0x40, 0x02}})),
            spec_packet(0x0C, {ack(0x40), {0x06, 0x87, 0x00, 0x0E, 0x10, 0x00}}));
  // Load default settings: back to 115200 = 0x0001C200, after the ACK.
  Sink back;
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x03, 0x30, 0x05}}), &back), spec_packet(0x0C, {ack(0x30)}));
  EXPECT_EQ(back.baud_after, 115200u);
}

// ------------------------------------------------------- client replays

// The 7-series example (mip_sdk examples/cpp/7_series/stream_imu) at its
// SAMPLE_RATE_HZ, here with decimation 100 (10 Hz at a base rate of 1000 Hz).
TEST(MipDevice, MipSdk7SeriesStartUpReplayGetsEveryReplyThenStreamsExactlyWhatItAskedFor) {
  drivers::mip::Encoder e(options_1000hz());
  drivers::CommandResponder& d = *e.command_responder();
  EXPECT_EQ(ask(d, spec_packet(0x01, {{0x02, 0x01}})), spec_packet(0x01, {ack(0x01)}));  // Ping
  EXPECT_EQ(ask(d, spec_packet(0x01, {{0x02, 0x02}})), spec_packet(0x01, {ack(0x02)}));  // Set To Idle
  const Bytes info = ask(d, spec_packet(0x01, {{0x02, 0x03}}));                         // Get Device Info
  ASSERT_GE(info.size(), 10u);
  EXPECT_EQ(Bytes(info.begin() + 4, info.begin() + 10), (Bytes{0x04, 0xF1, 0x03, 0x00, 0x54, 0x81}));
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x03, 0x30, 0x05}})), spec_packet(0x0C, {ack(0x30)}));  // load default
  const Bytes desc = ask(d, spec_packet(0x01, {{0x02, 0x04}}));  // Get Device Descriptors
  ASSERT_GE(desc.size(), 10u);
  EXPECT_EQ(Bytes(desc.begin() + 4, desc.begin() + 9), (Bytes{0x04, 0xF1, 0x04, 0x00, 0x32}));
  // Get Base Rate (0x0C,0x0E) of 0x80 -> 0x8E: set, u16 1000 = 0x03E8.
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x03, 0x0E, 0x80}})),
            spec_packet(0x0C, {ack(0x0E), {0x05, 0x8E, 0x80, 0x03, 0xE8}}));
  // Message Format (0x0C,0x0F): write, set 0x80, 2 fields, accel and gyro at 100 = 0x0064.
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x0B, 0x0F, 0x01, 0x80, 0x02, 0x04, 0x00, 0x64, 0x05, 0x00, 0x64}})),
            spec_packet(0x0C, {ack(0x0F)}));
  EXPECT_TRUE(stream(e, 0, 200).empty()) << "idle until Resume";
  EXPECT_EQ(ask(d, spec_packet(0x01, {{0x02, 0x06}})), spec_packet(0x01, {ack(0x06)}));  // Resume
  // Then: exactly accel + gyro, on every 100th sample (10 Hz), nothing else.
  const auto sent = stream(e, 200, 1000);
  ASSERT_EQ(sent.size(), 10u);
  for (const auto& [k, fields] : sent) {
    EXPECT_EQ(k % 100, 0u);
    EXPECT_EQ(fields, (std::vector<std::uint8_t>{0x04, 0x05}));
  }
  const drivers::CommandCounters c = d.command_counters();
  EXPECT_EQ(c.received, 8u);
  EXPECT_EQ(c.answered, 8u);
  EXPECT_EQ(c.nacked, 0u);
  EXPECT_EQ(c.mode, "streaming");
}

// The 5-series example: Get IMU Base Rate (0x0C,0x06) and IMU Message Format (0x0C,0x08).
TEST(MipDevice, MipSdk5SeriesStartUpReplayUsesTheImuSpecificCommands) {
  drivers::mip::Encoder e(options_1000hz());
  drivers::CommandResponder& d = *e.command_responder();
  EXPECT_EQ(ask(d, spec_packet(0x01, {{0x02, 0x01}})), spec_packet(0x01, {ack(0x01)}));
  EXPECT_EQ(ask(d, spec_packet(0x01, {{0x02, 0x02}})), spec_packet(0x01, {ack(0x02)}));
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x03, 0x30, 0x05}})), spec_packet(0x0C, {ack(0x30)}));
  // Get IMU Base Rate -> 0x83: u16.
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x02, 0x06}})), spec_packet(0x0C, {ack(0x06), {0x04, 0x83, 0x03, 0xE8}}));
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x0A, 0x08, 0x01, 0x02, 0x04, 0x00, 0x64, 0x05, 0x00, 0x64}})),
            spec_packet(0x0C, {ack(0x08)}));
  EXPECT_EQ(ask(d, spec_packet(0x01, {{0x02, 0x06}})), spec_packet(0x01, {ack(0x06)}));
  const auto sent = stream(e, 0, 1000);
  ASSERT_EQ(sent.size(), 10u);
  EXPECT_EQ(sent.begin()->first, 0u);
  EXPECT_EQ(sent.begin()->second, (std::vector<std::uint8_t>{0x04, 0x05}));
}

TEST(MipDevice, Px4MicrostrainStartUpReplayGetsEveryAckItWaitsFor) {
  drivers::mip::Encoder e(options_1000hz());
  drivers::CommandResponder& d = *e.command_responder();
  // connectAtBaud(115200): forceIdle.
  EXPECT_EQ(ask(d, spec_packet(0x01, {{0x02, 0x02}})), spec_packet(0x01, {ack(0x02)}));
  // getSupportedDescriptors: both commands; it needs 0x0109, 0x0C0E, 0x0C0F, 0x0D01, 0x0C11, 0x0106 listed.
  const Bytes desc = ask(d, spec_packet(0x01, {{0x02, 0x04}}));
  for (const Bytes& needed : {Bytes{0x01, 0x09}, Bytes{0x0C, 0x0E}, Bytes{0x0C, 0x0F}, Bytes{0x0D, 0x01},
                              Bytes{0x0C, 0x11}, Bytes{0x01, 0x06}, Bytes{0x80, 0x04}, Bytes{0x80, 0x05}}) {
    EXPECT_NE(std::search(desc.begin() + 10, desc.end() - 2, needed.begin(), needed.end()), desc.end() - 2);
  }
  EXPECT_EQ(ask(d, spec_packet(0x01, {{0x02, 0x07}})), spec_packet(0x01, {ack(0x07), {0x02, 0x86}}));
  // writeBaudRate(921600, port 1) -> Comm Port Speed; the change follows the ACK.
  Sink sink;
  EXPECT_EQ(ask(d, spec_packet(0x01, {{0x08, 0x09, 0x01, 0x01, 0x00, 0x0E, 0x10, 0x00}}), &sink),
            spec_packet(0x01, {ack(0x09)}));
  EXPECT_EQ(sink.baud_after, 921600u);
  // connectAtBaud(921600): forceIdle.
  EXPECT_EQ(ask(d, spec_packet(0x01, {{0x02, 0x02}})), spec_packet(0x01, {ack(0x02)}));
  // configureImuMessageFormat: base rate 0x80, accel + gyro at 1000/500 = 2.
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x03, 0x0E, 0x80}})),
            spec_packet(0x0C, {ack(0x0E), {0x05, 0x8E, 0x80, 0x03, 0xE8}}));
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x0B, 0x0F, 0x01, 0x80, 0x02, 0x04, 0x00, 0x02, 0x05, 0x00, 0x02}})),
            spec_packet(0x0C, {ack(0x0F)}));
  // configureFilterMessageFormat: base rate 0x82, then a format with no field.
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x03, 0x0E, 0x82}})),
            spec_packet(0x0C, {ack(0x0E), {0x05, 0x8E, 0x82, 0x03, 0xE8}}));
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x05, 0x0F, 0x01, 0x82, 0x00}})), spec_packet(0x0C, {ack(0x0F)}));
  // configureGnssMessageFormat(0x91 / 0x92): no GNSS receiver: invalid parameter (not fatal to PX4).
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x03, 0x0E, 0x91}})), spec_packet(0x0C, {ack(0x0E, 0x03)}));
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x03, 0x0E, 0x92}})), spec_packet(0x0C, {ack(0x0E, 0x03)}));
  // Aiding and filter initialisation: not listed, so PX4 sends nothing. Reset Filter:
  EXPECT_EQ(ask(d, spec_packet(0x0D, {{0x02, 0x01}})), spec_packet(0x0D, {ack(0x01)}));
  // Datastream Control: write, all streams (0), on.
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x05, 0x11, 0x01, 0x00, 0x01}})), spec_packet(0x0C, {ack(0x11)}));
  EXPECT_EQ(ask(d, spec_packet(0x01, {{0x02, 0x06}})), spec_packet(0x01, {ack(0x06)}));
  // 500 Hz accel + gyro.
  const auto sent = stream(e, 1, 1000);
  ASSERT_EQ(sent.size(), 500u);
  for (const auto& [k, fields] : sent) {
    EXPECT_EQ(k % 2, 0u);
    EXPECT_EQ(fields, (std::vector<std::uint8_t>{0x04, 0x05}));
  }
  EXPECT_EQ(d.command_counters().baud, 921600u);
}

// Issue 28: the same start-up with the device's filter data set on (scene
// key mip.filter_rate_hz). PX4 reads the filter fields the device lists and
// asks for each at base_rate / MS_FILT_RATE_HZ (250 Hz: 1000 / 250 = 4);
// without them its configureFilterMessageFormat writes an empty format and
// no filter data ever arrives. The field list is configureFilterMessageFormat's
// order: LLH 0x01, attitude quaternion 0x03, NED velocity 0x02, LLH
// uncertainty 0x08, velocity uncertainty 0x09, Euler uncertainty 0x0A,
// filter status 0x10, shared GPS timestamp 0xD3 (the stored version with
// configureGnssMessageFormat; PX4-Autopilot 606cd80986e16b31deb7e327eb7f01a1b219a108
// asks for the same without 0xD3). Where the device lists no Get Base Rate
// (0x0C,0x0E) PX4 falls back to Get Filter Base Rate (0x0C,0x0B: "Filter base
// rate command is not supported" otherwise) and Filter Message Format
// (0x0C,0x0A): both answered here too.
TEST(MipDevice, Px4MicrostrainStartUpWithTheFilterSetConfiguresAndStreamsTheFilterData) {
  drivers::StreamEncoderOptions o = options_1000hz();
  o.mip_nav.filter_rate_hz = 100;  // the power-up rate; PX4 sets its own
  drivers::mip::Encoder e(o);
  drivers::CommandResponder& d = *e.command_responder();
  EXPECT_EQ(ask(d, spec_packet(0x01, {{0x02, 0x02}})), spec_packet(0x01, {ack(0x02)}));
  const Bytes desc = ask(d, spec_packet(0x01, {{0x02, 0x04}}));
  for (const Bytes& needed : {Bytes{0x0C, 0x0E}, Bytes{0x0C, 0x0F}, Bytes{0x0C, 0x0B}, Bytes{0x0C, 0x0A},
                              Bytes{0x82, 0x01}, Bytes{0x82, 0x03}, Bytes{0x82, 0x02}, Bytes{0x82, 0x08},
                              Bytes{0x82, 0x09}, Bytes{0x82, 0x0A}, Bytes{0x82, 0x10}, Bytes{0x82, 0xD3}}) {
    bool listed = false;  // the reply's u16 list, after the ACK (4 bytes) and the 0x82 field header (2)
    for (std::size_t i = 10; i + 1 < desc.size() - 2; i += 2) listed = listed || (desc[i] == needed[0] && desc[i + 1] == needed[1]);
    EXPECT_TRUE(listed) << int(needed[0]) << "," << int(needed[1]);
  }
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x0B, 0x0F, 0x01, 0x80, 0x02, 0x04, 0x00, 0x02, 0x05, 0x00, 0x02}})),
            spec_packet(0x0C, {ack(0x0F)}));
  // configureFilterMessageFormat: the base rate, by either command.
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x03, 0x0E, 0x82}})),
            spec_packet(0x0C, {ack(0x0E), {0x05, 0x8E, 0x82, 0x03, 0xE8}}));
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x02, 0x0B}})), spec_packet(0x0C, {ack(0x0B), {0x04, 0x8A, 0x03, 0xE8}}));
  // Filter Message Format (0x0C,0x0A) then Message Format (0x0C,0x0F): 8 fields at decimation 4.
  const Bytes list{0x08, 0x01, 0x00, 0x04, 0x03, 0x00, 0x04, 0x02, 0x00, 0x04, 0x08, 0x00, 0x04,
                   0x09, 0x00, 0x04, 0x0A, 0x00, 0x04, 0x10, 0x00, 0x04, 0xD3, 0x00, 0x04};
  Bytes cmd_a{static_cast<std::uint8_t>(3 + list.size()), 0x0A, 0x01};
  cmd_a.insert(cmd_a.end(), list.begin(), list.end());
  EXPECT_EQ(ask(d, spec_packet(0x0C, {cmd_a})), spec_packet(0x0C, {ack(0x0A)}));
  Bytes cmd_f{static_cast<std::uint8_t>(4 + list.size()), 0x0F, 0x01, 0x82};
  cmd_f.insert(cmd_f.end(), list.begin(), list.end());
  EXPECT_EQ(ask(d, spec_packet(0x0C, {cmd_f})), spec_packet(0x0C, {ack(0x0F)}));
  // Read back (0x0C,0x0F function 2 -> 0x8F: set, count, list).
  Bytes readback{static_cast<std::uint8_t>(3 + list.size()), 0x8F, 0x82};
  readback.insert(readback.end(), list.begin(), list.end());
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x04, 0x0F, 0x02, 0x82}})), spec_packet(0x0C, {ack(0x0F), readback}));
  EXPECT_EQ(ask(d, spec_packet(0x0D, {{0x02, 0x01}})), spec_packet(0x0D, {ack(0x01)}));
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x05, 0x11, 0x01, 0x00, 0x01}})), spec_packet(0x0C, {ack(0x11)}));
  EXPECT_EQ(ask(d, spec_packet(0x01, {{0x02, 0x06}})), spec_packet(0x01, {ack(0x06)}));
  // One second: 500 IMU packets (accel + gyro) and 250 filter packets with the 8 fields in PX4's order.
  std::size_t imu = 0, filter = 0;
  for (std::uint64_t k = 0; k < 1000; ++k) {
    drivers::ImuFrameInput s;
    s.sample_counter = k;
    s.t_ns = static_cast<TimeNs>(k) * 1'000'000;
    Bytes out;
    e.encode(s, out);
    std::size_t garbage = 0, tail = 0;
    for (const SeenPacket& p : split_packets(out, &garbage, &tail)) {
      if (p.set == 0x80) {
        ++imu;
        EXPECT_EQ(p.fields, (std::vector<std::uint8_t>{0x04, 0x05}));
      } else {
        ASSERT_EQ(p.set, 0x82);
        ++filter;
        EXPECT_EQ(k % 4, 0u);
        EXPECT_EQ(p.fields, (std::vector<std::uint8_t>{0x01, 0x03, 0x02, 0x08, 0x09, 0x0A, 0x10, 0xD3}));
      }
    }
    EXPECT_EQ(garbage + tail, 0u);
  }
  EXPECT_EQ(imu, 500u);
  EXPECT_EQ(filter, 250u);
  EXPECT_EQ(d.command_counters().nacked, 0u);
}

// Issue 28: the GNSS set 0x81 by its own commands (Get GNSS Base Rate
// 0x0C,0x07 -> 0x84; GNSS Message Format 0x0C,0x09 -> 0x81) and by the
// descriptor-set ones; a field the receiver has not (0x81,0x04) is refused
// with nothing changed.
TEST(MipDevice, GnssSetFormatIsSetByItsOwnAndTheDescriptorSetCommands) {
  drivers::StreamEncoderOptions o = options_1000hz();
  o.mip_nav.gnss_rate_hz = 4;
  drivers::mip::Encoder e(o);
  drivers::CommandResponder& d = *e.command_responder();
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x02, 0x07}})), spec_packet(0x0C, {ack(0x07), {0x04, 0x84, 0x03, 0xE8}}));
  // Power-up: LLH, NED velocity, fix info, GPS timestamp at 1000 / 4 = 250 = 0x00FA.
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x03, 0x09, 0x02}})),
            spec_packet(0x0C, {ack(0x09), {0x0F, 0x81, 0x04, 0x03, 0x00, 0xFA, 0x05, 0x00, 0xFA, 0x0B, 0x00, 0xFA,
                                          0xD3, 0x00, 0xFA}}));
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x07, 0x09, 0x01, 0x01, 0x04, 0x00, 0x64}})), spec_packet(0x0C, {ack(0x09, 0x03)}));
  // Message Format 0x0F on set 0x81: fix info and GPS time 0x09 at 500 (2 Hz).
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x0B, 0x0F, 0x01, 0x81, 0x02, 0x0B, 0x01, 0xF4, 0x09, 0x01, 0xF4}})),
            spec_packet(0x0C, {ack(0x0F)}));
  std::size_t gnss = 0;
  for (std::uint64_t k = 0; k < 2000; ++k) {
    drivers::ImuFrameInput s;
    s.sample_counter = k;
    s.t_ns = static_cast<TimeNs>(k) * 1'000'000;
    Bytes out;
    e.encode(s, out);
    for (const SeenPacket& p : split_packets(out)) {
      if (p.set != 0x81) continue;
      ++gnss;
      EXPECT_EQ(k % 500, 0u);
      EXPECT_EQ(p.fields, (std::vector<std::uint8_t>{0x0B, 0x09}));
    }
  }
  EXPECT_EQ(gnss, 4u);
  // Datastream Control off for 0x81 alone: the IMU goes on, GNSS stops.
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x05, 0x11, 0x01, 0x81, 0x00}})), spec_packet(0x0C, {ack(0x11)}));
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x04, 0x11, 0x02, 0x81}})), spec_packet(0x0C, {ack(0x11), {0x04, 0x85, 0x81, 0x00}}));
  Bytes out;
  drivers::ImuFrameInput s;
  s.sample_counter = 2000;
  e.encode(s, out);
  const auto packets = split_packets(out);
  ASSERT_EQ(packets.size(), 1u);
  EXPECT_EQ(packets[0].set, 0x80);
}

// Without the GNSS receiver its commands stay unknown and set 0x81 invalid, as before issue 28.
TEST(MipDevice, WithoutAGnssReceiverItsCommandsAreRefusedAsBefore) {
  drivers::mip::Encoder e(options_1000hz());
  drivers::CommandResponder& d = *e.command_responder();
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x02, 0x07}})), spec_packet(0x0C, {ack(0x07, 0x01)}));
  EXPECT_EQ(ask(d, spec_packet(0x0C, {{0x03, 0x0E, 0x81}})), spec_packet(0x0C, {ack(0x0E, 0x03)}));
}

TEST(MipDevice, TheDefaultStreamIsTheOldEncodersOutputByteForByte) {
  // Without any command the device sends what the encoder sent before issue
  // 27 (the scenes' compared bytes): the same encoder with answering off.
  drivers::StreamEncoderOptions off = options_1000hz();
  off.mip_device.answers_commands = false;
  drivers::mip::Encoder legacy(off), device(options_1000hz());
  EXPECT_EQ(legacy.command_responder(), nullptr);
  for (std::uint64_t k = 0; k < 50; ++k) {
    drivers::ImuFrameInput s;
    s.sample_counter = k;
    s.t_ns = static_cast<TimeNs>(k) * 1'000'000;
    s.gyro_rad_s = Vec3(0.1 * static_cast<double>(k), -0.2, 0.3);
    s.accel_m_s2 = Vec3(1.0, 2.0, -9.8);
    Bytes a, b;
    legacy.encode(s, a);
    device.encode(s, b);
    ASSERT_EQ(a, b) << k;
  }
}

// ------------------------------------------------------------ scene keys

std::string scene_with_device(const std::string& protocol, const std::string& device_table) {
  return "[scene]\nname = \"t\"\nphysics = \"flat\"\n[trajectory]\nsource = \"sample:static\"\nduration_s = 10\n"
         "[[imu]]\nname = \"a\"\nrate_hz = 500\nprotocol = \"" + protocol + "\"\n[imu.transport]\ntype = \"null\"\n" +
         device_table;
}

TEST(MipDevice, SceneKeysUnderImuDeviceSetIdentityAndPowerUpMode) {
  const scene::SceneConfig c = scene::parse_scene_text(
      scene_with_device("mip", "[imu.device]\npower_up_mode = \"idle\"\nmodel_name = \"3DM-GX5-25\"\n"
                               "model_number = \"6251-4220\"\nserial_number = \"6251.99\"\n"
                               "firmware_version = \"1.2.03\"\nhardware_revision = \"B\"\n"),
      "t.toml", "/tmp");
  const drivers::MipDeviceConfig& d = c.imus.at(0).stream_options.mip_device;
  EXPECT_TRUE(d.power_up_idle);
  EXPECT_EQ(d.model_name, "3DM-GX5-25");
  EXPECT_EQ(d.model_number, "6251-4220");
  EXPECT_EQ(d.serial_number, "6251.99");
  EXPECT_EQ(d.firmware_version, 1203);
  EXPECT_EQ(d.hardware_revision, "B");
  // Defaults: a streaming 3DM-CV7-AHRS.
  const scene::SceneConfig dflt = scene::parse_scene_text(scene_with_device("mip", ""), "t.toml", "/tmp");
  EXPECT_FALSE(dflt.imus.at(0).stream_options.mip_device.power_up_idle);
  EXPECT_EQ(dflt.imus.at(0).stream_options.mip_device.model_name, "3DM-CV7-AHRS");
  // Refused: a string longer than its 16-character field, a bad mode, another protocol.
  for (const std::string& bad : {scene_with_device("mip", "[imu.device]\nmodel_name = \"0123456789abcdefg\"\n"),
                                 scene_with_device("mip", "[imu.device]\npower_up_mode = \"asleep\"\n"),
                                 scene_with_device("mip", "[imu.device]\nfirmware_version = \"1.10.0\"\n"),
                                 scene_with_device("native", "[imu.device]\npower_up_mode = \"idle\"\n")}) {
    EXPECT_THROW((void)scene::parse_scene_text(bad, "t.toml", "/tmp"), std::exception) << bad;
  }
}

// The writer thread's side, with a device that takes at most 7 bytes per
// write (a UART's kernel buffer nearly full): replies still never land
// inside a frame, and the baud change comes after the ACK's last byte.
class SlowUart final : public drivers::WriterDevice {
 public:
  struct Shared {
    std::mutex mutex;
    Bytes wire;
    std::vector<std::pair<std::size_t, std::uint32_t>> baud_changes;  // wire offset, rate
  };
  SlowUart(std::shared_ptr<Shared> shared, int input_fd) : shared_(std::move(shared)), input_fd_(input_fd) {}
  bool datagrams() const override { return false; }
  int poll_fd() const override { return input_fd_; }
  drivers::DeviceWrite write(std::span<const std::byte> bytes) override {
    const std::size_t take = std::min<std::size_t>(bytes.size(), 7);
    std::lock_guard lock(shared_->mutex);
    for (std::size_t i = 0; i < take; ++i) shared_->wire.push_back(static_cast<std::uint8_t>(bytes[i]));
    return {drivers::DeviceWrite::Outcome::written, take, {}};
  }
  std::optional<std::string> service(short revents, std::uint64_t* discarded) override {
    if (revents & POLLIN) {
      std::byte buf[256];
      const ssize_t n = ::read(input_fd_, buf, sizeof buf);
      if (n > 0) deliver_input(std::span<const std::byte>(buf, static_cast<std::size_t>(n)), discarded);
    }
    return std::nullopt;
  }
  bool set_baud(std::uint32_t baud, std::string&) override {
    std::lock_guard lock(shared_->mutex);
    shared_->baud_changes.emplace_back(shared_->wire.size(), baud);
    return true;
  }
  void on_link_lost() override {}
  bool try_restore(std::string&) override { return true; }
  bool initially_up() const override { return true; }

 private:
  std::shared_ptr<Shared> shared_;
  int input_fd_;
};

TEST(MipDevice, TheWriterPutsRepliesBetweenFramesAndChangesBaudAfterTheAckEvenOnPartialWrites) {
  int pipe_fds[2];
  ASSERT_EQ(::pipe2(pipe_fds, O_NONBLOCK | O_CLOEXEC), 0);
  auto shared = std::make_shared<SlowUart::Shared>();
  drivers::QueuedWriterOptions wo;
  wo.name = "slow uart";
  wo.baud = 115200;
  wo.log = [](std::string_view) {};
  drivers::QueuedWriter writer(std::make_unique<SlowUart>(shared, pipe_fds[0]), wo);
  drivers::mip::Encoder e(options_1000hz());
  writer.set_input_handler(e.command_responder());

  const Bytes ping = spec_packet(0x01, {{0x02, 0x01}});
  const Bytes to_460800 = spec_packet(0x01, {{0x08, 0x09, 0x01, 0x01, 0x00, 0x07, 0x08, 0x00}});
  constexpr int kRounds = 40;
  for (int r = 0; r < kRounds; ++r) {
    for (int f = 0; f < 5; ++f) {
      drivers::ImuFrameInput s;
      s.sample_counter = static_cast<std::uint64_t>(r * 5 + f);
      Bytes frame;
      e.encode(s, frame);
      ASSERT_TRUE(writer.offer(std::as_bytes(std::span<const std::uint8_t>(frame))));
    }
    // Mid-run, the rate change and a ping in one read: the ping's ACK is
    // queued before the rate change's ACK has left, and must still leave
    // after the change (at the new rate), not hold the change back.
    Bytes c = ping;
    if (r == kRounds / 2) {
      c = to_460800;
      c.insert(c.end(), ping.begin(), ping.end());
    }
    ASSERT_EQ(::write(pipe_fds[1], c.data(), c.size()), static_cast<ssize_t>(c.size()));
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  constexpr std::uint64_t kReplies = kRounds + 1;  // one per command
  while (writer.counters().replies_sent < kReplies &&
         std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  ASSERT_TRUE(writer.flush(std::chrono::seconds(5)));
  writer.stop(std::chrono::milliseconds(100));
  ::close(pipe_fds[0]);
  ::close(pipe_fds[1]);

  std::lock_guard lock(shared->mutex);
  std::size_t garbage = 0, tail = 0;
  const std::vector<SeenPacket> packets = split_packets(shared->wire, &garbage, &tail);
  EXPECT_EQ(garbage + tail, 0u) << "a reply inside a frame would leave bytes outside whole packets";
  std::size_t replies = 0, frames = 0;
  for (const SeenPacket& p : packets) (p.set < 0x80 ? replies : frames) += 1;
  EXPECT_EQ(replies, kReplies);
  EXPECT_EQ(frames, static_cast<std::size_t>(kRounds * 5));
  // One baud change, right where the Comm Port Speed ACK ends.
  ASSERT_EQ(shared->baud_changes.size(), 1u);
  EXPECT_EQ(shared->baud_changes[0].second, 460800u);
  const Bytes ack_packet = spec_packet(0x01, {ack(0x09)});
  const std::size_t at = shared->baud_changes[0].first;
  ASSERT_GE(at, ack_packet.size());
  EXPECT_EQ(Bytes(shared->wire.begin() + static_cast<std::ptrdiff_t>(at - ack_packet.size()),
                  shared->wire.begin() + static_cast<std::ptrdiff_t>(at)),
            ack_packet);
  EXPECT_EQ(writer.baud(), 460800u);
  EXPECT_EQ(writer.counters().input_bytes, kRounds * ping.size() + to_460800.size());
}

// ----------------------------------------------- on a pty, while streaming

bool read_some(int fd, Bytes& into, int timeout_ms) {
  pollfd p{fd, POLLIN, 0};
  if (::poll(&p, 1, timeout_ms) <= 0) return false;
  std::uint8_t buf[4096];
  const ssize_t n = ::read(fd, buf, sizeof buf);
  if (n <= 0) return false;
  into.insert(into.end(), buf, buf + n);
  return true;
}

TEST(MipDevice, OnAPtyCommandsAt100HzWhileStreamingAreAllAnsweredBetweenFramesAndEmissionAllocatesNothing) {
  const std::string link = ::testing::TempDir() + "imuemu_mip_device_" + std::to_string(::getpid());
  drivers::PtyTransportOptions po;
  po.link_path = link;
  po.log = [](std::string_view) {};
  auto encoder = std::make_unique<drivers::mip::Encoder>(options_1000hz());
  auto transport = std::make_unique<drivers::PtyTransport>(po);
  drivers::PtyTransport* pty = transport.get();
  std::unique_ptr<device::Device> dev = device::make_stream_device(std::move(encoder), std::move(transport));

  const int fd = ::open(link.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK);
  ASSERT_GE(fd, 0);
  termios t{};
  ::tcgetattr(fd, &t);
  ::cfmakeraw(&t);
  ::tcsetattr(fd, TCSANOW, &t);
  const auto until_up = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (!pty->link_up() && std::chrono::steady_clock::now() < until_up)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  ASSERT_TRUE(pty->link_up());

  // The emission thread: one sample per ms, allocations counted on it alone.
  std::atomic<bool> stop{false};
  std::atomic<std::uint64_t> emitted{0};
  std::thread emission([&] {
    drivers::LinkActions none;
    drivers::ImuFrameInput s;
    s.accel_m_s2 = Vec3(0.0, 0.0, -9.80665);
    t_counting = true;
    for (std::uint64_t k = 0; !stop.load(std::memory_order_relaxed); ++k) {
      s.sample_counter = k;
      s.t_ns = static_cast<TimeNs>(k) * 1'000'000;
      (void)dev->emit(s, none, 0);
      emitted.fetch_add(1, std::memory_order_relaxed);
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    t_counting = false;
  });

  // The client: 150 commands at 100 per second (ping, read the format, get
  // the base rate), reading everything the device sends meanwhile.
  const std::vector<Bytes> commands{spec_packet(0x01, {{0x02, 0x01}}), spec_packet(0x0C, {{0x04, 0x0F, 0x02, 0x80}}),
                                    spec_packet(0x0C, {{0x03, 0x0E, 0x80}})};
  constexpr int kCommands = 150;
  Bytes received;
  for (int i = 0; i < kCommands; ++i) {
    const Bytes& c = commands[static_cast<std::size_t>(i) % commands.size()];
    ASSERT_EQ(::write(fd, c.data(), c.size()), static_cast<ssize_t>(c.size()));
    const auto next = std::chrono::steady_clock::now() + std::chrono::milliseconds(10);
    while (std::chrono::steady_clock::now() < next) read_some(fd, received, 2);
  }
  // Every reply, however long the host takes (no timing asserted).
  auto replies_seen = [&] {
    std::size_t n = 0;
    for (const SeenPacket& p : split_packets(received)) n += p.set < 0x80 ? 1 : 0;
    return n;
  };
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (replies_seen() < static_cast<std::size_t>(kCommands) && std::chrono::steady_clock::now() < deadline)
    read_some(fd, received, 20);
  stop = true;
  emission.join();
  while (read_some(fd, received, 50)) {
  }

  std::size_t garbage = 0, tail = 0;
  const std::vector<SeenPacket> packets = split_packets(received, &garbage, &tail);
  std::size_t replies = 0, data = 0;
  for (const SeenPacket& p : packets) {
    if (p.set < 0x80) {
      ++replies;
      EXPECT_EQ(p.fields.front(), 0xF1);
    } else {
      ++data;
      EXPECT_EQ(p.fields, (std::vector<std::uint8_t>{0x04, 0x05, 0x07, 0x08, 0x12, 0x18}));
    }
  }
  // A reply inside a frame would break both: every byte is in a whole,
  // valid packet (the first data packet may be cut by the reader's arrival:
  // counted garbage only before the first packet).
  EXPECT_EQ(replies, static_cast<std::size_t>(kCommands));
  EXPECT_GT(data, 100u);
  EXPECT_EQ(garbage, 0u);
  EXPECT_EQ(g_emission_allocations.load(), 0u) << "the emission thread allocated while commands were answered";
  const std::optional<device::CommandStatus> status = dev->command_status();
  ASSERT_TRUE(status);
  EXPECT_EQ(status->received, static_cast<std::uint64_t>(kCommands));
  EXPECT_EQ(status->answered, static_cast<std::uint64_t>(kCommands));
  EXPECT_EQ(status->replies_dropped, 0u);
  EXPECT_EQ(dev->counters().input_bytes, [&] {
    std::uint64_t n = 0;
    for (int i = 0; i < kCommands; ++i) n += commands[static_cast<std::size_t>(i) % commands.size()].size();
    return n;
  }());
  EXPECT_EQ(dev->counters().replies_sent, static_cast<std::uint64_t>(kCommands));
  std::printf("emitted %llu samples, %zu data packets and %zu replies read, 0 bytes outside packets\n",
              static_cast<unsigned long long>(emitted.load()), data, replies);
  ::close(fd);
  dev->stop(std::chrono::milliseconds(100), false);
}

// The MAVLink device (tests/device/test_mavlink_device.cpp) serialises its
// answers on the emission thread (one seq for every packet): that thread
// still allocates nothing - the answers come through a fixed-capacity ring
// and go into the output the device reserved. Here because this file owns
// the room's allocation counter.
TEST(MipDevice, MavlinkAnswersSerialisedOnTheEmissionThreadAllocateNothing) {
  drivers::StreamEncoderOptions o;
  o.nominal_sample_rate_hz = 100.0;
  drivers::mavlink2::Encoder enc(o);
  drivers::CommandResponder* r = enc.command_responder();
  ASSERT_NE(r, nullptr);
  struct UnusedSink final : drivers::ReplySink {
    bool reply(std::span<const std::uint8_t>) override { return true; }
    void change_baud_after_replies(std::uint32_t) override {}
  } sink;
  // COMMAND_LONG REQUEST_MESSAGE(HEARTBEAT) and PARAM_REQUEST_LIST as the
  // device's own parser must accept them (CRC with CRC_EXTRA 152 / 159).
  auto frame = [](std::uint32_t msgid, Bytes payload, std::uint8_t extra) {
    Bytes f{0xFD, static_cast<std::uint8_t>(payload.size()), 0, 0, 0, 255, 190, static_cast<std::uint8_t>(msgid), 0, 0};
    f.insert(f.end(), payload.begin(), payload.end());
    Bytes crc_in(f.begin() + 1, f.end());
    crc_in.push_back(extra);
    const std::uint16_t crc = drivers::mavlink2::crc16_mcrf4xx(crc_in);
    f.push_back(static_cast<std::uint8_t>(crc));
    f.push_back(static_cast<std::uint8_t>(crc >> 8));
    return f;
  };
  Bytes cmd(33, 0);
  cmd[28] = 0x00;  // command 512 = 0x0200
  cmd[29] = 0x02;
  cmd[30] = 1;
  cmd[31] = 200;
  Bytes out;
  out.reserve(4096);
  drivers::ImuFrameInput s;
  s.period_ns = 10'000'000;
  std::uint64_t allocations = 0;
  for (std::uint64_t k = 0; k < 200; ++k) {
    if (k % 4 == 0) r->on_input(frame(76, cmd, 152), sink);
    if (k % 4 == 2) r->on_input(frame(21, Bytes{1, 200}, 159), sink);
    s.sample_counter = k;
    s.t_ns = static_cast<TimeNs>(k) * s.period_ns;
    out.clear();
    const std::uint64_t before = g_emission_allocations.load();
    t_counting = true;
    enc.encode(s, out);
    enc.periodic(s.t_ns, out);
    t_counting = false;
    allocations += g_emission_allocations.load() - before;
  }
  EXPECT_EQ(allocations, 0u);
  const drivers::CommandCounters c = r->command_counters();
  EXPECT_EQ(c.received, 100u);
  EXPECT_EQ(c.answered, 100u);
}

// The replies a device sends (the emission tests below count them).
struct CountingReplySink final : drivers::ReplySink {
  std::size_t replies = 0;
  bool reply(std::span<const std::uint8_t>) override { return ++replies, true; }
  void change_baud_after_replies(std::uint32_t) override {}
};

struct EmissionTally {
  std::uint64_t allocations = 0;  // inside encode() only
  std::uint64_t bytes = 0;        // emitted
};
// Encodes `samples` samples of `period_ns` with a navigation fix at
// `latitude_rad` into a buffer reserved to max_bytes_per_sample(), as the
// emission thread does, calling between(k) before sample k (the commands
// the io thread answers meanwhile, not counted).
EmissionTally encode_counting_allocations(drivers::StreamEncoder& enc, std::uint64_t samples, TimeNs period_ns,
                                          double latitude_rad, const std::function<void(std::uint64_t)>& between) {
  Bytes out;
  out.reserve(enc.max_bytes_per_sample());
  drivers::ImuFrameInput s;
  s.period_ns = period_ns;
  s.has_navigation = true;
  s.latitude_rad = latitude_rad;
  EmissionTally tally;
  for (std::uint64_t k = 0; k < samples; ++k) {
    between(k);
    s.sample_counter = k;
    s.t_ns = static_cast<TimeNs>(k) * s.period_ns;
    out.clear();
    const std::uint64_t before = g_emission_allocations.load();
    t_counting = true;
    enc.encode(s, out);
    t_counting = false;
    tally.allocations += g_emission_allocations.load() - before;
    tally.bytes += out.size();
  }
  return tally;
}

// The VectorNav device (tests/device/test_vectornav_device.cpp): its encoder
// builds three binary outputs and an ASCII sentence per sample and hands its
// latest measurements to the command side, while register writes change
// what it streams between samples - allocating nothing. Here because this
// file owns the room's allocation counter.
TEST(MipDevice, VectorNavEmissionWithCommandsBetweenSamplesAllocatesNothing) {
  drivers::StreamEncoderOptions o;
  o.nominal_sample_rate_hz = 400.0;
  o.vectornav.model = drivers::VectorNavModel::vn300;
  drivers::vectornav::Encoder enc(o);
  drivers::CommandResponder* r = enc.command_responder();
  ASSERT_NE(r, nullptr);
  CountingReplySink sink;
  auto send = [&](const std::string& body) {
    char sum[8];
    std::uint8_t x = 0;
    for (const char c : body) x ^= static_cast<std::uint8_t>(c);
    std::snprintf(sum, sizeof sum, "*%02X\r\n", x);
    const std::string cmd = "$" + body + sum;
    r->on_input(std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(cmd.data()), cmd.size()), sink);
  };
  send("VNWRG,05,921600");
  send("VNWRG,75,1,2,01,0721");
  send("VNWRG,76,1,8,31,0001,0106,0613");
  send("VNWRG,77,1,80,49,0003,26B8,0018");
  const EmissionTally tally = encode_counting_allocations(enc, 400, 2'500'000, 0.8, [&](std::uint64_t k) {
    if (k % 10 == 0) send("VNRRG,08");
    if (k % 100 == 50) send(k % 200 == 50 ? "VNWRG,06,19" : "VNWRG,06,14");
  });
  EXPECT_EQ(tally.allocations, 0u);
  EXPECT_EQ(sink.replies, 4u + 40u + 4u);
  EXPECT_EQ(r->command_counters().nacked, 0u);
}

// The SBG device (tests/device/test_sbg_device.cpp): every log on at once
// (IMU at 1 kHz, the navigation logs at the 200 Hz main loop) while
// OUTPUT_CONF and REST API commands change what it streams between samples
// - allocating nothing on the emission thread.
TEST(MipDevice, SbgEmissionWithCommandsBetweenSamplesAllocatesNothing) {
  drivers::StreamEncoderOptions o;
  o.nominal_sample_rate_hz = 1000.0;
  o.sbg.model = drivers::SbgModel::ellipse_n;
  drivers::sbg::Encoder enc(o);
  drivers::CommandResponder* r = enc.command_responder();
  ASSERT_NE(r, nullptr);
  CountingReplySink sink;
  auto send = [&](std::uint8_t msg, const Bytes& payload) {
    Bytes frame;
    drivers::sbg::append_frame(msg, drivers::sbg::kClassCmd0, payload, frame);
    r->on_input(frame, sink);
  };
  auto output_conf = [&](std::uint8_t log, std::uint8_t cls, std::uint16_t mode) {
    send(drivers::sbg::kCmdOutputConf, Bytes{0, log, cls, static_cast<std::uint8_t>(mode & 0xFF),
                                             static_cast<std::uint8_t>(mode >> 8)});
  };
  for (const int log : {1, 2, 4, 6, 7, 8, 13, 14}) output_conf(static_cast<std::uint8_t>(log), 0, 1);
  output_conf(3, 0, 1001);
  output_conf(44, 0, 1001);
  output_conf(0, 1, 20001);
  const EmissionTally tally = encode_counting_allocations(enc, 1000, 1'000'000, 0.7, [&](std::uint64_t k) {
    if (k % 100 == 0) send(drivers::sbg::kCmdInfo, Bytes{});
    if (k % 250 == 125) {
      const std::string path = "/api/v1/settings/output/comA/messages/ekfEuler";
      const std::string body = k % 500 == 125 ? "\"100ms\"" : "\"5ms\"";
      Bytes p(path.begin(), path.end());
      p.push_back(0);
      p.push_back(0);
      p.insert(p.end(), body.begin(), body.end());
      p.push_back(0);
      send(drivers::sbg::kCmdApiPost, p);
    }
  });
  EXPECT_EQ(tally.allocations, 0u);
  EXPECT_EQ(sink.replies, 11u + 10u + 4u);
  EXPECT_EQ(r->command_counters().nacked, 0u);
}

// The Xsens MTi device (tests/device/test_xsens_device.cpp): its encoder
// builds an MTData2 of every quantity in float64 and fixed point per sample
// and hands its latest measurements to the command side, while ReqData,
// GotoConfig / SetOutputConfiguration / GotoMeasurement change what it
// streams between samples - allocating nothing.
TEST(MipDevice, XsensEmissionWithCommandsBetweenSamplesAllocatesNothing) {
  drivers::StreamEncoderOptions o;
  o.nominal_sample_rate_hz = 400.0;
  o.xsens.model = drivers::XsensModel::mti680g;
  drivers::xsens::Encoder enc(o);
  drivers::CommandResponder* r = enc.command_responder();
  ASSERT_NE(r, nullptr);
  CountingReplySink sink;
  // Xbus frames written here from [L 2.2]: FA FF MID LEN DATA CS.
  auto send = [&](std::uint8_t mid, std::vector<std::uint8_t> data) {
    Bytes f{0xFA, 0xFF, mid, static_cast<std::uint8_t>(data.size())};
    f.insert(f.end(), data.begin(), data.end());
    unsigned sum = 0;
    for (std::size_t i = 1; i < f.size(); ++i) sum += f[i];
    f.push_back(static_cast<std::uint8_t>(0x100 - (sum & 0xFF)));
    r->on_input(f, sink);
  };
  auto configure = [&](bool wide) {
    send(0x30, {});
    std::vector<std::uint8_t> cfg;
    const std::vector<std::uint16_t> ids =
        wide ? std::vector<std::uint16_t>{0x1020, 0x1060, 0x1010, 0x0813, 0x2013, 0x2027, 0x2033, 0x3010, 0x4012,
                                          0x4023, 0x4037, 0x5022, 0x5043, 0x7010, 0x8021, 0x8033, 0xC023, 0xD016, 0xE020}
             : std::vector<std::uint16_t>{0x1020, 0x1060, 0x2010, 0x4020, 0x8020, 0xE020};
    for (const std::uint16_t id : ids)
      for (const std::uint16_t v : {id, std::uint16_t{400}}) {
        cfg.push_back(static_cast<std::uint8_t>(v >> 8));
        cfg.push_back(static_cast<std::uint8_t>(v & 0xFF));
      }
    send(0xC0, cfg);
    send(0x10, {});
  };
  configure(true);
  const EmissionTally tally = encode_counting_allocations(enc, 400, 2'500'000, 0.8, [&](std::uint64_t k) {
    if (k % 10 == 0) send(0x34, {});  // ReqData
    if (k % 100 == 50) configure(k % 200 != 50);
  });
  EXPECT_EQ(tally.allocations, 0u);
  EXPECT_GT(tally.bytes, 400u * 100u);  // every sample streamed (config mode only between the commands)
  EXPECT_EQ(sink.replies, 3u + 40u + 4u * 3u);
  EXPECT_EQ(r->command_counters().nacked, 0u);
}

TEST(MipDevice, OnAPtyABaudChangeIsRecordedAfterTheAck) {
  const std::string link = ::testing::TempDir() + "imuemu_mip_baud_" + std::to_string(::getpid());
  drivers::PtyTransportOptions po;
  po.link_path = link;
  po.log = [](std::string_view) {};
  drivers::StreamEncoderOptions o = options_1000hz();
  o.mip_device.power_up_idle = true;  // a quiet line: the reply is all there is
  auto transport = std::make_unique<drivers::PtyTransport>(po);
  drivers::PtyTransport* pty = transport.get();
  std::unique_ptr<device::Device> dev =
      device::make_stream_device(std::make_unique<drivers::mip::Encoder>(o), std::move(transport));
  EXPECT_EQ(pty->baud(), 115200u);
  const int fd = ::open(link.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK);
  ASSERT_GE(fd, 0);
  termios t{};
  ::tcgetattr(fd, &t);
  ::cfmakeraw(&t);
  ::tcsetattr(fd, TCSANOW, &t);
  const Bytes cmd = spec_packet(0x0C, {{0x07, 0x40, 0x01, 0x00, 0x07, 0x08, 0x00}});  // UART Baudrate 460800
  ASSERT_EQ(::write(fd, cmd.data(), cmd.size()), static_cast<ssize_t>(cmd.size()));
  Bytes got;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (got.size() < 10 && std::chrono::steady_clock::now() < deadline) read_some(fd, got, 20);
  EXPECT_EQ(got, spec_packet(0x0C, {ack(0x40)}));
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (pty->baud() != 460800u && std::chrono::steady_clock::now() < until)
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  EXPECT_EQ(pty->baud(), 460800u);
  ASSERT_TRUE(dev->command_status());
  EXPECT_EQ(dev->command_status()->baud, 460800u);
  ::close(fd);
  dev->stop(std::chrono::milliseconds(100), false);
}

}  // namespace
