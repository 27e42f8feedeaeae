#include "task_config.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"

namespace cell::task_service {
namespace {

using ::cell::testing::IsOk;
using ::testing::HasSubstr;

Result<TaskConfig> parse(const std::string& text) {
  auto doc = config::load_string(text, "task.yaml");
  if (!doc) {
    return std::move(doc).error();
  }
  return load_config(*doc);
}

TEST(TaskConfig, TheShippedConfigLoads) {
  auto doc = config::load_file(cell::testing::source_dir() + "/config/task.yaml");
  ASSERT_THAT(doc, IsOk());
  auto c = load_config(*doc);
  ASSERT_THAT(c, IsOk());
  EXPECT_EQ(c->robots.size(), 3U);
  ASSERT_EQ(c->belts.size(), 1U);
  EXPECT_NEAR(c->belts[0].direction.y(), -1.0, 1e-12);
  EXPECT_EQ(c->robots[1].gateway, "gateway.picker");
  EXPECT_EQ(c->cameras[0].service, "camera.ibm7545_eye");
  EXPECT_EQ(c->motion_service, "motion");
}

TEST(TaskConfig, WatchedServicesDefaultFromTheIds) {
  auto c = parse("robots:\n  - {id: r, config: x.yaml}\ncameras:\n  - {id: c, robot: r, "
                 "working_plane_z_mm: 0}\n");
  ASSERT_THAT(c, IsOk());
  EXPECT_EQ(c->robots[0].gateway, "gateway.r");
  EXPECT_EQ(c->cameras[0].service, "camera.c");
  EXPECT_EQ(c->motion_service, "motion");
  EXPECT_EQ(c->vision_service, "vision");
  auto bad = parse("robots:\n  - {id: r, config: x.yaml}\nservices: {motion: ''}\n");
  ASSERT_FALSE(bad);
  EXPECT_THAT(bad.error().message, HasSubstr("services.motion"));
}

TEST(TaskConfig, ErrorsNameTheLineAndTheKey) {
  auto c = parse(
      "robots:\n  - {id: r, config: x.yaml}\ncameras:\n  - {id: c, robot: q, "
      "working_plane_z_mm: 0}\nbelts:\n  - {id: b, robot: r, mm_per_count: -1, direction: "
      "[0, 0, 0], nearest_mm: [0, 0, 0]}\ntimeouts: {motion_s: 0}\nfoo: 1\n");
  ASSERT_FALSE(c);
  const std::string& m = c.error().message;
  EXPECT_THAT(m, HasSubstr("task.yaml:4:"));
  EXPECT_THAT(m, HasSubstr("robot 'q' is not in robots"));
  EXPECT_THAT(m, HasSubstr("mm_per_count"));
  EXPECT_THAT(m, HasSubstr("non-zero vector"));
  EXPECT_THAT(m, HasSubstr("motion_s"));
  EXPECT_THAT(m, HasSubstr("foo"));
}

}  // namespace
}  // namespace cell::task_service
