#include "cell/rapt/sema.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/rapt/parser.hpp"
#include "cell/testing/tolerances.hpp"
#include "support.hpp"

namespace cell::rapt {
namespace {

using testing::has_diagnostic;
using ::testing::HasSubstr;

using ::cell::testing::kTol;

Program analyze_text(const std::string& text, Diagnostics& d) {
  return analyze(parse(text, d), "test.rapt", d);
}

// Digest 003 §1.1: the Fig. 3.1 model; frames follow §1.4 (X = normal or axis).
TEST(Sema, FeatureFramesFollowTheLargeSmallRule) {
  Diagnostics d;
  const Program p = analyze_text(R"(
body/body1;
  p1=point/0,0,0; p2=point/20,0,0; p3=point/20,-20,0; p4=point/20,-20,30;
  p5=point/20,0,30; p6=point/0,0,30; p7=point/0,-20,0; p8=point/10,-10,0;
  p9=point/10,-10,-20;
  f1=face/p1,p2,p5,ylarge; f2=face/p1,p2,p3,zsmall; f3=face/p1,p6,p7,xsmall;
  f6=face/horiz,25,zsmall;
  l1=line/p2,p3; l3=line/p8,p9;
  e1=edge/l1,ysmall; e9=edge/l1,ylarge; s1=shaft/axis,l3,radius,5,zsmall;
terbod;
terapt;)",
                                 d);
  ASSERT_FALSE(d.has_errors()) << d.format_all();
  const Body& b = p.body(2);
  auto feature = [&](const std::string& name) {
    return b.features[static_cast<std::size_t>(b.feature_index.at(name))];
  };
  EXPECT_TRUE(feature("f1").axis().isApprox(Eigen::Vector3d(0, 1, 0), kTol));
  EXPECT_TRUE(feature("f2").axis().isApprox(Eigen::Vector3d(0, 0, -1), kTol));
  EXPECT_TRUE(feature("f3").axis().isApprox(Eigen::Vector3d(-1, 0, 0), kTol));
  EXPECT_TRUE(feature("f6").axis().isApprox(Eigen::Vector3d(0, 0, -1), kTol));
  EXPECT_NEAR(feature("f6").origin().z(), 25.0, kTol);
  EXPECT_TRUE(feature("s1").axis().isApprox(Eigen::Vector3d(0, 0, -1), kTol));
  EXPECT_DOUBLE_EQ(feature("s1").radius, 5.0);
  EXPECT_DOUBLE_EQ(feature("e1").length, 20.0);
  for (const Feature& f : b.features) {  // right-handed orthonormal frames
    EXPECT_NEAR(f.body_T_feature.linear().determinant(), 1.0, kTol) << f.name;
  }
  // Digest §2.2 [verified] edge end-point quirk: origin + length * X, not the line's end.
  const auto [a, z] = feature("e9").edge_end_points();
  EXPECT_TRUE(a.isApprox(Eigen::Vector3d(20, 0, 0), kTol));
  EXPECT_TRUE(z.isApprox(Eigen::Vector3d(20, 20, 0), kTol));
}

TEST(Sema, NamesTheUnknownAndTheAmbiguous) {
  Diagnostics d;
  (void)analyze_text(R"(body/b1; p1=point/0,0,0; p2=point/1,0,0; p3=point/0,1,0;
f1=face/p1,p2,p9,zlarge; f2=face/p1,p2,p3,zlarge; terbod;
body/b2; q1=point/0,0,0; q2=point/1,0,0; q3=point/0,1,0; f2=face/q1,q2,q3,zlarge; terbod;
against/f7 of b1, f2 of b2;
against/f2, f2 of b1;
against/f2 of b9, f2 of b1;
terapt;)",
                     d);
  EXPECT_TRUE(has_diagnostic(d, 2, 15, "unknown point 'p9' in body 'b1'")) << d.format_all();
  EXPECT_TRUE(has_diagnostic(d, 4, 9, "unknown feature 'f7' of body 'b1'"));
  EXPECT_TRUE(has_diagnostic(d, 5, 9, "feature 'f2' is ambiguous: it is defined in b1, b2"));
  EXPECT_TRUE(has_diagnostic(d, 6, 15, "unknown body 'b9'"));
}

TEST(Sema, RejectsARelationBetweenIncompatibleFeatures) {
  Diagnostics d;
  (void)analyze_text(R"(body/b1; p1=point/0,0,0; p2=point/1,0,0; p3=point/0,1,0;
f1=face/p1,p2,p3,zlarge; l1=line/p1,p2; h1=hole/axis,l1,radius,2,xlarge; terbod;
body/b2; q1=point/0,0,0; q2=point/1,0,0; l2=line/q1,q2; e1=edge/l2,xlarge; terbod;
against/h1 of b1, e1 of b2;
fits/f1 of b1, e1 of b2;
coplanar/f1 of b1, e1 of b2;
terapt;)",
                     d);
  EXPECT_EQ(d.error_count(), 3U) << d.format_all();
  EXPECT_TRUE(has_diagnostic(d, 4, 1,
                             "AGAINST between a hole ('h1 of b1') and a edge ('e1 of b2') is not "
                             "allowed: AGAINST takes face-face, face-shaft"));
  EXPECT_TRUE(has_diagnostic(d, 5, 1, "FITS between a face"));
  EXPECT_TRUE(has_diagnostic(d, 6, 1, "COPLANAR takes face-face"));
}

TEST(Sema, ChecksVisionPackages) {
  Diagnostics d;
  (void)analyze_text(R"(body/b1; p1=point/0,0,0; p2=point/1,0,0; p3=point/0,1,0;
f1=face/p1,p2,p3,zlarge; l1=line/p1,p2; e1=edge/l1,xlarge; terbod;
body/b2; q1=point/0,0,0; q2=point/1,0,0; l2=line/q1,q2; e1=edge/l2,xlarge; terbod;
w1=point/0,0,0; w2=point/1,0,0; w3=point/0,1,0; wf=face/w1,w2,w3,zlarge; c0=point/0,0,100;
cam=camera/position,c0,theta,0,phi,0,psi,0,focus,10;
combine;
  look/f1 of b1, cam;
  look/e1 of b1, cam;
  inviolate/fits, wf, f1 of b1;
  inviolate/against, wf, e1 of b1;
  look/e1 of b2, cam;
  look/e1 of b1;
tercom;
look/e1 of b1, cam;
tolerance/tran,3;
terapt;)",
                     d);
  EXPECT_EQ(d.error_count(), 7U) << d.format_all();
  EXPECT_TRUE(has_diagnostic(d, 7, 8, "LOOK needs an edge: 'f1 of b1' is a face"));
  EXPECT_TRUE(has_diagnostic(d, 9, 13, "INVIOLATE supports only AGAINST between two faces"));
  EXPECT_TRUE(has_diagnostic(d, 10, 26, "'e1 of b1' is a edge"));
  EXPECT_TRUE(has_diagnostic(d, 11, 3, "must concern one body: this LOOK is of 'b2'"));
  EXPECT_TRUE(has_diagnostic(d, 12, 3, "LOOK has no camera"));
  EXPECT_TRUE(has_diagnostic(d, 14, 1, "LOOK is only allowed inside a COMBINE"));
  EXPECT_TRUE(has_diagnostic(d, 15, 1, "only allowed inside COMBINE"));
}

TEST(Sema, ActionsNeedAnAgentAndCannotMoveTheWorld) {
  Diagnostics d;
  (void)analyze_text(R"(body/b1; terbod; body/b2; terbod; body/b3; terbod;
agent/b1;
tied/b2, world;
move/b3;
move/b2;
tied/b1, b3;
move/b3;
untied/b1, b2;
terapt;)",
                     d);
  EXPECT_TRUE(has_diagnostic(d, 4, 1, "'b3' cannot be moved: it is neither an AGENT nor TIED"))
      << d.format_all();
  EXPECT_TRUE(has_diagnostic(d, 5, 1, "MOVE/b2 would move the world"));
  EXPECT_TRUE(has_diagnostic(d, 8, 1, "UNTIED/b1,b2: they are not TIED"));
  EXPECT_EQ(d.error_count(), 4U);  // also b2 (world-tied, no agent)
}

// Thesis §3.2.6 and digest §1.3: the unmoved body table and TIE table of Appendix V.
TEST(Sema, AppendixVTablesOfMovedBodiesAndTies) {
  const CompiledProgram& cp = testing::appendix_v();
  const Program& p = cp.program;
  ASSERT_EQ(p.situation_count(), 16);
  ASSERT_EQ(p.body_count(), 4);
  EXPECT_EQ(p.moved[1], (std::vector<int>{2}));         // sit 2: move/b1
  EXPECT_TRUE(p.moved[2].empty());                      // sit 3: vision package
  EXPECT_EQ(p.moved[4], (std::vector<int>{2, 4}));      // sit 5: b3 moves, b1 TIED to it
  EXPECT_EQ(p.moved[7], (std::vector<int>{2}));         // sit 8: untied after sit 7
  EXPECT_EQ(p.moved[15], (std::vector<int>{2, 3, 4}));  // sit 16: the super TIE
  EXPECT_EQ(p.unmoved(16), std::vector<int>{});
  EXPECT_EQ(p.unmoved(4), (std::vector<int>{3, 4}));
  EXPECT_EQ(p.situation(3).action.kind, ActionKind::kVision);
  EXPECT_EQ(p.packages.size(), 4U);
  EXPECT_EQ(p.packages[0].body, 4);
  EXPECT_EQ(p.packages[1].situation, 10);
  EXPECT_EQ(p.ties_after[3], (std::vector<std::pair<int, int>>{{2, 4}}));  // after sit 4
  EXPECT_TRUE(p.ties_after[6].empty());                                    // after sit 7
  EXPECT_EQ(p.global_tolerance.at(4), 5.0);
  EXPECT_EQ(p.packages[2].local_tolerance, 12.0);
}

}  // namespace
}  // namespace cell::rapt
