#include "drivers/link_budget.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <stdexcept>
#include <tuple>

#include "drivers/transport.hpp"

namespace imuemu::drivers {
namespace {

// Up to 10 significant digits: integers print exactly, without an exponent.
std::string number(double value) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "%.10g", value);
  return buffer;
}

std::string percent(double fraction) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "%.2f %%", fraction * 100.0);
  return buffer;
}

// The verdict from an exact comparison: `used` and `capacity` are both in the
// same unit (integer-valued doubles in every realistic case: bytes/s x bits,
// frames/s x bits x rates), so "exactly 70 %" (used * 10 == capacity * 7) is
// not warned and "exactly 100 %" is not refused, with no rounding of a
// quotient in between.
BudgetVerdict verdict_of(double used, double capacity) {
  if (used > capacity * kLinkRefuseLoadFraction) return BudgetVerdict::refuse;
  if (used * 10.0 > capacity * 7.0) return BudgetVerdict::warn;  // kLinkWarnLoadFraction = 7/10
  return BudgetVerdict::ok;
}

std::string verdict_text(BudgetVerdict verdict) {
  switch (verdict) {
    case BudgetVerdict::ok: return "ok";
    case BudgetVerdict::warn: return "warning: above 70 % of the capacity, little room for retries and jitter";
    case BudgetVerdict::refuse: return "refused: above 100 % of the capacity, the schedule cannot be kept";
  }
  return "";
}

void require_finite_non_negative(double value, const std::string& what) {
  if (!std::isfinite(value) || value < 0.0) {
    throw std::invalid_argument("link budget: " + what + " must be finite and >= 0, got " + number(value));
  }
}

}  // namespace

std::string to_string(BudgetVerdict verdict) {
  switch (verdict) {
    case BudgetVerdict::ok: return "ok";
    case BudgetVerdict::warn: return "warn";
    case BudgetVerdict::refuse: return "refuse";
  }
  return "?";
}

// ---- UART ----

// Asynchronous serial framing (each character: a start bit, the data bits
// LSB first, an optional parity bit, one or two stop bits; TIA-232 / the
// usual UART definition): 1 + 8 + 0 + 1 = 10 bits at 8N1, 11 at 8E1 / 8N2.
int uart_bits_per_byte(const SerialSettings& settings) {
  validate(settings);
  return 1 + settings.data_bits + (settings.parity == Parity::none ? 0 : 1) + settings.stop_bits;
}

LinkBudget uart_budget(double bytes_per_second, const SerialSettings& settings) {
  require_finite_non_negative(bytes_per_second, "bytes per second");
  const int bits_per_byte = uart_bits_per_byte(settings);
  LinkBudget budget;
  budget.capacity_bits_per_second = settings.baud;
  budget.bits_per_second_used = bytes_per_second * bits_per_byte;
  budget.load_fraction = budget.bits_per_second_used / budget.capacity_bits_per_second;
  budget.verdict = verdict_of(budget.bits_per_second_used, budget.capacity_bits_per_second);
  budget.message = "uart " + to_string(settings) + ": " + number(bytes_per_second) + " B/s x " +
                   std::to_string(bits_per_byte) + " bit/byte = " + number(budget.bits_per_second_used) +
                   " bit/s of " + number(budget.capacity_bits_per_second) + " bit/s (" +
                   percent(budget.load_fraction) + "): " + verdict_text(budget.verdict);
  return budget;
}

LinkBudget uart_budget(const StreamEncoder& encoder, double sample_rate_hz, const SerialSettings& settings) {
  require_finite_non_negative(sample_rate_hz, "sample rate");
  const double configured = encoder.configured_bytes_per_second(sample_rate_hz);
  const double max_bytes_per_sample = static_cast<double>(encoder.max_bytes_per_sample());
  LinkBudget budget = uart_budget(configured, settings);
  budget.worst_case_bytes_per_second = max_bytes_per_sample * sample_rate_hz;
  budget.worst_case_load_fraction =
      *budget.worst_case_bytes_per_second * uart_bits_per_byte(settings) / budget.capacity_bits_per_second;
  budget.message = encoder.name() + " at " + number(sample_rate_hz) + " Hz, outputs as configured: " +
                   budget.message + " (worst case, every output on every sample: " + number(max_bytes_per_sample) +
                   " B/sample = " + number(*budget.worst_case_bytes_per_second) + " B/s, " +
                   percent(*budget.worst_case_load_fraction) + ")";
  return budget;
}

// ---- CAN ----

// ISO 11898-1:2015 DLC 9..15 -> 12, 16, 20, 24, 32, 48, 64 data bytes (the
// same table in Linux's can_fd_dlc2len, include/linux/can/length.h).
std::size_t canfd_data_length(std::size_t payload_bytes) {
  if (payload_bytes <= 8) return payload_bytes;
  for (const std::size_t length : {12, 16, 20, 24, 32, 48, 64}) {
    if (payload_bytes <= length) return length;
  }
  throw std::invalid_argument("link budget: a CAN FD frame carries at most 64 bytes, got " +
                              std::to_string(payload_bytes));
}

CanFrameBits can_frame_worst_case_bits(bool extended, bool fd, bool brs, std::size_t payload_bytes) {
  CanFrameBits bits;
  if (!fd) {
    if (brs) throw std::invalid_argument("link budget: bit rate switch (BRS) needs a CAN FD frame");
    if (payload_bytes > 8) {
      throw std::invalid_argument("link budget: a classic CAN frame carries at most 8 bytes, got " +
                                  std::to_string(payload_bytes));
    }
    // Davis, Burns, Bril, Lukkien, "Controller Area Network (CAN)
    // schedulability analysis: refuted, revisited and revised", Real-Time
    // Systems 35 (2007), Eq. (1):
    //   C = (g + 8 s + 13 + floor((g + 8 s - 1) / 4)) tau_bit
    // g = 34 (11-bit id: SOF..DLC 19 + CRC 15) or 54 (29-bit: 39 + 15) bits
    // exposed to stuffing; 13 = CRC delimiter, ACK slot and delimiter, 7 EOF
    // and the 3-bit inter-frame space, never stuffed; in the worst case one
    // stuff bit follows the first 5 bits and then every 4 (the stuff bit
    // starts the next run), hence floor((n - 1) / 4).
    // 8 bytes: 135 bits (11-bit id), 160 bits (29-bit id).
    const auto g = static_cast<std::int64_t>(extended ? 54 : 34);
    const auto data = static_cast<std::int64_t>(8 * payload_bytes);
    bits.nominal_bits = g + data + 13 + (g + data - 1) / 4;
    return bits;
  }

  // CAN FD, ISO 11898-1:2015 frame format (FD base / FD extended format):
  //  SOF 1, base id 11, [SRR 1, IDE 1, id extension 18 (29-bit only)],
  //  RRS 1, [IDE 1 (11-bit only)], FDF 1, res 1, BRS 1   -> arbitration
  //  phase: 17 bits (11-bit id) or 36 bits (29-bit id), at the nominal rate;
  //  ESI 1, DLC 4, data 8 n (n rounded up to the DLC table) -> data phase
  //  when BRS: the bit rate switches at the BRS sample point and back at the
  //  CRC delimiter's.
  //  Dynamic stuffing covers SOF..end of the data field only (Vector
  //  e-learning "Bit stuffing for CAN FD",
  //  elearning.vector.com/mod/page/view.php?id=370); worst case as above,
  //  floor((L - 1) / 4) stuff bits for L stuffed bits.
  //  CRC field: stuff count 4 (3-bit Gray-coded count of dynamic stuff bits
  //  modulo 8 + parity; the ISO CRC field, see Microchip "ISO vs. non-ISO
  //  CRC"), CRC sequence 17 bits (n <= 16) or 21 bits (n > 16); fixed stuff
  //  bits: one before the stuff count and one after every 4 bits of the field
  //  (Vector, ibid.; CiA "CRC in CAN frames", www.canopen.org/en/can-knowledge/can/crc/),
  //  so 1 + (21 - 1) / 4 = 6 for 4 + 17 bits and 1 + (25 - 1) / 4 = 7 for
  //  4 + 21 bits.
  //  Then CRC delimiter 1, ACK slot 1, ACK delimiter 1, EOF 7, IFS 3 = 13,
  //  unstuffed, at the nominal rate.
  // With BRS, the BRS bit and the CRC delimiter (each partly in both phases)
  // and every dynamic stuff bit a worst-case arbitration field can hold are
  // charged at the nominal rate: an upper bound on the frame time.
  // 64 bytes, 11-bit id, no BRS: 17 + 5 + 512 + 133 + 32 + 13 = 712 bits.
  const std::size_t n = canfd_data_length(payload_bytes);
  const std::int64_t arbitration = extended ? 36 : 17;
  const std::int64_t control_data = 5 + 8 * static_cast<std::int64_t>(n);
  const std::int64_t stuffed = arbitration + control_data;
  const std::int64_t stuff_total = (stuffed - 1) / 4;
  const std::int64_t stuff_arbitration = (arbitration - 1) / 4;
  const std::int64_t crc_sequence = n <= 16 ? 17 : 21;
  const std::int64_t crc_field_unstuffed = 4 + crc_sequence;
  const std::int64_t crc_field = crc_field_unstuffed + 1 + (crc_field_unstuffed - 1) / 4;
  const std::int64_t trailer = 13;
  if (brs) {
    bits.nominal_bits = arbitration + stuff_arbitration + trailer;
    bits.data_bits = control_data + (stuff_total - stuff_arbitration) + crc_field;
  } else {
    bits.nominal_bits = stuffed + stuff_total + crc_field + trailer;
  }
  return bits;
}

LinkBudget can_budget(std::span<const CanTraffic> traffic, const CanBitRates& rates) {
  if (!std::isfinite(rates.nominal_bit_rate) || rates.nominal_bit_rate <= 0.0) {
    throw std::invalid_argument("link budget: CAN nominal bit rate must be > 0, got " +
                                number(rates.nominal_bit_rate));
  }
  bool any_brs = false;
  for (const CanTraffic& t : traffic) any_brs = any_brs || (t.fd && t.brs);
  if (any_brs && (!std::isfinite(rates.data_bit_rate) || rates.data_bit_rate <= 0.0)) {
    throw std::invalid_argument("link budget: CAN FD data bit rate must be > 0 for BRS frames, got " +
                                number(rates.data_bit_rate));
  }
  // Bus time per second, kept as an exact sum of integers where the inputs
  // are integers: sum f (Nn Rd + Nd Rn) against Rn Rd (Rd := 1 without BRS).
  const double rn = rates.nominal_bit_rate;
  const double rd = any_brs ? rates.data_bit_rate : 1.0;
  double used = 0.0;
  double frames = 0.0;
  std::int64_t longest_frame_nominal = 0, longest_frame_data = 0;
  for (const CanTraffic& t : traffic) {
    require_finite_non_negative(t.frames_per_second, "CAN frames per second");
    const CanFrameBits bits = can_frame_worst_case_bits(t.extended, t.fd, t.fd && t.brs, t.payload_bytes);
    used += t.frames_per_second *
            (static_cast<double>(bits.nominal_bits) * rd + static_cast<double>(bits.data_bits) * rn);
    frames += t.frames_per_second;
    if (bits.total() > longest_frame_nominal + longest_frame_data) {
      longest_frame_nominal = bits.nominal_bits;
      longest_frame_data = bits.data_bits;
    }
  }
  const double capacity = rn * rd;
  LinkBudget budget;
  budget.load_fraction = used / capacity;
  budget.capacity_bits_per_second = rn;
  budget.bits_per_second_used = used / rd;  // nominal bit times per second
  budget.verdict = verdict_of(used, capacity);
  std::string rate_text = number(rn) + " bit/s";
  if (any_brs) rate_text += " (data phase " + number(rates.data_bit_rate) + " bit/s)";
  budget.message = "can " + rate_text + ": " + number(frames) + " frames/s, worst case with bit stuffing " +
                   number(budget.bits_per_second_used) + " nominal bit times/s of " + number(rn) + " (" +
                   percent(budget.load_fraction) + "; longest frame " + std::to_string(longest_frame_nominal) +
                   " nominal" + (longest_frame_data > 0 ? " + " + std::to_string(longest_frame_data) + " data" : "") +
                   " bits): " + verdict_text(budget.verdict);
  return budget;
}

std::vector<CanTraffic> measure_can_traffic(CanEncoder& encoder, double sample_rate_hz, bool fd_brs) {
  if (!std::isfinite(sample_rate_hz) || sample_rate_hz <= 0.0) {
    throw std::invalid_argument("link budget: sample rate must be > 0, got " + number(sample_rate_hz));
  }
  // One second of samples on the rate's grid (at least one sample).
  const auto samples = static_cast<std::int64_t>(std::max(1.0, std::round(sample_rate_hz)));
  const double seconds = static_cast<double>(samples) / sample_rate_hz;
  const auto period_ns = static_cast<TimeNs>(std::llround(1e9 / sample_rate_hz));
  std::map<std::tuple<bool, bool, std::size_t>, std::int64_t> counts;  // (extended, fd, len) -> frames
  std::vector<CanFrame> frames;
  for (std::int64_t k = 0; k < samples; ++k) {
    ImuFrameInput sample;
    sample.sample_counter = static_cast<std::uint64_t>(k);
    sample.t_ns = k * period_ns;
    sample.period_ns = period_ns;
    sample.accel_m_s2 = Vec3(0.0, 0.0, -9.80665);  // at rest, FRD: specific force up
    frames.clear();
    encoder.periodic(sample.t_ns, frames);
    encoder.encode(sample, frames);
    for (const CanFrame& f : frames) ++counts[{f.extended, f.fd, f.len}];
  }
  std::vector<CanTraffic> traffic;
  for (const auto& [key, count] : counts) {
    CanTraffic t;
    t.extended = std::get<0>(key);
    t.fd = std::get<1>(key);
    t.brs = t.fd && fd_brs;
    t.payload_bytes = std::get<2>(key);
    t.frames_per_second = static_cast<double>(count) / seconds;
    traffic.push_back(t);
  }
  return traffic;
}

}  // namespace imuemu::drivers
