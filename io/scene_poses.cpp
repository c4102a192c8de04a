#include "io/scene_poses.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <numbers>

#include "core/attitude.hpp"
#include "core/so3.hpp"
#include "core/time_arith.hpp"

namespace imuemu::io {
namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;

struct EcefPose {
  Vec3 x_e;
  Mat3 R_b_e;
};

earth::Geodetic geodetic_of(const TrajectoryRecord& rec, const Vec3& x_e) {
  if (rec.position_kind == PositionKind::geodetic)
    return {rec.position.x() * kDegToRad, rec.position.y() * kDegToRad, rec.position.z()};
  return earth::geodetic_from_ecef(x_e);
}

Mat3 body_to_local(const TrajectoryRecord& rec) {
  if (rec.attitude_kind == AttitudeKind::heading_pitch_roll)
    return attitude::rotation_from_hpr(
        {rec.attitude[0] * kDegToRad, rec.attitude[1] * kDegToRad, rec.attitude[2] * kDegToRad});
  return attitude::rotation_from_quaternion(rec.attitude[0], rec.attitude[1], rec.attitude[2], rec.attitude[3]);
}

EcefPose to_ecef(const TrajectoryRecord& rec) {
  const Vec3 x_e = rec.position_kind == PositionKind::geodetic
                       ? earth::ecef_from_geodetic(geodetic_of(rec, Vec3::Zero()))
                       : rec.position;
  if (rec.attitude_kind == AttitudeKind::quaternion_ecef) return {x_e, body_to_local(rec)};
  const earth::Geodetic g = geodetic_of(rec, x_e);
  return {x_e, attitude::ned_to_ecef(g.latitude_rad, g.longitude_rad) * body_to_local(rec)};
}

}  // namespace

Pose ScenePoseConverter::convert(const TrajectoryRecord& rec, const std::string& source) {
  if (rec.position_kind == PositionKind::local_ned) {
    if (physics_ == Physics::ecef) {
      throw TrajectoryFormatError({source, rec.line, "north_m", 0},
                                  "geodetic (lat_deg,lon_deg,h_m) or ECEF (x_m,y_m,z_m) positions for the ecef scene",
                                  "local north/east/down positions have no Earth origin");
    }
    if (rec.attitude_kind == AttitudeKind::quaternion_ecef)
      throw TrajectoryFormatError({source, rec.line, "qw", 0}, "a body-to-NED attitude with local positions",
                                  "an ECEF attitude");
    if (input_frame_ == InputFrame::earth_fixed)
      throw TrajectoryFormatError({source, rec.line, "north_m", 0},
                                  "Earth-fixed positions like the records before",
                                  "a local north/east/down position after Earth-fixed (geodetic or ECEF) ones: "
                                  "the two have no common frame");
    input_frame_ = InputFrame::local_ned;
    return {rec.t_ns, rec.position, body_to_local(rec)};
  }
  if (physics_ == Physics::flat && input_frame_ == InputFrame::local_ned)
    throw TrajectoryFormatError({source, rec.line, "", 0}, "local north/east/down positions like the records before",
                                "an Earth-fixed (geodetic or ECEF) position after local north/east/down ones: "
                                "the two have no common frame");
  const EcefPose p = to_ecef(rec);
  if (physics_ == Physics::ecef) return {rec.t_ns, p.x_e, p.R_b_e};
  input_frame_ = InputFrame::earth_fixed;
  if (!tangent_) tangent_.emplace(geodetic_of(rec, p.x_e));
  return {rec.t_ns, tangent_->ned_from_ecef(p.x_e), tangent_->R_n_to_e().transpose() * p.R_b_e};
}

namespace {

// WGS84 defining constants (NIMA TR8350.2): semi-major axis and flattening.
constexpr double kWgs84A_m = 6378137.0;
constexpr double kWgs84F = 1.0 / 298.257223563;

// omega_el^l, the rotation rate of the local NED frame carried along at
// velocity v_l (NED) at geodetic g: (lambda_dot cos(lat), -lat_dot,
// -lambda_dot sin(lat)) with lat_dot = v_N/(R_M+h), lambda_dot =
// v_E/((R_N+h) cos(lat)) (meridian and prime-vertical radii of curvature).
Vec3 transport_rate_local(const earth::Geodetic& g, const Vec3& v_l) {
  const double e2 = kWgs84F * (2.0 - kWgs84F);
  const double s = std::sin(g.latitude_rad);
  const double w = std::sqrt(1.0 - e2 * s * s);
  const double r_n = kWgs84A_m / w;
  const double r_m = kWgs84A_m * (1.0 - e2) / (w * w * w);
  return {v_l.y() / (r_n + g.height_m), -v_l.x() / (r_m + g.height_m),
          -v_l.y() * std::tan(g.latitude_rad) / (r_n + g.height_m)};
}

}  // namespace

PoseRates ScenePoseConverter::convert_rates(const TrajectoryRecord& rec) const {
  const PoseRates& in = rec.rates;
  if (!in.any() || rec.position_kind == PositionKind::local_ned) return in;  // local NED is the flat scene's frame
  const Vec3 x_e = rec.position_kind == PositionKind::geodetic
                       ? earth::ecef_from_geodetic(geodetic_of(rec, Vec3::Zero()))
                       : rec.position;
  const earth::Geodetic g = geodetic_of(rec, x_e);
  const Mat3 R_l_e = attitude::ned_to_ecef(g.latitude_rad, g.longitude_rad);
  // Velocity and acceleration as given: in local NED for geodetic records,
  // in ECEF for ECEF ones.
  const bool given_in_local = rec.position_kind == PositionKind::geodetic;
  const auto to_ecef = [&](const Vec3& v) -> Vec3 { return given_in_local ? Vec3(R_l_e * v) : v; };
  // The scene's axes: ECEF, or the fixed tangent frame of the first record.
  const auto to_scene = [&](const Vec3& v_e) -> Vec3 {
    return physics_ == Physics::ecef || !tangent_ ? v_e : Vec3(tangent_->R_n_to_e().transpose() * v_e);
  };
  PoseRates out;
  if (in.velocity_m_s) out.velocity_m_s = to_scene(to_ecef(*in.velocity_m_s));
  if (in.acceleration_m_s2) out.acceleration_m_s2 = to_scene(to_ecef(*in.acceleration_m_s2));
  if (in.angular_rate_rad_s) {
    Vec3 w = *in.angular_rate_rad_s;
    if (rec.attitude_kind != AttitudeKind::quaternion_ecef && in.velocity_m_s) {
      // omega_eb^b = omega_lb^b + R_b^l^T omega_el^l (R_b^e = R_l^e R_b^l
      // differentiated); the tangent frame is fixed to the Earth, so the
      // same rate is relative to it.
      const Vec3 v_l = given_in_local ? *in.velocity_m_s : Vec3(R_l_e.transpose() * *in.velocity_m_s);
      w += body_to_local(rec).transpose() * transport_rate_local(g, v_l);
    }
    out.angular_rate_rad_s = w;
  }
  return out;
}

std::vector<Pose> poses_in_scene(const Trajectory& trajectory, Physics physics) {
  std::vector<Pose> poses;
  poses.reserve(trajectory.records.size());
  ScenePoseConverter converter(physics);
  for (const auto& rec : trajectory.records) poses.push_back(converter.convert(rec, trajectory.source));
  return poses;
}

namespace {

std::string fixed(double v, int decimals) {
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof buf, v, std::chars_format::fixed, decimals);
  return std::string(buf, r.ptr);
}

std::string sci(double v) {
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof buf, v, std::chars_format::scientific, 2);
  return std::string(buf, r.ptr);
}

double median(std::vector<double> v) {
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

Vec3 ecef_position(const TrajectoryRecord& rec) {
  return rec.position_kind == PositionKind::geodetic ? earth::ecef_from_geodetic(geodetic_of(rec, Vec3::Zero()))
                                                     : rec.position;
}

// Up to kPlausibilitySamples record indices spread evenly over the file.
std::vector<std::size_t> sample_indices(std::size_t n) {
  std::vector<std::size_t> out;
  const std::size_t count = std::min(n, kPlausibilitySamples);
  for (std::size_t s = 0; s < count; ++s) out.push_back(count == 1 ? 0 : s * (n - 1) / (count - 1));
  return out;
}

// The first record at least min_ns after (or before, step -1) record j,
// within max_ns; npos if none.
std::size_t neighbour(const std::vector<TrajectoryRecord>& r, std::size_t j, int step, TimeNs min_ns, TimeNs max_ns) {
  for (std::size_t i = j;;) {
    if (step < 0 ? i == 0 : i + 1 >= r.size()) return std::string::npos;
    i = step < 0 ? i - 1 : i + 1;
    const std::uint64_t d = step < 0 ? ns_between(r[i].t_ns, r[j].t_ns) : ns_between(r[j].t_ns, r[i].t_ns);
    if (d > static_cast<std::uint64_t>(max_ns)) return std::string::npos;
    if (d >= static_cast<std::uint64_t>(min_ns)) return i;
  }
}

}  // namespace

std::optional<std::string> attitude_frame_warning(const Trajectory& trajectory) {
  if (trajectory.position_kind == PositionKind::local_ned ||
      trajectory.attitude_kind == AttitudeKind::heading_pitch_roll)
    return std::nullopt;
  const bool columns_local = trajectory.attitude_kind == AttitudeKind::quaternion;
  const std::vector<TrajectoryRecord>& r = trajectory.records;
  // Knots 2..10 s apart: long enough that GNSS-like position noise (sigma
  // 2 m) stays near 1 m/s^2 (sqrt(6) sigma / h^2) in the second difference,
  // a few degrees against g, and short enough to follow a turn.
  constexpr TimeNs kMinStepNs = 2 * kNsPerSecond, kMaxStepNs = 10 * kNsPerSecond;
  std::vector<double> angle_as_written_deg, angle_other_deg, force_difference_m_s2, force_m_s2;
  std::size_t first_line = 0, last_line = 0;
  for (const std::size_t j : sample_indices(r.size())) {
    const std::size_t i = neighbour(r, j, -1, kMinStepNs, kMaxStepNs);
    const std::size_t k = neighbour(r, j, +1, kMinStepNs, kMaxStepNs);
    if (i == std::string::npos || k == std::string::npos) continue;
    const double h1 = static_cast<double>(r[j].t_ns - r[i].t_ns) * 1e-9;
    const double h2 = static_cast<double>(r[k].t_ns - r[j].t_ns) * 1e-9;
    const Vec3 xi = ecef_position(r[i]), xj = ecef_position(r[j]), xk = ecef_position(r[k]);
    // Second divided difference (acceleration) and central velocity.
    const Vec3 a = 2.0 * ((xk - xj) / h2 - (xj - xi) / h1) / (h1 + h2);
    const Vec3 v = (xk - xi) / (h1 + h2);
    // Eq. 3.70 in the rotating ECEF frame; normal gravity already holds the
    // centrifugal term.
    const Vec3 f_e = a + 2.0 * earth::rotation_rate_ecef().cross(v) - earth::normal_gravity_ecef(xj);
    // Near free fall there is no up axis to compare; a non-finite force (a
    // degenerate position) is skipped too, so the medians never see a NaN.
    if (!(f_e.norm() >= 0.5 * earth::kStandardGravity_m_s2)) continue;
    const Mat3 Q = body_to_local(r[j]);  // the quaternion's matrix, whatever frame it is for
    const earth::Geodetic g = geodetic_of(r[j], xj);
    const Mat3 as_local = attitude::ned_to_ecef(g.latitude_rad, g.longitude_rad) * Q;  // read as R_b^l
    const Mat3& as_ecef = Q;                                                            // read as R_b^e
    const Mat3& written = columns_local ? as_local : as_ecef;
    const Mat3& other = columns_local ? as_ecef : as_local;
    const auto angle_deg = [&](const Mat3& R_b_e) {
      const Vec3 up_e = -R_b_e.col(2);  // body FRD: z is down
      return std::acos(std::clamp(up_e.dot(f_e.normalized()), -1.0, 1.0)) * 180.0 / std::numbers::pi;
    };
    angle_as_written_deg.push_back(angle_deg(written));
    angle_other_deg.push_back(angle_deg(other));
    force_difference_m_s2.push_back((written.transpose() * f_e - other.transpose() * f_e).norm());
    force_m_s2.push_back(f_e.norm());
    if (first_line == 0) first_line = r[j].line;
    last_line = r[j].line;
  }
  if (angle_as_written_deg.size() < 3) return std::nullopt;
  const double written_deg = median(angle_as_written_deg), other_deg = median(angle_other_deg);
  // A wide margin between the readings as well: a correct file can put the
  // body's up axis near the other reading's by chance (inverted flight or a
  // z-up body frame at high latitude); the confusion itself gives about
  // 90 deg + latitude against a few degrees.
  if (!(written_deg > 45.0 && other_deg < 15.0 && written_deg - other_deg > 60.0)) return std::nullopt;
  const std::string written_cols = columns_local ? "qw,qx,qy,qz" : "qw_ecef,qx_ecef,qy_ecef,qz_ecef";
  const std::string other_cols = columns_local ? "qw_ecef,qx_ecef,qy_ecef,qz_ecef" : "qw,qx,qy,qz";
  const std::string written_frame = columns_local ? "q_b^l (body to local NED)" : "q_b^e (body to ECEF)";
  const std::string other_frame = columns_local ? "q_b^e (body to ECEF)" : "q_b^l (body to local NED)";
  return trajectory.source + ": the columns " + written_cols + " are read as " + written_frame + ", but at " +
         std::to_string(angle_as_written_deg.size()) + " knots sampled between lines " + std::to_string(first_line) +
         " and " + std::to_string(last_line) + " the specific force the positions imply (median " +
         fixed(median(force_m_s2), 2) + " m/s^2) is " + fixed(written_deg, 1) +
         " deg (median) from the body's up axis read that way and " + fixed(other_deg, 1) +
         " deg read as " + other_frame + ", as a vehicle's is: the file probably holds " + other_frame +
         "; if so, name the columns " + other_cols + ". Read as written, the accelerometers differ by " +
         fixed(median(force_difference_m_s2), 1) + " m/s^2 (median) from that reading";
}

std::optional<std::string> flat_scene_warning(const Trajectory& trajectory, Physics physics) {
  if (physics != Physics::flat || trajectory.records.empty()) return std::nullopt;
  const std::vector<TrajectoryRecord>& r = trajectory.records;
  const double R = 6371000.0;  // mean Earth radius: scale of gravity's turn, d/R rad
  const double g = earth::kStandardGravity_m_s2;
  if (trajectory.position_kind == PositionKind::local_ned) {
    // ECEF values in north_m,east_m,down_m: |p| at the Earth's radius from
    // the frame origin and a "height" beyond 100 km. Either alone is
    // possible (UTM northings reach 1e7 m; a down_m of -1e5 is a rocket);
    // both together are an Earth-fixed position in the wrong columns.
    const auto far = std::max_element(r.begin(), r.end(), [](const TrajectoryRecord& a, const TrajectoryRecord& b) {
      return a.position.norm() < b.position.norm();
    });
    const double norm = far->position.norm();
    if (!(norm > 6.2e6 && norm < 6.6e6 && std::abs(far->position.z()) > 1e5)) return std::nullopt;
    return trajectory.source + ":" + std::to_string(far->line) + ": the flat scene's local NED position (" +
           sci(far->position.x()) + ", " + sci(far->position.y()) + ", " + sci(far->position.z()) + ") m is " +
           sci(norm) + " m from the frame origin, the Earth's radius, with down_m " + sci(far->position.z()) +
           " m: these look like ECEF coordinates; name the columns x_m,y_m,z_m (the flat scene then works in the "
           "tangent frame of the first record) or use --scene ecef";
  }
  double extent_m = 0.0, speed_m_s = 0.0;
  const Vec3 origin = ecef_position(r.front());
  // Speed over steps of at least 1 s: dense noisy fixes (100 Hz GNSS with
  // metres of noise) would give hundreds of m/s knot to knot.
  constexpr std::uint64_t kMinSpeedStepNs = 1'000'000'000;
  std::size_t previous = 0;
  for (std::size_t i = 0; i < r.size(); ++i) {
    const Vec3 x = ecef_position(r[i]);
    extent_m = std::max(extent_m, (x - origin).norm());
    const std::uint64_t step_ns = ns_between(r[previous].t_ns, r[i].t_ns);
    if (step_ns >= kMinSpeedStepNs) {
      speed_m_s = std::max(speed_m_s, (x - ecef_position(r[previous])).norm() / (static_cast<double>(step_ns) * 1e-9));
      previous = i;
    }
  }
  return trajectory.source + ": --scene flat on Earth-fixed (" + std::string(to_string(trajectory.position_kind)) +
         ") positions: they are put in the NED tangent frame of line " + std::to_string(r.front().line) +
         " and the flat physics leaves out the Earth rate (" + sci(earth::kRotationRate_rad_s) +
         " rad/s in the gyros), Coriolis (2 omega_ie v, up to " + sci(2.0 * earth::kRotationRate_rad_s * speed_m_s) +
         " m/s^2 at the fastest speed over 1 s or more, " + fixed(speed_m_s, 1) + " m/s) and gravity's turn across the " +
         fixed(extent_m, 0) + " m the trajectory reaches from that origin (g d/R = " + sci(g * extent_m / R) +
         " m/s^2 in the accelerometers); --scene ecef has them all";
}

}  // namespace imuemu::io
