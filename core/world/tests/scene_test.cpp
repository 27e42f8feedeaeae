// Scene files: the shipped scenes load, and bad scenes are refused with file:line:col.
#include "cell/world/scene.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <numbers>
#include <vector>

#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"
#include "cell/world/world.hpp"

namespace cell::world {
namespace {

using ::cell::testing::IsErr;
using ::cell::testing::IsErrWith;
using ::cell::testing::IsOk;
using ::testing::AllOf;
using ::testing::HasSubstr;
using ::testing::Not;

Result<World> build(const std::string& text) {
  const Catalogue cat = Catalogue::standard();
  auto scene = parse_scene(text, "scene.yaml", cat);
  if (!scene) {
    return std::move(scene).error();
  }
  return World::create(*scene, cat, WorldOptions{});
}

TEST(Scene, EveryShippedSceneLoadsAndBuilds) {
  const std::string dir = cell::testing::source_dir() + "/config/scenes";
  int count = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    if (entry.path().extension() != ".yaml") {
      continue;
    }
    SCOPED_TRACE(entry.path().string());
    const Catalogue cat = Catalogue::standard();
    auto scene = load_scene_file(entry.path().string(), cat);
    ASSERT_THAT(scene, IsOk());
    auto world = World::create(*scene, cat, WorldOptions{});
    ASSERT_THAT(world, IsOk());
    EXPECT_FALSE(world->parts().empty());
    for (const auto& part : world->parts()) {
      EXPECT_NE(part.support.kind, Support::Kind::kFloor) << part.id << " is on the floor";
    }
    ++count;
  }
  EXPECT_GE(count, 3);
}

// The thesis scene: 15 ICs, all on the table, inside the 7545's image window: 512 x 480 px at
// 3.56 x 3.48 px/mm, about 144 x 138 mm, centred on (134.39, 501.25) mm with its i axis along
// link 2 (150 deg at the grab pose J1 + J2 = 45 + 105 deg), digest 000 §4, §7, §9.2.
TEST(Scene, TheThesisTableHasFifteenIcsInTheImageWindow) {
  const Catalogue cat = Catalogue::standard();
  auto scene = load_scene_file(cell::testing::source_dir() + "/config/scenes/table_ics.yaml", cat);
  ASSERT_THAT(scene, IsOk());
  auto world = World::create(*scene, cat, WorldOptions{});
  ASSERT_THAT(world, IsOk());
  ASSERT_EQ(world->parts().size(), 15U);
  const Eigen::Vector2d centre(134.39, 501.25);  // digest 000 §9.2 case 9
  const double a = 150.0 * std::numbers::pi / 180.0;
  const Eigen::Vector2d i_axis(std::cos(a), std::sin(a));
  const Eigen::Vector2d j_axis(-std::sin(a), std::cos(a));
  constexpr double kMarginMm = 2.0;
  for (const auto& part : world->parts()) {
    SCOPED_TRACE(part.id);
    EXPECT_EQ(part.support_name, "table");
    EXPECT_EQ(part.cls->shape, Shape::kDip);
    EXPECT_DOUBLE_EQ(part.world_T_part.translation().z(), 750.0);
    for (const auto& p : part.footprint.points) {
      EXPECT_LT(std::abs((p - centre).dot(i_axis)), 512 / 3.56 / 2 - kMarginMm);
      EXPECT_LT(std::abs((p - centre).dot(j_axis)), 480 / 3.48 / 2 - kMarginMm);
    }
  }
}

TEST(Scene, AnUnknownClassIsRefusedWithFileLineAndTheKnownClasses) {
  const std::string text =
      "table: {height_mm: 750}\n"
      "parts:\n"
      "  - {id: a, class: dip14, x_mm: 100, y_mm: 100}\n"
      "  - {id: b, class: dip15, x_mm: 200, y_mm: 100}\n";
  const auto scene = parse_scene(text, "scene.yaml", Catalogue::standard());
  EXPECT_THAT(scene, IsErrWith(Errc::kConfig, "scene.yaml:4:"));
  EXPECT_THAT(scene, IsErrWith(Errc::kConfig, "unknown part class 'dip15'"));
  EXPECT_THAT(scene, IsErrWith(Errc::kConfig, "dip14"));
}

TEST(Scene, OverlappingPartsAreRefusedNamingBothAndTheirLines) {
  const auto world = build(
      "table: {height_mm: 750}\n"
      "parts:\n"
      "  - {id: a, class: dip14, x_mm: 100, y_mm: 100}\n"
      "  - {id: b, class: dip14, x_mm: 105, y_mm: 101, yaw_deg: 30}\n"
      "  - {id: c, class: dip14, x_mm: 300, y_mm: 100}\n");
  EXPECT_THAT(world, IsErrWith(Errc::kConfig,
                               "scene.yaml:4:5: part 'b' (dip14) overlaps part "
                               "'a' (dip14, declared at scene.yaml:3:5)"));
  EXPECT_THAT(world, Not(IsErrWith(Errc::kConfig, "'c'")));
}

TEST(Scene, PartsCloserThanTheMinimumSeparationAreRefused) {
  // dip14 bodies are 6.35 wide, leads 7.87: centres 10 mm apart leave 2.13 mm.
  const std::string parts =
      "parts:\n"
      "  - {id: a, class: dip14, x_mm: 100, y_mm: 100}\n"
      "  - {id: b, class: dip14, x_mm: 100, y_mm: 110}\n";
  EXPECT_THAT(build("min_separation_mm: 2\n" + parts), IsOk());
  EXPECT_THAT(build("min_separation_mm: 5.7\n" + parts),
              IsErrWith(Errc::kConfig,
                        "scene.yaml:4:5: part 'b' (dip14) is 2.13 mm from part 'a' "
                        "(dip14, declared at scene.yaml:3:5), closer than "
                        "min_separation_mm 5.7"));
}

TEST(Scene, PartsOnDifferentSupportsDoNotConflict) {
  // A part on the belt and one on the table at the same x-y (the belt passes over the table).
  EXPECT_THAT(build("belts:\n"
                    "  - {id: b1, origin_mm: [0, 0, 900], length_mm: 500, width_mm: 100,\n"
                    "     mm_per_count: 0.1}\n"
                    "parts:\n"
                    "  - {id: a, class: dip14, x_mm: 100, y_mm: 0}\n"
                    "  - {id: b, class: dip14, pose: {xyz_mm: [100, 0, 750]}}\n"),
              IsOk());
}

TEST(Scene, UnknownKeysAndBadValuesAreAllReported) {
  const auto scene = parse_scene(
      "table: {height_mm: 750, colour: white}\n"
      "belts:\n"
      "  - {id: b1, origin_mm: [0, 0, 800], length_mm: 500, width_mm: 100, mm_per_count: 0.1,\n"
      "     photocell_at_mm: 600}\n"
      "parts:\n"
      "  - {id: a, class: dip14, x_mm: 100}\n"
      "  - {id: a, class: dip14, x_mm: 100, y_mm: 5}\n",
      "scene.yaml", Catalogue::standard());
  ASSERT_THAT(scene, IsErr(Errc::kConfig));
  const std::string& m = scene.error().message;
  EXPECT_THAT(m, HasSubstr("scene.yaml:1:"));
  EXPECT_THAT(m, HasSubstr("colour"));
  EXPECT_THAT(m, HasSubstr("scene.yaml:3:5: belt 'b1': photocell_at_mm must be in [0, "
                           "length_mm = 500], got 600"));
  EXPECT_THAT(m, HasSubstr("missing required key 'parts[0].y_mm'"));
  EXPECT_THAT(m, HasSubstr("part id 'a' is used twice"));
}

// Digest 002 §6.2 T9: 1024 ppr on a 50 mm roller with x4 decoding = 0.03835 mm per count.
TEST(Scene, BeltEncoderScaleFromTheRoller) {
  const auto scene = parse_scene(
      "belts:\n"
      "  - {id: b1, origin_mm: [0, 0, 760], length_mm: 1000, width_mm: 200, counts_per_rev: 1024,\n"
      "     roller_diameter_mm: 50, quadrature: 4, direction_deg: -90}\n",
      "scene.yaml", Catalogue::standard());
  ASSERT_THAT(scene, IsOk());
  ASSERT_EQ(scene->belts.size(), 1U);
  EXPECT_NEAR(scene->belts[0].mm_per_count, 0.03835, 5e-6);
  EXPECT_TRUE(scene->belts[0].direction().isApprox(Eigen::Vector3d(0, -1, 0), 1e-12));
  const auto both = parse_scene(
      "belts:\n"
      "  - {id: b1, origin_mm: [0, 0, 760], length_mm: 1000, width_mm: 200, mm_per_count: 0.1,\n"
      "     counts_per_rev: 1024, roller_diameter_mm: 50}\n",
      "scene.yaml", Catalogue::standard());
  EXPECT_THAT(both, IsErrWith(Errc::kConfig, "give either mm_per_count, or counts_per_rev"));
}

TEST(Scene, SceneClassesAreUsable) {
  const auto world = build(
      "classes:\n"
      "  - {name: washer, shape: disc, length_mm: 12, height_mm: 1.5, reflectance: 0.7}\n"
      "  - {name: chip, shape: dip, pins: 8, length_mm: 10, width_mm: 6.5}\n"
      "  - {name: wedge, shape: polyhedron, mesh: {vertices_mm: [[0,0,0],[10,0,0],[0,10,0],"
      "[0,0,10]], faces: [[0,2,1],[0,1,3],[0,3,2],[1,2,3]]}}\n"
      "parts:\n"
      "  - {class: washer, x_mm: 0, y_mm: 100}\n"
      "  - {class: chip, x_mm: 50, y_mm: 100}\n"
      "  - {class: wedge, x_mm: 100, y_mm: 100}\n");
  ASSERT_THAT(world, IsOk());
  ASSERT_EQ(world->parts().size(), 3U);
  EXPECT_EQ(world->parts()[0].id, "p1");
  EXPECT_DOUBLE_EQ(world->parts()[0].cls->width_mm, 12.0);
  EXPECT_EQ(world->parts()[1].cls->dip.pins, 8);
  EXPECT_DOUBLE_EQ(world->parts()[2].cls->height_mm, 10.0);
}

TEST(Scene, BadClassesAreRefused) {
  const auto scene = parse_scene(
      "classes:\n"
      "  - {name: dip14, shape: rectangle, length_mm: 1, width_mm: 1, height_mm: 1}\n"
      "  - {name: blob, shape: circle, length_mm: 1}\n"
      "  - {name: open, shape: polyhedron, mesh: {vertices_mm: [[0,0,0],[10,0,0],[0,10,0],"
      "[0,0,10]], faces: [[0,2,1],[0,1,3],[0,3,2]]}}\n",
      "scene.yaml", Catalogue::standard());
  ASSERT_THAT(scene, IsErr(Errc::kConfig));
  EXPECT_THAT(scene.error().message, HasSubstr("class 'dip14' is already in the catalogue"));
  EXPECT_THAT(scene.error().message, HasSubstr("scene.yaml:3:"));
  EXPECT_THAT(scene.error().message, HasSubstr("unknown shape 'circle'"));
  EXPECT_THAT(scene.error().message, HasSubstr("scene.yaml:4:"));
  EXPECT_THAT(scene.error().message, HasSubstr("at least 4 vertices and 4 faces"));
  EXPECT_THAT(scene.error().message, Not(HasSubstr("unknown key")));
}

TEST(Scene, GraspYawsAreReadInDegrees) {
  const auto scene = parse_scene(
      "classes:\n"
      "  - {name: chip, shape: dip, pins: 8, length_mm: 10, width_mm: 6.5, grasp_yaws_deg: [0]}\n"
      "  - {name: tile, shape: square, length_mm: 10, height_mm: 2, grasp_yaws_deg: [0, 45]}\n"
      "  - {name: plate, shape: rectangle, length_mm: 10, width_mm: 5, height_mm: 2}\n",
      "scene.yaml", Catalogue::standard());
  ASSERT_THAT(scene, IsOk());
  ASSERT_EQ(scene->classes.size(), 3U);
  EXPECT_EQ(scene->classes[0].grasp_yaws_rad, std::vector<double>{0.0});
  ASSERT_EQ(scene->classes[1].grasp_yaws_rad.size(), 2U);
  EXPECT_NEAR(scene->classes[1].grasp_yaws_rad[1], std::numbers::pi / 4.0, 1e-15);
  EXPECT_EQ(scene->classes[2].grasp_yaws_rad, (std::vector<double>{0.0, std::numbers::pi / 2.0}));
}

TEST(Scene, BadGraspYawsAreRefusedNamingTheKey) {
  const auto scene = parse_scene(
      "classes:\n"
      "  - {name: a, shape: dip, pins: 8, length_mm: 10, width_mm: 6.5, grasp_yaws_deg: []}\n"
      "  - {name: b, shape: dip, pins: 8, length_mm: 10, width_mm: 6.5, grasp_yaws_deg: [0, x]}\n"
      "  - {name: c, shape: dip, pins: 8, length_mm: 10, width_mm: 6.5, grasp_yaws_deg: 90}\n",
      "scene.yaml", Catalogue::standard());
  ASSERT_THAT(scene, IsErr(Errc::kConfig));
  const std::string& m = scene.error().message;
  EXPECT_THAT(m, HasSubstr("scene.yaml:2:"));
  EXPECT_THAT(m, HasSubstr("key 'classes[0].grasp_yaws_deg': must list at least one yaw"));
  EXPECT_THAT(m, HasSubstr("scene.yaml:3:"));
  EXPECT_THAT(m, HasSubstr("key 'classes[1].grasp_yaws_deg[1]': expected a finite number"));
  EXPECT_THAT(m, HasSubstr("scene.yaml:4:"));
  EXPECT_THAT(m, HasSubstr("key 'classes[2].grasp_yaws_deg': expected a list"));
  EXPECT_THAT(m, Not(HasSubstr("grasp_yaws_rad")));  // one error per bad key, not two
  EXPECT_THAT(m, Not(HasSubstr("unknown key")));
}

TEST(Scene, AMissingFileOrBrokenYamlSaysWhere) {
  EXPECT_THAT(load_scene_file("/nonexistent/scene.yaml", Catalogue::standard()),
              IsErrWith(Errc::kConfig, "/nonexistent/scene.yaml: cannot open"));
  EXPECT_THAT(parse_scene("parts: [\n  {class: dip14\n", "scene.yaml", Catalogue::standard()),
              IsErrWith(Errc::kConfig, "scene.yaml:"));
}

TEST(Scene, AScatterThatCannotFitSaysHowFarItGot) {
  const auto world = build(
      "scatter:\n"
      "  - {count: 50, classes: [dip40], x_mm: [0, 60], y_mm: [0, 60], min_separation_mm: 5,\n"
      "     max_attempts_per_part: 50}\n");
  EXPECT_THAT(world, IsErrWith(Errc::kConfig, "scene.yaml:2:5: scatter: placed"));
  EXPECT_THAT(world, IsErrWith(Errc::kConfig, "of 50 parts"));
}

}  // namespace
}  // namespace cell::world
