// GNSS truth and errors; see gnss.hpp.
#include "core/aiding/gnss.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

#include "core/attitude.hpp"
#include "core/aiding/sample_index.hpp"
#include "core/setting_error.hpp"
#include "core/time_arith.hpp"

namespace imuemu::aiding {

namespace {

constexpr unsigned kSensorGnss = 18;

void need_finite(const Vec3& v, const char* key) {
  if (!v.allFinite()) throw SettingError(key, std::string("GNSS: ") + key + " is not finite");
}

}  // namespace

AntennaTruth antenna_truth(const Vec3& position_m, const Vec3& velocity_m_s, const Mat3& R_b_f,
                           const Vec3& omega_fb_b_rad_s, const Vec3& lever_arm_b_m) {
  need_finite(position_m, "position_m");
  need_finite(velocity_m_s, "velocity_m_s");
  need_finite(omega_fb_b_rad_s, "angular_rate_rad_s");
  if (!R_b_f.allFinite()) throw SettingError("attitude", "GNSS: attitude is not finite");
  require_within("lever_arm_m", "antenna lever arm", lever_arm_b_m,
                 {-kMaxLeverArm_m, kMaxLeverArm_m, "m", "body axes; an airliner spans 80 m"});
  AntennaTruth a;
  a.position_m = position_m + R_b_f * lever_arm_b_m;
  a.velocity_m_s = velocity_m_s + R_b_f * omega_fb_b_rad_s.cross(lever_arm_b_m);
  return a;
}

earth::Geodetic offset_geodetic(const Vec3& x_e_m, const Vec3& d_ned_m) {
  need_finite(x_e_m, "position_m");
  need_finite(d_ned_m, "error_m");
  const earth::Geodetic at = earth::geodetic_from_ecef(x_e_m);
  return earth::geodetic_from_ecef(x_e_m + attitude::ned_to_ecef(at.latitude_rad, at.longitude_rad) * d_ned_m);
}

Vec3 ned_from_ecef_velocity(const earth::Geodetic& at, const Vec3& v_e_m_s) {
  need_finite(v_e_m_s, "velocity_m_s");
  if (!std::isfinite(at.latitude_rad) || !std::isfinite(at.longitude_rad))
    throw SettingError("position", "GNSS: position is not finite");
  return attitude::ned_to_ecef(at.latitude_rad, at.longitude_rad).transpose() * v_e_m_s;
}

double sigma_from_cep_m(double cep_m) {
  require_within("cep_m", "CEP", cep_m, {0.0, kGnssMaxSigma_m, "m", "a 50 % circle"});
  return cep_m / std::sqrt(2.0 * std::log(2.0));
}

void validate(const GnssSpec& s) {
  const SettingBound sigma{0.0, kGnssMaxSigma_m, "m", "10 km; a fix worse than that is no fix"};
  require_within("horizontal_white_m", "GNSS horizontal white noise", s.horizontal_white_m, sigma);
  require_within("horizontal_gm_sigma_m", "GNSS horizontal Gauss-Markov sigma", s.horizontal_gm_sigma_m, sigma);
  require_within("vertical_white_m", "GNSS vertical white noise", s.vertical_white_m, sigma);
  require_within("vertical_gm_sigma_m", "GNSS vertical Gauss-Markov sigma", s.vertical_gm_sigma_m, sigma);
  const SettingBound tau{sensor::kMinTauS, sensor::kMaxTauS, "s", "as the IMU's Gauss-Markov tau"};
  require_within("horizontal_gm_tau_s", "GNSS horizontal Gauss-Markov tau", s.horizontal_gm_tau_s, tau);
  require_within("vertical_gm_tau_s", "GNSS vertical Gauss-Markov tau", s.vertical_gm_tau_s, tau);
  const SettingBound vel{0.0, kGnssMaxVelocitySigma_m_s, "m/s", "100 m/s; receivers state 0.05..0.5 m/s"};
  require_within("horizontal_velocity_m_s", "GNSS horizontal velocity noise", s.horizontal_velocity_m_s, vel);
  require_within("vertical_velocity_m_s", "GNSS vertical velocity noise", s.vertical_velocity_m_s, vel);
  require_within("rate_hz", "GNSS output rate", s.rate_hz, {0.001, 1000.0, "Hz", "receivers: 1..25 Hz"});
  const double period_ms = 1000.0 / s.rate_hz;
  if (std::abs(period_ms - std::round(period_ms)) > 1e-9 * period_ms)
    throw SettingError("rate_hz", "GNSS output rate " + setting_number(s.rate_hz) +
                                      " Hz is not a whole number of milliseconds per fix (u-blox CFG-RATE)");
  require_within("latency_ms", "GNSS latency", s.latency_ms, {0.0, 10000.0, "ms", "receivers: 20..100 ms"});
  require_within("time_to_first_fix_s", "GNSS time to first fix", s.time_to_first_fix_s,
                 {0.0, 86400.0, "s", "a cold start is ~30 s"});
  if (static_cast<unsigned>(s.fix_type) > static_cast<unsigned>(GnssFixType::gnss_dr))
    throw SettingError("fix_type", "GNSS fix type " + std::to_string(static_cast<unsigned>(s.fix_type)) + " is not 0..4");
  require_within("satellites", "GNSS satellites", s.satellites, {0.0, 255.0, "", "UBX numSV is a byte"});
  const SettingBound dop{0.0, 99.99, "", "NMEA prints DOP as x.xx, up to 99.99"};
  require_within("hdop", "HDOP", s.hdop, dop);
  require_within("vdop", "VDOP", s.vdop, dop);
  require_within("pdop", "PDOP", s.pdop, dop);
}

GnssAccuracy stated_accuracy(const GnssSpec& s) {
  GnssAccuracy a;
  a.horizontal_m = std::sqrt(2.0 * (s.horizontal_white_m * s.horizontal_white_m +
                                    s.horizontal_gm_sigma_m * s.horizontal_gm_sigma_m));
  a.vertical_m = std::hypot(s.vertical_white_m, s.vertical_gm_sigma_m);
  a.speed_m_s = std::sqrt(2.0 * s.horizontal_velocity_m_s * s.horizontal_velocity_m_s +
                          s.vertical_velocity_m_s * s.vertical_velocity_m_s);
  return a;
}

GnssReceiverModel::GnssReceiverModel(const GnssSpec& spec, TimeNs gps_at_start_ns, const std::string& device)
    : spec_(spec) {
  validate(spec);
  if (gps_at_start_ns < 0)
    throw std::invalid_argument("GNSS: power-on GPS time " + std::to_string(gps_at_start_ns) + " ns is before 1980-01-06");
  period_ns_ = static_cast<TimeNs>(std::llround(1000.0 / spec.rate_hz)) * 1'000'000;
  latency_ns_ = static_cast<TimeNs>(std::llround(spec.latency_ms * 1e6));
  // First epoch: the first whole period at or after power-on + TTFF.
  const TimeNs ready = saturating_add_ns(gps_at_start_ns, static_cast<TimeNs>(std::llround(spec.time_to_first_fix_s * 1e9)));
  const TimeNs periods = ready / period_ns_ + (ready % period_ns_ != 0 ? 1 : 0);
  first_epoch_ns_ = saturating_mul_ns(periods, period_ns_);
  const double dt_s = static_cast<double>(period_ns_) * 1e-9;
  const std::uint64_t dev = sensor::device_hash(device);
  for (unsigned a = 0; a < 3; ++a) {
    const bool h = a < 2;
    white_[a] = h ? spec.horizontal_white_m : spec.vertical_white_m;
    vel_[a] = h ? spec.horizontal_velocity_m_s : spec.vertical_velocity_m_s;
    const double sigma = h ? spec.horizontal_gm_sigma_m : spec.vertical_gm_sigma_m;
    phi_[a] = std::exp(-dt_s / (h ? spec.horizontal_gm_tau_s : spec.vertical_gm_tau_s));
    drive_[a] = sigma * std::sqrt(1.0 - phi_[a] * phi_[a]);
    white_stream_[a].state = sensor::stream_key(spec.seed, dev, kSensorGnss, a, sensor::kTermWhite, 0);
    gm_stream_[a].state = sensor::stream_key(spec.seed, dev, kSensorGnss, a, sensor::kTermGaussMarkov, 0);
    vel_stream_[a].state = sensor::stream_key(spec.seed, dev, kSensorGnss, a, sensor::kTermVelocity, 0);
    gm_[a] = sigma > 0.0 ? sigma * gm_stream_[a].gaussian() : 0.0;  // stationary start
  }
}

std::optional<TimeNs> GnssReceiverModel::epoch_gps_ns(std::uint64_t j) const {
  if (j > static_cast<std::uint64_t>(kMaxTimeNs)) return std::nullopt;
  const auto offset = checked_mul_ns(static_cast<TimeNs>(j), period_ns_);
  return offset ? checked_add_ns(first_epoch_ns_, *offset) : std::nullopt;
}

GnssError GnssReceiverModel::error(std::uint64_t j) {
  check_sample_index("GNSS", j, next_j_);
  GnssError e;
  for (; next_j_ <= j; ++next_j_) {
    for (int a = 0; a < 3; ++a) {
      if (next_j_ > 0 && drive_[a] > 0.0) gm_[a] = phi_[a] * gm_[a] + drive_[a] * gm_stream_[a].gaussian();
      const double w = white_[a] > 0.0 ? white_[a] * white_stream_[a].gaussian() : 0.0;
      e.position_ned_m[a] = gm_[a] + w;
      e.velocity_ned_m_s[a] = vel_[a] > 0.0 ? vel_[a] * vel_stream_[a].gaussian() : 0.0;
    }
  }
  return e;
}

}  // namespace imuemu::aiding
