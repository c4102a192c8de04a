// Link budget at configuration time: does the traffic a scene asks for fit
// the line (UART) or the bus (CAN), with worst-case framing overhead?
//
//   load = line time used per second / 1 s
//   verdict: ok up to 70 %, warn above 70 % (little room for retries, other
//   nodes, jitter), refuse above 100 % (the schedule cannot be kept: frames
//   would queue and be dropped).
//
// UART: bits per byte = 1 start + data bits + parity bit (if any) + stop bits.
// CAN: every frame charged its WORST-CASE length including bit stuffing
// (classic CAN: Davis, Burns, Bril, Lukkien 2007; CAN FD: ISO 11898-1:2015
// frame format; the counts and their sources are in link_budget.cpp).
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "drivers/protocol.hpp"
#include "drivers/serial_transport.hpp"

namespace imuemu::drivers {

inline constexpr double kLinkWarnLoadFraction = 0.70;    // warn strictly above
inline constexpr double kLinkRefuseLoadFraction = 1.00;  // refuse strictly above

enum class BudgetVerdict { ok, warn, refuse };
std::string to_string(BudgetVerdict verdict);  // "ok" | "warn" | "refuse"

struct LinkBudget {
  double load_fraction = 0.0;              // 1.0 = the line is busy all the time
  double bits_per_second_used = 0.0;       // UART: line bits/s; CAN: nominal-bit-time equivalents per second
  double capacity_bits_per_second = 0.0;   // UART: baud; CAN: nominal bit rate
  BudgetVerdict verdict = BudgetVerdict::ok;
  std::string message;                     // names the numbers, e.g. "uart 115200 8N1: 11521 B/s x 10 bit = ..."
  // UART of a stream encoder: every output at its maximum on every sample
  // (max_bytes_per_sample() x rate), beside the configured traffic the
  // verdict is on (a device whose driver may ask for more than its
  // power-up outputs).
  std::optional<double> worst_case_bytes_per_second;
  std::optional<double> worst_case_load_fraction;
};

// ---- UART ----

// 1 start + data bits + parity (0/1) + stop bits: 10 at 8N1, 11 at 8E1 / 8N2.
// Throws TransportError (drivers/transport.hpp) for invalid settings.
int uart_bits_per_byte(const SerialSettings& settings);
LinkBudget uart_budget(double bytes_per_second, const SerialSettings& settings);
// A stream encoder at `sample_rate_hz`: the verdict on what it is configured
// to send (configured_bytes_per_second), the worst case (every output,
// max_bytes_per_sample() x rate) beside it in the fields and the message.
LinkBudget uart_budget(const StreamEncoder& encoder, double sample_rate_hz, const SerialSettings& settings);

// ---- CAN ----

struct CanBitRates {
  double nominal_bit_rate = 500'000;   // arbitration phase (and everything of a classic frame)
  double data_bit_rate = 2'000'000;    // CAN FD data phase when the frame has BRS
};

// One kind of frame on the bus and how often it is sent.
struct CanTraffic {
  double frames_per_second = 0.0;
  bool extended = false;          // 29-bit identifier
  bool fd = false;                // CAN FD frame
  bool brs = false;               // CAN FD bit rate switch (data phase at data_bit_rate)
  std::size_t payload_bytes = 0;  // classic 0..8; FD 0..64, rounded up to the next DLC length
};

// The data field length a CAN FD frame really carries for `payload_bytes`:
// 0..8, then 12, 16, 20, 24, 32, 48, 64 (ISO 11898-1:2015 DLC table). Throws
// std::invalid_argument above 64.
std::size_t canfd_data_length(std::size_t payload_bytes);

// Worst-case bits of one frame (stuffing included), split by bit rate.
struct CanFrameBits {
  std::int64_t nominal_bits = 0;  // at the nominal bit rate
  std::int64_t data_bits = 0;     // at the data bit rate (CAN FD with BRS only)
  std::int64_t total() const { return nominal_bits + data_bits; }
};
// Throws std::invalid_argument naming the field (classic payload > 8, FD > 64,
// BRS without FD).
CanFrameBits can_frame_worst_case_bits(bool extended, bool fd, bool brs, std::size_t payload_bytes);

// Throws std::invalid_argument for non-positive bit rates or negative rates.
LinkBudget can_budget(std::span<const CanTraffic> traffic, const CanBitRates& rates);

// The traffic a CAN encoder really produces at `sample_rate_hz`: encodes one
// second of samples (zero motion, sample_counter 0.., t_ns on the rate's
// grid) with periodic() called once per sample as the emitter does, and
// groups the frames by (extended, fd, length). `fd_brs`: the transport's
// CANFD_BRS setting, applied to FD frames. Uses the encoder (it is advanced
// by one second): pass a fresh one.
std::vector<CanTraffic> measure_can_traffic(CanEncoder& encoder, double sample_rate_hz, bool fd_brs);

}  // namespace imuemu::drivers
