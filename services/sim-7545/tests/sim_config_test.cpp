#include "sim_config.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"

namespace cell::sim7545 {
namespace {

using ::cell::testing::IsErrWith;
using ::testing::HasSubstr;

TEST(SimConfig, TheShippedConfigLoads) {
  auto doc = config::load_file(cell::testing::source_dir() + "/config/sim-7545.yaml");
  ASSERT_TRUE(doc) << doc.error().message;
  auto c = load_config(*doc);
  ASSERT_TRUE(c) << c.error().message;
  EXPECT_EQ(c->shm_name, "/cell-dpr7545");
  EXPECT_EQ(c->state_robot_id, "ibm7545.sim");
  EXPECT_DOUBLE_EQ(c->plants[1].viscous_per_s, 180.0);
}

TEST(SimConfig, ErrorsNameTheKeyTheValueAndTheRule) {
  auto doc = config::load_string(
      "robot_config: x.yaml\nshm_name: no-slash\ndelay_s: -1\ndeadline_slack_us: -5\n"
      "joints: [{viscous_per_s: 1}, {}, {}, {home_edge_counts: 5000}]\n"
      "fault_injection: {enabled: true, colour: red}\n",
      "sim.yaml");
  ASSERT_TRUE(doc);
  auto c = load_config(*doc);
  ASSERT_FALSE(c);
  EXPECT_THAT(c.error().message, HasSubstr("sim.yaml:2:11: key 'shm_name'"));
  EXPECT_THAT(c.error().message, HasSubstr("must start with '/'"));
  EXPECT_THAT(c.error().message, HasSubstr("key 'delay_s': must be in [0, 10], got -1"));
  EXPECT_THAT(c.error().message, HasSubstr("key 'deadline_slack_us': must be in [0, 100000]"));
  EXPECT_THAT(c.error().message, HasSubstr("home_edge_counts"));
  EXPECT_THAT(c.error().message, HasSubstr("unknown key 'fault_injection.colour'"));
}

TEST(SimConfig, JointsNeedFourEntries) {
  auto doc = config::load_string("robot_config: x.yaml\njoints: [{}, {}]\n", "sim.yaml");
  ASSERT_TRUE(doc);
  EXPECT_THAT(load_config(*doc), IsErrWith(Errc::kConfig, "needs 4 entries (J1, J2, Z, R), got 2"));
}

}  // namespace
}  // namespace cell::sim7545
