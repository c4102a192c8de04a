// The World Magnetic Model (WMM2025), from its technical report: Chulliat
// et al., "The US/UK World Magnetic Model for 2025-2030: Technical Report",
// NOAA NCEI / BGS, 2025, Section 1.2 "Model equations" (issue 28). The
// coefficients are NOAA's WMM.COF (config/wmm/WMM2025.COF, generated into
// wmm2025_coefficients.inc by scripts/gen_wmm_coefficients.py).
//
// Steps (report equations in brackets):
//  * Time (eq. 9): g_n^m(t) = g_n^m(t0) + (t - t0) g_dot_n^m, same for h;
//    t in decimal years, t0 = 2025.0; valid 2025.0 <= t <= 2030.0.
//  * Geodetic (phi, lambda, h) -> geocentric spherical (phi', lambda, r)
//    (eqs. 7, 8) through WGS84 ECEF (core/earth.hpp): r = |x^e|,
//    phi' = atan2(z, sqrt(x^2 + y^2)).
//  * Potential V = a sum_{n=1}^{12} (a/r)^(n+1) sum_{m=0}^{n}
//    (g cos m lambda + h sin m lambda) P_n^m(sin phi') (eq. 4),
//    a = 6371200 m, with the Schmidt semi-normalised associated Legendre
//    functions (eq. 5)
//        P_n^m(mu) = sqrt((2 - delta_m0) (n-m)! / (n+m)!) P_{n,m}(mu),
//    P_{n,m}(mu) = (1 - mu^2)^(m/2) d^m P_n(mu) / d mu^m (no Condon-Shortley
//    phase), computed by the standard recursions
//        P_{n,n} = (2n-1) cos phi' P_{n-1,n-1},
//        (n-m) P_{n,m} = (2n-1) sin phi' P_{n-1,m} - (n+m-1) P_{n-2,m},
//    and their phi'-derivatives by differentiating those.
//  * Field in the geocentric frame, B = -grad V (eqs. 10-12), nT:
//        X' = -sum (a/r)^(n+2) sum (g cos m l + h sin m l) dP_n^m/dphi'
//        Y' =  sum (a/r)^(n+2) sum m (g sin m l - h cos m l) P_n^m / cos phi'
//        Z' = -sum (n+1) (a/r)^(n+2) sum (g cos m l + h sin m l) P_n^m
//    P_n^m / cos phi' for m >= 1 is computed directly (the recursions run
//    on it from P_{m,m} / cos phi' = (2m-1)!! cos^(m-1) phi'), so Y' has no
//    0/0 at the geographic poles: there it is the limit along the meridian
//    lambda, and the field is continuous.
//  * Rotation to the geodetic North-East-Down frame (eq. 17), psi = phi' - phi:
//        X = X' cos psi - Z' sin psi,  Y = Y',  Z = X' sin psi + Z' cos psi.
//  * Elements (eq. 19): H = hypot(X, Y), F = hypot(H, Z),
//    I = atan2(Z, H), D = atan2(Y, X).
#pragma once

#include "core/earth.hpp"
#include "core/types.hpp"

namespace imuemu::aiding {

struct WmmCoefficient {
  int n, m;
  double g_nt, h_nt, g_dot_nt_per_year, h_dot_nt_per_year;
};

inline constexpr int kWmmDegree = 12;
inline constexpr double kWmmReferenceRadius_m = 6371200.0;
// The model's validity (report Section 1.1): 5 years from the epoch,
// heights from 1 km below the ellipsoid to 850 km above it.
inline constexpr double kWmmValidYears = 5.0;
inline constexpr double kWmmMinHeight_m = -1000.0;
inline constexpr double kWmmMaxHeight_m = 850000.0;

struct MagneticElements {
  Vec3 ned_nt = Vec3::Zero();  // X north, Y east, Z down (nT)
  double horizontal_nt = 0.0;  // H
  double total_nt = 0.0;       // F
  double inclination_rad = 0.0;  // I, positive down
  double declination_rad = 0.0;  // D, positive east of true north
};

// The WMM2025 main field at a geodetic position and a decimal year.
// Throws SettingError for a NaN/infinite input, a latitude outside
// [-90, 90] deg, a height outside [-1, 850] km or a date outside
// [2025.0, 2030.0] (the model's stated validity; extrapolating further is
// not the model). Longitude: any finite value (periodic).
MagneticElements wmm2025(const earth::Geodetic& position, double decimal_year);

// The coefficient table the model uses (kWmm2025Coefficients), for tests
// and for `imuemu` to print its provenance.
const WmmCoefficient* wmm2025_coefficients(int& count) noexcept;
double wmm2025_epoch_year() noexcept;

}  // namespace imuemu::aiding
