// The statistics a GNSS receiver's position and velocity errors must have
// (issue 28, acceptance 1 with the errors on), for tests that measure them
// on the wire (tests/drivers/test_gnss_errors.cpp on encoded bytes,
// tests/cli/test_gnss_gpsd.cpp through gpsd). Written from the model's
// definition (core/aiding/gnss.hpp: per axis white + first-order
// Gauss-Markov, the GM discretised exactly per fix), not from its code.
//
// Per axis, error = white (sigma_w) + Gauss-Markov (stationary sigma_g,
// phi = exp(-dt/tau) per fix), so sigma^2 = sigma_w^2 + sigma_g^2, plus the
// format's quantisation (step^2/12, a uniform rounding error) in the white
// part. For N fixes:
//   * mean: zero within z standard errors of a mean of correlated samples,
//     Var(mean) = (1/N^2) sum_{i,j} Cov(e_i, e_j)
//               = sigma_w^2/N + sigma_g^2 (N + 2 sum_{k=1}^{N-1} (N-k) phi^k) / N^2;
//   * sigma: the sample variance s^2 against its expectation
//     E[s^2] = sigma^2 - Var(mean) (correlated samples) within the
//     chi-square band of nu = N_eff degrees of freedom at +-z
//     (Wilson-Hilferty: chi2_q/nu = (1 - 2/(9 nu) + z sqrt(2/(9 nu)))^3),
//     N_eff = N / (1 + 2 sum_{k>=1} rho_k^2), the number of independent
//     samples whose sample variance varies as much (for a Gaussian process
//     Var(s^2) ~ (2 sigma^4 / N) (1 + 2 sum rho_k^2)); rho_k = a phi^k,
//     a = sigma_g^2 / sigma^2: sum rho_k^2 = a^2 phi^2 / (1 - phi^2).
// z = 4: a correct model fails one check in ~16 000 for a random seed (the
// tests fix their seeds, so they are deterministic).
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

namespace imuemu::test {

struct GnssAxisModel {
  double white = 0.0, gm_sigma = 0.0, tau_s = 1.0;
  double quant_step = 0.0;  // the wire's resolution (m or m/s)
};

struct GnssAxisStats {
  std::size_t n = 0;
  double mean = 0.0, sigma = 0.0;
  double configured_sigma = 0.0, mean_band = 0.0, sigma_lo = 0.0, sigma_hi = 0.0, n_eff = 0.0;
  bool ok = false;
};

// Checks one series of errors (EXPECTs, naming `what`) and returns the
// numbers; `line` gets them as one log line.
inline GnssAxisStats check_gnss_axis(const char* what, const std::vector<double>& errors, const GnssAxisModel& m,
                                     double dt_s, std::string& line, double z = 4.0) {
  GnssAxisStats r;
  r.n = errors.size();
  const double nd = static_cast<double>(r.n);
  if (r.n < 2) {
    ADD_FAILURE() << what << ": " << r.n << " samples";
    return r;
  }
  double sum = 0.0;
  for (double v : errors) sum += v;
  r.mean = sum / nd;
  double ss = 0.0;
  for (double v : errors) ss += (v - r.mean) * (v - r.mean);
  const double var = ss / (nd - 1.0);
  r.sigma = std::sqrt(var);
  const double sw2 = m.white * m.white + m.quant_step * m.quant_step / 12.0, sg2 = m.gm_sigma * m.gm_sigma;
  const double sigma2 = sw2 + sg2;
  r.configured_sigma = std::sqrt(sigma2);
  const double phi = sg2 > 0.0 ? std::exp(-dt_s / m.tau_s) : 0.0;
  double gm_pairs = nd;  // N + 2 sum_{k=1}^{N-1} (N-k) phi^k
  double pk = 1.0;
  for (std::size_t k = 1; k < r.n && sg2 > 0.0; ++k) {
    pk *= phi;
    if (pk < 1e-300) break;
    gm_pairs += 2.0 * (nd - static_cast<double>(k)) * pk;
  }
  const double var_mean = sw2 / nd + sg2 * gm_pairs / (nd * nd);
  r.mean_band = z * std::sqrt(var_mean);
  const double a = sg2 / sigma2;
  r.n_eff = nd / (1.0 + 2.0 * a * a * phi * phi / (1.0 - phi * phi));
  const double expected_var = sigma2 - var_mean;
  const auto wilson_hilferty = [&](double zz) {
    const double c = 2.0 / (9.0 * r.n_eff);
    return std::pow(std::max(0.0, 1.0 - c + zz * std::sqrt(c)), 3);
  };
  r.sigma_lo = std::sqrt(expected_var * wilson_hilferty(-z));
  r.sigma_hi = std::sqrt(expected_var * wilson_hilferty(z));
  EXPECT_LE(std::abs(r.mean), r.mean_band) << what << ": mean " << r.mean << " outside " << z
                                           << " standard errors (" << r.mean_band << ")";
  EXPECT_GE(r.sigma, r.sigma_lo) << what << ": sigma " << r.sigma << " below the band [" << r.sigma_lo << ", "
                                 << r.sigma_hi << "] of configured " << r.configured_sigma;
  EXPECT_LE(r.sigma, r.sigma_hi) << what << ": sigma " << r.sigma << " above the band [" << r.sigma_lo << ", "
                                 << r.sigma_hi << "] of configured " << r.configured_sigma;
  r.ok = std::abs(r.mean) <= r.mean_band && r.sigma >= r.sigma_lo && r.sigma <= r.sigma_hi;
  char buffer[360];
  std::snprintf(buffer, sizeof buffer,
                "%-20s N %6zu N_eff %7.0f  mean %+.5f (band +-%.5f)  sigma %.5f  configured %.5f  band [%.5f, %.5f]\n",
                what, r.n, r.n_eff, r.mean, r.mean_band, r.sigma, r.configured_sigma, r.sigma_lo, r.sigma_hi);
  line += buffer;
  return r;
}

}  // namespace imuemu::test
