// Link and protocol faults (issue 18) at the encoder/transport edge:
// drivers/link_fault.hpp applied to every protocol.
//
// Independent truth used here:
//  - the unfaulted stream of a second, untouched encoder (LinkActions{} must
//    be byte-identical to encode() + periodic(); faulted ticks are compared
//    byte by byte with it);
//  - the wire fields read at the offsets the specifications give (native:
//    docs/native-protocol.md; MAVLink: packet format, len at 1, seq at 4,
//    HEARTBEAT system_status at payload 7; MIP: payload length at 3; DroneCAN:
//    tail byte, transfer CRC in the first frame, NodeStatus bit layout;
//    J1939: 29-bit id, Address Claimed NAME), checksums recomputed here
//    bit by bit from their Rocksoft parameters / the MIP manual;
//  - the bit positions of bit flips from splitmix64 written here from its
//    published definition;
//  - the project's decoders, fed tick by tick: their counters must move by
//    exactly the effect the spec predicts on exactly the faulted ticks (and
//    the tick after, where a decoder has to see the next frame to judge),
//    and by nothing on every other tick.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <new>
#include <set>
#include <span>
#include <vector>

#include <unistd.h>

#include <nlohmann/json.hpp>

#include "drivers/link_fault.hpp"
#include "drivers/protocols/dronecan.hpp"
#include "drivers/protocols/j1939.hpp"
#include "drivers/protocols/mavlink2.hpp"
#include "drivers/protocols/mip.hpp"
#include "drivers/protocols/native.hpp"
#include "drivers/protocols/nmea.hpp"
#include "drivers/protocols/ubx.hpp"
#include "drivers/protocols/stream_protocols.hpp"

// The replaced operator new / delete below pair malloc with free; GCC
// cannot see that through the replacement and warns where it inlines them.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
#endif

// Heap allocations of this thread while counting (the emission thread must
// not allocate: encode_with_link_faults is checked with it below).
namespace {
thread_local bool g_count_allocations = false;
thread_local std::size_t g_allocations = 0;
}  // namespace

void* operator new(std::size_t bytes) {
  if (g_count_allocations) ++g_allocations;
  if (void* p = std::malloc(bytes == 0 ? 1 : bytes)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
#include "tests/support/replaced_new_forms.hpp"  // the nothrow and array forms through these two

using namespace imuemu;
using namespace imuemu::drivers;
using Bytes = std::vector<std::uint8_t>;
using Frames = std::vector<CanFrame>;

namespace {

constexpr TimeNs kPeriodNs = 10'000'000;       // 100 Hz: a heartbeat / NodeStatus every 100 ticks
constexpr TimeNs kStartNs = 2'000'000'000;     // t of tick 0
constexpr int kTicks = 400;

ImuFrameInput sample_at(int k) {
  ImuFrameInput s;
  s.sample_counter = static_cast<std::uint64_t>(k);
  s.t_ns = kStartNs + k * kPeriodNs;
  s.period_ns = kPeriodNs;
  const double x = 0.01 * k;
  s.gyro_rad_s = Vec3(0.1 * std::sin(x), -0.05 + 0.001 * k, 0.3 * std::cos(0.7 * x));
  s.accel_m_s2 = Vec3(0.2 * std::cos(x), 0.1 * std::sin(1.3 * x), -9.80665 + 0.01 * std::sin(x));
  s.delta_theta_rad = s.gyro_rad_s * 0.01;
  s.delta_velocity_m_s = s.accel_m_s2 * 0.01;
  return s;
}

// ---------------------------------------------------------------- references

// splitmix64 (Steele, Lea, Flood 2014; Vigna's reference constants): the
// output of state seed + (j+1) * gamma.
std::uint64_t ref_splitmix64(std::uint64_t seed, std::uint64_t j) {
  std::uint64_t z = seed + (j + 1) * 0x9E3779B97F4A7C15ULL;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
  return z ^ (z >> 31);
}

// The distinct bit positions link_fault.hpp promises for `flips` flips.
std::vector<std::uint64_t> ref_flip_positions(std::uint64_t seed, std::uint32_t flips, std::uint64_t n_bits) {
  std::vector<std::uint64_t> positions;
  for (std::uint64_t j = 0; positions.size() < flips; ++j) {
    const std::uint64_t p = ref_splitmix64(seed, j) % n_bits;
    if (std::find(positions.begin(), positions.end(), p) == positions.end()) positions.push_back(p);
  }
  return positions;
}

std::uint32_t ref_crc32c(const std::uint8_t* data, std::size_t n) {
  std::uint32_t crc = 0xFFFFFFFFu;
  for (std::size_t i = 0; i < n; ++i) {
    crc ^= data[i];
    for (int b = 0; b < 8; ++b) crc = (crc & 1u) != 0 ? (crc >> 1) ^ 0x82F63B78u : crc >> 1;
  }
  return crc ^ 0xFFFFFFFFu;
}

std::uint16_t ref_crc16_mcrf4xx(const std::uint8_t* data, std::size_t n, std::uint16_t crc = 0xFFFF) {
  for (std::size_t i = 0; i < n; ++i) {
    crc = static_cast<std::uint16_t>(crc ^ data[i]);
    for (int b = 0; b < 8; ++b)
      crc = (crc & 1u) != 0 ? static_cast<std::uint16_t>((crc >> 1) ^ 0x8408u) : static_cast<std::uint16_t>(crc >> 1);
  }
  return crc;
}

// 3DM-GX5 DCP manual 6.4.
std::uint16_t ref_fletcher(const std::uint8_t* data, std::size_t n) {
  std::uint8_t a = 0, b = 0;
  for (std::size_t i = 0; i < n; ++i) {
    a = static_cast<std::uint8_t>(a + data[i]);
    b = static_cast<std::uint8_t>(b + a);
  }
  return static_cast<std::uint16_t>(a << 8 | b);
}

// CRC-16-CCITT-FALSE, MSB first (DroneCAN transfer CRC).
std::uint16_t ref_crc16_ccitt(std::uint16_t crc, const std::uint8_t* data, std::size_t n) {
  for (std::size_t i = 0; i < n; ++i) {
    for (int bit = 7; bit >= 0; --bit) {
      const bool in = ((data[i] >> bit) & 1) != 0;
      const bool top = (crc & 0x8000) != 0;
      crc = static_cast<std::uint16_t>(crc << 1);
      if (in != top) crc ^= 0x1021;
    }
  }
  return crc;
}

// Sizes of the frames of a stream tick by the protocols' own length fields.
std::size_t mavlink_frame_bytes(const Bytes& b, std::size_t at) { return 10u + b[at + 1] + 2u; }
std::size_t mip_frame_bytes(const Bytes& b, std::size_t at) { return 4u + b[at + 3] + 2u; }

// No start-of-frame pattern inside the frame (after its first byte): a
// receiver that rejects it then skips exactly the frame.
bool sync_free(const Bytes& frame, std::span<const std::uint8_t> sync) {
  for (std::size_t i = 1; i + sync.size() <= frame.size(); ++i)
    if (std::equal(sync.begin(), sync.end(), frame.begin() + static_cast<std::ptrdiff_t>(i))) return false;
  return true;
}

Bytes slice(const Bytes& b, std::size_t at, std::size_t n) {
  return Bytes(b.begin() + static_cast<std::ptrdiff_t>(at), b.begin() + static_cast<std::ptrdiff_t>(at + n));
}

// ---------------------------------------------------------------- running

using ActionsOf = std::function<LinkActions(int)>;

template <class Encoder>
std::vector<Bytes> run_stream(Encoder encoder, const ActionsOf& actions) {
  std::vector<Bytes> ticks;
  Bytes out;
  for (int k = 0; k < kTicks; ++k) {
    out.clear();
    encode_with_link_faults(actions(k), encoder, sample_at(k), out);
    ticks.push_back(out);
  }
  return ticks;
}

template <class Encoder>
std::vector<Bytes> run_stream_plain(Encoder encoder) {
  std::vector<Bytes> ticks;
  for (int k = 0; k < kTicks; ++k) {
    Bytes out;
    encoder.encode(sample_at(k), out);
    encoder.periodic(sample_at(k).t_ns, out);
    ticks.push_back(out);
  }
  return ticks;
}

template <class Encoder>
std::vector<Frames> run_can(Encoder encoder, const ActionsOf& actions) {
  std::vector<Frames> ticks;
  Frames out;
  for (int k = 0; k < kTicks; ++k) {
    out.clear();
    encode_with_link_faults(actions(k), encoder, sample_at(k), out);
    ticks.push_back(out);
  }
  return ticks;
}

template <class Encoder>
std::vector<Frames> run_can_plain(Encoder encoder) {
  std::vector<Frames> ticks;
  for (int k = 0; k < kTicks; ++k) {
    Frames out;
    encoder.encode(sample_at(k), out);
    encoder.periodic(sample_at(k).t_ns, out);
    ticks.push_back(out);
  }
  return ticks;
}

bool same_frames(const Frames& a, const Frames& b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (a[i].id != b[i].id || a[i].extended != b[i].extended || a[i].fd != b[i].fd || a[i].len != b[i].len ||
        !std::equal(a[i].data.begin(), a[i].data.begin() + a[i].len, b[i].data.begin()))
      return false;
  }
  return true;
}

// A decoder's counters after each tick, and which tick delivered each sample.
struct Trace {
  std::vector<DecoderCounters> after;
  std::vector<std::pair<int, DecodedSample>> samples;
};

Trace decode_stream(StreamDecoder& decoder, const std::vector<Bytes>& ticks) {
  Trace t;
  for (int k = 0; k < static_cast<int>(ticks.size()); ++k) {
    decoder.feed(ticks[k], [&](const DecodedSample& s) { t.samples.emplace_back(k, s); });
    t.after.push_back(decoder.counters());
  }
  return t;
}

Trace decode_can(CanDecoder& decoder, const std::vector<Frames>& ticks) {
  Trace t;
  for (int k = 0; k < static_cast<int>(ticks.size()); ++k) {
    for (const CanFrame& f : ticks[k]) decoder.feed(f, [&](const DecodedSample& s) { t.samples.emplace_back(k, s); });
    t.after.push_back(decoder.counters());
  }
  return t;
}

// What the counters should do on one tick.
struct Delta {
  std::uint64_t samples = 1;
  std::uint64_t checksum_errors = 0;
  std::uint64_t other_errors = 0;
  std::uint64_t sequence_gaps = 0;
  std::uint64_t resync_bytes = 0;
};

// Every tick's counter movement against `expected` (default: one sample,
// nothing else).
void expect_deltas(const Trace& t, const std::map<int, Delta>& expected) {
  DecoderCounters before;
  for (int k = 0; k < static_cast<int>(t.after.size()); ++k) {
    const DecoderCounters& a = t.after[k];
    const auto it = expected.find(k);
    const Delta d = it == expected.end() ? Delta{} : it->second;
    EXPECT_EQ(a.samples - before.samples, d.samples) << "tick " << k;
    EXPECT_EQ(a.checksum_errors - before.checksum_errors, d.checksum_errors) << "tick " << k;
    EXPECT_EQ(a.other_errors - before.other_errors, d.other_errors) << "tick " << k;
    EXPECT_EQ(a.sequence_gaps - before.sequence_gaps, d.sequence_gaps) << "tick " << k;
    EXPECT_EQ(a.resync_bytes - before.resync_bytes, d.resync_bytes) << "tick " << k;
    before = a;
  }
}

LinkActions none_at(int) { return {}; }

StreamEncoderOptions mavlink_options() {
  StreamEncoderOptions o;
  o.mavlink_temperature_degC = 25.0;
  return o;
}

// A tick from `from` on whose reference frame (the tick's first frame)
// satisfies `ok`; the test fails when none does.
int pick_tick(int from, const std::function<bool(int)>& ok) {
  for (int k = from; k < kTicks - 2; ++k)
    if (ok(k)) return k;
  ADD_FAILURE() << "no tick from " << from << " fits the scenario";
  return from;
}

bool heartbeat_tick(int k) { return k % 100 == 0; }  // t = 2 s + k * 10 ms: whole seconds

// ============================================================== no action

TEST(LinkFaults, NoActionIsByteIdenticalToEncodePlusPeriodicForEveryProtocol) {
  EXPECT_EQ(run_stream(native::Encoder(true), none_at), run_stream_plain(native::Encoder(true)));
  EXPECT_EQ(run_stream(native::Encoder(false), none_at), run_stream_plain(native::Encoder(false)));
  StreamEncoderOptions both = mavlink_options();
  both.mavlink_highres_imu = true;
  EXPECT_EQ(run_stream(mavlink2::Encoder(both), none_at), run_stream_plain(mavlink2::Encoder(both)));
  EXPECT_EQ(run_stream(mip::Encoder(StreamEncoderOptions{}), none_at),
            run_stream_plain(mip::Encoder(StreamEncoderOptions{})));
  const auto dc = run_can(dronecan::DroneCanEncoder(), none_at);
  const auto dc_plain = run_can_plain(dronecan::DroneCanEncoder());
  j1939::J1939Options jo;
  jo.send_slope = true;
  const auto jj = run_can(j1939::J1939Encoder(jo), none_at);
  const auto jj_plain = run_can_plain(j1939::J1939Encoder(jo));
  for (int k = 0; k < kTicks; ++k) {
    EXPECT_TRUE(same_frames(dc[k], dc_plain[k])) << k;
    EXPECT_TRUE(same_frames(jj[k], jj_plain[k])) << k;
  }
  EXPECT_FALSE(LinkActions{}.any());
}

TEST(LinkFaults, OutputNeverReallocatesOnceReserved) {
  mavlink2::Encoder enc(mavlink_options());
  Bytes out;
  out.reserve(link_fault_reserve(enc, 8));
  const std::uint8_t* data = out.data();
  const std::size_t capacity = out.capacity();
  for (int k = 0; k < kTicks; ++k) {
    LinkActions a;
    a.copies = static_cast<std::uint8_t>(k % 9);
    a.restart = k % 50 == 0;
    a.bit_flips = 3;
    a.truncate_bytes = static_cast<std::uint32_t>(k % 5);
    out.clear();
    encode_with_link_faults(a, enc, sample_at(k), out);
  }
  EXPECT_EQ(out.data(), data);
  EXPECT_EQ(out.capacity(), capacity);

  dronecan::DroneCanEncoder can;
  Frames frames;
  frames.reserve(link_fault_reserve_can_frames(8));
  const CanFrame* fdata = frames.data();
  for (int k = 0; k < kTicks; ++k) {
    LinkActions a;
    a.copies = static_cast<std::uint8_t>(k % 9);
    a.restart = k % 50 == 0;
    frames.clear();
    encode_with_link_faults(a, can, sample_at(k), frames);
  }
  EXPECT_EQ(frames.data(), fdata);
}

// Every action, varied tick by tick, after a warm-up that grew the output:
// no heap allocation at all, for every protocol.
LinkActions varied_actions(int k) {
  LinkActions a;
  a.copies = static_cast<std::uint8_t>(k % 7);
  a.restart = k % 37 == 0;
  a.drop = k % 11 == 0;
  a.silence = k % 13 == 0;
  a.corrupt_checksum = k % 3 == 0;
  a.bad_length = k % 5 == 0;
  a.truncate_bytes = static_cast<std::uint32_t>(k % 4);
  a.bit_flips = static_cast<std::uint32_t>(k % 6);
  a.bit_error_seed = static_cast<std::uint64_t>(k);
  a.sequence_step = k % 17 == 0 ? 3 : 0;
  a.sequence_reset = k % 19 == 0;
  a.can_wrong_id = k % 23 == 0;
  a.can_id = 0x321;
  a.can_missing_frame = k % 29 == 0;
  return a;
}

template <class Encoder, class Out>
std::size_t allocations_after_warm_up(Encoder encoder, Out& out) {
  for (int k = 0; k < kTicks; ++k) {
    out.clear();
    encode_with_link_faults(varied_actions(k), encoder, sample_at(k), out);
  }
  g_allocations = 0;
  g_count_allocations = true;
  for (int k = kTicks; k < 2 * kTicks; ++k) {
    out.clear();
    encode_with_link_faults(varied_actions(k), encoder, sample_at(k), out);
  }
  g_count_allocations = false;
  return g_allocations;
}

TEST(LinkFaults, NoHeapAllocationOnTheEmissionPathAfterWarmUp) {
  StreamEncoderOptions both = mavlink_options();
  both.mavlink_highres_imu = true;
  Bytes bytes;
  bytes.reserve(link_fault_reserve(mavlink2::Encoder(both), 6));
  EXPECT_EQ(allocations_after_warm_up(native::Encoder(true), bytes), 0u);
  EXPECT_EQ(allocations_after_warm_up(mavlink2::Encoder(both), bytes), 0u);
  EXPECT_EQ(allocations_after_warm_up(mip::Encoder(StreamEncoderOptions{}), bytes), 0u);
  Frames frames;
  frames.reserve(link_fault_reserve_can_frames(6));
  EXPECT_EQ(allocations_after_warm_up(dronecan::DroneCanEncoder(), frames), 0u);
  j1939::J1939Options jo;
  jo.send_slope = true;
  EXPECT_EQ(allocations_after_warm_up(j1939::J1939Encoder(jo), frames), 0u);
  // The counter does count: a vector that grows is seen.
  g_allocations = 0;
  g_count_allocations = true;
  { std::vector<int> grows(100); (void)grows; }
  g_count_allocations = false;
  EXPECT_EQ(g_allocations, 1u);
}

// The GNSS receivers (issue 28) on the same emission path: epochs with a
// fix (the sentences formatted with snprintf into a stack buffer), values
// beyond every field's range included, every link action; nothing
// allocated once the output has grown.
TEST(LinkFaults, GnssReceiversAllocateNothingOnTheEmissionPath) {
  const auto gnss_sample = [](int k) {
    ImuFrameInput s = sample_at(k);
    s.has_navigation = true;
    s.latitude_rad = k % 9 == 0 ? -1.5 : 0.7;
    s.longitude_rad = k % 7 == 0 ? 3.1 : -2.0;
    s.height_m = k % 5 == 0 ? 1e300 : 123.456;
    s.velocity_ned_m_s = k % 3 == 0 ? Vec3(1e300, -1e300, 0.0) : Vec3(3.0, -4.0, 0.5);
    return s;
  };
  const auto count = [&](StreamEncoder& encoder) {
    Bytes out;
    out.reserve(link_fault_reserve(encoder, 6));
    for (int k = 0; k < kTicks; ++k) {
      out.clear();
      encode_with_link_faults(varied_actions(k), encoder, gnss_sample(k), out);
    }
    g_allocations = 0;
    g_count_allocations = true;
    for (int k = kTicks; k < 2 * kTicks; ++k) {
      out.clear();
      encode_with_link_faults(varied_actions(k), encoder, gnss_sample(k), out);
    }
    g_count_allocations = false;
    return g_allocations;
  };
  nmea::Encoder nmea(StreamEncoderOptions{});
  ubx::Encoder ubx(StreamEncoderOptions{});
  EXPECT_EQ(count(nmea), 0u);
  EXPECT_EQ(count(ubx), 0u);
  // With the receiver's errors on (drivers/gnss_fix.hpp GnssFixSource: the
  // error model steps per fix, the offset goes through ECEF).
  StreamEncoderOptions with_errors;
  with_errors.nominal_sample_rate_hz = 10.0;
  with_errors.gnss.errors.horizontal_white_m = 1.0;
  with_errors.gnss.errors.horizontal_gm_sigma_m = 2.0;
  with_errors.gnss.errors.vertical_white_m = 3.0;
  with_errors.gnss.errors.horizontal_velocity_m_s = 0.1;
  nmea::Encoder nmea_errors(with_errors);
  ubx::Encoder ubx_errors(with_errors);
  EXPECT_EQ(count(nmea_errors), 0u);
  EXPECT_EQ(count(ubx_errors), 0u);
}

// ============================================================== native

class NativeFaults : public ::testing::Test {
 public:
  static constexpr std::array<std::uint8_t, 2> kSync{native::kSync0, native::kSync1};

 protected:
  std::vector<Bytes> ref = run_stream_plain(native::Encoder(true));
  std::vector<Bytes> faulted(const ActionsOf& a) { return run_stream(native::Encoder(true), a); }
  Trace decode(const std::vector<Bytes>& ticks) {
    native::Decoder d;
    return decode_stream(d, ticks);
  }
  int clean_tick(int from) {
    return pick_tick(from, [&](int k) { return sync_free(ref[k], kSync) && sync_free(ref[k + 1], kSync); });
  }
};

TEST_F(NativeFaults, CorruptChecksumIsOneChecksumErrorTheFrameSkippedAndOneGap) {
  const int k = clean_tick(10);
  const auto out = faulted([&](int i) { LinkActions a; a.corrupt_checksum = i == k; return a; });
  ASSERT_EQ(out[k].size(), native::kFrameBytesDeltas);
  const std::uint32_t sent = out[k][122] | out[k][123] << 8 | out[k][124] << 16 | std::uint32_t{out[k][125]} << 24;
  EXPECT_EQ(sent, ~ref_crc32c(out[k].data(), 122));  // every bit of the right CRC inverted
  EXPECT_EQ(slice(out[k], 0, 122), slice(ref[k], 0, 122));
  for (int i = 0; i < kTicks; ++i) {
    if (i != k) {
      EXPECT_EQ(out[i], ref[i]) << i;
    }
  }
  expect_deltas(decode(out), {{k, {0, 1, 0, 0, native::kFrameBytesDeltas}}, {k + 1, {1, 0, 0, 1, 0}}});
}

TEST_F(NativeFaults, BadLengthIsMalformedLengthPlusOne) {
  const int k = clean_tick(20);
  const auto out = faulted([&](int i) { LinkActions a; a.bad_length = i == k; return a; });
  EXPECT_EQ(out[k][4] | out[k][5] << 8, 117);  // 116 + 1
  Bytes restored = out[k];
  restored[4] = 116;
  EXPECT_EQ(restored, ref[k]);
  expect_deltas(decode(out), {{k, {0, 0, 1, 0, native::kFrameBytesDeltas}}, {k + 1, {1, 0, 0, 1, 0}}});
}

TEST_F(NativeFaults, TruncatedFrameIsCutAndFailsItsCrcOnTheNextFrame) {
  const int k = clean_tick(30);
  const std::uint32_t cut = 10;
  const auto out = faulted([&](int i) { LinkActions a; a.truncate_bytes = i == k ? cut : 0; return a; });
  EXPECT_EQ(out[k], slice(ref[k], 0, ref[k].size() - cut));
  // Judged when the next frame completes the 126 bytes: CRC fails, the
  // 116 bytes of the cut frame are skipped, the next frame is fine.
  expect_deltas(decode(out), {{k, {0, 0, 0, 0, 0}}, {k + 1, {1, 1, 0, 1, native::kFrameBytesDeltas - cut}}});
  // Never to nothing.
  const auto all = faulted([&](int i) { LinkActions a; a.truncate_bytes = i == k ? 100000 : 0; return a; });
  EXPECT_EQ(all[k], slice(ref[k], 0, 1));
}

TEST_F(NativeFaults, BitFlipsAtTheSeededPositionsReproducibleAndTheFrameLost) {
  const std::uint32_t flips = 5;
  const int k = clean_tick(40);
  const std::uint64_t n_bits = native::kFrameBytesDeltas * 8;
  const auto flipped = [&](std::uint64_t seed) {
    Bytes b = ref[k];
    for (const std::uint64_t p : ref_flip_positions(seed, flips, n_bits))
      b[p / 8] = static_cast<std::uint8_t>(b[p / 8] ^ (1u << (p % 8)));
    return b;
  };
  // A seed whose positions all fall in the payload (bytes 6..121) and make
  // no sync pattern: the receiver then sees exactly a CRC failure.
  std::uint64_t seed = 1;
  for (; seed < 1000; ++seed) {
    const auto p = ref_flip_positions(seed, flips, n_bits);
    if (std::all_of(p.begin(), p.end(), [](std::uint64_t b) { return b / 8 >= 6 && b / 8 < 122; }) &&
        sync_free(flipped(seed), kSync))
      break;
  }
  ASSERT_LT(seed, 1000u);
  const auto actions = [&](int i) {
    LinkActions a;
    a.bit_flips = i == k ? flips : 0;
    a.bit_error_seed = seed;
    return a;
  };
  const auto out = faulted(actions);
  EXPECT_EQ(out[k], flipped(seed));
  EXPECT_EQ(faulted(actions), out);  // reproducible
  for (int i = 0; i < kTicks; ++i) {
    if (i != k) {
      EXPECT_EQ(out[i], ref[i]) << i;
    }
  }
  for (std::uint64_t b = 0; b < n_bits; ++b)
    EXPECT_EQ(link_fault_bit_position(seed, b, n_bits), ref_splitmix64(seed, b) % n_bits);
  // Another seed, other bits.
  const auto other = faulted([&](int i) {
    LinkActions a = actions(i);
    a.bit_error_seed = seed + 1;
    return a;
  });
  EXPECT_NE(other[k], out[k]);
  expect_deltas(decode(out), {{k, {0, 1, 0, 0, native::kFrameBytesDeltas}}, {k + 1, {1, 0, 0, 1, 0}}});
}

TEST_F(NativeFaults, BitFlipsAskedForBeyondTheLimitAreCappedAndDistinct) {
  const int k = 5;
  const auto out = faulted([&](int i) {
    LinkActions a;
    a.bit_flips = i == k ? 1000 : 0;
    a.bit_error_seed = 42;
    return a;
  });
  std::uint64_t differing = 0;
  for (std::size_t i = 0; i < ref[k].size(); ++i)
    differing += static_cast<std::uint64_t>(std::popcount(static_cast<unsigned>(out[k][i] ^ ref[k][i])));
  EXPECT_EQ(differing, kMaxBitFlipsPerSample);
}

TEST_F(NativeFaults, SequenceJumpResetAndRestartMoveTheSequenceFieldOnly) {
  const auto seq = [](const Bytes& b) {
    std::uint64_t v = 0;
    for (int i = 0; i < 8; ++i) v |= std::uint64_t{b[6 + i]} << (8 * i);
    return v;
  };
  const auto out = faulted([&](int i) {
    LinkActions a;
    if (i == 50) a.sequence_step = 7;
    if (i == 120) a.sequence_reset = true;
    if (i == 200) a.restart = true;
    return a;
  });
  EXPECT_EQ(seq(out[49]), 49u);
  EXPECT_EQ(seq(out[50]), 57u);   // jumped by exactly 7...
  EXPECT_EQ(seq(out[119]), 126u); // ...and stays shifted
  EXPECT_EQ(seq(out[120]), 0u);
  EXPECT_EQ(seq(out[199]), 79u);
  EXPECT_EQ(seq(out[200]), 0u);
  EXPECT_EQ(seq(out[201]), 1u);
  for (int i : {50, 120, 200}) {  // CRC recomputed over the new field: a valid frame
    EXPECT_EQ(out[i].size(), native::kFrameBytesDeltas);
    const std::uint32_t crc = out[i][122] | out[i][123] << 8 | out[i][124] << 16 | std::uint32_t{out[i][125]} << 24;
    EXPECT_EQ(crc, ref_crc32c(out[i].data(), 122));
    EXPECT_EQ(slice(out[i], 14, 108), slice(ref[i], 14, 108));
  }
  // The receiver: 7 missing numbers at the jump; a step back is a restart
  // (spec section 6 item 5): no gap counted.
  expect_deltas(decode(out), {{50, {1, 0, 0, 7, 0}}});
}

TEST_F(NativeFaults, DropSilenceDuplicateAndBabble) {
  const auto out = faulted([&](int i) {
    LinkActions a;
    if (i == 60) a.drop = true;
    if (i >= 70 && i < 73) a.silence = true;
    if (i == 80) a.copies = 2;
    if (i == 90) a.copies = 4;
    return a;
  });
  EXPECT_TRUE(out[60].empty());
  for (int i = 70; i < 73; ++i) EXPECT_TRUE(out[i].empty());
  Bytes twice = ref[80];
  twice.insert(twice.end(), ref[80].begin(), ref[80].end());
  EXPECT_EQ(out[80], twice);
  // Babble: the same stale sample in 4 full frames; native's sequence is the
  // sample counter, so all four carry 90.
  Bytes four;
  for (int c = 0; c < 4; ++c) four.insert(four.end(), ref[90].begin(), ref[90].end());
  EXPECT_EQ(out[90], four);
  // After every fault the stream is the unfaulted one again.
  for (int i = 91; i < kTicks; ++i) EXPECT_EQ(out[i], ref[i]) << i;
  expect_deltas(decode(out), {{60, {0, 0, 0, 0, 0}}, {61, {1, 0, 0, 1, 0}},
                              {70, {0, 0, 0, 0, 0}}, {71, {0, 0, 0, 0, 0}}, {72, {0, 0, 0, 0, 0}},
                              {73, {1, 0, 0, 3, 0}}, {80, {2, 0, 0, 0, 0}}, {90, {4, 0, 0, 0, 0}}});
}

// ============================================================== MAVLink 2

class MavlinkFaults : public ::testing::Test {
 public:
  static constexpr std::array<std::uint8_t, 1> kSync{mavlink2::kMagic};

 protected:
  StreamEncoderOptions options = mavlink_options();
  std::vector<Bytes> ref = run_stream_plain(mavlink2::Encoder(options));
  std::vector<Bytes> faulted(const ActionsOf& a) { return run_stream(mavlink2::Encoder(options), a); }
  Trace decode(const std::vector<Bytes>& ticks) {
    mavlink2::Decoder d(options);
    return decode_stream(d, ticks);
  }
  // A tick with HIL_SENSOR only, no 0xFD inside it, and none in the next.
  int clean_tick(int from) {
    return pick_tick(from, [&](int k) {
      return !heartbeat_tick(k) && !heartbeat_tick(k + 1) && sync_free(ref[k], kSync) && sync_free(ref[k + 1], kSync);
    });
  }
};

TEST_F(MavlinkFaults, CorruptChecksumInvertsTheX25CrcOneChecksumErrorOneGap) {
  const int k = clean_tick(5);
  const auto out = faulted([&](int i) { LinkActions a; a.corrupt_checksum = i == k; return a; });
  const std::size_t n = mavlink_frame_bytes(out[k], 0);
  ASSERT_EQ(n, out[k].size());
  // CRC-16/MCRF4XX over bytes 1..9+len and HIL_SENSOR's CRC_EXTRA 108.
  const std::uint16_t right = ref_crc16_mcrf4xx(std::array<std::uint8_t, 1>{108}.data(), 1,
                                                ref_crc16_mcrf4xx(out[k].data() + 1, n - 3));
  EXPECT_EQ(static_cast<std::uint16_t>(out[k][n - 2] | out[k][n - 1] << 8), static_cast<std::uint16_t>(~right));
  expect_deltas(decode(out), {{k, {0, 1, 0, 0, n}}, {k + 1, {1, 0, 0, 1, 0}}});
}

TEST_F(MavlinkFaults, BadLengthIsLenPlusOneJudgedWithTheNextPacket) {
  const int k = clean_tick(15);
  const auto out = faulted([&](int i) { LinkActions a; a.bad_length = i == k; return a; });
  EXPECT_EQ(out[k][1], ref[k][1] + 1);
  const std::size_t n = ref[k].size();
  expect_deltas(decode(out), {{k, {0, 0, 0, 0, 0}}, {k + 1, {1, 1, 0, 1, n}}});
}

TEST_F(MavlinkFaults, TruncateSequenceJumpAndReset) {
  const int k = clean_tick(25);
  const int j = clean_tick(k + 3);
  const int r = clean_tick(j + 3);
  const auto out = faulted([&](int i) {
    LinkActions a;
    a.truncate_bytes = i == k ? 5 : 0;
    if (i == j) a.sequence_step = 9;
    if (i == r) a.sequence_reset = true;
    return a;
  });
  EXPECT_EQ(out[k], slice(ref[k], 0, ref[k].size() - 5));
  EXPECT_EQ(out[j][4], static_cast<std::uint8_t>(ref[j][4] + 9));
  EXPECT_EQ(out[r][4], 0);
  // After the jump the counter counts on from there.
  EXPECT_EQ(out[j + 1][4], static_cast<std::uint8_t>(out[j][4] + 1));
  // The packet before the reset carried ref seq + 9; 0 follows it after
  // (256 - (that + 1)) % 256 missing numbers (8-bit counter).
  const std::uint8_t before_reset = static_cast<std::uint8_t>(ref[r - 1][4] + 9);
  const std::uint64_t reset_gaps = static_cast<std::uint8_t>(0 - before_reset - 1);
  expect_deltas(decode(out), {{k, {0, 0, 0, 0, 0}}, {k + 1, {1, 1, 0, 1, ref[k].size() - 5}},
                              {j, {1, 0, 0, 9, 0}}, {r, {1, 0, 0, reset_gaps, 0}}});
}

TEST_F(MavlinkFaults, RestartSendsABootHeartbeatAtSeqZeroThenActiveASecondLater) {
  const int k = 150;
  const auto out = faulted([&](int i) { LinkActions a; a.restart = i == k; return a; });
  const Bytes& b = out[k];
  ASSERT_GE(b.size(), 21u);
  EXPECT_EQ(b[0], 0xFD);
  EXPECT_EQ(b[4], 0);             // seq restarts at 0
  EXPECT_EQ(b[7] | b[8] << 8 | b[9] << 16, 0);  // HEARTBEAT
  EXPECT_EQ(b[10 + 7], 1);        // system_status MAV_STATE_BOOT
  const std::size_t hb = mavlink_frame_bytes(b, 0);
  EXPECT_EQ(b[hb + 4], 1);        // then HIL_SENSOR, seq 1
  EXPECT_EQ(b[hb + 7], 107);
  EXPECT_EQ(hb + mavlink_frame_bytes(b, hb), b.size());  // no second heartbeat this tick
  // Next heartbeat one period later: active again.
  for (int i = k + 1; i < k + 100; ++i) EXPECT_EQ(mavlink_frame_bytes(out[i], 0), out[i].size()) << i;
  const Bytes& next = out[k + 100];
  const std::size_t at = mavlink_frame_bytes(next, 0);
  ASSERT_GT(next.size(), at);
  EXPECT_EQ(next[at + 7], 0);
  EXPECT_EQ(next[at + 10 + 7], 4);  // MAV_STATE_ACTIVE
  // The receiver: the step back to 0 reads as (256 - last - 1) % 256 lost.
  const std::uint64_t gaps = static_cast<std::uint8_t>(0 - ref[k - 1][4] - 1);
  expect_deltas(decode(out), {{k, {1, 0, 0, gaps, 0}}});
}

TEST_F(MavlinkFaults, DropKeepsTheHeartbeatBabbleCountsOnDuplicateRepeats) {
  const auto out = faulted([&](int i) {
    LinkActions a;
    if (i == 200) a.drop = true;  // a heartbeat tick
    if (i == 210) a.copies = 2;
    if (i == 220) a.copies = 5;
    if (i >= 230 && i < 232) a.silence = true;
    return a;
  });
  ASSERT_TRUE(heartbeat_tick(200));
  EXPECT_EQ(out[200], slice(ref[200], mavlink_frame_bytes(ref[200], 0), ref[200].size() - mavlink_frame_bytes(ref[200], 0)));
  EXPECT_EQ(out[200][7], 0);  // the heartbeat alone
  Bytes twice = ref[210];
  twice.insert(twice.end(), ref[210].begin(), ref[210].end());
  EXPECT_EQ(out[210], twice);
  // Babble: five valid packets of the same sample, seq counting on.
  std::size_t at = 0;
  for (int c = 0; c < 5; ++c) {
    const std::size_t n = mavlink_frame_bytes(out[220], at);
    EXPECT_EQ(out[220][at + 4], static_cast<std::uint8_t>(ref[220][4] + c));
    EXPECT_EQ(slice(out[220], at + 10, n - 12), slice(ref[220], 10, n - 12));
    at += n;
  }
  EXPECT_EQ(at, out[220].size());
  EXPECT_TRUE(out[230].empty());
  EXPECT_TRUE(out[231].empty());
  expect_deltas(decode(out), {{200, {0, 0, 0, 1, 0}}, {210, {2, 0, 0, 0, 0}}, {220, {5, 0, 0, 0, 0}},
                              {230, {0, 0, 0, 0, 0}}, {231, {0, 0, 0, 0, 0}}, {232, {1, 0, 0, 2, 0}}});
}

TEST_F(MavlinkFaults, EveryPacketOfTheSampleIsCorruptedWithHighresImuAlongside) {
  StreamEncoderOptions both = mavlink_options();
  both.mavlink_highres_imu = true;
  both.mavlink_heartbeat = false;
  mavlink2::Encoder enc(both);
  Bytes out;
  LinkActions a;
  a.corrupt_checksum = true;
  a.bad_length = true;
  encode_with_link_faults(a, enc, sample_at(1), out);
  mavlink2::Encoder plain(both);
  Bytes ref_bytes;
  plain.encode(sample_at(1), ref_bytes);
  ASSERT_EQ(out.size(), ref_bytes.size());
  const std::size_t first = mavlink_frame_bytes(ref_bytes, 0);
  for (const std::size_t at : {std::size_t{0}, first}) {
    const std::size_t n = mavlink_frame_bytes(ref_bytes, at);
    EXPECT_EQ(out[at + 1], ref_bytes[at + 1] + 1) << at;
    EXPECT_EQ(out[at + n - 2], static_cast<std::uint8_t>(~ref_bytes[at + n - 2])) << at;
    EXPECT_EQ(out[at + n - 1], static_cast<std::uint8_t>(~ref_bytes[at + n - 1])) << at;
    EXPECT_EQ(slice(out, at + 2, n - 4), slice(ref_bytes, at + 2, n - 4)) << at;
  }
}

// ============================================================== MIP

class MipFaults : public ::testing::Test {
 public:
  static constexpr std::array<std::uint8_t, 2> kSync{mip::kSync1, mip::kSync2};

 protected:
  StreamEncoderOptions options{};
  std::vector<Bytes> ref = run_stream_plain(mip::Encoder(options));
  std::vector<Bytes> faulted(const ActionsOf& a) { return run_stream(mip::Encoder(options), a); }
  Trace decode(const std::vector<Bytes>& ticks) {
    mip::Decoder d(options);
    return decode_stream(d, ticks);
  }
  int clean_tick(int from) {
    return pick_tick(from, [&](int k) { return sync_free(ref[k], kSync) && sync_free(ref[k + 1], kSync); });
  }
};

TEST_F(MipFaults, ChecksumLengthTruncationEachLoseExactlyTheirPacket) {
  const int c = clean_tick(10);
  const int l = clean_tick(c + 2);
  const int t = clean_tick(l + 2);
  const auto out = faulted([&](int i) {
    LinkActions a;
    a.corrupt_checksum = i == c;
    a.bad_length = i == l;
    a.truncate_bytes = i == t ? 7 : 0;
    return a;
  });
  const std::size_t n = ref[c].size();
  ASSERT_EQ(n, mip_frame_bytes(ref[c], 0));
  const std::uint16_t right = ref_fletcher(out[c].data(), n - 2);
  EXPECT_EQ(static_cast<std::uint16_t>(out[c][n - 2] << 8 | out[c][n - 1]), static_cast<std::uint16_t>(~right));
  EXPECT_EQ(out[l][3], ref[l][3] + 1);
  EXPECT_EQ(out[t], slice(ref[t], 0, ref[t].size() - 7));
  // MIP has no counter: a lost packet shows as a missing sample only.
  expect_deltas(decode(out), {{c, {0, 1, 0, 0, n}},
                              {l, {0, 0, 0, 0, 0}}, {l + 1, {1, 1, 0, 0, ref[l].size()}},
                              {t, {0, 0, 0, 0, 0}}, {t + 1, {1, 1, 0, 0, ref[t].size() - 7}}});
}

TEST_F(MipFaults, RestartAndSequenceActionsChangeNothingOnTheWire) {
  const auto out = faulted([&](int i) {
    LinkActions a;
    a.restart = i == 30;
    a.sequence_step = i == 40 ? 3 : 0;
    a.sequence_reset = i == 50;
    return a;
  });
  EXPECT_EQ(out, ref);
  EXPECT_FALSE(link_fault_support(mip::Encoder(options)).sequence);
}

// ============================================================== reference receiver

// tests/support/protocol_reference.py's receiver (written from the specs)
// over a whole stream, as JSON.
nlohmann::json python_reference_decode(const std::string& protocol, const Bytes& stream) {
  const std::filesystem::path file = std::filesystem::temp_directory_path() /
                                     ("imuemu_link_faults_" + protocol + "_" + std::to_string(::getpid()) + ".bin");
  {
    std::ofstream f(file, std::ios::binary);
    f.write(reinterpret_cast<const char*>(stream.data()), static_cast<std::streamsize>(stream.size()));
  }
  const std::string command = "/usr/bin/python3 " + std::string(IMUEMU_SOURCE_DIR) +
                              "/tests/support/protocol_reference.py decode " + protocol + " " + file.string();
  std::string text;
  if (FILE* pipe = ::popen(command.c_str(), "r")) {
    char buffer[4096];
    std::size_t n = 0;
    while ((n = std::fread(buffer, 1, sizeof buffer, pipe)) > 0) text.append(buffer, n);
    EXPECT_EQ(::pclose(pipe), 0) << command;
  }
  std::filesystem::remove(file);
  return nlohmann::json::parse(text);
}

// Every stream action at once on sync-free ticks (bit flips anywhere): the
// project's decoder and the reference receiver must count the same.
template <class Encoder>
void expect_reference_receiver_agrees(const std::string& protocol, const Encoder& encoder,
                                      std::span<const std::uint8_t> sync, StreamDecoder& decoder) {
  const std::vector<Bytes> ref = run_stream_plain(encoder);
  std::map<int, LinkActions> plan;
  const std::vector<std::function<void(LinkActions&)>> faults = {
      [](LinkActions& a) { a.corrupt_checksum = true; },  [](LinkActions& a) { a.bad_length = true; },
      [](LinkActions& a) { a.truncate_bytes = 4; },       [](LinkActions& a) { a.drop = true; },
      [](LinkActions& a) { a.copies = 2; },               [](LinkActions& a) { a.copies = 3; },
      [](LinkActions& a) { a.silence = true; },           [](LinkActions& a) { a.sequence_step = 3; },
      [](LinkActions& a) { a.sequence_reset = true; },    [](LinkActions& a) { a.restart = true; },
      [](LinkActions& a) { a.bit_flips = 3; a.bit_error_seed = 77; },
      [](LinkActions& a) { a.bit_flips = 1; a.bit_error_seed = 78; }};
  int k = 3;
  for (const auto& fault : faults) {
    k = pick_tick(k, [&](int i) {
      return !heartbeat_tick(i) && !heartbeat_tick(i + 1) && sync_free(ref[i], sync) && sync_free(ref[i + 1], sync);
    });
    fault(plan[k]);
    k += 3;
  }
  ASSERT_EQ(plan.size(), faults.size());
  const auto ticks = run_stream(encoder, [&](int i) {
    const auto it = plan.find(i);
    return it == plan.end() ? LinkActions{} : it->second;
  });
  Bytes stream;
  for (const Bytes& t : ticks) stream.insert(stream.end(), t.begin(), t.end());
  std::uint64_t samples = 0;
  decoder.feed(stream, [&](const DecodedSample&) { ++samples; });
  const DecoderCounters& c = decoder.counters();
  const nlohmann::json reference = python_reference_decode(protocol, stream);
  const nlohmann::json& rc = reference.at("counters");
  EXPECT_EQ(rc.at("samples").get<std::uint64_t>(), samples) << protocol;
  EXPECT_EQ(rc.at("frames").get<std::uint64_t>(), c.frames) << protocol;
  EXPECT_EQ(rc.at("checksum_errors").get<std::uint64_t>(), c.checksum_errors) << protocol;
  EXPECT_EQ(rc.at("other_errors").get<std::uint64_t>(), c.other_errors) << protocol;
  EXPECT_EQ(rc.at("resync_bytes").get<std::uint64_t>(), c.resync_bytes) << protocol;
  EXPECT_EQ(rc.at("sequence_gaps").get<std::uint64_t>(), c.sequence_gaps) << protocol;
  // The faults did show: at least the checksum, length and truncation
  // losses, and two extra samples from duplicate and babble.
  EXPECT_GE(c.checksum_errors + c.other_errors, 3u) << protocol;
  EXPECT_GT(c.resync_bytes, 0u) << protocol;
}

TEST(LinkFaults, ReferenceReceiverFromTheSpecsCountsWhatTheDecodersCount) {
  {
    native::Decoder d;
    expect_reference_receiver_agrees("native", native::Encoder(true), NativeFaults::kSync, d);
  }
  {
    mavlink2::Decoder d(mavlink_options());
    expect_reference_receiver_agrees("mavlink2", mavlink2::Encoder(mavlink_options()), MavlinkFaults::kSync, d);
  }
  {
    mip::Decoder d(StreamEncoderOptions{});
    expect_reference_receiver_agrees("mip", mip::Encoder(StreamEncoderOptions{}), MipFaults::kSync, d);
  }
}

// ============================================================== DroneCAN

class DroneCanFaults : public ::testing::Test {
 protected:
  dronecan::DroneCanOptions options{};
  std::vector<Frames> ref = run_can_plain(dronecan::DroneCanEncoder(options));
  std::vector<Frames> faulted(const ActionsOf& a) { return run_can(dronecan::DroneCanEncoder(options), a); }
  Trace decode(const std::vector<Frames>& ticks, dronecan::DroneCanDecoder* keep = nullptr) {
    dronecan::DroneCanDecoder d(options);
    Trace t = decode_can(d, ticks);
    if (keep != nullptr) *keep = d;
    return t;
  }
  static std::uint8_t tail(const CanFrame& f) { return f.data[f.len - 1]; }
  // RawIMU frames of a tick (NodeStatus, when there, comes after them).
  static constexpr std::size_t kRawImuFrames = 7;  // 47 + 2 CRC bytes, 7 per frame
};

TEST_F(DroneCanFaults, CorruptChecksumInvertsTheTransferCrc) {
  const int k = 33;
  const auto out = faulted([&](int i) { LinkActions a; a.corrupt_checksum = i == k; return a; });
  ASSERT_EQ(out[k].size(), kRawImuFrames);
  // The transfer CRC (first two bytes, LSB first) against CRC-16-CCITT-FALSE
  // over the signature (LSB first) and the payload.
  std::vector<std::uint8_t> payload;
  for (std::size_t f = 0; f < kRawImuFrames; ++f)
    payload.insert(payload.end(), out[k][f].data.begin() + (f == 0 ? 2 : 0), out[k][f].data.begin() + out[k][f].len - 1);
  ASSERT_EQ(payload.size(), dronecan::kRawImuPayloadBytes);
  std::uint8_t sig[8];
  for (int i = 0; i < 8; ++i) sig[i] = static_cast<std::uint8_t>(dronecan::kRawImuSignature >> (8 * i));
  const std::uint16_t right = ref_crc16_ccitt(ref_crc16_ccitt(0xFFFF, sig, 8), payload.data(), payload.size());
  EXPECT_EQ(static_cast<std::uint16_t>(out[k][0].data[0] | out[k][0].data[1] << 8), static_cast<std::uint16_t>(~right));
  for (std::size_t f = 1; f < kRawImuFrames; ++f) EXPECT_TRUE(same_frames({out[k][f]}, {ref[k][f]}));
  expect_deltas(decode(out), {{k, {0, 1, 0, 0, 0}}, {k + 1, {1, 0, 0, 1, 0}}});
}

TEST_F(DroneCanFaults, TruncationAndBadLengthShortenTheLastFrameKeepingTheTail) {
  const auto out = faulted([&](int i) {
    LinkActions a;
    a.truncate_bytes = i == 40 ? 3 : 0;
    a.bad_length = i == 50;
    return a;
  });
  for (const auto& [k, cut] : {std::pair{40, 3}, std::pair{50, 1}}) {
    const CanFrame& last = out[k][kRawImuFrames - 1];
    const CanFrame& was = ref[k][kRawImuFrames - 1];
    EXPECT_EQ(last.len, was.len - cut);
    EXPECT_EQ(tail(last), tail(was));  // end bit, toggle, transfer id kept
    EXPECT_TRUE(std::equal(last.data.begin(), last.data.begin() + last.len - 1, was.data.begin()));
  }
  // The transfer is framed fine but a few bytes short: its CRC fails.
  expect_deltas(decode(out), {{40, {0, 1, 0, 0, 0}}, {41, {1, 0, 0, 1, 0}}, {50, {0, 1, 0, 0, 0}}, {51, {1, 0, 0, 1, 0}}});
}

TEST_F(DroneCanFaults, MissingSecondFrameBreaksTheTransferOnItsToggle) {
  const int k = 60;
  const auto out = faulted([&](int i) { LinkActions a; a.can_missing_frame = i == k; return a; });
  ASSERT_EQ(out[k].size(), kRawImuFrames - 1);
  EXPECT_TRUE(same_frames({out[k][0]}, {ref[k][0]}));
  for (std::size_t f = 1; f + 1 < kRawImuFrames; ++f) EXPECT_TRUE(same_frames({out[k][f]}, {ref[k][f + 1]}));
  dronecan::DroneCanDecoder d(options);
  const Trace t = decode_can(d, out);
  expect_deltas(t, {{k, {0, 0, 1, 0, 0}}, {k + 1, {1, 0, 0, 1, 0}}});
  EXPECT_EQ(d.detail().bad_toggle, 1u);
}

TEST_F(DroneCanFaults, WrongIdStandardAndExtended) {
  const auto out = faulted([&](int i) {
    LinkActions a;
    a.can_wrong_id = i == 70 || i == 80;
    a.can_id = i == 70 ? 0x123u : (0x123u | kCanIdExtendedFlag);
    return a;
  });
  for (const CanFrame& f : out[70]) {
    EXPECT_EQ(f.id, 0x123u);
    EXPECT_FALSE(f.extended);
  }
  for (const CanFrame& f : out[80]) {
    EXPECT_EQ(f.id, 0x123u);
    EXPECT_TRUE(f.extended);
  }
  // 0x123 extended: data type (0x123 >> 8) & 0xFFFF = 1, source 0x23, a
  // message (bit 7 clear): a type the decoder has no signature for.
  dronecan::DroneCanDecoder d(options);
  const Trace t = decode_can(d, out);
  expect_deltas(t, {{70, {0, 0, 7, 0, 0}}, {71, {1, 0, 0, 1, 0}}, {80, {0, 0, 7, 0, 0}}, {81, {1, 0, 0, 1, 0}}});
  EXPECT_EQ(d.detail().not_dronecan_frame, 7u);
  EXPECT_EQ(d.detail().unknown_data_type, 7u);
}

TEST_F(DroneCanFaults, SequenceJumpAndResetMoveTheTransferId) {
  // RawIMU transfer ids run 0, 1, ... from tick 0, modulo 32.
  const auto out = faulted([&](int i) {
    LinkActions a;
    if (i == 90) a.sequence_step = 5;
    if (i == 117) a.sequence_reset = true;  // last id (116 + 5) % 32 = 25: 0 is 7 ahead
    return a;
  });
  EXPECT_EQ(tail(out[89][0]) & 0x1F, 89 % 32);
  EXPECT_EQ(tail(out[90][0]) & 0x1F, (90 + 5) % 32);
  EXPECT_EQ(tail(out[117][0]) & 0x1F, 0);
  EXPECT_EQ(tail(out[118][0]) & 0x1F, 1);
  expect_deltas(decode(out), {{90, {1, 0, 0, 5, 0}}, {117, {1, 0, 0, 6, 0}}});
}

TEST_F(DroneCanFaults, RestartSendsNodeStatusInitializationWithUptimeZeroThenOperational) {
  const int k = 250;  // 2.5 s after start: uptime was 2 s
  const auto out = faulted([&](int i) {
    LinkActions a;
    a.silence = i >= k - 20 && i < k;  // off for 0.2 s
    a.restart = i == k;
    return a;
  });
  for (int i = k - 20; i < k; ++i) EXPECT_TRUE(out[i].empty());
  ASSERT_EQ(out[k].size(), 1 + kRawImuFrames);
  const CanFrame& ns = out[k][0];
  EXPECT_EQ(ns.id, dronecan::message_can_id(24, dronecan::kNodeStatusDataTypeId, options.node_id));
  ASSERT_EQ(ns.len, 8);
  EXPECT_EQ(ns.data[0] | ns.data[1] | ns.data[2] | ns.data[3], 0);  // uptime_sec 0
  // health(2) mode(3) sub_mode(3), most significant bit first: OK, INITIALIZATION (1), 0.
  EXPECT_EQ(ns.data[4], 0x08);
  EXPECT_EQ(tail(ns), 0xC0);  // single frame, transfer id 0
  EXPECT_EQ(tail(out[k][1]), 0x80);  // RawIMU starts again at transfer id 0
  EXPECT_EQ(tail(out[k][kRawImuFrames]) & 0x1F, 0);
  // Nothing more until one period later: OPERATIONAL, uptime 1 s, transfer id 1.
  for (int i = k + 1; i < k + 100; ++i) EXPECT_EQ(out[i].size(), kRawImuFrames) << i;
  ASSERT_EQ(out[k + 100].size(), kRawImuFrames + 1);
  const CanFrame& ns1 = out[k + 100][kRawImuFrames];
  EXPECT_EQ(ns1.data[0], 1);
  EXPECT_EQ(ns1.data[4], 0x00);
  EXPECT_EQ(tail(ns1), 0xC1);

  dronecan::DroneCanDecoder d(options);
  const Trace t = decode_can(d, out);
  // Before: RawIMU ids ... 229 % 32 = 5; after the restart 0 is 27 ahead =
  // 5 behind: stale, dropped; 1 follows it: the decoder follows the jump.
  // NodeStatus id 0 after id 2: 30 ahead, stale too (its first).
  expect_deltas(t, {{k - 20, {0, 0, 0, 0, 0}}, {k - 19, {0, 0, 0, 0, 0}}, {k - 18, {0, 0, 0, 0, 0}},
                    {k - 17, {0, 0, 0, 0, 0}}, {k - 16, {0, 0, 0, 0, 0}}, {k - 15, {0, 0, 0, 0, 0}},
                    {k - 14, {0, 0, 0, 0, 0}}, {k - 13, {0, 0, 0, 0, 0}}, {k - 12, {0, 0, 0, 0, 0}},
                    {k - 11, {0, 0, 0, 0, 0}}, {k - 10, {0, 0, 0, 0, 0}}, {k - 9, {0, 0, 0, 0, 0}},
                    {k - 8, {0, 0, 0, 0, 0}}, {k - 7, {0, 0, 0, 0, 0}}, {k - 6, {0, 0, 0, 0, 0}},
                    {k - 5, {0, 0, 0, 0, 0}}, {k - 4, {0, 0, 0, 0, 0}}, {k - 3, {0, 0, 0, 0, 0}},
                    {k - 2, {0, 0, 0, 0, 0}}, {k - 1, {0, 0, 0, 0, 0}},
                    {k, {0, 0, 2, 0, 0}}});
  EXPECT_EQ(d.detail().stale_transfer, 2u);
  const auto status = d.last_node_status(options.node_id);
  ASSERT_TRUE(status.has_value());
  EXPECT_EQ(status->mode, 0);  // OPERATIONAL again at the end
}

TEST_F(DroneCanFaults, DuplicateIsRefusedBabbleCountsOnDropKeepsNodeStatus) {
  const auto out = faulted([&](int i) {
    LinkActions a;
    if (i == 300) a.drop = true;  // a NodeStatus tick (3 s)
    if (i == 310) a.copies = 2;
    if (i == 320) a.copies = 3;
    return a;
  });
  ASSERT_EQ(out[300].size(), 1u);
  EXPECT_TRUE(same_frames(out[300], {ref[300].back()}));
  EXPECT_EQ(out[310].size(), 2 * kRawImuFrames);
  ASSERT_EQ(out[320].size(), 3 * kRawImuFrames);
  for (int c = 0; c < 3; ++c) EXPECT_EQ(tail(out[320][c * kRawImuFrames]) & 0x1F, (320 + c) % 32);
  dronecan::DroneCanDecoder d(options);
  const Trace t = decode_can(d, out);
  expect_deltas(t, {{300, {0, 0, 0, 0, 0}}, {301, {1, 0, 0, 1, 0}}, {310, {1, 0, 1, 0, 0}}, {320, {3, 0, 0, 0, 0}}});
  EXPECT_EQ(d.detail().duplicate_transfer, 1u);
  EXPECT_FALSE(link_fault_support(dronecan::DroneCanEncoder(options)).bit_errors);
}

TEST_F(DroneCanFaults, ChecksumFaultCoversEverySampleTransferButNotNodeStatus) {
  dronecan::DroneCanEncoder enc(options);
  Frames out;
  LinkActions a;
  a.corrupt_checksum = true;
  encode_with_link_faults(a, enc, sample_at(0), out);  // tick 0: RawIMU + NodeStatus
  ASSERT_EQ(out.size(), kRawImuFrames + 1);
  // corrupt_checksum covers the sample's frames only: NodeStatus untouched.
  EXPECT_EQ(tail(out.back()), 0xC0);
  // A babbled sample's 3 transfers each get the treatment.
  Frames many;
  a.copies = 3;
  dronecan::DroneCanEncoder enc2(options);
  encode_with_link_faults(a, enc2, sample_at(0), many);
  dronecan::DroneCanDecoder d(options);
  for (const CanFrame& f : many) d.feed(f, nullptr);
  EXPECT_EQ(d.counters().checksum_errors, 3u);
}

// A tail-byte transport whose sample is a single-frame transfer (no
// transfer CRC): corrupt_checksum sets the toggle bit, which a first frame
// must have clear (DroneCAN spec 4.1).
class SingleFrameTailEncoder final : public CanEncoder {
 public:
  std::string name() const override { return "single-frame"; }
  void encode(const ImuFrameInput&, std::vector<CanFrame>& out) override {
    CanFrame f;
    f.id = dronecan::message_can_id(24, dronecan::kNodeStatusDataTypeId, 42);
    f.extended = true;
    f.len = 8;
    f.data[7] = static_cast<std::uint8_t>(0xC0 | (transfer_id_++ & 0x1F));
    out.push_back(f);
  }
  bool frames_have_tail_byte() const override { return true; }

 private:
  std::uint8_t transfer_id_ = 0;
};

TEST(LinkFaults, SingleFrameTransferChecksumFaultSetsTheToggleBit) {
  SingleFrameTailEncoder enc;
  Frames out;
  encode_with_link_faults(LinkActions{}, enc, sample_at(0), out);
  LinkActions a;
  a.corrupt_checksum = true;
  encode_with_link_faults(a, enc, sample_at(1), out);
  ASSERT_EQ(out.size(), 2u);
  EXPECT_EQ(out[0].data[7], 0xC0);
  EXPECT_EQ(out[1].data[7], 0xE1);  // start, end, toggle, transfer id 1
  dronecan::DroneCanDecoder d;
  for (const CanFrame& f : out) d.feed(f, nullptr);
  EXPECT_EQ(d.detail().bad_toggle, 1u);
  EXPECT_EQ(d.counters().frames, 1u);
}

// ============================================================== J1939

class J1939Faults : public ::testing::Test {
 protected:
  j1939::J1939Options options{};
  std::vector<Frames> ref = run_can_plain(j1939::J1939Encoder(options));
  std::vector<Frames> faulted(const ActionsOf& a) { return run_can(j1939::J1939Encoder(options), a); }
};

TEST_F(J1939Faults, MissingFrameLosesTheAccelerationOfThatSampleOnly) {
  const int k = 40;
  const auto out = faulted([&](int i) { LinkActions a; a.can_missing_frame = i == k; return a; });
  ASSERT_EQ(out[k].size(), 1u);
  EXPECT_EQ(j1939::parse_can_id(out[k][0].id).pgn, j1939::kPgnAngularRateInformation);
  j1939::J1939Decoder d(options);
  const Trace t = decode_can(d, out);
  // ARI k waits for its ACCS; ARI k+1 emits it alone (gyro only) and is
  // then completed by ACCS k+1.
  expect_deltas(t, {{k, {0, 0, 0, 0, 0}}, {k + 1, {2, 0, 0, 0, 0}}});
  ASSERT_EQ(t.samples.size(), static_cast<std::size_t>(kTicks));
  const DecodedSample& alone = t.samples[k].second;
  EXPECT_EQ(alone.accel_m_s2, Vec3::Zero());
  EXPECT_NEAR(alone.gyro_rad_s.x(), sample_at(k).gyro_rad_s.x(), 1e-3);
}

TEST_F(J1939Faults, TruncationWrongIdRestartAndUnsupportedActions) {
  options.name = 0x8000'0000'0012'3456ULL;
  const auto out = faulted([&](int i) {
    LinkActions a;
    a.truncate_bytes = i == 50 ? 2 : 0;
    a.can_wrong_id = i == 60;
    a.can_id = 0x7FF;
    a.restart = i == 70;
    a.corrupt_checksum = i == 80;   // J1939 frames carry no checksum: nothing
    a.sequence_step = i == 90 ? 4 : 0;  // nor a counter
    a.bit_flips = i == 95 ? 7 : 0;      // the controller's CRC and retransmission hide bit errors
    a.bit_error_seed = 3;
    return a;
  });
  EXPECT_TRUE(same_frames(out[95], ref[95]));
  for (const CanFrame& f : out[50]) EXPECT_EQ(f.len, 6);
  for (const CanFrame& f : out[60]) {
    EXPECT_EQ(f.id, 0x7FFu);
    EXPECT_FALSE(f.extended);
  }
  ASSERT_EQ(out[70].size(), 3u);
  EXPECT_EQ(out[70][0].id, 0x18EEFF80u);  // priority 6, PGN 0xEE00 to 0xFF, SA 0x80
  EXPECT_TRUE(out[70][0].extended);
  for (int i = 0; i < 8; ++i) EXPECT_EQ(out[70][0].data[i], static_cast<std::uint8_t>(options.name >> (8 * i)));
  EXPECT_TRUE(same_frames(out[80], ref[80]));
  EXPECT_TRUE(same_frames(out[90], ref[90]));
  j1939::J1939Decoder d(options);
  const Trace t = decode_can(d, out);
  expect_deltas(t, {{50, {0, 0, 2, 0, 0}}, {60, {0, 0, 2, 0, 0}}});
  EXPECT_EQ(d.detail().not_j1939_frame, 4u);
  EXPECT_EQ(d.claimed_name(0x80), options.name);
  const LinkFaultSupport s = link_fault_support(j1939::J1939Encoder(options));
  EXPECT_FALSE(s.sequence);
  EXPECT_FALSE(s.checksum);
  EXPECT_TRUE(s.missing_frame);
}

}  // namespace
