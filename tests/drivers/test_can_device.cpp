// The CAN devices answer the requests their drivers send (issue 27), tested
// at the frame seam (frames in -> reply frames out): the host has no CAN, so
// the SocketCAN path runs only in the hil fixtures.
//
// Every request is built here by hand, and every reply decoded here, from the
// documents, not from the code under test:
//  - DroneCAN specification 4.1 (CAN bus transport layer): 29-bit service
//    frame id = priority(5) << 24 | service type id(8) << 16 |
//    request_not_response(1) << 15 | destination node id(7) << 8 |
//    service_not_message(1)=1 << 7 | source node id(7); tail byte start(7)
//    end(6) toggle(5) transfer id(4..0), toggle 0 in the first frame; a
//    multi-frame transfer starts with the transfer CRC (CRC-16-CCITT-FALSE
//    seeded with the data type signature, 8 bytes LSB first), little-endian.
//  - DSDL uavcan/protocol: 1.GetNodeInfo (response NodeStatus status,
//    SoftwareVersion, HardwareVersion, uint8[<=80] name), 5.RestartNode
//    (uint40 magic_number 0xACCE551B1E -> bool ok, void7),
//    param/11.GetSet; signatures as published by the DroneCAN dsdlc
//    (libcanard examples: UAVCAN_GET_NODE_INFO_DATA_TYPE_SIGNATURE).
//    Sub-byte fields fill a byte from its most significant bit (NodeStatus
//    health in bits 7-6, mode 5-3).
//  - J1939-21 (Request PGN 59904 = 0xEA00, data = requested PGN 3 bytes LE;
//    Acknowledgement 59392 control 1 = NACK; BAM: TP.CM 0xEC00 control 32,
//    size, packets, 0xFF, PGN; TP.DT 0xEB00 sequence 1..n, 7 bytes, 0xFF
//    padding), J1939-81 (Address Claimed 0xEE00 to 255, data = NAME LE;
//    Cannot Claim from 254; lower NAME wins), J1939-71 (Component ID 65259:
//    make*model*serial*unit*; Software ID 65242: count, then fields each '*').
#include <gtest/gtest.h>

#include <cstdint>
#include <string>
#include <vector>

#include "drivers/protocol.hpp"
#include "drivers/protocols/dronecan.hpp"
#include "drivers/protocols/j1939.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace imuemu::drivers {}
namespace unity_drivers_test_can_device {
namespace imuemu { using namespace ::imuemu; }
namespace imuemu::drivers { using namespace ::imuemu::drivers; }

namespace imuemu::drivers {
namespace {

class CollectingSink final : public CanReplySink {
 public:
  bool reply(const CanFrame& frame) override {
    frames.push_back(frame);
    return true;
  }
  std::vector<CanFrame> frames;
};

// ---- DroneCAN, from the spec ----

constexpr std::uint64_t kGetNodeInfoSig = 0xEE468A8121C46A9EULL;  // published signature
constexpr std::uint64_t kGetSetSig = 0xA7B622F939D1A4D5ULL;

std::uint16_t crc_ccitt(std::uint16_t crc, std::uint8_t byte) {
  crc = static_cast<std::uint16_t>(crc ^ (byte << 8));
  for (int i = 0; i < 8; ++i) crc = (crc & 0x8000) ? static_cast<std::uint16_t>((crc << 1) ^ 0x1021) : static_cast<std::uint16_t>(crc << 1);
  return crc;
}
std::uint16_t spec_transfer_crc(std::uint64_t signature, const std::vector<std::uint8_t>& payload) {
  std::uint16_t crc = 0xFFFF;
  for (int i = 0; i < 8; ++i) crc = crc_ccitt(crc, static_cast<std::uint8_t>(signature >> (8 * i)));
  for (std::uint8_t b : payload) crc = crc_ccitt(crc, b);
  return crc;
}

std::uint32_t service_id(unsigned prio, unsigned service, bool request, unsigned dest, unsigned src) {
  return prio << 24 | service << 16 | (request ? 1u : 0u) << 15 | dest << 8 | 1u << 7 | src;
}

// The frames of a request transfer, split by hand.
std::vector<CanFrame> request_frames(std::uint32_t id, std::uint64_t signature, std::vector<std::uint8_t> payload,
                                     unsigned tid) {
  std::vector<CanFrame> out;
  if (payload.size() <= 7) {
    CanFrame f;
    f.id = id;
    f.extended = true;
    for (std::size_t i = 0; i < payload.size(); ++i) f.data[i] = payload[i];
    f.data[payload.size()] = static_cast<std::uint8_t>(0xC0 | tid);
    f.len = static_cast<std::uint8_t>(payload.size() + 1);
    out.push_back(f);
    return out;
  }
  const std::uint16_t crc = spec_transfer_crc(signature, payload);
  payload.insert(payload.begin(), {static_cast<std::uint8_t>(crc & 0xFF), static_cast<std::uint8_t>(crc >> 8)});
  bool toggle = false;
  for (std::size_t off = 0; off < payload.size(); off += 7) {
    const std::size_t n = std::min<std::size_t>(7, payload.size() - off);
    CanFrame f;
    f.id = id;
    f.extended = true;
    for (std::size_t i = 0; i < n; ++i) f.data[i] = payload[off + i];
    f.data[n] = static_cast<std::uint8_t>((off == 0 ? 0x80 : 0) | (off + n == payload.size() ? 0x40 : 0) |
                                          (toggle ? 0x20 : 0) | tid);
    f.len = static_cast<std::uint8_t>(n + 1);
    out.push_back(f);
    toggle = !toggle;
  }
  return out;
}

// Reassembles one response transfer: checks ids, tail bytes, toggle and
// (multi-frame) the CRC; returns the payload.
std::vector<std::uint8_t> response_payload(const std::vector<CanFrame>& frames, std::uint32_t id, unsigned tid,
                                           std::uint64_t signature) {
  std::vector<std::uint8_t> stream;
  EXPECT_FALSE(frames.empty());
  for (std::size_t i = 0; i < frames.size(); ++i) {
    const CanFrame& f = frames[i];
    EXPECT_TRUE(f.extended);
    EXPECT_EQ(f.id, id) << "frame " << i;
    EXPECT_GE(f.len, 1);
    const std::uint8_t tail = f.data[f.len - 1];
    EXPECT_EQ((tail & 0x80) != 0, i == 0) << "start bit, frame " << i;
    EXPECT_EQ((tail & 0x40) != 0, i + 1 == frames.size()) << "end bit, frame " << i;
    EXPECT_EQ((tail & 0x20) != 0, i % 2 == 1) << "toggle, frame " << i;
    EXPECT_EQ(tail & 0x1F, tid);
    if (i + 1 < frames.size()) {
      EXPECT_EQ(f.len, 8);
    }
    stream.insert(stream.end(), f.data.begin(), f.data.begin() + f.len - 1);
  }
  if (frames.size() == 1) return stream;
  const std::uint16_t crc = static_cast<std::uint16_t>(stream[0] | stream[1] << 8);
  std::vector<std::uint8_t> payload(stream.begin() + 2, stream.end());
  EXPECT_EQ(crc, spec_transfer_crc(signature, payload)) << "transfer CRC seeded with the signature";
  return payload;
}

struct NodeStatusFields {
  std::uint32_t uptime_sec;
  unsigned health, mode;
};
NodeStatusFields node_status_of(const std::uint8_t* p) {
  return {static_cast<std::uint32_t>(p[0] | p[1] << 8 | p[2] << 16 | std::uint32_t{p[3]} << 24),
          static_cast<unsigned>(p[4] >> 6), static_cast<unsigned>((p[4] >> 3) & 7)};
}

// The NodeStatus frames (data type 341, message frames) among `frames`.
std::vector<NodeStatusFields> node_statuses(const std::vector<CanFrame>& frames, unsigned node) {
  std::vector<NodeStatusFields> out;
  for (const CanFrame& f : frames)
    if ((f.id & 0x80) == 0 && ((f.id >> 8) & 0xFFFF) == 341 && (f.id & 0x7F) == node && f.len == 8)
      out.push_back(node_status_of(f.data.data()));
  return out;
}

dronecan::DroneCanOptions identity() {
  dronecan::DroneCanOptions o;
  o.node_id = 42;
  o.name = "org.example.imu";
  o.software_major = 2;
  o.software_minor = 3;
  o.software_vcs_commit = 0xDEADBEEF;
  o.hardware_major = 4;
  o.hardware_minor = 5;
  std::array<std::uint8_t, 16> uid{};
  for (unsigned i = 0; i < 16; ++i) uid[i] = static_cast<std::uint8_t>(0xA0 + i);
  o.unique_id = uid;
  return o;
}

bool matches(const std::vector<CanReceiveFilter>& filters, std::uint32_t id) {
  for (const CanReceiveFilter& f : filters)
    if (f.extended && (id & f.mask) == (f.id & f.mask)) return true;
  return false;
}

TEST(CanDeviceDroneCan, FiltersLetThroughExactlyServiceRequestsToTheNode) {
  dronecan::DroneCanEncoder encoder(identity());
  const auto filters = encoder.command_responder()->receive_filters();
  EXPECT_TRUE(matches(filters, service_id(30, 1, true, 42, 10)));
  EXPECT_TRUE(matches(filters, service_id(0, 11, true, 42, 127)));
  EXPECT_FALSE(matches(filters, service_id(30, 1, true, 43, 10)));   // another node's request
  EXPECT_FALSE(matches(filters, service_id(30, 1, false, 42, 10)));  // a response
  EXPECT_FALSE(matches(filters, 24u << 24 | 341u << 8 | 10));        // a message (NodeStatus of node 10)
}

TEST(CanDeviceDroneCan, GetNodeInfoAnswersTheConfiguredIdentityInAMultiFrameTransfer) {
  const dronecan::DroneCanOptions o = identity();
  dronecan::DroneCanEncoder encoder(o);
  std::vector<CanFrame> out;
  encoder.periodic(0, out);  // power-up NodeStatus
  out.clear();
  encoder.periodic(3 * kNsPerSecond, out);  // uptime 3 s
  CollectingSink sink;
  for (const CanFrame& f : request_frames(service_id(30, 1, true, 42, 10), kGetNodeInfoSig, {}, 5))
    encoder.command_responder()->on_frame(f, sink);

  const std::vector<std::uint8_t> p = response_payload(sink.frames, service_id(30, 1, false, 10, 42), 5, kGetNodeInfoSig);
  const std::size_t expected_size = 7 + 15 + 18 + 1 + o.name.size();
  ASSERT_EQ(p.size(), expected_size);
  EXPECT_EQ(sink.frames.size(), (expected_size + 2 + 6) / 7);
  const NodeStatusFields status = node_status_of(p.data());
  EXPECT_EQ(status.uptime_sec, 3u);
  EXPECT_EQ(status.health, 0u);
  EXPECT_EQ(status.mode, 0u);  // OPERATIONAL
  EXPECT_EQ(p[7], 2);          // software major
  EXPECT_EQ(p[8], 3);          // minor
  EXPECT_EQ(p[9], 1);          // optional_field_flags: VCS commit
  EXPECT_EQ(p[10] | p[11] << 8 | p[12] << 16 | std::uint32_t{p[13]} << 24, 0xDEADBEEFu);
  for (int i = 14; i < 22; ++i) EXPECT_EQ(p[i], 0);  // image_crc
  EXPECT_EQ(p[22], 4);  // hardware major
  EXPECT_EQ(p[23], 5);
  for (unsigned i = 0; i < 16; ++i) EXPECT_EQ(p[24 + i], 0xA0 + i);
  EXPECT_EQ(p[40], 0);  // certificate_of_authenticity length
  EXPECT_EQ(std::string(p.begin() + 41, p.end()), "org.example.imu");  // tail array: no length
  const CommandCounters c = encoder.command_responder()->command_counters();
  EXPECT_EQ(c.received, 1u);
  EXPECT_EQ(c.answered, 1u);
}

TEST(CanDeviceDroneCan, RequestsForOtherNodesOrBrokenTransfersAreNotAnswered) {
  dronecan::DroneCanEncoder encoder(identity());
  CollectingSink sink;
  for (const CanFrame& f : request_frames(service_id(30, 1, true, 43, 10), kGetNodeInfoSig, {}, 1))
    encoder.command_responder()->on_frame(f, sink);
  // A multi-frame GetSet request whose CRC is wrong.
  std::vector<CanFrame> broken =
      request_frames(service_id(30, 11, true, 42, 10), kGetSetSig, {0, 0, 'u', 'a', 'v', 'c', 'a', 'n', '.', 'x'}, 2);
  broken[0].data[0] ^= 0x01;
  for (const CanFrame& f : broken) encoder.command_responder()->on_frame(f, sink);
  EXPECT_TRUE(sink.frames.empty());
  EXPECT_GT(encoder.command_responder()->command_counters().not_command_bytes, 0u);
}

TEST(CanDeviceDroneCan, RestartNodeWithTheMagicNumberRestartsTheNode) {
  dronecan::DroneCanEncoder encoder(identity());
  std::vector<CanFrame> out;
  encoder.periodic(0, out);
  encoder.periodic(5 * kNsPerSecond, out);
  CollectingSink sink;
  // Wrong magic: ok = false, no restart.
  for (const CanFrame& f : request_frames(service_id(20, 5, true, 42, 10), 0, {0x1E, 0x1B, 0x55, 0xCE, 0xAD}, 3))
    encoder.command_responder()->on_frame(f, sink);
  ASSERT_EQ(sink.frames.size(), 1u);
  EXPECT_EQ(sink.frames[0].id, service_id(20, 5, false, 10, 42));
  ASSERT_EQ(sink.frames[0].len, 2);
  EXPECT_EQ(sink.frames[0].data[0], 0x00);
  EXPECT_EQ(sink.frames[0].data[1], 0xC0 | 3);
  out.clear();
  encoder.periodic(5 * kNsPerSecond + 1000, out);
  EXPECT_TRUE(out.empty());

  // MAGIC_NUMBER = 0xACCE551B1E, uint40 little-endian: ok = true (bit 7).
  sink.frames.clear();
  for (const CanFrame& f : request_frames(service_id(20, 5, true, 42, 10), 0, {0x1E, 0x1B, 0x55, 0xCE, 0xAC}, 4))
    encoder.command_responder()->on_frame(f, sink);
  ASSERT_EQ(sink.frames.size(), 1u);
  EXPECT_EQ(sink.frames[0].data[0], 0x80);
  EXPECT_EQ(sink.frames[0].data[1], 0xC0 | 4);

  // At its next sample the node powers up again: INITIALIZATION, uptime 0;
  // a second later OPERATIONAL with uptime 1.
  const TimeNs t = 6 * kNsPerSecond;
  out.clear();
  encoder.periodic(t, out);
  auto s = node_statuses(out, 42);
  ASSERT_EQ(s.size(), 1u);
  EXPECT_EQ(s[0].mode, 1u);
  EXPECT_EQ(s[0].uptime_sec, 0u);
  out.clear();
  encoder.periodic(t + kNsPerSecond, out);
  s = node_statuses(out, 42);
  ASSERT_EQ(s.size(), 1u);
  EXPECT_EQ(s[0].mode, 0u);
  EXPECT_EQ(s[0].uptime_sec, 1u);
}

// ArduPilot's allocation server: a node that sent a WARNING (or
// INITIALIZATION) NodeStatus is asked GetNodeInfo; it must answer, and its
// next NodeStatus must be OPERATIONAL / OK again.
TEST(CanDeviceDroneCan, ArduPilotStyleCheckAfterWarningAndRestartRecovers) {
  dronecan::DroneCanEncoder encoder(identity());
  std::vector<CanFrame> out;
  encoder.periodic(0, out);
  ImuFrameInput sample;
  sample.t_ns = kNsPerSecond / 2;
  sample.period_ns = kNsPerSecond / 100;
  sample.status = kStatusSaturated;
  encoder.encode(sample, out);
  out.clear();
  encoder.periodic(kNsPerSecond, out);
  auto s = node_statuses(out, 42);
  ASSERT_EQ(s.size(), 1u);
  EXPECT_EQ(s[0].health, 1u);  // WARNING

  CollectingSink sink;
  for (const CanFrame& f : request_frames(service_id(30, 1, true, 42, 10), kGetNodeInfoSig, {}, 7))
    encoder.command_responder()->on_frame(f, sink);
  std::vector<std::uint8_t> p = response_payload(sink.frames, service_id(30, 1, false, 10, 42), 7, kGetNodeInfoSig);
  ASSERT_GE(p.size(), 7u);
  EXPECT_EQ(node_status_of(p.data()).health, 1u);  // it reports the state it announced

  sample.t_ns = 3 * kNsPerSecond / 2;
  sample.status = 0;
  encoder.encode(sample, out);
  out.clear();
  encoder.periodic(2 * kNsPerSecond, out);
  s = node_statuses(out, 42);
  ASSERT_EQ(s.size(), 1u);
  EXPECT_EQ(s[0].health, 0u);
  EXPECT_EQ(s[0].mode, 0u);

  // A fault-injected restart: INITIALIZATION, GetNodeInfo answered, then OPERATIONAL.
  out.clear();
  encoder.restart(2 * kNsPerSecond + 1, out);
  s = node_statuses(out, 42);
  ASSERT_EQ(s.size(), 1u);
  EXPECT_EQ(s[0].mode, 1u);
  sink.frames.clear();
  for (const CanFrame& f : request_frames(service_id(30, 1, true, 42, 10), kGetNodeInfoSig, {}, 8))
    encoder.command_responder()->on_frame(f, sink);
  p = response_payload(sink.frames, service_id(30, 1, false, 10, 42), 8, kGetNodeInfoSig);
  ASSERT_GE(p.size(), 7u);
  EXPECT_EQ(node_status_of(p.data()).mode, 1u);
  out.clear();
  encoder.periodic(3 * kNsPerSecond + 1, out);
  s = node_statuses(out, 42);
  ASSERT_EQ(s.size(), 1u);
  EXPECT_EQ(s[0].mode, 0u);
  EXPECT_EQ(s[0].health, 0u);
  EXPECT_EQ(encoder.command_responder()->command_counters().answered, 2u);
}

TEST(CanDeviceDroneCan, PowerUpInitializationForTheFirstSecondWhenConfigured) {
  dronecan::DroneCanOptions o = identity();
  o.initialization_at_power_up = true;
  dronecan::DroneCanEncoder encoder(o);
  std::vector<CanFrame> out;
  encoder.periodic(0, out);
  encoder.periodic(kNsPerSecond, out);
  const auto s = node_statuses(out, 42);
  ASSERT_EQ(s.size(), 2u);
  EXPECT_EQ(s[0].mode, 1u);  // INITIALIZATION
  EXPECT_EQ(s[1].mode, 0u);  // OPERATIONAL
}

TEST(CanDeviceDroneCan, ParamGetSetAnswersReadOnlyValuesAndEmptyForUnknown) {
  dronecan::DroneCanEncoder encoder(identity());
  auto* node = encoder.command_responder();
  CollectingSink sink;
  // By index 0: uint13 index = 0, Value tag 0 (empty), name empty -> 2 bytes.
  for (const CanFrame& f : request_frames(service_id(28, 11, true, 42, 10), kGetSetSig, {0x00, 0x00}, 9))
    node->on_frame(f, sink);
  std::vector<std::uint8_t> p = response_payload(sink.frames, service_id(28, 11, false, 10, 42), 9, kGetSetSig);
  // void5 + tag 1 (integer_value), int64 42; default the same; max, min empty; name.
  std::vector<std::uint8_t> expected{0x01, 42, 0, 0, 0, 0, 0, 0, 0, 0x01, 42, 0, 0, 0, 0, 0, 0, 0, 0x00, 0x00};
  const std::string name = "uavcan.node_id";
  expected.insert(expected.end(), name.begin(), name.end());
  EXPECT_EQ(p, expected);

  // By name (a multi-frame request: 2 + 18 bytes), with a set attempt
  // (boolean_value 0) that is refused: the current value comes back.
  sink.frames.clear();
  std::vector<std::uint8_t> request{0x00, 0x03, 0x00};
  const std::string bool_name = "imu.send_integrals";
  request.insert(request.end(), bool_name.begin(), bool_name.end());
  for (const CanFrame& f : request_frames(service_id(28, 11, true, 42, 10), kGetSetSig, request, 10))
    node->on_frame(f, sink);
  p = response_payload(sink.frames, service_id(28, 11, false, 10, 42), 10, kGetSetSig);
  expected = {0x03, 0x01, 0x03, 0x01, 0x00, 0x00};
  expected.insert(expected.end(), bool_name.begin(), bool_name.end());
  EXPECT_EQ(p, expected);

  // Unknown index 200 (uint13: low byte 200, then 5 high bits 0, tag 0): the empty answer.
  sink.frames.clear();
  for (const CanFrame& f : request_frames(service_id(28, 11, true, 42, 10), kGetSetSig, {200, 0x00}, 11))
    node->on_frame(f, sink);
  ASSERT_EQ(sink.frames.size(), 1u);
  ASSERT_EQ(sink.frames[0].len, 5);
  for (int i = 0; i < 4; ++i) EXPECT_EQ(sink.frames[0].data[i], 0);
  EXPECT_EQ(sink.frames[0].data[4], 0xC0 | 11);
}

// ---- J1939, from J1939-21 / -81 / -71 ----

std::uint32_t j1939_id(unsigned prio, unsigned pf, unsigned ps, unsigned sa) { return prio << 26 | pf << 16 | ps << 8 | sa; }

CanFrame request_for(std::uint32_t pgn, unsigned destination, unsigned source) {
  CanFrame f;
  f.id = j1939_id(6, 0xEA, destination, source);
  f.extended = true;
  f.len = 3;
  f.data[0] = pgn & 0xFF;
  f.data[1] = (pgn >> 8) & 0xFF;
  f.data[2] = (pgn >> 16) & 0xFF;
  return f;
}

CanFrame claim_from(unsigned source, std::uint64_t name) {
  CanFrame f;
  f.id = j1939_id(6, 0xEE, 0xFF, source);
  f.extended = true;
  f.len = 8;
  for (int i = 0; i < 8; ++i) f.data[i] = static_cast<std::uint8_t>(name >> (8 * i));
  return f;
}

std::uint64_t name_of(const CanFrame& f) {
  std::uint64_t n = 0;
  for (int i = 0; i < 8; ++i) n |= std::uint64_t{f.data[i]} << (8 * i);
  return n;
}

j1939::J1939Options j1939_identity() {
  j1939::J1939Options o;
  o.source_address = 0x80;
  o.name = 0x00A0'0000'0012'3456ULL;  // not arbitrary-address capable (bit 63 clear)
  o.make = "ACME";
  o.model = "IMU-9";
  o.serial_number = "SN0042";
  o.unit_number = "7";
  o.software_ids = {"ab"};
  return o;
}

TEST(CanDeviceJ1939, FiltersLetThroughRequestsToItOrGlobalAndClaims) {
  j1939::J1939Encoder encoder(j1939_identity());
  const auto filters = encoder.command_responder()->receive_filters();
  EXPECT_TRUE(matches(filters, request_for(0xEE00, 0x80, 0x21).id));
  EXPECT_TRUE(matches(filters, request_for(0xEE00, 0xFF, 0x21).id));
  EXPECT_FALSE(matches(filters, request_for(0xEE00, 0x81, 0x21).id));
  EXPECT_TRUE(matches(filters, claim_from(0x21, 5).id));
  EXPECT_FALSE(matches(filters, j1939_id(3, 0xF0, 0x2A, 0x21)));  // another node's ARI
}

TEST(CanDeviceJ1939, RequestForAddressClaimedGetsTheClaim) {
  j1939::J1939Encoder encoder(j1939_identity());
  CollectingSink sink;
  encoder.command_responder()->on_frame(request_for(60928, 0xFF, 0x21), sink);
  ASSERT_EQ(sink.frames.size(), 1u);
  EXPECT_EQ(sink.frames[0].id, j1939_id(6, 0xEE, 0xFF, 0x80));
  EXPECT_EQ(sink.frames[0].len, 8);
  EXPECT_EQ(name_of(sink.frames[0]), 0x00A0'0000'0012'3456ULL);
  // To another address: not for it.
  sink.frames.clear();
  encoder.command_responder()->on_frame(request_for(60928, 0x81, 0x21), sink);
  EXPECT_TRUE(sink.frames.empty());
}

TEST(CanDeviceJ1939, ComponentIdentificationGoesOutAsBam) {
  j1939::J1939Encoder encoder(j1939_identity());
  CollectingSink sink;
  encoder.command_responder()->on_frame(request_for(65259, 0x80, 0x21), sink);
  const std::string text = "ACME*IMU-9*SN0042*7*";  // 20 bytes: 3 packets
  ASSERT_EQ(sink.frames.size(), 4u);
  const CanFrame& cm = sink.frames[0];
  EXPECT_EQ(cm.id, j1939_id(7, 0xEC, 0xFF, 0x80));
  ASSERT_EQ(cm.len, 8);
  const std::vector<std::uint8_t> cm_expected{32, 20, 0, 3, 0xFF, 0xEB, 0xFE, 0x00};
  EXPECT_EQ(std::vector<std::uint8_t>(cm.data.begin(), cm.data.begin() + 8), cm_expected);
  std::string reassembled;
  for (unsigned i = 1; i < 4; ++i) {
    const CanFrame& dt = sink.frames[i];
    EXPECT_EQ(dt.id, j1939_id(7, 0xEB, 0xFF, 0x80));
    ASSERT_EQ(dt.len, 8);
    EXPECT_EQ(dt.data[0], i);
    for (int b = 1; b < 8; ++b) reassembled.push_back(static_cast<char>(dt.data[b]));
  }
  EXPECT_EQ(reassembled.substr(0, 20), text);
  EXPECT_EQ(reassembled[20], '\xFF');  // padding
}

TEST(CanDeviceJ1939, SoftwareIdentificationFitsOneFrame) {
  j1939::J1939Encoder encoder(j1939_identity());
  CollectingSink sink;
  encoder.command_responder()->on_frame(request_for(65242, 0xFF, 0x21), sink);
  ASSERT_EQ(sink.frames.size(), 1u);
  EXPECT_EQ(sink.frames[0].id, j1939_id(6, 0xFE, 0xDA, 0x80));
  ASSERT_EQ(sink.frames[0].len, 4);
  EXPECT_EQ(sink.frames[0].data[0], 1);
  EXPECT_EQ(sink.frames[0].data[1], 'a');
  EXPECT_EQ(sink.frames[0].data[2], 'b');
  EXPECT_EQ(sink.frames[0].data[3], '*');
}

TEST(CanDeviceJ1939, UnsupportedPgnIsNackedOnlyWhenAskedDirectly) {
  j1939::J1939Encoder encoder(j1939_identity());
  CollectingSink sink;
  encoder.command_responder()->on_frame(request_for(0xFEE5, 0xFF, 0x21), sink);  // global: silence
  EXPECT_TRUE(sink.frames.empty());
  encoder.command_responder()->on_frame(request_for(0xFEE5, 0x80, 0x21), sink);
  ASSERT_EQ(sink.frames.size(), 1u);
  EXPECT_EQ(sink.frames[0].id, j1939_id(6, 0xE8, 0xFF, 0x80));
  const std::vector<std::uint8_t> nack{1, 0xFF, 0xFF, 0xFF, 0x21, 0xE5, 0xFE, 0x00};
  EXPECT_EQ(std::vector<std::uint8_t>(sink.frames[0].data.begin(), sink.frames[0].data.begin() + 8), nack);
  EXPECT_EQ(encoder.command_responder()->command_counters().nacked, 1u);
}

std::size_t frames_from(const std::vector<CanFrame>& frames, unsigned sa) {
  std::size_t n = 0;
  for (const CanFrame& f : frames) n += (f.id & 0xFF) == sa ? 1 : 0;
  return n;
}

TEST(CanDeviceJ1939, AddressConflictLowerNameWinsHigherNameGetsOurClaimAgain) {
  j1939::J1939Encoder encoder(j1939_identity());
  CollectingSink sink;
  ImuFrameInput sample;
  std::vector<CanFrame> out;

  // A contender with a higher (lower-priority) NAME: we claim again.
  encoder.command_responder()->on_frame(claim_from(0x80, 0x00A0'0000'0099'9999ULL), sink);
  ASSERT_EQ(sink.frames.size(), 1u);
  EXPECT_EQ(sink.frames[0].id, j1939_id(6, 0xEE, 0xFF, 0x80));
  EXPECT_EQ(name_of(sink.frames[0]), 0x00A0'0000'0012'3456ULL);
  encoder.encode(sample, out);
  EXPECT_EQ(frames_from(out, 0x80), 2u);  // ARI, ACCS still from 0x80

  // A contender with a lower NAME wins; we are not arbitrary-address
  // capable: Cannot Claim (source 254) and silence.
  sink.frames.clear();
  encoder.command_responder()->on_frame(claim_from(0x80, 0x0000'0000'0000'0001ULL), sink);
  ASSERT_EQ(sink.frames.size(), 1u);
  EXPECT_EQ(sink.frames[0].id, j1939_id(6, 0xEE, 0xFF, 0xFE));
  EXPECT_EQ(name_of(sink.frames[0]), 0x00A0'0000'0012'3456ULL);
  out.clear();
  encoder.encode(sample, out);
  EXPECT_TRUE(out.empty());
  // Asked for Address Claimed now: Cannot Claim again; asked for anything else: nothing.
  sink.frames.clear();
  encoder.command_responder()->on_frame(request_for(60928, 0xFF, 0x21), sink);
  ASSERT_EQ(sink.frames.size(), 1u);
  EXPECT_EQ(sink.frames[0].id, j1939_id(6, 0xEE, 0xFF, 0xFE));
  sink.frames.clear();
  encoder.command_responder()->on_frame(request_for(65259, 0xFF, 0x21), sink);
  EXPECT_TRUE(sink.frames.empty());
}

TEST(CanDeviceJ1939, ArbitraryAddressCapableNodeMovesToAFreeAddress) {
  j1939::J1939Options o = j1939_identity();
  o.name |= 1ULL << 63;  // arbitrary address capable
  j1939::J1939Encoder encoder(o);
  CollectingSink sink;
  encoder.command_responder()->on_frame(claim_from(129, 0x10), sink);  // 129 is taken by a lower NAME
  EXPECT_TRUE(sink.frames.empty());
  encoder.command_responder()->on_frame(claim_from(0x80, 0x01), sink);
  ASSERT_EQ(sink.frames.size(), 1u);
  EXPECT_EQ(sink.frames[0].id, j1939_id(6, 0xEE, 0xFF, 130));  // 128 lost, 129 taken
  EXPECT_EQ(name_of(sink.frames[0]), o.name);
  std::vector<CanFrame> out;
  encoder.encode(ImuFrameInput{}, out);
  EXPECT_EQ(frames_from(out, 130), out.size());
  EXPECT_FALSE(out.empty());
}

}  // namespace
}  // namespace imuemu::drivers
}  // namespace unity_drivers_test_can_device
