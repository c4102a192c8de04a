// [live] latency_budget_ms (issue 17): which method a budget buys, the
// emission delay and producer lead it sets, and what --check-config prints.
// Before this change the key was refused as unknown and a live scene always
// ran the smoothing method at look-ahead + margin.
#include <gtest/gtest.h>

#include <string>

#include "core/stream.hpp"
#include "daemon/scene/scene_check.hpp"
#include "daemon/scene/scene_config.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace imuemu::scene {}
namespace unity_scene_test_latency_plan {
namespace imuemu { using namespace ::imuemu; }
namespace imuemu::scene { using namespace ::imuemu::scene; }

namespace imuemu::scene {
namespace {

std::string scene_text(const std::string& source, double knot_interval_s, const std::string& live) {
  return "[scene]\nname = \"t\"\nphysics = \"flat\"\n[trajectory]\nsource = \"" + source +
         "\"\nknot_interval_s = " + std::to_string(knot_interval_s) + "\n[live]\n" + live +
         "\n[[imu]]\nname = \"imu0\"\nrate_hz = 1000\nprotocol = \"native\"\n[imu.transport]\ntype = \"null\"\n";
}

TEST(LatencyPlan, ABudgetBelowTheSmoothingLookaheadRunsTheCausalMethod) {
  const SceneConfig s = parse_scene_text(scene_text("mavlink:127.0.0.1:14560", 0.004, "latency_budget_ms = 6"), "t.toml", ".");
  EXPECT_EQ(s.trajectory.kind, SourceKind::mavlink_udp);
  EXPECT_EQ(s.trajectory.port, 14560);
  const LatencyPlan plan = latency_plan(s, s.imus[0]);
  EXPECT_TRUE(plan.causal);
  EXPECT_TRUE(pipeline_options(s, s.imus[0]).causal);
  EXPECT_EQ(plan.lookahead_ns, 4'000'000);        // one pose interval
  EXPECT_EQ(plan.emission_delay_ns, 6'000'000);   // the budget
  EXPECT_EQ(plan.producer_lead_ns, 1'000'000);    // (6 - 4) / 2 ms
  EXPECT_EQ(plan.arrival_slack_ns, 1'000'000);    // 6 - 1 - 4 ms
  EXPECT_GT(plan.smoothing_lookahead_ns, plan.emission_delay_ns);
  EXPECT_EQ(plan.smoothing_lookahead_ns,
            StreamPipeline::lookahead_ns([&] {
              PipelineOptions po = pipeline_options(s, s.imus[0]);
              po.causal = false;
              return po;
            }(), 4'000'000));

  const SceneCheck check = check_scene(s);
  ASSERT_EQ(check.imus.size(), 1u);
  EXPECT_TRUE(check.imus[0].causal);
  EXPECT_EQ(check.max_emission_delay_ns, 6'000'000);
  const std::string text = to_text(check);
  EXPECT_NE(text.find("causal Hermite"), std::string::npos) << text;
  EXPECT_NE(text.find("look-ahead 4.0 ms (one pose interval), emitted 6.0 ms after the pose"), std::string::npos) << text;
  // (2 pi 1 Hz 4 ms)^2 / 12 = 5.26e-5.
  EXPECT_NE(text.find("acceleration error <= 5.3e-05 (poses with rates)"), std::string::npos) << text;
  EXPECT_NE(to_json(check).find("\"method\": \"causal-hermite\""), std::string::npos);
}

TEST(LatencyPlan, ABudgetAboveTheLookaheadKeepsTheSmoothingMethod) {
  const SceneConfig s = parse_scene_text(scene_text("udp:127.0.0.1:5005", 0.02, "latency_budget_ms = 500"), "t.toml", ".");
  const LatencyPlan plan = latency_plan(s, s.imus[0]);
  EXPECT_FALSE(plan.causal);
  EXPECT_EQ(plan.emission_delay_ns, 500'000'000);
  EXPECT_EQ(plan.producer_lead_ns, 20'000'000);
  EXPECT_FALSE(pipeline_options(s, s.imus[0]).causal);
  // Without a budget: look-ahead + margin, as before.
  const SceneConfig d = parse_scene_text(scene_text("udp:127.0.0.1:5005", 0.02, "margin_s = 0.05"), "t.toml", ".");
  const LatencyPlan old = latency_plan(d, d.imus[0]);
  EXPECT_FALSE(old.causal);
  EXPECT_EQ(old.emission_delay_ns, old.smoothing_lookahead_ns + 50'000'000);
}

TEST(LatencyPlan, BudgetAndMarginTogetherAreRefused) {
  try {
    parse_scene_text(scene_text("udp:127.0.0.1:5005", 0.004, "latency_budget_ms = 6\nmargin_s = 0.01"), "t.toml", ".");
    ADD_FAILURE() << "accepted";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("latency_budget_ms"), std::string::npos) << e.what();
  }
  EXPECT_ANY_THROW(parse_scene_text(scene_text("udp:127.0.0.1:5005", 0.004, "latency_budget_ms = 0.5"), "t.toml", "."));
}

}  // namespace
}  // namespace imuemu::scene
}  // namespace unity_scene_test_latency_plan
