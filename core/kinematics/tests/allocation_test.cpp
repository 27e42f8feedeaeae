// The analytic IK and FK must not allocate (issue 3: "analytic IK must be allocation-free").
// This test binary replaces the global operator new with a counting one (support/counting_new).

#include <new>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/geometry/angles.hpp"
#include "cell/geometry/pose2.hpp"
#include "support/counting_new.hpp"
#include "support/test_robots.hpp"

namespace cell::kinematics {
namespace {

template <typename Fn>
long allocations_during(Fn&& fn) {
  const long before = test::allocation_count();
  fn();
  return test::allocation_count() - before;
}

TEST(Allocation, CountingAllocatorSeesAllocations) {
  // The counter works (a direct call of the replaceable operator new cannot be elided).
  EXPECT_EQ(allocations_during([] {
              void* volatile p = ::operator new(64);
              ::operator delete(p);
            }),
            1);
}

TEST(Allocation, ExcaliburForwardAndInverseDoNotAllocate) {
  const auto robot = test::load_shipped("excalibur");
  ASSERT_TRUE(robot) << robot.error().message;
  const ExcaliburModel& m = *robot->excalibur();
  ExcaliburJoints q;
  q << 0.5, 1.0, -2.0, 0.3, -0.7, 0.2;
  bool ok = true;
  const long n = allocations_during([&] {
    for (int i = 0; i < 100; ++i) {
      const Eigen::Isometry3d t = forward(m, q);
      const auto all = inverse_all(m, t, q);
      const auto nearest = inverse(m, t, q);
      ok = ok && all.has_value() && nearest.has_value() && all->size() == 8;
    }
  });
  EXPECT_TRUE(ok);
  EXPECT_EQ(n, 0);
}

TEST(Allocation, ScaraForwardAndInverseDoNotAllocate) {
  const auto robot = test::load_shipped("ibm7545");
  ASSERT_TRUE(robot) << robot.error().message;
  const ScaraModel& m = *robot->scara();
  const ScaraJoints q(1.0, 1.2, 100.0, 0.3);
  bool ok = true;
  const long n = allocations_during([&] {
    for (int i = 0; i < 100; ++i) {
      const Eigen::Isometry3d t = forward(m, q);
      const auto all = inverse_all(m, t);
      const auto one = inverse(m, t, ElbowBranch::kJ2Positive);
      const auto nearest = inverse(m, t, q);
      ok = ok && all.has_value() && one.has_value() && nearest.has_value();
    }
  });
  EXPECT_TRUE(ok);
  EXPECT_EQ(n, 0);
}

TEST(Allocation, GenericRobotModelDoesNotAllocateOnSuccess) {
  const auto robot = test::load_shipped("excalibur");
  ASSERT_TRUE(robot) << robot.error().message;
  JointVector q(6);
  q << 0.5, 1.0, -2.0, 0.3, -0.7, 0.2;
  bool ok = true;
  const long n = allocations_during([&] {
    for (int i = 0; i < 100; ++i) {
      const auto t = robot->forward(q);
      const auto back = robot->inverse(*t, q);
      ok = ok && t.has_value() && back.has_value();
    }
  });
  EXPECT_TRUE(ok);
  EXPECT_EQ(n, 0);
}

}  // namespace
}  // namespace cell::kinematics
