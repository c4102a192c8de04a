// Issue 28: what the engine hands a GNSS receiver device. A device whose
// encoder needs_navigation() gets, per sample, the smoothed trajectory's
// WGS84 latitude, longitude, ellipsoidal height and NED velocity at the
// sample's instant (ecef scene); a flat scene has no geodetic position and
// the fields stay unset; an IMU protocol's device does not ask for them.
// Truth: the knots are a motion linear in latitude, longitude and height,
// whose NED velocity the test writes from the WGS84 radii of curvature
// (NIMA TR8350.2), independent of the producer's conversion.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <memory>
#include <mutex>
#include <vector>

#include "core/earth.hpp"
#include "daemon/device/device.hpp"
#include "daemon/engine/emission.hpp"
#include "drivers/protocols/stream_protocols.hpp"
#include "tests/support/recording_transport.hpp"

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
  }
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
