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

// A chain designed at one sampling rate.
struct Design {
  double sample_rate_hz = 0.0;
  std::vector<Biquad> sections;  // in cascade
  std::vector<int> averages;     // boxcar lengths, in cascade
  bool empty() const { return sections.empty() && averages.empty(); }
};

// Designs `stages` at fs. Throws std::invalid_argument naming "stage N" and
// the field for a stage the design refuses (frequency not in (0, fs/2),
// order or length out of range, q < 0).
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
