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
