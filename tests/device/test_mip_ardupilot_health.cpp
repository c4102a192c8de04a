// Issue 28 acceptance 2: the MIP device's GNSS (0x81) and filter (0x82) data
// sets held against ArduPilot's MicroStrain5 and MicroStrain7 external-AHRS
// health and pre-arm conditions, through a run that starts cold, aligns,
// fixes, loses GNSS for 30 s and recovers.
//
// The stream is decoded here by a decoder written from the MIP DCP manuals
// alone (3DM-GX5-45 / 3DM-CV7 DCP: packet 0x75 0x65, set, length, fields,
// Fletcher-16 [6.3, 6.4]; 0x81,0x03 LLH = 4 doubles (lat, lon deg, ellipsoid
// and MSL height m), 2 floats, u16 valid; 0x81,0x05 NED velocity = 8 floats,
// u16; 0x81,0x0B fix info = u8 fix type (0 = 3D, 3 = none), u8 satellites,
// u16 flags, u16 valid; 0x82,0x10 filter status = u16 state, u16 mode, u16
// flags; 0x82,0x01 LLH = 3 doubles, u16; 0x82,0x03 quaternion = 4 floats
// (w first; v_ned = q v_vehicle q*), u16; 0xD3 GPS timestamp = double tow,
// u16 week, u16 valid), not from imuemu's headers.
//
// The conditions are those of ArduPilot's sources, read at
//   ArduPilot/ardupilot libraries/AP_ExternalAHRS/AP_ExternalAHRS_MicroStrain5.cpp
//     (commit 04ec15caa2c7508290c6127e9a3d0c0d1ae31452):
//     healthy(): now - last_ins_pkt < 40 ms, now - last_gps_pkt < 500 ms,
//       now - last_filter_pkt < 500 ms;
//     pre_arm_check(): healthy(), gnss fix_type >= 3 (3D), filter_status.state == 0x02
//       (GX5 "running, solution valid").
//   .../AP_ExternalAHRS_MicroStrain7.cpp (commit 078745519bbd47a89b1674015409b5052ced3932):
//     times_healthy(): IMU and filter packets less than 40 ms * 1.1 = 44 ms
//       old, GNSS less than 500 ms * 1.1 = 550 ms;
//     filter_healthy(): state GQ7_AHRS (3) or GQ7_FULL_NAV (4);
//     initialised(): an IMU, a GNSS and a filter packet seen;
//     pre_arm_check(): initialised, times_healthy, filter_healthy and a 3D
//       fix on either GNSS instance.
//   .../MicroStrain_common.cpp (commit 08e0d9229301a9fc8f1ed355a3cfc8e7a7d5cb76):
//     a packet's time is when it is parsed (AP_HAL::millis()); sets 0x80 IMU,
//     0x81 / 0x91 / 0x92 GNSS (0x81 is instance 0), 0x82 filter; MIP fix type
//     0x00 -> GPS_FIX_TYPE_3D_FIX, 0x03 -> NO_FIX.
// Simulated time: a packet arrives at its sample's instant (no transport
// latency); "now" is each sample instant in ms. No wall clock.
#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>
#include <utility>
#include <vector>

#include "drivers/protocols/mip.hpp"
#include "drivers/protocols/stream_protocols.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_device_test_mip_ardupilot_health {
namespace imuemu { using namespace ::imuemu; }

namespace {

using namespace imuemu;
using Bytes = std::vector<std::uint8_t>;

// ---- the independent decoder
std::uint64_t be(const std::uint8_t* p, int n) {
  std::uint64_t v = 0;
  for (int i = 0; i < n; ++i) v = v << 8 | p[i];
  return v;
}
double be_f64(const std::uint8_t* p) {
  const std::uint64_t u = be(p, 8);
  double d;
  std::memcpy(&d, &u, 8);
  return d;
}
double be_f32(const std::uint8_t* p) {
  const auto u = static_cast<std::uint32_t>(be(p, 4));
  float f;
  std::memcpy(&f, &u, 4);
  return f;
}

struct Packet {
  std::uint8_t set = 0;
  std::vector<std::pair<std::uint8_t, Bytes>> fields;  // descriptor, data
};
// Every packet of one sample's bytes; a bad checksum or a field list that
// does not tile the payload fails the test.
std::vector<Packet> spec_packets(const Bytes& s) {
  std::vector<Packet> out;
  std::size_t i = 0;
  while (i < s.size()) {
    EXPECT_TRUE(i + 6 <= s.size() && s[i] == 0x75 && s[i + 1] == 0x65) << "no packet at " << i;
    if (!(i + 6 <= s.size() && s[i] == 0x75 && s[i + 1] == 0x65)) return out;
    const std::size_t len = s[i + 3];
    std::uint8_t a = 0, b = 0;
    for (std::size_t k = i; k < i + 4 + len; ++k) {
      a = static_cast<std::uint8_t>(a + s[k]);
      b = static_cast<std::uint8_t>(b + a);
    }
    EXPECT_EQ(s[i + 4 + len], a);
    EXPECT_EQ(s[i + 5 + len], b);
    Packet p;
    p.set = s[i + 2];
    std::size_t f = i + 4;
    while (f < i + 4 + len) {
      const std::size_t fl = s[f];
      EXPECT_GE(fl, 2u);
      if (fl < 2) break;
      p.fields.emplace_back(s[f + 1], Bytes(s.begin() + static_cast<std::ptrdiff_t>(f + 2),
                                            s.begin() + static_cast<std::ptrdiff_t>(f + fl)));
      f += fl;
    }
    EXPECT_EQ(f, i + 4 + len);
    out.push_back(std::move(p));
    i += len + 6;
  }
  return out;
}

// ---- the truth: a vehicle flying north-east at 20 m/s, 100 m over
// Barcelona, yawing at 1 deg/s (the frames' navigation fields, exact).
constexpr double kPi = 3.14159265358979323846;
constexpr double kLat0 = 41.38 * kPi / 180.0, kLon0 = 2.17 * kPi / 180.0;
constexpr double kRate = 100.0;
struct Truth {
  double lat_rad, lon_rad, h_m;
  Vec3 v_ned;
  double yaw_rad;
};
Truth truth_at(double t) {
  const double a = 6378137.0;  // radii only need to be consistent here: the test compares with these
  return {kLat0 + 14.0 * t / a, kLon0 + 14.0 * t / (a * std::cos(kLat0)), 100.0 + 0.5 * t,
          Vec3(14.0, 14.0, -0.5), 0.3 + kPi / 180.0 * t};
}
drivers::ImuFrameInput frame_at(std::uint64_t k) {
  const double t = static_cast<double>(k) / kRate;
  const Truth x = truth_at(t);
  drivers::ImuFrameInput f;
  f.sample_counter = k;
  f.t_ns = static_cast<TimeNs>(k) * 10'000'000;
  f.period_ns = 10'000'000;
  f.accel_m_s2 = Vec3(0.0, 0.0, -9.80665);
  f.has_navigation = true;
  f.latitude_rad = x.lat_rad;
  f.longitude_rad = x.lon_rad;
  f.height_m = x.h_m;
  f.velocity_ned_m_s = x.v_ned;
  f.sensor_to_ned = Eigen::AngleAxisd(x.yaw_rad, Vec3::UnitZ()).toRotationMatrix();
  return f;
}

// The scene: 100 Hz IMU, 4 Hz GNSS, 50 Hz filter; aligned after 5 s, first
// fix at 30 s, GNSS outage 60..90 s; filter errors off (truth).
drivers::StreamEncoderOptions scene_options(drivers::MipFilterStates states) {
  drivers::StreamEncoderOptions o;
  o.nominal_sample_rate_hz = kRate;
  o.mip_time_base = drivers::MipTimeBase::gps;
  o.mip_gps_time_at_t0_ns = 2400LL * 604'800LL * 1'000'000'000LL;
  o.mip_nav.gnss_rate_hz = 4;
  o.mip_nav.filter_rate_hz = 50;
  o.mip_nav.filter_states = states;
  o.mip_nav.filter_alignment_s = 5.0;
  o.mip_nav.gnss_first_fix_s = 30.0;
  o.mip_nav.gnss_outage_start_s = 60.0;
  o.mip_nav.gnss_outage_duration_s = 30.0;
  o.mip_nav.filter_roll_pitch_sigma_deg = o.mip_nav.filter_heading_sigma_deg = 0.0;
  o.mip_nav.filter_horizontal_sigma_m = o.mip_nav.filter_vertical_sigma_m = 0.0;
  o.mip_nav.filter_velocity_sigma_m_s = 0.0;
  return o;
}

// What ArduPilot keeps from the stream (MicroStrain_common.cpp handle_*).
struct ApState {
  std::int64_t last_imu_ms = -1, last_gps_ms = -1, last_filter_ms = -1;
  int fix_type = 0;  // AP_GPS: 0 no GPS, 1 no fix, 3 3D
  int filter_state = -1;
};
// Intervals [from, to) in seconds where a condition held, by sample instants.
using Intervals = std::vector<std::pair<double, double>>;
struct Track {
  Intervals spans;
  void at(double t, bool holds, double dt) {
    if (holds) {
      if (!spans.empty() && std::abs(spans.back().second - t) < 1e-9) spans.back().second = t + dt;
      else spans.push_back({t, t + dt});
    }
  }
};
std::string text(const Intervals& v) {
  std::string s;
  for (const auto& [a, b] : v) s += "[" + std::to_string(a) + ", " + std::to_string(b) + ") ";
  return s;
}
void expect_spans(const Intervals& got, const Intervals& want, const char* what) {
  ASSERT_EQ(got.size(), want.size()) << what << ": " << text(got);
  for (std::size_t i = 0; i < got.size(); ++i) {
    EXPECT_NEAR(got[i].first, want[i].first, 1e-9) << what << ": " << text(got);
    EXPECT_NEAR(got[i].second, want[i].second, 1e-9) << what << ": " << text(got);
  }
}

struct RunRecord {
  Track ms5_healthy, ms5_fix, ms5_running, ms5_prearm;
  Track ms7_initialised, ms7_times, ms7_filter, ms7_prearm;
  int checked_gnss = 0, checked_filter = 0;
};

constexpr std::uint64_t kSamples = 12'000;  // 120 s

RunRecord run_scene(drivers::MipFilterStates states) {
  drivers::mip::Encoder e(scene_options(states));
  ApState ap;
  RunRecord r;
  const double dt = 1.0 / kRate;
  for (std::uint64_t k = 0; k < kSamples; ++k) {
    const drivers::ImuFrameInput f = frame_at(k);
    Bytes out;
    e.encode(f, out);
    const std::int64_t now_ms = static_cast<std::int64_t>(k) * 10;
    const double t = static_cast<double>(k) / kRate;
    const Truth x = truth_at(t);
    for (const Packet& p : spec_packets(out)) {
      if (p.set == 0x80) ap.last_imu_ms = now_ms;
      if (p.set == 0x81) {
        ap.last_gps_ms = now_ms;
        for (const auto& [d, v] : p.fields) {
          if (d == 0x0B) {
            EXPECT_EQ(v.size(), 6u);
            ap.fix_type = v[0] == 0x00 ? 3 : v[0] == 0x03 ? 1 : 0;
          }
          if (d == 0x03 && be(v.data() + 40, 2) != 0) {  // a valid LLH: the trajectory's
            EXPECT_EQ(v.size(), 42u);
            EXPECT_NEAR(be_f64(v.data()), x.lat_rad * 180.0 / kPi, 1e-12);
            EXPECT_NEAR(be_f64(v.data() + 8), x.lon_rad * 180.0 / kPi, 1e-12);
            EXPECT_NEAR(be_f64(v.data() + 16), x.h_m, 1e-9);
            ++r.checked_gnss;
          }
          if (d == 0x05 && be(v.data() + 32, 2) != 0) {
            EXPECT_EQ(v.size(), 34u);
            for (int i = 0; i < 3; ++i) EXPECT_NEAR(be_f32(v.data() + 4 * i), x.v_ned[i], 1e-5);
            EXPECT_NEAR(be_f32(v.data() + 20), 45.0, 1e-4);  // heading (deg): north-east
          }
        }
      }
      if (p.set == 0x82) {
        ap.last_filter_ms = now_ms;
        for (const auto& [d, v] : p.fields) {
          if (d == 0x10) {
            EXPECT_EQ(v.size(), 6u);
            ap.filter_state = static_cast<int>(be(v.data(), 2));
          }
          if (d == 0x03 && be(v.data() + 16, 2) != 0) {  // a valid attitude: yaw about down
            EXPECT_NEAR(be_f32(v.data()), std::cos(x.yaw_rad / 2), 1e-6);
            EXPECT_NEAR(be_f32(v.data() + 12), std::sin(x.yaw_rad / 2), 1e-6);
            ++r.checked_filter;
          }
          if (d == 0x01 && be(v.data() + 24, 2) != 0) {
            EXPECT_NEAR(be_f64(v.data()), x.lat_rad * 180.0 / kPi, 1e-12);
            EXPECT_NEAR(be_f64(v.data() + 8), x.lon_rad * 180.0 / kPi, 1e-12);
          }
          if (d == 0xD3) {  // GPS week 2400, tow = t
            EXPECT_EQ(be(v.data() + 8, 2), 2400u);
            EXPECT_NEAR(be_f64(v.data()), t, 1e-9);
          }
        }
      }
    }
    auto age_below = [&](std::int64_t last, double limit_ms) { return last >= 0 && double(now_ms - last) < limit_ms; };
    // MicroStrain5.
    const bool ms5_healthy = age_below(ap.last_imu_ms, 40) && age_below(ap.last_gps_ms, 500) &&
                             age_below(ap.last_filter_ms, 500);
    r.ms5_healthy.at(t, ms5_healthy, dt);
    r.ms5_fix.at(t, ap.fix_type >= 3, dt);
    r.ms5_running.at(t, ap.filter_state == 0x02, dt);
    r.ms5_prearm.at(t, ms5_healthy && ap.fix_type >= 3 && ap.filter_state == 0x02, dt);
    // MicroStrain7.
    const bool init = ap.last_imu_ms >= 0 && ap.last_gps_ms >= 0 && ap.last_filter_ms >= 0;
    const bool times = age_below(ap.last_imu_ms, 40 * 1.1) && age_below(ap.last_gps_ms, 500 * 1.1) &&
                       age_below(ap.last_filter_ms, 40 * 1.1);
    const bool filter = ap.filter_state == 3 || ap.filter_state == 4;
    r.ms7_initialised.at(t, init, dt);
    r.ms7_times.at(t, times, dt);
    r.ms7_filter.at(t, filter, dt);
    r.ms7_prearm.at(t, init && times && filter && ap.fix_type >= 3, dt);
  }
  return r;
}

// A 3DM-CV7 personality (filter states 1 init, 3 AHRS, 4 full nav) against
// MicroStrain7: packets are fresh from the first sample on; the filter is
// healthy (AHRS) once aligned at 5 s and stays so through the outage (AHRS
// again); pre-arm passes only with a 3D fix: 30..60 s and from 90 s.
TEST(MipArduPilotHealth, Cv7ThroughColdStartAlignFixAndOutageMeetsMicroStrain7WhenExpected) {
  const RunRecord r = run_scene(drivers::MipFilterStates::cv7);
  expect_spans(r.ms7_initialised.spans, {{0.0, 120.0}}, "MicroStrain7 initialised");
  expect_spans(r.ms7_times.spans, {{0.0, 120.0}}, "MicroStrain7 times_healthy");
  expect_spans(r.ms7_filter.spans, {{5.0, 120.0}}, "MicroStrain7 filter_healthy (AHRS or full nav)");
  expect_spans(r.ms7_prearm.spans, {{30.0, 60.0}, {90.0, 120.0}}, "MicroStrain7 pre_arm_check");
  // The same stream's fix as MicroStrain5 reads it.
  expect_spans(r.ms5_fix.spans, {{30.0, 60.0}, {90.0, 120.0}}, "fix >= 3D");
  // MicroStrain5 wants GX5 state 2: a CV7 reports 2 only as vertical gyro, never here.
  EXPECT_TRUE(r.ms5_running.spans.empty()) << text(r.ms5_running.spans);
  // Every valid GNSS LLH (4 Hz x 60 s with a fix) and filter attitude (50 Hz x 115 s) matched the trajectory.
  EXPECT_EQ(r.checked_gnss, 4 * 60);
  EXPECT_EQ(r.checked_filter, 50 * 115);
}

// A 3DM-GX5-45 personality (0x82,0x10 states 1 init, 2 running valid) against
// MicroStrain5: healthy by packet ages throughout; the filter runs from the
// first fix (30 s) on, through the outage (dead reckoning, GNSS-unavailable
// flag); pre-arm passes with the fix only.
TEST(MipArduPilotHealth, Gx5ThroughColdStartAlignFixAndOutageMeetsMicroStrain5WhenExpected) {
  const RunRecord r = run_scene(drivers::MipFilterStates::gx5);
  expect_spans(r.ms5_healthy.spans, {{0.0, 120.0}}, "MicroStrain5 healthy");
  expect_spans(r.ms5_fix.spans, {{30.0, 60.0}, {90.0, 120.0}}, "MicroStrain5 fix >= 3");
  expect_spans(r.ms5_running.spans, {{30.0, 120.0}}, "MicroStrain5 filter state 0x02");
  expect_spans(r.ms5_prearm.spans, {{30.0, 60.0}, {90.0, 120.0}}, "MicroStrain5 pre_arm_check");
  // MicroStrain7 would call a GX5's running state 2 "vertical gyro": never healthy.
  EXPECT_TRUE(r.ms7_filter.spans.empty()) << text(r.ms7_filter.spans);
}

// Off by default: the same options without the nav keys send only 0x80.
TEST(MipArduPilotHealth, WithoutGnssAndFilterRatesOnlyTheImuSetIsSent) {
  drivers::StreamEncoderOptions o;
  o.nominal_sample_rate_hz = kRate;
  drivers::mip::Encoder e(o);
  for (std::uint64_t k = 0; k < 200; ++k) {
    Bytes out;
    e.encode(frame_at(k), out);
    const auto packets = spec_packets(out);
    ASSERT_EQ(packets.size(), 1u);
    EXPECT_EQ(packets[0].set, 0x80);
  }
}

}  // namespace

namespace {

// The filter's errors: with the datasheet defaults (3DM-GX5-45: 2.5 m
// horizontal, 5 m vertical, 0.1 m/s per axis, 1 sigma) the decoded solution
// minus the trajectory has those statistics over 3000 epochs (60 s at 50 Hz:
// a sigma estimate within 1.3 % (1 sigma) of the truth, checked at 6 %; means
// within 4 standard errors), and the same seed gives the same bytes.
TEST(MipArduPilotHealth, FilterErrorsHaveTheDatasheetSigmasAndFollowTheSeed) {
  auto options = [](std::uint64_t seed) {
    drivers::StreamEncoderOptions o;
    o.nominal_sample_rate_hz = kRate;
    o.mip_nav.gnss_rate_hz = 4;
    o.mip_nav.filter_rate_hz = 50;
    o.mip_nav.filter_alignment_s = 0.0;
    o.mip_nav.gnss_first_fix_s = 0.0;
    o.aiding_seed = seed;
    return o;
  };
  drivers::mip::Encoder a(options(7)), b(options(7)), c(options(8));
  // WGS84 meridian and prime-vertical radii at the latitude (NIMA TR8350.2).
  const double e2 = 6.69437999014e-3, s2 = std::pow(std::sin(kLat0), 2);
  const double m_r = 6378137.0 * (1 - e2) / std::pow(1 - e2 * s2, 1.5), n_r = 6378137.0 / std::sqrt(1 - e2 * s2);
  double sum[5] = {}, sum2[5] = {};
  int n = 0;
  bool c_differs = false;
  for (std::uint64_t k = 0; k < 6000; ++k) {
    const drivers::ImuFrameInput f = frame_at(k);
    Bytes oa, ob, oc;
    a.encode(f, oa);
    b.encode(f, ob);
    c.encode(f, oc);
    ASSERT_EQ(oa, ob);
    c_differs = c_differs || oa != oc;
    const Truth x = truth_at(static_cast<double>(k) / kRate);
    for (const Packet& p : spec_packets(oa)) {
      if (p.set != 0x82) continue;
      double err[5] = {};
      int got = 0;
      for (const auto& [d, v] : p.fields) {
        if (d == 0x01 && be(v.data() + 24, 2) == 1) {
          err[0] = (be_f64(v.data()) * kPi / 180.0 - x.lat_rad) * m_r;
          err[1] = (be_f64(v.data() + 8) * kPi / 180.0 - x.lon_rad) * n_r * std::cos(x.lat_rad);
          err[2] = be_f64(v.data() + 16) - x.h_m;
          ++got;
        }
        if (d == 0x02 && be(v.data() + 12, 2) == 1) {
          err[3] = be_f32(v.data()) - x.v_ned.x();
          err[4] = be_f32(v.data() + 8) - x.v_ned.z();
          ++got;
        }
      }
      ASSERT_EQ(got, 2);
      for (int i = 0; i < 5; ++i) {
        sum[i] += err[i];
        sum2[i] += err[i] * err[i];
      }
      ++n;
    }
  }
  ASSERT_EQ(n, 3000);
  EXPECT_TRUE(c_differs);
  const double want[5] = {2.5, 2.5, 5.0, 0.1, 0.1};
  for (int i = 0; i < 5; ++i) {
    const double mean = sum[i] / n, sd = std::sqrt(sum2[i] / n - mean * mean);
    EXPECT_NEAR(mean, 0.0, 4.0 * want[i] / std::sqrt(n)) << i;
    EXPECT_NEAR(sd, want[i], 0.06 * want[i]) << i;
  }
}

}  // namespace
}  // namespace unity_device_test_mip_ardupilot_health
