// The magnetometer: the Earth's field (core/aiding/wmm.hpp) in the sensor's
// axes, with the errors magnetometer datasheets and compass calibration
// state (issue 28). Pure maths, seeded, no I/O.
//
// Frames (thesis §1.3): the attitude is R_b^n (body FRD -> local NED) for
// the flat scene, or R_b^e for the ecef scene with R_n^e of the site
// (attitude::ned_to_ecef); the field is known in NED:
//     b^b = (R_b^n)^T b^n            (body_field_ut)
//     b^s = R_b^s b^b                (mounting; identity by default)
// The sensor then reads (the standard hard/soft-iron model, e.g. Vasconcelos
// et al., IEEE TAES 47(2), 2011, eq. 3; per-axis noise added afterwards):
//     m = W b^s + h + w,   w ~ N(0, diag(sigma^2))
// with W the 3x3 soft-iron matrix (scale factors, cross-coupling,
// induced fields; dimensionless, identity = none) and h the hard-iron
// offset (permanent magnetisation near the sensor). Units: microtesla, as
// datasheets state them in gauss or uT (1 G = 100 uT; 1 uT = 1000 nT):
//  * noise_rms_ut: per-sample RMS at the output rate (LIS3MDL at +-4 G:
//    3.2 mG = 0.32 uT on x/y); noise_density_ut_rt_hz: the IMU's one-sided
//    PSD convention (sigma = N sqrt(fs)); the variances add.
//  * range_ut: full scale +-range, each axis clipped (flagged); 0: none.
//  * lsb_ut: quantisation step (LIS3MDL +-4 G: 1/6842 G = 0.0146 uT).
// Random terms have their own stream keyed by (seed, device, sensor 17,
// axis, term), as the IMU's.
#pragma once

#include <cstdint>
#include <string>

#include "core/sensor/sensor_model.hpp"
#include "core/types.hpp"

namespace imuemu::aiding {

struct MagnetometerSpec {
  Vec3 hard_iron_ut = Vec3::Zero();
  Mat3 soft_iron = Mat3::Identity();
  Mat3 sensor_from_body = Mat3::Identity();  // R_b^s, a rotation
  Vec3 noise_rms_ut = Vec3::Zero();
  Vec3 noise_density_ut_rt_hz = Vec3::Zero();
  double range_ut = 0.0;
  double lsb_ut = 0.0;
  std::uint64_t seed = 0;
};

// Bounds: the Earth's field is 22..67 uT; vehicles' hard iron reaches a few
// hundred uT. 10 mT (100 G) is beyond any compass part's full scale
// (+-16 G = 1600 uT for the LIS3MDL; +-49 G for the AK09916).
inline constexpr double kMagMaxField_ut = 10000.0;
inline constexpr double kMagMaxNoise_ut = 1000.0;
inline constexpr double kMagMaxSoftIronElement = 10.0;
inline constexpr double kMagMinSoftIronDeterminant = 1e-3;
inline constexpr double kMagMaxRateHz = 1e6;

// Throws SettingError (key: the field) for a spec outside the bounds, a
// singular soft-iron matrix (|det| < 1e-3: no material maps a field onto a
// plane, and calibration could not undo it) or a mounting that is not a
// rotation (R^T R = I, det +1, within 1e-9).
void validate(const MagnetometerSpec& spec);

// (R_b^n)^T b^n in uT from b^n in nT. Throws SettingError for a non-finite input.
Vec3 body_field_ut(const Mat3& R_b_n, const Vec3& field_ned_nt);

struct MagnetometerSample {
  Vec3 field_ut = Vec3::Zero();  // sensor axes
  std::uint8_t clipped_axes = 0; // bit i: axis i hit +-range
};

class Magnetometer {
 public:
  // Throws as validate and for a rate outside (0, 1 MHz].
  Magnetometer(const MagnetometerSpec& spec, double rate_hz, const std::string& device);
  // Sample k (k >= next_index(); skipped samples' noise is drawn, so sample
  // k is the same whichever samples were asked for) of the true field in
  // body axes (uT). Throws for k < next_index() or more than 2^28 after it
  // (sample_index.hpp), or a non-finite field or one beyond kMagMaxField_ut;
  // a refused call changes nothing.
  MagnetometerSample measure(std::uint64_t k, const Vec3& field_body_ut);
  std::uint64_t next_index() const { return next_k_; }

 private:
  Vec3 noise() noexcept;
  MagnetometerSpec spec_;
  Mat3 total_ = Mat3::Identity();  // W R_b^s
  Vec3 sigma_ut_ = Vec3::Zero();
  std::uint64_t next_k_ = 0;
  sensor::Stream stream_[3];
};

}  // namespace imuemu::aiding
