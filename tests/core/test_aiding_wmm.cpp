// The World Magnetic Model and the magnetometer (core/aiding/, issue 28)
// against independent truth: the official WMM2025 test values, the
// calendar against dates known by heart, the sensor model against
// hand-computed rotations.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <numbers>
#include <sstream>
#include <string>

#include <unistd.h>

#include <GeographicLib/MagneticModel.hpp>

#include "core/aiding/calendar.hpp"
#include "core/aiding/magnetometer.hpp"
#include "core/aiding/wmm.hpp"
#include "core/attitude.hpp"
#include "core/setting_error.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace imuemu::aiding {}
namespace unity_core_test_aiding_wmm {
namespace imuemu { using namespace ::imuemu; }
namespace imuemu::aiding { using namespace ::imuemu::aiding; }

namespace imuemu::aiding {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

earth::Geodetic at(double lat_deg, double lon_deg, double height_m) {
  return {lat_deg * kDeg, lon_deg * kDeg, height_m};
}

// The WMM2025 test values published with the model by NOAA NCEI / BGS
// ("WMM2025 Test Values", WMM2025testvalues.pdf, the report's test-value
// table; also WMM2025_TEST_VALUES.txt in WMM2025COF.zip): decimal year,
// height above the WGS84 ellipsoid (km), geodetic latitude and longitude
// (deg) -> X, Y, Z (nT, printed to 0.1) and D (deg, printed to 0.01).
struct TestValue {
  double year, height_km, lat_deg, lon_deg, x_nt, y_nt, z_nt, d_deg;
};
constexpr TestValue kWmm2025TestValues[] = {
    {2025.0, 0.0, 80.0, 0.0, 6521.6, 145.9, 54791.5, 1.28},
    {2025.0, 0.0, 0.0, 120.0, 39677.8, -109.6, -10580.2, -0.16},
    {2025.0, 0.0, -80.0, 240.0, 6117.5, 15751.9, -52022.5, 68.78},
    {2025.0, 100.0, 80.0, 0.0, 6216.0, 92.4, 52598.8, 0.85},
    {2025.0, 100.0, 0.0, 120.0, 37688.6, -96.2, -10152.1, -0.15},
    {2025.0, 100.0, -80.0, 240.0, 5907.6, 14780.3, -49540.7, 68.21},
    {2027.5, 0.0, 80.0, 0.0, 6500.8, 294.5, 54869.4, 2.59},
    {2027.5, 0.0, 0.0, 120.0, 39701.6, -167.4, -10381.8, -0.24},
    {2027.5, 0.0, -80.0, 240.0, 6200.7, 15730.3, -51783.7, 68.49},
    {2027.5, 100.0, 80.0, 0.0, 6196.7, 233.8, 52670.5, 2.16},
    {2027.5, 100.0, 0.0, 120.0, 37711.5, -148.7, -9969.8, -0.23},
    {2027.5, 100.0, -80.0, 240.0, 5984.0, 14760.1, -49317.7, 67.93},
};

TEST(Wmm2025, MatchesTheOfficialTestValuesWithinTheirPrintedDigits) {
  double max_nt = 0.0, max_d_deg = 0.0;
  for (const TestValue& v : kWmm2025TestValues) {
    const MagneticElements e = wmm2025(at(v.lat_deg, v.lon_deg, v.height_km * 1000.0), v.year);
    const Vec3 published(v.x_nt, v.y_nt, v.z_nt);
    const double dev = (e.ned_nt - published).cwiseAbs().maxCoeff();
    const double dev_d = std::abs(e.declination_rad / kDeg - v.d_deg);
    max_nt = std::max(max_nt, dev);
    max_d_deg = std::max(max_d_deg, dev_d);
    // Half the last printed digit (the official values are the official
    // software's double-precision output, rounded).
    EXPECT_LE(dev, 0.05 + 1e-6) << v.year << " " << v.height_km << " " << v.lat_deg << " " << v.lon_deg;
    EXPECT_LE(dev_d, 0.005 + 1e-9) << v.year << " " << v.lat_deg;
    // The elements from the components.
    EXPECT_NEAR(e.total_nt, e.ned_nt.norm(), 1e-9);
    EXPECT_NEAR(std::tan(e.inclination_rad), e.ned_nt.z() / e.horizontal_nt, 1e-9);
  }
  std::printf("WMM2025 against the 12 official test values: max |dX|,|dY|,|dZ| %.4f nT, max |dD| %.5f deg\n",
              max_nt, max_d_deg);
}

// An independent evaluation: GeographicLib's MagneticModel (its own
// Clenshaw summation and geocentric conversion; Karney, GeographicLib
// "Magnetic models" data format) loaded with the same coefficients,
// written here in its format: a text metadata file "<name>.wmm" (WMMF-1)
// and "<name>.wmm.cof" (8-byte ID, then per model int32 N, M and the C and
// S coefficients as little-endian doubles in column-major order, m = 0..N,
// n = m..N, S without m = 0); model 0 the main field at the epoch, model 1
// its rate per year (NumModels 1: linear in time). GeographicLib returns
// east, north, up.
std::string write_geographiclib_model(const std::string& dir) {
  int count = 0;
  const WmmCoefficient* table = wmm2025_coefficients(count);
  // One name per process: the release and sanitizer flavours may run this
  // test at the same time in the same TempDir.
  const std::string name = "imuemu_wmm2025_" + std::to_string(::getpid());
  std::ofstream meta(dir + "/" + name + ".wmm");
  meta << "WMMF-1\nName " << name << "\nDescription WMM2025 from config/wmm/WMM2025.COF\nRadius 6371200\n"
       << "NumModels 1\nEpoch 2025\nDeltaEpoch 5\nMinTime 2025\nMaxTime 2030\nMinHeight -1000\n"
       << "MaxHeight 850000\nNormalization Schmidt\nByteOrder Little\nID WMM2025A\n";
  std::ofstream cof(dir + "/" + name + ".wmm.cof", std::ios::binary);
  cof.write("WMM2025A", 8);
  auto put_int = [&](std::int32_t v) { cof.write(reinterpret_cast<const char*>(&v), 4); };
  auto put = [&](double v) { cof.write(reinterpret_cast<const char*>(&v), 8); };
  for (int model = 0; model < 2; ++model) {
    auto coefficient = [&](int n, int m, bool sine) {
      for (int i = 0; i < count; ++i)
        if (table[i].n == n && table[i].m == m)
          return model == 0 ? (sine ? table[i].h_nt : table[i].g_nt)
                            : (sine ? table[i].h_dot_nt_per_year : table[i].g_dot_nt_per_year);
      return 0.0;  // n = 0
    };
    put_int(kWmmDegree);
    put_int(kWmmDegree);
    for (int m = 0; m <= kWmmDegree; ++m)
      for (int n = m; n <= kWmmDegree; ++n) put(coefficient(n, m, false));
    for (int m = 1; m <= kWmmDegree; ++m)
      for (int n = m; n <= kWmmDegree; ++n) put(coefficient(n, m, true));
  }
  return name;
}

TEST(Wmm2025, AgreesWithGeographicLibsMagneticModelOnAGlobalGrid) {
  const std::string dir = ::testing::TempDir();
  const std::string name = write_geographiclib_model(dir);
  const GeographicLib::MagneticModel reference(name, dir);
  double max_nt = 0.0;
  int points = 0;
  for (double year : {2025.0, 2026.37, 2029.99})
    for (double h : {-1000.0, 0.0, 12000.0, 400000.0, 850000.0})
      for (double lat = -90.0; lat <= 90.0; lat += 7.5)
        for (double lon = -180.0; lon < 180.0; lon += 15.0) {
          double bx = 0.0, by = 0.0, bz = 0.0;
          reference(year, lat, lon, h, bx, by, bz);
          const Vec3 ref(by, bx, -bz);  // east, north, up -> NED
          const Vec3 ours = wmm2025(at(lat, lon, h), year).ned_nt;
          // At a pole NED's north depends on longitude; compare the
          // horizontal magnitude and the vertical there.
          const double dev = std::abs(lat) == 90.0
                                 ? std::max(std::abs(ours.head<2>().norm() - ref.head<2>().norm()),
                                            std::abs(ours.z() - ref.z()))
                                 : (ours - ref).cwiseAbs().maxCoeff();
          max_nt = std::max(max_nt, dev);
          ++points;
          ASSERT_LT(dev, 1e-6) << year << " " << h << " " << lat << " " << lon;
        }
  std::filesystem::remove(dir + "/" + name + ".wmm");
  std::filesystem::remove(dir + "/" + name + ".wmm.cof");
  std::printf("WMM2025 against GeographicLib::MagneticModel with the same coefficients: %d points, max deviation %.3g nT\n",
              points, max_nt);
}

TEST(Wmm2025, CarriedTableEqualsTheCoefficientFile) {
  std::ifstream in(std::string(IMUEMU_SOURCE_DIR) + "/config/wmm/WMM2025.COF");
  ASSERT_TRUE(in) << "config/wmm/WMM2025.COF";
  std::string header;
  std::getline(in, header);
  EXPECT_NE(header.find("WMM-2025"), std::string::npos);
  int count = 0;
  const WmmCoefficient* table = wmm2025_coefficients(count);
  ASSERT_EQ(count, 90);
  EXPECT_EQ(wmm2025_epoch_year(), 2025.0);
  std::string line;
  int row = 0;
  while (std::getline(in, line) && line.rfind("9999", 0) != 0) {
    std::istringstream fields(line);
    WmmCoefficient c{};
    fields >> c.n >> c.m >> c.g_nt >> c.h_nt >> c.g_dot_nt_per_year >> c.h_dot_nt_per_year;
    ASSERT_LT(row, count);
    EXPECT_EQ(table[row].n, c.n);
    EXPECT_EQ(table[row].m, c.m);
    EXPECT_EQ(table[row].g_nt, c.g_nt);
    EXPECT_EQ(table[row].h_nt, c.h_nt);
    EXPECT_EQ(table[row].g_dot_nt_per_year, c.g_dot_nt_per_year);
    EXPECT_EQ(table[row].h_dot_nt_per_year, c.h_dot_nt_per_year);
    ++row;
  }
  EXPECT_EQ(row, count);
}

TEST(Wmm2025, FiniteAndContinuousAtTheGeographicPoles) {
  for (double lat : {90.0, -90.0}) {
    const double toward = lat > 0 ? -1e-7 : 1e-7;
    for (double lon : {0.0, 77.0, -120.0}) {
      const MagneticElements pole = wmm2025(at(lat, lon, 0.0), 2026.0);
      const MagneticElements near = wmm2025(at(lat + toward, lon, 0.0), 2026.0);
      ASSERT_TRUE(pole.ned_nt.allFinite());
      EXPECT_LT((pole.ned_nt - near.ned_nt).norm(), 0.01) << lat << " " << lon;
    }
  }
}

TEST(Wmm2025, RefusesNanAndOutsideItsValidity) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(wmm2025(at(nan, 0.0, 0.0), 2026.0), SettingError);
  EXPECT_THROW(wmm2025(at(0.0, nan, 0.0), 2026.0), SettingError);
  EXPECT_THROW(wmm2025(at(0.0, 0.0, nan), 2026.0), SettingError);
  EXPECT_THROW(wmm2025(at(0.0, 0.0, 0.0), nan), SettingError);
  EXPECT_THROW(wmm2025(at(91.0, 0.0, 0.0), 2026.0), SettingError);
  EXPECT_THROW(wmm2025(at(0.0, 0.0, -1001.0), 2026.0), SettingError);
  EXPECT_THROW(wmm2025(at(0.0, 0.0, 850001.0), 2026.0), SettingError);
  EXPECT_THROW(wmm2025(at(0.0, 0.0, 0.0), 2024.99), SettingError);
  EXPECT_THROW(wmm2025(at(0.0, 0.0, 0.0), 2030.01), SettingError);
  EXPECT_NO_THROW(wmm2025(at(0.0, 0.0, 0.0), 2030.0));
}

TEST(Calendar, KnownDatesAndDecimalYears) {
  // 2017-01-01T00:00:00Z = 1483228800 s POSIX; 2000-03-01 = 951868800 s;
  // 2019-04-07 = 1554595200 s (date(1) -u -d ... +%s).
  EXPECT_EQ(posix_ns_from_calendar({2017, 1, 1, 0, 0, 0, 0}), 1'483'228'800LL * kNsPerSecond);
  EXPECT_EQ(posix_ns_from_calendar({2000, 3, 1, 0, 0, 0, 0}), 951'868'800LL * kNsPerSecond);
  EXPECT_EQ(posix_ns_from_calendar({2019, 4, 7, 0, 0, 0, 0}), 1'554'595'200LL * kNsPerSecond);
  const UtcCalendar c = calendar_from_posix_ns(951'782'400LL * kNsPerSecond + 123);  // 2000-02-29
  EXPECT_EQ(c.year, 2000);
  EXPECT_EQ(c.month, 2);
  EXPECT_EQ(c.day, 29);
  EXPECT_EQ(c.nanosecond, 123);
  const UtcCalendar before = calendar_from_posix_ns(-1);  // 1969-12-31T23:59:59.999999999
  EXPECT_EQ(before.year, 1969);
  EXPECT_EQ(before.day, 31);
  EXPECT_EQ(before.second, 59);
  EXPECT_EQ(before.nanosecond, 999'999'999);
  // 2025-01-01 is 2025.0; 2027-07-02T12:00Z is 2027 + 182.5/365 = 2027.5.
  EXPECT_EQ(decimal_year_from_posix_ns(posix_ns_from_calendar({2025, 1, 1, 0, 0, 0, 0})), 2025.0);
  EXPECT_NEAR(decimal_year_from_posix_ns(posix_ns_from_calendar({2027, 7, 2, 12, 0, 0, 0})), 2027.5, 1e-12);
  EXPECT_NEAR(decimal_year_from_posix_ns(posix_ns_from_calendar({2028, 7, 2, 0, 0, 0, 0})), 2028.5, 1e-12);  // leap year
  EXPECT_THROW(posix_ns_from_calendar({2025, 2, 29, 0, 0, 0, 0}), std::invalid_argument);
  EXPECT_THROW(posix_ns_from_calendar({2025, 13, 1, 0, 0, 0, 0}), std::invalid_argument);
  EXPECT_THROW(posix_ns_from_calendar({3000, 1, 1, 0, 0, 0, 0}), std::invalid_argument);  // beyond int64 ns
  for (TimeNs t : {TimeNs{0}, TimeNs{1'483'228'799'999'999'999}, TimeNs{-86'400'000'000'001}, TimeNs{kNsPerSecond * 4'102'444'800}}) {
    EXPECT_EQ(posix_ns_from_calendar(calendar_from_posix_ns(t)), t);
  }
}

TEST(Magnetometer, RotatesTheFieldIntoSensorAxesWithHardAndSoftIron) {
  // Field 20 uT north, 0 east, 45 uT down; body yawed 90 deg (nose east):
  // the field's north lies on the body's -y (left wing), down on +z.
  const Vec3 ned_nt(20000.0, 0.0, 45000.0);
  const Mat3 yaw90 = attitude::rotation_from_hpr({std::numbers::pi / 2.0, 0.0, 0.0});
  const Vec3 b = body_field_ut(yaw90, ned_nt);
  EXPECT_NEAR(b.x(), 0.0, 1e-12);
  EXPECT_NEAR(b.y(), -20.0, 1e-12);
  EXPECT_NEAR(b.z(), 45.0, 1e-12);

  MagnetometerSpec spec;
  spec.hard_iron_ut = Vec3(5.0, -3.0, 1.0);
  spec.soft_iron << 1.1, 0.05, 0.0, 0.05, 0.9, 0.0, 0.0, 0.0, 1.0;
  Magnetometer mag(spec, 100.0, "mag");
  const Vec3 m = mag.measure(0, b).field_ut;
  // W b + h by hand: (1.1*0 + 0.05*-20 + 5, 0.05*0 + 0.9*-20 - 3, 45 + 1).
  EXPECT_NEAR(m.x(), 4.0, 1e-12);
  EXPECT_NEAR(m.y(), -21.0, 1e-12);
  EXPECT_NEAR(m.z(), 46.0, 1e-12);

  // A sensor mounted rolled 180 deg about x: y and z flip.
  MagnetometerSpec flipped;
  flipped.sensor_from_body = Vec3(1.0, -1.0, -1.0).asDiagonal();
  Magnetometer upside(flipped, 100.0, "mag");
  EXPECT_TRUE(upside.measure(0, b).field_ut.isApprox(Vec3(0.0, 20.0, -45.0), 1e-12));
}

TEST(Magnetometer, NoiseRangeAndReproducibility) {
  MagnetometerSpec spec;
  spec.noise_rms_ut = Vec3(0.32, 0.32, 0.52);  // LIS3MDL +-4 G: 3.2 / 3.2 / 5.2 mG RMS
  spec.range_ut = 400.0;
  spec.seed = 11;
  const std::size_t n = 100000;
  Magnetometer a(spec, 80.0, "mag"), b(spec, 80.0, "mag");
  Vec3 sum = Vec3::Zero(), sum2 = Vec3::Zero();
  const Vec3 truth(20.0, -5.0, 40.0);
  for (std::size_t k = 0; k < n; ++k) {
    const Vec3 e = a.measure(k, truth).field_ut - truth;
    sum += e;
    sum2 += e.cwiseProduct(e);
    if (k % 7 == 6) {
      EXPECT_EQ(b.measure(k, truth).field_ut, e + truth) << k;  // b skips; same bits
    }
  }
  for (int i = 0; i < 3; ++i) {
    const double s2 = spec.noise_rms_ut[i] * spec.noise_rms_ut[i];
    EXPECT_NEAR(sum[i] / n, 0.0, 5.0 * std::sqrt(s2 / n));
    EXPECT_NEAR(sum2[i] / n, s2, 5.0 * s2 * std::sqrt(2.0 / n));
  }
  const MagnetometerSample big = a.measure(n, Vec3(500.0, -450.0, 10.0));
  EXPECT_EQ(big.field_ut.x(), 400.0);
  EXPECT_EQ(big.field_ut.y(), -400.0);
  EXPECT_EQ(big.clipped_axes, 0b011);
}

TEST(Magnetometer, RefusesBadSpecsAndInputs) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  MagnetometerSpec s;
  s.soft_iron = Mat3::Zero();
  EXPECT_THROW(Magnetometer(s, 10.0, "m"), SettingError);
  s = {};
  s.soft_iron(0, 1) = nan;
  EXPECT_THROW(Magnetometer(s, 10.0, "m"), SettingError);
  s = {};
  s.sensor_from_body = 2.0 * Mat3::Identity();
  EXPECT_THROW(Magnetometer(s, 10.0, "m"), SettingError);
  s = {};
  s.hard_iron_ut.x() = nan;
  EXPECT_THROW(Magnetometer(s, 10.0, "m"), SettingError);
  EXPECT_THROW(Magnetometer(MagnetometerSpec{}, -1.0, "m"), SettingError);
  Magnetometer m(MagnetometerSpec{}, 10.0, "m");
  EXPECT_THROW(m.measure(0, Vec3(nan, 0.0, 0.0)), SettingError);
  EXPECT_THROW(m.measure(std::numeric_limits<std::uint64_t>::max(), Vec3(20.0, 0.0, 40.0)), std::invalid_argument);
  EXPECT_EQ(m.next_index(), 0u);
  EXPECT_THROW(body_field_ut(Mat3::Identity(), Vec3(nan, 0.0, 0.0)), SettingError);
}

}  // namespace
}  // namespace imuemu::aiding
}  // namespace unity_core_test_aiding_wmm
