// Issue 28: what the engine hands a GNSS receiver device. A device whose
// encoder needs_navigation() gets, per sample, the smoothed trajectory's
// WGS84 latitude, longitude, ellipsoidal height and NED velocity at the
// sample's instant (ecef scene); a flat scene has no geodetic position and
// the fields stay unset; an IMU protocol's device does not ask for them.
// Truth: the knots are a motion linear in latitude, longitude and height,
// whose NED velocity the test writes from the WGS84 radii of curvature
// (NIMA TR8350.2), independent of the producer's conversion.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstring>
#include <cmath>
#include <memory>
#include <mutex>
#include <vector>

#include "core/earth.hpp"
#include "daemon/device/device.hpp"
#include "daemon/engine/emission.hpp"
#include "drivers/protocols/mavlink2.hpp"
#include "drivers/protocols/stream_protocols.hpp"
#include "tests/support/recording_transport.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace imuemu::emission {}
namespace unity_engine_test_gnss_navigation {
namespace imuemu { using namespace ::imuemu; }
namespace imuemu::emission { using namespace ::imuemu::emission; }

namespace imuemu::emission {
namespace {

using namespace std::chrono_literals;

constexpr double kPi = 3.14159265358979323846;
constexpr double kLat0Deg = -33.86, kLon0Deg = 151.21, kH0M = 80.0;
constexpr double kLatRateDegS = -4e-5, kLonRateDegS = 1.2e-4, kClimbMS = -0.5;

// Records the navigation fields of every sample it is handed.
class NavigationRecorder final : public drivers::StreamEncoder {
 public:
  struct Shared {
    std::mutex mutex;
    std::vector<drivers::ImuFrameInput> frames;
  };
  explicit NavigationRecorder(std::shared_ptr<Shared> shared) : shared_(std::move(shared)) {}
  std::string name() const override { return "navigation-recorder"; }
  void encode(const drivers::ImuFrameInput& sample, std::vector<std::uint8_t>& out) override {
    {
      std::lock_guard lock(shared_->mutex);
      shared_->frames.push_back(sample);
    }
    out.push_back(0);
  }
  std::size_t max_bytes_per_sample() const override { return 1; }
  bool needs_navigation() const override { return true; }

 private:
  std::shared_ptr<Shared> shared_;
};

std::vector<Pose> linear_geodetic_knots(double duration_s) {
  std::vector<Pose> knots;
  for (int i = 0; i <= static_cast<int>(duration_s * 10); ++i) {
    const double t = i / 10.0;
    Pose p;
    p.t_ns = static_cast<TimeNs>(i) * 100'000'000;
    p.position_m = earth::ecef_from_geodetic({(kLat0Deg + kLatRateDegS * t) * kPi / 180.0,
                                              (kLon0Deg + kLonRateDegS * t) * kPi / 180.0, kH0M + kClimbMS * t});
    knots.push_back(p);
  }
  return knots;
}

std::vector<drivers::ImuFrameInput> run(Physics physics, std::int64_t rate_hz, std::uint64_t ticks) {
  auto shared = std::make_shared<NavigationRecorder::Shared>();
  DeviceOptions d;
  d.name = "gnss0";
  d.rate_hz = rate_hz;
  d.pipeline.scene.physics = physics;
  d.pipeline.rate_hz = rate_hz;
  d.pipeline.kernel.delta = 1;
  d.device = device::make_stream_device(std::make_unique<NavigationRecorder>(shared),
                                        std::make_unique<test_support::RecordingTransport>());
  EXPECT_TRUE(d.device->needs().navigation);
  std::vector<DeviceOptions> devices;
  devices.push_back(std::move(d));
  EngineOptions eo;
  eo.trajectory = linear_geodetic_knots(3.0);
  eo.drop_late_ticks = false;
  eo.max_ticks_per_device = ticks;
  eo.ring_capacity = 64;  // the whole run computed before the clock starts
  EmissionEngine engine(std::move(eo), std::move(devices));
  engine.start();
  EXPECT_TRUE(engine.wait(30s));
  engine.stop();
  std::lock_guard lock(shared->mutex);
  return shared->frames;
}

TEST(GnssNavigation, EcefSamplesCarryTheTrajectorysGeodeticPositionAndNedVelocity) {
  const std::vector<drivers::ImuFrameInput> frames = run(Physics::ecef, 5, 10);
  ASSERT_EQ(frames.size(), 10u);
  const double e2 = (1.0 / 298.257223563) * (2.0 - 1.0 / 298.257223563);
  const double a = 6378137.0;
  for (const drivers::ImuFrameInput& f : frames) {
    SCOPED_TRACE(f.t_ns);
    ASSERT_TRUE(f.has_navigation);
    EXPECT_EQ(f.t_ns, static_cast<TimeNs>(f.sample_counter) * 200'000'000);  // the 5 Hz grid from the first knot
    const double t = static_cast<double>(f.t_ns) * 1e-9;
    const double lat_deg = kLat0Deg + kLatRateDegS * t, h = kH0M + kClimbMS * t;
    // 1e-10 deg is 11 um: far below any receiver format's resolution.
    EXPECT_NEAR(f.latitude_rad * 180.0 / kPi, lat_deg, 1e-10);
    EXPECT_NEAR(f.longitude_rad * 180.0 / kPi, kLon0Deg + kLonRateDegS * t, 1e-10);
    EXPECT_NEAR(f.height_m, h, 1e-5);
    const double s = std::sin(lat_deg * kPi / 180.0), w = std::sqrt(1.0 - e2 * s * s);
    const double v_n = (a * (1.0 - e2) / (w * w * w) + h) * kLatRateDegS * kPi / 180.0;
    const double v_e = (a / w + h) * std::cos(lat_deg * kPi / 180.0) * kLonRateDegS * kPi / 180.0;
    EXPECT_NEAR(f.velocity_ned_m_s.x(), v_n, 1e-5);
    EXPECT_NEAR(f.velocity_ned_m_s.y(), v_e, 1e-5);
    EXPECT_NEAR(f.velocity_ned_m_s.z(), -kClimbMS, 1e-5);
    // The knots' attitude is R_s^e = I: R_s^n = (R_n^e)^T, whose rows are
    // the local north, east and down unit vectors in ECEF axes.
    const double phi = f.latitude_rad, lam = f.longitude_rad;
    Mat3 ned_rows;
    ned_rows << -std::sin(phi) * std::cos(lam), -std::sin(phi) * std::sin(lam), std::cos(phi),  //
        -std::sin(lam), std::cos(lam), 0.0,                                                      //
        -std::cos(phi) * std::cos(lam), -std::cos(phi) * std::sin(lam), -std::sin(phi);
    EXPECT_LT((f.sensor_to_ned - ned_rows).cwiseAbs().maxCoeff(), 1e-9);
  }
}

// Issue 28 through the engine: a MAVLink device with HIL_GPS at 5 Hz and the
// barometer and magnetometer groups on, at 10 Hz on the same knots. What
// reaches its transport: HIL_GPS lat / lon / alt equal to the knots' motion
// within the wire's resolution, and HIL_SENSOR fields_updated 7167.
TEST(GnssNavigation, MavlinkHilGpsAndTheSensorGroupsThroughTheEngine) {
  drivers::StreamEncoderOptions o;
  o.nominal_sample_rate_hz = 10.0;
  o.mavlink_hil_gps_rate_hz = 5;
  o.mavlink_baro = true;
  o.mavlink_mag = true;
  auto transport = std::make_unique<test_support::RecordingTransport>();
  const test_support::RecordingTransport* recorded = transport.get();
  DeviceOptions d;
  d.name = "px4";
  d.rate_hz = 10;
  d.pipeline.scene.physics = Physics::ecef;
  d.pipeline.rate_hz = 10;
  d.pipeline.kernel.delta = 1;
  d.device = device::make_stream_device(drivers::make_stream_encoder("mavlink2", o), std::move(transport));
  EXPECT_TRUE(d.device->needs().navigation);
  std::vector<DeviceOptions> devices;
  devices.push_back(std::move(d));
  EngineOptions eo;
  eo.trajectory = linear_geodetic_knots(3.0);
  eo.drop_late_ticks = false;
  eo.max_ticks_per_device = 20;
  eo.ring_capacity = 64;
  EmissionEngine engine(std::move(eo), std::move(devices));
  engine.start();
  EXPECT_TRUE(engine.wait(30s));
  engine.stop();
  const std::vector<std::uint8_t> bytes = recorded->bytes();

  // Frames by the MAVLink 2 layout (magic 0xFD, len, ..., msgid at 7..9,
  // payload from 10, 2 CRC bytes); the CRCs by the listen decoder.
  drivers::mavlink2::Decoder decoder(o);
  decoder.feed(bytes, nullptr);
  EXPECT_EQ(decoder.counters().checksum_errors + decoder.counters().other_errors + decoder.counters().resync_bytes, 0u);
  int gps = 0, sensor = 0;
  for (std::size_t at = 0; at + 12 <= bytes.size();) {
    ASSERT_EQ(bytes[at], 0xFD);
    const std::size_t len = bytes[at + 1];
    const std::uint32_t id = bytes[at + 7] | bytes[at + 8] << 8 | bytes[at + 9] << 16;
    std::array<std::uint8_t, 255> p{};
    std::copy_n(bytes.begin() + static_cast<std::ptrdiff_t>(at + 10), len, p.begin());
    auto i32 = [&p](std::size_t k) {
      std::int32_t v;
      std::memcpy(&v, p.data() + k, 4);
      return v;
    };
    if (id == 113) {
      std::uint64_t time_usec;
      std::memcpy(&time_usec, p.data(), 8);
      EXPECT_EQ(time_usec % 200'000, 0u);  // the 5 Hz grid
      const double t = static_cast<double>(time_usec) * 1e-6;
      EXPECT_NEAR(i32(8), (kLat0Deg + kLatRateDegS * t) * 1e7, 0.5 + 1e-3);
      EXPECT_NEAR(i32(12), (kLon0Deg + kLonRateDegS * t) * 1e7, 0.5 + 1e-3);
      EXPECT_NEAR(i32(16), (kH0M + kClimbMS * t) * 1e3, 0.5 + 0.01);
      ++gps;
    } else if (id == 107) {
      std::uint32_t updated;
      std::memcpy(&updated, p.data() + 60, 4);
      EXPECT_EQ(updated, 7167u);
      ++sensor;
    }
    at += 12 + len;
  }
  EXPECT_EQ(sensor, 20);
  EXPECT_EQ(gps, 10);
}

TEST(GnssNavigation, FlatSceneHasNoGeodeticPositionAndImuProtocolsDoNotAskForOne) {
  const std::vector<drivers::ImuFrameInput> frames = run(Physics::flat, 5, 3);
  ASSERT_EQ(frames.size(), 3u);
  for (const drivers::ImuFrameInput& f : frames) EXPECT_FALSE(f.has_navigation);
  for (const char* imu : {"native", "mavlink2", "mip"}) {
    const auto dev = device::make_stream_device(drivers::make_stream_encoder(imu),
                                                std::make_unique<test_support::RecordingTransport>());
    EXPECT_FALSE(dev->needs().navigation) << imu;
  }
  for (const char* gnss : {"nmea", "ubx"}) {
    const auto dev = device::make_stream_device(drivers::make_stream_encoder(gnss),
                                                std::make_unique<test_support::RecordingTransport>());
    EXPECT_TRUE(dev->needs().navigation) << gnss;
  }
}

}  // namespace
}  // namespace imuemu::emission
}  // namespace unity_engine_test_gnss_navigation
