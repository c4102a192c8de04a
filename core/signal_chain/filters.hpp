// The sensor's own digital filters (issue 16), run at a device's internal
// rate before decimation to the output rate. Pure maths, no I/O.
//
// Every recursive stage is a cascade of second-order sections (biquads)
//     H(z) = (b0 + b1 z^-1 + b2 z^-2) / (1 + a1 z^-1 + a2 z^-2)
// designed from its analog prototype by the bilinear transform with the
// cutoff prewarped (s = K (1 - z^-1)/(1 + z^-1), K = 2 pi fc / tan(pi fc / fs)),
// so the digital filter's -3 dB point (notch centre) is exactly where the
// datasheet puts it, at any fs (Oppenheim & Schafer, Discrete-Time Signal
// Processing, 3rd ed., §7.2.2). The FIR stages are moving averages: a boxcar
// of L samples (a first-order CIC integrator-comb at unit gain, as the
// decimation averaging of ADIS parts), and the Bartlett window, two boxcars
// of L in cascade (the ADIS16470's FILT_CTRL filter, "number of taps in each
// stage" 2^N).
#pragma once

#include <array>
#include <complex>
#include <cstddef>
#include <string>
#include <vector>

namespace imuemu::signal_chain {

// H(z) = (b0 + b1 z^-1 + b2 z^-2) / (1 + a1 z^-1 + a2 z^-2).
struct Biquad {
  double b0 = 1.0, b1 = 0.0, b2 = 0.0, a1 = 0.0, a2 = 0.0;
};

enum class StageKind {
  low_pass,     // order 1..3, Butterworth poles, -3 dB at frequency_hz (ICM-42688-P UI filter: order and bandwidth)
  anti_alias,   // second order, -3 dB at frequency_hz, quality factor q (0: 1/sqrt(2), Butterworth)
  butterworth,  // order 1..16, -3 dB at frequency_hz
  notch,        // second-order notch at frequency_hz, quality factor q (centre / -3 dB width)
  average,      // moving average of `length` samples (boxcar, CIC of order 1)
  bartlett,     // two moving averages of `length` samples in cascade (triangular window of 2 length - 1 taps)
};
std::string to_string(StageKind kind);
// "low-pass" | "anti-alias" | "butterworth" | "notch" | "average" | "bartlett"; throws std::invalid_argument.
StageKind stage_kind_from_string(const std::string& name);

struct Stage {
  StageKind kind = StageKind::low_pass;
  double frequency_hz = 0.0;
  int order = 2;
  double q = 0.0;
  int length = 1;
};

inline constexpr int kMaxButterworthOrder = 16;
inline constexpr int kMaxAverageLength = 4096;
// The lowest corner (or notch centre) a recursive stage takes, as a fraction
// of the internal rate fs. The bilinear design's denominator at DC,
// 1 + a1 + a2 = 4 K^2 / (1 + K/Q + K^2) with K = tan(pi fc / fs), is the
// difference of numbers near 2 and 1: rounded to eps = 2.2e-16 it moves the
// stage's DC gain by about eps / (4 K^2), 0.1 ppm at fc = 1e-5 fs (below
// the 5 ppm scale factor of a navigation-grade gyro, HG9900), 100 % at
// 3e-9 fs, and 0/0 (NaN) once K^2 underflows (issue 26, N5: a low-pass at
// 1e-300 Hz). No datasheet filter comes near: the ICM-42688-P's narrowest UI
// filter is max(400 Hz, ODR)/40 (GYRO_UI_FILT_BW = 7, GYRO_ACCEL_CONFIG0),
// 10 Hz, 1.25e-3 of its 8 kHz preset rate; the ADIS16470's Bartlett and
// decimation filters are FIR.
inline constexpr double kMinCornerFraction = 1e-5;
// Quality factor of the anti-alias and notch stages: the ICM-42688-P's notch
// (DS-000347 §5.1, GYRO_NF_BW_SEL) spans bandwidths of 1449 Hz to 10 Hz
// at centres of 1-3 kHz, Q of 0.7 to 300; a second-order low-pass above
// Q = 1000 is a resonator 60 dB above its DC gain, below 0.05 two real poles
// more than a decade apart (and K/Q overflows at Q = 1e-300).
inline constexpr double kMinQ = 0.05, kMaxQ = 1000.0;

// A chain designed at one sampling rate.
struct Design {
  double sample_rate_hz = 0.0;
  std::vector<Biquad> sections;  // in cascade
  std::vector<int> averages;     // boxcar lengths, in cascade
  bool empty() const { return sections.empty() && averages.empty(); }
};

// Designs `stages` at fs. Throws SettingError (core/setting_error.hpp; key
// "stage[i].field") naming "stage N" and the field for a stage the design
// refuses (frequency not in [kMinCornerFraction fs, fs/2), order or length
// out of range, q outside [kMinQ, kMaxQ] where it is read, q < 0).
Design design(const std::vector<Stage>& stages, double sample_rate_hz);

// Single designs (exposed for tests and presets).
Biquad low_pass_first_order(double cutoff_hz, double fs_hz);
Biquad low_pass_second_order(double cutoff_hz, double q, double fs_hz);
Biquad notch(double centre_hz, double q, double fs_hz);
std::vector<Biquad> butterworth(int order, double cutoff_hz, double fs_hz);

// H(e^{j 2 pi f / fs}) of the whole chain.
std::complex<double> response(const Design& d, double f_hz);
// Group delay -d(arg H)/d(omega), in samples of the design's rate, at f
// (exact, from the coefficients: for a polynomial P(z^-1) = sum p_n z^-n the
// delay is Re(sum n p_n e^{-j w n} / sum p_n e^{-j w n}); a section's is its
// numerator's minus its denominator's; a boxcar of L is (L - 1)/2).
double group_delay_samples(const Design& d, double f_hz);

// The filter chain on six channels (gyro x y z, accel x y z), state in
// transposed direct form II; no allocation per sample.
class Filter {
 public:
  using Channels = std::array<double, 6>;
  explicit Filter(const Design& d);
  // The state a constant input x has settled to (no start-up transient).
  void settle(const Channels& x);
  Channels step(const Channels& x) noexcept;
  bool empty() const { return sections_.empty() && averages_.empty(); }

 private:
  struct Average {
    int length = 1;
    std::vector<double> ring;  // length x 6, channel-major
    Channels sum{};
    int next = 0;
  };
  std::vector<Biquad> sections_;
  std::vector<Channels> s1_, s2_;
  std::vector<Average> averages_;
};

}  // namespace imuemu::signal_chain
