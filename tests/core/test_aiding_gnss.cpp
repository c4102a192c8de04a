// GNSS truth, time and errors (core/aiding/, issue 28) against independent
// truth: a lever arm under an analytic rotation (and its numerical
// derivative), GPS week / time of week / UTC at dates known from
// IS-GPS-200 and IERS Bulletin C, and the Gauss-Markov statistics against
// their sampling distributions over a long run.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <numbers>
#include <vector>

#include "core/aiding/calendar.hpp"
#include "core/aiding/gnss.hpp"
#include "core/aiding/gnss_time.hpp"
#include "core/attitude.hpp"
#include "core/setting_error.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace imuemu::aiding {}
namespace unity_core_test_aiding_gnss {
namespace imuemu { using namespace ::imuemu; }
namespace imuemu::aiding { using namespace ::imuemu::aiding; }

namespace imuemu::aiding {
namespace {

constexpr TimeNs kS = kNsPerSecond;

TEST(GnssLeverArm, AntennaPositionAndVelocityUnderAYawingBody) {
  // Body at the NED origin moving north at 10 m/s, heading 90 deg (nose
  // east), yawing at 0.2 rad/s; antenna 1 m forward, 0.5 m up (z down: -0.5).
  const Vec3 l(1.0, 0.0, -0.5);
  const Vec3 omega(0.0, 0.0, 0.2);
  const double psi0 = std::numbers::pi / 2.0;
  const auto R = [&](double t) { return attitude::rotation_from_hpr({psi0 + 0.2 * t, 0.0, 0.0}); };
  const AntennaTruth a = antenna_truth(Vec3(0.0, 0.0, 0.0), Vec3(10.0, 0.0, 0.0), R(0.0), omega, l);
  // By hand: forward is east, so the antenna is 1 m east and 0.5 m up.
  EXPECT_NEAR((a.position_m - Vec3(0.0, 1.0, -0.5)).norm(), 0.0, 1e-15);
  // omega x l = (0, 0.2, 0) in body: 0.2 m/s to the right wing, which points south.
  EXPECT_NEAR((a.velocity_m_s - Vec3(10.0 - 0.2, 0.0, 0.0)).norm(), 0.0, 1e-15);
  // And against the derivative of x(t) = p(t) + R(t) l, central difference.
  const double h = 1e-5;
  const Vec3 numeric = Vec3(10.0, 0.0, 0.0) + (R(h) * l - R(-h) * l) / (2.0 * h);
  EXPECT_LT((a.velocity_m_s - numeric).norm(), 1e-9);
}

TEST(GnssLeverArm, RefusesNanAndHugeLeverArms) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const Mat3 I = Mat3::Identity();
  EXPECT_THROW(antenna_truth(Vec3(nan, 0, 0), Vec3::Zero(), I, Vec3::Zero(), Vec3::Zero()), SettingError);
  EXPECT_THROW(antenna_truth(Vec3::Zero(), Vec3::Zero(), I, Vec3::Zero(), Vec3(0, 101.0, 0)), SettingError);
  Mat3 bad = I;
  bad(1, 1) = nan;
  EXPECT_THROW(antenna_truth(Vec3::Zero(), Vec3::Zero(), bad, Vec3::Zero(), Vec3::Zero()), SettingError);
}

TEST(GnssLeverArm, NedOffsetInTheEcefScene) {
  const earth::Geodetic origin{0.7, -1.2, 350.0};
  const Vec3 x = earth::ecef_from_geodetic(origin);
  const earth::Geodetic moved = offset_geodetic(x, Vec3(0.0, 0.0, -10.0));  // 10 m up
  EXPECT_NEAR(moved.height_m, 360.0, 1e-6);
  EXPECT_NEAR(moved.latitude_rad, origin.latitude_rad, 1e-12);
  const Vec3 v_ned = ned_from_ecef_velocity(origin, attitude::ned_to_ecef(0.7, -1.2) * Vec3(3.0, -4.0, 0.5));
  EXPECT_LT((v_ned - Vec3(3.0, -4.0, 0.5)).norm(), 1e-12);
}

TEST(GpsTime, WeekTimeOfWeekAndUtcAtKnownDates) {
  // GPS epoch 1980-01-06T00:00:00Z: week 0, tow 0.
  EXPECT_EQ(gps_from_utc_ns(315'964'800LL * kS), 0);
  // 2017-01-01T00:00:00Z (POSIX 1483228800): GPS - UTC became 18 s
  // (IERS Bulletin C 52); GPS week 1930 began that day, so tow = 18 s.
  const TimeNs gps2017 = gps_from_utc_ns(1'483'228'800LL * kS);
  EXPECT_EQ(gps2017, (1'483'228'800LL - 315'964'800LL + 18) * kS);
  EXPECT_EQ(gps_week_time(gps2017).week, 1930);
  EXPECT_EQ(gps_week_time(gps2017).time_of_week_ns, 18 * kS);
  // One second earlier in UTC (23:59:59): 17 s then, 2 GPS seconds earlier.
  EXPECT_EQ(gps2017 - gps_from_utc_ns(1'483'228'799LL * kS), 2 * kS);
  // The GPS second between them is the leap second: 2016-12-31T23:59:60.
  const UtcCalendar leap = utc_calendar_from_gps_ns(gps2017 - kS + 250'000'000);
  EXPECT_EQ(leap.year, 2016);
  EXPECT_EQ(leap.month, 12);
  EXPECT_EQ(leap.day, 31);
  EXPECT_EQ(leap.hour, 23);
  EXPECT_EQ(leap.minute, 59);
  EXPECT_EQ(leap.second, 60);
  EXPECT_EQ(leap.nanosecond, 250'000'000);
  const UtcCalendar after = utc_calendar_from_gps_ns(gps2017);
  EXPECT_EQ(after.year, 2017);
  EXPECT_EQ(after.second, 0);
  EXPECT_EQ(utc_from_gps_ns(gps2017), 1'483'228'800LL * kS);
  // Second week-number rollover, 2019-04-07T00:00:00Z (POSIX 1554595200):
  // week 2048, which the 10-bit legacy week shows as 0; tow 18 s.
  const GpsWeekTime roll2 = gps_week_time(gps_from_utc_ns(1'554'595'200LL * kS));
  EXPECT_EQ(roll2.week, 2048);
  EXPECT_EQ(roll2.week_mod_1024, 0);
  EXPECT_EQ(roll2.time_of_week_ns, 18 * kS);
  // First rollover, 1999-08-22T00:00:00Z (POSIX 935280000), GPS - UTC = 13 s.
  const GpsWeekTime roll1 = gps_week_time(gps_from_utc_ns(935'280'000LL * kS));
  EXPECT_EQ(roll1.week, 1024);
  EXPECT_EQ(roll1.week_mod_1024, 0);
  EXPECT_EQ(roll1.time_of_week_ns, 13 * kS);
  EXPECT_EQ(gps_ns_from_week_time(2048, 18 * kS), gps_from_utc_ns(1'554'595'200LL * kS));
  // Trajectory time: a run starting 2016-12-31T23:59:58Z sees 3 s later UTC 00:00:00 (the leap second inside).
  const TimeNs epoch = 1'483'228'798LL * kS;
  EXPECT_EQ(utc_from_gps_ns(gps_ns_at(3 * kS, epoch)), 1'483'228'800LL * kS);
  EXPECT_EQ(utc_calendar_from_gps_ns(gps_ns_at(2 * kS, epoch)).second, 60);
  // Every UTC second of 1980..2030 round-trips (sampled daily).
  for (TimeNs t = 315'964'800LL * kS; t < 1'893'456'000LL * kS; t += 86'400LL * kS)
    ASSERT_EQ(utc_from_gps_ns(gps_from_utc_ns(t)), t);
}

TEST(GpsTime, RefusesTimesOutsideTheScale) {
  EXPECT_THROW(gps_from_utc_ns(0), std::invalid_argument);  // 1970: before the GPS epoch
  EXPECT_THROW(gps_week_time(-1), std::invalid_argument);
  EXPECT_THROW(utc_from_gps_ns(-1), std::invalid_argument);
  EXPECT_THROW(gps_ns_from_week_time(1, kNsPerWeek), std::invalid_argument);
  EXPECT_THROW(gps_ns_from_week_time(std::numeric_limits<std::int64_t>::max() / 2, 0), std::invalid_argument);
  EXPECT_THROW(gps_ns_at(std::numeric_limits<TimeNs>::max(), 1'483'228'800LL * kS), std::invalid_argument);
}

// Sample mean, variance and autocorrelation at lag L of one sequence.
struct Stats {
  double mean, var, rho;
};
Stats stats(const std::vector<double>& x, std::size_t lag) {
  const double n = static_cast<double>(x.size());
  double m = 0.0;
  for (double v : x) m += v;
  m /= n;
  double c0 = 0.0, cl = 0.0;
  for (std::size_t i = 0; i < x.size(); ++i) {
    c0 += (x[i] - m) * (x[i] - m);
    if (i + lag < x.size()) cl += (x[i] - m) * (x[i + lag] - m);
  }
  return {m, c0 / n, cl / c0};
}

TEST(GnssErrors, GaussMarkovVarianceAndAutocorrelationMatchSigmaAndTau) {
  // Horizontal GM 2 m / 30 s and vertical 3.5 m / 60 s at 5 Hz, no white
  // noise: 1.2e6 fixes (2.4e5 s, 4000..8000 tau).
  GnssSpec spec;
  spec.horizontal_gm_sigma_m = 2.0;
  spec.horizontal_gm_tau_s = 30.0;
  spec.vertical_gm_sigma_m = 3.5;
  spec.vertical_gm_tau_s = 60.0;
  spec.rate_hz = 5.0;
  spec.seed = 2026;
  GnssReceiverModel rx(spec, 1'400'000'000LL * kS, "gnss");
  const std::size_t n = 1'200'000;
  std::vector<double> axis[3];
  for (auto& v : axis) v.reserve(n);
  for (std::size_t j = 0; j < n; ++j) {
    const GnssError e = rx.error(j);
    for (int a = 0; a < 3; ++a) axis[a].push_back(e.position_ned_m[a]);
  }
  for (int a = 0; a < 3; ++a) {
    const double sigma = a < 2 ? 2.0 : 3.5, tau = a < 2 ? 30.0 : 60.0;
    const std::size_t lag = static_cast<std::size_t>(tau * 5.0);  // lag = tau
    const Stats s = stats(axis[a], lag);
    // Sampling errors of an AR(1) sequence, phi = exp(-dt/tau) (Bartlett 1946;
    // Priestley, Spectral Analysis and Time Series, §5.3): var(mean) =
    // sigma^2/n (1+phi)/(1-phi); var(s^2) = 2 sigma^4/n (1+phi^2)/(1-phi^2);
    // var(r_L) = [(1+phi^2)(1-phi^2L)/(1-phi^2) - 2 L phi^2L] / n.
    const double phi = std::exp(-0.2 / tau), dn = static_cast<double>(n);
    const double sd_mean = sigma * std::sqrt((1 + phi) / (1 - phi) / dn);
    const double sd_var = sigma * sigma * std::sqrt(2.0 * (1 + phi * phi) / (1 - phi * phi) / dn);
    const double p2l = std::pow(phi, 2.0 * static_cast<double>(lag));
    const double sd_rho = std::sqrt(((1 + phi * phi) * (1 - p2l) / (1 - phi * phi) - 2.0 * static_cast<double>(lag) * p2l) / dn);
    std::printf("GM axis %d: mean %.4f m (sd %.4f), var %.4f m^2 (want %.4f, sd %.4f), rho(tau) %.4f (want %.4f, sd %.4f)\n",
                a, s.mean, sd_mean, s.var, sigma * sigma, sd_var, s.rho, std::exp(-1.0), sd_rho);
    EXPECT_NEAR(s.mean, 0.0, 4.0 * sd_mean) << a;
    EXPECT_NEAR(s.var, sigma * sigma, 4.0 * sd_var) << a;
    EXPECT_NEAR(s.rho, std::exp(-1.0), 4.0 * sd_rho) << a;
    // Lag 1 (phi itself) is much tighter: the exact discretisation.
    EXPECT_NEAR(stats(axis[a], 1).rho, phi, 4.0 * std::sqrt((1 - phi * phi) / dn) + 1e-4) << a;
  }
}

TEST(GnssErrors, WhitePositionAndVelocityNoiseHaveTheirSigmas) {
  GnssSpec spec;
  spec.horizontal_white_m = sigma_from_cep_m(2.5);  // "2.5 m CEP"
  spec.vertical_white_m = 3.0;
  spec.horizontal_velocity_m_s = 0.05;
  spec.vertical_velocity_m_s = 0.1;
  spec.rate_hz = 10.0;
  spec.seed = 5;
  EXPECT_NEAR(spec.horizontal_white_m, 2.5 / 1.177410, 1e-5);
  GnssReceiverModel rx(spec, 0, "gnss");
  const std::size_t n = 200'000;
  std::vector<double> p[3], v[3];
  std::size_t inside_cep = 0;
  for (std::size_t j = 0; j < n; ++j) {
    const GnssError e = rx.error(j);
    for (int a = 0; a < 3; ++a) {
      p[a].push_back(e.position_ned_m[a]);
      v[a].push_back(e.velocity_ned_m_s[a]);
    }
    if (std::hypot(e.position_ned_m.x(), e.position_ned_m.y()) <= 2.5) ++inside_cep;
  }
  const double dn = static_cast<double>(n);
  for (int a = 0; a < 3; ++a) {
    const double sp = a < 2 ? spec.horizontal_white_m : 3.0, sv = a < 2 ? 0.05 : 0.1;
    const Stats s = stats(p[a], 1), t = stats(v[a], 1);
    EXPECT_NEAR(s.var, sp * sp, 5.0 * sp * sp * std::sqrt(2.0 / dn)) << a;
    EXPECT_NEAR(t.var, sv * sv, 5.0 * sv * sv * std::sqrt(2.0 / dn)) << a;
    EXPECT_NEAR(s.rho, 0.0, 5.0 / std::sqrt(dn)) << a;
  }
  // Half the horizontal fixes inside the CEP (binomial sd 0.5/sqrt(n)).
  EXPECT_NEAR(static_cast<double>(inside_cep) / dn, 0.5, 5.0 * 0.5 / std::sqrt(dn));
  const GnssAccuracy acc = stated_accuracy(spec);
  EXPECT_NEAR(acc.horizontal_m, std::sqrt(2.0) * spec.horizontal_white_m, 1e-12);
  EXPECT_NEAR(acc.vertical_m, 3.0, 1e-12);
}

TEST(GnssErrors, EpochsOnWholePeriodsAfterTheTimeToFirstFix) {
  GnssSpec spec;
  spec.rate_hz = 4.0;  // 250 ms
  spec.time_to_first_fix_s = 29.9;
  spec.latency_ms = 45.0;
  const TimeNs on = 1'300'000'000LL * kS + 123'456'789;  // power-on, arbitrary fraction
  GnssReceiverModel rx(spec, on, "gnss");
  EXPECT_EQ(rx.period_ns(), 250'000'000);
  EXPECT_EQ(rx.latency_ns(), 45'000'000);
  // on + 29.9 s = ...30.023456789 s -> next quarter second: ...30.25 s.
  EXPECT_EQ(*rx.epoch_gps_ns(0), 1'300'000'030LL * kS + 250'000'000);
  EXPECT_EQ(*rx.epoch_gps_ns(3), 1'300'000'031LL * kS);
  EXPECT_FALSE(rx.epoch_gps_ns(std::numeric_limits<std::uint64_t>::max()).has_value());
}

TEST(GnssErrors, SameSeedSameBitsSkippingIncluded) {
  GnssSpec spec;
  spec.horizontal_white_m = 1.0;
  spec.horizontal_gm_sigma_m = 2.0;
  spec.vertical_white_m = 1.5;
  spec.vertical_gm_sigma_m = 3.0;
  spec.horizontal_velocity_m_s = 0.05;
  spec.seed = 77;
  GnssReceiverModel a(spec, 0, "gnss"), b(spec, 0, "gnss"), c(spec, 0, "other");
  GnssError last;
  for (std::uint64_t j = 0; j < 50; ++j) last = a.error(j);
  const GnssError skipped = b.error(49);
  EXPECT_EQ(last.position_ned_m, skipped.position_ned_m);
  EXPECT_EQ(last.velocity_ned_m_s, skipped.velocity_ned_m_s);
  EXPECT_NE(c.error(49).position_ned_m, skipped.position_ned_m);
  EXPECT_THROW(a.error(10), std::invalid_argument);
  EXPECT_THROW(a.error(std::numeric_limits<std::uint64_t>::max()), std::invalid_argument);  // would never end
  EXPECT_EQ(a.next_index(), 50u);
}

TEST(GnssErrors, RefusesBadSpecs) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  GnssSpec s;
  s.horizontal_white_m = nan;
  EXPECT_THROW(GnssReceiverModel(s, 0, "g"), SettingError);
  s = {};
  s.rate_hz = 3.0;  // 333.33 ms: not a whole number of ms
  EXPECT_THROW(GnssReceiverModel(s, 0, "g"), SettingError);
  s = {};
  s.vertical_gm_tau_s = 0.0;
  EXPECT_THROW(GnssReceiverModel(s, 0, "g"), SettingError);
  s = {};
  s.satellites = 300;
  EXPECT_THROW(GnssReceiverModel(s, 0, "g"), SettingError);
  s = {};
  s.fix_type = static_cast<GnssFixType>(9);
  EXPECT_THROW(GnssReceiverModel(s, 0, "g"), SettingError);
  EXPECT_THROW(GnssReceiverModel(GnssSpec{}, -1, "g"), std::invalid_argument);
  EXPECT_THROW(sigma_from_cep_m(-1.0), SettingError);
}

}  // namespace
}  // namespace imuemu::aiding
}  // namespace unity_core_test_aiding_gnss
