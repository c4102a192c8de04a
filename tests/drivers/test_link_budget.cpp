// Link budget (drivers/link_budget.hpp): UART framing bits, worst-case CAN
// and CAN FD frame lengths with bit stuffing, and the ok / warn / refuse
// boundaries at exactly 70 % and 100 % of the capacity.
//
// The golden frame lengths are counted by hand in the comments, and the
// dynamic stuff-bit count the formulas assume is checked against a bit-level
// stuffing simulator (insert a complementary bit after five equal bits).
#include <gtest/gtest.h>

#include <sys/wait.h>

#include <cstdint>
#include <cstdio>
#include <string>
#include <random>
#include <vector>

#include "drivers/link_budget.hpp"
#include "drivers/protocols/can_protocols.hpp"
#include "drivers/protocols/stream_protocols.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_drivers_test_link_budget {
namespace imuemu { using namespace ::imuemu; }

namespace drv = imuemu::drivers;
using drv::BudgetVerdict;

namespace {

drv::SerialSettings serial(int baud, int data_bits, drv::Parity parity, int stop_bits) {
  drv::SerialSettings s;
  s.baud = baud;
  s.data_bits = data_bits;
  s.parity = parity;
  s.stop_bits = stop_bits;
  return s;
}

BudgetVerdict uart_verdict(double bytes_per_second, const drv::SerialSettings& s) {
  return drv::uart_budget(bytes_per_second, s).verdict;
}

BudgetVerdict can_verdict(double frames_per_second, bool extended, bool fd, bool brs, std::size_t payload,
                          double nominal, double data = 2'000'000) {
  const std::vector<drv::CanTraffic> traffic{{frames_per_second, extended, fd, brs, payload}};
  return drv::can_budget(traffic, drv::CanBitRates{nominal, data}).verdict;
}

// Number of stuff bits a transmitter inserts into `bits` (ISO 11898-1: after
// five consecutive equal bits, a complementary bit, which itself counts
// towards the next run).
int stuff_bits(const std::vector<int>& bits) {
  int inserted = 0, run = 0, last = -1;
  for (const int b : bits) {
    if (b == last) {
      ++run;
    } else {
      last = b;
      run = 1;
    }
    if (run == 5) {
      ++inserted;
      last = 1 - b;  // the stuff bit
      run = 1;
    }
  }
  return inserted;
}

}  // namespace

TEST(UartBudget, BitsPerByteCountStartDataParityStop) {
  using P = drv::Parity;
  EXPECT_EQ(drv::uart_bits_per_byte(serial(115200, 8, P::none, 1)), 10);  // 1 + 8 + 0 + 1
  EXPECT_EQ(drv::uart_bits_per_byte(serial(115200, 8, P::even, 1)), 11);  // 1 + 8 + 1 + 1
  EXPECT_EQ(drv::uart_bits_per_byte(serial(115200, 8, P::none, 2)), 11);  // 1 + 8 + 0 + 2
  EXPECT_EQ(drv::uart_bits_per_byte(serial(115200, 7, P::odd, 2)), 11);   // 1 + 7 + 1 + 2
  EXPECT_EQ(drv::uart_bits_per_byte(serial(115200, 5, P::none, 1)), 7);
  EXPECT_THROW(drv::uart_bits_per_byte(serial(0, 8, P::none, 1)), drv::TransportError);
  EXPECT_THROW(drv::uart_bits_per_byte(serial(9600, 9, P::none, 1)), drv::TransportError);
}

TEST(UartBudget, Boundaries8N1) {
  const auto s = serial(115200, 8, drv::Parity::none, 1);
  // 70 %: 0.7 * 115200 / 10 = 8064 B/s; 100 %: 11520 B/s.
  EXPECT_EQ(uart_verdict(8064, s), BudgetVerdict::ok);
  EXPECT_EQ(uart_verdict(8065, s), BudgetVerdict::warn);
  EXPECT_EQ(uart_verdict(11520, s), BudgetVerdict::warn);
  EXPECT_EQ(uart_verdict(11521, s), BudgetVerdict::refuse);
  EXPECT_EQ(uart_verdict(0, s), BudgetVerdict::ok);

  const drv::LinkBudget b = drv::uart_budget(11521, s);
  EXPECT_DOUBLE_EQ(b.bits_per_second_used, 115210.0);
  EXPECT_DOUBLE_EQ(b.capacity_bits_per_second, 115200.0);
  EXPECT_NEAR(b.load_fraction, 115210.0 / 115200.0, 1e-15);
  for (const char* part : {"11521", "115200", "115210", "10 bit", "8N1", "refused"})
    EXPECT_NE(b.message.find(part), std::string::npos) << part << " missing in: " << b.message;
  EXPECT_NE(drv::uart_budget(8065, s).message.find("warning"), std::string::npos);
}

TEST(UartBudget, Boundaries8E1And8N2) {
  // 11 bits per byte: at 110000 baud, 70 % = 7000 B/s and 100 % = 10000 B/s.
  for (const auto& s : {serial(110000, 8, drv::Parity::even, 1), serial(110000, 8, drv::Parity::none, 2)}) {
    SCOPED_TRACE(drv::to_string(s));
    EXPECT_EQ(uart_verdict(7000, s), BudgetVerdict::ok);
    EXPECT_EQ(uart_verdict(7001, s), BudgetVerdict::warn);
    EXPECT_EQ(uart_verdict(10000, s), BudgetVerdict::warn);
    EXPECT_EQ(uart_verdict(10001, s), BudgetVerdict::refuse);
  }
  // At 921600 8E1: 100 % is 921600 / 11 = 83781.8 B/s.
  const auto s = serial(921600, 8, drv::Parity::even, 1);
  EXPECT_EQ(uart_verdict(83781, s), BudgetVerdict::warn);
  EXPECT_EQ(uart_verdict(83782, s), BudgetVerdict::refuse);
  EXPECT_THROW(drv::uart_budget(-1.0, s), std::invalid_argument);
}

TEST(UartBudget, FromARealStreamEncoder) {
  // native with deltas: 126-byte frames (6 header + 116 payload + 4 CRC,
  // docs/native-protocol.md). 400 Hz: 50400 B/s = 504000 bit/s at 8N1.
  drv::StreamEncoderOptions o;
  o.include_deltas = true;
  const auto encoder = drv::make_stream_encoder("native", o);
  ASSERT_EQ(encoder->max_bytes_per_sample(), 126u);
  const drv::LinkBudget at_460800 = drv::uart_budget(*encoder, 400.0, serial(460800, 8, drv::Parity::none, 1));
  EXPECT_EQ(at_460800.verdict, BudgetVerdict::refuse) << at_460800.message;
  EXPECT_DOUBLE_EQ(at_460800.bits_per_second_used, 504000.0);
  EXPECT_NE(at_460800.message.find("native"), std::string::npos) << at_460800.message;
  const drv::LinkBudget at_921600 = drv::uart_budget(*encoder, 400.0, serial(921600, 8, drv::Parity::none, 1));
  EXPECT_EQ(at_921600.verdict, BudgetVerdict::ok) << at_921600.message;  // 54.7 %
}

TEST(UartBudget, AProtocolNoConfigurationChangesIsJudgedOnItsWorstCase) {
  // native: 126-byte frames on every sample whatever is configured, so the
  // configured traffic and the worst case beside it are both 126 x 400 B/s.
  drv::StreamEncoderOptions o;
  o.include_deltas = true;
  const auto encoder = drv::make_stream_encoder("native", o);
  EXPECT_DOUBLE_EQ(encoder->configured_bytes_per_second(400.0), 126.0 * 400);
  const drv::LinkBudget b = drv::uart_budget(*encoder, 400.0, serial(921600, 8, drv::Parity::none, 1));
  ASSERT_TRUE(b.worst_case_bytes_per_second.has_value() && b.worst_case_load_fraction.has_value());
  EXPECT_DOUBLE_EQ(*b.worst_case_bytes_per_second, 126.0 * 400);
  EXPECT_DOUBLE_EQ(*b.worst_case_load_fraction, b.load_fraction);
}

TEST(CanBudget, WorstCaseStuffBitsMatchABitLevelStuffer) {
  // The formulas charge floor((L - 1) / 4) stuff bits to L stuffable bits.
  // The worst pattern 00000 1111 0000 1111 ... reaches it exactly; random
  // patterns never exceed it.
  std::mt19937 rng(7);
  for (int length = 1; length <= 600; ++length) {
    std::vector<int> worst(static_cast<std::size_t>(length));
    for (int i = 0; i < length; ++i) worst[static_cast<std::size_t>(i)] = i < 5 ? 0 : ((i - 5) / 4) % 2 == 0 ? 1 : 0;
    ASSERT_EQ(stuff_bits(worst), (length - 1) / 4) << "length " << length;
    for (int trial = 0; trial < 20; ++trial) {
      std::vector<int> bits(static_cast<std::size_t>(length));
      const int bias = trial % 4;  // long runs are likelier with biased bits
      for (int& b : bits) b = static_cast<int>(rng() % 8) < 4 + bias ? 0 : 1;
      ASSERT_LE(stuff_bits(bits), (length - 1) / 4) << "length " << length;
    }
  }
}

TEST(CanBudget, ClassicGoldenFrameLengths) {
  // Davis et al. 2007: C = g + 8s + 13 + floor((g + 8s - 1) / 4).
  // 11-bit, 8 bytes: 34 + 64 + 13 + floor(97 / 4) = 111 + 24 = 135.
  EXPECT_EQ(drv::can_frame_worst_case_bits(false, false, false, 8).nominal_bits, 135);
  // 29-bit, 8 bytes: 54 + 64 + 13 + floor(117 / 4) = 131 + 29 = 160.
  EXPECT_EQ(drv::can_frame_worst_case_bits(true, false, false, 8).nominal_bits, 160);
  // 11-bit, 0 bytes: 34 + 13 + floor(33 / 4) = 47 + 8 = 55.
  EXPECT_EQ(drv::can_frame_worst_case_bits(false, false, false, 0).nominal_bits, 55);
  // 11-bit, 7 bytes: 34 + 56 + 13 + floor(89 / 4) = 103 + 22 = 125.
  EXPECT_EQ(drv::can_frame_worst_case_bits(false, false, false, 7).nominal_bits, 125);
  EXPECT_EQ(drv::can_frame_worst_case_bits(false, false, false, 8).data_bits, 0);
  EXPECT_THROW(drv::can_frame_worst_case_bits(false, false, false, 9), std::invalid_argument);
  EXPECT_THROW(drv::can_frame_worst_case_bits(false, false, true, 8), std::invalid_argument);
}

TEST(CanBudget, ClassicBoundaries11And29BitIds) {
  // 11-bit, 7 bytes (125 bits) at 500 kbit/s: 100 % = 4000 frames/s, 70 % = 2800.
  EXPECT_EQ(can_verdict(2800, false, false, false, 7, 500'000), BudgetVerdict::ok);
  EXPECT_EQ(can_verdict(2801, false, false, false, 7, 500'000), BudgetVerdict::warn);
  EXPECT_EQ(can_verdict(4000, false, false, false, 7, 500'000), BudgetVerdict::warn);
  EXPECT_EQ(can_verdict(4001, false, false, false, 7, 500'000), BudgetVerdict::refuse);
  // 11-bit, 8 bytes (135 bits) at 135 kbit/s: 100 % = 1000 frames/s, 70 % = 700.
  EXPECT_EQ(can_verdict(700, false, false, false, 8, 135'000), BudgetVerdict::ok);
  EXPECT_EQ(can_verdict(701, false, false, false, 8, 135'000), BudgetVerdict::warn);
  EXPECT_EQ(can_verdict(1000, false, false, false, 8, 135'000), BudgetVerdict::warn);
  EXPECT_EQ(can_verdict(1001, false, false, false, 8, 135'000), BudgetVerdict::refuse);
  // 29-bit, 8 bytes (160 bits) at 500 kbit/s: 100 % = 3125 frames/s, 70 % = 2187.5.
  EXPECT_EQ(can_verdict(2187.5, true, false, false, 8, 500'000), BudgetVerdict::ok);
  EXPECT_EQ(can_verdict(2187.5 + 1.0 / 64, true, false, false, 8, 500'000), BudgetVerdict::warn);
  EXPECT_EQ(can_verdict(3125, true, false, false, 8, 500'000), BudgetVerdict::warn);
  EXPECT_EQ(can_verdict(3126, true, false, false, 8, 500'000), BudgetVerdict::refuse);

  const std::vector<drv::CanTraffic> t{{3126, true, false, false, 8}};
  const drv::LinkBudget b = drv::can_budget(t, drv::CanBitRates{500'000, 2'000'000});
  EXPECT_DOUBLE_EQ(b.bits_per_second_used, 3126.0 * 160.0);
  EXPECT_DOUBLE_EQ(b.capacity_bits_per_second, 500'000.0);
  for (const char* part : {"3126 frames/s", "500160", "500000", "160 nominal", "refused"})
    EXPECT_NE(b.message.find(part), std::string::npos) << part << " missing in: " << b.message;
}

TEST(CanBudget, FdGoldenFrameLengthsAndDlcRounding) {
  // FD, 11-bit id, 64 bytes, no BRS: stuffed region SOF..data = 17 + 5 + 512
  // = 534 bits, floor(533 / 4) = 133 stuff bits; CRC field 4 + 21 + 7 fixed
  // stuff = 32; trailer 13: 534 + 133 + 32 + 13 = 712.
  EXPECT_EQ(drv::can_frame_worst_case_bits(false, true, false, 64).nominal_bits, 712);
  // 29-bit id: 36 + 5 + 512 = 553, floor(552 / 4) = 138: 553 + 138 + 32 + 13 = 736.
  EXPECT_EQ(drv::can_frame_worst_case_bits(true, true, false, 64).nominal_bits, 736);
  // 11-bit, 8 bytes: 22 + 64 = 86, floor(85 / 4) = 21, CRC field 4 + 17 + 6 = 27:
  // 86 + 21 + 27 + 13 = 147.
  EXPECT_EQ(drv::can_frame_worst_case_bits(false, true, false, 8).nominal_bits, 147);
  // 11-bit, 20 bytes (first CRC-21 length): 22 + 160 = 182, 45 stuff, 32, 13 = 272.
  EXPECT_EQ(drv::can_frame_worst_case_bits(false, true, false, 20).nominal_bits, 272);
  // BRS, 11-bit, 8 bytes: nominal = 17 arbitration + floor(16 / 4) = 4 stuff + 13
  // trailer = 34; data = 5 + 64 + (21 - 4) + 27 = 113; 34 + 113 = 147.
  const drv::CanFrameBits brs8 = drv::can_frame_worst_case_bits(false, true, true, 8);
  EXPECT_EQ(brs8.nominal_bits, 34);
  EXPECT_EQ(brs8.data_bits, 113);
  // BRS, 11-bit, 64 bytes: 34 nominal; 5 + 512 + 129 + 32 = 678 data.
  const drv::CanFrameBits brs64 = drv::can_frame_worst_case_bits(false, true, true, 64);
  EXPECT_EQ(brs64.nominal_bits, 34);
  EXPECT_EQ(brs64.data_bits, 678);
  // BRS, 29-bit, 64 bytes: nominal 36 + floor(35 / 4) = 8 + 13 = 57; data 5 + 512 + 130 + 32 = 679.
  const drv::CanFrameBits brs64x = drv::can_frame_worst_case_bits(true, true, true, 64);
  EXPECT_EQ(brs64x.nominal_bits, 57);
  EXPECT_EQ(brs64x.data_bits, 679);

  // DLC table: 9..12 -> 12, 13..16 -> 16, 17..20 -> 20, 21..24 -> 24, 25..32
  // -> 32, 33..48 -> 48, 49..64 -> 64.
  const std::vector<std::pair<std::size_t, std::size_t>> table{
      {0, 0}, {8, 8}, {9, 12}, {12, 12}, {13, 16}, {17, 20}, {21, 24}, {25, 32}, {33, 48}, {49, 64}, {64, 64}};
  for (const auto& [in, out] : table) EXPECT_EQ(drv::canfd_data_length(in), out) << in;
  EXPECT_EQ(drv::can_frame_worst_case_bits(false, true, false, 9).total(),
            drv::can_frame_worst_case_bits(false, true, false, 12).total());
  EXPECT_THROW(drv::canfd_data_length(65), std::invalid_argument);
  EXPECT_THROW(drv::can_frame_worst_case_bits(false, true, false, 65), std::invalid_argument);
}

TEST(CanBudget, FdBoundariesWithAndWithoutBrs) {
  // No BRS, 11-bit, 8 bytes (147 bits) at 147 kbit/s: 100 % = 1000 frames/s.
  EXPECT_EQ(can_verdict(700, false, true, false, 8, 147'000), BudgetVerdict::ok);
  EXPECT_EQ(can_verdict(701, false, true, false, 8, 147'000), BudgetVerdict::warn);
  EXPECT_EQ(can_verdict(1000, false, true, false, 8, 147'000), BudgetVerdict::warn);
  EXPECT_EQ(can_verdict(1001, false, true, false, 8, 147'000), BudgetVerdict::refuse);
  // BRS, 11-bit, 8 bytes (34 nominal + 113 data bits) at 68 / 226 kbit/s:
  // each frame takes 0.5 ms + 0.5 ms, so 1000 frames/s = 100 %, 700 = 70 %.
  EXPECT_EQ(can_verdict(700, false, true, true, 8, 68'000, 226'000), BudgetVerdict::ok);
  EXPECT_EQ(can_verdict(701, false, true, true, 8, 68'000, 226'000), BudgetVerdict::warn);
  EXPECT_EQ(can_verdict(1000, false, true, true, 8, 68'000, 226'000), BudgetVerdict::warn);
  EXPECT_EQ(can_verdict(1001, false, true, true, 8, 68'000, 226'000), BudgetVerdict::refuse);
  // The data rate only matters with BRS: the same frames without BRS take
  // 147 bits at 68 kbit/s each, 1000 frames/s = 216 %.
  EXPECT_EQ(can_verdict(1000, false, true, false, 8, 68'000, 226'000), BudgetVerdict::refuse);
  // Realistic: 64-byte BRS frames at 500 k / 2 M: 34 / 500e3 + 678 / 2e6 =
  // 407 us per frame; 1000 frames/s = 40.7 %.
  const std::vector<drv::CanTraffic> t{{1000, false, true, true, 64}};
  const drv::LinkBudget b = drv::can_budget(t, drv::CanBitRates{500'000, 2'000'000});
  EXPECT_NEAR(b.load_fraction, 0.407, 1e-12);
  EXPECT_EQ(b.verdict, BudgetVerdict::ok);
  EXPECT_THROW(drv::can_budget(t, drv::CanBitRates{500'000, 0}), std::invalid_argument);
  EXPECT_THROW(drv::can_budget(t, drv::CanBitRates{0, 2'000'000}), std::invalid_argument);
}

TEST(CanBudget, MeasuresARealDroneCanEncoder) {
  // RawIMU: 47 payload bytes + 2 transfer-CRC bytes = 49, 7 per frame (the
  // 8th is the tail byte) -> 7 frames of 8 bytes per sample; NodeStatus (7
  // bytes + tail) once a second. 400 Hz: 2800 + 1 = 2801 29-bit frames/s.
  auto encoder = drv::make_can_encoder("dronecan");
  const std::vector<drv::CanTraffic> traffic = drv::measure_can_traffic(*encoder, 400.0, false);
  ASSERT_EQ(traffic.size(), 1u);
  EXPECT_TRUE(traffic[0].extended);
  EXPECT_FALSE(traffic[0].fd);
  EXPECT_EQ(traffic[0].payload_bytes, 8u);
  EXPECT_DOUBLE_EQ(traffic[0].frames_per_second, 2801.0);
  // 2801 x 160 bits = 448160 bit/s: 89.6 % of 500 kbit/s (warned), 44.8 % of 1 Mbit/s.
  const drv::LinkBudget at_500k = drv::can_budget(traffic, drv::CanBitRates{500'000, 2'000'000});
  EXPECT_EQ(at_500k.verdict, BudgetVerdict::warn) << at_500k.message;
  EXPECT_DOUBLE_EQ(at_500k.bits_per_second_used, 448160.0);
  const drv::LinkBudget at_1m = drv::can_budget(traffic, drv::CanBitRates{1'000'000, 2'000'000});
  EXPECT_EQ(at_1m.verdict, BudgetVerdict::ok) << at_1m.message;
  // 1 kHz at 500 kbit/s: 7001 x 160 = 1120160 bit/s: refused.
  auto encoder_1k = drv::make_can_encoder("dronecan");
  const drv::LinkBudget at_1khz =
      drv::can_budget(drv::measure_can_traffic(*encoder_1k, 1000.0, false), drv::CanBitRates{500'000, 2'000'000});
  EXPECT_EQ(at_1khz.verdict, BudgetVerdict::refuse) << at_1khz.message;
  EXPECT_DOUBLE_EQ(at_1khz.bits_per_second_used, 1120160.0);
}

TEST(CanBudget, MeasuresARealJ1939Encoder) {
  // ARI + ACCS, one 8-byte 29-bit frame each per sample; 100 Hz -> 200 frames/s.
  auto encoder = drv::make_can_encoder("j1939");
  const std::vector<drv::CanTraffic> traffic = drv::measure_can_traffic(*encoder, 100.0, false);
  ASSERT_EQ(traffic.size(), 1u);
  EXPECT_TRUE(traffic[0].extended);
  EXPECT_EQ(traffic[0].payload_bytes, 8u);
  EXPECT_DOUBLE_EQ(traffic[0].frames_per_second, 200.0);
  EXPECT_DOUBLE_EQ(drv::can_budget(traffic, drv::CanBitRates{250'000, 0}).load_fraction, 200.0 * 160.0 / 250'000.0);
  EXPECT_THROW(drv::measure_can_traffic(*encoder, 0.0, false), std::invalid_argument);
}

// `imuemu budget` through the real binary: refused traffic exits non-zero
// with the numbers, acceptable traffic exits 0.
TEST(BudgetCommand, RefusesWhatDoesNotFitAndNamesTheNumbers) {
  const auto run = [](const std::string& args, std::string& output) {
    const std::string command = std::string(IMUEMU_CLI_PATH) + " budget " + args + " 2>&1";
    FILE* p = ::popen(command.c_str(), "r");
    if (p == nullptr) return -1;
    char buffer[1024];
    std::size_t n;
    while ((n = std::fread(buffer, 1, sizeof buffer, p)) > 0) output.append(buffer, n);
    const int status = ::pclose(p);
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  };
  std::string refused, fits, can;
  // native with deltas, 126 B x 400 Hz x 10 bit = 504000 bit/s > 460800.
  EXPECT_NE(run("--protocol native --rate 400 --baud 460800", refused), 0) << refused;
  for (const char* part : {"504000", "460800", "refused"})
    EXPECT_NE(refused.find(part), std::string::npos) << part << " missing in: " << refused;
  EXPECT_EQ(run("--protocol native --rate 400 --baud 921600", fits), 0) << fits;
  // DroneCAN 400 Hz: 2801 x 160 = 448160 bit/s of 500000: warned, still exit 0.
  EXPECT_EQ(run("--protocol dronecan --rate 400 --bitrate 500000", can), 0) << can;
  EXPECT_NE(can.find("448160"), std::string::npos) << can;
  EXPECT_NE(can.find("warning"), std::string::npos) << can;
}
}  // namespace unity_drivers_test_link_budget
