#include "core/allan/allan.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>

namespace imuemu::allan {
namespace {

constexpr double kStandardGravity_m_s2 = 9.80665;  // CGPM 1901, the "g" of datasheets
constexpr double kRadToDeg = 180.0 / std::numbers::pi;
constexpr double kSecondsPerHour = 3600.0;
constexpr double kSqrtSecondsPerHour = 60.0;

double to_double(std::int64_t v) { return static_cast<double>(v); }

// exp(a ln x - x - lnGamma(a)): the common factor of P(a, x) and Q(a, x).
double gamma_prefactor(double a, double x) { return std::exp(a * std::log(x) - x - std::lgamma(a)); }

// P(a, x) = x^a e^-x / Gamma(a) * sum_n x^n / (a (a+1) ... (a+n)), for x < a + 1
// (Abramowitz & Stegun 6.5.29).
double gamma_p_series(double a, double x) {
  double term = 1.0 / a;
  double sum = term;
  for (int n = 1; n < 1'000'000; ++n) {
    term *= x / (a + n);
    sum += term;
    if (std::abs(term) < std::abs(sum) * 1e-17) break;
  }
  return std::min(1.0, sum * gamma_prefactor(a, x));
}

// Q(a, x) = 1 - P(a, x) from Legendre's continued fraction
// (A&S 6.5.31) Q = prefactor / (x + 1 - a - 1(1 - a) / (x + 3 - a - 2(2 - a) / (x + 5 - a - ...))),
// evaluated by the modified Lentz method; for x >= a + 1.
double gamma_q_continued_fraction(double a, double x) {
  constexpr double kTiny = 1e-300;
  double b = x + 1.0 - a;
  double c = 1.0 / kTiny;
  double d = 1.0 / b;
  double h = d;
  for (int i = 1; i < 1'000'000; ++i) {
    const double an = -i * (i - a);
    b += 2.0;
    d = an * d + b;
    if (std::abs(d) < kTiny) d = kTiny;
    c = b + an / c;
    if (std::abs(c) < kTiny) c = kTiny;
    d = 1.0 / d;
    const double step = d * c;
    h *= step;
    if (std::abs(step - 1.0) < 1e-16) break;
  }
  return std::clamp(gamma_prefactor(a, x) * h, 0.0, 1.0);
}

double chi_squared_pdf(double x, double dof) {
  if (x <= 0.0) return 0.0;
  const double a = 0.5 * dof;
  return 0.5 * std::exp((a - 1.0) * std::log(0.5 * x) - 0.5 * x - std::lgamma(a));
}

// Standard normal quantile by Newton on Phi(z) = erfc(-z / sqrt 2) / 2 from 0
// (Phi is concave for z > 0 and convex below, so the iterates approach the
// root from the side of 0 without overshooting).
double normal_quantile(double p) {
  double z = 0.0;
  for (int i = 0; i < 100; ++i) {
    const double cdf = 0.5 * std::erfc(-z / std::numbers::sqrt2);
    const double pdf = std::exp(-0.5 * z * z) / std::sqrt(2.0 * std::numbers::pi);
    const double step = (cdf - p) / pdf;
    z -= step;
    if (std::abs(step) < 1e-14 * (1.0 + std::abs(z))) break;
  }
  return z;
}

NoiseType noise_of_slope(double variance_slope) {
  // Nearest of the power laws sigma^2 ~ tau^-2, -1, 0, +1; a ramp (+2) is a
  // drift, not a noise, and is given the random-walk FM degrees of freedom
  // (the fewest of the four at a given tau beyond the minimum, hence the
  // widest interval).
  if (variance_slope < -1.5) return NoiseType::white_pm;
  if (variance_slope < -0.5) return NoiseType::white_fm;
  if (variance_slope < 0.5) return NoiseType::flicker_fm;
  return NoiseType::random_walk_fm;
}

struct SubsetFit {
  std::array<double, kTermCount> coefficient{};  // squared coefficients c_k = value^2
  std::array<double, kTermCount> variance{};     // their covariance diagonal (independent tau)
  double cost = std::numeric_limits<double>::infinity();
};

// Weighted non-negative least squares: min sum_j w_j (s2_j - sum_k c_k f_k(tau_j))^2,
// c >= 0, over the enabled terms, by solving each subset unconstrained and
// keeping the cheapest one whose coefficients are all positive. That is the
// exact NNLS solution: the optimum is the unconstrained optimum of its own
// support, and every feasible subset solution is a feasible point.
SubsetFit nnls_by_subsets(const std::vector<double>& tau_s, const std::vector<double>& s2,
                          const std::vector<double>& weight, const std::array<bool, kTermCount>& enabled) {
  const Eigen::Index rows = static_cast<Eigen::Index>(tau_s.size());
  Eigen::VectorXd b(rows);
  for (Eigen::Index j = 0; j < rows; ++j) b[j] = std::sqrt(weight[static_cast<std::size_t>(j)]) * s2[static_cast<std::size_t>(j)];
  SubsetFit best;
  best.cost = b.squaredNorm();  // the empty subset: every coefficient 0
  for (unsigned mask = 1; mask < (1u << kTermCount); ++mask) {
    std::vector<int> members;
    bool allowed = true;
    for (int k = 0; k < kTermCount; ++k) {
      if ((mask >> k) & 1u) {
        if (!enabled[static_cast<std::size_t>(k)]) allowed = false;
        members.push_back(k);
      }
    }
    const Eigen::Index cols = static_cast<Eigen::Index>(members.size());
    if (!allowed || cols > rows) continue;
    Eigen::MatrixXd a(rows, cols);
    Eigen::VectorXd column_scale(cols);
    for (Eigen::Index c = 0; c < cols; ++c) {
      for (Eigen::Index j = 0; j < rows; ++j) {
        const auto ju = static_cast<std::size_t>(j);
        a(j, c) = std::sqrt(weight[ju]) * term_basis(members[static_cast<std::size_t>(c)], tau_s[ju]);
      }
      // The basis spans tau^-2 .. tau^+2 over many decades: scale columns to
      // unit norm so the QR's rank decision sees comparable columns.
      column_scale[c] = a.col(c).norm();
      if (column_scale[c] <= 0.0) column_scale[c] = 1.0;
      a.col(c) /= column_scale[c];
    }
    const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(a);
    if (qr.rank() < cols) continue;
    const Eigen::VectorXd scaled = qr.solve(b);
    bool feasible = true;
    for (Eigen::Index c = 0; c < cols; ++c) feasible = feasible && scaled[c] > 0.0 && std::isfinite(scaled[c]);
    if (!feasible) continue;
    const double cost = (a * scaled - b).squaredNorm();
    if (cost >= best.cost) continue;
    // Covariance of the squared coefficients: (A^T A)^-1 of the weighted,
    // scaled design (weights are inverse variances), unscaled back.
    const Eigen::MatrixXd normal = a.transpose() * a;
    const Eigen::MatrixXd covariance = normal.ldlt().solve(Eigen::MatrixXd::Identity(cols, cols));
    SubsetFit fit;
    fit.cost = cost;
    for (Eigen::Index c = 0; c < cols; ++c) {
      const auto k = static_cast<std::size_t>(members[static_cast<std::size_t>(c)]);
      fit.coefficient[k] = scaled[c] / column_scale[c];
      fit.variance[k] = std::max(0.0, covariance(c, c)) / (column_scale[c] * column_scale[c]);
    }
    best = fit;
  }
  return best;
}

double model_variance(const std::array<double, kTermCount>& c, double tau_s) {
  double v = 0.0;
  for (int k = 0; k < kTermCount; ++k) v += c[static_cast<std::size_t>(k)] * term_basis(k, tau_s);
  return v;
}

// The generalised covariance G(l) of the integrated series of the five-term
// model at lag l samples (header: allan_variance_covariance), in
// (rate x samples)^2. Only second differences of it are ever used.
double generalized_covariance(const std::array<double, kTermCount>& c, double tau0_s, double lag) {
  const double l = std::abs(lag);
  double g = -c[white] * l / (2.0 * tau0_s) + c[rate_random_walk] * tau0_s * (l * l * l - l) / 12.0;
  if (l == 0.0) {
    g += c[quantization] / (tau0_s * tau0_s);
  } else {
    g += c[bias_instability] * l * l * std::log(l) / (2.0 * std::numbers::pi);
  }
  return g;
}

// E[d1_0 d2_l]: the covariance of the second differences of span m1 (start 0)
// and m2 (start l).
double difference_covariance(const std::array<double, kTermCount>& c, double tau0_s, double m1, double m2, double l) {
  static constexpr double kTap[3] = {1.0, -2.0, 1.0};
  double sum = 0.0;
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) sum += kTap[a] * kTap[b] * generalized_covariance(c, tau0_s, l + b * m2 - a * m1);
  return sum;
}

// Number of (i, j), 0 <= i < count1, 0 <= j < count2, with j - i = l.
double pair_count(double count1, double count2, double l) {
  return std::max(0.0, std::min(count1, count2 - l) - std::max(0.0, -l));
}

// sum over integer l in [lo, hi] of E[d1_0 d2_l]^2 x pair_count(l): exact
// (every lag) up to kCoreLagSamples lags, otherwise every step-th lag (at
// most that many), each standing for its cell (the summand is piecewise
// polynomial with kinks every m1 and m2 lags over 2 (m1 + m2) lags, so 256
// samples put at least 64 in each piece; tests/core/test_allan.cpp checks the
// sampled sum against the exact one through the scaling of each term).
constexpr std::int64_t kCoreLagSamples = 256;
double lag_sum(const std::array<double, kTermCount>& c, double tau0_s, double m1, double m2, double count1,
               double count2, std::int64_t lo, std::int64_t hi) {
  if (hi < lo) return 0.0;
  const std::int64_t width = hi - lo + 1;
  double sum = 0.0;
  if (width <= kCoreLagSamples) {
    for (std::int64_t l = lo; l <= hi; ++l) {
      const double ld = to_double(l);
      const double e = difference_covariance(c, tau0_s, m1, m2, ld);
      sum += e * e * pair_count(count1, count2, ld);
    }
    return sum;
  }
  // An integer step, each sample the middle lag of its cell (a fractional
  // step would skip single lags, which near the peak of the summand is a
  // per-cent error when the width is just above the threshold).
  const std::int64_t step = (width + kCoreLagSamples - 1) / kCoreLagSamples;
  for (std::int64_t start = lo; start <= hi; start += step) {
    const std::int64_t cell = std::min(step, hi - start + 1);
    const double ld = to_double(start + (cell - 1) / 2);
    const double e = difference_covariance(c, tau0_s, m1, m2, ld);
    sum += e * e * pair_count(count1, count2, ld) * to_double(cell);
  }
  return sum;
}

// The flicker tail: sum over |l| in [near, far] on one side (sign +1: l > 0)
// of the same summand, which is smooth there (every argument of G on one
// side of 0) and falls as l^-4: midpoints of kTailSamples geometric cells.
double tail_sum(const std::array<double, kTermCount>& c, double tau0_s, double m1, double m2, double count1,
                double count2, double near, double far, double sign) {
  constexpr int kTailSamples = 32;
  if (!(far > near)) return 0.0;
  const double ratio = std::pow(far / near, 1.0 / kTailSamples);
  double sum = 0.0, edge = near;
  for (int k = 0; k < kTailSamples; ++k) {
    const double next = edge * ratio;
    const double ld = sign * std::sqrt(edge * next);
    const double e = difference_covariance(c, tau0_s, m1, m2, ld);
    sum += e * e * pair_count(count1, count2, ld) * (next - edge);
    edge = next;
  }
  return sum;
}

}  // namespace

// ------------------------------------------------------------ the estimate

std::vector<std::int64_t> log_spaced_factors(std::int64_t sample_count, int points_per_decade, double max_fraction) {
  if (points_per_decade < 1) throw std::invalid_argument("allan: points per decade must be at least 1");
  if (!(max_fraction > 0.0 && max_fraction <= 0.5))
    throw std::invalid_argument("allan: the largest tau must be a fraction in (0, 0.5] of the record");
  std::vector<std::int64_t> factors;
  if (sample_count < 2) return factors;
  const std::int64_t limit =
      std::max<std::int64_t>(1, std::min(static_cast<std::int64_t>(std::floor(to_double(sample_count) * max_fraction)),
                                         sample_count / 2));
  for (int k = 0;; ++k) {
    const double m_real = std::pow(10.0, static_cast<double>(k) / static_cast<double>(points_per_decade));
    if (m_real > to_double(limit) + 0.5) break;
    const auto m = static_cast<std::int64_t>(std::llround(m_real));
    if (m > limit) break;
    if (factors.empty() || m > factors.back()) factors.push_back(m);
  }
  return factors;
}

std::vector<double> integrate_rate(std::span<const double> rate, double offset) {
  std::vector<double> theta(rate.size() + 1);
  double sum = 0.0;
  theta[0] = 0.0;
  for (std::size_t k = 0; k < rate.size(); ++k) {
    sum += rate[k] - offset;
    theta[k + 1] = sum;
  }
  return theta;
}

std::int64_t stride_for(std::int64_t m, std::int64_t ratio) { return ratio <= 0 ? 1 : std::max<std::int64_t>(1, m / ratio); }

double overlapping_allan_variance(std::span<const double> theta, std::int64_t m, std::int64_t stride) {
  if (m < 1 || 2 * m >= static_cast<std::int64_t>(theta.size()))
    throw std::invalid_argument("allan: averaging factor " + std::to_string(m) + " needs more than " +
                                std::to_string(2 * m) + " integrated points, have " + std::to_string(theta.size()));
  if (stride < 1) throw std::invalid_argument("allan: the stride must be at least 1");
  const auto mu = static_cast<std::size_t>(m);
  const std::size_t starts = theta.size() - 2 * mu;
  if (stride > 1) {
    const auto su = static_cast<std::size_t>(stride);
    double sum = 0.0;
    std::size_t terms = 0;
    for (std::size_t i = 0; i < starts; i += su, ++terms) {
      const double d = theta[i + 2 * mu] - 2.0 * theta[i + mu] + theta[i];
      sum += d * d;
    }
    const double md = to_double(m);
    return sum / (2.0 * md * md * static_cast<double>(terms));
  }
  const std::size_t terms = starts;
  const double* x0 = theta.data();
  const double* x1 = theta.data() + mu;
  const double* x2 = theta.data() + 2 * mu;
  // Four independent accumulators: the compiler may not reassociate a
  // floating-point sum, and one chain of dependent adds would bound the loop
  // by the add latency instead of memory bandwidth.
  double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0;
  std::size_t i = 0;
  for (; i + 4 <= terms; i += 4) {
    const double d0 = x2[i] - 2.0 * x1[i] + x0[i];
    const double d1 = x2[i + 1] - 2.0 * x1[i + 1] + x0[i + 1];
    const double d2 = x2[i + 2] - 2.0 * x1[i + 2] + x0[i + 2];
    const double d3 = x2[i + 3] - 2.0 * x1[i + 3] + x0[i + 3];
    s0 += d0 * d0;
    s1 += d1 * d1;
    s2 += d2 * d2;
    s3 += d3 * d3;
  }
  for (; i < terms; ++i) {
    const double d = x2[i] - 2.0 * x1[i] + x0[i];
    s0 += d * d;
  }
  const double md = to_double(m);
  return ((s0 + s1) + (s2 + s3)) / (2.0 * md * md * static_cast<double>(terms));
}

// ------------------------------------------------- degrees of freedom, CI

std::string to_string(NoiseType type) {
  switch (type) {
    case NoiseType::white_pm: return "white_pm";
    case NoiseType::white_fm: return "white_fm";
    case NoiseType::flicker_fm: return "flicker_fm";
    case NoiseType::random_walk_fm: return "random_walk_fm";
  }
  return "?";
}

double equivalent_degrees_of_freedom(NoiseType type, std::int64_t sample_count, std::int64_t m) {
  const double p = to_double(sample_count) + 1.0;  // phase points
  const double md = to_double(m);
  double edf = 1.0;
  switch (type) {
    case NoiseType::white_pm:
      edf = (p + 1.0) * (p - 2.0 * md) / (2.0 * (p - md));
      break;
    case NoiseType::white_fm:
      edf = (3.0 * (p - 1.0) / (2.0 * md) - 2.0 * (p - 2.0) / p) * 4.0 * md * md / (4.0 * md * md + 5.0);
      break;
    case NoiseType::flicker_fm:
      edf = m == 1 ? 2.0 * (p - 2.0) / (2.3 * p - 4.9) : 5.0 * p * p / (4.0 * md * (p + 3.0 * md));
      break;
    case NoiseType::random_walk_fm:
      edf = (p - 2.0) / md * ((p - 1.0) * (p - 1.0) - 3.0 * md * (p - 1.0) + 4.0 * md * md) / ((p - 3.0) * (p - 3.0));
      break;
  }
  if (!std::isfinite(edf)) return 1.0;
  return std::max(1.0, edf);
}

double regularized_gamma_p(double a, double x) {
  if (!(a > 0.0)) throw std::invalid_argument("regularized_gamma_p: a must be positive");
  if (!(x > 0.0)) return 0.0;
  if (std::isinf(x)) return 1.0;
  return x < a + 1.0 ? gamma_p_series(a, x) : 1.0 - gamma_q_continued_fraction(a, x);
}

double chi_squared_cdf(double x, double dof) { return regularized_gamma_p(0.5 * dof, 0.5 * x); }

double chi_squared_quantile(double p, double dof) {
  if (!(p > 0.0 && p < 1.0)) throw std::invalid_argument("chi_squared_quantile: p must be in (0, 1)");
  if (!(dof > 0.0) || !std::isfinite(dof)) throw std::invalid_argument("chi_squared_quantile: dof must be positive");
  // Wilson & Hilferty (1931): (X/k)^(1/3) is nearly normal with mean
  // 1 - 2/(9k) and variance 2/(9k).
  const double z = normal_quantile(p);
  const double h = 2.0 / (9.0 * dof);
  double x = dof * std::pow(std::max(1e-3, 1.0 - h + z * std::sqrt(h)), 3.0);
  double lo = 0.0, hi = std::numeric_limits<double>::infinity();
  for (int i = 0; i < 400; ++i) {
    const double f = chi_squared_cdf(x, dof) - p;
    if (f == 0.0) return x;
    if (f < 0.0) lo = x; else hi = x;
    const double pdf = chi_squared_pdf(x, dof);
    double next = pdf > 0.0 ? x - f / pdf : std::numeric_limits<double>::quiet_NaN();
    if (!(next > lo && next < hi)) next = std::isinf(hi) ? 2.0 * x + 1.0 : 0.5 * (lo + hi);
    if (std::abs(next - x) <= 1e-13 * x) return next;
    x = next;
  }
  return x;
}

Interval deviation_interval(double deviation, double dof, double confidence) {
  if (!(confidence > 0.0 && confidence < 1.0))
    throw std::invalid_argument("deviation_interval: confidence must be in (0, 1)");
  const double alpha = 1.0 - confidence;
  const double chi_low = chi_squared_quantile(0.5 * alpha, dof);
  const double chi_high = chi_squared_quantile(1.0 - 0.5 * alpha, dof);
  return {deviation * std::sqrt(dof / chi_high), deviation * std::sqrt(dof / chi_low)};
}

// ----------------------------------------------------------------- the fit

std::string term_name(int term) {
  switch (term) {
    case quantization: return "quantization";
    case white: return "white";
    case bias_instability: return "bias_instability";
    case rate_random_walk: return "rate_random_walk";
    case rate_ramp: return "rate_ramp";
    default: return "?";
  }
}

double term_basis(int term, double tau_s) {
  switch (term) {
    case quantization: return 3.0 / (tau_s * tau_s);
    case white: return 1.0 / tau_s;
    case bias_instability: return 2.0 * std::numbers::ln2 / std::numbers::pi;
    case rate_random_walk: return tau_s / 3.0;
    case rate_ramp: return 0.5 * tau_s * tau_s;
    default: return 0.0;
  }
}

int term_variance_slope(int term) { return term - 2; }

double model_adev(const std::array<FittedTerm, kTermCount>& terms, double tau_s) {
  double v = 0.0;
  for (int k = 0; k < kTermCount; ++k) {
    const double value = terms[static_cast<std::size_t>(k)].value;
    v += value * value * term_basis(k, tau_s);
  }
  return std::sqrt(v);
}

double allan_variance_covariance(const std::array<double, kTermCount>& c, double tau0_s, std::int64_t sample_count,
                                 std::int64_t m1, std::int64_t m2) {
  if (m1 < 1 || m2 < 1 || 2 * m1 >= sample_count + 1 || 2 * m2 >= sample_count + 1)
    throw std::invalid_argument("allan: averaging factors " + std::to_string(m1) + " and " + std::to_string(m2) +
                                " need more than twice as many samples, have " + std::to_string(sample_count));
  if (!(tau0_s > 0.0)) throw std::invalid_argument("allan: the sample interval must be positive");
  const double m1d = to_double(m1), m2d = to_double(m2);
  const double count1 = to_double(sample_count + 1 - 2 * m1), count2 = to_double(sample_count + 1 - 2 * m2);
  // White PM .. random walk: E[d1_0 d2_l] = 0 outside [-2 m2, 2 m1] (every
  // argument of G on one side of 0, where G is a polynomial of degree <= 3 in
  // l + b m2 - a m1, which the two second differences annihilate).
  const std::int64_t lo = -2 * m2, hi = 2 * m1;
  double sum = 0.0;
  if (hi - lo + 1 <= kCoreLagSamples || c[quantization] <= 0.0) {
    sum = lag_sum(c, tau0_s, m1d, m2d, count1, count2, lo, hi);
  } else {
    // White PM's G is a spike at lag 0, so E[d1_0 d2_l] has spikes at the
    // nine lags a m1 - b m2 that a sample grid would miss: sample the rest,
    // then add at those lags (each once) what the spike changes.
    std::array<double, kTermCount> smooth = c;
    smooth[quantization] = 0.0;
    sum = lag_sum(smooth, tau0_s, m1d, m2d, count1, count2, lo, hi);
    std::array<std::int64_t, 9> spikes{};
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) spikes[static_cast<std::size_t>(3 * a + b)] = a * m1 - b * m2;
    std::sort(spikes.begin(), spikes.end());
    const auto end = std::unique(spikes.begin(), spikes.end());
    for (auto it = spikes.begin(); it != end; ++it) {
      const double ld = to_double(*it);
      const double full = difference_covariance(c, tau0_s, m1d, m2d, ld);
      const double rest = difference_covariance(smooth, tau0_s, m1d, m2d, ld);
      sum += (full * full - rest * rest) * pair_count(count1, count2, ld);
    }
  }
  if (c[bias_instability] > 0.0) {
    // Flicker's tail, E[d1 d2] ~ l^-2: out to 16 x the support each side
    // (what is left is of order 16^-3 of the tail's start).
    const double support = 2.0 * (m1d + m2d);
    sum += tail_sum(c, tau0_s, m1d, m2d, count1, count2, 2.0 * m1d + 0.5, 16.0 * support, +1.0);
    sum += tail_sum(c, tau0_s, m1d, m2d, count1, count2, 2.0 * m2d + 0.5, 16.0 * support, -1.0);
  }
  return 2.0 * sum / (4.0 * m1d * m1d * m2d * m2d * count1 * count2);
}

namespace {

// Variance of each fitted squared coefficient when the weighted least squares
// c = G A^T W s, G = (A^T W A)^-1, meets estimates s whose covariance S is
// not diagonal: Cov(c) = G A^T W S W A G (the sandwich; Huber 1967, White
// 1980). S is allan_variance_covariance under the fitted model c itself;
// the weights W are those of the last solve. The weights depend on the data
// only through the model, whose first-order effect on c multiplies the
// residual and vanishes in expectation, so the fixed weights' formula holds
// to first order. Only the fitted (positive) terms enter A: a term the
// non-negative fit dropped has no interval.
std::array<double, kTermCount> sandwich_variance(const std::array<double, kTermCount>& c, double tau0_s,
                                                 std::int64_t n, const std::vector<Point>& points,
                                                 const std::vector<std::size_t>& index, const std::vector<double>& weight) {
  std::array<double, kTermCount> out{};
  std::vector<int> members;
  for (int k = 0; k < kTermCount; ++k)
    if (c[static_cast<std::size_t>(k)] > 0.0) members.push_back(k);
  const auto rows = static_cast<Eigen::Index>(index.size());
  const auto cols = static_cast<Eigen::Index>(members.size());
  if (cols == 0 || rows < cols || weight.size() != index.size()) return out;
  Eigen::MatrixXd a(rows, cols);  // sqrt(W) A, columns scaled to unit norm
  Eigen::VectorXd scale(cols);
  for (Eigen::Index col = 0; col < cols; ++col) {
    for (Eigen::Index j = 0; j < rows; ++j) {
      const auto ju = static_cast<std::size_t>(j);
      a(j, col) = std::sqrt(weight[ju]) * term_basis(members[static_cast<std::size_t>(col)], points[index[ju]].tau_s);
    }
    scale[col] = a.col(col).norm();
    if (scale[col] <= 0.0) scale[col] = 1.0;
    a.col(col) /= scale[col];
  }
  const Eigen::MatrixXd normal = a.transpose() * a;
  const Eigen::MatrixXd g = normal.ldlt().solve(Eigen::MatrixXd::Identity(cols, cols));
  // sqrt(W) S sqrt(W), symmetric.
  Eigen::MatrixXd s(rows, rows);
  for (Eigen::Index i = 0; i < rows; ++i) {
    for (Eigen::Index j = i; j < rows; ++j) {
      const auto iu = static_cast<std::size_t>(i), ju = static_cast<std::size_t>(j);
      const double cov = allan_variance_covariance(c, tau0_s, n, points[index[iu]].m, points[index[ju]].m);
      s(i, j) = s(j, i) = std::sqrt(weight[iu] * weight[ju]) * cov;
    }
  }
  const Eigen::MatrixXd b = g * a.transpose();  // (cols x rows)
  const Eigen::MatrixXd v = b * s * b.transpose();
  for (Eigen::Index col = 0; col < cols; ++col)
    out[static_cast<std::size_t>(members[static_cast<std::size_t>(col)])] = std::max(0.0, v(col, col)) / (scale[col] * scale[col]);
  return out;
}

}  // namespace

Analysis analyse(std::span<const double> rate, double tau0_s, const AnalysisOptions& options) {
  if (!(tau0_s > 0.0) || !std::isfinite(tau0_s)) throw std::invalid_argument("allan: the sample interval must be positive");
  if (!(options.confidence > 0.0 && options.confidence < 1.0))
    throw std::invalid_argument("allan: the confidence must be in (0, 1)");
  const auto n = static_cast<std::int64_t>(rate.size());
  if (n < kMinSamples)
    throw std::invalid_argument("allan: " + std::to_string(n) + " samples is too short; at least " +
                                std::to_string(kMinSamples) + " are needed");
  double sum = 0.0;
  for (std::size_t k = 0; k < rate.size(); ++k) {
    if (!std::isfinite(rate[k]))
      throw std::invalid_argument("allan: sample " + std::to_string(k) + " is not a finite number");
    sum += rate[k];
  }
  Analysis out;
  out.tau0_s = tau0_s;
  out.sample_count = n;
  const std::vector<double> theta = integrate_rate(rate, sum / to_double(n));
  const std::vector<std::int64_t> factors = log_spaced_factors(n, options.points_per_decade, options.max_tau_fraction);
  std::vector<double> s2(factors.size());
  out.points.resize(factors.size());
  double max_s2 = 0.0;
  for (std::size_t j = 0; j < factors.size(); ++j) {
    Point& pt = out.points[j];
    pt.m = factors[j];
    pt.tau_s = to_double(pt.m) * tau0_s;
    s2[j] = overlapping_allan_variance(theta, pt.m, stride_for(pt.m, options.overlap_ratio));
    pt.adev = std::sqrt(s2[j]);
    pt.in_fit = (options.fit_min_tau_s <= 0.0 || pt.tau_s >= options.fit_min_tau_s * (1.0 - 1e-12)) &&
                (options.fit_max_tau_s <= 0.0 || pt.tau_s <= options.fit_max_tau_s * (1.0 + 1e-12));
    max_s2 = std::max(max_s2, s2[j]);
  }
  const std::size_t count = factors.size();

  // Dominant noise before any fit: the local slope of the estimate.
  for (std::size_t j = 0; j < count; ++j) {
    const std::size_t a = j == 0 ? 0 : j - 1;
    const std::size_t b = std::min(count - 1, j + 1);
    double slope = -1.0;
    if (b > a && s2[a] > 0.0 && s2[b] > 0.0)
      slope = std::log(s2[b] / s2[a]) / std::log(out.points[b].tau_s / out.points[a].tau_s);
    out.points[j].noise = noise_of_slope(slope);
    out.points[j].edf = equivalent_degrees_of_freedom(out.points[j].noise, n, out.points[j].m);
  }

  std::array<double, kTermCount> coefficient{};
  std::array<double, kTermCount> variance{};
  std::array<double, kTermCount> sandwich{};
  const bool any_term = std::any_of(options.terms.begin(), options.terms.end(), [](bool b) { return b; });
  if (max_s2 > 0.0 && any_term) {
    std::vector<double> tau, est, edf_of, weight;
    std::vector<std::size_t> index;
    for (std::size_t j = 0; j < count; ++j) {
      if (!out.points[j].in_fit) continue;
      index.push_back(j);
      tau.push_back(out.points[j].tau_s);
      est.push_back(s2[j]);
    }
    // A model variance below this is treated as this (weights stay finite).
    const double floor_s2 = max_s2 * 1e-24;
    std::vector<std::size_t> fit_row(count, count);  // point -> row of est (count: not fitted)
    for (std::size_t i = 0; i < index.size(); ++i) fit_row[index[i]] = i;
    const auto exact_where_white_pm = [&] {
      for (std::size_t j = 0; j < count; ++j) {
        Point& pt = out.points[j];
        if (pt.noise != NoiseType::white_pm || stride_for(pt.m, options.overlap_ratio) == 1) continue;
        s2[j] = overlapping_allan_variance(theta, pt.m, 1);
        pt.adev = std::sqrt(s2[j]);
        if (fit_row[j] < count) est[fit_row[j]] = s2[j];
      }
    };
    // Two passes: fit with the slope-identified EDF, re-identify the noise
    // from the fitted model, fit again with those EDF. Between them, points
    // where white PM dominates are recomputed at stride 1: its differences
    // are correlated only at lags 0, m and 2m, so a stride would throw away
    // nearly independent terms (stride_for's argument needs the smooth
    // correlation of the redder noises).
    for (int pass = 0; pass < 2 && !index.empty(); ++pass) {
      if (pass == 1) exact_where_white_pm();
      std::vector<double> reference(est);
      for (double& r : reference) r = std::max(r, floor_s2);
      for (int iteration = 0; iteration < 30; ++iteration) {
        weight.assign(index.size(), 0.0);
        for (std::size_t i = 0; i < index.size(); ++i)
          weight[i] = out.points[index[i]].edf / (2.0 * reference[i] * reference[i]);
        const SubsetFit fit = nnls_by_subsets(tau, est, weight, options.terms);
        coefficient = fit.coefficient;
        variance = fit.variance;
        ++out.fit_iterations;
        double change = 0.0;
        for (std::size_t i = 0; i < index.size(); ++i) {
          const double model = std::max(model_variance(coefficient, tau[i]), floor_s2);
          change = std::max(change, std::abs(model / reference[i] - 1.0));
          reference[i] = model;
        }
        if (change < 1e-9) break;
      }
      // Re-identify every point's noise from the model's largest term there
      // (inside and outside the fit range: the model is the best description
      // of the whole curve there is).
      for (std::size_t j = 0; j < count; ++j) {
        int dominant = -1;
        double largest = 0.0;
        for (int k = 0; k < kTermCount; ++k) {
          const double share = coefficient[static_cast<std::size_t>(k)] * term_basis(k, out.points[j].tau_s);
          if (share > largest) {
            largest = share;
            dominant = k;
          }
        }
        if (dominant >= 0) {
          out.points[j].noise = noise_of_slope(term_variance_slope(dominant));
          out.points[j].edf = equivalent_degrees_of_freedom(out.points[j].noise, n, out.points[j].m);
        }
      }
    }
    exact_where_white_pm();  // a point the last identification made white PM
    if (!index.empty() && options.coefficient_covariance) sandwich = sandwich_variance(coefficient, tau0_s, n, out.points, index, weight);
  }

  for (Point& pt : out.points) {
    const Interval ci = deviation_interval(pt.adev, pt.edf, options.confidence);
    pt.ci_low = ci.low;
    pt.ci_high = ci.high;
  }
  const double z = std::sqrt(chi_squared_quantile(options.confidence, 1.0));  // two-sided normal quantile
  for (int k = 0; k < kTermCount; ++k) {
    const auto ku = static_cast<std::size_t>(k);
    FittedTerm& t = out.terms[ku];
    t.enabled = options.terms[ku];
    const double c = coefficient[ku];
    if (c <= 0.0) continue;
    // The sandwich variance; the independent-tau one if the former is not
    // positive (a degenerate design), which it never is for a fitted term.
    const double var_c = sandwich[ku] > 0.0 ? sandwich[ku] : variance[ku];
    const double sigma_c = std::sqrt(var_c);
    t.value = std::sqrt(c);
    t.formal_sigma = std::sqrt(variance[ku]) / (2.0 * t.value);
    t.sigma = sigma_c / (2.0 * t.value);
    t.low = std::sqrt(std::max(0.0, c - z * sigma_c));
    t.high = std::sqrt(c + z * sigma_c);
  }
  out.model_adev.resize(count);
  for (int k = 0; k < kTermCount; ++k) out.term_adev[static_cast<std::size_t>(k)].resize(count);
  for (std::size_t j = 0; j < count; ++j) {
    const double tau = out.points[j].tau_s;
    out.model_adev[j] = model_adev(out.terms, tau);
    for (int k = 0; k < kTermCount; ++k) {
      const double value = out.terms[static_cast<std::size_t>(k)].value;
      out.term_adev[static_cast<std::size_t>(k)][j] = value * std::sqrt(term_basis(k, tau));
    }
  }
  return out;
}

// ------------------------------------------------- datasheet units

std::vector<UnitValue> datasheet_units(SensorKind kind, int term, double v) {
  const double g = kStandardGravity_m_s2;
  if (kind == SensorKind::gyro) {
    const double deg = v * kRadToDeg;
    switch (term) {
      case quantization: return {{"rad", v}, {"arcsec", deg * 3600.0}};
      case white: return {{"rad/sqrt(s)", v}, {"deg/sqrt(h)", deg * kSqrtSecondsPerHour}, {"deg/s/sqrt(Hz)", deg},
                          {"deg/h/sqrt(Hz)", deg * kSecondsPerHour}};
      case bias_instability: return {{"rad/s", v}, {"deg/h", deg * kSecondsPerHour}, {"deg/s", deg}};
      case rate_random_walk: return {{"rad/s/sqrt(s)", v}, {"deg/h/sqrt(h)", deg * kSecondsPerHour * kSqrtSecondsPerHour}};
      case rate_ramp: return {{"rad/s^2", v}, {"deg/h^2", deg * kSecondsPerHour * kSecondsPerHour}};
      default: return {};
    }
  }
  const double ug = v / g * 1e6;
  switch (term) {
    case quantization: return {{"m/s", v}, {"mm/s", v * 1e3}};
    case white: return {{"m/s/sqrt(s)", v}, {"m/s/sqrt(h)", v * kSqrtSecondsPerHour}, {"ug/sqrt(Hz)", ug}};
    case bias_instability: return {{"m/s^2", v}, {"ug", ug}, {"mg", ug * 1e-3}};
    case rate_random_walk: return {{"m/s^2/sqrt(s)", v}, {"m/s^2/sqrt(h)", v * kSqrtSecondsPerHour},
                                   {"ug/sqrt(h)", ug * kSqrtSecondsPerHour}};
    case rate_ramp: return {{"m/s^3", v}, {"ug/h", ug * kSecondsPerHour}, {"m/s^2/h", v * kSecondsPerHour}};
    default: return {};
  }
}

}  // namespace imuemu::allan
