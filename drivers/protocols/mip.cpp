// MicroStrain MIP encoder/decoder for the IMU data set (0x80).
//
// Sources (read, nothing copied):
//  [P] 3DM-GX5-35 DCP manual, 6 "MIP Packet Reference": packet = 0x75 0x65,
//      descriptor set, payload length (sum of the field lengths), fields
//      (length incl. itself and the descriptor, descriptor, data), 2-byte
//      Fletcher checksum over every preceding byte of the packet (6.3, 6.4).
//  [D] 3DM-CV7 online DCP manual, data fields of set 0x80: Scaled
//      Accelerometer 0x04 (vector3f, g), Scaled Gyro 0x05 (vector3f, rad/s),
//      Delta Theta 0x07 (vector3f, rad), Delta Velocity 0x08 (vector3f,
//      g*s), GPS Timestamp 0x12 (double tow [s], u16 week number since 1980,
//      u16 valid flags: pps 0, refresh 1, initialized 2, tow 3, week 4);
//      Overrange Status 0x18 (u16: accel x/y/z 0x1/0x2/0x4, gyro x/y/z
//      0x10/0x20/0x40). Values are IEEE-754 big-endian; 1 g = 9.80665 m/s^2.
//  [F] 3DM-GX5-10 / 3DM-CV7 user manuals, "Sensor Frame": x along the long
//      side toward the connector, y 90 deg to the right of x, z through the
//      bottom - NED-aligned when the connector points north, upright, level.
//      IMU quantities are reported in the vehicle frame, which is the sensor
//      frame unless a sensor-to-vehicle transform is set (default none).
//
// Units and axes: the emulated device is mounted connector forward, upright,
// with no sensor-to-vehicle transform, so its sensor frame is body FRD and
// the axis conversion is the identity (frd_to_mip_sensor()). Units are
// converted explicitly: specific force m/s^2 -> g and delta-v m/s -> g*s by
// dividing by 9.80665, angular rate and delta theta stay rad/s and rad.
// Accelerometers report specific force: level at rest z = -1 g
// (LORD-MicroStrain/microstrain_inertial issue #97: "-9.81 does make sense").
#include "drivers/protocols/mip.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include "drivers/protocols/gps_time.hpp"
#include "drivers/protocols/mip_device.hpp"
#include "drivers/protocols/mip_nav.hpp"
#include "drivers/protocols/wire_bytes.hpp"

namespace imuemu::drivers::mip {

namespace {

constexpr std::size_t kVectorFieldBytes = 2 + 12;
constexpr std::size_t kGpsFieldBytes = 2 + 8 + 2 + 2;
constexpr std::size_t kOverrangeFieldBytes = 2 + 2;

Vec3 frd_to_mip_sensor(const Vec3& v_frd) { return v_frd; }
Vec3 mip_sensor_to_frd(const Vec3& v_sensor) { return v_sensor; }

// Appends one vector3f field; returns the overrange bits (first_bit, +1, +2)
// of the axes that had to be clamped (beyond the float range) or were NaN.
std::uint16_t put_vector_field(std::vector<std::uint8_t>& out, std::uint8_t descriptor, const Vec3& v,
                               std::uint16_t first_bit) {
  std::uint16_t overrange = 0;
  std::array<std::uint8_t, kVectorFieldBytes> f{};
  f[0] = static_cast<std::uint8_t>(kVectorFieldBytes);
  f[1] = descriptor;
  for (int i = 0; i < 3; ++i) {
    const wire::WireValue w = wire::to_wire_float<float>(v[i]);
    if (w.clamped || w.was_nan) overrange |= static_cast<std::uint16_t>(first_bit << i);
    wire::put_be<float>(f.data() + 2 + 4 * i, static_cast<float>(w.value));
  }
  out.insert(out.end(), f.begin(), f.end());
  return overrange;
}

void put_gps_field(std::vector<std::uint8_t>& out, const GpsTimestamp& ts) {
  std::array<std::uint8_t, kGpsFieldBytes> g{};
  g[0] = static_cast<std::uint8_t>(kGpsFieldBytes);
  g[1] = kGpsTimestamp;
  wire::put_be<double>(g.data() + 2, ts.tow_s);
  wire::put_be<std::uint16_t>(g.data() + 10, ts.week);
  wire::put_be<std::uint16_t>(g.data() + 12, ts.valid_flags);
  out.insert(out.end(), g.begin(), g.end());
}

Vec3 get_vector(const std::uint8_t* at) {
  return {wire::get_be<float>(at), wire::get_be<float>(at + 4), wire::get_be<float>(at + 8)};
}

// A time (ns, >= 0) as week number and time of week; nothing when the week
// does not fit the u16 field. The time of week is a double on the wire [D];
// below 604800 s a double resolves 0.12 ns, so integer ns survive the round
// trip exactly.
std::optional<GpsTimestamp> weeks_of(std::int64_t ns) {
  if (ns < 0 || ns / kNsPerGpsWeek > std::numeric_limits<std::uint16_t>::max()) return std::nullopt;
  GpsTimestamp ts;
  ts.week = static_cast<std::uint16_t>(ns / kNsPerGpsWeek);
  ts.tow_s = static_cast<double>(ns % kNsPerGpsWeek) / 1e9;
  return ts;
}

}  // namespace

GpsTimestamp gps_timestamp_of(TimeNs t_ns, const StreamEncoderOptions& options) {
  std::optional<std::int64_t> gps_ns;
  switch (options.mip_time_base) {
    case MipTimeBase::unknown: {
      // Internal clock: the trajectory time itself, flags clear. A time
      // before 0 cannot be carried: zeros (as the flags say, not a time).
      return weeks_of(t_ns).value_or(GpsTimestamp{});
    }
    case MipTimeBase::gps: {
      std::int64_t sum = 0;
      if (!__builtin_add_overflow(options.mip_gps_time_at_t0_ns, t_ns, &sum)) gps_ns = sum;
      break;
    }
    case MipTimeBase::utc:
      gps_ns = gps_time::gps_from_utc_ns(t_ns, options.mip_gps_minus_utc_s);
      break;
  }
  // Times the field cannot carry (before the GPS epoch, week beyond u16)
  // go out as zero with the valid bits clear.
  std::optional<GpsTimestamp> ts = gps_ns ? weeks_of(*gps_ns) : std::nullopt;
  if (!ts) return GpsTimestamp{};
  ts->valid_flags = kGpsTimeValid;
  return *ts;
}

std::optional<TimeNs> trajectory_time_of(double tow_s, std::uint16_t week, std::uint16_t valid_flags,
                                         const StreamEncoderOptions& options) {
  if (!std::isfinite(tow_s) || tow_s < 0.0 || tow_s >= 604800.0) return std::nullopt;
  const std::int64_t ns = std::int64_t{week} * kNsPerGpsWeek + std::llround(tow_s * 1e9);
  const std::uint16_t needed = kTowValid | kWeekNumberValid;
  if ((valid_flags & needed) != needed) {
    // Not GPS time: the device's internal clock.
    if (options.mip_time_base != MipTimeBase::unknown) return std::nullopt;
    return ns;
  }
  switch (options.mip_time_base) {
    case MipTimeBase::unknown: return ns;  // GPS time from a device that has it
    case MipTimeBase::gps: {
      TimeNs t_ns = 0;
      if (__builtin_sub_overflow(ns, options.mip_gps_time_at_t0_ns, &t_ns)) return std::nullopt;
      return t_ns;
    }
    case MipTimeBase::utc: return gps_time::utc_from_gps_ns(ns, options.mip_gps_minus_utc_s);
  }
  return std::nullopt;
}

std::uint16_t fletcher_checksum(std::span<const std::uint8_t> bytes) {
  std::uint8_t sum1 = 0;
  std::uint8_t sum2 = 0;
  for (const std::uint8_t b : bytes) {
    sum1 = static_cast<std::uint8_t>(sum1 + b);
    sum2 = static_cast<std::uint8_t>(sum2 + sum1);
  }
  return static_cast<std::uint16_t>(sum1 << 8 | sum2);
}

Encoder::Encoder(const StreamEncoderOptions& options) : options_(options) {
  // The base rate the device reports (Get Base Rate): the scene's rate,
  // which every decimation divides; 1000 Hz (the CV7's IMU rate) while the
  // rate is not known (an encoder made only to check options).
  const double r = options_.nominal_sample_rate_hz;
  const auto base_rate_hz = static_cast<std::uint16_t>(r >= 1.0 ? std::min(std::lround(r), 65535L) : 1000L);
  NavFields nav;
  if (options_.mip_nav.any()) {
    // Issue 28: the GNSS receiver's and the filter's sets, each at its own
    // power-up decimation of the base rate.
    const MipNavConfig& n = options_.mip_nav;
    nav.gnss = gnss_fields(n);
    nav.filter = filter_fields(n);
    for (const std::uint8_t f : gnss_power_up_fields(n)) nav.gnss_power_up.push_back({f, decimation_of(n.gnss_rate_hz, base_rate_hz)});
    for (const std::uint8_t f : filter_power_up_fields(n))
      nav.filter_power_up.push_back({f, decimation_of(n.filter_rate_hz, base_rate_hz)});
    nav_ = std::make_unique<NavEncoder>(options_, base_rate_hz);
    auto fill = [](SetFormat& s, const std::vector<FieldRate>& f) {
      s.send = !f.empty();
      s.count = static_cast<std::uint8_t>(std::min(f.size(), kMaxFormatFields));
      std::copy_n(f.begin(), s.count, s.fields.begin());
    };
    fill(nav_power_up_.gnss, nav.gnss_power_up);
    fill(nav_power_up_.filter, nav.filter_power_up);
  }
  if (options_.mip_device.answers_commands)
    device_ = std::make_unique<Device>(options_.mip_device, sensor_fields(), base_rate_hz, std::move(nav));
}

Encoder::~Encoder() = default;

void Encoder::restart(TimeNs now_ns, std::vector<std::uint8_t>& out) {
  (void)now_ns;
  (void)out;  // no power-up packet
  if (!device_) return;
  ++restarts_;
  device_->note_restart();
}

Encoder& Encoder::operator=(const Encoder& other) {
  if (this != &other) {
    Encoder fresh(other.options_);
    options_ = fresh.options_;
    device_ = std::move(fresh.device_);
    nav_ = std::move(fresh.nav_);
    nav_power_up_ = fresh.nav_power_up_;
    restarts_ = 0;
  }
  return *this;
}

CommandResponder* Encoder::command_responder() { return device_.get(); }

std::vector<std::uint8_t> Encoder::sensor_fields() const {
  std::vector<std::uint8_t> f;
  f.reserve(6);
  f.push_back(kScaledAccel);
  f.push_back(kScaledGyro);
  if (options_.include_deltas) {
    f.push_back(kDeltaTheta);
    f.push_back(kDeltaVelocity);
  }
  f.push_back(kGpsTimestamp);
  if (options_.mip_overrange_status) f.push_back(kOverrangeStatus);
  return f;
}

void Encoder::encode_format(const ImuFrameInput& sample, std::span<const FieldRate> fields,
                            std::vector<std::uint8_t>& out) {
  bool due = false;
  for (const FieldRate& f : fields) due = due || sample.sample_counter % f.decimation == 0;
  if (!due) return;  // no field on this sample: no packet
  const std::size_t start = out.size();
  out.insert(out.end(), {kSync1, kSync2, kSensorDataSet, 0});
  // The overrange bits of every axis, whichever fields carry them.
  const Vec3 accel_g = frd_to_mip_sensor(sample.accel_m_s2) / kStandardGravity_m_s2;
  const Vec3 dv_gs = frd_to_mip_sensor(sample.delta_velocity_m_s) / kStandardGravity_m_s2;
  std::uint16_t overrange = (sample.status & kStatusSaturated) != 0 ? kOverrangeAccelGyroAll : 0;
  for (int i = 0; i < 3; ++i) {
    for (const double v : {accel_g[i], dv_gs[i]}) {
      const wire::WireValue w = wire::to_wire_float<float>(v);
      if (w.clamped || w.was_nan) overrange |= static_cast<std::uint16_t>(kOverrangeAccelX << i);
    }
    for (const double v : {sample.gyro_rad_s[i], sample.delta_theta_rad[i]}) {
      const wire::WireValue w = wire::to_wire_float<float>(v);
      if (w.clamped || w.was_nan) overrange |= static_cast<std::uint16_t>(kOverrangeGyroX << i);
    }
  }
  for (const FieldRate& f : fields) {
    if (sample.sample_counter % f.decimation != 0) continue;
    switch (f.descriptor) {
      case kScaledAccel: put_vector_field(out, kScaledAccel, accel_g, kOverrangeAccelX); break;
      case kScaledGyro:
        put_vector_field(out, kScaledGyro, frd_to_mip_sensor(sample.gyro_rad_s), kOverrangeGyroX);
        break;
      case kDeltaTheta:
        put_vector_field(out, kDeltaTheta, frd_to_mip_sensor(sample.delta_theta_rad), kOverrangeGyroX);
        break;
      case kDeltaVelocity: put_vector_field(out, kDeltaVelocity, dv_gs, kOverrangeAccelX); break;
      case kGpsTimestamp: put_gps_field(out, gps_timestamp_of(sample.t_ns, options_)); break;
      case kOverrangeStatus: {
        std::array<std::uint8_t, kOverrangeFieldBytes> o{static_cast<std::uint8_t>(kOverrangeFieldBytes),
                                                         kOverrangeStatus};
        wire::put_be<std::uint16_t>(o.data() + 2, overrange);
        out.insert(out.end(), o.begin(), o.end());
        break;
      }
      default: break;  // the device accepts only the fields above (mip_device.cpp)
    }
  }
  out[start + 3] = static_cast<std::uint8_t>(out.size() - start - kHeaderBytes);
  const std::uint16_t checksum =
      fletcher_checksum(std::span<const std::uint8_t>(out.data() + start, out.size() - start));
  out.push_back(static_cast<std::uint8_t>(checksum >> 8));
  out.push_back(static_cast<std::uint8_t>(checksum));
}

void Encoder::encode(const ImuFrameInput& sample, std::vector<std::uint8_t>& out) {
  const StreamConfig* c = nullptr;
  if (device_) {
    // What the driver left the device doing (wait-free read of the io
    // thread's last change).
    const EmitConfig& published = device_->emit_config();
    // After a restart fault the io thread has not taken in yet: the startup settings.
    c = published.restarts_handled < restarts_ ? &published.startup : &published;
  }
  encode_imu(sample, c, out);
  if (nav_) {
    // Issue 28: then the GNSS and filter packets due at this sample.
    const StreamConfig& n = c != nullptr ? *c : nav_power_up_;
    const std::span<const FieldRate> none;
    nav_->encode(sample, n.gnss.send ? std::span<const FieldRate>(n.gnss.fields.data(), n.gnss.count) : none,
                 n.filter.send ? std::span<const FieldRate>(n.filter.fields.data(), n.filter.count) : none, out);
  }
}

void Encoder::encode_imu(const ImuFrameInput& sample, const StreamConfig* c, std::vector<std::uint8_t>& out) {
  if (c != nullptr) {
    // Idle (or the 0x80 stream off) sends nothing; a format of its own sends
    // its fields at their decimations; otherwise the power-up stream below.
    if (!c->send) return;
    if (!c->scene_format) {
      encode_format(sample, std::span<const FieldRate>(c->fields.data(), c->count), out);
      return;
    }
  }
  // Built in place at the end of `out`; length and checksum patched last.
  const std::size_t start = out.size();
  out.insert(out.end(), {kSync1, kSync2, kSensorDataSet, 0});

  std::uint16_t overrange = 0;
  overrange |= put_vector_field(out, kScaledAccel, frd_to_mip_sensor(sample.accel_m_s2) / kStandardGravity_m_s2,
                                kOverrangeAccelX);
  overrange |= put_vector_field(out, kScaledGyro, frd_to_mip_sensor(sample.gyro_rad_s), kOverrangeGyroX);
  if (options_.include_deltas) {
    overrange |= put_vector_field(out, kDeltaTheta, frd_to_mip_sensor(sample.delta_theta_rad), kOverrangeGyroX);
    overrange |= put_vector_field(out, kDeltaVelocity,
                                  frd_to_mip_sensor(sample.delta_velocity_m_s) / kStandardGravity_m_s2,
                                  kOverrangeAccelX);
  }

  // GPS timestamp (0x80,0x12): by the time base (gps_timestamp_of).
  put_gps_field(out, gps_timestamp_of(sample.t_ns, options_));

  // The sensor model's saturated bit does not say which axis: every accel
  // and gyro axis is flagged; axes clamped here add their own bit anyway.
  if ((sample.status & kStatusSaturated) != 0) overrange |= kOverrangeAccelGyroAll;
  if (options_.mip_overrange_status) {
    std::array<std::uint8_t, kOverrangeFieldBytes> f{static_cast<std::uint8_t>(kOverrangeFieldBytes),
                                                     kOverrangeStatus};
    wire::put_be<std::uint16_t>(f.data() + 2, overrange);
    out.insert(out.end(), f.begin(), f.end());
  }

  out[start + 3] = static_cast<std::uint8_t>(out.size() - start - kHeaderBytes);
  const std::uint16_t checksum =
      fletcher_checksum(std::span<const std::uint8_t>(out.data() + start, out.size() - start));
  out.push_back(static_cast<std::uint8_t>(checksum >> 8));
  out.push_back(static_cast<std::uint8_t>(checksum));
}

StreamFrameLayout Encoder::frame_layout(std::span<const std::uint8_t> frame) const {
  // [P 6.3]: sync1 sync2 descriptor-set payload-length, the fields, then the
  // 2-byte checksum (MSB first).
  if (frame.size() < kHeaderBytes) return StreamFrameLayout{frame.size()};
  const std::size_t payload = frame[3];
  StreamFrameLayout layout;
  layout.frame_bytes = std::min(frame.size(), kHeaderBytes + payload + kChecksumBytes);
  layout.length_offset = 3;
  layout.length_bytes = 1;
  layout.checksum_offset = kHeaderBytes + payload;
  layout.checksum_bytes = layout.checksum_offset + kChecksumBytes <= frame.size() ? kChecksumBytes : 0;
  return layout;
}

std::size_t Encoder::max_bytes_per_sample() const {
  std::size_t payload = 2 * kVectorFieldBytes + kGpsFieldBytes;
  if (options_.include_deltas) payload += 2 * kVectorFieldBytes;
  if (options_.mip_overrange_status) payload += kOverrangeFieldBytes;
  return kHeaderBytes + payload + kChecksumBytes + max_gnss_packet_bytes(options_.mip_nav) +
         max_filter_packet_bytes(options_.mip_nav);
}

void Decoder::feed(std::span<const std::uint8_t> bytes, const SampleCallback& on_sample) {
  buffer_.insert(buffer_.end(), bytes.begin(), bytes.end());
  static constexpr std::array<std::uint8_t, 2> kSync{kSync1, kSync2};

  wire::scan_frames(buffer_, kSync, counters_, [&](std::span<const std::uint8_t> c) {
    using wire::Candidate;
    if (c.size() < kHeaderBytes) return wire::CandidateResult{Candidate::kNeedMore};
    const std::size_t payload_bytes = c[3];
    const std::size_t total = kHeaderBytes + payload_bytes + kChecksumBytes;
    if (c.size() < total) return wire::CandidateResult{Candidate::kNeedMore};
    const std::uint16_t sent = wire::get_be<std::uint16_t>(c.data() + kHeaderBytes + payload_bytes);
    if (fletcher_checksum(c.first(kHeaderBytes + payload_bytes)) != sent) {
      return wire::CandidateResult{Candidate::kBadChecksum};
    }
    ++counters_.frames;
    const wire::CandidateResult accepted{Candidate::kAccepted, total};
    // Other descriptor sets (command replies, filter data) are valid MIP
    // packets that carry no IMU sample.
    if (c[2] != kSensorDataSet) return accepted;

    DecodedSample s;
    bool has_imu_field = false;
    bool bad = false;
    std::size_t at = kHeaderBytes;
    const std::size_t end = kHeaderBytes + payload_bytes;
    while (at < end && !bad) {
      const std::size_t field_bytes = c[at];
      if (field_bytes < 2 || at + field_bytes > end) {
        bad = true;
        break;
      }
      const std::uint8_t descriptor = c[at + 1];
      const std::uint8_t* data = c.data() + at + 2;
      const std::size_t data_bytes = field_bytes - 2;
      auto vector_field = [&](Vec3& into, double scale) {
        if (data_bytes != 12) {
          bad = true;
          return;
        }
        into = mip_sensor_to_frd(get_vector(data)) * scale;
        has_imu_field = true;
      };
      switch (descriptor) {
        case kScaledAccel: vector_field(s.accel_m_s2, kStandardGravity_m_s2); break;
        case kScaledGyro: vector_field(s.gyro_rad_s, 1.0); break;
        case kDeltaTheta: vector_field(s.delta_theta_rad, 1.0); break;
        case kDeltaVelocity: vector_field(s.delta_velocity_m_s, kStandardGravity_m_s2); break;
        case kGpsTimestamp: {
          if (data_bytes != 12) {
            bad = true;
            break;
          }
          const std::optional<TimeNs> t_ns =
              trajectory_time_of(wire::get_be<double>(data), wire::get_be<std::uint16_t>(data + 8),
                                 wire::get_be<std::uint16_t>(data + 10), options_);
          if (t_ns) {
            s.t_ns = *t_ns;
            s.has_time = true;
          }
          break;
        }
        case kOverrangeStatus:
          if (data_bytes != 2) {
            bad = true;
            break;
          }
          if ((wire::get_be<std::uint16_t>(data) & kOverrangeAccelGyroAll) != 0) s.status |= kStatusSaturated;
          break;
        default: break;  // fields this decoder does not use
      }
      at += field_bytes;
    }

    if (bad || !s.accel_m_s2.allFinite() || !s.gyro_rad_s.allFinite() || !s.delta_theta_rad.allFinite() ||
        !s.delta_velocity_m_s.allFinite()) {
      ++counters_.other_errors;  // malformed field list or NaN/inf values
    } else if (has_imu_field) {
      ++counters_.samples;
      if (on_sample) on_sample(s);
    }
    return accepted;
  });
}

}  // namespace imuemu::drivers::mip
