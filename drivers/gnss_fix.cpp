// The error-free GNSS epoch of one device sample; see gnss_fix.hpp.
#include "drivers/gnss_fix.hpp"

#include "drivers/protocols/gps_time.hpp"

namespace imuemu::drivers {

GnssFix fix_from_frame(const ImuFrameInput& frame, const GnssReceiverConfig& config) {
  GnssFix fix;
  std::optional<std::int64_t> gps;
  if (config.time_base == GnssTimeBase::utc) {
    gps = gps_time::gps_from_utc_ns(frame.t_ns, config.gps_minus_utc_s);
  } else if (std::int64_t sum = 0; !__builtin_add_overflow(config.gps_time_at_t0_ns, frame.t_ns, &sum) && sum >= 0) {
    gps = sum;
  }
  // GPS - UTC at the epoch: the table is indexed by UTC, which differs from
  // GPS time by the offset itself (at most a second off across a leap).
  const std::optional<TimeNs> utc = gps ? gps_time::utc_from_gps_ns(*gps, config.gps_minus_utc_s) : std::nullopt;
  if (!gps || !utc) {
    fix.time_valid = false;
    fix.gps_minus_utc_s = config.gps_minus_utc_s.value_or(gps_time::latest_gps_minus_utc_s());
    return fix;
  }
  fix.gps_time_ns = *gps;
  fix.gps_minus_utc_s = config.gps_minus_utc_s.value_or(gps_time::gps_minus_utc_s(*utc));
  fix.satellites = config.satellites;
  fix.pdop = config.pdop;
  fix.hdop = config.hdop;
  fix.vdop = config.vdop;
  fix.horizontal_accuracy_m = config.horizontal_accuracy_m;
  fix.vertical_accuracy_m = config.vertical_accuracy_m;
  fix.speed_accuracy_m_s = config.speed_accuracy_m_s;
  fix.time_accuracy_ns = config.time_accuracy_ns;
  fix.geoid_separation_m = config.geoid_separation_m;
  fix.since_start_ms = static_cast<std::uint32_t>(frame.sample_counter * static_cast<std::uint64_t>(
                                                      frame.period_ns > 0 ? frame.period_ns / 1'000'000 : 0));
  if (frame.has_navigation) {
    fix.fix_type = GnssFixType::fix_3d;
    fix.latitude_rad = frame.latitude_rad;
    fix.longitude_rad = frame.longitude_rad;
    fix.height_m = frame.height_m;
    fix.velocity_ned_m_s = frame.velocity_ned_m_s;
  } else {
    fix.satellites = 0;
  }
  return fix;
}

}  // namespace imuemu::drivers
