// cellctl world ... against an in-process cell-sim-world on a private bus.
#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>

#include "cell/testing/env.hpp"
#include "cell/testing/service_harness.hpp"
#include "cli_run.hpp"
#include "session.hpp"
#include "sim_world_service.hpp"

namespace cell::cellctl {
namespace {

using nlohmann::json;
using testing::cellctl;
using testing::CliRun;
using ::testing::HasSubstr;

class CellctlWorldTest : public ::testing::Test {
 protected:
  static sim_world::SimWorldConfig config(const std::string& scene) {
    sim_world::SimWorldConfig c;
    c.common.service_id = "sim-world";
    c.scene = cell::testing::source_dir() + "/config/scenes/" + scene;
    c.world.robots = {{"ibm7545", Eigen::Isometry3d(Eigen::Translation3d(0, 0, 981.51))}};
    return c;
  }

  explicit CellctlWorldTest(const std::string& scene = "table_ics.yaml")
      : domain_(cell::testing::test_domain_id()),
        partition_(cell::testing::unique_partition()),
        world_(domain_, partition_, config(scene), "sim-world") {}

  CliRun run(std::vector<std::string> args) {
    std::vector<std::string> all{
        "--domain", std::to_string(domain_), "--partition", partition_, "--timeout", "10"};
    all.insert(all.end(), args.begin(), args.end());
    return cellctl(all);
  }

  /// `cellctl --json world parts`, parsed.
  json parts() {
    const CliRun r = run({"--json", "world", "parts"});
    EXPECT_EQ(r.code, kExitOk) << r.err;
    return json::parse(r.out)["parts"];
  }

  static const json* find(const json& parts, const std::string& id) {
    for (const auto& p : parts) {
      if (p["id"] == id) {
        return &p;
      }
    }
    return nullptr;
  }

  /// A temporary scene file with `text`.
  std::string scene_file(const std::string& text) {
    std::ofstream(scene_path()) << text;
    return scene_path();
  }
  std::string scene_path() const { return ::testing::TempDir() + "/" + partition_ + "_scene.yaml"; }
  ~CellctlWorldTest() override { std::remove(scene_path().c_str()); }

  std::uint32_t domain_;
  std::string partition_;
  cell::testing::ServiceHarness<sim_world::SimWorldConfig, sim_world::SimWorldService> world_;
};

TEST_F(CellctlWorldTest, PartsListsEveryPartWithPoseGraspAndSupport) {
  const json list = parts();
  ASSERT_EQ(list.size(), 15U);
  const json* ic8 = find(list, "ic8");
  ASSERT_NE(ic8, nullptr);
  EXPECT_EQ((*ic8)["class"], "dip20");
  EXPECT_EQ((*ic8)["support"], "table");
  EXPECT_NEAR((*ic8)["pose"]["x_mm"].get<double>(), 134.39, 1e-6);
  EXPECT_NEAR((*ic8)["pose"]["y_mm"].get<double>(), 501.25, 1e-6);
  EXPECT_NEAR((*ic8)["pose"]["z_mm"].get<double>(), 750.0, 1e-6);
  EXPECT_NEAR((*ic8)["pose"]["yaw_deg"].get<double>(), -116.0, 1e-6);
  EXPECT_NEAR((*ic8)["grasp"]["z_mm"].get<double>(), 753.81, 1e-6);
  EXPECT_EQ((*ic8)["pins"], 20);
  // The table for people.
  const CliRun r = run({"world", "parts"});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  EXPECT_THAT(r.out, HasSubstr("yaw [deg]"));
  EXPECT_THAT(r.out, HasSubstr("ic8"));
  EXPECT_THAT(r.out, HasSubstr("134.39"));
}

TEST_F(CellctlWorldTest, ResetWithABadSceneNamesTheFileLineAndKeepsTheWorld) {
  const std::string bad = scene_file(
      "table: {height_mm: 750}\n"
      "parts:\n"
      "  - {id: a, class: dip14, x_mm: 0, y_mm: 300}\n"
      "  - {id: b, class: dip14, x_mm: 2, y_mm: 301}\n");
  CliRun r = run({"world", "reset", "--scene", bad});
  EXPECT_EQ(r.code, kExitFailure);
  EXPECT_THAT(r.err, HasSubstr(bad + ":4:5: part 'b' (dip14) overlaps part 'a'"));
  EXPECT_EQ(parts().size(), 15U);
  const std::string good = scene_file(
      "table: {height_mm: 750}\n"
      "parts:\n"
      "  - {id: a, class: dip14, x_mm: 0, y_mm: 300}\n");
  r = run({"--json", "world", "reset", "--scene", good});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  EXPECT_EQ(json::parse(r.out)["parts"].size(), 1U);
  EXPECT_EQ(parts().size(), 1U);
  r = run({"world", "reset", "--scene", "/nonexistent/scene.yaml"});
  EXPECT_EQ(r.code, kExitUsage);
  EXPECT_THAT(r.err, HasSubstr("--scene /nonexistent/scene.yaml: cannot open"));
  r = run({"world", "reset"});  // back to the configured scene
  ASSERT_EQ(r.code, kExitOk) << r.err;
  EXPECT_EQ(parts().size(), 15U);
}

TEST_F(CellctlWorldTest, SpawnRemoveAndScatter) {
  CliRun r =
      run({"--json", "world", "spawn", "--class", "dip14", "--pose", "-300,0,30", "--id", "s1"});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  const json spawned = json::parse(r.out)["parts"];
  ASSERT_EQ(spawned.size(), 1U);
  EXPECT_EQ(spawned[0]["id"], "s1");
  EXPECT_NEAR(spawned[0]["pose"]["yaw_deg"].get<double>(), 30.0, 1e-9);
  EXPECT_NEAR(spawned[0]["pose"]["z_mm"].get<double>(), 750.0, 1e-9);
  ASSERT_NE(find(parts(), "s1"), nullptr);
  r = run({"world", "spawn", "--class", "dip14", "--pose", "-300,1,0"});
  EXPECT_EQ(r.code, kExitFailure);
  EXPECT_THAT(r.err, HasSubstr("overlaps part 's1'"));
  r = run({"world", "spawn", "--class", "dip99", "--pose", "-300,100,0"});
  EXPECT_EQ(r.code, kExitFailure);
  EXPECT_THAT(r.err, HasSubstr("unknown part class 'dip99'"));
  r = run({"world", "spawn", "--class", "dip14", "--pose", "-300,100"});
  EXPECT_EQ(r.code, kExitUsage);
  EXPECT_THAT(r.err, HasSubstr("--pose: expected x,y,yaw_deg (3 values), got 2"));
  r = run({"world", "remove", "--id", "s1"});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  EXPECT_EQ(find(parts(), "s1"), nullptr);
  r = run({"world", "remove", "--id", "s1"});
  EXPECT_EQ(r.code, kExitFailure);
  EXPECT_THAT(r.err, HasSubstr("no part 's1'"));
  // Scatter twice from the same state with the same seed: the same parts.
  r = run({"--json", "world", "scatter", "--count", "2", "--classes", "dip8", "--seed", "3"});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  const json first = json::parse(r.out)["parts"];
  ASSERT_EQ(first.size(), 2U);
  for (const auto& p : first) {
    ASSERT_EQ(run({"world", "remove", "--id", p["id"].get<std::string>()}).code, kExitOk);
  }
  r = run({"--json", "world", "scatter", "--count", "2", "--classes", "dip8", "--seed", "3"});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  const json second = json::parse(r.out)["parts"];
  ASSERT_EQ(second.size(), 2U);
  for (std::size_t i = 0; i < 2; ++i) {
    EXPECT_EQ(first[i]["pose"], second[i]["pose"]);
  }
  r = run({"world", "scatter", "--count", "0"});
  EXPECT_EQ(r.code, kExitUsage);
  r = run({"world", "scatter", "--count", "2", "--classes", "dip8,,dip14"});
  EXPECT_EQ(r.code, kExitUsage);
  EXPECT_THAT(r.err, HasSubstr("an empty class name"));
}

TEST_F(CellctlWorldTest, WithoutASimulatorItSaysSo) {
  const CliRun r = cellctl({"--domain", std::to_string(domain_), "--partition",
                            partition_ + "-nobody", "--timeout", "0.5", "world", "parts"});
  EXPECT_EQ(r.code, kExitFailure);
  EXPECT_THAT(r.err, HasSubstr("is sim-world running"));
}

class CellctlWorldBeltTest : public CellctlWorldTest {
 protected:
  CellctlWorldBeltTest() : CellctlWorldTest("belt_conveyor.yaml") {}
};

TEST_F(CellctlWorldBeltTest, BeltSpeedIsSetAndPartsRide) {
  const json before = parts();
  const double y0 = (*find(before, "la1"))["pose"]["y_mm"].get<double>();
  CliRun r = run({"world", "belt", "--id", "belt1", "--speed", "0"});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  EXPECT_THAT(r.out, HasSubstr("belt 'belt1': speed 0.0 mm/s"));
  const double y1 = (*find(parts(), "la1"))["pose"]["y_mm"].get<double>();
  EXPECT_LT(y1, y0);  // it moved toward -y at 100 mm/s until stopped
  EXPECT_EQ((*find(parts(), "la1"))["pose"]["y_mm"].get<double>(), y1);  // and now stays
  r = run({"world", "belt", "--id", "belt9", "--speed", "10"});
  EXPECT_EQ(r.code, kExitFailure);
  EXPECT_THAT(r.err, HasSubstr("no belt 'belt9' in the world (belts: belt1)"));
}

}  // namespace
}  // namespace cell::cellctl
