#include "cell/kinematics/robot_config.hpp"

#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/geometry/angles.hpp"
#include "cell/testing/matchers.hpp"
#include "support/test_robots.hpp"

namespace cell::kinematics {
namespace {

using ::cell::testing::IsErr;
using ::cell::testing::IsErrWith;
using ::cell::testing::IsOk;
using geometry::deg_to_rad;
using ::testing::HasSubstr;

// Line numbers matter: the error tests below point at them.
const std::string kScara =
    "id: test_scara\n"                                                                       // 1
    "kind: scara\n"                                                                          // 2
    "joints:\n"                                                                              // 3
    "  - {name: j1, type: revolute, lower_deg: 0, upper_deg: 200, max_speed_deg_s: 45}\n"    // 4
    "  - {name: j2, type: revolute, lower_deg: 0, upper_deg: 135, max_speed_deg_s: 50}\n"    // 5
    "  - {name: z, type: prismatic, lower_mm: 0, upper_mm: 250, max_speed_mm_s: 100}\n"      // 6
    "  - {name: r, type: revolute, lower_deg: -180, upper_deg: 180, max_speed_deg_s: 70}\n"  // 7
    "scara:\n"                                                                               // 8
    "  link1_mm: 400\n"                                                                      // 9
    "  link2_mm: 250\n";                                                                     // 10

Result<RobotModel> parse(const std::string& text) {
  auto doc = config::load_string(text, "robot.yaml");
  if (!doc) {
    return std::move(doc).error();
  }
  return parse_robot(*doc);
}

std::string replace(std::string text, const std::string& from, const std::string& to) {
  const std::size_t at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  return at == std::string::npos ? text : text.replace(at, from.size(), to);
}

TEST(LoadRobot, ShippedFilesLoad) {
  for (const char* name : {"ibm7545", "scara_picker", "excalibur"}) {
    SCOPED_TRACE(name);
    const auto robot = test::load_shipped(name);
    ASSERT_THAT(robot, IsOk());
    EXPECT_EQ(robot->id(), name);
    EXPECT_FALSE(robot->description().empty());
  }
}

TEST(LoadRobot, Ibm7545ValuesAreConvertedToInternalUnits) {
  const auto robot = test::load_shipped("ibm7545");
  ASSERT_THAT(robot, IsOk());
  const ScaraModel& m = *robot->scara();
  EXPECT_DOUBLE_EQ(m.link1_mm, 400.0);
  EXPECT_DOUBLE_EQ(m.link2_mm, 250.0);
  EXPECT_EQ(m.z_direction, ZDirection::kDown);
  EXPECT_EQ(m.roll_reference, RollReference::kWorld);
  EXPECT_EQ(m.roll_sense, RotationSense::kClockwise);
  EXPECT_NEAR(m.joints[0].upper, deg_to_rad(200.0), 1e-15);
  EXPECT_NEAR(m.joints[0].counts_per_unit, 872.2222 * 180.0 / geometry::kPi, 1e-9);
  EXPECT_DOUBLE_EQ(m.joints[2].counts_per_unit, 380.96);
  ASSERT_TRUE(m.joints[0].overrun_counts.has_value());
  EXPECT_EQ((*m.joints[0].overrun_counts)[0], -4361);
  EXPECT_EQ((*m.joints[0].overrun_counts)[1], 176188);
  ASSERT_TRUE(m.cartesian_limits.y.has_value());
  EXPECT_DOUBLE_EQ(m.cartesian_limits.y->lower, -386.0);
}

TEST(LoadRobot, ExcaliburOffsetsAndGuards) {
  const auto robot = test::load_shipped("excalibur");
  ASSERT_THAT(robot, IsOk());
  const ExcaliburModel& m = *robot->excalibur();
  EXPECT_DOUBLE_EQ(m.a2_mm, 304.8);
  EXPECT_NEAR(m.controller_offset[1], deg_to_rad(30.0), 1e-15);
  EXPECT_NEAR(m.controller_offset[2], deg_to_rad(-150.0), 1e-15);
  EXPECT_EQ(m.wrist_singularity, WristSingularity::kZeroTheta4);
  ASSERT_TRUE(m.cartesian_limits.z.has_value());
  EXPECT_DOUBLE_EQ(m.cartesian_limits.z->lower, 0.0);
  ASSERT_TRUE(m.cartesian_limits.base_guard.has_value());
  EXPECT_DOUBLE_EQ(m.cartesian_limits.base_guard->radius_mm, 120.0);
}

TEST(LoadRobot, MinimalScaraParses) {
  const auto robot = parse(kScara);
  ASSERT_THAT(robot, IsOk());
  EXPECT_EQ(robot->scara()->z_direction, ZDirection::kUp);  // defaults
  EXPECT_EQ(robot->scara()->roll_reference, RollReference::kLink2);
}

TEST(LoadRobot, AccelerationLimitDefaultsToFullSpeedInAQuarterSecond) {
  const auto robot = parse(kScara);
  ASSERT_THAT(robot, IsOk());
  EXPECT_NEAR(robot->joints()[0].max_accel, deg_to_rad(180.0), 1e-12);  // 4 * 45 deg/s
  EXPECT_NEAR(robot->joints()[2].max_accel, 400.0, 1e-12);              // 4 * 100 mm/s
  const auto explicit_accel =
      parse(replace(kScara, "max_speed_mm_s: 100", "max_speed_mm_s: 100, max_accel_mm_s2: 1500"));
  ASSERT_THAT(explicit_accel, IsOk());
  EXPECT_NEAR(explicit_accel->joints()[2].max_accel, 1500.0, 1e-12);
  EXPECT_THAT(
      parse(replace(kScara, "max_speed_deg_s: 70", "max_speed_deg_s: 70, max_accel_deg_s2: -1")),
      IsErrWith(Errc::kConfig, "key 'joints[3].max_accel_deg_s2': must be > 0, got -1"));
}

TEST(LoadRobot, NegativeLinkLengthNamesFileLineAndKey) {
  EXPECT_THAT(
      parse(replace(kScara, "link2_mm: 250", "link2_mm: -250")),
      IsErrWith(Errc::kConfig, "robot.yaml:10:13: key 'scara.link2_mm': must be > 0, got -250"));
}

TEST(LoadRobot, UnknownKeyIsReportedWhereItIs) {
  EXPECT_THAT(parse(kScara + "  link3_mm: 5\n"),
              IsErrWith(Errc::kConfig, "robot.yaml:11:3: unknown key 'scara.link3_mm'"));
}

TEST(LoadRobot, WrongTypeNamesTheKey) {
  EXPECT_THAT(parse(replace(kScara, "link1_mm: 400", "link1_mm: four hundred")),
              IsErrWith(Errc::kConfig,
                        "robot.yaml:9:13: key 'scara.link1_mm': expected a finite number, got "
                        "'four hundred'"));
}

TEST(LoadRobot, JointRulesNameTheJointKey) {
  const auto robot = parse(replace(kScara, "upper_deg: 135", "upper_deg: -5"));
  EXPECT_THAT(robot, IsErrWith(Errc::kConfig, "robot.yaml:5:"));
  EXPECT_THAT(robot,
              IsErrWith(Errc::kConfig,
                        "key 'joints[1].upper_deg': must be greater than lower_deg (0), got -5"));
  EXPECT_THAT(parse(replace(kScara, "max_speed_mm_s: 100", "max_speed_mm_s: 0")),
              IsErrWith(Errc::kConfig, "key 'joints[2].max_speed_mm_s': must be > 0, got 0"));
}

TEST(LoadRobot, JointUnitsFollowTheJointType) {
  // A prismatic joint given in degrees: the degree keys are unknown, the mm keys missing.
  const auto robot =
      parse(replace(kScara, "lower_mm: 0, upper_mm: 250", "lower_deg: 0, upper_deg: 250"));
  EXPECT_THAT(robot, IsErrWith(Errc::kConfig, "unknown key 'joints[2].lower_deg'"));
  EXPECT_THAT(robot, IsErrWith(Errc::kConfig, "missing required key 'joints[2].upper_mm'"));
}

TEST(LoadRobot, JointTypeMustMatchTheKind) {
  const auto robot = parse(
      replace(kScara, "name: z, type: prismatic, lower_mm: 0, upper_mm: 250, max_speed_mm_s: 100",
              "name: z, type: revolute, lower_deg: 0, upper_deg: 250, max_speed_deg_s: 100"));
  EXPECT_THAT(robot,
              IsErrWith(Errc::kConfig,
                        "robot.yaml:6:21: key 'joints[2].type': joint 3 of a scara (J1, J2, Z, R) "
                        "must be prismatic, got revolute"));
}

TEST(LoadRobot, WrongJointCountForTheKind) {
  const auto robot = parse(replace(
      kScara,
      "  - {name: r, type: revolute, lower_deg: -180, upper_deg: 180, max_speed_deg_s: 70}\n", ""));
  EXPECT_THAT(robot,
              IsErrWith(Errc::kConfig, "robot.yaml:4:3: key 'joints': a scara needs 4 joints"));
}

TEST(LoadRobot, UnknownKindAndJointTypeListTheChoices) {
  EXPECT_THAT(parse(replace(kScara, "kind: scara", "kind: puma")),
              IsErrWith(Errc::kConfig,
                        "robot.yaml:2:7: key 'kind': must be scara or excalibur, got 'puma'"));
  EXPECT_THAT(parse(replace(kScara, "type: prismatic", "type: telescopic")),
              IsErrWith(Errc::kConfig,
                        "key 'joints[2].type': must be revolute or prismatic, got 'telescopic'"));
  EXPECT_THAT(
      parse(kScara + "  z_positive: sideways\n"),
      IsErrWith(Errc::kConfig, "key 'scara.z_positive': must be up or down, got 'sideways'"));
}

TEST(LoadRobot, MissingSectionAndSectionOfTheOtherKind) {
  const auto robot = parse(replace(kScara, "kind: scara", "kind: excalibur"));
  EXPECT_THAT(robot, IsErrWith(Errc::kConfig, "missing required section 'excalibur'"));
  EXPECT_THAT(robot, IsErrWith(Errc::kConfig, "unknown key 'scara'"));
}

TEST(LoadRobot, CartesianLimitsAreChecked) {
  EXPECT_THAT(parse(kScara + "cartesian_limits:\n  x_mm: [650, -650]\n"),
              IsErrWith(Errc::kConfig,
                        "robot.yaml:12:9: key 'cartesian_limits.x_mm': must be [lower, upper] with "
                        "lower < upper, got [650, -650]"));
  EXPECT_THAT(parse(kScara + "cartesian_limits:\n  x_mm: [1, 2, 3]\n"),
              IsErrWith(Errc::kConfig, "key 'cartesian_limits.x_mm': expected a list of 2 values"));
}

TEST(LoadRobot, EveryProblemIsReportedAtOnce) {
  std::string text = replace(kScara, "link2_mm: 250", "link2_mm: abc");
  text = replace(text, "max_speed_deg_s: 45", "max_speed_deg: 45");
  const auto robot = parse(text);
  ASSERT_THAT(robot, IsErr(Errc::kConfig));
  EXPECT_THAT(robot.error().message, HasSubstr("key 'scara.link2_mm'"));
  EXPECT_THAT(robot.error().message, HasSubstr("unknown key 'joints[0].max_speed_deg'"));
  EXPECT_THAT(robot.error().message, HasSubstr("missing required key 'joints[0].max_speed_deg_s'"));
}

TEST(LoadRobot, MissingFileNamesThePath) {
  EXPECT_THAT(load_robot("/nonexistent/robot.yaml"),
              IsErrWith(Errc::kConfig, "/nonexistent/robot.yaml: cannot open"));
}

}  // namespace
}  // namespace cell::kinematics
