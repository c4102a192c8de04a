// The magnetometer model; see magnetometer.hpp.
#include "core/aiding/magnetometer.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

#include "core/aiding/sample_index.hpp"
#include "core/setting_error.hpp"

namespace imuemu::aiding {

namespace {

constexpr unsigned kSensorMagnetometer = 17;

bool all_finite(const Mat3& m) { return m.allFinite(); }

}  // namespace

void validate(const MagnetometerSpec& s) {
  require_within("hard_iron_ut", "hard iron", s.hard_iron_ut,
                 {-kMagMaxField_ut, kMagMaxField_ut, "uT", "10 mT; vehicles' hard iron is a few hundred uT"});
  require_within("noise_rms_ut", "magnetometer noise", s.noise_rms_ut,
                 {0.0, kMagMaxNoise_ut, "uT", "1 mT RMS; LIS3MDL: 0.32 uT"});
  require_within("noise_density_ut_rt_hz", "magnetometer noise density", s.noise_density_ut_rt_hz,
                 {0.0, kMagMaxNoise_ut, "uT/sqrt(Hz)", "1 mT/sqrt(Hz)"});
  require_within("range_ut", "magnetometer range", s.range_ut,
                 {0.0, kMagMaxField_ut, "uT", "0 for none; LIS3MDL: 400..1600 uT"});
  require_within("lsb_ut", "magnetometer resolution", s.lsb_ut,
                 {0.0, s.range_ut > 0.0 ? s.range_ut : kMagMaxField_ut, "uT", "0 for none, within the range"});
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c)
      require_within("soft_iron", "soft iron element", s.soft_iron(r, c),
                     {-kMagMaxSoftIronElement, kMagMaxSoftIronElement, "", "dimensionless; calibrations find 0.8..1.2 on the diagonal"});
  if (!(std::abs(s.soft_iron.determinant()) >= kMagMinSoftIronDeterminant))
    throw SettingError("soft_iron", "soft iron matrix is singular (determinant " +
                                        setting_number(s.soft_iron.determinant()) + ", needs |det| >= 0.001)");
  if (!all_finite(s.sensor_from_body) ||
      !((s.sensor_from_body.transpose() * s.sensor_from_body - Mat3::Identity()).cwiseAbs().maxCoeff() <= 1e-9) ||
      !(std::abs(s.sensor_from_body.determinant() - 1.0) <= 1e-9))
    throw SettingError("sensor_from_body", "magnetometer mounting is not a rotation (R^T R = I, det +1)");
}

Vec3 body_field_ut(const Mat3& R_b_n, const Vec3& field_ned_nt) {
  if (!R_b_n.allFinite() || !field_ned_nt.allFinite())
    throw SettingError("field", "magnetometer: attitude or field is not finite");
  return R_b_n.transpose() * field_ned_nt * 1e-3;
}

Magnetometer::Magnetometer(const MagnetometerSpec& spec, double rate_hz, const std::string& device) : spec_(spec) {
  validate(spec);
  require_within("rate_hz", "magnetometer rate", rate_hz, {1e-9, kMagMaxRateHz, "Hz", "positive, at most 1 MHz"});
  total_ = spec.soft_iron * spec.sensor_from_body;
  const std::uint64_t dev = sensor::device_hash(device);
  for (unsigned a = 0; a < 3; ++a) {
    sigma_ut_[a] = std::sqrt(spec.noise_rms_ut[a] * spec.noise_rms_ut[a] +
                             spec.noise_density_ut_rt_hz[a] * spec.noise_density_ut_rt_hz[a] * rate_hz);
    stream_[a].state = sensor::stream_key(spec.seed, dev, kSensorMagnetometer, a, sensor::kTermWhite, 0);
  }
}

Vec3 Magnetometer::noise() noexcept {
  Vec3 w = Vec3::Zero();
  for (int a = 0; a < 3; ++a)
    if (sigma_ut_[a] > 0.0) w[a] = sigma_ut_[a] * stream_[a].gaussian();
  return w;
}

MagnetometerSample Magnetometer::measure(std::uint64_t k, const Vec3& field_body_ut) {
  check_sample_index("magnetometer", k, next_k_);
  require_within("field_ut", "true field", field_body_ut,
                 {-kMagMaxField_ut, kMagMaxField_ut, "uT", "10 mT; the Earth's is below 70 uT"});
  for (; next_k_ < k; ++next_k_) noise();
  ++next_k_;
  MagnetometerSample out;
  out.field_ut = total_ * field_body_ut + spec_.hard_iron_ut + noise();
  for (int a = 0; a < 3; ++a) {
    double& v = out.field_ut[a];
    // Quantise, then clip: the converter's largest code is the full scale.
    if (spec_.lsb_ut > 0.0) v = std::round(v / spec_.lsb_ut) * spec_.lsb_ut;
    if (spec_.range_ut > 0.0 && std::abs(v) >= spec_.range_ut) {
      v = std::copysign(spec_.range_ut, v);
      out.clipped_axes = static_cast<std::uint8_t>(out.clipped_axes | (1u << a));
    }
  }
  return out;
}

}  // namespace imuemu::aiding
