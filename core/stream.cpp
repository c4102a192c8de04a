#include "core/stream.hpp"

#include "core/decimal_seconds.hpp"

#include "core/limits.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/derivatives.hpp"
#include "core/so3.hpp"
#include "core/time_arith.hpp"

namespace imuemu {
namespace {

// Prefix sums of the kernel's weights times k^p (p = 0..3) for the weight,
// its rate and its acceleration: sum_{k=k1..k2} w_k k^p in O(1).
class KernelMoments {
 public:
  explicit KernelMoments(const smoothing::UniformKernel& kernel) : delta_(kernel.delta()) {
    const auto size = static_cast<std::size_t>(2 * delta_ + 2);
    for (auto& by_type : prefix_)
      for (auto& v : by_type) v.assign(size, 0.0);
    long double acc[3][4] = {};
    for (int k = -delta_; k <= delta_; ++k) {
      const double w[3] = {kernel.weight(k), kernel.weight_rate(k), kernel.weight_accel(k)};
      long double kp = 1.0L;
      for (int p = 0; p < 4; ++p) {
        for (int t = 0; t < 3; ++t) {
          acc[t][p] += static_cast<long double>(w[t]) * kp;
          prefix_[t][p][static_cast<std::size_t>(k + delta_ + 1)] = static_cast<double>(acc[t][p]);
        }
        kp *= k;
      }
    }
  }
  // sum over k in [k1, k2] of weight-type t (0 value, 1 rate, 2 accel) times k^p.
  double sum(int t, int p, int k1, int k2) const {
    const auto& v = prefix_[static_cast<std::size_t>(t)][static_cast<std::size_t>(p)];
    return v[static_cast<std::size_t>(k2 + delta_ + 1)] - v[static_cast<std::size_t>(k1 + delta_)];
  }

 private:
  int delta_;
  std::array<std::array<std::vector<double>, 4>, 3> prefix_;
};

// Ends::extrapolate: how many knots at each end shape the virtual knots
// beyond it (position polynomials of degree up to kEndKnots - 1 = 6, body
// rate polynomials of degree 5). Before issue 14 they were a parabola
// (constant acceleration) and the geodesic (constant body rate), whose error
// one interval out, h^3 f''' (0.5 m on a 500 m circle
// at 50 m/s), made the first and last seconds 15-300x worse than the
// interior. Measured at 400 Hz, Delta one interval (accel max, all samples vs
// more than 5 s from the ends): 6 knots 3.2e-3 vs 1.6e-3 (circle) and 5.6e-3
// vs 1.5e-3 (flight) with 5 virtual knots; 7 knots 1.6e-3 vs 1.6e-3 and
// 1.5e-3 vs 1.5e-3; 8 knots 1.6e-3 and 1.8e-3. The price: knot noise is
// amplified at the ends (one interval out the degree-6 extrapolation has
// Lagrange weights of RMS 58 on the seven knots' errors; docs/accuracy.md).
// A run's first segment is built once knot 1 + spline_window_knots (= 5) has
// arrived; waiting for seven at the head adds one knot interval of look-ahead
// to a run's first samples only. The attitude follows the intervals' body
// rates (extend()); on the 90 deg/s yaw of reference::FastYaw that took the
// all-samples gyro max from 2.6e-2 (a polynomial of rotation vectors in the
// end knot's chart, which had to stop at the knots within 2 rad) to 1.4e-3
// rad/s, with the flight unchanged.
constexpr std::size_t kEndKnots = 7;

// Value at t of the polynomial through (tau_i, y_i), i < n (Lagrange form).
template <typename Value>
Value lagrange(const std::array<double, kEndKnots>& tau, const std::array<Value, kEndKnots>& y, std::size_t n, double t) {
  Value sum = Value::Zero();
  for (std::size_t i = 0; i < n; ++i) {
    double basis = 1.0;
    for (std::size_t j = 0; j < n; ++j)
      if (j != i) basis *= (t - tau[j]) / (tau[i] - tau[j]);
    sum += basis * y[i];
  }
  return sum;
}

// Virtual knots continuing the trajectory beyond ends[0], away from ends[1],
// until they cover pad_ns plus extra_intervals end intervals. `ends` holds
// the run's end knots nearest first (2..kEndKnots of them). What the ends
// assume (README, "What the ends assume"): the motion goes on as the
// polynomials in time through those knots:
//  - position: the polynomial through the knots' positions (scene frame,
//    relative to the end knot, so nothing cancels at ECEF magnitudes);
//  - attitude: the polynomial through the knot intervals' mean body rates,
//    log(R_inner^T R_outer) / h at each interval's midpoint (body axes, so a
//    spinning body's rate is a smooth sequence however fast it turns: up to pi
//    per interval, where a polynomial of log(R_end^T R) in one chart would
//    leave its branch after two intervals of a 90 deg/s yaw), each virtual
//    interval then composed as R_next = R exp(rate(midpoint) h).
// Exact for a constant body rate and for positions of degree <= 6. Returned
// nearest first.
std::vector<Pose> extend(std::span<const Pose> ends, TimeNs pad_ns, std::int64_t extra_intervals) {
  std::vector<Pose> out;
  const Pose& from = ends[0];
  const Pose& towards = ends[1];
  const bool before = towards.t_ns > from.t_ns;
  const TimeNs end_h = static_cast<TimeNs>(ns_between(std::min(from.t_ns, towards.t_ns), std::max(from.t_ns, towards.t_ns)));
  // The end interval, or wider when that would take more than
  // kMaxPaddingKnots virtual knots to cover the padding (knots 1 ns apart
  // and a 1 s padding: a billion); the virtual knots stay on the curve.
  const TimeNs h = std::max(end_h, pad_ns / limits::kMaxPaddingKnots + 1);
  const std::size_t n = std::min(ends.size(), kEndKnots);
  std::array<double, kEndKnots> tau{}, midpoint{};
  std::array<Vec3, kEndKnots> position{}, rate{};
  for (std::size_t i = 0; i < n; ++i) {
    tau[i] = seconds_between(from.t_ns, ends[i].t_ns);
    position[i] = ends[i].position_m - from.position_m;
  }
  for (std::size_t i = 0; i + 1 < n; ++i) {  // interval from knot i + 1 (inner) out to knot i
    midpoint[i] = 0.5 * (tau[i] + tau[i + 1]);
    rate[i] = so3::log(ends[i + 1].attitude.transpose() * ends[i].attitude) / std::abs(tau[i] - tau[i + 1]);
  }
  // The polynomials are trusted only as far out as the end knots reach
  // (n - 1 end intervals): further out their Lagrange weights grow like
  // (distance / interval)^degree, and dense live poses (250 Hz with float
  // attitudes, a 0.28 s padding: 70 intervals) turned their rounding into
  // body rates of 1e4 rad/s, and no sample was ever emitted. Beyond that
  // reach the motion goes on at the reach's velocity and body rate.
  const double reach = static_cast<double>(n - 1) * seconds_between(0, end_h) * (before ? -1.0 : 1.0);
  const auto beyond_reach = [&](double t) { return before ? t < reach : t > reach; };
  const Vec3 p_reach = lagrange(tau, position, n, reach);
  const double dt_fd = 1e-3 * (reach / static_cast<double>(n - 1));
  const Vec3 v_reach = (p_reach - lagrange(tau, position, n, reach - dt_fd)) / dt_fd;
  const Vec3 rate_reach = lagrange(midpoint, rate, n - 1, reach);
  Mat3 attitude = from.attitude;
  double t_previous = 0.0;
  for (std::int64_t k = 1; k * h < pad_ns + extra_intervals * h; ++k) {
    // The caller refused knots whose padding leaves int64 (StreamPipeline::push),
    // so these are exact; saturating keeps them defined regardless.
    const TimeNs step_ns = saturating_mul_ns(k, h);
    const TimeNs t_ns = before ? saturating_sub_ns(from.t_ns, step_ns) : saturating_add_ns(from.t_ns, step_ns);
    const double t = seconds_between(from.t_ns, t_ns);
    const double t_mid = 0.5 * (t + t_previous);
    const Vec3 body_rate = beyond_reach(t_mid) ? rate_reach : lagrange(midpoint, rate, n - 1, t_mid);
    attitude = attitude * so3::exp(body_rate * std::abs(t - t_previous));
    t_previous = t;
    const Vec3 offset = beyond_reach(t) ? Vec3(p_reach + v_reach * (t - reach)) : lagrange(tau, position, n, t);
    out.push_back({t_ns, from.position_m + offset, attitude});
  }
  return out;
}

// See PipelineOptions::min_kernel_samples: the internal oversampling factor.
std::int64_t oversampling(const PipelineOptions& o) {
  if (o.derivatives != Derivatives::kernel || o.kernel.width != smoothing::KernelWidth::window ||
      o.kernel.delta < 1 || o.kernel.delta >= o.min_kernel_samples)
    return 1;
  const std::int64_t m = (o.min_kernel_samples + o.kernel.delta - 1) / o.kernel.delta;
  return o.rate_hz * m <= 1'000'000 ? m : 1;
}

// The options the engine runs with internally (oversampled, see above).
PipelineOptions internal_options(const PipelineOptions& o) {
  PipelineOptions inner = o;
  const std::int64_t m = oversampling(o);
  inner.rate_hz *= m;
  inner.kernel.delta *= static_cast<int>(m);
  return inner;
}

// See PipelineOptions::attitude_node_step.
std::size_t attitude_node_step(const PipelineOptions& o) {
  if (o.derivatives != Derivatives::kernel || o.kernel.width != smoothing::KernelWidth::window) return 1;
  if (o.attitude_node_step > 0) return static_cast<std::size_t>(o.attitude_node_step);
  return static_cast<std::size_t>(std::max(1, o.kernel.delta / 32));
}

}  // namespace

// One gap-free stretch of knots. Dense samples live on the grid
//   g -> base + floor(g * 1e9 / rate) ns (+ the exact sub-ns fraction),
// g = 0, 1, ...; base is the first knot (Ends::clip) or a whole number of
// seconds before it (Ends::extrapolate, whose padded samples are computed and
// dropped), so the output samples sit on the grid of the first knot.
//
// Work proceeds in blocks of output samples sharing a chart (PipelineOptions,
// Chart::local): a block [begin, end) is solved as soon as the dense samples
// its windows read have been interpolated, which happens once the knots
// (plus the spline look-ahead) covering them have arrived.
class StreamPipeline::Run {
  struct SegmentInfo {
    interp::Segment segment;
    std::size_t first_index;  // first dense index with t >= segment.start
  };

 public:
  Run(const PipelineOptions& options, std::deque<StreamSample>& out, TimeNs origin_ns)
      : opt_(internal_options(options)),
        output_every_(static_cast<std::size_t>(oversampling(options))),
        out_(out),
        period_s_(1.0 / static_cast<double>(opt_.rate_hz)),
        kernel_(opt_.kernel, period_s_),
        builder_(opt_.interpolation),
        kernel_rates_(opt_.derivatives == Derivatives::kernel),
        closed_form_(kernel_rates_ && opt_.closed_form_positions),
        global_(opt_.chart == Chart::global),
        origin_ns_(origin_ns) {
    if (kernel_rates_ && kernel_.delta() < 1) throw std::invalid_argument("kernel derivatives need a window: Delta >= 1");
    if (closed_form_) moments_.emplace(kernel_);
    const auto delta = static_cast<std::size_t>(kernel_.delta());
    nominal_ = std::max<std::size_t>(16, 2 * delta);
    overlap_ = global_ ? 0 : std::max<std::size_t>(4, delta / 4);
    node_step_ = attitude_node_step(opt_);
    // Nodes reach up to one node step beyond the samples they serve.
    reach_ = delta + std::max<std::size_t>(overlap_, 4) + (node_step_ > 1 ? node_step_ : 0);
    if (opt_.ends == Ends::extrapolate) {
      const std::int64_t pad_samples = opt_.kernel.delta + 8;
      pad_s_ = (pad_samples + opt_.rate_hz - 1) / opt_.rate_hz;
    }
  }

  // Knot already validated against the previous one by the caller. Strong
  // guarantee: if it throws (a smoothing window that would span more rotation
  // than a chart holds), the run is as before the call. Everything a push
  // changes before the blocks are solved (the builder, the new segments and
  // dense samples, the scalars below) is restored from a checkpoint; the
  // blocks are planned (the only check that throws) before any is solved.
  void push(const Pose& knot) {
    Checkpoint saved{builder_,  segments_.size(), dense_.size(), dense_count_, real_count_, k0_,
                     t_first_,  t_last_,          head_done_,    head_,        tail_};
    try {
      push_knot(knot);
      plan_blocks();
    } catch (...) {
      builder_ = std::move(saved.builder);
      segments_.resize(saved.segments);
      dense_.resize(saved.dense);
      dense_count_ = saved.dense_count;
      real_count_ = saved.real_count;
      k0_ = saved.k0;
      t_first_ = saved.t_first;
      t_last_ = saved.t_last;
      head_done_ = saved.head_done;
      head_ = std::move(saved.head);
      tail_ = saved.tail;
      throw;
    }
    solve_blocks();
  }

  // Ns of the smoothing half-window (Delta samples): two knots closer than
  // this share a window.
  TimeNs window_half_ns() const {
    return saturating_mul_ns(kernel_.delta(), kNsPerSecond) / opt_.rate_hz;
  }
  TimeNs pad_ns() const { return saturating_mul_ns(pad_s_, kNsPerSecond); }
  // Virtual knots beyond the padding: the spline's window (its C2 solve at
  // the last real knots then ends on virtual knots, not at a clamped window
  // end a few knots away), or one interval for the methods without tangents.
  std::int64_t extra_intervals() const {
    const auto m = opt_.interpolation.method;
    const bool tangents = m == interp::Method::hermite || m == interp::Method::park_ravani;
    return tangents ? opt_.interpolation.spline_window_knots : 1;
  }

 private:
  struct Checkpoint {
    interp::SegmentBuilder builder;
    std::size_t segments, dense, dense_count, real_count;
    std::int64_t k0;
    TimeNs t_first, t_last;
    bool head_done;
    std::vector<Pose> head;
    std::array<Pose, kEndKnots> tail;
  };

  // The blocks solve_blocks() would solve now, with their chart check
  // (solve()'s) only: throws what solve_blocks would, changes nothing.
  void plan_blocks() const {
    if (global_ || finished_) return;
    std::size_t begin = next_begin_;
    while (begin < dense_count_ && begin + nominal_ + reach_ <= dense_count_) {
      std::size_t length = nominal_;
      while (!fits_chart(begin, begin + length)) {
        if (length == 1) throw_chart_error(begin);
        length = (length + 1) / 2;
      }
      begin += length;
    }
  }
  // solve()'s test: every sample its window reads within kMaxChartAngleRad
  // of the block's reference (the same arithmetic, so the same verdict).
  bool fits_chart(std::size_t begin, std::size_t end) const {
    const std::size_t n = dense_count_;
    const Mat3 R_ref = dense(begin + (end - begin) / 2).attitude;
    const std::size_t lo = begin > reach_ ? begin - reach_ : 0;
    const std::size_t hi = std::min(n, end + reach_);
    for (std::size_t j = lo; j < hi; ++j) {
      const Vec3 rho = so3::log(R_ref.transpose() * dense(j).attitude);
      if (rho.norm() > kMaxChartAngleRad) return false;
    }
    return true;
  }
  [[noreturn]] static void throw_chart_error(std::size_t sample) {
    throw std::invalid_argument("the smoothing window around output sample " + std::to_string(sample) +
                                " spans more rotation than a chart can hold (> " + std::to_string(kMaxChartAngleRad) +
                                " rad from its centre): reduce Delta or the kernel width, or add knots");
  }

 public:
  void push_knot(const Pose& knot) {
    if (real_count_ == 0) {
      t_first_ = knot.t_ns;
      // The first grid index at or after t_first - pad, on the stream's grid
      // (origin + floor(k 1e9 / rate)): every run of a split stream stays on
      // the first run's grid. For the first run it is exactly -pad_s * rate.
      const TimeNs start = saturating_sub_ns(t_first_, pad_ns());  // exact: the caller checked the padding
      const TimeNs d = saturating_sub_ns(start, origin_ns_);
      const std::int64_t rem = floor_mod(d, kNsPerSecond);
      k0_ = (d - rem) / kNsPerSecond * opt_.rate_hz + rem * opt_.rate_hz / kNsPerSecond;  // floor(d rate / 1e9)
      while (absolute_time(k0_) < start) ++k0_;
    }
    ++real_count_;
    t_last_ = knot.t_ns;
    if (opt_.ends == Ends::extrapolate) {
      std::move(tail_.begin() + 1, tail_.end(), tail_.begin());
      tail_.back() = knot;
      if (!head_done_) {
        head_.push_back(knot);
        if (head_.size() < kEndKnots) return;
        push_head();
        return;
      }
    }
    feed(knot);
  }

  void finish() {
    if (opt_.ends == Ends::extrapolate) {
      if (!head_done_) {
        if (head_.size() < 2) return;  // caller reports the isolated knot
        push_head();
      }
      // Virtual knots after the last: the mirror of the head.
      std::vector<Pose> ends(tail_.rbegin(), tail_.rbegin() + static_cast<std::ptrdiff_t>(std::min(real_count_, kEndKnots)));
      dense_end_ns_ = saturating_add_ns(t_last_, pad_ns());
      end_known_ = true;
      for (const Pose& v : extend(ends, pad_ns(), extra_intervals())) feed(v);
    } else {
      dense_end_ns_ = t_last_;
      end_known_ = true;
    }
    builder_.finish();
    finished_ = true;
    take_segments();
    if (opt_.ends == Ends::clip && dense_count_ < 2)
      throw std::invalid_argument("trajectory from " + std::to_string(t_first_) +
                                  " ns is shorter than two output samples");
    solve_blocks();
  }

  std::size_t real_knots() const { return real_count_; }
  std::size_t buffered() const { return dense_.size() + pending_.size(); }

 private:
  void push_head() {
    head_done_ = true;
    std::vector<Pose> virtual_knots = extend(head_, pad_ns(), extra_intervals());
    for (auto it = virtual_knots.rbegin(); it != virtual_knots.rend(); ++it) builder_.push(*it);
    for (const Pose& k : head_) feed(k);
    head_.clear();
  }

  // During push() the blocks are solved once, after planning (see push).
  void feed(const Pose& knot) {
    builder_.push(knot);
    take_segments();
    if (finished_ || end_known_) solve_blocks();
  }

  // Grid instant of dense index g: integer ns and the sub-ns fraction.
  TimeNs grid_time(std::size_t g) const { return absolute_time(k0_ + static_cast<std::int64_t>(g)); }
  double grid_fraction_ns(std::size_t g) const {
    const std::int64_t r = floor_mod(k0_ + static_cast<std::int64_t>(g), opt_.rate_hz);
    return static_cast<double>((r * kNsPerSecond) % opt_.rate_hz) / static_cast<double>(opt_.rate_hz);
  }
  static std::int64_t floor_mod(std::int64_t k, std::int64_t m) { return ((k % m) + m) % m; }
  // origin + floor(k * 1e9 / rate) for any integer k, without overflow.
  TimeNs absolute_time(std::int64_t k) const {
    const std::int64_t r = floor_mod(k, opt_.rate_hz);
    const std::int64_t whole = (k - r) / opt_.rate_hz;
    // Saturating: one grid instant past a run that ends within a period of
    // INT64_MAX compares as "beyond the end" instead of wrapping.
    return saturating_add_ns(saturating_add_ns(origin_ns_, saturating_mul_ns(whole, kNsPerSecond)),
                             r * kNsPerSecond / opt_.rate_hz);
  }

  // Interpolates the dense samples of every segment the builder has ready.
  void take_segments() {
    auto& ready = builder_.ready();
    while (!ready.empty()) {
      segments_.push_back({ready.front(), dense_count_});
      ready.pop_front();
      generate(segments_.back(), finished_ && ready.empty());
    }
    if (finished_ && !segments_.empty()) generate(segments_.back(), true);
  }

  // Dense samples on `s` with t < s.end (or <= for the run's last segment),
  // never beyond the padded end.
  void generate(const SegmentInfo& s, bool last) {
    for (;;) {
      const TimeNs t = grid_time(dense_count_);
      if (last ? t > s.segment.end.t_ns : t >= s.segment.end.t_ns) break;
      if (end_known_ && t > dense_end_ns_) break;
      dense_.push_back(interp::evaluate(s.segment, t, grid_fraction_ns(dense_count_)));
      ++dense_count_;
    }
  }

  const Pose& dense(std::size_t j) const { return dense_[j - dense_first_]; }
  Kinematics& pending(std::size_t j) { return pending_[j - pending_first_]; }

  void solve_blocks() {
    while (next_begin_ < dense_count_) {
      std::size_t length = nominal_;
      if (finished_) {
        length = std::min(nominal_, dense_count_ - next_begin_);
      } else if (next_begin_ + nominal_ + reach_ > dense_count_) {
        break;  // the windows of a full block are not all here yet
      }
      const std::size_t begin = next_begin_;
      if (global_) {
        solve(begin, begin + length, true);
        for (std::size_t j = begin; j < begin + length; ++j) {
          pending(j).attitude = attitudes_[j - a_lo_];
          if (kernel_rates_) pending(j).angular_rate_rad_s = rates_[j - a_lo_];
        }
      } else {
        // Halved while the window strays more than kMaxChartAngleRad from the
        // block's reference.
        while (!solve(begin, begin + length, false)) {
          if (length == 1) {
            throw std::invalid_argument(
                "the smoothing window around output sample " + std::to_string(begin) +
                " spans more rotation than a chart can hold (> " + std::to_string(kMaxChartAngleRad) +
                " rad from its centre): reduce Delta or the kernel width, or add knots");
          }
          length = (length + 1) / 2;
        }
        // Neighbouring blocks' attitudes differ at second order (smoothing in
        // exponential coordinates depends on the chart); they are blended
        // over 2*overlap samples centred on each block boundary.
        const std::size_t blend_lo = a_lo_;
        const double blend_len = static_cast<double>(begin + overlap_ - blend_lo);
        for (std::size_t j = a_lo_; j < a_hi_; ++j) {
          Kinematics& kin = pending(j);
          if (begin == 0 || j >= begin + overlap_) {
            kin.attitude = attitudes_[j - a_lo_];
            if (kernel_rates_) kin.angular_rate_rad_s = rates_[j - a_lo_];
          } else {
            // Samples before begin+overlap already hold the previous blocks'
            // value: move it towards this block's along the geodesic.
            const double x = (static_cast<double>(j - blend_lo) + 0.5) / blend_len;
            const smoothing::QuinticStep w = smoothing::quintic_step(x);
            Vec3 unused = Vec3::Zero();
            so3::geodesic_blend(kin.attitude, kernel_rates_ ? kin.angular_rate_rad_s : unused, attitudes_[j - a_lo_],
                          kernel_rates_ ? rates_[j - a_lo_] : unused, w.s,
                          w.ds_du / (blend_len * period_s_), kernel_rates_);
          }
        }
      }
      next_begin_ = begin + length;
      const bool all = finished_ && next_begin_ == dense_count_;
      finalize(all ? dense_count_ : (next_begin_ > overlap_ ? next_begin_ - overlap_ : 0), all);
    }
  }

  // Smooths block [begin, end) in a chart at its middle sample (or, for the
  // global chart, at the identity and the origin). Positions, velocities and
  // accelerations are final and written into the pending samples (position
  // smoothing is linear, so every chart gives the same answer). Attitudes
  // (and, with kernel derivatives, body rates) are chart dependent at second
  // order, so the block leaves them in attitudes_/rates_ on [a_lo_, a_hi_):
  // `overlap` samples beyond each end, for blending with the neighbours.
  // Returns false (writing nothing) if some sample of the window is too far
  // from the reference for the local chart.
  bool solve(std::size_t begin, std::size_t end, bool global) {
    // During streaming every index read below is < n: the block waits until
    // dense samples reach end + reach. Only at the true end is it clipped, so
    // clipping reproduces Eq. 3.68's one-sided windows there.
    const std::size_t n = dense_count_;
    const std::size_t ref = begin + (end - begin) / 2;
    const Mat3 R_ref = global ? Mat3::Identity() : dense(ref).attitude;
    const Vec3 d_ref = global ? Vec3::Zero() : dense(ref).position_m;
    const std::size_t a_lo = begin > overlap_ ? begin - overlap_ : 0;
    const std::size_t a_hi = std::min(n, end + overlap_);
    const std::size_t lo = begin > reach_ ? begin - reach_ : 0;
    const std::size_t hi = std::min(n, end + reach_);
    const std::size_t m = hi - lo;
    rho_.resize(m);
    delta_.resize(m);
    for (std::size_t j = lo; j < hi; ++j) {
      rho_[j - lo] = so3::log(R_ref.transpose() * dense(j).attitude);
      if (!global && rho_[j - lo].norm() > kMaxChartAngleRad) return false;
      delta_[j - lo] = dense(j).position_m - d_ref;
    }
    a_lo_ = a_lo;
    a_hi_ = a_hi;
    while (pending_first_ + pending_.size() < a_hi) {
      pending_.emplace_back();
      pending_.back().t_ns = grid_time(pending_first_ + pending_.size() - 1);
    }
    attitudes_.resize(a_hi - a_lo);
    rates_.resize(a_hi - a_lo);
    if (kernel_rates_ && node_step_ > 1) {
      smooth_attitude_at_nodes(a_lo, a_hi, lo, n, R_ref);
    } else {
      for (std::size_t j = a_lo; j < a_hi; ++j) {
      if (kernel_rates_) {
        const smoothing::Smoothed r = smoothing::smooth_with_derivatives(kernel_, rho_, j - lo, false);
        attitudes_[j - a_lo] = R_ref * so3::exp(r.value);
        rates_[j - a_lo] = so3::W(r.value) * r.rate;  // Eq. 3.59-3.60, exact r~'
      } else {
        attitudes_[j - a_lo] = R_ref * so3::exp(smoothing::smooth_at(kernel_, rho_, j - lo));
      }
      }
    }
    if (kernel_rates_) {
      for (std::size_t i = begin; i < end; ++i) {
        const smoothing::Smoothed d = closed_form_ ? smooth_position_in_closed_form(i, d_ref, n)
                                                   : smoothing::smooth_with_derivatives(kernel_, delta_, i - lo);
        Kinematics& kin = pending(i);
        kin.position_m = d_ref + d.value;
        kin.velocity_m_s = d.rate;
        kin.acceleration_m_s2 = d.accel;
      }
      return true;
    }
    // The thesis' stencils (Eq. 3.71-3.74) on the smoothed positions.
    const std::size_t s_lo = begin >= 4 ? begin - 4 : 0;
    const std::size_t s_hi = std::min(n, end + 4);
    delta_s_.resize(m);
    for (std::size_t j = s_lo; j < s_hi; ++j) delta_s_[j - lo] = smoothing::smooth_at(kernel_, delta_, j - lo);
    auto at_delta = [&](std::size_t j) -> const Vec3& { return delta_s_[j - lo]; };
    velocity_.resize(m);
    const std::size_t v_lo = begin >= 2 ? begin - 2 : 0;
    const std::size_t v_hi = std::min(n, end + 2);
    for (std::size_t j = v_lo; j < v_hi; ++j) velocity_[j - lo] = derivatives::stencil(at_delta, j, n, period_s_);
    auto at_velocity = [&](std::size_t j) -> const Vec3& { return velocity_[j - lo]; };
    for (std::size_t i = begin; i < end; ++i) {
      Kinematics& kin = pending(i);
      kin.position_m = d_ref + delta_s_[i - lo];
      kin.velocity_m_s = velocity_[i - lo];
      kin.acceleration_m_s2 = derivatives::stencil(at_velocity, i, n, period_s_);
    }
    return true;
  }

  // Attitudes and body rates on [a_lo, a_hi) from Eq. 3.68 evaluated (with
  // its exact first and second time derivatives) at the nodes g = q * step
  // (and the last sample), quintic Hermite in between:
  //   rho(u) = h0 v0 + h1 H v0' + h2 H^2 v0'' + h3 v1 + h4 H v1' + h5 H^2 v1'',
  // u in [0, 1] across a node interval of H seconds; omega = W(rho) rho'.
  void smooth_attitude_at_nodes(std::size_t a_lo, std::size_t a_hi, std::size_t lo, std::size_t n, const Mat3& R_ref) {
    const std::size_t step = node_step_;
    std::size_t q0 = (a_lo / step) * step;
    smoothing::Smoothed v0 = smoothing::smooth_with_derivatives(kernel_, rho_, q0 - lo, true);
    std::size_t j = a_lo;
    while (j < a_hi) {
      const std::size_t q1 = std::min(q0 + step, n - 1);
      if (q1 == q0) {  // the run's last sample is itself a node
        attitudes_[j - a_lo] = R_ref * so3::exp(v0.value);
        rates_[j - a_lo] = so3::W(v0.value) * v0.rate;
        ++j;
        continue;
      }
      const smoothing::Smoothed v1 = smoothing::smooth_with_derivatives(kernel_, rho_, q1 - lo, true);
      const double H = static_cast<double>(q1 - q0) * period_s_;
      const Vec3 d0 = H * v0.rate, d1 = H * v1.rate, c0 = (H * H) * v0.accel, c1 = (H * H) * v1.accel;
      const double inv = 1.0 / static_cast<double>(q1 - q0);
      for (; j < a_hi && (j < q1 || q1 == n - 1); ++j) {
        const double u = static_cast<double>(j - q0) * inv;
        const double u2 = u * u, u3 = u2 * u, u4 = u3 * u, u5 = u4 * u;
        const Vec3 value = (1.0 - 10.0 * u3 + 15.0 * u4 - 6.0 * u5) * v0.value +
                           (u - 6.0 * u3 + 8.0 * u4 - 3.0 * u5) * d0 +
                           (0.5 * u2 - 1.5 * u3 + 1.5 * u4 - 0.5 * u5) * c0 +
                           (10.0 * u3 - 15.0 * u4 + 6.0 * u5) * v1.value + (-4.0 * u3 + 7.0 * u4 - 3.0 * u5) * d1 +
                           (0.5 * u3 - u4 + 0.5 * u5) * c1;
        const Vec3 rate = ((-30.0 * u2 + 60.0 * u3 - 30.0 * u4) * v0.value +
                           (1.0 - 18.0 * u2 + 32.0 * u3 - 15.0 * u4) * d0 +
                           (u - 4.5 * u2 + 6.0 * u3 - 2.5 * u4) * c0 +
                           (30.0 * u2 - 60.0 * u3 + 30.0 * u4) * v1.value +
                           (-12.0 * u2 + 28.0 * u3 - 15.0 * u4) * d1 + (1.5 * u2 - 4.0 * u3 + 2.5 * u4) * c1) /
                          H;
        attitudes_[j - a_lo] = R_ref * so3::exp(value);
        rates_[j - a_lo] = so3::W(value) * rate;  // Eq. 3.59-3.60
      }
      q0 = q1;
      v0 = v1;
    }
  }

  // smoothing::smooth_with_derivatives of the dense positions (relative to
  // d_ref) at sample i, with the sums over each knot segment's samples done in
  // closed form: on a segment the offset is a cubic in k (the sample offset
  // from i), d(k) = d_m - d_ref + e0 + e1 k + e2 k^2 + e3 k^3, so
  // sum_k w_k d(k) = sum_p e_p (sum_k w_k k^p) from the prefix moments.
  // O(knots in the window) per sample instead of O(Delta).
  smoothing::Smoothed smooth_position_in_closed_form(std::size_t i, const Vec3& d_ref, std::size_t n) const {
    const auto delta = static_cast<std::ptrdiff_t>(kernel_.delta());
    const auto ii = static_cast<std::ptrdiff_t>(i);
    const auto k_lo = static_cast<int>(std::max<std::ptrdiff_t>(-delta, -ii));
    const auto k_hi = static_cast<int>(std::min<std::ptrdiff_t>(delta, static_cast<std::ptrdiff_t>(n) - 1 - ii));
    const TimeNs t_i_ns = grid_time(i);
    const double extra_i = grid_fraction_ns(i);
    const double step_ns = 1e9 / static_cast<double>(opt_.rate_hz);
    // Polynomial of segment s in k around i: coefficients e0..e3 (relative to its start).
    auto coefficients = [&](const SegmentInfo& s, Vec3 e[4]) {
      const interp::Segment& seg = s.segment;
      const double h_ns = static_cast<double>(seg.end.t_ns - seg.start.t_ns);
      const double u0 = (static_cast<double>(t_i_ns - seg.start.t_ns) + extra_i) / h_ns;
      const double sk = step_ns / h_ns;
      const auto& c = seg.position;
      e[0] = ((c[2] * u0 + c[1]) * u0 + c[0]) * u0;
      e[1] = (c[0] + (2.0 * c[1] + 3.0 * c[2] * u0) * u0) * sk;
      e[2] = (c[1] + 3.0 * c[2] * u0) * (sk * sk);
      e[3] = c[2] * (sk * sk * sk);
    };
    auto segment_of = [&](std::size_t j) {
      const auto it = std::upper_bound(segments_.begin(), segments_.end(), j,
                                       [](std::size_t v, const SegmentInfo& s) { return v < s.first_index; });
      return static_cast<std::size_t>(it - segments_.begin()) - 1;
    };
    auto segment_end = [&](std::size_t m) {
      return m + 1 < segments_.size() ? segments_[m + 1].first_index : dense_count_;
    };
    // The value at i itself: its own segment's polynomial at k = 0.
    Vec3 e[4];
    const std::size_t m_i = segment_of(i);
    coefficients(segments_[m_i], e);
    const Vec3 f_i = segments_[m_i].segment.start.position_m - d_ref + e[0];
    Vec3 s_sum[3] = {Vec3::Zero(), Vec3::Zero(), Vec3::Zero()};
    const std::size_t j_lo = static_cast<std::size_t>(ii + k_lo), j_hi = static_cast<std::size_t>(ii + k_hi);
    for (std::size_t m = segment_of(j_lo); m < segments_.size() && segments_[m].first_index <= j_hi; ++m) {
      const auto k1 = static_cast<int>(std::max<std::ptrdiff_t>(static_cast<std::ptrdiff_t>(segments_[m].first_index) - ii, k_lo));
      const auto k2 = static_cast<int>(std::min<std::ptrdiff_t>(static_cast<std::ptrdiff_t>(segment_end(m)) - 1 - ii, k_hi));
      if (k2 < k1) continue;
      coefficients(segments_[m], e);
      const Vec3 base = segments_[m].segment.start.position_m - d_ref + e[0] - f_i;
      for (int t = 0; t < 3; ++t)
        s_sum[t] += base * moments_->sum(t, 0, k1, k2) + e[1] * moments_->sum(t, 1, k1, k2) +
                    e[2] * moments_->sum(t, 2, k1, k2) + e[3] * moments_->sum(t, 3, k1, k2);
    }
    const double d0 = moments_->sum(0, 0, k_lo, k_hi), d1 = moments_->sum(1, 0, k_lo, k_hi),
                 d2 = moments_->sum(2, 0, k_lo, k_hi);
    // Same quotient-rule combination as smoothing::smooth_with_derivatives.
    const double inv = 1.0 / d0;
    smoothing::Smoothed out;
    out.value = f_i + s_sum[0] * inv;
    out.rate = (s_sum[1] - s_sum[0] * (d1 * inv)) * inv;
    out.accel = (s_sum[2] - 2.0 * s_sum[1] * (d1 * inv) - s_sum[0] * (d2 * inv) +
                 2.0 * s_sum[0] * (d1 * d1 * inv * inv)) *
                inv;
    return out;
  }

  // Samples below `final_upto` have their final attitude (no later block
  // blends them); with all == true the run is complete. Computes what is left
  // (finite-difference body rates, the IMU), hands the output samples over
  // and drops what no later block reads.
  void finalize(std::size_t final_upto, bool all) {
    // The thesis stencils read attitudes two samples on either side.
    const std::size_t ready_upto = kernel_rates_ || all ? final_upto : (final_upto > 2 ? final_upto - 2 : 0);
    for (; next_final_ < ready_upto; ++next_final_) {
      const std::size_t i = next_final_;
      Kinematics& kin = pending(i);
      if (!kernel_rates_) {
        // Thesis stencils on the final smoothed attitudes, in each sample's
        // own chart: rho_j = log(R~_i^T R~_j) is 0 at i where W(0) = I, so
        // omega_i is the Eq. 3.71-3.74 derivative of rho at i (Eq. 3.59-3.60).
        const Mat3 Rt = kin.attitude.transpose();
        auto at_rho = [&](std::size_t j) -> Vec3 {
          return j == i ? Vec3::Zero() : so3::log(Rt * pending(j).attitude);
        };
        const std::size_t n = all ? dense_count_ : dense_count_ + 3;  // interior: n is beyond i + 2
        kin.angular_rate_rad_s = derivatives::stencil(at_rho, i, n, period_s_);
      }
      const auto every = static_cast<std::int64_t>(output_every_);
      if (kin.t_ns >= t_first_ && kin.t_ns <= t_last_ && floor_mod(k0_ + static_cast<std::int64_t>(i), every) == 0)
        out_.push_back({kin, imu_from_kinematics(opt_.scene, kin)});
    }
    // Drop what no later work reads: pending samples before next_final_ - 2
    // (stencils), dense samples and segments before the next block's reach.
    const std::size_t keep_pending = next_final_ > 2 ? next_final_ - 2 : 0;
    while (pending_first_ < keep_pending && !pending_.empty()) {
      pending_.pop_front();
      ++pending_first_;
    }
    const std::size_t keep_dense = next_begin_ > reach_ ? next_begin_ - reach_ : 0;
    while (dense_first_ < keep_dense && !dense_.empty()) {
      dense_.pop_front();
      ++dense_first_;
    }
    while (segments_.size() > 1 && segments_[1].first_index <= keep_dense) segments_.pop_front();
  }

  const PipelineOptions opt_;  // as run: oversampled if Delta is small
  std::size_t output_every_;   // the oversampling factor
  std::deque<StreamSample>& out_;
  double period_s_;
  smoothing::UniformKernel kernel_;
  interp::SegmentBuilder builder_;
  bool kernel_rates_, closed_form_, global_;
  std::optional<KernelMoments> moments_;
  std::size_t nominal_ = 0, overlap_ = 0, reach_ = 0, node_step_ = 1;
  std::int64_t pad_s_ = 0;

  std::size_t real_count_ = 0;
  TimeNs origin_ns_;            // the stream's output grid: origin + floor(k 1e9 / rate)
  std::int64_t k0_ = 0;         // grid index of dense sample 0
  TimeNs t_first_ = 0, t_last_ = 0, dense_end_ns_ = 0;
  bool head_done_ = false, finished_ = false, end_known_ = false;
  std::vector<Pose> head_;
  std::array<Pose, kEndKnots> tail_;  // the run's last knots, newest last

  std::deque<SegmentInfo> segments_;
  std::deque<Pose> dense_;
  std::size_t dense_first_ = 0, dense_count_ = 0;
  std::deque<Kinematics> pending_;
  std::size_t pending_first_ = 0, next_begin_ = 0, next_final_ = 0;

  // Scratch of one block solve.
  std::size_t a_lo_ = 0, a_hi_ = 0;
  std::vector<Vec3> rho_, delta_, delta_s_, velocity_, rates_;
  std::vector<Mat3> attitudes_;
};

namespace {
// Exact decimal seconds: a double would round an epoch time to ~us.
std::string knot_time(TimeNs t_ns) { return format_decimal_seconds(t_ns) + " s"; }
}  // namespace

StreamPipeline::StreamPipeline(const PipelineOptions& options) : options_(options) {
  if (options.rate_hz <= 0 || options.rate_hz > 1'000'000)
    throw std::invalid_argument("output rate " + std::to_string(options.rate_hz) + " Hz: expected 1..1000000");
  if (!(options.max_gap_s > 0.0)) throw std::invalid_argument("max gap must be > 0 s");
  // The one cap on the window (core/limits.hpp), whoever chose Delta.
  if (options.kernel.delta > limits::kMaxWindowSamples)
    throw limits::SizeLimitError("smoothing window Delta " + std::to_string(options.kernel.delta) +
                                 " samples: at most " + std::to_string(limits::kMaxWindowSamples));
  if (options.causal) {
    CausalHermiteOptions co;
    co.scene = options.scene;
    co.rate_hz = options.rate_hz;
    co.max_gap_ns = static_cast<TimeNs>(std::llround(std::min(options.max_gap_s, 1e9) * 1e9));
    causal_ = std::make_unique<CausalHermite>(co);
  }
  // Construct one run now so bad kernel/spline options fail here, not at the first knot.
  run_ = std::make_unique<Run>(options_, out_, 0);
}

void StreamPipeline::push(const Pose& knot, const PoseRates& rates) {
  if (!causal_) return push(knot);
  if (finished_) throw std::logic_error("StreamPipeline::push after finish");
  causal_->push(knot, rates);  // refuses (changing nothing) what it cannot follow
  if (knots_pushed_ == 0) first_knot_ns_ = knot.t_ns;
  last_knot_ = knot;
  ++knots_pushed_;
  CausalSample c;
  while (causal_->pop(c)) {
    out_.push_back({c.kinematics, c.imu});
    newest_output_ns_ = c.kinematics.t_ns;
    any_output_ = true;
  }
}

StreamPipeline::~StreamPipeline() = default;

namespace {
std::string knot_name(std::size_t index, TimeNs t_ns) {
  return "knot " + std::to_string(index) + " (t=" + knot_time(t_ns) + ")";
}
}  // namespace

void StreamPipeline::push(const Pose& knot) {
  if (causal_) return push(knot, PoseRates{});
  if (finished_) throw std::logic_error("StreamPipeline::push after finish");
  // Every knot-level rule first; nothing changes until they all pass.
  const bool gap = check_knot(knot);
  const bool new_run = knots_pushed_ == 0 || gap;

  // The knot is acceptable on its own; what is left can only fail inside the
  // run (a window spanning too much rotation), which Run::push rolls back.
  // A gap's split finishes the old run first, so that one is kept aside.
  std::unique_ptr<Run> old_run;
  const std::size_t out_before = out_.size();
  try {
    if (gap) {
      old_run = std::make_unique<Run>(*run_);
      run_->finish();
      run_ = std::make_unique<Run>(options_, out_, first_knot_ns_);
    } else if (knots_pushed_ == 0) {
      run_ = std::make_unique<Run>(options_, out_, knot.t_ns);  // the output grid starts at the first knot
    }
    run_->push(knot);
  } catch (...) {
    if (old_run) run_ = std::move(old_run);
    if (knots_pushed_ == 0) run_ = std::make_unique<Run>(options_, out_, 0);
    out_.resize(out_before);
    throw;
  }
  record(knot, new_run);
  if (!out_.empty()) {
    newest_output_ns_ = out_.back().kinematics.t_ns;
    any_output_ = true;
  }
}

void StreamPipeline::record(const Pose& knot, bool new_run) {
  if (knots_pushed_ == 0) first_knot_ns_ = knot.t_ns;
  if (new_run) {
    run_first_knot_ = knots_pushed_;
    recent_.clear();
  }
  recent_.push_back(knot);
  while (recent_.size() > 1 && ns_between(recent_.front().t_ns, knot.t_ns) > static_cast<std::uint64_t>(run_->window_half_ns()))
    recent_.pop_front();
  last_knot_ = knot;
  ++knots_pushed_;
}

void StreamPipeline::check_last_run() const {
  if (knots_in_run() >= 2) return;
  if (knots_pushed_ < 2)
    throw interp::InterpolationError("interpolation needs at least 2 knots, got " + std::to_string(knots_pushed_));
  throw GapError(GapError::Kind::isolated, {run_first_knot_}, {last_knot_.t_ns}, options_.max_gap_s);
}

void StreamPipeline::check_trajectory(const std::vector<Pose>& knots, const PipelineOptions& options) {
  StreamPipeline rules(options);
  for (const Pose& knot : knots) {
    const bool gap = rules.check_knot(knot);
    rules.record(knot, rules.knots_pushed_ == 0 || gap);
  }
  rules.check_last_run();
}

bool StreamPipeline::check_knot(const Pose& knot) const {
  interp::check_knot_finite(knot, knots_pushed_);
  bool gap = false;
  if (knots_pushed_ > 0) {
    interp::check_next_knot(last_knot_, knot, knots_pushed_);
    const auto max_gap_ns = static_cast<std::uint64_t>(std::min(options_.max_gap_s, 1e9) * 1e9);
    const std::uint64_t step_ns = ns_between(last_knot_.t_ns, knot.t_ns);  // exact for any ordered pair
    if (step_ns > max_gap_ns) {
      if (options_.gap_policy == GapPolicy::error)
        throw GapError(GapError::Kind::too_long, {knots_pushed_ - 1, knots_pushed_}, {last_knot_.t_ns, knot.t_ns},
                       options_.max_gap_s);
      // GapPolicy::split: the stretch before the gap ends here, with its own
      // end windows; the next starts at this knot.
      if (knots_in_run() < 2)
        throw GapError(GapError::Kind::isolated, {run_first_knot_}, {last_knot_.t_ns}, options_.max_gap_s);
      gap = true;
    }
  }
  const bool new_run = knots_pushed_ == 0 || gap;
  check_padding(knot, new_run);
  check_chart_span(knot, new_run);
  return gap;
}

// Ends::extrapolate pads pad_ns, plus extra_intervals() knot intervals h, before a run's
// first knot and after its last (virtual knots, see extend()); a knot whose
// padding would leave int64 is refused here rather than overflow there. Every
// knot is checked as if it were the last; the second knot of a run also
// checks the head padding of the first, which uses the first interval.
void StreamPipeline::check_padding(const Pose& knot, bool new_run) const {
  if (options_.ends != Ends::extrapolate) return;
  const TimeNs pad_ns = run_->pad_ns();
  const auto refuse = [&](std::size_t index, TimeNs t_ns, TimeNs reach_ns, const char* side) {
    throw interp::InterpolationError(knot_name(index, t_ns) + ": the end extrapolation reaches " +
                                     std::to_string(static_cast<double>(reach_ns) * 1e-9) + " s " + side +
                                     " it, beyond the int64 nanosecond time range; move the trajectory's times "
                                     "away from +-9.22e9 s");
  };
  const TimeNs h_ns = new_run ? 0 : knot.t_ns - last_knot_.t_ns;  // <= the gap limit: no overflow
  const TimeNs reach_ns = saturating_add_ns(pad_ns, saturating_mul_ns(run_->extra_intervals(), h_ns));
  if (!checked_add_ns(knot.t_ns, reach_ns)) refuse(knots_pushed_, knot.t_ns, reach_ns, "after");
  if (new_run && !checked_sub_ns(knot.t_ns, pad_ns)) refuse(knots_pushed_, knot.t_ns, pad_ns, "before");
  if (!new_run && knots_in_run() == 1 && !checked_sub_ns(last_knot_.t_ns, reach_ns))
    refuse(run_first_knot_, last_knot_.t_ns, reach_ns, "before");
}

// Knot-level form of the chart rule (kMaxChartAngleRad): two knots within one
// smoothing half-window of each other share windows, and a window holding
// attitudes more than kMaxChartAngleRad apart fits no chart. Refusing the knot
// that brings such an attitude (a heading glitch) keeps the stream going;
// without this the run would only fail later, at some good knot's push, and
// then at every one after it.
void StreamPipeline::check_chart_span(const Pose& knot, bool new_run) const {
  if (options_.chart == Chart::global || new_run) return;
  const auto span_ns = static_cast<std::uint64_t>(run_->window_half_ns());
  for (auto it = recent_.rbegin(); it != recent_.rend(); ++it) {
    if (ns_between(it->t_ns, knot.t_ns) > span_ns) break;
    const double angle_rad = so3::angle(it->attitude.transpose() * knot.attitude);
    if (angle_rad > kMaxChartAngleRad) {
      const auto index = knots_pushed_ - 1 - static_cast<std::size_t>(it - recent_.rbegin());
      throw std::invalid_argument(knot_name(knots_pushed_, knot.t_ns) + ": the smoothing window spans more "
                                  "rotation than a chart can hold (> " + std::to_string(kMaxChartAngleRad) +
                                  " rad): its attitude is " + std::to_string(angle_rad) + " rad from that of " +
                                  knot_name(index, it->t_ns) + ", within one smoothing half-window (" +
                                  std::to_string(static_cast<double>(span_ns) * 1e-9) +
                                  " s); a glitch, or reduce Delta, or add knots");
    }
  }
}

void StreamPipeline::finish() {
  if (finished_) return;
  if (causal_) {  // every sample up to the last knot is already out; nothing extrapolated beyond it
    finished_ = true;
    return;
  }
  check_last_run();
  run_->finish();
  finished_ = true;
  if (!out_.empty()) {
    newest_output_ns_ = out_.back().kinematics.t_ns;
    any_output_ = true;
  }
}

bool StreamPipeline::pop(StreamSample& out) {
  if (out_.empty()) return false;
  out = out_.front();
  out_.pop_front();
  return true;
}

std::size_t StreamPipeline::buffered_samples() const {
  return causal_ ? out_.size() : run_->buffered() + out_.size();
}

TimeNs StreamPipeline::current_lag_ns() const {
  return any_output_ && knots_pushed_ > 0 ? last_knot_.t_ns - newest_output_ns_ : 0;
}

TimeNs StreamPipeline::lookahead_ns(const PipelineOptions& output_options, TimeNs knot_interval_ns) {
  // The causal method: a sample is final once the knot after it arrived.
  if (output_options.causal) return CausalHermite::lookahead_ns(knot_interval_ns);
  const PipelineOptions options = internal_options(output_options);
  const auto delta = static_cast<std::int64_t>(options.kernel.delta);
  const bool global = options.chart == Chart::global;
  const std::int64_t nominal = std::max<std::int64_t>(16, 2 * delta);
  const std::int64_t overlap = global ? 0 : std::max<std::int64_t>(4, delta / 4);
  const auto node_step = static_cast<std::int64_t>(attitude_node_step(options));
  const std::int64_t reach = delta + std::max<std::int64_t>(overlap, 4) + (node_step > 1 ? node_step : 0);
  // Sample i is final once the block holding i + overlap is solved; that block
  // (at most nominal long) reads reach beyond its end; the thesis stencils
  // read two more; a dense sample needs the segment around it, i.e. the next
  // knot plus the spline look-ahead.
  const std::int64_t samples = overlap + nominal + reach + 3;
  const bool tangents = options.interpolation.method == interp::Method::hermite ||
                        options.interpolation.method == interp::Method::park_ravani;
  const std::int64_t knots = 1 + (tangents ? options.interpolation.spline_window_knots : 0);
  return saturating_add_ns(saturating_mul_ns(samples, kNsPerSecond) / options.rate_hz,
                           saturating_mul_ns(knot_interval_ns, knots));
}

void run_streaming(const std::vector<Pose>& knots, const PipelineOptions& options, const StreamSampleSink& sink,
                   const ProgressFn& progress) {
  // Whole-list checks first, so a bad file is refused before any work, and
  // the derived sizes before anything is allocated for them (core/limits.hpp).
  interp::check_knots(knots);
  (void)batch_sample_count(knots, options.rate_hz);
  // Park-Ravani's recursion diverges on long trajectories; the whole list is
  // at hand, so say so (naming the knots) before its wild attitudes reach the
  // smoother, which would only report a window spanning too much rotation.
  if (options.interpolation.method == interp::Method::park_ravani)
    (void)interp::park_ravani_coefficients(knots, options.interpolation);
  StreamPipeline stream(options);
  StreamSample sample;
  auto drain = [&] {
    while (stream.pop(sample)) sink(sample);
  };
  const std::size_t report_every = std::max<std::size_t>(1, knots.size() / 50);
  for (std::size_t k = 0; k < knots.size(); ++k) {
    stream.push(knots[k]);
    drain();
    if (progress && k % report_every == 0) progress(static_cast<double>(k) / static_cast<double>(knots.size()));
  }
  stream.finish();
  drain();
  if (progress) progress(1.0);
}

}  // namespace imuemu
