// Densifying a knot trajectory on SE(3) onto output times (thesis §3.5, §3.6):
//  - geodesic two-point interpolation (Prop. 3.19, Eq. 3.44),
//  - minimum-acceleration two-point interpolation along the geodesic with a
//    cubic time warp p(tau), p(0)=0, p(1)=1, p'(0)=sigma, p'(1)=mu (Lemma 3.22),
//  - Park-Ravani multi-point C2 attitude scheme of §3.6.1 (cubic r(tau) per
//    segment, angular velocity and acceleration continuous at the knots), with a
//    natural cubic spline for position (the thesis' suggestion, §3.6.1).
// All three stay in the product for comparison.
#pragma once

#include <array>
#include <deque>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/trajectory.hpp"

namespace imuemu::interp {

enum class Method {
  geodesic,
  min_acceleration,
  park_ravani,
  // Cubic Hermite in each segment's chart at its first knot,
  // R(tau) = R_m exp(rho(tau)), with knot body rates from the cubic-spline
  // (C2) condition written in each knot's own chart (no branch cut is ever
  // near) and carried between charts by W^-1 (as in Eq. 3.63): body rate
  // continuous across knots, angular acceleration continuous to first order
  // in the knot step. Ends clamped to one-sided second-order rates.
  // Positions: cubic spline (C2), clamped to one-sided second-order end
  // slopes. Interpolates the knots.
  hermite,
};

struct Options {
  Method method = Method::geodesic;
  // Lemma 3.22 boundary speeds, in units of the geodesic's own speed.
  double sigma = 1.0;
  double mu = 1.0;
  // Park-Ravani initial conditions, body frame, rad/s and rad/s^2. If
  // initial_rate_from_first_segment is true the initial rate is the first
  // geodesic segment's constant rate (and initial_rate_rad_s is ignored).
  bool initial_rate_from_first_segment = true;
  Vec3 initial_rate_rad_s = Vec3::Zero();
  Vec3 initial_angular_accel_rad_s2 = Vec3::Zero();
  // Hermite knot rates and the cubic-spline position slopes (hermite,
  // park-ravani) solve the C2 condition over the knots within this many
  // knots of each knot, not over the whole trajectory: a streaming engine can
  // then build a segment as soon as spline_window_knots knots beyond it have
  // arrived (its look-ahead). The C2 system's influence decays by 2 - sqrt 3
  // = 0.268 per knot, so the result differs from the whole-trajectory spline
  // by ~0.268^L times the window-end condition's error (L = 4: ~5e-3 of
  // it), and is identical to it when the trajectory has at most L + 1 knots.
  // Measured on the one-hour flight (1 Hz knots, tests/core/test_stream.cpp): gyro
  // RMS error against truth 1.31e-5 (L = 2), 4.2e-6 (3), 1.24e-6 (4),
  // 1.41e-6 (whole trajectory); each knot of L adds one knot interval of
  // look-ahead.
  int spline_window_knots = 4;
};

// Thrown for knots the method cannot interpolate: non-increasing times, fewer
// than two knots, or consecutive attitudes whose relative rotation angle is
// (numerically) pi, where the geodesic is not unique (thesis: Tr(R_{i-1}^T R_i)
// != -1). The message names the two knots (0-based indices and times).
struct InterpolationError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Relative-rotation angle above which two consecutive knots are refused as
// antipodal (rad). pi - 1e-6: below this the log's axis is still well defined.
inline constexpr double kAntipodalMarginRad = 1e-6;

// Pose on the geodesic from a to b (Eq. 3.44) at tau in [0, 1].
Pose geodesic(const Pose& a, const Pose& b, double tau);

// Lemma 3.22 time warp p(tau).
double min_acceleration_warp(double tau, double sigma, double mu);

// One knot segment of any method, as two cubics in tau = (t - t_m) / (t_{m+1} - t_m):
//   R(tau) = R_m exp(rho(tau)),  rho(tau) = ((r[2] tau + r[1]) tau + r[0]) tau
//   d(tau) = d_m + ((p[2] tau + p[1]) tau + p[0]) tau
// (geodesic Eq. 3.44: rho = tau xi; Lemma 3.22: rho = p(tau) xi; Park-Ravani
// Eq. 3.64; hermite: the cubic Hermite in the chart at knot m).
struct Segment {
  Pose start;                       // knot m
  Pose end;                         // knot m + 1
  std::array<Vec3, 3> rho;          // attitude cubic in start's chart (rad)
  std::array<Vec3, 3> position;     // position cubic relative to start (m)
};

// The segment's pose at t_ns + extra_ns (extra_ns in [0, 1)); t within
// [start.t_ns, end.t_ns]. At a knot time (extra_ns == 0) it returns the knot.
Pose evaluate(const Segment& segment, TimeNs t_ns, double extra_ns = 0.0);

// Builds segments incrementally from knots pushed in time order: the one
// implementation behind both interpolate() and the streaming pipeline.
// Segment m is ready once knot m + 1 + lookahead_knots() has been pushed (or
// finish() was called).
class SegmentBuilder {
 public:
  explicit SegmentBuilder(const Options& options);
  // Appends a knot. Throws InterpolationError (naming the knots by their
  // 0-based push index and time) for a non-increasing time, a non-finite pose
  // or an antipodal step to the previous knot, and for a diverging
  // Park-Ravani recursion; the builder is unchanged by a refused knot.
  void push(const Pose& knot);
  // No more knots: builds the remaining segments (needs >= 2 knots).
  void finish();
  std::deque<Segment>& ready() { return ready_; }
  std::size_t knots_pushed() const { return pushed_; }
  // Knots needed beyond a segment's end knot before it can be built.
  int lookahead_knots() const { return lookahead_; }

 private:
  void build_available(bool finished);
  void compute_tangents(std::size_t k, bool finished);

  Options options_;
  int lookahead_;
  std::deque<Pose> knots_;          // knots_[0] has push index first_
  std::deque<Vec3> rates_, slopes_; // tangents (rad/s, m/s) at knots first_ + j, once known
  std::size_t first_ = 0, pushed_ = 0, next_segment_ = 0, tangents_done_ = 0;
  bool finished_ = false;
  std::array<Vec3, 3> pr_prev_{};   // Park-Ravani: previous segment's (c, b, a)
  double pr_prev_duration_s_ = 0.0;
  std::deque<Segment> ready_;
};

// All segments of a knot list (after check_knots).
std::vector<Segment> build_segments(const std::vector<Pose>& knots, const Options& options);

// Evaluates the chosen method at every time in `times` (each within
// [knots.front().t_ns, knots.back().t_ns]; sorted ascending). Knot times may be
// non-uniform for geodesic/min_acceleration; Park-Ravani uses each segment's
// own duration for tau.
// `extra_ns` (empty, or one per time, each in [0, 1)) adds a sub-nanosecond
// offset to each time, so a grid like k/3000 s can be evaluated at its exact
// instants while its timestamps stay integer nanoseconds.
std::vector<Pose> interpolate(const std::vector<Pose>& knots, const std::vector<TimeNs>& times,
                              const Options& options, std::span<const double> extra_ns = {});

// Validates knots (throws InterpolationError naming the offending knots).
void check_knots(const std::vector<Pose>& knots);
// The same checks for one knot following `previous` (index = the new knot's
// 0-based index, for messages).
void check_next_knot(const Pose& previous, const Pose& next, std::size_t index);
void check_knot_finite(const Pose& knot, std::size_t index);

// Park-Ravani coefficients of one segment (§3.6.1, Eq. 3.64): on segment i,
// between knots i-1 and i, R(t) = R_{i-1} exp([a tau^3 + b tau^2 + c tau]) with
// tau = (t - t_{i-1}) / (t_i - t_{i-1}). The coefficients are in tau units, so
// the body rate is W(r) r'(tau) / duration_s.
// Position of every method as a cubic in tau on each knot segment m:
//   d(tau) = d_m + c[0] tau + c[1] tau^2 + c[2] tau^3,  tau in [0, 1],
// the same curve interpolate() evaluates (geodesic: linear; min-accel: the
// Lemma 3.22 warp; park-ravani: natural spline; hermite: clamped spline).
// Lets the smoother integrate the kernel against it in closed form.
using PositionCubic = std::array<Vec3, 3>;
std::vector<PositionCubic> position_cubics(const std::vector<Pose>& knots, const Options& options);

struct ParkRavaniSegment {
  Vec3 a = Vec3::Zero();
  Vec3 b = Vec3::Zero();
  Vec3 c = Vec3::Zero();
  double duration_s = 0.0;
};
// One entry per segment (knots.size() - 1), after check_knots(knots).
std::vector<ParkRavaniSegment> park_ravani_coefficients(const std::vector<Pose>& knots,
                                                        const Options& options);

Method method_from_string(const std::string& name);  // "geodesic", "min-accel", "park-ravani", "hermite"
std::string to_string(Method m);

}  // namespace imuemu::interp
