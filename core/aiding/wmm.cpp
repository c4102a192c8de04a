// The World Magnetic Model; see wmm.hpp.
#include "core/aiding/wmm.hpp"

#include <array>
#include <cmath>
#include <numbers>

#include "core/setting_error.hpp"

namespace imuemu::aiding {

namespace {

#include "core/aiding/wmm2025_coefficients.inc"

constexpr int kRows = static_cast<int>(sizeof kWmm2025Coefficients / sizeof kWmm2025Coefficients[0]);
static_assert(kRows == kWmmDegree * (kWmmDegree + 3) / 2, "n = 1..12, m = 0..n");

constexpr int index_of(int n, int m) { return n * (n + 1) / 2 + m; }
constexpr int kTerms = index_of(kWmmDegree, kWmmDegree) + 1;

// sqrt((2 - delta_m0) (n-m)! / (n+m)!), computed once.
std::array<double, kTerms> make_schmidt() {
  std::array<double, kTerms> s{};
  for (int n = 0; n <= kWmmDegree; ++n)
    for (int m = 0; m <= n; ++m) {
      double ratio = m == 0 ? 1.0 : 2.0;
      for (int k = n - m + 1; k <= n + m; ++k) ratio /= k;
      s[index_of(n, m)] = std::sqrt(ratio);
    }
  return s;
}

}  // namespace

const WmmCoefficient* wmm2025_coefficients(int& count) noexcept {
  count = kRows;
  return kWmm2025Coefficients;
}

double wmm2025_epoch_year() noexcept { return kWmm2025EpochYear; }

MagneticElements wmm2025(const earth::Geodetic& g, double t_year) {
  constexpr double kDeg = std::numbers::pi / 180.0;
  require_within("latitude", "latitude", g.latitude_rad / kDeg, {-90.0 - 1e-9, 90.0 + 1e-9, "deg", "geodetic latitude"});
  if (!std::isfinite(g.longitude_rad))
    require_within("longitude", "longitude", g.longitude_rad / kDeg, {-1e300, 1e300, "deg", "finite"});
  require_within("height_m", "height", g.height_m,
                 {kWmmMinHeight_m, kWmmMaxHeight_m, "m", "the WMM's validity: -1 km to 850 km above the ellipsoid"});
  require_within("decimal_year", "date", t_year,
                 {kWmm2025EpochYear, kWmm2025EpochYear + kWmmValidYears, "year", "WMM2025 is valid 2025.0 to 2030.0"});
  static const std::array<double, kTerms> schmidt = make_schmidt();

  // Geocentric spherical coordinates (report eqs. 7, 8).
  const Vec3 x = earth::ecef_from_geodetic(g);
  const double p = std::hypot(x.x(), x.y());
  const double r = x.norm();
  const double phi_c = std::atan2(x.z(), p);
  const double mu = std::sin(phi_c), nu = std::cos(phi_c);
  const double lambda = g.longitude_rad;

  // Unnormalised P_{n,m}, dP_{n,m}/dphi' and (m >= 1) Q_{n,m} = P_{n,m} / cos phi'.
  std::array<double, kTerms> P{}, dP{}, Q{};
  P[0] = 1.0;
  for (int m = 0; m <= kWmmDegree; ++m) {
    if (m >= 1) {
      const int mm = index_of(m, m), prev = index_of(m - 1, m - 1);
      const double f = 2.0 * m - 1.0;
      P[mm] = f * nu * P[prev];
      dP[mm] = f * (nu * dP[prev] - mu * P[prev]);
      Q[mm] = m == 1 ? 1.0 : f * nu * Q[prev];  // (2m-1)!! nu^(m-1)
    }
    for (int n = m + 1; n <= kWmmDegree; ++n) {
      const int i = index_of(n, m), i1 = index_of(n - 1, m);
      const double a = (2.0 * n - 1.0) / (n - m);
      const double b = n >= m + 2 ? (n + m - 1.0) / (n - m) : 0.0;
      const int i2 = n >= m + 2 ? index_of(n - 2, m) : i1;
      P[i] = a * mu * P[i1] - b * P[i2];
      dP[i] = a * (nu * P[i1] + mu * dP[i1]) - b * dP[i2];
      Q[i] = a * mu * Q[i1] - b * Q[i2];
    }
  }

  const double dt = t_year - kWmm2025EpochYear;
  const double ratio = kWmmReferenceRadius_m / r;
  std::array<double, kWmmDegree + 1> cos_ml{}, sin_ml{};
  for (int m = 0; m <= kWmmDegree; ++m) {
    cos_ml[m] = std::cos(m * lambda);
    sin_ml[m] = std::sin(m * lambda);
  }
  double xs = 0.0, ys = 0.0, zs = 0.0;
  double ratio_pow = ratio * ratio;  // (a/r)^(n+2) for n = 0
  int row = 0;
  for (int n = 1; n <= kWmmDegree; ++n) {
    ratio_pow *= ratio;
    for (int m = 0; m <= n; ++m, ++row) {
      const WmmCoefficient& c = kWmm2025Coefficients[row];
      const double gnm = c.g_nt + dt * c.g_dot_nt_per_year;
      const double hnm = c.h_nt + dt * c.h_dot_nt_per_year;
      const int i = index_of(n, m);
      const double s = schmidt[i];
      const double along = gnm * cos_ml[m] + hnm * sin_ml[m];
      xs -= ratio_pow * along * s * dP[i];
      zs -= (n + 1) * ratio_pow * along * s * P[i];
      if (m >= 1) ys += ratio_pow * m * (gnm * sin_ml[m] - hnm * cos_ml[m]) * s * Q[i];
    }
  }

  // Geocentric -> geodetic NED (report eq. 17).
  const double psi = phi_c - g.latitude_rad;
  MagneticElements e;
  e.ned_nt = Vec3(xs * std::cos(psi) - zs * std::sin(psi), ys, xs * std::sin(psi) + zs * std::cos(psi));
  e.horizontal_nt = std::hypot(e.ned_nt.x(), e.ned_nt.y());
  e.total_nt = std::hypot(e.horizontal_nt, e.ned_nt.z());
  e.inclination_rad = std::atan2(e.ned_nt.z(), e.horizontal_nt);
  e.declination_rad = std::atan2(e.ned_nt.y(), e.ned_nt.x());
  return e;
}

}  // namespace imuemu::aiding
