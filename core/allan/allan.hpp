// Allan-variance analysis of one sensor axis (pure maths, no I/O): the
// overlapping Allan deviation on a log-spaced tau grid, its confidence
// intervals from equivalent degrees of freedom and chi-squared quantiles, and
// the five-term noise fit of IEEE Std 952-1997 Annex C. docs/allan.md has the
// definitions and conventions; every formula below cites its source.
//
// Conventions. The input is a uniformly sampled rate series y_k (gyro rad/s
// or accelerometer m/s^2) with interval tau0. For tau = m tau0 the
// overlapping Allan variance is (IEEE Std 1139-2008 / NIST SP 1065 Eq. 11,
// written with the integrated series theta_k = sum_{j<k} y_j, in units of
// rate x samples):
//   sigma^2(m tau0) = 1 / (2 m^2 M) * sum_{i=0}^{M-1} (theta_{i+2m} - 2 theta_{i+m} + theta_i)^2,
//   M = N + 1 - 2m terms for N rate samples (N + 1 phase points),
// which is O(N) per tau. The five terms of the fit are
//   sigma^2(tau) = 3 Q^2 / tau^2 + N^2 / tau + (2 ln 2 / pi) B^2 + K^2 tau / 3 + R^2 tau^2 / 2
// (quantisation Q, angle/velocity random walk N, bias instability B whose
// deviation floor is sqrt(2 ln 2 / pi) B = 0.664 B, rate random walk K, rate
// ramp R), in the input's units: Q in rate*s, N in rate*sqrt(s), B in rate,
// K in rate/sqrt(s), R in rate/s.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace imuemu::allan {

// ------------------------------------------------------------ the estimate

// Averaging factors m (tau = m tau0) for n rate samples: round(10^(k / per
// decade)) for k = 0, 1, ..., without repeats, up to floor(n * max_fraction)
// (and never beyond n / 2, where fewer than two terms are left). Empty when
// n < 2. std::invalid_argument for points_per_decade < 1 or max_fraction
// outside (0, 0.5].
std::vector<std::int64_t> log_spaced_factors(std::int64_t sample_count, int points_per_decade = 10,
                                             double max_fraction = 0.25);

// theta_k = sum_{j<k} (y_j - offset), k = 0..n (n + 1 values). Removing a
// constant offset (the caller passes the mean) leaves every Allan variance
// unchanged, because the second difference cancels a linear theta, and keeps
// the cumulative sum small so its second differences do not lose digits.
std::vector<double> integrate_rate(std::span<const double> rate, double offset);

// The overlapping Allan variance at averaging factor m, from the integrated
// series of integrate_rate (n + 1 values), in squared rate units, using the
// differences that start every `stride` samples (1: every start, the fully
// overlapping estimator). std::invalid_argument unless 1 <= m, 2m <
// theta.size() and stride >= 1.
double overlapping_allan_variance(std::span<const double> theta, std::int64_t m, std::int64_t stride = 1);

// The stride analyse() uses at factor m: max(1, m / ratio). With ratio 64 a
// difference still overlaps the next by 63/64 of its span; the estimator's
// variance is that of the fully overlapping one to O((stride/m)^2) (its
// terms' correlation is a smooth function of the start offset, sampled 64
// times per m instead of m times), so the EDF formulas apply unchanged
// (tests/core/test_allan.cpp checks the coverage), while a 24-hour 200 Hz axis
// costs about 23 N instead of 64 N difference evaluations. ratio 0: always 1.
std::int64_t stride_for(std::int64_t m, std::int64_t ratio);

// ------------------------------------------------- degrees of freedom, CI

// Power-law noise of the rate, named after the clock literature (the rate is
// the "frequency", the integrated angle/velocity the "phase"): white PM is
// quantisation (sigma ~ tau^-1), white FM angle/velocity random walk
// (tau^-1/2), flicker FM bias instability (flat), random-walk FM rate random
// walk (tau^+1/2).
enum class NoiseType { white_pm, white_fm, flicker_fm, random_walk_fm };
std::string to_string(NoiseType type);

// Equivalent chi-squared degrees of freedom of the overlapping Allan variance
// at factor m from n rate samples (n + 1 phase points), for the given
// dominant noise: the approximations of Howe, Allan and Barnes (1981), as
// tabulated in NIST SP 1065 (Riley 2008) Table 5 and used by Stable32. With
// P = n + 1 phase points:
//   white PM:  (P + 1)(P - 2m) / (2 (P - m))
//   white FM:  (3 (P - 1) / (2m) - 2 (P - 2) / P) * 4m^2 / (4m^2 + 5)
//   flicker FM: m = 1: 2 (P - 2) / (2.3 P - 4.9); m >= 2: 5 P^2 / (4m (P + 3m))
//   random-walk FM: (P - 2) / m * ((P - 1)^2 - 3m (P - 1) + 4m^2) / (P - 3)^2
// Never below 1 (the formulas are asymptotic; at the largest tau of a short
// series they can fall below one degree of freedom, which would claim less
// than a single difference's worth of information).
double equivalent_degrees_of_freedom(NoiseType type, std::int64_t sample_count, std::int64_t m);

// Regularised lower incomplete gamma P(a, x) (series for x < a + 1, Legendre
// continued fraction otherwise), the CDF of chi^2 with dof = 2a at 2x.
double regularized_gamma_p(double a, double x);
double chi_squared_cdf(double x, double dof);
// Inverse of chi_squared_cdf: Wilson-Hilferty start, then safeguarded Newton
// on the CDF (bisection when a step leaves the bracket) to 1e-12 relative.
// std::invalid_argument unless 0 < p < 1 and dof > 0.
double chi_squared_quantile(double p, double dof);

// Two-sided confidence interval of a deviation estimated with `dof` degrees of
// freedom: sigma^2 in [dof s^2 / chi2(1 - a/2), dof s^2 / chi2(a/2)], a = 1 - confidence
// (NIST SP 1065 Eq. 44-45).
struct Interval {
  double low = 0.0, high = 0.0;
};
Interval deviation_interval(double deviation, double dof, double confidence);

// ----------------------------------------------------------------- the fit

enum Term : int { quantization = 0, white = 1, bias_instability = 2, rate_random_walk = 3, rate_ramp = 4 };
inline constexpr int kTermCount = 5;
std::string term_name(int term);  // "quantization", "white", "bias_instability", ...

// sigma^2 contribution of a term with coefficient 1 at tau (IEEE Std 952-1997
// Annex C, Table C.1): 3/tau^2, 1/tau, 2 ln2/pi, tau/3, tau^2/2.
double term_basis(int term, double tau_s);
// log-log slope of sigma^2 of each term: -2, -1, 0, +1, +2.
int term_variance_slope(int term);

struct Point {
  std::int64_t m = 0;
  double tau_s = 0.0;
  double adev = 0.0;      // overlapping Allan deviation, rate units
  double ci_low = 0.0;    // confidence interval of adev
  double ci_high = 0.0;
  double edf = 0.0;       // equivalent degrees of freedom used for the interval
  NoiseType noise = NoiseType::white_fm;  // dominant noise assumed for the EDF
  bool in_fit = false;    // within the fit's tau range
};

struct FittedTerm {
  bool enabled = false;
  // The coefficient (Q, N, B, K or R, input units as in the header comment),
  // >= 0; 0 when the non-negative fit drops the term.
  double value = 0.0;
  // 1-sigma uncertainty of `value`, from the covariance of the squared
  // coefficient carried to the coefficient as sigma_c / (2 value).
  // `sigma` is honest: the sandwich covariance of the weighted least squares
  // with the full covariance of the Allan variance estimates across tau
  // (allan_variance_covariance), which are strongly correlated (neighbouring
  // tau share most of their differences). `formal_sigma` is what the weighted
  // least squares reports when it treats every tau as independent,
  // (A^T W A)^-1; kept for comparison, it is 1.5-3x too small at 10 points
  // per decade (docs/allan.md). 0 for a dropped term.
  double sigma = 0.0;
  double formal_sigma = 0.0;
  // Interval of `value` at the analysis' confidence: normal on the squared
  // coefficient with `sigma`'s variance, clipped at 0.
  double low = 0.0, high = 0.0;
};

struct AnalysisOptions {
  int points_per_decade = 10;
  double max_tau_fraction = 0.25;  // largest tau = fraction of the record
  double confidence = 0.90;
  // Terms the fit may use (all by default) and the tau range it sees
  // (<= 0: no bound).
  std::array<bool, kTermCount> terms{true, true, true, true, true};
  double fit_min_tau_s = 0.0, fit_max_tau_s = 0.0;
  // See stride_for: 0 computes every overlapping difference.
  std::int64_t overlap_ratio = 64;
  // The fitted terms' sandwich covariance (FittedTerm::sigma), which costs
  // O(points^2 x 256) evaluations (about 15 ms for a 4096-sample series, 50 ms
  // for a 2-hour 200 Hz one). false: `sigma`, `low` and `high` come from the
  // independent-tau covariance (formal_sigma), too narrow; for callers that
  // use only the per-tau intervals.
  bool coefficient_covariance = true;
};

struct Analysis {
  double tau0_s = 0.0;
  std::int64_t sample_count = 0;
  std::vector<Point> points;
  std::array<FittedTerm, kTermCount> terms;
  // The fitted model's deviation at each point's tau, and each term's own.
  std::vector<double> model_adev;
  std::array<std::vector<double>, kTermCount> term_adev;
  int fit_iterations = 0;
};

// The whole analysis of one axis: estimate, noise identification, EDF and
// interval per tau, and the five-term fit by weighted non-negative least
// squares in sigma^2. Weights are EDF / (2 model^2) (the variance of a
// chi^2-distributed variance estimate), iterated with the model in place of
// the estimate; the dominant noise at each tau (for its EDF) is the term with
// the largest share of the fitted model there (before the first fit: the
// local slope of the estimate). Non-negativity: exact, by solving every
// subset of the enabled terms and keeping the best feasible one (5 terms:
// 31 subsets). The fitted terms' covariance is the sandwich
// G A^T W S W A G, G = (A^T W A)^-1, with S the covariance of the estimates
// across tau under the fitted model (allan_variance_covariance), not the
// independent-tau G alone. std::invalid_argument for tau0 <= 0, fewer than
// kMinSamples samples or a non-finite value (naming the sample index).
inline constexpr std::int64_t kMinSamples = 32;
Analysis analyse(std::span<const double> rate, double tau0_s, const AnalysisOptions& options = {});

// Covariance of the overlapping Allan variance estimates at factors m1 and
// m2 (every start, n rate samples at tau0) when the rate is the five-term
// model with squared coefficients c (Q^2, N^2, B^2, K^2, R^2; the ramp is
// deterministic and adds none), for Gaussian noise. Each estimate is
// s^2(m) = 1/(2 m^2 M) sum_i d_i^2 with d_i the second difference of the
// integrated series at span m, M = n + 1 - 2m, so
//   Cov(s^2(m1), s^2(m2)) = 2 / (4 m1^2 m2^2 M1 M2) sum_i sum_j E[d1_i d2_j]^2
// (Isserlis), and E[d1_i d2_j] = sum_a sum_b h1_a h2_b G(j - i + b - a) with
// h = (1, -2, 1) at offsets (0, m, 2m) and G the generalised covariance of
// the integrated series (the second difference annihilates constants and
// lines, so G matters only up to a linear term; Matheron 1973):
//   quantisation (white PM, theta white of variance Q^2/tau0^2): G = Q^2/tau0^2 [l = 0]
//   white FM (random-walk theta, step variance N^2/tau0): G = -N^2 |l| / (2 tau0)
//   flicker FM: G = B^2 l^2 ln|l| / (2 pi)
//   rate random walk (integrated random walk, rate step variance K^2 tau0): G = K^2 tau0 (|l|^3 - |l|) / 12
// in (rate x samples)^2. Each gives the Allan variance of its basis (the
// flicker G exactly at every m, the random walk's as (2m^2 + 1)/(6m) tau0 K^2;
// tests/core/test_allan.cpp). The sum over lags is exact while the support is at
// most 256 lags wide (white PM .. random walk: E[d1 d2] = 0 outside
// -2 m2 <= l <= 2 m1); wider ranges are sampled at 256 points (the summand is
// piecewise polynomial; white PM's spikes at the lags a m1 - b m2 are added
// exactly), and the flicker's long-range tail (E[d1 d2] ~ l^-2)
// is summed on 32 geometric cells a side out to 16 x the support.
// std::invalid_argument unless 1 <= m and 2m < n + 1 for both.
double allan_variance_covariance(const std::array<double, kTermCount>& squared_coefficients, double tau0_s,
                                 std::int64_t sample_count, std::int64_t m1, std::int64_t m2);

// Deviation of the fitted model at tau.
double model_adev(const std::array<FittedTerm, kTermCount>& terms, double tau_s);

// ------------------------------------------------- datasheet units

enum class SensorKind { gyro, accel };

// A coefficient in one datasheet unit, e.g. {"deg/sqrt(h)", 0.15}.
struct UnitValue {
  std::string unit;
  double value = 0.0;
};
// The usual datasheet units of a term for a gyro (input rad/s) or an
// accelerometer (input m/s^2, g = 9.80665 m/s^2): the first entry is the SI
// coefficient itself.
//   gyro:  Q rad, arcsec; N rad/sqrt(s), deg/sqrt(h), deg/s/sqrt(Hz), deg/h/sqrt(Hz);
//          B rad/s, deg/h, deg/s; K rad/s/sqrt(s), deg/h/sqrt(h); R rad/s^2, deg/h^2
//   accel: Q m/s, mm/s; N m/s/sqrt(s), m/s/sqrt(h), ug/sqrt(Hz); B m/s^2, ug, mg;
//          K m/s^2/sqrt(s), m/s^2/sqrt(h), ug/sqrt(h); R m/s^3, ug/h, m/s^2/h
std::vector<UnitValue> datasheet_units(SensorKind kind, int term, double coefficient_si);

}  // namespace imuemu::allan
