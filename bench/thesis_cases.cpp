// Data behind the thesis' Appendix A and B figures (Figures 2-8): writes one
// CSV per curve into the directory given as argv[1], for
// scripts/thesis_figures.py to plot, and prints a summary of each curve.
//
//   Table 1 (two knots) : geodesic (Fig. 2), its heading against linear heading
//                         interpolation (Fig. 3), Lemma 3.22 minimum
//                         acceleration with (sigma, mu) = (1, 3) and (10, -5)
//                         (Fig. 4).
//   Table 2 left/right  : Park-Ravani §3.6.1 (Figs. 5, 6) and the §3.6.2
//                         procedure, geodesic + Eq. 3.68 bump smoothing with
//                         Delta = 10 and Phi(t_j - t_i), t in seconds (Figs. 7, 8).
//
// All at 100 Hz, attitude only. The smoothing is the literal Eq. 3.68 on the
// global exponential coordinates r = log R (thesis §3.6.2), written out here
// so this tool depends only on core/interpolation and core/so3.
#include <Eigen/Geometry>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <numbers>
#include <string>
#include <vector>

#include "core/attitude.hpp"
#include "core/interpolation.hpp"
#include "core/so3.hpp"

namespace {

using imuemu::kNsPerSecond;
using imuemu::Mat3;
using imuemu::Pose;
using imuemu::TimeNs;
using imuemu::Vec3;
namespace interp = imuemu::interp;
namespace so3 = imuemu::so3;

constexpr double kDeg = std::numbers::pi / 180.0;
constexpr TimeNs kStepNs = kNsPerSecond / 100;  // 100 Hz output (Appendix A, B)

struct Hpr {
  double heading_deg, pitch_deg, roll_deg;
};

// Eq. 1.2 through the product's own attitude room (the tests check it
// against an independent Eigen AngleAxis product).
Mat3 rotation_from_hpr_deg(const Hpr& a) {
  return imuemu::attitude::rotation_from_hpr({a.heading_deg * kDeg, a.pitch_deg * kDeg, a.roll_deg * kDeg});
}

Hpr hpr_deg_from_rotation(const Mat3& R) {
  const imuemu::attitude::HeadingPitchRoll a = imuemu::attitude::hpr_from_rotation(R);
  return {a.heading_rad / kDeg, a.pitch_rad / kDeg, a.roll_rad / kDeg};
}

struct Knot {
  double t_s;
  Hpr hpr;
};

const std::vector<Knot> kTable1 = {{1, {20, 0, 30}}, {2, {20, 10, 5}}};
const std::vector<Knot> kTable2Right = {{1, {10, 0, 0}},   {2, {15, 3, 5}},    {3, {30, 10, 15}},
                                        {4, {40, 20, 15}}, {5, {50, 25, 20}},  {6, {40, 20, 30}},
                                        {7, {35, 25, 35}}, {8, {30, 30, 40}},  {9, {25, 35, 45}},
                                        {10, {45, 25, 50}}};
const std::vector<Knot> kTable2Left(kTable2Right.begin(), kTable2Right.begin() + 4);

std::vector<Pose> poses(const std::vector<Knot>& knots) {
  std::vector<Pose> out;
  for (const Knot& k : knots) {
    out.push_back({static_cast<TimeNs>(std::llround(k.t_s * 1e9)), Vec3::Zero(), rotation_from_hpr_deg(k.hpr)});
  }
  return out;
}

std::vector<TimeNs> output_times(const std::vector<Pose>& knots) {
  std::vector<TimeNs> t;
  for (TimeNs x = knots.front().t_ns; x <= knots.back().t_ns; x += kStepNs) t.push_back(x);
  return t;
}

struct Curve {
  std::vector<TimeNs> t_ns;
  std::vector<Mat3> R;
};

Curve run(const std::vector<Knot>& table, interp::Method method, double sigma = 1.0, double mu = 1.0) {
  const auto knots = poses(table);
  interp::Options o;
  o.method = method;
  o.sigma = sigma;
  o.mu = mu;
  Curve c;
  c.t_ns = output_times(knots);
  for (const Pose& p : interp::interpolate(knots, c.t_ns, o)) c.R.push_back(p.attitude);
  return c;
}

// Eq. 3.66/3.68: Phi(t) = exp(-1/(1-t^2)) on |t| < 1, t in seconds, window of
// +-delta samples clipped at the ends and renormalised.
double phi(double t_s) { return std::abs(t_s) < 1.0 ? std::exp(-1.0 / (1.0 - t_s * t_s)) : 0.0; }

Curve smoothed(const std::vector<Knot>& table, int delta) {
  const Curve g = run(table, interp::Method::geodesic);
  const std::size_t m = g.t_ns.size();
  std::vector<Vec3> r(m);
  for (std::size_t i = 0; i < m; ++i) r[i] = so3::log(g.R[i]);  // global exponential coordinates
  Curve c;
  c.t_ns = g.t_ns;
  const std::size_t d = static_cast<std::size_t>(delta);
  for (std::size_t i = 0; i < m; ++i) {
    const std::size_t lo = i >= d ? i - d : 0;
    const std::size_t hi = std::min(m - 1, i + d);
    Vec3 num = Vec3::Zero();
    double den = 0.0;
    for (std::size_t j = lo; j <= hi; ++j) {
      const double w = phi(static_cast<double>(g.t_ns[j] - g.t_ns[i]) * 1e-9);
      num += w * r[j];
      den += w;
    }
    c.R.push_back(so3::exp(num / den));
  }
  return c;
}

// Body rate magnitude by forward differences |log(R_k^T R_{k+1})| / dt; the
// last sample repeats the previous value.
std::vector<double> rate_deg_s(const Curve& c) {
  std::vector<double> w(c.R.size(), 0.0);
  for (std::size_t k = 0; k + 1 < c.R.size(); ++k) {
    const double dt = static_cast<double>(c.t_ns[k + 1] - c.t_ns[k]) * 1e-9;
    w[k] = so3::angle(c.R[k].transpose() * c.R[k + 1]) / dt / kDeg;
  }
  if (w.size() > 1) w.back() = w[w.size() - 2];
  return w;
}

std::string seconds_text(TimeNs t_ns) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%" PRId64 ".%09" PRId64, t_ns / kNsPerSecond, t_ns % kNsPerSecond);
  return buf;
}

void write_curve(const std::filesystem::path& file, const Curve& c) {
  std::ofstream out(file);
  out << "time_s,heading_deg,pitch_deg,roll_deg,angular_rate_deg_s\n";
  const auto w = rate_deg_s(c);
  char buf[160];
  for (std::size_t k = 0; k < c.R.size(); ++k) {
    const Hpr a = hpr_deg_from_rotation(c.R[k]);
    std::snprintf(buf, sizeof buf, ",%.9f,%.9f,%.9f,%.9f\n", a.heading_deg, a.pitch_deg, a.roll_deg, w[k]);
    out << seconds_text(c.t_ns[k]) << buf;
  }
  if (!out) throw std::runtime_error("cannot write " + file.string());
}

void write_knots(const std::filesystem::path& file, const std::vector<Knot>& table) {
  std::ofstream out(file);
  out << "time_s,heading_deg,pitch_deg,roll_deg\n";
  for (const Knot& k : table) {
    out << k.t_s << ',' << k.hpr.heading_deg << ',' << k.hpr.pitch_deg << ',' << k.hpr.roll_deg << '\n';
  }
  if (!out) throw std::runtime_error("cannot write " + file.string());
}

void summarize(const std::string& name, const Curve& c) {
  double peak = 0.0, hmin = 1e9, hmax = -1e9, pmin = 1e9, pmax = -1e9, rmin = 1e9, rmax = -1e9;
  for (double w : rate_deg_s(c)) peak = std::max(peak, w);
  for (const Mat3& R : c.R) {
    const Hpr a = hpr_deg_from_rotation(R);
    hmin = std::min(hmin, a.heading_deg), hmax = std::max(hmax, a.heading_deg);
    pmin = std::min(pmin, a.pitch_deg), pmax = std::max(pmax, a.pitch_deg);
    rmin = std::min(rmin, a.roll_deg), rmax = std::max(rmax, a.roll_deg);
  }
  std::printf("%-26s peak rate %9.2f deg/s  heading [%8.2f, %8.2f]  pitch [%7.2f, %7.2f]  roll [%8.2f, %8.2f] deg\n",
              name.c_str(), peak, hmin, hmax, pmin, pmax, rmin, rmax);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::cerr << "usage: " << argv[0] << " OUTPUT_DIR\n"
              << "Writes the CSV data behind the thesis' Figures 2-8 into OUTPUT_DIR.\n";
    return 2;
  }
  try {
    const std::filesystem::path dir = argv[1];
    std::filesystem::create_directories(dir);
    write_knots(dir / "table1_knots.csv", kTable1);
    write_knots(dir / "table2_left_knots.csv", kTable2Left);
    write_knots(dir / "table2_right_knots.csv", kTable2Right);

    struct Named {
      std::string file;
      Curve curve;
    };
    std::vector<Named> curves = {
        {"fig2_geodesic", run(kTable1, interp::Method::geodesic)},
        {"fig4_minaccel_1_3", run(kTable1, interp::Method::min_acceleration, 1.0, 3.0)},
        {"fig4_minaccel_10_-5", run(kTable1, interp::Method::min_acceleration, 10.0, -5.0)},
        {"fig5_park_ravani_4", run(kTable2Left, interp::Method::park_ravani)},
        {"fig6_park_ravani_10", run(kTable2Right, interp::Method::park_ravani)},
        {"fig7_smoothed_4", smoothed(kTable2Left, 10)},
        {"fig8_smoothed_10", smoothed(kTable2Right, 10)},
    };
    for (const Named& n : curves) {
      write_curve(dir / (n.file + ".csv"), n.curve);
      summarize(n.file, n.curve);
    }

    // Fig. 3: heading of Table 1 by linear interpolation of the angles.
    {
      const auto knots = poses(kTable1);
      std::ofstream out(dir / "fig3_linear_heading.csv");
      out << "time_s,heading_deg\n";
      for (TimeNs t : output_times(knots)) {
        const double tau = static_cast<double>(t - knots[0].t_ns) / static_cast<double>(knots[1].t_ns - knots[0].t_ns);
        char buf[64];
        std::snprintf(buf, sizeof buf, ",%.9f\n",
                      kTable1[0].hpr.heading_deg + tau * (kTable1[1].hpr.heading_deg - kTable1[0].hpr.heading_deg));
        out << seconds_text(t) << buf;
      }
      if (!out) throw std::runtime_error("cannot write fig3_linear_heading.csv");
    }
    std::printf("CSV files written to %s\n", dir.string().c_str());
  } catch (const std::exception& e) {
    std::cerr << "thesis_cases: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
