// Fault injection, sensor side and timeline (core/fault/, issue 18), against
// independent truth: a linear-in-k input whose every sample is known in
// closed form, the effect each fault kind must have written out here from
// its definition (docs/faults.md), and bit-for-bit comparison with the
// unfaulted input outside the fault's samples. Random terms are checked
// against their sampling distributions (seeded, several standard errors wide).
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <sstream>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/fault/fault.hpp"
#include "core/fault/timeline.hpp"
#include "io/fault_log.hpp"

// Counts this binary's allocations while g_counting is set (the timeline's step() must allocate nothing per sample).
#include "tests/support/allocation_counter.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace imuemu::fault {}
namespace unity_io_test_faults {
namespace imuemu { using namespace ::imuemu; }
namespace imuemu::fault { using namespace ::imuemu::fault; }

namespace imuemu::fault {
namespace {

constexpr std::int64_t kRate = 100;
constexpr TimeNs kPeriod = 10'000'000;
constexpr TimeNs kT0 = 5 * kNsPerSecond;  // trajectory time of sample 0
constexpr double kH = 0.01;               // s

TimeNs t_of(std::uint64_t k) { return kT0 + static_cast<TimeNs>(k) * kPeriod; }

// The unfaulted sample k: rates and forces linear in k, increments = value x h.
SampleValues input(std::uint64_t k) {
  const double x = static_cast<double>(k);
  SampleValues v;
  v.gyro_rad_s = Vec3(0.1 + 0.001 * x, -0.2 + 0.002 * x, 0.3 - 0.001 * x);
  v.accel_m_s2 = Vec3(0.5 + 0.01 * x, -0.3, -9.8 + 0.003 * x);
  v.delta_theta_rad = v.gyro_rad_s * kH;
  v.delta_velocity_m_s = v.accel_m_s2 * kH;
  v.period_ns = kPeriod;
  return v;
}

struct FaultRun {
  std::vector<SampleValues> out;
  std::vector<SampleFaults> faults;
  std::vector<FaultEvent> events;
};

DeviceContext context() {
  DeviceContext c;
  c.device = "imu0";
  c.rate_hz = kRate;
  c.gyro_noise_density = Vec3::Constant(0.01);  // sigma 0.1 rad/s at 100 Hz
  c.accel_noise_density = Vec3::Constant(0.02);
  return c;
}

FaultRun run(TimelineOptions o, std::uint64_t n, const std::function<void(FaultTimeline&, std::uint64_t)>& before = {}) {
  FaultTimeline tl(std::move(o));
  FaultRun r;
  for (std::uint64_t k = 0; k < n; ++k) {
    if (before) before(tl, k);
    SampleValues v = input(k);
    r.faults.push_back(tl.step(k, t_of(k), v));
    r.out.push_back(v);
    tl.drain_events(r.events);
  }
  tl.finish();
  tl.drain_events(r.events);
  return r;
}

// A fault from 0.1 s since start for 0.05 s: samples 10..14 exactly.
FaultSpec window_spec(Kind kind) {
  FaultSpec s = default_spec(kind);
  s.clock = Clock::since_start;
  s.start_ns = 100'000'000;
  s.duration_ns = 50'000'000;
  s.seed = 7;
  return s;
}

TimelineOptions with(const FaultSpec& s) {
  TimelineOptions o;
  o.context = context();
  o.faults = {s};
  return o;
}

TimelineOptions no_faults() {
  TimelineOptions o;
  o.context = context();
  return o;
}

bool same_bits(const SampleValues& a, const SampleValues& b) {
  auto eq = [](const Vec3& x, const Vec3& y) {
    return std::memcmp(x.data(), y.data(), sizeof(double) * 3) == 0;
  };
  return eq(a.gyro_rad_s, b.gyro_rad_s) && eq(a.accel_m_s2, b.accel_m_s2) && eq(a.delta_theta_rad, b.delta_theta_rad) &&
         eq(a.delta_velocity_m_s, b.delta_velocity_m_s);
}

// Outside 10..14 every sample is the input bit for bit, and the events name
// exactly samples 10 (start) and 14 (end).
void expect_window_only(const FaultRun& r, const std::string& what) {
  for (std::uint64_t k = 0; k < r.out.size(); ++k)
    if (k < 10 || k > 14) {
      EXPECT_TRUE(same_bits(r.out[k], input(k))) << what << " changed sample " << k;
    }
  ASSERT_EQ(r.events.size(), 2u) << what;
  EXPECT_EQ(r.events[0].phase, FaultEvent::Phase::start);
  EXPECT_EQ(r.events[0].sample_counter, 10u) << what;
  EXPECT_EQ(r.events[0].t_ns, t_of(10)) << what;
  EXPECT_EQ(r.events[1].phase, FaultEvent::Phase::end);
  EXPECT_EQ(r.events[1].sample_counter, 14u) << what;
  EXPECT_EQ(r.events[1].t_ns, t_of(14)) << what;
  EXPECT_EQ(r.events[0].spec.device, "imu0");
}

// Checks one triad-axis value and its increment.
void expect_axis(const SampleValues& got, int tri, int a, double rate, double inc, const std::string& what) {
  const Vec3& g = tri == 0 ? got.gyro_rad_s : got.accel_m_s2;
  const Vec3& d = tri == 0 ? got.delta_theta_rad : got.delta_velocity_m_s;
  EXPECT_NEAR(g[a], rate, 1e-12 * (1.0 + std::abs(rate))) << what << " triad " << tri << " axis " << a;
  EXPECT_NEAR(d[a], inc, 1e-14 * (1.0 + std::abs(inc))) << what << " increment, triad " << tri << " axis " << a;
}

Vec3 rate_of(const SampleValues& v, int tri) { return tri == 0 ? v.gyro_rad_s : v.accel_m_s2; }
Vec3 inc_of(const SampleValues& v, int tri) { return tri == 0 ? v.delta_theta_rad : v.delta_velocity_m_s; }

TEST(Faults, DeterministicSensorKindsActExactlyOnTheirSamplesWithTheAnalyticEffect) {
  const double gyro_range = kDefaultGyroRangeRadS, accel_range = kDefaultAccelRangeMS2;
  for (Kind kind : {Kind::stuck, Kind::dead, Kind::bias_step, Kind::bias_ramp, Kind::scale_step, Kind::saturation,
                    Kind::slow, Kind::intermittent, Kind::delayed, Kind::plausible_drift, Kind::spikes}) {
    FaultSpec s = window_spec(kind);
    s.gyro_bias_rad_s = 0.05;
    s.accel_bias_m_s2 = -0.4;
    s.gyro_ramp_rad_s2 = 0.01;
    s.accel_ramp_m_s3 = -0.02;
    s.scale_ppm = 2500.0;
    s.divisor = 2;
    s.on_ns = 20'000'000;
    s.off_ns = 10'000'000;
    s.delay_ns = 30'000'000;
    s.rate_hz = 1e5;  // spikes: p = 1 - e^-1000 = 1 per sample
    if (kind == Kind::plausible_drift) {
      s.gyro_bias_rad_s = 3e-4;  // cap reached 0.03 s after the start
      s.accel_bias_m_s2 = 6e-4;
    }
    const std::string what(kind_name(kind));
    const FaultRun r = run(with(s), 40);
    expect_window_only(r, what);
    for (std::uint64_t k = 10; k <= 14; ++k) {
      const SampleValues in = input(k);
      const double tau = static_cast<double>(k - 10) * kH;
      for (int tri = 0; tri < 2; ++tri) {
        const double range = tri == 0 ? gyro_range : accel_range;
        const double bias = tri == 0 ? s.gyro_bias_rad_s : s.accel_bias_m_s2;
        const double ramp = tri == 0 ? s.gyro_ramp_rad_s2 : s.accel_ramp_m_s3;
        for (int a = 0; a < 3; ++a) {
          const double v = rate_of(in, tri)[a], d = inc_of(in, tri)[a];
          double ev = v, ed = d;
          switch (kind) {
            case Kind::stuck: ev = rate_of(input(9), tri)[a]; ed = ev * kH; break;  // frozen at sample 9
            case Kind::dead: ev = 0.0; ed = 0.0; break;
            case Kind::bias_step: ev = v + bias; ed = d + bias * kH; break;
            case Kind::bias_ramp:
              // b = r (t - t_s), its integral over (t - h, t] from t_s on.
              ev = v + ramp * tau;
              ed = d + (k == 10 ? 0.0 : ramp * kH * (tau - kH / 2));
              break;
            case Kind::plausible_drift: {
              // b = min(cap, r tau) with |r| = 0.01 and 0.02, caps 3e-4 and 6e-4:
              // the cap is reached at tau = 0.03 s (k = 13).
              const double sign = ramp < 0 ? -1.0 : 1.0, cap = bias, r0 = std::abs(ramp);
              ev = v + sign * std::min(cap, r0 * tau);
              const double integrals[5] = {0.0, r0 * kH * kH / 2, r0 * kH * kH * 1.5, r0 * kH * kH * 2.5, cap * kH};
              ed = d + sign * integrals[k - 10];
              break;
            }
            case Kind::scale_step: ev = v * 1.0025; ed = d * 1.0025; break;
            case Kind::saturation: ev = v < 0 ? -range : range; ed = ev * kH; break;
            case Kind::slow: {
              // The value changes every 2nd sample from the first: 10, 12, 14.
              const std::uint64_t held = k - (k - 10) % 2;
              ev = rate_of(input(held), tri)[a];
              ed = ev * kH;
              break;
            }
            case Kind::intermittent:
              // 20 ms on, 10 ms off from 0.1 s: on at 10, 11, 13, 14; off at 12.
              if (k != 12) ev = ed = 0.0;
              break;
            case Kind::delayed: ev = rate_of(input(k - 3), tri)[a]; ed = inc_of(input(k - 3), tri)[a]; break;
            case Kind::spikes: ev = v + bias; ed = d + bias * kH; break;
            default: break;
          }
          expect_axis(r.out[k], tri, a, ev, ed, what + " sample " + std::to_string(k));
        }
      }
      const bool saturated = (r.faults[k].flags & kFlagSaturated) != 0;
      EXPECT_EQ(saturated, kind == Kind::saturation) << what;
      EXPECT_EQ(r.faults[k].flags & kFlagFault, 0u) << what << ": flag_status was not asked for";
      EXPECT_FALSE(r.faults[k].link.any()) << what;
    }
  }
}

TEST(Faults, OnlyTheConfiguredTriadAndAxesChangeAndFlagStatusRaisesTheFaultFlag) {
  FaultSpec s = window_spec(Kind::dead);
  s.triad = Triad::accel;
  s.axes = 0b101;  // x and z
  s.flag_status = true;
  const FaultRun r = run(with(s), 20);
  expect_window_only(r, "dead accel xz");
  for (std::uint64_t k = 10; k <= 14; ++k) {
    const SampleValues in = input(k);
    EXPECT_TRUE(std::memcmp(r.out[k].gyro_rad_s.data(), in.gyro_rad_s.data(), 24) == 0);
    EXPECT_TRUE(std::memcmp(r.out[k].delta_theta_rad.data(), in.delta_theta_rad.data(), 24) == 0);
    EXPECT_EQ(r.out[k].accel_m_s2[0], 0.0);
    EXPECT_EQ(r.out[k].accel_m_s2[1], in.accel_m_s2[1]);
    EXPECT_EQ(r.out[k].accel_m_s2[2], 0.0);
    EXPECT_EQ(r.out[k].delta_velocity_m_s[1], in.delta_velocity_m_s[1]);
    EXPECT_EQ(r.faults[k].flags, static_cast<std::uint32_t>(kFlagFault));
  }
  EXPECT_EQ(r.faults[9].flags, 0u);
  EXPECT_EQ(r.faults[15].flags, 0u);
}

TEST(Faults, GarbageIsUniformWithinTheRangeAndReproducible) {
  FaultSpec s = window_spec(Kind::garbage);
  s.duration_ns = 100 * kNsPerSecond;
  const FaultRun a = run(with(s), 4010), b = run(with(s), 4010);
  double sum = 0.0, sum2 = 0.0;
  int n = 0;
  for (std::uint64_t k = 10; k < 4010; ++k) {
    EXPECT_TRUE(same_bits(a.out[k], b.out[k])) << k;
    for (int ax = 0; ax < 3; ++ax) {
      const double g = a.out[k].gyro_rad_s[ax] / kDefaultGyroRangeRadS;
      ASSERT_LE(std::abs(g), 1.0);
      ASSERT_LE(std::abs(a.out[k].accel_m_s2[ax]), kDefaultAccelRangeMS2);
      EXPECT_EQ(a.out[k].delta_theta_rad[ax], a.out[k].gyro_rad_s[ax] * kH);
      sum += g;
      sum2 += g * g;
      ++n;
    }
  }
  // Uniform on [-1, 1]: mean 0 (sd 1/sqrt(3n)), mean square 1/3 (sd sqrt(4/45 / n)).
  EXPECT_NEAR(sum / n, 0.0, 5.0 / std::sqrt(3.0 * n));
  EXPECT_NEAR(sum2 / n, 1.0 / 3.0, 5.0 * std::sqrt(4.0 / 45.0 / n));
  // Another seed, other values.
  s.seed = 8;
  const FaultRun c = run(with(s), 20);
  EXPECT_NE(c.out[10].gyro_rad_s[0], a.out[10].gyro_rad_s[0]);
}

TEST(Faults, NoiseGainAddsIndependentNoiseOfSigmaNSqrtRateSqrtKSquaredMinusOne) {
  FaultSpec s = window_spec(Kind::noise_gain);
  s.noise_factor = 3.0;
  s.duration_ns = 200 * kNsPerSecond;
  const std::uint64_t n = 20010;
  const FaultRun r = run(with(s), n);
  const double expected = 0.01 * std::sqrt(100.0) * std::sqrt(8.0);  // gyro: 0.283 rad/s
  double sum2 = 0.0, cross = 0.0;
  for (std::uint64_t k = 10; k < n; ++k) {
    const double e = r.out[k].gyro_rad_s[0] - input(k).gyro_rad_s[0];
    const double e2 = r.out[k].gyro_rad_s[1] - input(k).gyro_rad_s[1];
    EXPECT_NEAR(r.out[k].delta_theta_rad[0] - input(k).delta_theta_rad[0], e * kH, 1e-15);
    sum2 += e * e;
    cross += e * e2;
  }
  const double m = static_cast<double>(n - 10);
  // Sample variance of a Gaussian: relative sd sqrt(2/m) = 1 %; axes uncorrelated (sd 1/sqrt(m)).
  EXPECT_NEAR(std::sqrt(sum2 / m) / expected, 1.0, 5.0 * std::sqrt(0.5 / m));
  EXPECT_NEAR(cross / sum2, 0.0, 5.0 / std::sqrt(m));
}

TEST(Faults, SpikesArriveAsAPoissonProcessAtTheirRate) {
  FaultSpec s = window_spec(Kind::spikes);
  s.rate_hz = 5.0;
  s.gyro_bias_rad_s = 1.0;
  s.triad = Triad::gyro;
  s.duration_ns = 200 * kNsPerSecond;
  const std::uint64_t n = 20010;
  const FaultRun r = run(with(s), n);
  int spikes = 0;
  for (std::uint64_t k = 10; k < n; ++k) {
    const double e = r.out[k].gyro_rad_s[2] - input(k).gyro_rad_s[2];
    if (e != 0.0) {
      EXPECT_NEAR(e, 1.0, 1e-12);
      EXPECT_NEAR(r.out[k].gyro_rad_s[0] - input(k).gyro_rad_s[0], 1.0, 1e-12);  // all axes of the sample
      ++spikes;
    }
  }
  // Bernoulli per sample, p = 1 - e^(-5 x 0.01): mean 975.4, sd 30.5.
  const double p = -std::expm1(-0.05), mean = p * static_cast<double>(n - 10);
  EXPECT_NEAR(spikes, mean, 5.0 * std::sqrt(mean * (1 - p)));
}

TEST(Faults, DrawsDependOnTheSampleNotOnWhichSamplesWereAsked) {
  FaultSpec s = window_spec(Kind::garbage);
  s.duration_ns = 10 * kNsPerSecond;
  FaultTimeline all(with(s)), skipping(with(s));
  for (std::uint64_t k = 0; k < 100; ++k) {
    SampleValues a = input(k);
    all.step(k, t_of(k), a);
    if (k % 7 != 0 && k != 99) continue;
    SampleValues b = input(k);
    skipping.step(k, t_of(k), b);
    if (k >= 10) {
      EXPECT_TRUE(same_bits(a, b)) << k;
    }
  }
}

TEST(Faults, ClearReturnsToTheOutputOfARunThatNeverHadTheFault) {
  for (Kind kind : {Kind::stuck, Kind::garbage, Kind::slow, Kind::delayed, Kind::noise_gain, Kind::bias_ramp}) {
    FaultSpec s = default_spec(kind);
    s.gyro_ramp_rad_s2 = 0.1;
    s.noise_factor = 4.0;
    s.delay_ns = 50'000'000;
    s.divisor = 3;
    std::uint64_t id = 0;
    const FaultRun r = run(no_faults(), 60,
                      [&](FaultTimeline& tl, std::uint64_t k) {
                        if (k == 20) id = tl.inject(s);  // start 0 since start: in the past, starts at sample 20
                        if (k == 30) {
                          EXPECT_TRUE(tl.clear(id));
                        }
                      });
    const std::string what(kind_name(kind));
    for (std::uint64_t k = 0; k < 60; ++k)
      if (k < 20 || k >= 30) {
        EXPECT_TRUE(same_bits(r.out[k], input(k))) << what << " sample " << k;
      }
    EXPECT_FALSE(same_bits(r.out[25], input(25))) << what;
    ASSERT_EQ(r.events.size(), 2u) << what;
    EXPECT_EQ(r.events[0].sample_counter, 20u);
    EXPECT_EQ(r.events[1].sample_counter, 29u);
    EXPECT_EQ(r.events[0].spec.source, "control");
    EXPECT_EQ(r.events[0].fault_id, id);
  }
}

TEST(Faults, ARefusedInjectChangesNothing) {
  TimelineOptions o;
  o.context = context();
  o.max_faults = 2;
  FaultTimeline tl(o);
  SampleValues v = input(0);
  tl.step(0, t_of(0), v);
  const std::uint64_t first = tl.inject(default_spec(Kind::dead));
  FaultSpec bad = default_spec(Kind::noise_gain);
  bad.noise_factor = 0.5;
  try {
    tl.inject(bad);
    FAIL() << "noise_factor 0.5 accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("noise_factor"), std::string::npos) << e.what();
  }
  FaultSpec late = default_spec(Kind::delayed);
  late.delay_ns = kMaxDelayNs + 1;
  EXPECT_THROW(tl.inject(late), std::invalid_argument);
  EXPECT_EQ(tl.list().size(), 1u);
  const std::uint64_t second = tl.inject(default_spec(Kind::stuck));
  EXPECT_EQ(second, first + 1) << "a refused inject must not use up an id";
  EXPECT_THROW(tl.inject(default_spec(Kind::dead)), std::invalid_argument);  // max_faults 2
  EXPECT_EQ(tl.list().size(), 2u);
  EXPECT_FALSE(tl.clear(999));
  EXPECT_EQ(tl.list().size(), 2u);
  EXPECT_EQ(tl.clear_all(), 2u);
  EXPECT_TRUE(tl.list().empty());
}

TEST(Faults, TrajectoryClockStartsAtTheTrajectoryTimeAndFinishEndsOpenFaults) {
  FaultSpec s = default_spec(Kind::dead);
  s.clock = Clock::trajectory;
  s.start_ns = t_of(25) - 3'000'000;  // between samples 24 and 25
  s.duration_ns = 0;                  // until the end of the run
  const FaultRun r = run(with(s), 40);
  EXPECT_TRUE(same_bits(r.out[24], input(24)));
  EXPECT_EQ(r.out[25].gyro_rad_s, Vec3::Zero());
  ASSERT_EQ(r.events.size(), 2u);
  EXPECT_EQ(r.events[0].sample_counter, 25u);
  EXPECT_EQ(r.events[1].sample_counter, 39u);  // finish(): the last sample produced
}

TEST(Faults, AFaultBetweenTwoSamplesAffectsNothingAndLogsNothing) {
  FaultSpec s = default_spec(Kind::dead);
  s.start_ns = 101'000'000;
  s.duration_ns = 5'000'000;  // 0.101 .. 0.106 s: no sample
  const FaultRun r = run(with(s), 20);
  for (std::uint64_t k = 0; k < 20; ++k) EXPECT_TRUE(same_bits(r.out[k], input(k)));
  EXPECT_TRUE(r.events.empty());
}

TEST(Faults, RandomFaultsReproduceWithOneSeedAndDifferWithAnother) {
  auto options = [](std::uint64_t seed) {
    TimelineOptions o;
    o.context = context();
    o.random.per_hour = 600;  // 10 per minute
    o.random.kinds = {Kind::dead, Kind::bias_step, Kind::garbage, Kind::drop};
    o.random.duration_ns = 2 * kNsPerSecond;
    o.random.seed = seed;
    return o;
  };
  const std::uint64_t n = 100 * 300;  // 5 minutes at 100 Hz
  const FaultRun a = run(options(1), n), b = run(options(1), n), c = run(options(2), n);
  ASSERT_EQ(a.events.size(), b.events.size());
  for (std::size_t i = 0; i < a.events.size(); ++i) {
    EXPECT_EQ(a.events[i].sample_counter, b.events[i].sample_counter);
    EXPECT_EQ(a.events[i].spec.kind, b.events[i].spec.kind);
    EXPECT_EQ(a.events[i].spec.source, "random");
  }
  for (std::uint64_t k = 0; k < n; k += 97) EXPECT_TRUE(same_bits(a.out[k], b.out[k])) << k;
  // Poisson(50) faults in 5 minutes: 2 x 25 events give 20..80 faults with
  // overwhelming probability; a fault near another of its kind may merge
  // nothing (each is its own entry).
  EXPECT_GE(a.events.size(), 2u * 20u);
  EXPECT_LE(a.events.size(), 2u * 80u);
  bool differs = a.events.size() != c.events.size();
  for (std::size_t i = 0; !differs && i < a.events.size(); ++i)
    differs = a.events[i].sample_counter != c.events[i].sample_counter;
  EXPECT_TRUE(differs);
  // Every start has its end, each at least as late, within 2 s of samples.
  for (const FaultEvent& e : a.events)
    if (e.phase == FaultEvent::Phase::start) {
      const auto end = std::find_if(a.events.begin(), a.events.end(), [&](const FaultEvent& x) {
        return x.fault_id == e.fault_id && x.phase == FaultEvent::Phase::end;
      });
      ASSERT_NE(end, a.events.end());
      EXPECT_GE(end->sample_counter, e.sample_counter);
      EXPECT_LT(end->sample_counter - e.sample_counter, 200u);
    }
}

TEST(Faults, TheEventBufferIsBoundedAndCountsWhatOverflows) {
  TimelineOptions o;
  o.context = context();
  o.event_capacity = 4;
  for (int i = 0; i < 5; ++i) {
    FaultSpec s = default_spec(Kind::dead);
    s.start_ns = i * kPeriod;
    s.duration_ns = kPeriod;
    o.faults.push_back(s);
  }
  FaultTimeline tl(o);
  for (std::uint64_t k = 0; k < 10; ++k) {
    SampleValues v = input(k);
    tl.step(k, t_of(k), v);
  }
  EXPECT_EQ(tl.pending_events(), 4u);
  EXPECT_EQ(tl.counters().events_overflowed, 6u);  // 10 events, 4 kept
  EXPECT_EQ(tl.counters().started, 5u);
  EXPECT_EQ(tl.counters().ended, 5u);
}

TEST(Faults, StepAllocatesNothingPerSample) {
  TimelineOptions o;
  o.context = context();
  // Every kind at once, each over samples 100..5099, some ending, some not.
  for (std::string_view name : kind_names()) {
    FaultSpec s = default_spec(*kind_from_name(name));
    s.start_ns = kNsPerSecond;
    s.duration_ns = 50 * kNsPerSecond;
    s.gyro_bias_rad_s = 0.1;
    s.gyro_ramp_rad_s2 = 0.1;
    s.accel_bias_m_s2 = 0.1;
    s.scale_ppm = 10;
    s.noise_factor = 2;
    s.rate_hz = 3;
    s.on_ns = s.off_ns = 30'000'000;
    s.delay_ns = 100'000'000;
    s.bit_error_rate = 1e-3;
    s.truncate_bytes = 2;
    s.sequence_step = 3;
    s.time_step_ns = 1000;
    s.flag_status = true;
    if (s.kind == Kind::drop) {
      s.burst_samples = 4;
      s.rate_hz = 1;
    }
    o.faults.push_back(s);
  }
  FaultTimeline tl(o);
  std::vector<FaultEvent> events;
  events.reserve(1000);
  std::uint64_t allocations = 0, active = 0;
  for (std::uint64_t k = 0; k < 6000; ++k) {
    SampleValues v = input(k);
    g_allocations = 0;
    g_counting = true;
    const SampleFaults f = tl.step(k, t_of(k), v);
    g_counting = false;
    allocations += g_allocations;
    active += f.active;
    tl.drain_events(events);
    ASSERT_TRUE(v.gyro_rad_s.allFinite() && v.accel_m_s2.allFinite() && v.delta_theta_rad.allFinite() &&
                v.delta_velocity_m_s.allFinite());
  }
  EXPECT_EQ(allocations, 0u);
  // The counter counts (so the zero above means something).
  g_allocations = 0;
  g_counting = true;
  auto probe = std::make_unique<std::vector<int>>(3);
  g_counting = false;
  EXPECT_EQ(g_allocations, 2u);
  EXPECT_EQ(active, 5000u * kind_names().size()) << "every fault acted on its 5000 samples";
  EXPECT_EQ(events.size(), 2 * kind_names().size());
}

TEST(Faults, TheDeviceContextComesFromTheSensorModelAndBoundsTheDelay) {
  sensor::SensorModelSpec spec;
  spec.gyro.range = 250.0 * std::numbers::pi / 180.0;
  spec.accel.white_density = Vec3(1e-3, 2e-3, 3e-3);
  const DeviceContext c = device_context("imu9", 400, spec);
  EXPECT_EQ(c.gyro_range_rad_s, spec.gyro.range);
  EXPECT_EQ(c.accel_range_m_s2, kDefaultAccelRangeMS2) << "no accelerometer range: the default 16 g";
  EXPECT_EQ(c.accel_noise_density, spec.accel.white_density);
  EXPECT_EQ(device_context("imu9", 400, std::nullopt).gyro_range_rad_s, kDefaultGyroRangeRadS);
  // 1 s of history up to 65535 samples back: at 100 kHz 655.35 ms.
  EXPECT_EQ(max_delay_ns_at(400), kMaxDelayNs);
  EXPECT_EQ(max_delay_ns_at(100'000), 655'350'000);
  // A saturation fault goes to the model's range.
  TimelineOptions o;
  o.context = c;
  FaultSpec s = default_spec(Kind::saturation);
  s.triad = Triad::gyro;
  o.faults = {s};
  FaultTimeline tl(o);
  SampleValues v = input(0);
  v.gyro_rad_s[1] = -0.5;
  tl.step(0, 0, v);
  EXPECT_EQ(v.gyro_rad_s, Vec3(spec.gyro.range, -spec.gyro.range, spec.gyro.range));
  FaultSpec late = default_spec(Kind::delayed);
  late.delay_ns = 700'000'000;
  TimelineOptions fast;
  fast.context = context();
  fast.context.rate_hz = 100'000;
  FaultTimeline fast_tl(fast);
  EXPECT_THROW(fast_tl.inject(late), std::invalid_argument) << "700 ms is beyond 100 kHz's history";
  late.delay_ns = 600'000'000;
  EXPECT_NO_THROW(fast_tl.inject(late));
}

// ---- link decisions ----

TEST(FaultLink, OneShotAndTimeFaultsActOnTheirSamples) {
  TimelineOptions o;
  o.context = context();
  FaultSpec jump = window_spec(Kind::sequence_jump);
  jump.sequence_step = 7;
  FaultSpec reset = window_spec(Kind::sequence_reset);
  reset.start_ns = 200'000'000;
  FaultSpec tjump = window_spec(Kind::time_jump);
  tjump.start_ns = 300'000'000;
  tjump.time_step_ns = -25'000'000;
  FaultSpec freeze = window_spec(Kind::time_freeze);
  freeze.start_ns = 400'000'000;
  o.faults = {jump, reset, tjump, freeze};
  const FaultRun r = run(o, 60);
  for (std::uint64_t k = 0; k < 60; ++k) {
    const LinkDecision& d = r.faults[k].link;
    EXPECT_EQ(d.sequence_step, k == 10 ? 7 : 0) << k;
    EXPECT_EQ(d.sequence_reset, k == 20) << k;
    if (k >= 30 && k <= 34)
      EXPECT_EQ(d.protocol_time_ns, std::optional<TimeNs>(t_of(k) - 25'000'000)) << k;
    else if (k >= 40 && k <= 44)
      EXPECT_EQ(d.protocol_time_ns, std::optional<TimeNs>(t_of(40))) << k;
    else
      EXPECT_FALSE(d.protocol_time_ns.has_value()) << k;
    EXPECT_TRUE(same_bits(r.out[k], input(k))) << "a link fault changed the sensor values at " << k;
  }
  EXPECT_EQ(r.events.size(), 8u);
}

TEST(FaultLink, RestartIsSilentForItsDurationThenRestartsOnTheNextSample) {
  FaultSpec s = window_spec(Kind::restart);
  const FaultRun r = run(with(s), 20);
  for (std::uint64_t k = 0; k < 20; ++k) {
    EXPECT_EQ(r.faults[k].link.silence, k >= 10 && k <= 14) << k;
    EXPECT_EQ(r.faults[k].link.restart, k == 15) << k;
  }
}

TEST(FaultLink, DropsAtTheirProbabilityAndInBurstsOfTheirLength) {
  FaultSpec s = window_spec(Kind::drop);
  s.probability = 0.25;
  s.duration_ns = 100 * kNsPerSecond;
  const FaultRun r = run(with(s), 10010);
  int dropped = 0;
  for (std::uint64_t k = 10; k < 10010; ++k) dropped += r.faults[k].link.drop ? 1 : 0;
  EXPECT_NEAR(dropped, 2500.0, 5.0 * std::sqrt(10000 * 0.25 * 0.75));
  for (std::uint64_t k = 0; k < 10; ++k) EXPECT_FALSE(r.faults[k].link.drop);

  FaultSpec b = window_spec(Kind::drop);
  b.probability = 0.0;
  b.burst_samples = 6;
  b.rate_hz = 0.5;  // a burst every 2 s on average: runs rarely merge
  b.duration_ns = 100 * kNsPerSecond;
  const FaultRun rb = run(with(b), 10010);
  std::vector<int> runs;
  int current = 0;
  for (std::uint64_t k = 10; k < 10010; ++k) {
    if (rb.faults[k].link.drop) {
      ++current;
    } else if (current > 0) {
      runs.push_back(current);
      current = 0;
    }
  }
  ASSERT_GE(runs.size(), 25u);  // Poisson(50) bursts
  for (int len : runs) EXPECT_GE(len, 6) << "a burst shorter than burst_samples";
  int exact = 0;
  for (int len : runs) exact += len == 6 ? 1 : 0;
  EXPECT_GE(exact, static_cast<int>(runs.size()) * 8 / 10);
}

TEST(FaultLink, BitFlipCountIsBinomialOnAverage) {
  double sum = 0.0;
  for (std::uint64_t seed = 0; seed < 4000; ++seed) sum += bit_flip_count(1e-3, 800, seed);
  EXPECT_NEAR(sum / 4000.0, 0.8, 5.0 * std::sqrt(0.8 / 4000.0));
  EXPECT_EQ(bit_flip_count(0.0, 800, 1), 0u);
  EXPECT_LE(bit_flip_count(0.5, 10, 1), 10u);
}

// ---- validation and the log line ----

TEST(Faults, ValidateNamesTheFieldAndWhatWasExpected) {
  auto message = [](const FaultSpec& s) {
    try {
      validate(s);
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  FaultSpec s = default_spec(Kind::bias_step);
  EXPECT_NE(message(s).find("gyro_bias_rad_s or accel_bias_m_s2"), std::string::npos) << message(s);
  s.gyro_bias_rad_s = 0.1;
  EXPECT_EQ(message(s), "accepted");
  s.axes = 0;
  EXPECT_NE(message(s).find("axes"), std::string::npos);
  FaultSpec d = default_spec(Kind::delayed);
  d.delay_ns = 2 * kNsPerSecond;
  EXPECT_NE(message(d).find("delay"), std::string::npos);
  FaultSpec n = default_spec(Kind::plausible_drift);
  EXPECT_EQ(message(n), "accepted");
  n.gyro_bias_rad_s = std::nan("");
  EXPECT_NE(message(n).find("finite"), std::string::npos);
  for (std::string_view name : kind_names()) {
    ASSERT_TRUE(kind_from_name(name).has_value()) << name;
    EXPECT_EQ(kind_name(*kind_from_name(name)), name);
  }
  EXPECT_FALSE(kind_from_name("stuk").has_value());
  EXPECT_TRUE(is_can_only(Kind::can_wrong_id));
  EXPECT_TRUE(is_link_fault(Kind::drop));
  EXPECT_TRUE(is_sensor_fault(Kind::plausible_drift));
}

TEST(Faults, PlausibleDriftDefaultsStayFarBelowPx4DetectionLimits) {
  const FaultSpec d = default_spec(Kind::plausible_drift);
  EXPECT_LT(d.gyro_bias_rad_s, 0.15 / 10);  // EKF2_GYR_B_LIM 0.15 rad/s
  EXPECT_LT(d.accel_bias_m_s2, 0.4 / 2);    // EKF2_ABL_LIM 0.4 m/s^2
  EXPECT_NEAR(d.gyro_bias_rad_s / d.gyro_ramp_rad_s2, 100.0, 1e-9);  // cap reached after 100 s
}

TEST(FaultLog, OneJsonLinePerEventWithTheSamplesAndParameters) {
  FaultEvent e;
  e.phase = FaultEvent::Phase::end;
  e.fault_id = 3;
  e.spec = default_spec(Kind::bias_step);
  e.spec.device = "imu_a";
  e.spec.triad = Triad::gyro;
  e.spec.axes = 0b110;
  e.spec.gyro_bias_rad_s = 0.25;
  e.spec.start_ns = 1'500'000'000;
  e.spec.duration_ns = 2'000'000'000;
  e.spec.seed = 99;
  e.sample_counter = 1234;
  e.t_ns = 9'876'543'210;
  std::ostringstream out;
  fault_log::write_fault_event_json_line(out, e);
  const std::string line = out.str();
  ASSERT_FALSE(line.empty());
  EXPECT_EQ(line.back(), '\n');
  EXPECT_EQ(std::count(line.begin(), line.end(), '\n'), 1);
  const nlohmann::json j = nlohmann::json::parse(line);
  EXPECT_EQ(j["device"], "imu_a");
  EXPECT_EQ(j["phase"], "end");
  EXPECT_EQ(j["fault_id"], 3);
  EXPECT_EQ(j["type"], "bias_step");
  EXPECT_EQ(j["source"], "scene");
  EXPECT_EQ(j["sample_counter"], 1234);
  EXPECT_EQ(j["t_ns"], 9'876'543'210LL);
  EXPECT_EQ(j["sensor"], "gyro");
  EXPECT_EQ(j["axes"], "yz");
  EXPECT_EQ(j["clock"], "since_start");
  EXPECT_EQ(j["start_ns"], 1'500'000'000);
  EXPECT_EQ(j["duration_ns"], 2'000'000'000);
  EXPECT_EQ(j["seed"], 99);
  EXPECT_EQ(j["parameters"], nlohmann::json({{"gyro_bias_rad_s", 0.25}}));
  FaultEvent link;
  link.spec = default_spec(Kind::drop);
  const nlohmann::json l = fault_log::fault_event_json(link);
  EXPECT_FALSE(l.contains("sensor"));
  EXPECT_EQ(l["parameters"]["probability"], 1.0);
}

}  // namespace
}  // namespace imuemu::fault
}  // namespace unity_io_test_faults
