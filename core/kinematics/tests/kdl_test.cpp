// Cross-check of our forward kinematics against Orocos KDL (liborocos-kdl-dev) chains built from
// the same DH parameters / SCARA geometry, for random joint vectors (inside and outside limits).

#include <random>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <kdl/chainfksolverpos_recursive.hpp>

#include "cell/geometry/pose.hpp"
#include "cell/testing/matchers.hpp"
#include "cell/testing/tolerances.hpp"
#include "support/kdl_chains.hpp"
#include "support/test_robots.hpp"

namespace cell::kinematics {
namespace {

using ::cell::testing::IsNearPose;

constexpr int kKdlSamples = 2000;
using ::cell::testing::kTolMm;

TEST(KdlCrossCheck, ExcaliburForwardMatchesTheDhChain) {
  const auto robot = test::load_shipped("excalibur");
  ASSERT_TRUE(robot) << robot.error().message;
  ExcaliburModel m = *robot->excalibur();
  m.flange_T_tool = geometry::make_pose({5.0, 10.0, 60.0}, {.roll = 0.2, .yaw = -0.4});
  const KDL::Chain chain = peer::excalibur_chain(m);
  ASSERT_EQ(chain.getNrOfJoints(), 6u);
  KDL::ChainFkSolverPos_recursive fk(chain);
  std::mt19937_64 rng(61);
  std::uniform_real_distribution<double> angle(-4.0, 4.0);
  for (int n = 0; n < kKdlSamples; ++n) {
    ExcaliburJoints q;
    for (int i = 0; i < 6; ++i) {
      q(i) = angle(rng);
    }
    KDL::Frame f;
    ASSERT_GE(fk.JntToCart(peer::excalibur_kdl_joints(q), f), 0);
    ASSERT_THAT(forward(m, q), IsNearPose(peer::from_kdl(f), kTolMm)) << q.transpose();
  }
}

TEST(KdlCrossCheck, ScaraForwardMatchesTheChainForBothRobots) {
  for (const char* name : {"ibm7545", "scara_picker"}) {
    SCOPED_TRACE(name);
    const auto robot = test::load_shipped(name);
    ASSERT_TRUE(robot) << robot.error().message;
    ScaraModel m = *robot->scara();
    m.flange_T_tool = geometry::make_pose({30.0, -5.0, -40.0}, {.roll = 3.0});
    const KDL::Chain chain = peer::scara_chain(m);
    KDL::ChainFkSolverPos_recursive fk(chain);
    std::mt19937_64 rng(7);
    std::uniform_real_distribution<double> angle(-4.0, 4.0);
    std::uniform_real_distribution<double> stroke(-50.0, 300.0);
    for (int n = 0; n < kKdlSamples; ++n) {
      const ScaraJoints q(angle(rng), angle(rng), stroke(rng), angle(rng));
      KDL::Frame f;
      ASSERT_GE(fk.JntToCart(peer::scara_kdl_joints(m, q), f), 0);
      ASSERT_THAT(forward(m, q), IsNearPose(peer::from_kdl(f), kTolMm)) << q.transpose();
    }
  }
}

}  // namespace
}  // namespace cell::kinematics
