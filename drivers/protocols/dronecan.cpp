// DroneCAN RawIMU + NodeStatus encoder and decoder. The specification facts
// this file implements are listed, with their sources, in dronecan.hpp.
#include "drivers/protocols/dronecan.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "core/time_arith.hpp"

namespace imuemu::drivers::dronecan {

namespace {

constexpr std::uint32_t kExtendedIdMask = 0x1FFFFFFFu;
constexpr std::size_t kClassicCanBytes = 8;
constexpr std::size_t kFramePayloadBytes = kClassicCanBytes - 1;  // the last byte is the tail byte
constexpr float kFloat16Max = 65504.0f;                          // IEEE754Limits<16>::max in libuavcan
constexpr std::uint8_t kTransferIdMask = 0x1F;                   // 5-bit transfer id
constexpr std::uint8_t kTailStart = 0x80;
constexpr std::uint8_t kTailEnd = 0x40;
constexpr std::uint8_t kTailToggle = 0x20;
// RawIMU with a full covariance: 47 bytes + 36 float16 (tail array, no length).
constexpr std::size_t kRawImuMaxPayloadBytes = kRawImuPayloadBytes + 2 * kRawImuMaxCovariance;
// The largest payload this file serialises: a GetNodeInfo response with an
// 80-byte name (7 + 15 + 18 + 1 + 80 = 121 bytes) or RawIMU's 119.
constexpr std::size_t kMaxPayloadBytes = 128;

// DSDL bit-level serialisation as libcanard's canardEncodeScalar does it: the
// value's little-endian bytes, the bits of a trailing partial byte moved to
// the top of that byte, copied into the stream most significant bit first.
// Into a fixed buffer (the largest payload here, RawIMU with a full
// covariance): the encoder runs on the emission thread, which never
// allocates.
class BitWriter {
 public:
  void put(std::uint64_t value, unsigned bit_length) {
    if (bit_length < 64) value &= (std::uint64_t{1} << bit_length) - 1;
    std::uint8_t le[8];
    for (unsigned i = 0; i < 8; ++i) le[i] = static_cast<std::uint8_t>(value >> (8 * i));
    if (bit_length % 8 != 0)
      le[bit_length / 8] = static_cast<std::uint8_t>(le[bit_length / 8] << (8 - bit_length % 8));
    for (unsigned i = 0; i < bit_length; ++i) put_bit(((le[i / 8] >> (7 - i % 8)) & 1u) != 0);
  }
  void put_float32(float value) { put(std::bit_cast<std::uint32_t>(value), 32); }
  std::span<const std::uint8_t> bytes() const { return {bytes_.data(), (bit_count_ + 7) / 8}; }

 private:
  void put_bit(bool bit) {
    if (bit_count_ >= bytes_.size() * 8) return;  // never: every message here fits
    if (bit_count_ % 8 == 0) bytes_[bit_count_ / 8] = 0;
    if (bit) bytes_[bit_count_ / 8] = static_cast<std::uint8_t>(bytes_[bit_count_ / 8] | (0x80u >> (bit_count_ % 8)));
    ++bit_count_;
  }
  std::array<std::uint8_t, kMaxPayloadBytes> bytes_{};
  std::size_t bit_count_ = 0;
};

// The inverse (libcanard canardDecodeScalar, unsigned).
class BitReader {
 public:
  explicit BitReader(std::span<const std::uint8_t> bytes) : bytes_(bytes) {}
  bool has(unsigned bit_length) const { return bit_offset_ + bit_length <= bytes_.size() * 8; }
  std::uint64_t get(unsigned bit_length) {
    std::uint8_t le[8] = {0, 0, 0, 0, 0, 0, 0, 0};
    for (unsigned i = 0; i < bit_length; ++i, ++bit_offset_) {
      const bool bit = ((bytes_[bit_offset_ / 8] >> (7 - bit_offset_ % 8)) & 1u) != 0;
      if (bit) le[i / 8] = static_cast<std::uint8_t>(le[i / 8] | (0x80u >> (i % 8)));
    }
    if (bit_length % 8 != 0)
      le[bit_length / 8] = static_cast<std::uint8_t>(le[bit_length / 8] >> (8 - bit_length % 8));
    std::uint64_t value = 0;
    for (unsigned i = 0; i < 8; ++i) value |= std::uint64_t{le[i]} << (8 * i);
    return value;
  }
  float get_float32() { return std::bit_cast<float>(static_cast<std::uint32_t>(get(32))); }

 private:
  std::span<const std::uint8_t> bytes_;
  std::size_t bit_offset_ = 0;
};

// A DSDL "saturated float32" field from a double: libuavcan's float32 is the
// native float (exact representation, no clamp of its own), so the only
// clipping is the double -> float range.
float float32_saturated(double value, WireClip& clip) {
  clip = WireClip::kExact;
  if (!std::isfinite(value)) {
    clip = WireClip::kNotFinite;
    return 0.0f;
  }
  constexpr double kMax = std::numeric_limits<float>::max();
  if (value > kMax || value < -kMax) {
    clip = WireClip::kSaturated;
    return static_cast<float>(std::clamp(value, -kMax, kMax));
  }
  return static_cast<float>(value);
}

void append_transfer(std::vector<CanFrame>& out, std::uint32_t can_id, std::uint64_t signature,
                     std::span<const std::uint8_t> payload, std::uint8_t transfer_id) {
  const auto tid = static_cast<std::uint8_t>(transfer_id & kTransferIdMask);
  if (payload.size() <= kFramePayloadBytes) {  // single-frame transfer: no CRC
    CanFrame frame;
    frame.id = can_id;
    frame.extended = true;
    std::copy(payload.begin(), payload.end(), frame.data.begin());
    frame.data[payload.size()] = static_cast<std::uint8_t>(kTailStart | kTailEnd | tid);
    frame.len = static_cast<std::uint8_t>(payload.size() + 1);
    out.push_back(frame);
    return;
  }
  const std::uint16_t crc = transfer_crc(signature, payload);
  // CRC little-endian in the first frame, then the payload (a fixed buffer:
  // no allocation on the emission thread).
  std::array<std::uint8_t, 2 + kMaxPayloadBytes> buffer{};
  const std::size_t stream_bytes = std::min(buffer.size(), payload.size() + 2);
  buffer[0] = static_cast<std::uint8_t>(crc & 0xFF);
  buffer[1] = static_cast<std::uint8_t>(crc >> 8);
  std::copy_n(payload.begin(), stream_bytes - 2, buffer.begin() + 2);
  const std::span<const std::uint8_t> stream(buffer.data(), stream_bytes);
  bool toggle = false;  // DroneCAN (v0): 0 in the first frame
  for (std::size_t offset = 0; offset < stream.size();) {
    const std::size_t n = std::min(kFramePayloadBytes, stream.size() - offset);
    CanFrame frame;
    frame.id = can_id;
    frame.extended = true;
    std::copy_n(stream.begin() + static_cast<std::ptrdiff_t>(offset), n, frame.data.begin());
    std::uint8_t tail = tid;
    if (offset == 0) tail = static_cast<std::uint8_t>(tail | kTailStart);
    if (offset + n == stream.size()) tail = static_cast<std::uint8_t>(tail | kTailEnd);
    if (toggle) tail = static_cast<std::uint8_t>(tail | kTailToggle);
    frame.data[n] = tail;
    frame.len = static_cast<std::uint8_t>(n + 1);
    out.push_back(frame);
    toggle = !toggle;
    offset += n;
  }
}

std::uint64_t signature_of(std::uint16_t data_type_id, bool& known) {
  known = true;
  if (data_type_id == kRawImuDataTypeId) return kRawImuSignature;
  if (data_type_id == kNodeStatusDataTypeId) return kNodeStatusSignature;
  known = false;
  return 0;
}

std::size_t max_payload_of(std::uint16_t data_type_id) {
  return data_type_id == kRawImuDataTypeId ? kRawImuMaxPayloadBytes : kNodeStatusPayloadBytes;
}

}  // namespace

// ---- wire helpers ----

std::uint16_t crc16_ccitt_false(std::uint16_t crc, std::span<const std::uint8_t> bytes) {
  for (std::uint8_t byte : bytes) {
    crc = static_cast<std::uint16_t>(crc ^ (std::uint16_t{byte} << 8));
    for (int bit = 0; bit < 8; ++bit)
      crc = (crc & 0x8000u) != 0 ? static_cast<std::uint16_t>((crc << 1) ^ 0x1021u)
                                 : static_cast<std::uint16_t>(crc << 1);
  }
  return crc;
}

std::uint16_t transfer_crc(std::uint64_t data_type_signature, std::span<const std::uint8_t> payload) {
  std::uint8_t signature_le[8];
  for (unsigned i = 0; i < 8; ++i) signature_le[i] = static_cast<std::uint8_t>(data_type_signature >> (8 * i));
  return crc16_ccitt_false(crc16_ccitt_false(0xFFFF, signature_le), payload);
}

std::uint32_t message_can_id(std::uint8_t priority, std::uint16_t data_type_id, std::uint8_t source_node_id) {
  return (std::uint32_t{priority} & 0x1Fu) << 24 | std::uint32_t{data_type_id} << 8 |
         (std::uint32_t{source_node_id} & 0x7Fu);  // bit 7 service_not_message = 0
}

std::uint16_t float16_bits_libuavcan(float value) {
  // The arithmetic of libuavcan's nativeNonIeeeToHalf: scale the magnitude so
  // that its integer part is the half's significand (with the implicit bit
  // for normals, in units of 2^-24 for subnormals), truncate, then add one if
  // the dropped fraction is >= 0.5. The carry of that +1 runs into the
  // exponent field, so rounding up past 0x3FF moves to the next binade and
  // past 65504 reaches 0x7C00 (infinity).
  std::uint16_t bits = std::signbit(value) ? 0x8000 : 0;
  if (value == 0.0f) return bits;
  if (std::isnan(value)) return static_cast<std::uint16_t>(bits | 0x7FFFu);
  if (std::isinf(value)) return static_cast<std::uint16_t>(bits | 0x7C00u);
  int exponent = 0;
  (void)std::frexp(value, &exponent);  // |value| = m 2^exponent, m in [0.5, 1)
  if (exponent > 16) return static_cast<std::uint16_t>(bits | 0x7C00u);
  const float magnitude = std::fabs(value);
  float scaled = 0.0f;
  if (exponent < -13) {
    scaled = std::ldexp(magnitude, 24);  // subnormal half
  } else {
    scaled = std::ldexp(magnitude, 11 - exponent);  // in [1024, 2048)
    bits = static_cast<std::uint16_t>(bits | ((exponent + 14) << 10));
  }
  const auto integer = static_cast<std::uint32_t>(scaled);
  bits = static_cast<std::uint16_t>(bits | (integer & 0x3FFu));
  const float dropped = scaled - static_cast<float>(integer);
  if (dropped >= 0.5f) bits = static_cast<std::uint16_t>(bits + 1);
  return bits;
}

double float16_to_double(std::uint16_t bits) {
  const unsigned exponent = (bits >> 10) & 0x1Fu;
  const unsigned significand = bits & 0x3FFu;
  double magnitude = 0.0;
  if (exponent == 0) {
    magnitude = std::ldexp(static_cast<double>(significand), -24);
  } else if (exponent == 31) {
    magnitude = significand == 0 ? std::numeric_limits<double>::infinity()
                                 : std::numeric_limits<double>::quiet_NaN();
  } else {
    magnitude = std::ldexp(static_cast<double>(significand | 0x400u), static_cast<int>(exponent) - 25);
  }
  return (bits & 0x8000u) != 0 ? -magnitude : magnitude;
}

Float16Value float16_saturated(double value) {
  Float16Value out;
  if (!std::isfinite(value)) {
    out.clip = WireClip::kNotFinite;
    return out;  // +0
  }
  // The field type is float: the double is rounded to float first (outside
  // float's range only by clamping, the conversion would be undefined).
  constexpr double kFloatMax = std::numeric_limits<float>::max();
  auto as_float = static_cast<float>(std::clamp(value, -kFloatMax, kFloatMax));
  if (as_float > kFloat16Max) {
    as_float = kFloat16Max;
    out.clip = WireClip::kSaturated;
  } else if (as_float < -kFloat16Max) {
    as_float = -kFloat16Max;
    out.clip = WireClip::kSaturated;
  }
  out.bits = float16_bits_libuavcan(as_float);
  return out;
}

void validate(const DroneCanOptions& options) {
  if (options.node_id < 1 || options.node_id > 127)
    throw std::invalid_argument("dronecan: node_id must be 1..127 (got " + std::to_string(options.node_id) +
                                "); 0 is the anonymous node, which cannot send multi-frame transfers");
  if (options.raw_imu_priority > 31)
    throw std::invalid_argument("dronecan: raw_imu_priority must be 0..31 (5-bit CAN id field), got " +
                                std::to_string(options.raw_imu_priority));
  if (options.node_status_priority > 31)
    throw std::invalid_argument("dronecan: node_status_priority must be 0..31 (5-bit CAN id field), got " +
                                std::to_string(options.node_status_priority));
  if (options.name.empty() || options.name.size() > kNodeNameMaxBytes)
    throw std::invalid_argument("dronecan: name must be 1.." + std::to_string(kNodeNameMaxBytes) +
                                " bytes (GetNodeInfo name uint8[<=80]), got " + std::to_string(options.name.size()));
  if (options.node_status_period_ns <= 0)
    throw std::invalid_argument("dronecan: node_status_period_ns must be > 0, got " +
                                std::to_string(options.node_status_period_ns));
}

// ---- encoder ----

std::uint64_t raw_imu_timestamp_usec(TimeNs t_ns, TimeNs timestamp_offset_ns) {
  TimeNs stamped_ns = 0;
  if (__builtin_add_overflow(t_ns, timestamp_offset_ns, &stamped_ns))
    stamped_ns = timestamp_offset_ns > 0 ? std::numeric_limits<TimeNs>::max() : 0;
  const std::uint64_t usec = stamped_ns > 0 ? static_cast<std::uint64_t>(stamped_ns / 1000) : 0;
  // truncated uint56: the low 56 bits (2^56 us is 2284 years: int64 ns
  // never reaches it), and never the UNKNOWN value 0.
  return std::max<std::uint64_t>(usec & ((std::uint64_t{1} << 56) - 1), kRawImuEarliestKnownUsec);
}

namespace {

struct ClipCounts {
  unsigned saturated_values = 0;
  unsigned non_finite_values = 0;
};

ClipCounts write_raw_imu(BitWriter& writer, const ImuFrameInput& sample, const DroneCanOptions& options) {
  ClipCounts result;
  auto count = [&result](WireClip clip) {
    if (clip == WireClip::kSaturated) ++result.saturated_values;
    if (clip == WireClip::kNotFinite) ++result.non_finite_values;
  };

  // uavcan.Timestamp: truncated uint56 usec, where 0 is UNKNOWN (Timestamp
  // DSDL "uint56 UNKNOWN = 0"). The sample time is always known, so it is
  // never sent as 0: a time before 1 us (trajectory time 0 itself, the
  // first sample of every built-in trajectory) goes out as 1 us, the
  // earliest known time the field can carry.
  writer.put(raw_imu_timestamp_usec(sample.t_ns, options.timestamp_offset_ns), 56);

  // float32 integration_interval, seconds; non-positive = no integrals.
  const bool integrals = options.send_integrals && sample.period_ns > 0;
  WireClip clip = WireClip::kExact;
  writer.put_float32(integrals ? float32_saturated(seconds_between(0, sample.period_ns), clip) : -1.0f);
  count(clip);

  // Body axes: DroneCAN's X forward, Y right, Z down (spec section 5) are
  // imuemu's body FRD axes, so components go across unchanged.
  auto put_float16_vector = [&](const Vec3& v) {
    for (int axis = 0; axis < 3; ++axis) {
      const Float16Value h = float16_saturated(v[axis]);
      count(h.clip);
      writer.put(h.bits, 16);
    }
  };
  auto put_float32_vector = [&](const Vec3& v) {
    for (int axis = 0; axis < 3; ++axis) {
      WireClip c = WireClip::kExact;
      writer.put_float32(integrals ? float32_saturated(v[axis], c) : 0.0f);
      count(c);
    }
  };
  // float16[3] rate_gyro_latest (rad/s), float32[3] rate_gyro_integral: the
  // integral over integration_interval (rad) - what publishers put there (the
  // DSDL comment repeats "radian/second" from the rate line).
  put_float16_vector(sample.gyro_rad_s);
  put_float32_vector(sample.delta_theta_rad);
  // float16[3] accelerometer_latest (m/s^2), float32[3] accelerometer_integral (m/s).
  put_float16_vector(sample.accel_m_s2);
  put_float32_vector(sample.delta_velocity_m_s);
  // float16[<=36] covariance: empty, and as the last field of the top-level
  // type it has no length prefix (tail array optimisation): nothing to write.
  return result;
}

}  // namespace

RawImuPayload serialize_raw_imu(const ImuFrameInput& sample, const DroneCanOptions& options) {
  BitWriter writer;
  const ClipCounts counts = write_raw_imu(writer, sample, options);
  RawImuPayload result;
  result.bytes.assign(writer.bytes().begin(), writer.bytes().end());
  result.saturated_values = counts.saturated_values;
  result.non_finite_values = counts.non_finite_values;
  return result;
}

DroneCanEncoder::DroneCanEncoder(const DroneCanOptions& options) : options_(options) {
  validate(options_);
  // Before any NodeStatus: uptime 0, health OK, mode INITIALIZATION.
  shared_->node_status_payload.store(std::uint64_t{static_cast<std::uint8_t>(NodeMode::kInitialization)} << 35,
                                     std::memory_order_relaxed);
  node_ = std::make_unique<DroneCanNode>(options_, *shared_);
}

void DroneCanEncoder::note_time(TimeNs t_ns) {
  if (started_) return;
  started_ = true;
  start_ns_ = t_ns;
  next_node_status_ns_ = t_ns;
}

void DroneCanEncoder::encode(const ImuFrameInput& sample, std::vector<CanFrame>& out) {
  note_time(sample.t_ns);
  BitWriter writer;
  const ClipCounts payload = write_raw_imu(writer, sample, options_);
  saturated_values_ += payload.saturated_values;
  non_finite_values_ += payload.non_finite_values;
  status_since_node_status_ |= sample.status;
  if (payload.saturated_values > 0 || (sample.status & kStatusSaturated) != 0) saturated_since_node_status_ = true;
  if (payload.non_finite_values > 0 || (sample.status & kStatusFault) != 0) fault_since_node_status_ = true;

  append_transfer(out, message_can_id(options_.raw_imu_priority, kRawImuDataTypeId, options_.node_id),
                  kRawImuSignature, writer.bytes(), raw_imu_transfer_id_);
  raw_imu_transfer_id_ = static_cast<std::uint8_t>((raw_imu_transfer_id_ + 1) & kTransferIdMask);
}

void DroneCanEncoder::periodic(TimeNs now_ns, std::vector<CanFrame>& out) {
  note_time(now_ns);
  // A RestartNode its node acknowledged: the device powers up again here.
  if (shared_->restart_requested.exchange(false, std::memory_order_acq_rel)) {
    restart(now_ns, out);
    return;
  }
  if (now_ns < next_node_status_ns_) return;

  const bool initializing =
      options_.initialization_at_power_up && saturating_sub_ns(now_ns, start_ns_) < kNsPerSecond;
  append_node_status(now_ns, initializing ? NodeMode::kInitialization : NodeMode::kOperational, out);

  // Next due: the first whole period after start that is later than now (a
  // long pause sends one NodeStatus, not a burst of missed ones).
  const TimeNs periods = saturating_sub_ns(now_ns, start_ns_) / options_.node_status_period_ns + 1;
  next_node_status_ns_ = saturating_add_ns(start_ns_, saturating_mul_ns(options_.node_status_period_ns, periods));
}

void DroneCanEncoder::restart(TimeNs now_ns, std::vector<CanFrame>& out) {
  raw_imu_transfer_id_ = 0;
  node_status_transfer_id_ = 0;
  started_ = true;
  start_ns_ = now_ns;
  status_since_node_status_ = 0;
  saturated_since_node_status_ = false;
  fault_since_node_status_ = false;
  append_node_status(now_ns, NodeMode::kInitialization, out);
  next_node_status_ns_ = saturating_add_ns(now_ns, options_.node_status_period_ns);
}

void DroneCanEncoder::append_node_status(TimeNs now_ns, NodeMode mode, std::vector<CanFrame>& out) {
  const TimeNs uptime_ns = std::max<TimeNs>(0, saturating_sub_ns(now_ns, start_ns_));
  const auto uptime_sec = static_cast<std::uint64_t>(uptime_ns / kNsPerSecond);
  NodeHealth health = NodeHealth::kOk;
  if (saturated_since_node_status_) health = NodeHealth::kWarning;
  if (fault_since_node_status_) health = NodeHealth::kError;

  BitWriter writer;
  writer.put(std::min<std::uint64_t>(uptime_sec, std::numeric_limits<std::uint32_t>::max()), 32);
  writer.put(static_cast<std::uint64_t>(health), 2);
  writer.put(static_cast<std::uint64_t>(mode), 3);
  writer.put(0, 3);  // sub_mode: "keep zero when publishing"
  writer.put(status_since_node_status_ & 0xFFFFu, 16);
  const std::span<const std::uint8_t> payload = writer.bytes();
  std::uint64_t packed = 0;
  for (std::size_t i = 0; i < payload.size() && i < 8; ++i) packed |= std::uint64_t{payload[i]} << (8 * i);
  shared_->node_status_payload.store(packed, std::memory_order_relaxed);
  append_transfer(out, message_can_id(options_.node_status_priority, kNodeStatusDataTypeId, options_.node_id),
                  kNodeStatusSignature, payload, node_status_transfer_id_);
  node_status_transfer_id_ = static_cast<std::uint8_t>((node_status_transfer_id_ + 1) & kTransferIdMask);
  status_since_node_status_ = 0;
  saturated_since_node_status_ = false;
  fault_since_node_status_ = false;
}


// ---- node (service side) ----

std::array<std::uint8_t, 16> unique_id_of(const DroneCanOptions& options) {
  if (options.unique_id) return *options.unique_id;
  std::array<std::uint8_t, 16> id{'i', 'm', 'u', 'e', 'm', 'u'};
  id[15] = options.node_id;
  return id;
}

namespace {
constexpr std::uint32_t kServiceFlag = 1u << 7;   // service_not_message
constexpr std::uint32_t kRequestFlag = 1u << 15;  // request_not_response

// 29-bit id of a service frame (spec 4.1: priority(5) | service type id(8) |
// request_not_response(1) | destination node id(7) | service_not_message(1)=1 | source(7)).
std::uint32_t service_can_id(std::uint8_t priority, std::uint8_t service, bool request, std::uint8_t destination,
                             std::uint8_t source) {
  return (std::uint32_t{priority} & 0x1Fu) << 24 | std::uint32_t{service} << 16 | (request ? kRequestFlag : 0u) |
         (std::uint32_t{destination} & 0x7Fu) << 8 | kServiceFlag | (std::uint32_t{source} & 0x7Fu);
}

bool known_service(std::uint8_t service, std::uint64_t& signature) {
  switch (service) {
    case kGetNodeInfoServiceId: signature = kGetNodeInfoSignature; return true;
    case kRestartNodeServiceId: signature = kRestartNodeSignature; return true;
    case kParamGetSetServiceId: signature = kParamGetSetSignature; return true;
    default: return false;
  }
}

// The node's read-only parameters (param.GetSet): Value union tag 1
// integer_value (int64) or 3 boolean_value (uint8).
struct Param {
  const char* name;
  std::uint8_t tag;
  std::int64_t value;
};
std::vector<Param> params_of(const DroneCanOptions& o) {
  return {{"uavcan.node_id", 1, o.node_id},
          {"imu.raw_imu_priority", 1, o.raw_imu_priority},
          {"imu.node_status_period_ms", 1, o.node_status_period_ns / 1'000'000},
          {"imu.send_integrals", 3, o.send_integrals ? 1 : 0}};
}
}  // namespace

DroneCanNode::DroneCanNode(const DroneCanOptions& options, NodeShared& shared) : options_(options), shared_(shared) {}

std::vector<CanReceiveFilter> DroneCanNode::receive_filters() const {
  // Service requests addressed to this node, any service, any requester.
  const std::uint32_t id = kRequestFlag | std::uint32_t{options_.node_id} << 8 | kServiceFlag;
  const std::uint32_t mask = kRequestFlag | 0x7Fu << 8 | kServiceFlag;
  return {CanReceiveFilter{id, mask, true}};
}

void DroneCanNode::set_log(std::function<void(std::string_view)> log) {
  const std::lock_guard<std::mutex> lock(log_mutex_);
  log_ = std::move(log);
}

CommandCounters DroneCanNode::command_counters() const {
  CommandCounters c;
  c.received = received_.load(std::memory_order_relaxed);
  c.answered = answered_.load(std::memory_order_relaxed);
  c.nacked = unsupported_.load(std::memory_order_relaxed);  // DroneCAN has no NACK: unsupported services are not answered
  c.not_command_bytes = bad_bytes_.load(std::memory_order_relaxed);
  c.replies_dropped = dropped_.load(std::memory_order_relaxed);
  c.mode = "streaming";
  c.format = "RawIMU + NodeStatus";
  return c;
}

void DroneCanNode::on_frame(const CanFrame& frame, CanReplySink& replies) {
  const auto bad = [this, &frame] { bad_bytes_.fetch_add(frame.len, std::memory_order_relaxed); };
  if (!frame.extended || frame.fd || frame.len < 1 || frame.len > kClassicCanBytes) return bad();
  const std::uint32_t id = frame.id;
  if ((id & kServiceFlag) == 0 || (id & kRequestFlag) == 0 || ((id >> 8) & 0x7Fu) != options_.node_id) return bad();
  const auto source = static_cast<std::uint8_t>(id & 0x7Fu);
  if (source == 0) return bad();  // anonymous nodes cannot send service transfers (spec 4.1)
  const auto service = static_cast<std::uint8_t>((id >> 16) & 0xFFu);
  const auto priority = static_cast<std::uint8_t>((id >> 24) & 0x1Fu);
  const std::uint8_t tail = frame.data[frame.len - 1];
  const bool start = (tail & kTailStart) != 0, end = (tail & kTailEnd) != 0, toggle = (tail & kTailToggle) != 0;
  const auto tid = static_cast<std::uint8_t>(tail & kTransferIdMask);
  const std::span<const std::uint8_t> data(frame.data.data(), frame.len - 1u);

  if (start && end) {
    if (toggle) return bad();
    handle(service, priority, source, tid, data, replies);
    return;
  }
  Rx& rx = rx_[static_cast<std::uint16_t>(service << 8 | source)];
  if (start) {
    if (toggle || data.size() < 2) return bad();
    rx.in_progress = true;
    rx.transfer_id = tid;
    rx.next_toggle = true;
    rx.crc = static_cast<std::uint16_t>(data[0] | data[1] << 8);
    rx.payload.assign(data.begin() + 2, data.end());
    return;
  }
  if (!rx.in_progress || tid != rx.transfer_id || toggle != rx.next_toggle) {
    rx.in_progress = false;
    return bad();
  }
  rx.payload.insert(rx.payload.end(), data.begin(), data.end());
  rx.next_toggle = !rx.next_toggle;
  if (rx.payload.size() > 512) {
    rx.in_progress = false;
    return bad();
  }
  if (!end) return;
  rx.in_progress = false;
  std::uint64_t signature = 0;
  if (!known_service(service, signature)) {
    unsupported_.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  if (transfer_crc(signature, rx.payload) != rx.crc) {
    bad_bytes_.fetch_add(rx.payload.size() + 2, std::memory_order_relaxed);
    return;
  }
  handle(service, priority, source, tid, rx.payload, replies);
}

void DroneCanNode::respond(std::uint8_t service, std::uint64_t signature, std::uint8_t priority,
                           std::uint8_t destination, std::uint8_t transfer_id, std::span<const std::uint8_t> payload,
                           CanReplySink& replies) {
  std::vector<CanFrame> frames;
  append_transfer(frames, service_can_id(priority, service, false, destination, options_.node_id), signature, payload,
                  transfer_id);
  for (const CanFrame& f : frames) {
    if (!replies.reply(f)) {
      dropped_.fetch_add(1, std::memory_order_relaxed);
      return;
    }
  }
  answered_.fetch_add(1, std::memory_order_relaxed);
}

void DroneCanNode::handle(std::uint8_t service, std::uint8_t priority, std::uint8_t source, std::uint8_t transfer_id,
                          std::span<const std::uint8_t> payload, CanReplySink& replies) {
  std::uint64_t signature = 0;
  if (!known_service(service, signature)) {
    unsupported_.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  received_.fetch_add(1, std::memory_order_relaxed);
  BitWriter w;
  if (service == kGetNodeInfoServiceId) {
    // status: the last NodeStatus sent (7 bytes, as on the wire).
    const std::uint64_t status = shared_.node_status_payload.load(std::memory_order_relaxed);
    for (unsigned i = 0; i < kNodeStatusPayloadBytes; ++i) w.put((status >> (8 * i)) & 0xFF, 8);
    // SoftwareVersion: major, minor, optional_field_flags, vcs_commit, image_crc.
    w.put(options_.software_major, 8);
    w.put(options_.software_minor, 8);
    w.put(options_.software_vcs_commit != 0 ? 1 : 0, 8);  // OPTIONAL_FIELD_FLAG_VCS_COMMIT = 1
    w.put(options_.software_vcs_commit, 32);
    w.put(0, 64);  // image_crc: not given (flag bit 1 clear)
    // HardwareVersion: major, minor, unique_id[16], certificate_of_authenticity
    // uint8[<=255] (nested, so with its 8-bit length: 0).
    w.put(options_.hardware_major, 8);
    w.put(options_.hardware_minor, 8);
    for (std::uint8_t b : unique_id_of(options_)) w.put(b, 8);
    w.put(0, 8);
    // name uint8[<=80]: the top-level type's last array, no length field.
    for (char c : options_.name) w.put(static_cast<std::uint8_t>(c), 8);
  } else if (service == kRestartNodeServiceId) {
    BitReader r(payload);
    const bool ok = r.has(40) && r.get(40) == kRestartNodeMagic;
    w.put(ok ? 1 : 0, 1);
    w.put(0, 7);
    if (ok) {
      shared_.restart_requested.store(true, std::memory_order_release);
      const std::lock_guard<std::mutex> lock(log_mutex_);
      if (log_) log_("dronecan node " + std::to_string(options_.node_id) + ": RestartNode from node " +
                     std::to_string(source) + ": restarting");
    }
  } else {  // param.GetSet
    BitReader r(payload);
    std::uint64_t index = r.has(13) ? r.get(13) : 0;
    // Skip the request's Value (a set, refused: the current value is the answer).
    std::uint64_t tag = r.has(3) ? r.get(3) : 0;
    std::size_t value_bits = 0;
    if (tag == 1) value_bits = 64;
    else if (tag == 2) value_bits = 32;
    else if (tag == 3) value_bits = 8;
    std::string name;
    if (tag == 4) {
      const std::uint64_t n = r.has(8) ? r.get(8) : 0;
      value_bits = 8 * n;
    }
    for (std::size_t i = 0; i < value_bits && r.has(1); ++i) (void)r.get(1);
    while (r.has(8)) name.push_back(static_cast<char>(r.get(8)));
    const std::vector<Param> params = params_of(options_);
    const Param* found = nullptr;
    if (!name.empty()) {
      for (const Param& p : params)
        if (name == p.name) found = &p;
    } else if (index < params.size()) {
      found = &params[index];
    }
    const auto put_value = [&w](const Param* p) {
      w.put(0, 5);
      if (p == nullptr) {
        w.put(0, 3);  // Empty
        return;
      }
      w.put(p->tag, 3);
      if (p->tag == 1) w.put(static_cast<std::uint64_t>(p->value), 64);
      else w.put(static_cast<std::uint64_t>(p->value), 8);
    };
    put_value(found);  // value
    put_value(found);  // default_value: read-only, the value it always has
    w.put(0, 6);
    w.put(0, 2);  // max_value: Empty
    w.put(0, 6);
    w.put(0, 2);  // min_value: Empty
    if (found != nullptr)
      for (const char* c = found->name; *c != 0; ++c) w.put(static_cast<std::uint8_t>(*c), 8);
  }
  respond(service, signature, priority, source, transfer_id, w.bytes(), replies);
}

// ---- decoder ----

DroneCanDecoder::DroneCanDecoder(const DroneCanOptions& options) : options_(options) {}

std::optional<NodeStatusInfo> DroneCanDecoder::last_node_status(std::uint8_t node_id) const {
  const auto it = node_status_.find(node_id);
  if (it == node_status_.end()) return std::nullopt;
  return it->second;
}

void DroneCanDecoder::reject(std::uint64_t DroneCanErrorDetail::*what) {
  ++(detail_.*what);
  ++counters_.other_errors;
}

void DroneCanDecoder::break_transfer(Reassembly& state, std::uint64_t DroneCanErrorDetail::*what) {
  reject(what);
  state.in_progress = false;
  state.discarding = true;  // the rest of this transfer id's frames go silently
  state.payload.clear();
}

void DroneCanDecoder::feed(const CanFrame& frame, const SampleCallback& on_sample) {
  if (!frame.extended || frame.fd || frame.len == 0 || frame.len > kClassicCanBytes) {
    reject(&DroneCanErrorDetail::not_dronecan_frame);
    return;
  }
  const std::uint32_t id = frame.id & kExtendedIdMask;
  const bool service = ((id >> 7) & 1u) != 0;
  const auto source = static_cast<std::uint8_t>(id & 0x7Fu);
  if (service || source == 0) {  // services and anonymous messages are not ours
    reject(&DroneCanErrorDetail::not_dronecan_frame);
    return;
  }
  const auto data_type = static_cast<std::uint16_t>((id >> 8) & 0xFFFFu);
  bool known = false;
  const std::uint64_t signature = signature_of(data_type, known);
  if (!known) {
    reject(&DroneCanErrorDetail::unknown_data_type);
    return;
  }

  const std::uint8_t tail = frame.data[frame.len - 1];
  const bool start = (tail & kTailStart) != 0;
  const bool end = (tail & kTailEnd) != 0;
  const bool toggle = (tail & kTailToggle) != 0;
  const auto tid = static_cast<std::uint8_t>(tail & kTransferIdMask);
  const std::span<const std::uint8_t> bytes(frame.data.data(), frame.len - 1u);
  Reassembly& state = states_[std::uint32_t{data_type} << 8 | source];

  if (start) {
    if (state.in_progress) {  // the previous transfer lost its end
      reject(&DroneCanErrorDetail::interrupted_transfer);
      state.in_progress = false;
      state.payload.clear();
    }
    state.discarding = false;
    if (toggle) {
      reject(&DroneCanErrorDetail::bad_toggle);
      state.discarding = !end;
      state.transfer_id = tid;
      return;
    }
    if (end) {
      complete(state, source, data_type, tid, bytes, on_sample);
      return;
    }
    if (bytes.size() < 3) {  // 2 CRC bytes and at least one payload byte
      reject(&DroneCanErrorDetail::bad_length);
      state.discarding = true;
      state.transfer_id = tid;
      return;
    }
    state.in_progress = true;
    state.transfer_id = tid;
    state.next_toggle = true;
    state.expected_crc = static_cast<std::uint16_t>(bytes[0] | (bytes[1] << 8));
    state.payload.assign(bytes.begin() + 2, bytes.end());
    state.running_crc = transfer_crc(signature, state.payload);
    return;
  }

  if (!state.in_progress) {
    if (state.discarding && tid == state.transfer_id) {
      if (end) state.discarding = false;
      return;
    }
    reject(&DroneCanErrorDetail::missed_start);
    state.discarding = !end;  // the rest of this transfer goes silently
    state.transfer_id = tid;
    return;
  }
  if (tid != state.transfer_id) {
    break_transfer(state, &DroneCanErrorDetail::bad_transfer_id);
    return;
  }
  if (toggle != state.next_toggle) {
    break_transfer(state, &DroneCanErrorDetail::bad_toggle);
    if (end) state.discarding = false;
    return;
  }
  if (state.payload.size() + bytes.size() > max_payload_of(data_type)) {
    break_transfer(state, &DroneCanErrorDetail::bad_length);
    if (end) state.discarding = false;
    return;
  }
  state.payload.insert(state.payload.end(), bytes.begin(), bytes.end());
  state.running_crc = crc16_ccitt_false(state.running_crc, bytes);
  if (!end) {
    state.next_toggle = !state.next_toggle;
    return;
  }
  state.in_progress = false;
  if (state.running_crc != state.expected_crc) {
    ++counters_.checksum_errors;
    state.payload.clear();
    return;
  }
  const std::vector<std::uint8_t> payload = std::move(state.payload);
  state.payload.clear();
  complete(state, source, data_type, tid, payload, on_sample);
}

void DroneCanDecoder::complete(Reassembly& state, std::uint8_t source, std::uint16_t data_type,
                               std::uint8_t transfer_id, std::span<const std::uint8_t> payload,
                               const SampleCallback& on_sample) {
  // Transfer id sequence of this (node, type).
  if (state.have_last) {
    const auto forward = static_cast<std::uint8_t>((transfer_id - state.last_transfer_id) & kTransferIdMask);
    if (forward == 0) {
      reject(&DroneCanErrorDetail::duplicate_transfer);
      return;
    }
    if (forward >= 16) {
      const bool jump = state.have_stale &&
                        transfer_id == static_cast<std::uint8_t>((state.stale_transfer_id + 1) & kTransferIdMask);
      if (!jump) {
        reject(&DroneCanErrorDetail::stale_transfer);
        state.have_stale = true;
        state.stale_transfer_id = transfer_id;
        return;
      }
    } else {
      counters_.sequence_gaps += forward - 1u;
    }
    state.sequence += forward;
  } else {
    state.sequence = transfer_id;
  }
  state.have_last = true;
  state.have_stale = false;
  state.last_transfer_id = transfer_id;

  if (data_type == kNodeStatusDataTypeId) {
    if (payload.size() != kNodeStatusPayloadBytes) {
      reject(&DroneCanErrorDetail::bad_payload);
      return;
    }
    BitReader reader(payload);
    NodeStatusInfo info;
    info.uptime_sec = static_cast<std::uint32_t>(reader.get(32));
    info.health = static_cast<NodeHealth>(reader.get(2));
    info.mode = static_cast<std::uint8_t>(reader.get(3));
    info.sub_mode = static_cast<std::uint8_t>(reader.get(3));
    info.vendor_specific_status_code = static_cast<std::uint16_t>(reader.get(16));
    node_status_[source] = info;
    ++counters_.frames;
    return;
  }

  // RawIMU: the fixed part, then 0..36 float16 covariance entries that run to
  // the end of the transfer (tail array optimisation).
  const std::size_t covariance_bytes = payload.size() >= kRawImuPayloadBytes ? payload.size() - kRawImuPayloadBytes : 1;
  if (payload.size() < kRawImuPayloadBytes || covariance_bytes % 2 != 0 ||
      covariance_bytes / 2 > kRawImuMaxCovariance) {
    reject(&DroneCanErrorDetail::bad_payload);
    return;
  }
  BitReader reader(payload);
  const std::uint64_t usec = reader.get(56);
  const float integration_interval_s = reader.get_float32();
  bool finite = std::isfinite(integration_interval_s);
  auto get_float16_vector = [&]() {
    Vec3 v;
    for (int axis = 0; axis < 3; ++axis) {
      v[axis] = float16_to_double(static_cast<std::uint16_t>(reader.get(16)));
      finite = finite && std::isfinite(v[axis]);
    }
    return v;
  };
  auto get_float32_vector = [&]() {
    Vec3 v;
    for (int axis = 0; axis < 3; ++axis) {
      v[axis] = reader.get_float32();
      finite = finite && std::isfinite(v[axis]);
    }
    return v;
  };
  DecodedSample sample;
  sample.gyro_rad_s = get_float16_vector();
  const Vec3 gyro_integral_rad = get_float32_vector();
  sample.accel_m_s2 = get_float16_vector();
  const Vec3 accel_integral_m_s = get_float32_vector();
  if (!finite) {  // never Inf/NaN out
    reject(&DroneCanErrorDetail::bad_payload);
    return;
  }
  if (integration_interval_s > 0.0f) {
    sample.delta_theta_rad = gyro_integral_rad;
    sample.delta_velocity_m_s = accel_integral_m_s;
  }
  // 0 = uavcan.Timestamp.UNKNOWN; a uint56 of microseconds can exceed int64
  // nanoseconds (after ~292 years): such a time is left out, not wrapped.
  TimeNs t_ns = 0;
  sample.has_time = usec != 0 && usec <= static_cast<std::uint64_t>(std::numeric_limits<TimeNs>::max() / 1000) &&
                    !__builtin_sub_overflow(static_cast<TimeNs>(usec) * 1000, options_.timestamp_offset_ns, &t_ns);
  if (sample.has_time) sample.t_ns = t_ns;
  sample.has_sequence = true;
  sample.sequence = state.sequence;
  ++counters_.frames;
  ++counters_.samples;
  if (on_sample) on_sample(sample);
}

}  // namespace imuemu::drivers::dronecan
