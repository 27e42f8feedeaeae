#include "cell/rapt/nominal.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/testing/matchers.hpp"
#include "cell/testing/tolerances.hpp"
#include "support.hpp"

namespace cell::rapt {
namespace {

using ::cell::testing::IsNearPose;
using testing::has_diagnostic;
using ::testing::HasSubstr;
using testing::thesis_pose;
using V = Eigen::Vector3d;

using ::cell::testing::kTolMm;

// Digest 003 §6.1: the nominal positions printed in Appendix V section 3 (rows X, Y, Z, T)
// and the ROBMOD extract of situation 1.
TEST(NominalAppendixV, ReproducesThePrintedNominalPositions) {
  const CompiledProgram& cp = testing::appendix_v();
  const int b1 = testing::body(cp, "b1");
  const int b2 = testing::body(cp, "b2");
  const int b3 = testing::body(cp, "b3");
  ASSERT_TRUE(cp.nominal.complete());
  EXPECT_THAT(
      cp.nominal_pose(b3, 3),
      IsNearPose(thesis_pose(V(1, 0, 0), V(0, -1, 0), V(0, 0, -1), V(0, -150, 140)), kTolMm));
  EXPECT_THAT(cp.nominal_pose(b1, 10),
              IsNearPose(thesis_pose(V(0, 0, -1), V(0, 1, 0), V(1, 0, 0), V(200, -5, 35)), kTolMm));
  EXPECT_THAT(cp.nominal_pose(b2, 11), IsNearPose(Pose::Identity(), kTolMm));
  EXPECT_THAT(cp.nominal_pose(b3, 14),
              IsNearPose(thesis_pose(V(1, 0, 0), V(0, 0, 1), V(0, -1, 0), V(0, 100, 90)), kTolMm));
  // ROBMOD, situation 1: b1 at (200, -180, 200) with rotz 90 roty 90 rotz 90, b2 at the origin.
  EXPECT_THAT(
      cp.nominal_pose(b1, 1),
      IsNearPose(thesis_pose(V(-1, 0, 0), V(0, 0, 1), V(0, 1, 0), V(200, -180, 200)), kTolMm));
  EXPECT_THAT(cp.nominal_pose(b2, 1), IsNearPose(Pose::Identity(), kTolMm));
}

// Digest §8.2 case 7 [derived]: PN_b1,4 and the turn of situation 6.
TEST(NominalAppendixV, ReproducesTheDerivedPositionsOfSituations4To6) {
  const CompiledProgram& cp = testing::appendix_v();
  const int b1 = testing::body(cp, "b1");
  const int b3 = testing::body(cp, "b3");
  EXPECT_THAT(cp.nominal_pose(b1, 4),
              IsNearPose(thesis_pose(V(0, 1, 0), V(0, 0, 1), V(1, 0, 0), V(20, -145, 35)), kTolMm));
  // Situation 5: b3 moves 150 up (f3's normal), b1 follows through the TIE.
  EXPECT_TRUE(cp.nominal_pose(b3, 5).translation().isApprox(V(0, -150, 290), 1e-12));
  EXPECT_TRUE(cp.nominal_pose(b1, 5).translation().isApprox(V(20, -145, 185), 1e-12));
  // Situation 6: turned 180 degrees about h2 until f8 is against the world's f4.
  EXPECT_THAT(cp.nominal_pose(b3, 6),
              IsNearPose(thesis_pose(V(1, 0, 0), V(0, 1, 0), V(0, 0, 1), V(0, -120, 60)), kTolMm));
  // Every instance is fixed, by 3x16 merges of the world plus the relations.
  EXPECT_GT(cp.nominal.combinations, 10);
}

// Fig. 3.4 (thesis §3.3.3.3): block 1 on block 2 on the table, plus side faces. Block 2's
// rotation is not known on its own, so only a creation rule (AGPP,AGPP -> AGPP through
// block 2) lets the cycle finder relate block 1 to the table directly.
TEST(NominalCreation, StackedBlocksAreSolvedThroughACreationRule) {
  // Block 2 stands on the table (AGPP) with a side parallel to the wall (PARAX): LINLIN.
  // Block 1 sits on block 2 (AGPP) pinned into its vertical hole (FITS): ROT about the pin.
  // Block 1 touches both walls: LIN (vertical). No two relations join the same two bodies
  // any more, so the chain table-block2-block1 (LINLIN, ROT) must create one (Table 2:
  // ROT,LINLIN -> AGPP when the axis is along the normal) to fix block 1, then block 2.
  const auto c = testing::compile_text(R"(
body/block1; a=point/0,0,0; b=point/1,0,0; c=point/0,1,0; d=point/0,0,1;
  k=point/10,10,0; k2=point/10,10,-5;
  bottom=face/a,b,c,zsmall; g=face/a,c,d,xsmall; h=face/a,b,d,ysmall;
  pl=line/k,k2; pin=shaft/axis,pl,radius,2,zsmall; terbod;
body/block2; a=point/0,0,0; b=point/1,0,0; c=point/0,1,0; t=point/0,0,30;
  m=point/10,10,30; m2=point/10,10,20;
  bottom=face/a,b,c,zsmall; top=face/horiz,30,zlarge; side=face/a,c,t,xsmall;
  hl=line/m2,m; hole=hole/axis,hl,radius,2,zlarge; terbod;
o=point/0,0,0; x=point/1,0,0; y=point/0,1,0; z=point/0,0,1;
table=face/o,x,y,zlarge; wall=face/o,y,z,xlarge; wall2=face/o,x,z,ylarge;
against/bottom of block2, table;
parax/side of block2, wall;
against/bottom of block1, top of block2;
fits/pin of block1, hole of block2;
against/g of block1, wall;
against/h of block1, wall2;
terapt;)");
  ASSERT_TRUE(c.program) << testing::all(c.diags);
  const auto& n = c.program->nominal;
  EXPECT_GE(n.creations, 1);
  EXPECT_THAT(*n.pose(2, 1), IsNearPose(Pose(translation(V(0, 0, 30))), kTolMm));
  EXPECT_THAT(*n.pose(3, 1), IsNearPose(Pose::Identity(), kTolMm));
}

// Thesis §3.2.3-§3.2.5: an explicit TURN (degrees about a feature's axis), and a permanent
// subassembly whose relations keep a finger on the gripper in every situation; digest §4.4 S1:
// the finger's modifying factor follows the gripper's like a TIE.
TEST(NominalActions, ExplicitTurnAndAPermanentSubassembly) {
  const auto c = testing::compile_text(R"(
body/gripper; o=point/0,0,0; x=point/1,0,0; y=point/0,1,0; z=point/0,0,1;
  bottom=face/o,x,y,zsmall; side=face/o,y,z,xsmall; back=face/o,x,z,ysmall;
  ax=line/o,z; axis=edge/ax,zlarge;
  m=point/10,0,0; my=point/10,1,0; mz=point/10,0,1; palm=face/m,my,mz,xlarge; terbod;
body/finger; o=point/0,0,0; x=point/1,0,0; y=point/0,1,0; z=point/0,0,1;
  inner=face/o,y,z,xsmall; low=face/o,x,y,zsmall; back=face/o,x,z,ysmall; terbod;
body/block; o=point/0,0,0; x=point/1,0,0; y=point/0,1,0; z=point/0,0,1;
  bottom=face/o,x,y,zsmall; side=face/o,y,z,xsmall; back=face/o,x,z,ysmall; terbod;
wo=point/0,0,0; wx=point/1,0,0; wy=point/0,1,0; wz=point/0,0,1; t=point/0,0,100;
table=face/wo,wx,wy,zlarge; wall=face/wo,wy,wz,xlarge; wall2=face/wo,wx,wz,ylarge;
agent/gripper;
hand=subass/perm;
  against/inner of finger, palm of gripper;
  coplanar/low of finger, bottom of gripper;
  coplanar/back of finger, back of gripper;
tersub;
against/bottom of gripper, table; against/side of gripper, wall; against/back of gripper, wall2;
against/bottom of block, table; against/side of block, wall; against/back of block, wall2;
turn/gripper, about, axis of gripper, 90;
move/gripper, perpto, bottom of gripper, -40;
terapt;)");
  ASSERT_TRUE(c.program) << testing::all(c.diags);
  const CompiledProgram& cp = *c.program;
  const int gripper = testing::body(cp, "gripper");
  const int finger = testing::body(cp, "finger");
  // Situation 2: turned +90 degrees about its own z axis (right-handed).
  Pose turned = Pose::Identity();
  turned.linear() = Eigen::AngleAxisd(M_PI / 2, V::UnitZ()).toRotationMatrix();
  EXPECT_THAT(cp.nominal_pose(gripper, 2), IsNearPose(turned, kTolMm));
  // Situation 3: 40 mm against the bottom's normal (-z), i.e. up.
  EXPECT_THAT(cp.nominal_pose(gripper, 3),
              IsNearPose(Pose(translation(V(0, 0, 40)) * turned), kTolMm));
  // The finger stays on the palm (x = 10 in the gripper's frame) through both actions.
  for (const int s : {1, 2, 3}) {
    EXPECT_THAT(cp.nominal_pose(finger, s),
                IsNearPose(Pose(cp.nominal_pose(gripper, s) * translation(V(10, 0, 0))), kTolMm))
        << s;
  }
  EXPECT_EQ(cp.program.moved[1], (std::vector<int>{gripper, finger}));
  // Both moves are unspecified: the finger keeps its factor (T4 through the subassembly link).
  EXPECT_EQ(cp.mf_before.notation(finger, 3), "3,2");
}

TEST(NominalErrors, AnUnderConstrainedBodyIsReportedWithItsSituationsAndRelations) {
  const auto c = testing::compile_text(R"(body/b1; p=point/0,0,0; q=point/1,0,0; r=point/0,1,0;
  f=face/p,q,r,zsmall; terbod;
o=point/0,0,0; x=point/1,0,0; y=point/0,1,0; table=face/o,x,y,zlarge;
agent/b1;
against/f of b1, table;
terapt;)");
  EXPECT_FALSE(c.program.has_value());
  EXPECT_TRUE(has_diagnostic(c.diags, 1, 6,
                             "under-constrained program: the position of b1 in situation 1 is "
                             "not determined relative to the world; AGPP (2 translational, 1 "
                             "rotational freedoms) with the world from AGAINST/f of b1, table"))
      << testing::all(c.diags);
}

TEST(NominalErrors, AGeneralMoveWithoutRelationsIsReportedAtTheMove) {
  const auto c = testing::compile_text(R"(body/b1; p=point/0,0,0; q=point/1,0,0; r=point/0,1,0;
  s=point/0,0,1; f=face/p,q,r,zsmall; g=face/p,r,s,xsmall; h=face/p,q,s,ysmall; terbod;
o=point/0,0,0; x=point/1,0,0; y=point/0,1,0; z=point/0,0,1;
table=face/o,x,y,zlarge; wall=face/o,y,z,xlarge; wall2=face/o,x,z,ylarge;
agent/b1;
against/f of b1, table; against/g of b1, wall; against/h of b1, wall2;
move/b1;
terapt;)");
  EXPECT_TRUE(has_diagnostic(c.diags, 7, 1,
                             "the position of b1 in situation 2 is not determined relative to "
                             "the world; no relation, explicit action or TIE connects it"))
      << testing::all(c.diags);
}

TEST(NominalErrors, InconsistentRelationsAreReportedWithBothPositions) {
  const auto c = testing::compile_text(R"(body/b1; p=point/0,0,0; q=point/1,0,0; r=point/0,1,0;
  s=point/0,0,1; t=point/0,0,10; f=face/p,q,r,zsmall; top=face/horiz,10,zlarge;
  g=face/p,r,s,xsmall; h=face/p,q,s,ysmall; terbod;
o=point/0,0,0; x=point/1,0,0; y=point/0,1,0; z=point/0,0,1;
c=point/0,0,12; cx=point/1,0,12; cy=point/0,1,12;
table=face/o,x,y,zlarge; wall=face/o,y,z,xlarge; wall2=face/o,x,z,ylarge;
ceiling=face/c,cx,cy,zsmall;
against/f of b1, table; against/g of b1, wall; against/h of b1, wall2;
against/top of b1, ceiling;
terapt;)");
  EXPECT_FALSE(c.program.has_value());
  bool found = false;
  for (const Diagnostic& d : c.diags.items()) {
    if (d.message.find("inconsistent program") != std::string::npos) {
      found = true;
      EXPECT_THAT(d.message, HasSubstr("the relation AGAINST/top of b1, ceiling of world in "
                                       "situation 1 (at 9:1) does not hold"));
      EXPECT_THAT(d.message, HasSubstr("off by 2 mm"));
    }
  }
  EXPECT_TRUE(found) << testing::all(c.diags);
}

}  // namespace
}  // namespace cell::rapt
