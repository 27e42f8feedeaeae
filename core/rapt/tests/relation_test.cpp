#include "cell/rapt/relation.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <random>

#include "cell/rapt/rule_tables.hpp"
#include "cell/testing/matchers.hpp"
#include "cell/testing/tolerances.hpp"

namespace cell::rapt {
namespace {

using ::cell::testing::IsNearPose;
using Eigen::Vector3d;

using ::cell::testing::kTolMm;
const Tolerances kTolerances{1e-6, 1e-9};

/// A feature frame with origin o and X axis x.
Pose feat(const Vector3d& o, const Vector3d& x) { return frame_from_x(o, x.normalized()); }

Relation rel(RelType type, const Pose& fa, const Pose& fb, double offset = 0.0) {
  Relation r;
  r.type = type;
  r.a = 0;
  r.b = 1;
  r.a_T_fa = fa;
  r.b_T_fb = fb;
  r.offset = offset;
  return r;
}

// Appendix I as printed: 45 combination rules, 33 creation rules; spot-check rows.
TEST(RuleTables, HoldAppendixIAsPrinted) {
  EXPECT_EQ(combination_table().size(), 45U);
  EXPECT_EQ(creation_table().size(), 33U);
  const RuleEntry* agpp_fits = combination_rule(RelType::kFits, RelType::kAgpp);  // any order
  ASSERT_NE(agpp_fits, nullptr);
  EXPECT_EQ(agpp_fits->general->type, RelType::kFix);
  EXPECT_TRUE(agpp_fits->admits(RelType::kRot));
  EXPECT_TRUE(agpp_fits->admits(RelType::kLin));
  EXPECT_FALSE(agpp_fits->admits(RelType::kAgpp));
  const RuleEntry* agpp_agpc = combination_rule(RelType::kAgpp, RelType::kAgpc);
  EXPECT_TRUE(agpp_agpc->two_solutions);
  EXPECT_TRUE(agpp_agpc->special_rotylin);
  EXPECT_FALSE(combination_rule(RelType::kAgpc, RelType::kAgpc)->general.has_value());
  EXPECT_EQ(combination_rule(RelType::kFix, RelType::kAgpp), nullptr);
  const RuleEntry* lin_lin = creation_rule(RelType::kLin, RelType::kLin);
  EXPECT_EQ(lin_lin->general->type, RelType::kLinlin);
  EXPECT_TRUE(creation_rule(RelType::kLinlin, RelType::kLinlin)->general->looser);  // PARAX*
  // Table 6.2.
  EXPECT_EQ(symbolic_rule(RelType::kAgpp, SymbolicInput::kAgpp, true)->result, RelType::kAgpp);
  EXPECT_EQ(symbolic_rule(RelType::kAgpp, SymbolicInput::kAgpp, false)->result, RelType::kLin);
  EXPECT_EQ(symbolic_rule(RelType::kAgpp, SymbolicInput::kAgpe, false)->result, RelType::kLin);
  EXPECT_EQ(symbolic_rule(RelType::kLin, SymbolicInput::kAgpe, false)->result, RelType::kFix);
  EXPECT_EQ(symbolic_rule(RelType::kFix, SymbolicInput::kAgpe, false), nullptr);
  EXPECT_EQ(dof(RelType::kAgpc).translational, 2);
  EXPECT_EQ(dof(RelType::kAgpc).rotational, 2);
}

// A unit box (body B) on a table (body A): bottom face z=0 normal -z, side x=0 normal -x.
struct Box {
  Pose table_top = feat({0, 0, 0}, {0, 0, 1});
  Pose wall = feat({0, 0, 0}, {1, 0, 0});
  Pose wall2 = feat({0, 0, 0}, {0, 1, 0});
  Pose bottom = feat({0, 0, 0}, {0, 0, -1});
  Pose side = feat({0, 0, 0}, {-1, 0, 0});
  Pose side2 = feat({0, 0, 0}, {0, -1, 0});
};

TEST(Combination, TwoFacePairsGiveALinAlongTheirCommonLine) {
  const Box b;
  const auto r = intersect(rel(RelType::kAgpp, b.table_top, b.bottom),
                           rel(RelType::kAgpp, b.wall, b.side), kTolerances);
  ASSERT_EQ(r.outcome, Outcome::kOk) << r.detail;
  EXPECT_EQ(r.relation.type, RelType::kLin);
  EXPECT_TRUE(parallel(r.relation.a_T_fa.linear().col(0), Vector3d::UnitY(), 1e-12));
  // A third pair fixes it (Table 1: AGPP+LIN -> FIX) at the identity.
  const auto fix = intersect(r.relation, rel(RelType::kAgpp, b.wall2, b.side2), kTolerances);
  ASSERT_EQ(fix.outcome, Outcome::kOk);
  EXPECT_EQ(fix.relation.type, RelType::kFix);
  EXPECT_THAT(fixed_pose(fix.relation), IsNearPose(Pose::Identity(), kTolMm));
}

TEST(Combination, ParallelFacePairsAreTheSpecialCaseAgppOrIncompatible) {
  const Box b;
  const Pose top = feat({0, 0, 10}, {0, 0, 1});
  const Pose lid = feat({0, 0, 10}, {0, 0, -1});
  const auto same =
      intersect(rel(RelType::kAgpp, b.table_top, b.bottom), rel(RelType::kAgpp, top, lid), kTolerances);
  ASSERT_EQ(same.outcome, Outcome::kOk) << same.detail;
  EXPECT_EQ(same.relation.type, RelType::kAgpp);
  const Pose lid_off = feat({0, 0, 12}, {0, 0, -1});
  const auto bad = intersect(rel(RelType::kAgpp, b.table_top, b.bottom),
                             rel(RelType::kAgpp, top, lid_off), kTolerances);
  EXPECT_EQ(bad.outcome, Outcome::kIncompatible);
  EXPECT_NEAR(bad.residual_mm, 2.0, 1e-9);
}

// Thesis §3.3.3.3: AGPP+FITS gives FIX in general, ROT when the X axes of one body's features
// are parallel.
TEST(Combination, FaceAndFitsGiveRotWhenTheAxisIsAlongTheNormal) {
  const Pose hole = feat({5, 5, 0}, {0, 0, 1});    // body A: hole axis out of the table
  const Pose shaft = feat({0, 0, 0}, {0, 0, -1});  // body B: shaft pointing down
  const Box b;
  const auto r =
      intersect(rel(RelType::kFits, hole, shaft), rel(RelType::kAgpp, b.table_top, b.bottom), kTolerances);
  ASSERT_EQ(r.outcome, Outcome::kOk) << r.detail;
  EXPECT_EQ(r.relation.type, RelType::kRot);
  // The rotation axis is the hole axis through (5,5,0).
  EXPECT_TRUE(r.relation.a_T_fa.translation().head<2>().isApprox(Eigen::Vector2d(5, 5), 1e-12));
  // + PARAX fixes the angle (Table 1: PARAX+ROT -> FIX).
  const auto fix = intersect(r.relation, rel(RelType::kParax, b.wall, b.wall), kTolerances);
  ASSERT_EQ(fix.outcome, Outcome::kOk) << fix.detail;
  EXPECT_EQ(fix.relation.type, RelType::kFix);
  const Pose x = fixed_pose(fix.relation);
  EXPECT_TRUE(x.translation().isApprox(Vector3d(5, 5, 0), 1e-9));
  EXPECT_TRUE((x.linear() * Vector3d::UnitX()).isApprox(-Vector3d::UnitX(), 1e-9));
}

TEST(Combination, FaceAndCylinderHasTwoSolutionsAndTwoCylindersNoRule) {
  const Box b;
  const Pose rail = feat({0, 0, 0}, {1, 0, 0});  // a plane of A with normal x
  const Pose edge = feat({0, 0, 0}, {0, 1, 1});  // an edge of B
  const auto two = intersect(rel(RelType::kAgpp, b.table_top, b.bottom),
                             rel(RelType::kAgpc, rail, edge, 0.0), kTolerances);
  EXPECT_EQ(two.outcome, Outcome::kTwoSolutions) << two.detail;
  const auto none = intersect(rel(RelType::kAgpc, rail, edge, 0.0),
                              rel(RelType::kAgpc, b.table_top, edge, 0.0), kTolerances);
  EXPECT_EQ(none.outcome, Outcome::kInexpressible);
}

// Property: for random poses X and random features, each of the seven group types built to
// hold at X combines with FIX(X) into FIX(X), and has zero residual at X.
TEST(Combination, RandomRelationsHoldAtTheirPoseAndIntersectExactly) {
  std::mt19937 rng(7);
  std::normal_distribution<double> n(0.0, 1.0);
  auto random_pose = [&] {
    Pose p = Pose::Identity();
    p.linear() = Eigen::Quaterniond(n(rng), n(rng), n(rng), n(rng)).normalized().toRotationMatrix();
    p.translation() = 100.0 * Vector3d(n(rng), n(rng), n(rng));
    return p;
  };
  for (int trial = 0; trial < 50; ++trial) {
    const Pose x = random_pose();   // a_T_b
    const Pose fb = random_pose();  // b_T_fb
    for (const RelType t : {RelType::kFix, RelType::kLin, RelType::kLinlin, RelType::kRot,
                            RelType::kFits, RelType::kAgpp, RelType::kParax}) {
      // fa = X * fb (* M for the flipped types) so that S contains the identity part.
      const bool flip = t == RelType::kFits || t == RelType::kAgpp || t == RelType::kParax;
      const Pose fa = flip ? Pose(x * fb * flip_x()) : Pose(x * fb);
      const Relation r = rel(t, fa, fb);
      const auto [rad, mm] = residual(r, x);
      EXPECT_LT(mm, 1e-9) << to_string(t);
      EXPECT_LT(rad, 1e-9) << to_string(t);
      Relation fix = rel(RelType::kFix, x, Pose::Identity());
      const auto both = intersect(r, fix, kTolerances);
      ASSERT_EQ(both.outcome, Outcome::kOk) << to_string(t) << ": " << both.detail;
      EXPECT_EQ(both.relation.type, RelType::kFix);
      EXPECT_THAT(fixed_pose(both.relation), IsNearPose(x, 1e-7));
      // Seen from the other side it is the same set.
      const auto [rad2, mm2] = residual(reversed(r), x.inverse());
      EXPECT_LT(mm2, 1e-9);
      EXPECT_LT(rad2, 1e-9);
    }
  }
}

// Fig. 3.4: block 1 on block 2 on the table; block 2's top and bottom are parallel, so the
// creation rule AGPP,AGPP gives a virtual AGPP between block 1 and the table.
TEST(Creation, StackedBlocksGiveAVirtualAgpp) {
  Relation table_block2 = rel(RelType::kAgpp, feat({0, 0, 0}, {0, 0, 1}),
                              feat({0, 0, 0}, {0, 0, -1}));  // table(0) - block2(1)
  Relation block2_block1 = rel(RelType::kAgpp, feat({0, 0, 30}, {0, 0, 1}),
                               feat({0, 0, 0}, {0, 0, -1}));  // block2(1) - block1(2)
  block2_block1.a = 1;
  block2_block1.b = 2;
  const auto r = compose(table_block2, block2_block1, kTolerances);
  ASSERT_EQ(r.outcome, Outcome::kOk) << r.detail;
  EXPECT_EQ(r.relation.type, RelType::kAgpp);
  EXPECT_FALSE(r.relation.looser);
  EXPECT_EQ(r.relation.a, 0);
  EXPECT_EQ(r.relation.b, 2);
  // Block 1's bottom lies 30 mm above the table for every rotation and sliding of block 2.
  Pose x = Pose::Identity();
  x.translation() = Vector3d(7, -3, 30);
  x.linear() = Eigen::AngleAxisd(0.7, Vector3d::UnitZ()).toRotationMatrix();
  EXPECT_LT(residual(r.relation, x).second, 1e-9);
  x.translation().z() = 31;
  EXPECT_NEAR(residual(r.relation, x).second, 1.0, 1e-9);
}

TEST(Creation, LinesComposeIntoAPlaneAndRotationWithLineIsLooser) {
  Relation lin1 = rel(RelType::kLin, feat({0, 0, 0}, {1, 0, 0}), feat({0, 0, 0}, {1, 0, 0}));
  Relation lin2 = rel(RelType::kLin, feat({0, 0, 0}, {0, 1, 0}), feat({0, 0, 0}, {0, 1, 0}));
  lin2.a = 1;
  lin2.b = 2;
  const auto planar = compose(lin1, lin2, kTolerances);
  ASSERT_EQ(planar.outcome, Outcome::kOk);
  EXPECT_EQ(planar.relation.type, RelType::kLinlin);  // Table 2: LIN,LIN -> LINLIN
  EXPECT_FALSE(planar.relation.looser);
  Relation rot = rel(RelType::kRot, feat({0, 0, 0}, {0, 0, 1}), feat({0, 0, 0}, {0, 0, 1}));
  Relation lin3 = rel(RelType::kLin, feat({0, 0, 0}, {1, 0, 1}), feat({0, 0, 0}, {1, 0, 1}));
  lin3.a = 1;
  lin3.b = 2;
  const auto loose = compose(rot, lin3, kTolerances);
  ASSERT_EQ(loose.outcome, Outcome::kOk);
  EXPECT_EQ(loose.relation.type, RelType::kParax);  // Table 2: ROT,LIN -> PARAX*
  EXPECT_TRUE(loose.relation.looser);
}

}  // namespace
}  // namespace cell::rapt
