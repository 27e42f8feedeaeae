#include "cell/rapt/vision.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/testing/matchers.hpp"
#include "support.hpp"

namespace cell::rapt {
namespace {

using ::cell::testing::IsNearPose;
using testing::has_diagnostic;
using ::testing::HasSubstr;
using V = Eigen::Vector3d;

/// The run-time inputs of a package of a compiled program at the nominal state (FM = I), with
/// the given readings per LOOK.
RouteInputs nominal_inputs(const CompiledProgram& cp,
                           const CompiledPackage& pkg,
                           const std::vector<std::pair<ImagePoint, ImagePoint>>& readings) {
  const Package& decl = cp.program.packages[static_cast<std::size_t>(pkg.index)];
  RouteInputs in;
  in.world_T_nominal = cp.nominal_pose(pkg.body, pkg.situation);
  for (const InviolateDecl& inv : decl.inviolates) {
    in.world_T_reference.push_back(cp.nominal_pose(inv.reference.body, pkg.situation));
  }
  for (std::size_t k = 0; k < decl.looks.size(); ++k) {
    const Camera& cam = cp.program.cameras[static_cast<std::size_t>(decl.looks[k].camera)];
    in.cameras.push_back(CameraModel{cam.world_T_camera, cam.focus});
    in.readings.emplace_back(k < readings.size() ? std::optional(readings[k]) : std::nullopt);
  }
  return in;
}

std::pair<ImagePoint, ImagePoint> pt(double y1, double z1, double y2, double z2) {
  return {ImagePoint(y1, z1), ImagePoint(y2, z2)};
}

// Digest §8.2 case 8 [derived]: (0,5,0) for situation 3, (0,5,5) for 10, (0,12,12) for 11.
TEST(Tolerance, CombinesWithTheInviolateNormalsAsThesis51And52) {
  EXPECT_TRUE(combine_tolerance(5, {V(1, 0, 0), V(0, 0, 1)}).isApprox(V(0, 5, 0)));
  EXPECT_TRUE(combine_tolerance(5, {V(1, 0, 0)}).isApprox(V(0, 5, 5)));
  EXPECT_TRUE(combine_tolerance(12, {V(1, 0, 0)}).isApprox(V(0, 12, 12)));
  EXPECT_TRUE(combine_tolerance(4, {}).isApprox(V(4, 4, 4)));
  EXPECT_TRUE(combine_tolerance(4, {V(0, 0, 1), V(0, 0, -1)}).isApprox(V(4, 4, 0)));
  EXPECT_TRUE(combine_tolerance(4, {V(1, 0, 0), V(0, 1, 0), V(0, 0, 1)}).isZero());
  const CompiledProgram& cp = testing::appendix_v();
  EXPECT_TRUE(cp.packages[0].combined_tolerance_mm.isApprox(V(0, 5, 0)));
  EXPECT_EQ(cp.packages[0].tolerance_source, "local");
  EXPECT_TRUE(cp.packages[3].combined_tolerance_mm.isApprox(V(0, 5, 5)));
  EXPECT_EQ(cp.packages[3].tolerance_source, "global");  // TOLERANCE/b3,TRANS,5
}

// Digest §3.3-§3.4: stage 1 combines the INVIOLATEs, stage 2 appends LOOKs; the route is fixed
// at compile time.
TEST(SymbolicRoute, AppendixVRoutesFollowTable62) {
  const CompiledProgram& cp = testing::appendix_v();
  EXPECT_EQ(route_text(cp.program, cp.packages[0]),
            "merge(lin_agpe_fix(agpp_agpp_lin(AGPP[f1 of world, f7 of b3], AGPP[f2 of world, f8 "
            "of b3]), face[LOOK e1 of b3, cam1], e1 of b3))");
  // Situation 3: the second LOOK is redundant (the thesis: "one redundant LOOK").
  EXPECT_TRUE(cp.packages[0].looks[0].used);
  EXPECT_FALSE(cp.packages[0].looks[1].used);
  EXPECT_THAT(cp.packages[0].looks[1].note, HasSubstr("redundant"));
  EXPECT_EQ(route_text(cp.program, cp.packages[2]),
            "merge(lin_agpe_fix(agpp_agpe_lin(AGPP[f1 of world, f5 of b2], face[LOOK e2 of b2, "
            "cam6], e2 of b2), face[LOOK e1 of b2, cam6], e1 of b2))");
  for (const CompiledPackage& pkg : cp.packages) {
    EXPECT_TRUE(pkg.fixable) << pkg.situation;
    EXPECT_EQ(pkg.route.reached, RelType::kFix);
  }
}

// Digest §3.4 / thesis §6.6: ROTYLIN avoidance. Appendix VI looks at the vertical edge e1 first,
// which is parallel to the INVIOLATE face normal: the reasoner skips it, uses e2 for
// AGPP+AGPE -> LIN, and then e1 for LIN+AGPE -> FIX.
TEST(SymbolicRoute, SkipsARotylinLookAndUsesItLaterAgainstTheLin) {
  const CompiledProgram& cp = testing::appendix_vi();
  ASSERT_EQ(cp.packages.size(), 1U);
  EXPECT_EQ(route_text(cp.program, cp.packages[0]),
            "merge(lin_agpe_fix(agpp_agpe_lin(AGPP[wf5 of world, f5 of box], face[LOOK e2 of "
            "box, cam1], e2 of box), face[LOOK e1 of box, cam1], e1 of box))");
  EXPECT_EQ(cp.packages[0].situation, 2);  // "The camera cam1 is working in situation 2"
  EXPECT_THAT(cp.nominal_pose(2, 1), ::cell::testing::IsNearPose(Pose::Identity(), 1e-12));
}

// Digest §8.2 case 10: one INVIOLATE and one usable LOOK cannot fix the body: reported at
// compile time, the package ignored at run time and the body's MF entry points to itself in
// the previous situation.
TEST(SymbolicRoute, CannotFixIsReportedAtCompileTimeAndLinksToThePreviousSituation) {
  // One INVIOLATE (the bottom on the table) and two LOOKs of parallel edges: the first gives a
  // LIN along the edges; the second's face contains that direction, so nothing fixes the slide.
  const auto c = testing::compile_text(R"(body/b; p=point/0,0,0; q=point/50,0,0; r=point/0,40,0;
  s=point/0,0,30; t=point/50,40,0; f=face/p,q,r,zsmall; g=face/p,r,s,xsmall;
  h=face/p,q,s,ysmall; l=line/p,q; e=edge/l,xlarge; l2=line/r,t; e2=edge/l2,xlarge; terbod;
o=point/0,0,0; x=point/1,0,0; y=point/0,1,0; z=point/0,0,1; c=point/25,20,400;
table=face/o,x,y,zlarge; wall=face/o,y,z,xlarge; wall2=face/o,x,z,ylarge;
cam=camera/position,c,theta,0,phi,180,psi,0,focus,50;
against/f of b, table; against/g of b, wall; against/h of b, wall2;
combine; inviolate/against, table, f of b; look/e of b, cam; look/e2 of b, cam; tercom;
terapt;)");
  ASSERT_TRUE(c.program) << testing::all(c.diags);
  const CompiledPackage& pkg = c.program->packages[0];
  EXPECT_FALSE(pkg.fixable);
  EXPECT_EQ(pkg.route.reached, RelType::kLin);
  EXPECT_TRUE(pkg.looks[0].used);
  EXPECT_THAT(pkg.looks[1].note, HasSubstr("contains the LIN direction"));
  EXPECT_TRUE(has_diagnostic(c.diags, 8, 1, "cannot fix 'b' with this COMBINE package"))
      << testing::all(c.diags);
  EXPECT_EQ(c.program->mf_before.notation(2, 2), "2,1");
  // The run ignores the package (no reading is needed).
  auto r = run(*c.program, {});
  ASSERT_TRUE(r) << r.error().message;
  EXPECT_FALSE(r->packages[0].evaluated);
  EXPECT_THAT(r->packages[0].note, HasSubstr("cannot fix"));
}

TEST(SymbolicRoute, AnInviolateThatDoesNotHoldAtTheNominalPositionIsAnError) {
  const auto d = testing::compile_text(R"(body/b; p=point/0,0,0; q=point/50,0,0; r=point/0,40,0;
  s=point/0,0,30; f=face/p,q,r,zsmall; g=face/p,r,s,xsmall; h=face/p,q,s,ysmall;
  l=line/p,q; e=edge/l,xlarge; terbod;
o=point/0,0,0; x=point/1,0,0; y=point/0,1,0; z=point/0,0,1; c=point/25,20,400;
table=face/o,x,y,zlarge; wall=face/o,y,z,xlarge; wall2=face/o,x,z,ylarge;
cam=camera/position,c,theta,0,phi,180,psi,0,focus,50;
against/f of b, table; against/g of b, wall; against/h of b, wall2;
combine; inviolate/against, wall, f of b; look/e of b, cam; tercom;
terapt;)");
  EXPECT_FALSE(d.program.has_value());
  EXPECT_TRUE(has_diagnostic(d.diags, 8, 10,
                             "INVIOLATE/AGAINST, wall of world, f of b does not hold at the "
                             "nominal position of 'b' in situation 2"))
      << testing::all(d.diags);
}

// Thesis §5.3: the reference must belong to the world or to a body fixed in the world; here the
// reference body (a loose plate) has no determined position in the package's situation.
TEST(SymbolicRoute, AnInviolateReferenceThatIsNotFixedInTheWorldIsAnError) {
  const auto c = testing::compile_text(R"(body/b; p=point/0,0,0; q=point/50,0,0; r=point/0,40,0;
  s=point/0,0,30; f=face/p,q,r,zsmall; g=face/p,r,s,xsmall; h=face/p,q,s,ysmall;
  l=line/p,q; e=edge/l,xlarge; terbod;
body/plate; a=point/0,0,0; x=point/1,0,0; y=point/0,1,0; top=face/a,x,y,zlarge; terbod;
o=point/0,0,0; x=point/1,0,0; y=point/0,1,0; z=point/0,0,1; c=point/25,20,400;
table=face/o,x,y,zlarge; wall=face/o,y,z,xlarge; wall2=face/o,x,z,ylarge;
cam=camera/position,c,theta,0,phi,180,psi,0,focus,50;
against/f of b, table; against/g of b, wall; against/h of b, wall2;
combine; inviolate/against, top of plate, f of b; look/e of b, cam; tercom;
terapt;)");
  EXPECT_FALSE(c.program.has_value());
  EXPECT_TRUE(has_diagnostic(c.diags, 9, 10,
                             "the INVIOLATE reference 'top of plate' is not fixed in the world in "
                             "situation 2"))
      << testing::all(c.diags);
}

// Thesis §5.6: a general camera is a body (lens axis = body X, lens centre = origin); its
// predictions use that body's position.
TEST(SymbolicRoute, AGeneralCameraSeesThroughItsBodysFrame) {
  const auto c = testing::compile_text(R"(body/b; p=point/0,0,0; q=point/50,0,0; r=point/0,40,0;
  s=point/0,0,30; f=face/p,q,r,zsmall; g=face/p,r,s,xsmall; h=face/p,q,s,ysmall;
  l=line/p,r; e=edge/l,ylarge; terbod;
body/eye; a=point/0,0,0; x=point/1,0,0; y=point/0,1,0; z=point/0,0,1;
  front=face/a,y,z,xlarge; under=face/a,x,y,zsmall; left=face/a,x,z,ysmall; terbod;
o=point/0,0,0; x=point/1,0,0; y=point/0,1,0; z=point/0,0,1;
table=face/o,x,y,zlarge; wall=face/o,y,z,xlarge; wall2=face/o,x,z,ylarge;
k1=point/-200,0,0; k2=point/-200,1,0; k3=point/-200,0,1; far=face/k1,k2,k3,xsmall;
cam=camera/tv1, eye, focus, 50;
against/f of b, table; against/g of b, wall; against/h of b, wall2;
against/front of eye, far; against/under of eye, table; against/left of eye, wall2;
combine; inviolate/against, table, f of b; look/e of b, cam; tercom;
terapt;)");
  ASSERT_TRUE(c.program) << testing::all(c.diags);
  // The eye sits at (-200, 0, 0) looking along +x; e runs from (0,0,0) to (0,40,0).
  const CameraModel eye{c.program->nominal_pose(3, 2), 50.0};
  EXPECT_TRUE(eye.world_T_camera.translation().isApprox(V(-200, 0, 0), 1e-12));
  const auto& look = c.program->packages[0].looks[0];
  EXPECT_TRUE(look.predicted[0].isApprox(*eye.project(V(0, 0, 0)), 1e-12));
  EXPECT_TRUE(look.predicted[1].isApprox(*eye.project(V(0, 40, 0)), 1e-12));
  EXPECT_TRUE(look.predicted[1].isApprox(ImagePoint(10, 0), 1e-12));  // F * 40 / 200
}

// Digest §8.2 case 2 [verified]: situation 3, typed (-17,8), (-19,25) give y = -147.632 with
// the rotation unchanged; using the second (redundant) LOOK instead would give -164.24.
TEST(SymbolicEvaluation, Situation3ReproducesThePrintedVerifiedPosition) {
  const CompiledProgram& cp = testing::appendix_v();
  const CompiledPackage& pkg = cp.packages[0];
  auto pv = evaluate_route(cp.program, pkg,
                           nominal_inputs(cp, pkg, {pt(-17, 8, -19, 25), pt(-15, 19, -20, 21)}));
  ASSERT_TRUE(pv) << pv.error().message;
  EXPECT_THAT(*pv, IsNearPose(testing::thesis_pose(V(1, 0, 0), V(0, -1, 0), V(0, 0, -1),
                                                   V(0, -147.632, 140)),
                              1e-3));  // printed to 3 decimals
  EXPECT_NEAR(pv->translation().y(), -147.63194, 1e-5);
}

// Digest §8.2 case 3: typing the predicted end points returns the nominal position.
TEST(SymbolicEvaluation, PredictedReadingsGiveTheNominalPosition) {
  for (const CompiledProgram* cp : {&testing::appendix_v(), &testing::appendix_vi()}) {
    for (const CompiledPackage& pkg : cp->packages) {
      std::vector<std::pair<ImagePoint, ImagePoint>> readings;
      for (const CompiledLook& look : pkg.looks) {
        readings.emplace_back(look.predicted[0], look.predicted[1]);
      }
      auto pv = evaluate_route(cp->program, pkg, nominal_inputs(*cp, pkg, readings));
      ASSERT_TRUE(pv) << pv.error().message;
      EXPECT_THAT(*pv, IsNearPose(cp->nominal_pose(pkg.body, pkg.situation), 1e-9))
          << "situation " << pkg.situation;
    }
  }
}

// Digest §8.2 case 4: situation 11. The rotation about X of -4.7636 degrees is reproduced
// exactly; the translation (0, 1.290586, 1.255067) to 0.005 mm: with the origin-in-plane rule
// of LIN+AGPE we get (0, 1.29537, 1.25466), a difference the digest also found.
TEST(SymbolicEvaluation, Situation11ReproducesThePrintedRotationAndTheTranslationTo5um) {
  const CompiledProgram& cp = testing::appendix_v();
  const CompiledPackage& pkg = cp.packages[2];
  auto pv = evaluate_route(cp.program, pkg,
                           nominal_inputs(cp, pkg, {pt(-4, 3, 20, 5), pt(-3, 4, -5, -36)}));
  ASSERT_TRUE(pv) << pv.error().message;
  const Eigen::Matrix4d row = to_thesis(*pv);
  EXPECT_NEAR(row(1, 1), 0.9965458, 1e-7);
  EXPECT_NEAR(row(1, 2), -0.08304549, 1e-7);
  EXPECT_NEAR(row(2, 1), 0.08304549, 1e-7);
  EXPECT_NEAR(row(2, 2), 0.9965458, 1e-7);
  EXPECT_NEAR(row(3, 0), 0.0, 1e-9);
  EXPECT_NEAR(row(3, 1), 1.290586, 0.005);
  EXPECT_NEAR(row(3, 2), 1.255067, 0.001);
}

// Digest §8.2 case 5: situation 14. The rotation is reproduced exactly; the translation along
// the LIN is not: we get (0, 95.357, 93.207) against the printed (0, 97.924, 93.314). The
// printed position puts e2's point 13.06 mm from its origin in the second LOOK's face, so the
// decoded readings of that LOOK cannot be the ones typed (README: "what was reconstructed").
TEST(SymbolicEvaluation, Situation14ReproducesThePrintedRotation) {
  const CompiledProgram& cp = testing::appendix_v();
  const CompiledPackage& pkg = cp.packages[3];
  const RouteInputs in = nominal_inputs(cp, pkg, {pt(34, 6, -14, 8), pt(3, 21, 5, 8)});
  auto pv = evaluate_route(cp.program, pkg, in);
  ASSERT_TRUE(pv) << pv.error().message;
  const Eigen::Matrix4d row = to_thesis(*pv);
  EXPECT_NEAR(row(1, 1), -0.04163054, 1e-7);
  EXPECT_NEAR(row(1, 2), 0.9991331, 1e-7);
  EXPECT_NEAR(row(2, 1), -0.9991331, 1e-7);
  // The body origin (e1's origin) lies on the first LOOK's face, as in the printed result.
  auto face = face_from_image(in.cameras[0], ImagePoint(34, 6), ImagePoint(-14, 8));
  EXPECT_NEAR(face->normal.dot(pv->translation() - face->point), 0.0, 1e-9);
  const V printed(0, 97.92412, 93.31351);
  EXPECT_NEAR(face->normal.dot(printed - face->point), 0.0, 1e-4);
  // Our translation, pinned (origin-in-plane rule with the decoded readings).
  EXPECT_NEAR(row(3, 1), 95.357, 1e-3);
  EXPECT_NEAR(row(3, 2), 93.207, 1e-3);
}

// Digest §3.3 / §8.2 case 10: AGPP+AGPE has two solutions 180 degrees apart about the face
// normal; the one within 90 degrees of the nominal orientation is kept.
TEST(SymbolicEvaluation, KeepsTheSolutionNearestTheNominalOrientation) {
  const CompiledProgram& cp = testing::appendix_v();
  const CompiledPackage& pkg = cp.packages[2];  // b2, nominal identity
  for (const double angle_deg : {-40.0, -10.0, 10.0, 40.0, 80.0}) {
    // Rotate b2 about the INVIOLATE normal (world x) through its f5 face and image it.
    Pose truth = Pose::Identity();
    truth.linear() = Eigen::AngleAxisd(angle_deg * M_PI / 180.0, V::UnitX()).toRotationMatrix();
    truth.translation() = V(0, 2, -1);
    RouteInputs in = nominal_inputs(cp, pkg, {});
    for (std::size_t k = 0; k < 2; ++k) {
      const auto [a, b] = cp.program.feature(pkg.looks[k].decl.edge).edge_end_points();
      in.readings[k] =
          std::pair{*in.cameras[k].project(truth * a), *in.cameras[k].project(truth * b)};
    }
    auto pv = evaluate_route(cp.program, pkg, in);
    ASSERT_TRUE(pv) << pv.error().message;
    EXPECT_THAT(*pv, IsNearPose(truth, 1e-7)) << angle_deg;
  }
}

TEST(SymbolicEvaluation, NamesTheLookWhoseReadingIsMissingOrDegenerate) {
  const CompiledProgram& cp = testing::appendix_v();
  const CompiledPackage& pkg = cp.packages[2];
  auto missing = evaluate_route(cp.program, pkg, nominal_inputs(cp, pkg, {pt(-4, 3, 20, 5)}));
  ASSERT_FALSE(missing);
  EXPECT_THAT(missing.error().message, HasSubstr("LOOK/e1 of b2, cam6 at"));
  EXPECT_THAT(missing.error().message, HasSubstr("no measurement"));
  auto same = evaluate_route(cp.program, pkg,
                             nominal_inputs(cp, pkg, {pt(1, 1, 1, 1), pt(-3, 4, -5, -36)}));
  ASSERT_FALSE(same);
  EXPECT_THAT(same.error().message, HasSubstr("coincide"));
}

}  // namespace
}  // namespace cell::rapt
