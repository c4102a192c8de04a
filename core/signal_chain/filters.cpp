#include "core/signal_chain/filters.hpp"

#include <cmath>
#include <numbers>
#include <stdexcept>

#include "core/setting_error.hpp"

namespace imuemu::signal_chain {

namespace {

using cd = std::complex<double>;

// tan(pi f / fs): the prewarped analog cutoff in units of the bilinear
// transform's 2 fs (Oppenheim & Schafer §7.2.2, Eq. 7.26).
double prewarp(double f_hz, double fs_hz) { return std::tan(std::numbers::pi * f_hz / fs_hz); }

std::string stage_name(std::size_t i) { return "stage " + std::to_string(i + 1); }

}  // namespace

std::string to_string(StageKind kind) {
  switch (kind) {
    case StageKind::low_pass: return "low-pass";
    case StageKind::anti_alias: return "anti-alias";
    case StageKind::butterworth: return "butterworth";
    case StageKind::notch: return "notch";
    case StageKind::average: return "average";
    case StageKind::bartlett: return "bartlett";
  }
  return "?";
}

StageKind stage_kind_from_string(const std::string& name) {
  for (StageKind k : {StageKind::low_pass, StageKind::anti_alias, StageKind::butterworth, StageKind::notch,
                      StageKind::average, StageKind::bartlett})
    if (to_string(k) == name) return k;
  throw std::invalid_argument("unknown filter kind '" + name +
                              "' (expected low-pass, anti-alias, butterworth, notch, average or bartlett)");
}

Biquad low_pass_first_order(double cutoff_hz, double fs_hz) {
  // H(s) = 1 / (1 + s/wc) with s/wc = (1/K)(1 - z^-1)/(1 + z^-1).
  const double K = prewarp(cutoff_hz, fs_hz);
  Biquad b;
  b.b0 = b.b1 = K / (1.0 + K);
  b.b2 = 0.0;
  b.a1 = (K - 1.0) / (K + 1.0);
  b.a2 = 0.0;
  return b;
}

Biquad low_pass_second_order(double cutoff_hz, double q, double fs_hz) {
  // H(s) = 1 / ((s/wc)^2 + (s/wc)/Q + 1), same substitution.
  const double K = prewarp(cutoff_hz, fs_hz);
  const double norm = 1.0 / (1.0 + K / q + K * K);
  Biquad b;
  b.b0 = K * K * norm;
  b.b1 = 2.0 * b.b0;
  b.b2 = b.b0;
  b.a1 = 2.0 * (K * K - 1.0) * norm;
  b.a2 = (1.0 - K / q + K * K) * norm;
  return b;
}

Biquad notch(double centre_hz, double q, double fs_hz) {
  // H(s) = ((s/w0)^2 + 1) / ((s/w0)^2 + (s/w0)/Q + 1): zero gain at w0, unit gain at DC and Nyquist.
  const double K = prewarp(centre_hz, fs_hz);
  const double norm = 1.0 / (1.0 + K / q + K * K);
  Biquad b;
  b.b0 = (1.0 + K * K) * norm;
  b.b1 = 2.0 * (K * K - 1.0) * norm;
  b.b2 = b.b0;
  b.a1 = b.b1;
  b.a2 = (1.0 - K / q + K * K) * norm;
  return b;
}

std::vector<Biquad> butterworth(int order, double cutoff_hz, double fs_hz) {
  // Analog Butterworth: poles evenly spaced on the circle |s| = wc; the pair
  // k has Q_k = 1 / (2 sin((2k + 1) pi / (2N))), an odd order adds the real
  // pole. Every section is prewarped at the same cutoff, so |H| = 1/sqrt(2)
  // exactly there (each factor takes its analog value at the warped point).
  std::vector<Biquad> out;
  for (int k = 0; k < order / 2; ++k) {
    const double q = 1.0 / (2.0 * std::sin((2.0 * k + 1.0) * std::numbers::pi / (2.0 * order)));
    out.push_back(low_pass_second_order(cutoff_hz, q, fs_hz));
  }
  if (order % 2 == 1) out.push_back(low_pass_first_order(cutoff_hz, fs_hz));
  return out;
}

Design design(const std::vector<Stage>& stages, double fs_hz) {
  if (!(fs_hz > 0.0) || !std::isfinite(fs_hz))
    throw std::invalid_argument("filter chain: internal rate " + std::to_string(fs_hz) + " Hz is not positive");
  Design d;
  d.sample_rate_hz = fs_hz;
  for (std::size_t i = 0; i < stages.size(); ++i) {
    const Stage& s = stages[i];
    const std::string where = stage_name(i) + " (" + to_string(s.kind) + "): ";
    const std::string key = "stage[" + std::to_string(i) + "].";
    const bool recursive = s.kind != StageKind::average && s.kind != StageKind::bartlett;
    const double lowest_hz = kMinCornerFraction * fs_hz;
    if (recursive && !(s.frequency_hz >= lowest_hz && s.frequency_hz < 0.5 * fs_hz))
      throw SettingError(key + "frequency_hz",
                         where + "frequency_hz " + setting_number(s.frequency_hz) + " Hz is not in [" +
                             setting_number(lowest_hz) + ", " + setting_number(0.5 * fs_hz) + ") Hz (" +
                             (s.frequency_hz >= lowest_hz ? "below half the internal rate; raise oversampling"
                                                          : "at least 1e-5 of the internal rate: below it the design's "
                                                            "rounding moves its DC gain by more than 0.1 ppm") +
                             ")");
    if (!(s.q >= 0.0) || !std::isfinite(s.q)) throw SettingError(key + "q", where + "q must be >= 0");
    // Where q is read: the anti-alias stage (0: Butterworth) and the notch.
    const bool reads_q = (s.kind == StageKind::anti_alias && s.q != 0.0) || s.kind == StageKind::notch;
    if (reads_q && !(s.q >= kMinQ && s.q <= kMaxQ))
      throw SettingError(key + "q", where + "q " + setting_number(s.q) + " is not in [" + setting_number(kMinQ) + ", " +
                                        setting_number(kMaxQ) +
                                        "] (the ICM-42688-P notch spans Q 0.7..300; above 1000 a resonator, below "
                                        "0.05 two real poles a decade apart)");
    switch (s.kind) {
      case StageKind::low_pass:
        if (s.order < 1 || s.order > 3) throw SettingError(key + "order", where + "order must be 1, 2 or 3");
        for (const Biquad& b : butterworth(s.order, s.frequency_hz, fs_hz)) d.sections.push_back(b);
        break;
      case StageKind::anti_alias:
        d.sections.push_back(low_pass_second_order(s.frequency_hz, s.q > 0.0 ? s.q : std::numbers::sqrt2 / 2.0, fs_hz));
        break;
      case StageKind::butterworth:
        if (s.order < 1 || s.order > kMaxButterworthOrder)
          throw SettingError(key + "order", where + "order must be in 1.." + std::to_string(kMaxButterworthOrder));
        for (const Biquad& b : butterworth(s.order, s.frequency_hz, fs_hz)) d.sections.push_back(b);
        break;
      case StageKind::notch:
        d.sections.push_back(notch(s.frequency_hz, s.q, fs_hz));
        break;
      case StageKind::average:
      case StageKind::bartlett:
        if (s.length < 1 || s.length > kMaxAverageLength)
          throw SettingError(key + "length", where + "length must be in 1.." + std::to_string(kMaxAverageLength));
        if (s.length > 1) {
          d.averages.push_back(s.length);
          if (s.kind == StageKind::bartlett) d.averages.push_back(s.length);
        }
        break;
    }
  }
  return d;
}

std::complex<double> response(const Design& d, double f_hz) {
  const double w = 2.0 * std::numbers::pi * f_hz / d.sample_rate_hz;
  const cd z1 = std::polar(1.0, -w);  // z^-1
  cd h = 1.0;
  for (const Biquad& b : d.sections) h *= (b.b0 + z1 * (b.b1 + z1 * b.b2)) / (1.0 + z1 * (b.a1 + z1 * b.a2));
  for (int L : d.averages) {
    cd s = 0.0, zn = 1.0;
    for (int n = 0; n < L; ++n, zn *= z1) s += zn;
    h *= s / static_cast<double>(L);
  }
  return h;
}

double group_delay_samples(const Design& d, double f_hz) {
  const double w = 2.0 * std::numbers::pi * f_hz / d.sample_rate_hz;
  const cd z1 = std::polar(1.0, -w);
  const cd z2 = z1 * z1;
  // Re(sum n p_n z^-n / sum p_n z^-n) for p of degree 2.
  auto poly_delay = [&](double p0, double p1, double p2) {
    return std::real((p1 * z1 + 2.0 * p2 * z2) / (p0 + p1 * z1 + p2 * z2));
  };
  double tau = 0.0;
  for (const Biquad& b : d.sections) tau += poly_delay(b.b0, b.b1, b.b2) - poly_delay(1.0, b.a1, b.a2);
  for (int L : d.averages) tau += 0.5 * static_cast<double>(L - 1);  // linear phase
  return tau;
}

Filter::Filter(const Design& d) : sections_(d.sections), s1_(d.sections.size()), s2_(d.sections.size()) {
  for (int L : d.averages) {
    Average a;
    a.length = L;
    a.ring.assign(static_cast<std::size_t>(L) * 6, 0.0);
    averages_.push_back(std::move(a));
  }
}

void Filter::settle(const Channels& x) {
  Channels v = x;
  for (std::size_t i = 0; i < sections_.size(); ++i) {
    const Biquad& b = sections_[i];
    const double gain = (b.b0 + b.b1 + b.b2) / (1.0 + b.a1 + b.a2);
    for (std::size_t c = 0; c < 6; ++c) {
      const double y = gain * v[c];
      s2_[i][c] = b.b2 * v[c] - b.a2 * y;
      s1_[i][c] = y - b.b0 * v[c];
      v[c] = y;
    }
  }
  for (Average& a : averages_) {
    for (std::size_t c = 0; c < 6; ++c) {
      for (int n = 0; n < a.length; ++n) a.ring[c * static_cast<std::size_t>(a.length) + static_cast<std::size_t>(n)] = v[c];
      a.sum[c] = v[c] * a.length;
    }
    a.next = 0;
  }
}

Filter::Channels Filter::step(const Channels& x) noexcept {
  Channels v = x;
  for (std::size_t i = 0; i < sections_.size(); ++i) {
    const Biquad& b = sections_[i];
    Channels& s1 = s1_[i];
    Channels& s2 = s2_[i];
    for (std::size_t c = 0; c < 6; ++c) {
      const double y = b.b0 * v[c] + s1[c];
      s1[c] = b.b1 * v[c] - b.a1 * y + s2[c];
      s2[c] = b.b2 * v[c] - b.a2 * y;
      v[c] = y;
    }
  }
  for (Average& a : averages_) {
    const std::size_t L = static_cast<std::size_t>(a.length);
    const std::size_t n = static_cast<std::size_t>(a.next);
    for (std::size_t c = 0; c < 6; ++c) {
      double& slot = a.ring[c * L + n];
      a.sum[c] += v[c] - slot;
      slot = v[c];
    }
    a.next = a.next + 1 == a.length ? 0 : a.next + 1;
    if (a.next == 0) {
      // Once per window the running sums are recomputed from the ring, so
      // their rounding never accumulates beyond one window.
      for (std::size_t c = 0; c < 6; ++c) {
        double s = 0.0;
        for (std::size_t m = 0; m < L; ++m) s += a.ring[c * L + m];
        a.sum[c] = s;
      }
    }
    for (std::size_t c = 0; c < 6; ++c) v[c] = a.sum[c] / static_cast<double>(a.length);
  }
  return v;
}

}  // namespace imuemu::signal_chain
