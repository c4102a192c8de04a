// SAE J1939 ARI / ACCS / SSI2 encoder and decoder. Layouts, scalings, axes
// and their sources are listed in j1939.hpp.
#include "drivers/protocols/j1939.hpp"

#include <cmath>
#include <numbers>
#include <stdexcept>

namespace imuemu::drivers::j1939 {

namespace {

constexpr std::uint32_t kExtendedIdMask = 0x1FFFFFFFu;
constexpr std::size_t kFrameBytes = 8;
constexpr double kDegPerRad = 180.0 / std::numbers::pi;
constexpr std::uint8_t kNotAvailableByte = 0xFF;
constexpr std::uint8_t kErrorIndicatorByte = 0xFE;
constexpr std::uint8_t kTwoBitsNotAvailable = 0x3;

// Body FRD quantities in the PGNs' vehicle axes (see j1939.hpp "Axes").
struct VehicleRates {
  double pitch_deg_s, roll_deg_s, yaw_deg_s;
};
struct VehicleAccel {
  double lateral_m_s2, longitudinal_m_s2, vertical_m_s2;
};

// ARI and SSI2 are Z-Down (J670) unless all-Z-Up was asked for; ACCS is Z-Up
// unless all-Z-Down was asked for (j1939.hpp "Axes and signs").
bool angular_z_down(VehicleAxes axes) { return axes != VehicleAxes::kIso8855ZUp; }
bool accel_z_up(VehicleAxes axes) { return axes != VehicleAxes::kSaeJ670eZDown; }

VehicleRates rates_in_vehicle_axes(const Vec3& gyro_frd_rad_s, VehicleAxes axes) {
  const Vec3 deg_s = gyro_frd_rad_s * kDegPerRad;
  if (angular_z_down(axes)) return {deg_s.y(), deg_s.x(), deg_s.z()};
  // Z-Up: rotation about y LEFT and z UP = minus rotation about y right / z down.
  return {-deg_s.y(), deg_s.x(), -deg_s.z()};
}

VehicleAccel accel_in_vehicle_axes(const Vec3& f_frd_m_s2, VehicleAxes axes) {
  if (!accel_z_up(axes)) return {f_frd_m_s2.y(), f_frd_m_s2.x(), f_frd_m_s2.z()};
  return {-f_frd_m_s2.y(), f_frd_m_s2.x(), -f_frd_m_s2.z()};
}

Vec3 gyro_from_vehicle_axes(double pitch_deg_s, double roll_deg_s, double yaw_deg_s, VehicleAxes axes) {
  const Vec3 deg_s = angular_z_down(axes) ? Vec3(roll_deg_s, pitch_deg_s, yaw_deg_s)
                                          : Vec3(roll_deg_s, -pitch_deg_s, -yaw_deg_s);
  return deg_s / kDegPerRad;
}

Vec3 accel_from_vehicle_axes(double lateral, double longitudinal, double vertical, VehicleAxes axes) {
  return !accel_z_up(axes) ? Vec3(longitudinal, lateral, vertical) : Vec3(longitudinal, -lateral, -vertical);
}

// SPN 4976 pitch angle: the aerospace pitch in Z-Down axes, its negative
// about y left in Z-Up axes. Its own inverse.
double pitch_in_vehicle_axes(double pitch_rad, VehicleAxes axes) {
  return angular_z_down(axes) ? pitch_rad : -pitch_rad;
}

void put_le(std::array<std::uint8_t, 64>& data, std::size_t at, std::uint32_t raw, unsigned bytes) {
  for (unsigned i = 0; i < bytes; ++i) data[at + i] = static_cast<std::uint8_t>(raw >> (8 * i));
}

std::uint32_t get_le(const std::array<std::uint8_t, 64>& data, std::size_t at, unsigned bytes) {
  std::uint32_t raw = 0;
  for (unsigned i = 0; i < bytes; ++i) raw |= std::uint32_t{data[at + i]} << (8 * i);
  return raw;
}

std::uint32_t error_indicator_raw(const Scaling& scaling) {
  return std::uint32_t{kErrorIndicatorByte} << (8 * (scaling.bytes - 1));
}

FigureOfMerit figure_of_merit(const Encoded& value, std::uint32_t sample_status) {
  if (value.error || (sample_status & kStatusFault) != 0) return FigureOfMerit::kError;
  if (value.clamped || (sample_status & (kStatusExtrapolated | kStatusSaturated)) != 0)
    return FigureOfMerit::kDegraded;
  return FigureOfMerit::kFullyFunctional;
}

std::uint8_t pack_two_bit_fields(unsigned a, unsigned b, unsigned c, unsigned d) {
  return static_cast<std::uint8_t>((a & 3u) | (b & 3u) << 2 | (c & 3u) << 4 | (d & 3u) << 6);
}

CanFrame new_frame(const J1939Options& options, std::uint32_t pgn) {
  CanFrame frame;
  frame.id = can_id(options.priority, pgn, options.source_address);
  frame.extended = true;
  frame.len = kFrameBytes;
  return frame;
}

std::uint8_t latency_byte(const J1939Options& options) {
  if (!options.measurement_latency_ms) return kNotAvailableByte;
  return static_cast<std::uint8_t>(encode_value(*options.measurement_latency_ms, kLatencyScaling).raw);
}

// A received value: what it means, per J1939-71's parameter ranges.
enum class RawKind : std::uint8_t { kValid, kNotAvailable, kError, kReserved };
RawKind classify(std::uint32_t raw, const Scaling& scaling) {
  if (raw <= scaling.max_valid_raw) return RawKind::kValid;
  const std::uint32_t most_significant = raw >> (8 * (scaling.bytes - 1));
  if (most_significant == kNotAvailableByte) return RawKind::kNotAvailable;
  if (most_significant == kErrorIndicatorByte) return RawKind::kError;
  return RawKind::kReserved;
}

// One decoded value and the status bits its code and figure of merit imply.
struct Received {
  double value = 0.0;          // 0 when not available / error
  std::uint32_t status = 0;
};
Received receive(std::uint32_t raw, unsigned figure_of_merit, const Scaling& scaling) {
  Received out;
  switch (classify(raw, scaling)) {
    case RawKind::kValid:
      out.value = static_cast<double>(raw) * scaling.resolution + scaling.offset;
      break;
    case RawKind::kError:
      out.status |= kStatusFault;
      break;
    case RawKind::kNotAvailable:
    case RawKind::kReserved:  // the caller rejects the frame before using this
      break;
  }
  switch (static_cast<FigureOfMerit>(figure_of_merit & 3u)) {
    case FigureOfMerit::kError:
      out.status |= kStatusFault;
      break;
    case FigureOfMerit::kDegraded:
      // A value clamped by the encoder sits exactly at an end of the range.
      out.status |= (raw == 0 || raw == scaling.max_valid_raw) ? kStatusSaturated : kStatusExtrapolated;
      break;
    case FigureOfMerit::kFullyFunctional:
    case FigureOfMerit::kNotAvailable:
      break;
  }
  return out;
}

}  // namespace

std::uint32_t can_id(std::uint8_t priority, std::uint32_t pgn, std::uint8_t source_address) {
  return (std::uint32_t{priority} & 0x7u) << 26 | (pgn & 0x3FFFFu) << 8 | source_address;
}

IdFields parse_can_id(std::uint32_t id) {
  id &= kExtendedIdMask;
  IdFields fields{};
  fields.priority = static_cast<std::uint8_t>((id >> 26) & 0x7u);
  fields.source_address = static_cast<std::uint8_t>(id & 0xFFu);
  std::uint32_t pgn = (id >> 8) & 0x3FFFFu;
  const std::uint32_t pdu_format = (pgn >> 8) & 0xFFu;
  if (pdu_format < 240) pgn &= ~0xFFu;  // PDU1: PS is the destination address, not part of the PGN
  fields.pgn = pgn;
  return fields;
}

Encoded encode_value(double value, const Scaling& scaling) {
  Encoded out;
  if (!std::isfinite(value)) {
    out.raw = error_indicator_raw(scaling);
    out.error = true;
    return out;
  }
  const double steps = std::round((value - scaling.offset) / scaling.resolution);
  const auto max_raw = static_cast<double>(scaling.max_valid_raw);
  if (steps < 0.0) {
    out.raw = 0;
    out.clamped = true;
  } else if (steps > max_raw) {
    out.raw = scaling.max_valid_raw;
    out.clamped = true;
  } else {
    out.raw = static_cast<std::uint32_t>(steps);
  }
  return out;
}

std::uint32_t not_available_raw(const Scaling& scaling) {
  return scaling.bytes >= 4 ? 0xFFFFFFFFu : (std::uint32_t{1} << (8 * scaling.bytes)) - 1;
}

void validate(const J1939Options& options) {
  if (options.source_address > 253)
    throw std::invalid_argument("j1939: source_address must be 0..253 (254 is the null address, 255 global), got " +
                                std::to_string(options.source_address));
  if (options.priority > 7)
    throw std::invalid_argument("j1939: priority must be 0..7 (3-bit CAN id field), got " +
                                std::to_string(options.priority));
  if (options.measurement_latency_ms &&
      !(*options.measurement_latency_ms >= 0.0 && *options.measurement_latency_ms <= kLatencyScaling.max_value()))
    throw std::invalid_argument("j1939: measurement_latency_ms must be 0..125 ms (0.5 ms/bit, 1 byte), got " +
                                std::to_string(*options.measurement_latency_ms));
  if (!options.send_angular_rate && !options.send_acceleration && !options.send_slope)
    throw std::invalid_argument("j1939: at least one of send_angular_rate, send_acceleration, send_slope must be set");
}

// ---- encoder ----

J1939Encoder::J1939Encoder(const J1939Options& options) : options_(options) {
  validate(options_);
  shared_->address.store(options_.source_address, std::memory_order_relaxed);
  node_ = std::make_unique<J1939Node>(options_, *shared_);
}

void J1939Encoder::encode(const ImuFrameInput& sample, std::vector<CanFrame>& out) {
  // The address its node holds now (address-claim arbitration, issue 27); a
  // node that could not claim one sends nothing (J1939-81).
  const std::uint8_t address = shared_->address.load(std::memory_order_relaxed);
  if (address == kNullAddress) return;
  const std::size_t first = out.size();
  encode_frames(sample, out);
  if (address != options_.source_address)
    for (std::size_t i = first; i < out.size(); ++i) out[i].id = (out[i].id & ~0xFFu) | address;
}

void J1939Encoder::encode_frames(const ImuFrameInput& sample, std::vector<CanFrame>& out) {
  auto count = [this](const Encoded& e) {
    if (e.clamped) ++clamped_values_;
  };
  if (options_.send_angular_rate) {
    const VehicleRates rates = rates_in_vehicle_axes(sample.gyro_rad_s, options_.axes);
    const Encoded pitch = encode_value(rates.pitch_deg_s, kAngularRateScaling);
    const Encoded roll = encode_value(rates.roll_deg_s, kAngularRateScaling);
    const Encoded yaw = encode_value(rates.yaw_deg_s, kAngularRateScaling);
    count(pitch);
    count(roll);
    count(yaw);
    CanFrame frame = new_frame(options_, kPgnAngularRateInformation);
    put_le(frame.data, 0, pitch.raw, 2);
    put_le(frame.data, 2, roll.raw, 2);
    put_le(frame.data, 4, yaw.raw, 2);
    frame.data[6] = pack_two_bit_fields(static_cast<unsigned>(figure_of_merit(pitch, sample.status)),
                                        static_cast<unsigned>(figure_of_merit(roll, sample.status)),
                                        static_cast<unsigned>(figure_of_merit(yaw, sample.status)),
                                        kTwoBitsNotAvailable);
    frame.data[7] = latency_byte(options_);
    out.push_back(frame);
  }
  if (options_.send_acceleration) {
    const VehicleAccel accel = accel_in_vehicle_axes(sample.accel_m_s2, options_.axes);
    const Encoded lateral = encode_value(accel.lateral_m_s2, kAccelerationScaling);
    const Encoded longitudinal = encode_value(accel.longitudinal_m_s2, kAccelerationScaling);
    const Encoded vertical = encode_value(accel.vertical_m_s2, kAccelerationScaling);
    count(lateral);
    count(longitudinal);
    count(vertical);
    CanFrame frame = new_frame(options_, kPgnAccelerationSensor);
    put_le(frame.data, 0, lateral.raw, 2);
    put_le(frame.data, 2, longitudinal.raw, 2);
    put_le(frame.data, 4, vertical.raw, 2);
    frame.data[6] = pack_two_bit_fields(static_cast<unsigned>(figure_of_merit(lateral, sample.status)),
                                        static_cast<unsigned>(figure_of_merit(longitudinal, sample.status)),
                                        static_cast<unsigned>(figure_of_merit(vertical, sample.status)),
                                        kTwoBitsNotAvailable);  // variable repetition rate support: n/a
    frame.data[7] = kNotAvailableByte;                          // not defined
    out.push_back(frame);
  }
  if (options_.send_slope) {
    CanFrame frame = new_frame(options_, kPgnSlopeSensorInformation2);
    if (sample.has_level_attitude) {
      const Encoded pitch =
          encode_value(pitch_in_vehicle_axes(sample.pitch_rad, options_.axes) * kDegPerRad, kSlopeAngleScaling);
      const Encoded roll = encode_value(sample.roll_rad * kDegPerRad, kSlopeAngleScaling);
      count(pitch);
      count(roll);
      // SPN 4978 / 4980 "Compensation is the use of multiple sensors together
      // to enhance the output": the emulated angles are the true attitude,
      // free of the linear-acceleration error of a bare inclinometer: On.
      constexpr unsigned kCompensationOn = 0;  // J1939DA: 00b = On, 01b = Off
      put_le(frame.data, 0, pitch.raw, 3);
      put_le(frame.data, 3, roll.raw, 3);
      frame.data[6] = pack_two_bit_fields(kCompensationOn, static_cast<unsigned>(figure_of_merit(pitch, sample.status)),
                                          kCompensationOn, static_cast<unsigned>(figure_of_merit(roll, sample.status)));
    } else {
      put_le(frame.data, 0, not_available_raw(kSlopeAngleScaling), 3);
      put_le(frame.data, 3, not_available_raw(kSlopeAngleScaling), 3);
      frame.data[6] = 0xFF;  // compensation and figures of merit: not available
    }
    frame.data[7] = latency_byte(options_);
    out.push_back(frame);
  }
}

void J1939Encoder::restart(TimeNs now_ns, std::vector<CanFrame>& out) {
  (void)now_ns;
  CanFrame frame;
  frame.id = can_id(kAddressClaimedPriority, kPgnAddressClaimed | kGlobalAddress,
                    shared_->address.load(std::memory_order_relaxed));
  frame.extended = true;
  frame.len = kFrameBytes;
  for (unsigned i = 0; i < kFrameBytes; ++i) frame.data[i] = static_cast<std::uint8_t>(options_.name >> (8 * i));
  out.push_back(frame);
}

// ---- decoder ----

J1939Decoder::J1939Decoder(const J1939Options& options) : options_(options) {}

std::optional<J1939Decoder::Slope> J1939Decoder::last_slope(std::uint8_t source_address) const {
  const auto it = slope_.find(source_address);
  if (it == slope_.end()) return std::nullopt;
  return it->second;
}

void J1939Decoder::emit(DecodedSample& sample, const SampleCallback& on_sample) {
  ++counters_.samples;
  if (on_sample) on_sample(sample);
  sample = DecodedSample{};
}

void J1939Decoder::feed(const CanFrame& frame, const SampleCallback& on_sample) {
  if (!frame.extended || frame.fd || frame.len != kFrameBytes) {
    ++detail_.not_j1939_frame;
    ++counters_.other_errors;
    return;
  }
  const IdFields id = parse_can_id(frame.id);
  const std::uint8_t status_bits = frame.data[6];
  auto two_bits = [status_bits](unsigned field) { return (status_bits >> (2 * field)) & 3u; };
  auto reject_reserved = [this]() {
    ++detail_.reserved_value;
    ++counters_.other_errors;
  };

  if (id.pgn == kPgnAngularRateInformation || id.pgn == kPgnAccelerationSensor) {
    const Scaling& scaling = id.pgn == kPgnAngularRateInformation ? kAngularRateScaling : kAccelerationScaling;
    std::array<std::uint32_t, 3> raw{};
    for (unsigned i = 0; i < 3; ++i) {
      raw[i] = get_le(frame.data, 2 * i, 2);
      if (classify(raw[i], scaling) == RawKind::kReserved) {
        reject_reserved();
        return;
      }
    }
    std::array<Received, 3> value{};
    std::uint32_t status = 0;
    for (unsigned i = 0; i < 3; ++i) {
      value[i] = receive(raw[i], two_bits(i), scaling);
      status |= value[i].status;
    }
    ++counters_.frames;
    Pending& pending = pending_[id.source_address];
    if (id.pgn == kPgnAngularRateInformation) {
      if (pending.has_rates) emit(pending.sample, on_sample);  // the previous ARI found no ACCS
      pending.has_rates = true;
      pending.sample.gyro_rad_s = gyro_from_vehicle_axes(value[0].value, value[1].value, value[2].value, options_.axes);
      pending.sample.status = status;
      return;
    }
    pending.sample.accel_m_s2 = accel_from_vehicle_axes(value[0].value, value[1].value, value[2].value, options_.axes);
    pending.sample.status |= status;
    pending.has_rates = false;
    emit(pending.sample, on_sample);
    return;
  }

  if (id.pgn == kPgnSlopeSensorInformation2) {
    const std::uint32_t pitch_raw = get_le(frame.data, 0, 3);
    const std::uint32_t roll_raw = get_le(frame.data, 3, 3);
    const RawKind pitch_kind = classify(pitch_raw, kSlopeAngleScaling);
    const RawKind roll_kind = classify(roll_raw, kSlopeAngleScaling);
    if (pitch_kind == RawKind::kReserved || roll_kind == RawKind::kReserved) {
      reject_reserved();
      return;
    }
    const Received pitch = receive(pitch_raw, two_bits(1), kSlopeAngleScaling);
    const Received roll = receive(roll_raw, two_bits(3), kSlopeAngleScaling);
    Slope slope;
    slope.fault = ((pitch.status | roll.status) & kStatusFault) != 0;
    if (pitch_kind == RawKind::kValid && roll_kind == RawKind::kValid) {
      slope.angles = PitchRoll{pitch_in_vehicle_axes(pitch.value / kDegPerRad, options_.axes), roll.value / kDegPerRad};
    }
    slope_[id.source_address] = slope;
    ++counters_.frames;
    return;
  }

  if (id.pgn == kPgnAddressClaimed) {
    std::uint64_t name = 0;
    for (unsigned i = 0; i < kFrameBytes; ++i) name |= std::uint64_t{frame.data[i]} << (8 * i);
    claimed_names_[id.source_address] = name;
    ++counters_.frames;
    return;
  }

  ++detail_.unknown_pgn;
  ++counters_.other_errors;
}

std::optional<std::uint64_t> J1939Decoder::claimed_name(std::uint8_t source_address) const {
  const auto it = claimed_names_.find(source_address);
  if (it == claimed_names_.end()) return std::nullopt;
  return it->second;
}

// ---- node (request side) ----

namespace {
constexpr std::uint32_t kPgnFieldMask = 0x03FF0000u;    // EDP, DP, PF of a 29-bit id
constexpr std::uint32_t kPdu1Mask = 0x03FFFF00u;        // ... and PS (the destination of a PDU1 PGN)
constexpr std::uint8_t kFirstArbitraryAddress = 128;    // J1939 table B2: 128..247 self-configurable
constexpr std::uint8_t kLastArbitraryAddress = 247;

std::vector<std::uint8_t> ascii_fields(const std::vector<std::string>& fields) {
  std::vector<std::uint8_t> out;
  for (const std::string& f : fields) {
    out.insert(out.end(), f.begin(), f.end());
    out.push_back('*');
  }
  return out;
}
}  // namespace

J1939Node::J1939Node(const J1939Options& options, NodeShared& shared) : options_(options), shared_(shared) {}

std::vector<std::uint8_t> J1939Node::component_identification(const J1939Options& o) {
  return ascii_fields({o.make, o.model, o.serial_number, o.unit_number});
}

std::vector<std::uint8_t> J1939Node::software_identification(const J1939Options& o) {
  std::vector<std::uint8_t> out{static_cast<std::uint8_t>(o.software_ids.size())};
  const std::vector<std::uint8_t> fields = ascii_fields(o.software_ids);
  out.insert(out.end(), fields.begin(), fields.end());
  return out;
}

std::vector<CanReceiveFilter> J1939Node::receive_filters() const {
  std::vector<CanReceiveFilter> f;
  if ((options_.name >> 63) != 0) {
    // Arbitrary-address capable: the address may move, so take Requests to
    // any destination (on_frame keeps those to its address and global).
    f.push_back({kPgnRequest << 8, kPgnFieldMask, true});
  } else {
    f.push_back({(kPgnRequest | options_.source_address) << 8, kPdu1Mask, true});
    f.push_back({(kPgnRequest | kGlobalAddress) << 8, kPdu1Mask, true});
  }
  f.push_back({kPgnAddressClaimed << 8, kPgnFieldMask, true});  // claims of others (to global or to it)
  return f;
}

void J1939Node::set_log(std::function<void(std::string_view)> log) {
  const std::lock_guard<std::mutex> lock(log_mutex_);
  log_ = std::move(log);
}

void J1939Node::log(const std::string& line) {
  const std::lock_guard<std::mutex> lock(log_mutex_);
  if (log_) log_(line);
}

CommandCounters J1939Node::command_counters() const {
  CommandCounters c;
  c.received = received_.load(std::memory_order_relaxed);
  c.answered = answered_.load(std::memory_order_relaxed);
  c.nacked = nacked_.load(std::memory_order_relaxed);
  c.not_command_bytes = bad_bytes_.load(std::memory_order_relaxed);
  c.replies_dropped = dropped_.load(std::memory_order_relaxed);
  const std::uint8_t a = shared_.address.load(std::memory_order_relaxed);
  c.mode = a == kNullAddress ? "cannot claim an address (silent)" : "streaming from address " + std::to_string(a);
  c.format = "ARI/ACCS/SSI2 PGNs";
  return c;
}

bool J1939Node::send(const CanFrame& frame, CanReplySink& replies) {
  if (replies.reply(frame)) return true;
  dropped_.fetch_add(1, std::memory_order_relaxed);
  return false;
}

bool J1939Node::send_claim(std::uint8_t source, CanReplySink& replies) {
  CanFrame frame;
  frame.id = can_id(kAddressClaimedPriority, kPgnAddressClaimed | kGlobalAddress, source);
  frame.extended = true;
  frame.len = kFrameBytes;
  for (unsigned i = 0; i < kFrameBytes; ++i) frame.data[i] = static_cast<std::uint8_t>(options_.name >> (8 * i));
  return send(frame, replies);
}

bool J1939Node::send_pgn(std::uint32_t pgn, const std::vector<std::uint8_t>& data, CanReplySink& replies) {
  const std::uint8_t source = shared_.address.load(std::memory_order_relaxed);
  if (data.size() <= kFrameBytes) {
    CanFrame frame;
    frame.id = can_id(kIdentificationPriority, pgn, source);
    frame.extended = true;
    frame.len = static_cast<std::uint8_t>(data.size());
    std::copy(data.begin(), data.end(), frame.data.begin());
    return send(frame, replies);
  }
  // BAM (J1939-21 5.10.3.5): TP.CM to global announces size, packets and
  // PGN; TP.DT packets 1..n carry 7 bytes each, the last padded with 0xFF.
  const std::size_t packets = (data.size() + 6) / 7;
  CanFrame cm;
  cm.id = can_id(kTpPriority, kPgnTpCm | kGlobalAddress, source);
  cm.extended = true;
  cm.len = kFrameBytes;
  cm.data = {kTpCmBam, static_cast<std::uint8_t>(data.size() & 0xFF), static_cast<std::uint8_t>(data.size() >> 8),
             static_cast<std::uint8_t>(packets), 0xFF, static_cast<std::uint8_t>(pgn & 0xFF),
             static_cast<std::uint8_t>((pgn >> 8) & 0xFF), static_cast<std::uint8_t>((pgn >> 16) & 0xFF)};
  if (!send(cm, replies)) return false;
  for (std::size_t p = 0; p < packets; ++p) {
    CanFrame dt;
    dt.id = can_id(kTpPriority, kPgnTpDt | kGlobalAddress, source);
    dt.extended = true;
    dt.len = kFrameBytes;
    dt.data.fill(0xFF);
    dt.data[0] = static_cast<std::uint8_t>(p + 1);
    for (std::size_t i = 0; i < 7 && 7 * p + i < data.size(); ++i) dt.data[1 + i] = data[7 * p + i];
    if (!send(dt, replies)) return false;
  }
  return true;
}

void J1939Node::on_frame(const CanFrame& frame, CanReplySink& replies) {
  if (!frame.extended || frame.fd) {
    bad_bytes_.fetch_add(frame.len, std::memory_order_relaxed);
    return;
  }
  const std::uint32_t id = frame.id & 0x1FFFFFFFu;
  const auto pf = static_cast<std::uint8_t>((id >> 16) & 0xFF);
  const auto ps = static_cast<std::uint8_t>((id >> 8) & 0xFF);
  const auto sa = static_cast<std::uint8_t>(id & 0xFF);
  const bool dp_edp_zero = ((id >> 24) & 0x3u) == 0;
  const std::uint8_t address = shared_.address.load(std::memory_order_relaxed);

  if (dp_edp_zero && pf == (kPgnAddressClaimed >> 8)) {
    if (frame.len != kFrameBytes || sa == kNullAddress || sa == kGlobalAddress) return;
    std::uint64_t theirs = 0;
    for (unsigned i = 0; i < kFrameBytes; ++i) theirs |= std::uint64_t{frame.data[i]} << (8 * i);
    others_[sa] = theirs;
    if (sa != address || theirs == options_.name) return;
    received_.fetch_add(1, std::memory_order_relaxed);
    if (theirs > options_.name) {
      // Ours is the higher priority (lower NAME): claim again (J1939-81 4.5.3).
      if (send_claim(address, replies)) answered_.fetch_add(1, std::memory_order_relaxed);
      return;
    }
    // Lost the address to a lower NAME.
    if ((options_.name >> 63) != 0) {
      for (unsigned a = kFirstArbitraryAddress; a <= kLastArbitraryAddress; ++a) {
        const auto candidate = static_cast<std::uint8_t>(a);
        if (candidate == address) continue;
        const auto other = others_.find(candidate);
        if (other != others_.end() && other->second < options_.name) continue;
        shared_.address.store(candidate, std::memory_order_relaxed);
        log("j1939: address " + std::to_string(address) + " lost to a lower NAME; claiming " + std::to_string(a));
        if (send_claim(candidate, replies)) answered_.fetch_add(1, std::memory_order_relaxed);
        return;
      }
    }
    shared_.address.store(kNullAddress, std::memory_order_relaxed);
    log("j1939: address " + std::to_string(address) + " lost to a lower NAME; Cannot Claim, silent from now on");
    if (send_claim(kNullAddress, replies)) answered_.fetch_add(1, std::memory_order_relaxed);
    return;
  }

  if (dp_edp_zero && pf == (kPgnRequest >> 8)) {
    const bool to_me = address != kNullAddress && ps == address;
    if (!to_me && ps != kGlobalAddress) return;  // another node's request (arbitrary-address filters)
    if (frame.len < 3) {
      bad_bytes_.fetch_add(frame.len, std::memory_order_relaxed);
      return;
    }
    received_.fetch_add(1, std::memory_order_relaxed);
    const std::uint32_t pgn = frame.data[0] | frame.data[1] << 8 | std::uint32_t{frame.data[2]} << 16;
    bool sent = false;
    if (pgn == kPgnAddressClaimed) {
      sent = send_claim(address, replies);  // from 254 = Cannot Claim
    } else if (address == kNullAddress) {
      return;  // without an address, only Cannot Claim may be sent
    } else if (pgn == kPgnComponentIdentification) {
      sent = send_pgn(pgn, component_identification(options_), replies);
    } else if (pgn == kPgnSoftwareIdentification) {
      sent = send_pgn(pgn, software_identification(options_), replies);
    } else if (to_me) {
      // J1939-21 5.4.4: NACK a destination-specific request for a PGN not supported.
      CanFrame ack;
      ack.id = can_id(kIdentificationPriority, kPgnAcknowledgement | kGlobalAddress, address);
      ack.extended = true;
      ack.len = kFrameBytes;
      ack.data = {1, 0xFF, 0xFF, 0xFF, sa, frame.data[0], frame.data[1], frame.data[2]};
      if (send(ack, replies)) nacked_.fetch_add(1, std::memory_order_relaxed);
      return;
    } else {
      return;  // a global request for a PGN it does not have: no answer (J1939-21)
    }
    if (sent) answered_.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  bad_bytes_.fetch_add(frame.len, std::memory_order_relaxed);
}

}  // namespace imuemu::drivers::j1939
