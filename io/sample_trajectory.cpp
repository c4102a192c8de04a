// The built-in sample trajectories (io/sample_trajectory.hpp).
#include "io/sample_trajectory.hpp"

#include <charconv>
#include <memory>
#include <numbers>
#include <stdexcept>

#include "core/attitude.hpp"
#include "core/earth.hpp"
#include "core/limits.hpp"
#include "core/reference_motion.hpp"
#include "io/decimal_time.hpp"
#include "io/scene_poses.hpp"
#include "io/trajectory_csv.hpp"

namespace imuemu::io {
namespace {

constexpr double kRadToDeg = 180.0 / std::numbers::pi;

// Shortest round-trip decimal (std::to_chars), the CSV's number format.
std::string number(double v) {
  char buf[64];
  const auto res = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, res.ptr);
}

TimeNs seconds_ns(const std::string& what, double seconds) {
  if (const auto ns = limits::checked_ns_from_seconds(seconds)) return *ns;
  throw std::invalid_argument(what + " " + number(seconds) + ": does not fit int64 nanoseconds");
}

}  // namespace

std::string sample_trajectory_csv(const std::string& kind, double duration_s, double period_s) {
  const TimeNs duration_ns = seconds_ns("duration", duration_s);
  const TimeNs period_ns = seconds_ns("period", period_s);
  // The knot count, before the knots are sampled and formatted.
  if (!(period_ns > 0) || duration_ns < 0 ||
      static_cast<std::uint64_t>(duration_ns / period_ns) + 1 > limits::kMaxKnots)
    throw limits::SizeLimitError("a sample trajectory of " + number(duration_s) + " s with knots every " +
                                 number(period_s) + " s: more than " + std::to_string(limits::kMaxKnots) +
                                 " knots; use a longer period");
  std::string text;
  auto line = [&](TimeNs t, const Vec3& p, const attitude::HeadingPitchRoll& hpr) {
    text += io::format_decimal_seconds(t);
    for (double v : {p.x(), p.y(), p.z(), hpr.heading_rad * kRadToDeg, hpr.pitch_rad * kRadToDeg,
                     hpr.roll_rad * kRadToDeg}) {
      text += ',';
      text += number(v);
    }
    text += '\n';
  };
  if (kind == "circle") {
    const reference::Circle motion(500.0, 50.0, 0, duration_ns);
    text = "# imuemu sample: horizontal circle, radius 500 m at 50 m/s, local NED frame\n"
           "time_s,north_m,east_m,down_m,heading_deg,pitch_deg,roll_deg\n";
    for (const Pose& p : reference::sample_knots(motion, period_ns))
      line(p.t_ns, p.position_m, attitude::hpr_from_rotation(p.attitude));
  } else {
    std::unique_ptr<reference::Motion> motion;
    if (kind == "static")
      motion = std::make_unique<reference::Static>(reference::AircraftFlight::default_origin(),
                                                   attitude::HeadingPitchRoll{0.5, 0.02, -0.01}, Physics::ecef, 0,
                                                   duration_ns);
    else
      motion = std::make_unique<reference::AircraftFlight>(Physics::ecef, reference::AircraftFlight::default_origin(),
                                                           0, duration_ns);
    text = "# imuemu sample: " + kind +
           " near Barcelona, WGS84 geodetic position, attitude body FRD to local NED\n"
           "time_s,lat_deg,lon_deg,h_m,heading_deg,pitch_deg,roll_deg\n";
    for (const Pose& p : reference::sample_knots(*motion, period_ns)) {
      const earth::Geodetic g = earth::geodetic_from_ecef(p.position_m);
      const Mat3 R_b_l = attitude::ned_to_ecef(g.latitude_rad, g.longitude_rad).transpose() * p.attitude;
      line(p.t_ns, Vec3(g.latitude_rad * kRadToDeg, g.longitude_rad * kRadToDeg, g.height_m),
           attitude::hpr_from_rotation(R_b_l));
    }
  }
  return text;
}

std::vector<Pose> sample_trajectory_poses(const std::string& kind, double duration_s, double period_s,
                                          Physics physics) {
  const std::string text = sample_trajectory_csv(kind, duration_s, period_s);
  return poses_in_scene(parse_trajectory_csv(text, "built-in sample '" + kind + "'"), physics);
}

}  // namespace imuemu::io
