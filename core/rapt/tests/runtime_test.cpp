#include "cell/rapt/runtime.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <numbers>
#include <random>

#include "cell/testing/matchers.hpp"
#include "support.hpp"

namespace cell::rapt {
namespace {

using ::cell::testing::IsErr;
using ::cell::testing::IsNearPose;
using ::testing::HasSubstr;
using testing::thesis_pose;
using V = Eigen::Vector3d;

constexpr double kRunTolMm = 1e-6;

const RunResult& appendix_v_run() {
  static const RunResult r = [] {
    auto out = run(testing::appendix_v(), testing::appendix_v_readings());
    if (!out) {
      ADD_FAILURE() << out.error().message;
      return RunResult{};
    }
    return *out;
  }();
  return r;
}

// Digest §6.1: the printed verified ("real") positions of situations 3 and 10, through the
// whole run (readings file, MF array, (7.2)).
TEST(RunAppendixV, ReproducesThePrintedVerifiedPositions) {
  const CompiledProgram& cp = testing::appendix_v();
  const RunResult& r = appendix_v_run();
  ASSERT_EQ(r.packages.size(), 4U);
  EXPECT_THAT(
      r.packages[0].verified,
      IsNearPose(thesis_pose(V(1, 0, 0), V(0, -1, 0), V(0, 0, -1), V(0, -147.632, 140)), 1e-3));
  // Situation 10, the consistency check: the thesis got -5.000019.
  EXPECT_THAT(
      r.packages[1].verified,
      IsNearPose(thesis_pose(V(0, 0, -1), V(0, 1, 0), V(1, 0, 0), V(200, -5.000019, 35)), 1e-4));
  const int b3 = testing::body(cp, "b3");
  EXPECT_THAT(r.actual_pose(b3, 3), IsNearPose(r.packages[0].verified, 1e-12));
  // FM of b3 in situation 3: a translation of 2.368 mm, (0, -2.368, 0) in b3's local frame
  // (the thesis's row form prints it in the last row), digest §8.2 case 2.
  const Pose& fm = r.fm_of(b3, 3);
  EXPECT_TRUE(fm.linear().isIdentity(1e-12));
  EXPECT_NEAR(fm.translation().y(), -2.368, 1e-3);
  EXPECT_NEAR(fm.translation().x(), 0.0, 1e-12);
}

// Digest §8.2 case 7 [derived]: the propagation through situations 4-6.
TEST(RunAppendixV, PropagatesSituation3ThroughTheTieAndTheTurn) {
  const CompiledProgram& cp = testing::appendix_v();
  const RunResult& r = appendix_v_run();
  const int b1 = testing::body(cp, "b1");
  const int b3 = testing::body(cp, "b3");
  const double dy = r.packages[0].verified.translation().y() + 150.0;  // +2.368
  // (7.11): b1 placed on b3's actual position: FM_b1,4 = translation (2.368, 0, 0) in b1's frame.
  EXPECT_TRUE(r.fm_of(b1, 4).translation().isApprox(V(dy, 0, 0), 1e-9));
  EXPECT_TRUE(r.actual_pose(b1, 4).translation().isApprox(V(20, -145 + dy, 35), 1e-9));
  EXPECT_NEAR(r.actual_pose(b1, 4).translation().y(), -142.632, 1e-3);
  // Situation 5: b3 and b1 move up together (A1 / T4).
  EXPECT_TRUE(r.actual_pose(b3, 5).translation().isApprox(V(0, -150 + dy, 290), 1e-9));
  EXPECT_TRUE(r.actual_pose(b1, 5).translation().isApprox(V(20, -145 + dy, 185), 1e-9));
  // Situation 6: b3 is turned against the world (pointer to the world: I), and the triple
  // [4,6] of b1 evaluates to I.
  EXPECT_THAT(r.fm_of(b3, 6), IsNearPose(Pose::Identity(), 1e-9));
  EXPECT_THAT(r.fm_of(b1, 6), IsNearPose(Pose::Identity(), 1e-9));
  // The actual action of b1 from 5 to 6, in row form: rotation diag(1,-1,-1), last row
  // (0, -267.632, 350); nominal (0, -270, 350); method 1's correction a translation.
  const ActionOutcome* a = nullptr;
  for (const ActionOutcome& x : r.actions) {
    if (x.situation == 6 && x.body == b1) {
      a = &x;
    }
  }
  ASSERT_NE(a, nullptr);
  const Eigen::Matrix4d ta = to_thesis(a->actual);
  const Eigen::Matrix3d flip = V(1, -1, -1).asDiagonal();
  const Eigen::Matrix3d ta_rot = ta.topLeftCorner(3, 3);
  EXPECT_TRUE(ta_rot.isApprox(flip, 1e-9));
  EXPECT_TRUE(ta.row(3).head<3>().transpose().isApprox(V(0, -270 + dy, 350), 1e-9));
  EXPECT_TRUE(to_thesis(a->nominal).row(3).head<3>().transpose().isApprox(V(0, -270, 350), 1e-9));
  EXPECT_TRUE(a->correction.linear().isIdentity(1e-9));
  EXPECT_NEAR(a->correction.translation().norm(), dy, 1e-9);
}

// Thesis (7.13)-(7.19): the actions' decompositions hold for every move of the run.
TEST(RunAppendixV, ActionsDecomposeAsTheThesisSays) {
  const CompiledProgram& cp = testing::appendix_v();
  const RunResult& r = appendix_v_run();
  ASSERT_FALSE(r.actions.empty());
  for (const ActionOutcome& a : r.actions) {
    const Pose& pv0 = r.actual_pose(a.body, a.situation - 1);
    const Pose& pv1 = r.actual_pose(a.body, a.situation);
    const Pose& pn0 = cp.nominal_pose(a.body, a.situation - 1);
    const Pose& pn1 = cp.nominal_pose(a.body, a.situation);
    EXPECT_THAT(a.actual * pv0, IsNearPose(pv1, 1e-9));                 // (7.13) one step
    EXPECT_THAT(a.nominal * pn0, IsNearPose(pn1, 1e-9));                // (7.12)
    EXPECT_THAT(a.nominal * a.correction, IsNearPose(a.actual, 1e-9));  // (7.14) TA = TC ** TN
    EXPECT_THAT(a.step1 * pv0, IsNearPose(a.intermediate, 1e-9));       // method 2, step 1
    EXPECT_THAT(a.step2 * a.intermediate, IsNearPose(pv1, 1e-9));       // (7.18)-(7.19)
    // PN' has the same pose relative to PV(s) as PN(s-1) to PN(s): the approach is kept.
    EXPECT_THAT(pv1.inverse() * a.intermediate, IsNearPose(pn1.inverse() * pn0, 1e-9));
  }
}

/// Checks every instance's actual pose against what its (simplified) MF entry says.
void expect_links_hold(const CompiledProgram& cp, const RunResult& r) {
  for (int b = 1; b <= r.bodies; ++b) {
    for (int s = 1; s <= r.situations; ++s) {
      const MfEntry& e = cp.mf_after.at(b, s);
      const Pose pv = r.actual_pose(b, s);
      const std::string where = cp.body_names[static_cast<std::size_t>(b - 1)] + "@" +
                                std::to_string(s) + " " + cp.mf_after.notation(b, s);
      switch (e.kind) {
        case MfEntry::Kind::kIdentity:
          EXPECT_THAT(pv, IsNearPose(cp.nominal_pose(b, s), 1e-9)) << where;
          break;
        case MfEntry::Kind::kVerified:
          EXPECT_THAT(pv,
                      IsNearPose(r.packages[static_cast<std::size_t>(e.package)].verified, 1e-9))
              << where;
          break;
        case MfEntry::Kind::kPointer: {
          const int c = e.pointer.body;
          const int t = e.pointer.situation;
          if (c == b) {  // equality of factors
            EXPECT_THAT(r.fm_of(b, s), IsNearPose(r.fm_of(b, t), 1e-9)) << where;
          } else {  // b keeps its nominal pose relative to c's actual pose
            EXPECT_THAT(pv, IsNearPose(r.actual_pose(c, t) * cp.nominal_pose(c, t).inverse() *
                                           cp.nominal_pose(b, s),
                                       1e-9))
                << where;
          }
          break;
        }
        case MfEntry::Kind::kTriple: {  // b keeps its actual pose relative to a (the TIE)
          const MfRef a1 = e.triple[1];
          const MfRef a2 = e.triple[2];
          EXPECT_THAT(pv, IsNearPose(r.actual_pose(a2.body, a2.situation) *
                                         r.actual_pose(a1.body, a1.situation).inverse() *
                                         r.actual_pose(b, s - 1),
                                     1e-9))
              << where;
          break;
        }
      }
    }
  }
}

TEST(RunAppendixV, EveryActualPoseObeysItsModifyingFactorEntry) {
  expect_links_hold(testing::appendix_v(), appendix_v_run());
}

/// Readings that image `truth` (world_T_body of the package's body) exactly, and the nominal
/// predictions for every other package.
std::vector<Reading> readings_for(const CompiledProgram& cp, int package, const Pose& truth) {
  std::vector<Reading> out;
  for (const CompiledPackage& pkg : cp.packages) {
    for (const CompiledLook& look : pkg.looks) {
      Reading r;
      r.situation = pkg.situation;
      r.body = cp.program.body(pkg.body).name;
      r.edge = cp.program.feature(look.decl.edge).name;
      const Camera& cam = cp.program.cameras[static_cast<std::size_t>(look.decl.camera)];
      r.camera = cam.name;
      if (pkg.index == package) {
        const CameraModel model{cam.world_T_camera, cam.focus};
        const auto [a, b] = cp.program.feature(look.decl.edge).edge_end_points();
        r.p1 = *model.project(truth * a);
        r.p2 = *model.project(truth * b);
      } else {
        r.p1 = look.predicted[0];
        r.p2 = look.predicted[1];
      }
      out.push_back(r);
    }
  }
  return out;
}

/// A random small rigid motion (in world axes, about the body origin) that keeps the package's
/// INVIOLATE AGPPs: rotation about their common normal and translation in their common plane
/// (or along their common line).
Pose random_inviolate_motion(const CompiledProgram& cp,
                             const CompiledPackage& pkg,
                             std::mt19937& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const Package& decl = cp.program.packages[static_cast<std::size_t>(pkg.index)];
  std::vector<V> normals;
  for (const InviolateDecl& inv : decl.inviolates) {
    normals.push_back((cp.nominal_pose(inv.reference.body, pkg.situation) *
                       cp.program.feature(inv.reference).body_T_feature)
                          .linear()
                          .col(0));
  }
  const Pose pn = cp.nominal_pose(pkg.body, pkg.situation);
  Pose motion = Pose::Identity();
  if (normals.size() == 1) {
    const V n = normals[0];
    const V e1 = any_perpendicular(n);
    const V e2 = n.cross(e1);
    motion.linear() = Eigen::AngleAxisd(0.05 * u(rng), n).toRotationMatrix();  // ~3 degrees
    motion.translation() = pn.translation() - motion.linear() * pn.translation() +
                           3.0 * u(rng) * e1 + 3.0 * u(rng) * e2;
  } else {
    motion.translation() = 3.0 * u(rng) * normals[0].cross(normals[1]).normalized();
  }
  return motion * pn;
}

// Property (digest §8.2; issue 8): displace a verified body by a random small rigid motion
// consistent with its INVIOLATEs, image its LOOK edges, run: the recovered pose is the
// displacement to 1e-6 mm, and every body linked to it through the MF array moves as the
// linking rules say (the nominal relative pose to the verified body, or the tied relative pose).
TEST(RunProperty, RecoversRandomDisplacementsAndPropagatesThemByTheLinkingRules) {
  const CompiledProgram& cp = testing::appendix_v();
  std::mt19937 rng(2024);
  for (const CompiledPackage& pkg : cp.packages) {
    for (int trial = 0; trial < 10; ++trial) {
      const Pose truth = random_inviolate_motion(cp, pkg, rng);
      auto r = run(cp, readings_for(cp, pkg.index, truth));
      ASSERT_TRUE(r) << r.error().message;
      EXPECT_THAT(r->packages[static_cast<std::size_t>(pkg.index)].verified,
                  IsNearPose(truth, kRunTolMm))
          << "situation " << pkg.situation;
      expect_links_hold(cp, *r);
    }
  }
  // One case spelled out: b3 displaced along y in situation 3 carries b1's placement in
  // situation 4 (A2 pointer, (7.11)) and both through the TIE in situations 5 and 6.
  const Pose truth = random_inviolate_motion(cp, cp.packages[0], rng);
  auto r = run(cp, readings_for(cp, 0, truth));
  ASSERT_TRUE(r);
  const int b1 = testing::body(cp, "b1");
  const int b3 = testing::body(cp, "b3");
  const Pose shift = truth * cp.nominal_pose(b3, 3).inverse();  // world-frame displacement
  EXPECT_THAT(r->actual_pose(b1, 4), IsNearPose(shift * cp.nominal_pose(b1, 4), kRunTolMm));
  EXPECT_THAT(r->actual_pose(b1, 5), IsNearPose(shift * cp.nominal_pose(b1, 5), kRunTolMm));
  EXPECT_THAT(r->actual_pose(b3, 5), IsNearPose(shift * cp.nominal_pose(b3, 5), kRunTolMm));
  EXPECT_THAT(r->actual_pose(b3, 6), IsNearPose(cp.nominal_pose(b3, 6), kRunTolMm));
}

// Appendix VI: the trial-1 pose (rotation -1.67 degrees about the vertical X, translation
// (0, -0.19, 0.12)) imaged through the program's camera is recovered exactly through the route
// e2 then e1 (the printed pixel readings themselves cannot be used: README).
TEST(RunAppendixVI, RecoversATrialOnePoseFromConsistentImages) {
  const CompiledProgram& cp = testing::appendix_vi();
  // The printed rotation rows (0, 0.9995763, -0.02910785), (0, 0.02910785, 0.9995763), made
  // exactly orthonormal: a rotation about X by atan2(-0.02910785, 0.9995763) = -1.668 deg.
  Pose truth = Pose::Identity();
  truth.linear() =
      Eigen::AngleAxisd(std::atan2(-0.02910785, 0.9995763), V::UnitX()).toRotationMatrix();
  truth.translation() = V(0, -0.1896315, 0.1235619);
  EXPECT_NEAR(to_thesis(truth)(1, 2), -0.02910785, 1e-7);
  auto r = run(cp, readings_for(cp, 0, truth));
  ASSERT_TRUE(r) << r.error().message;
  EXPECT_THAT(r->packages[0].verified, IsNearPose(truth, kRunTolMm));
  EXPECT_THAT(r->actual_pose(2, 2), IsNearPose(truth, kRunTolMm));
}

TEST(RunErrors, EveryUnmatchedOrMissingReadingIsNamed) {
  const CompiledProgram& cp = testing::appendix_v();
  std::vector<Reading> readings = testing::appendix_v_readings();
  ASSERT_EQ(readings.size(), 8U);
  readings[1].edge = "e9";               // unknown LOOK
  readings.push_back(readings[2]);       // duplicate
  readings.erase(readings.begin() + 4);  // situation 11, e2: missing
  auto r = run(cp, readings);
  ASSERT_THAT(r, IsErr(Errc::kInvalidArgument));
  const std::string& m = r.error().message;
  EXPECT_THAT(m, HasSubstr("appendix_v_readings.yaml:17:5: no LOOK of e9 of b3 with camera cam1 "
                           "in situation 3 (its LOOKs are: e1 of b3 with cam1, e2 of b3 with "
                           "cam1)"));
  EXPECT_THAT(m, HasSubstr("a second reading for LOOK e1 of b1 with cam5 in situation 10"));
  EXPECT_THAT(m, HasSubstr("no reading for LOOK/e2 of b2, cam6 in situation 11"));
}

// A live run (services/task): through situation s, only the packages up to s need readings,
// and what they give equals the whole run's up to s.
TEST(RunThrough, EvaluatesUpToASituationWithTheReadingsTakenSoFar) {
  const CompiledProgram& cp = testing::appendix_v();
  const RunResult& whole = appendix_v_run();
  std::vector<Reading> first;
  for (const Reading& r : testing::appendix_v_readings()) {
    if (r.situation <= 3) {
      first.push_back(r);
    }
  }
  RunOptions options;
  options.through_situation = 9;  // before the package of situation 10
  auto part = run(cp, first, options);
  ASSERT_TRUE(part) << part.error().message;
  for (int b = 1; b <= cp.program.body_count(); ++b) {
    for (int s = 1; s <= 9; ++s) {
      EXPECT_THAT(part->actual_pose(b, s), IsNearPose(whole.actual_pose(b, s), kRunTolMm))
          << "body " << b << " situation " << s;
    }
    // Past it: not evaluated (the identity FM).
    EXPECT_THAT(part->fm_of(b, 12), IsNearPose(Pose::Identity(), 0.0));
  }
  for (const ActionOutcome& a : part->actions) {
    EXPECT_LE(a.situation, 9);
  }
  EXPECT_FALSE(part->packages[1].evaluated);  // situation 10's
  // Through situation 10 its package needs its readings again.
  options.through_situation = 10;
  EXPECT_THAT(run(cp, first, options), IsErr(Errc::kInvalidArgument));
}

// An assembly's final relations checked at measured poses (tests/task/assembly_cell_test.cpp).
TEST(RelationResidual, IsZeroAtTheNominalPosesAndMeasuresADisplacement) {
  const CompiledProgram& cp = testing::appendix_v();
  const Program& p = cp.program;
  const Situation& sit = p.situation(16);
  ASSERT_EQ(sit.relations.size(), 3U);
  for (const RelationDecl& r : sit.relations) {
    const auto [rad, mm] = relation_residual(p, r, cp.nominal_pose(r.a.body, 16),
                                             cp.nominal_pose(r.b.body, 16));
    EXPECT_LT(rad, 1e-9);
    EXPECT_LT(mm, 1e-6);
  }
  // b3 slid 0.7 mm along the world's z and turned 1 degree about it: coplanar/f1 of b3, f3 of
  // world (a vertical face) is off by the turn; against/f3 of b3, f2 of world (the floor) by
  // the slide.
  const Pose moved = Pose(Eigen::Translation3d(0, 0, 0.7) *
                          Eigen::AngleAxisd(1.0 * std::numbers::pi / 180.0, V::UnitZ())) *
                     cp.nominal_pose(testing::body(cp, "b3"), 16);
  EXPECT_NEAR(relation_residual(p, sit.relations[0], moved, cp.nominal_pose(1, 16)).first,
              1.0 * std::numbers::pi / 180.0, 1e-9);
  EXPECT_GT(relation_residual(p, sit.relations[1], moved, cp.nominal_pose(1, 16)).second, 0.69);
}

TEST(RunErrors, ReadingsFilesAreCheckedKeyByKey) {
  auto bad = parse_readings(
      "readings:\n  - {situation: 3, body: b3, edge: e1, camera: cam1, p1_mm: [1, 2]}\n"
      "  - {situation: x, body: b3, edge: e1, camera: cam1, p1_mm: [1, 2], p2_mm: [1], "
      "colour: red}\n",
      "r.yaml");
  ASSERT_THAT(bad, IsErr(Errc::kConfig));
  EXPECT_THAT(bad.error().message, HasSubstr("readings[0].p2_mm"));
  EXPECT_THAT(bad.error().message, HasSubstr("r.yaml:3:"));
  EXPECT_THAT(bad.error().message, HasSubstr("colour"));
  EXPECT_THAT(load_readings("/nonexistent/readings.yaml"), IsErr(Errc::kIo));
}

// Beyond the thesis: least squares over every end point of every LOOK.
TEST(LeastSquares, AgreesWithTheRouteOnConsistentDataAndShowsDisagreement) {
  const CompiledProgram& cp = testing::appendix_v();
  std::mt19937 rng(5);
  const Pose truth = random_inviolate_motion(cp, cp.packages[2], rng);
  RunOptions options;
  options.least_squares = true;
  auto r = run(cp, readings_for(cp, 2, truth), options);
  ASSERT_TRUE(r) << r.error().message;
  ASSERT_TRUE(r->packages[2].lsq.has_value()) << r->packages[2].note;
  const LsqReport& ok = *r->packages[2].lsq;
  EXPECT_EQ(ok.free_parameters, 3);
  EXPECT_EQ(ok.residual_count, 4);
  EXPECT_LT(ok.final_rms, 1e-6);
  EXPECT_THAT(ok.verified, IsNearPose(truth, 1e-5));
  // The thesis's situation 3 data: its redundant second LOOK disagrees with the first (using it
  // would put b3 at y = -164.24 instead of -147.63), which the residual shows.
  auto thesis = run(cp, testing::appendix_v_readings(), options);
  ASSERT_TRUE(thesis) << thesis.error().message;
  const LsqReport& lsq = *thesis->packages[0].lsq;
  EXPECT_EQ(lsq.free_parameters, 1);  // two INVIOLATEs leave the slide along y
  EXPECT_GT(lsq.final_rms, 0.3);
  EXPECT_LE(lsq.final_rms, lsq.initial_rms);
  EXPECT_GT(lsq.shift_mm, 1.0);
  EXPECT_THAT(lsq.brief(), HasSubstr("over 4 end points"));
}

}  // namespace
}  // namespace cell::rapt
