// FK -> IK -> FK round trips on 10,000 random joint vectors per robot, every branch
// (issue 3 "must hold"). The Cartesian limits and guards are switched off here: they refuse
// targets on purpose and are tested on their own (scara_test, excalibur_test).

#include <cmath>
#include <random>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/geometry/angles.hpp"
#include "cell/geometry/pose.hpp"
#include "cell/kinematics/excalibur.hpp"
#include "cell/kinematics/scara.hpp"
#include "cell/testing/matchers.hpp"
#include "cell/testing/tolerances.hpp"
#include "support/test_robots.hpp"

namespace cell::kinematics {
namespace {

constexpr int kSamples = 10000;
using ::cell::testing::kTolMm;
using ::cell::testing::kTolRad;
constexpr double kSameJointsTol = 1e-7;  // rad or mm: "this branch is the input"

template <typename Joints, std::size_t N>
Joints random_joints(const std::array<JointSpec, N>& joints, std::mt19937_64& rng) {
  Joints q;
  for (std::size_t i = 0; i < N; ++i) {
    std::uniform_real_distribution<double> d(joints[i].lower, joints[i].upper);
    q(static_cast<Eigen::Index>(i)) = d(rng);
  }
  return q;
}

template <typename Joints, std::size_t N>
bool same_joints(const std::array<JointSpec, N>& joints, const JointVector& a, const Joints& b) {
  for (std::size_t i = 0; i < N; ++i) {
    const auto k = static_cast<Eigen::Index>(i);
    const double diff =
        joints[i].type == JointType::kRevolute ? geometry::wrap_to_pi(a(k) - b(k)) : a(k) - b(k);
    if (std::abs(diff) > kSameJointsTol) {
      return false;
    }
  }
  return true;
}

struct Worst {
  double mm = 0.0;
  double rad = 0.0;
  void add(const Eigen::Isometry3d& expected, const Eigen::Isometry3d& actual) {
    mm = std::max(mm, (expected.translation() - actual.translation()).norm());
    rad = std::max(rad, geometry::rotation_distance(expected.linear(), actual.linear()));
  }
};

template <typename Model, typename Joints>
void round_trip(Model model,
                std::size_t branches,
                std::uint64_t seed,
                bool (*regular)(const Model&, const Joints&)) {
  model.cartesian_limits = CartesianLimits{};
  std::mt19937_64 rng(seed);
  Worst worst;
  int checked_identity = 0;
  for (int n = 0; n < kSamples; ++n) {
    const Joints q = random_joints<Joints>(model.joints, rng);
    const Eigen::Isometry3d base_T_tool = forward(model, q);
    const auto all = inverse_all(model, base_T_tool);
    ASSERT_TRUE(all) << "sample " << n << ": " << all.error().message;
    ASSERT_EQ(all->size(), branches);
    bool found_input = false;
    for (const IkSolution& s : *all) {
      ASSERT_TRUE(s.q.allFinite()) << "sample " << n << " " << s.branch;
      const Eigen::Isometry3d back = forward(model, Joints(s.q));
      worst.add(base_T_tool, back);
      found_input = found_input || same_joints(model.joints, s.q, q);
    }
    if (regular(model, q)) {
      ++checked_identity;
      EXPECT_TRUE(found_input) << "sample " << n << ": no branch returns the input joints "
                               << q.transpose();
    }
    if (::testing::Test::HasFailure()) {
      return;
    }
  }
  EXPECT_LE(worst.mm, kTolMm);
  EXPECT_LE(worst.rad, kTolRad);
  EXPECT_GT(checked_identity, kSamples * 9 / 10);
  ::testing::Test::RecordProperty("worst_mm", std::to_string(worst.mm));
  ::testing::Test::RecordProperty("worst_rad", std::to_string(worst.rad));
  std::printf("  %d samples x %zu branches: worst %.3g mm, %.3g rad\n", kSamples, branches,
              worst.mm, worst.rad);
}

bool scara_regular(const ScaraModel&, const ScaraJoints&) { return true; }

// Away from the singular sets, where a branch's joints are not unique.
bool excalibur_regular(const ExcaliburModel& m, const ExcaliburJoints& q) {
  const Eigen::Vector3d w = wrist_centre(m, forward(m, q));
  return std::abs(std::sin(q(4))) > 1e-6 && std::hypot(w.x(), w.y()) > 1e-6;
}

TEST(RoundTrip, Ibm7545EveryBranch) {
  const auto robot = test::load_shipped("ibm7545");
  ASSERT_TRUE(robot) << robot.error().message;
  round_trip<ScaraModel, ScaraJoints>(*robot->scara(), 2, 7545, scara_regular);
}

TEST(RoundTrip, ScaraPickerEveryBranch) {
  const auto robot = test::load_shipped("scara_picker");
  ASSERT_TRUE(robot) << robot.error().message;
  round_trip<ScaraModel, ScaraJoints>(*robot->scara(), 2, 600, scara_regular);
}

TEST(RoundTrip, ExcaliburEveryBranch) {
  const auto robot = test::load_shipped("excalibur");
  ASSERT_TRUE(robot) << robot.error().message;
  round_trip<ExcaliburModel, ExcaliburJoints>(*robot->excalibur(), 8, 1992, excalibur_regular);
}

// The same with a tool offset, which the IK removes before solving.
TEST(RoundTrip, ExcaliburWithAToolEveryBranch) {
  const auto robot = test::load_shipped("excalibur");
  ASSERT_TRUE(robot) << robot.error().message;
  ExcaliburModel m = *robot->excalibur();
  m.flange_T_tool =
      geometry::make_pose({10.0, -20.0, 85.0}, {.roll = 0.3, .pitch = -0.2, .yaw = 1.0});
  round_trip<ExcaliburModel, ExcaliburJoints>(m, 8, 2024, excalibur_regular);
}

}  // namespace
}  // namespace cell::kinematics
