// The error-free GNSS epoch of one device sample; see gnss_fix.hpp.
#include "drivers/gnss_fix.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "core/earth.hpp"
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

namespace {

// The core model's spec for the configured error terms at the device rate.
aiding::GnssSpec error_spec(const GnssErrorConfig& e, double rate_hz) {
  if (!(rate_hz > 0.0) || !std::isfinite(rate_hz))
    throw std::invalid_argument("GNSS errors: the receiver's navigation rate is not known (" + std::to_string(rate_hz) +
                                " Hz)");
  aiding::GnssSpec s;
  s.horizontal_white_m = e.horizontal_white_m;
  s.horizontal_gm_sigma_m = e.horizontal_gm_sigma_m;
  s.horizontal_gm_tau_s = e.horizontal_gm_tau_s;
  s.vertical_white_m = e.vertical_white_m;
  s.vertical_gm_sigma_m = e.vertical_gm_sigma_m;
  s.vertical_gm_tau_s = e.vertical_gm_tau_s;
  s.horizontal_velocity_m_s = e.horizontal_velocity_m_s;
  s.vertical_velocity_m_s = e.vertical_velocity_m_s;
  // A whole number of ms per fix (see the header); at least 1 ms.
  const double period_ms = std::max(1.0, std::round(1000.0 / rate_hz));
  s.rate_hz = 1000.0 / period_ms;
  s.seed = e.seed;
  return s;
}

}  // namespace

GnssFixSource::GnssFixSource(const GnssReceiverConfig& config, double rate_hz, const std::string& device_name)
    : config_(config) {
  if (!config_.errors.any()) return;
  initial_.emplace(error_spec(config_.errors, rate_hz), 0, device_name);
  model_ = initial_;
}

GnssFix GnssFixSource::fix(const ImuFrameInput& frame, std::uint64_t j) {
  GnssFix f = fix_from_frame(frame, config_);
  if (!model_ || f.fix_type == GnssFixType::none) return f;
  if (!last_j_ || *last_j_ != j) {  // the same fix again (a link fault's duplicate): the same error
    if (j < model_->next_index()) model_ = initial_;  // a copy of plain numbers: no allocation
    last_error_ = model_->error(j);
    last_j_ = j;
  }
  const aiding::GnssError& e = last_error_;
  const Vec3 x_e = earth::ecef_from_geodetic({f.latitude_rad, f.longitude_rad, f.height_m});
  if (!x_e.allFinite() || !f.velocity_ned_m_s.allFinite()) return f;  // nothing to perturb (the encoders bound it)
  const earth::Geodetic g = aiding::offset_geodetic(x_e, e.position_ned_m);
  f.latitude_rad = g.latitude_rad;
  f.longitude_rad = g.longitude_rad;
  f.height_m = g.height_m;
  f.velocity_ned_m_s += e.velocity_ned_m_s;
  return f;
}

}  // namespace imuemu::drivers
