#include "cell/rapt/mf_array.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <random>

#include "cell/testing/matchers.hpp"
#include "support.hpp"

namespace cell::rapt {
namespace {

using ::cell::testing::IsNearPose;
using ::testing::HasSubstr;

std::vector<std::string> row(const MfArray& a, int body) {
  std::vector<std::string> out;
  for (int s = 1; s <= a.situations(); ++s) {
    out.push_back(a.notation(body, s));
  }
  return out;
}

using Row = std::vector<std::string>;

// Digest 003 §6.1 / Appendix V section 2: the MF array built by the linking rules, exactly.
TEST(MfArrayAppendixV, LinkingRulesGiveThePrintedArray) {
  const MfArray& a = testing::appendix_v().mf_before;
  EXPECT_EQ(row(a, 1), Row(16, "I"));
  EXPECT_EQ(row(a, 2), (Row{"I", "2,1", "2,2", "4,4", "2,4", "[4,6]", "2,6", "2,7", "2,8", "P",
                            "2,10", "3,12", "[3,13]", "2,13", "[3,15]", "[4,16]"}));
  EXPECT_EQ(row(a, 3), (Row{"I", "3,1", "3,2", "3,3", "3,4", "3,5", "3,6", "3,7", "3,8", "3,9", "P",
                            "3,11", "1,13", "3,13", "4,15", "[4,16]"}));
  EXPECT_EQ(row(a, 4), (Row{"I", "4,1", "P", "4,3", "4,4", "1,6", "4,6", "4,7", "4,8", "[2,10]",
                            "4,10", "4,11", "4,12", "P", "4,14", "1,16"}));
}

// Digest §6.1: the array after simplification, exactly.
TEST(MfArrayAppendixV, SimplificationGivesThePrintedArray) {
  const MfArray& a = testing::appendix_v().mf_after;
  EXPECT_EQ(row(a, 1), Row(16, "I"));
  EXPECT_EQ(row(a, 2), (Row{"I", "I", "I", "4,4", "2,4", "[4,6]", "2,6", "2,7", "2,8", "P", "2,10",
                            "3,12", "[3,13]", "2,13", "[3,15]", "[4,16]"}));
  EXPECT_EQ(row(a, 3), (Row{"I", "I", "I", "I", "I", "I", "I", "I", "I", "I", "P", "3,11", "I", "I",
                            "4,15", "[4,16]"}));
  EXPECT_EQ(row(a, 4), (Row{"I", "I", "P", "4,3", "4,4", "I", "I", "I", "I", "[2,10]", "4,10",
                            "4,11", "4,12", "P", "4,14", "I"}));
  const CompiledProgram& cp = testing::appendix_v();
  EXPECT_EQ(a.named(2, 16, cp.body_names), "[b3,16]");
  EXPECT_EQ(a.named(3, 15, cp.body_names), "b3,15");
}

// Digest §6.1: situation 13 points b2 at the world although the first relation names b3; the
// multi-reference check fails (b3's factor depends on vision) and is reported as a warning.
TEST(MfArrayAppendixV, Situation13MultiReferenceCheckWarnsAndUsesTheWorld) {
  const CompiledProgram& cp = testing::appendix_v();
  ASSERT_EQ(cp.link.warnings.size(), 1U);
  EXPECT_EQ(cp.link.warnings[0].first.line, 213U);
  EXPECT_THAT(cp.link.warnings[0].second, HasSubstr("several bodies (b3, world)"));
  EXPECT_EQ(cp.link.rules[12][2], "T1");  // b2 in situation 13
}

LinkEvent move(int body, int member = 0, std::vector<int> refs = {}) {
  LinkEvent e;
  e.kind = LinkEvent::Kind::kMove;
  e.body = body;
  e.specified = !refs.empty();
  e.referenced_member = member == 0 ? body : member;
  e.references = std::move(refs);
  return e;
}

LinkEvent verify(int body, int package) {
  LinkEvent e;
  e.kind = LinkEvent::Kind::kVision;
  e.body = body;
  e.package = package;
  e.inviolate_references = {1};
  return e;
}

LinkChange tie(int a, int b) { return LinkChange{true, a, b, false}; }
LinkChange untie(int a, int b) { return LinkChange{false, a, b, false}; }

const std::vector<std::string> kNames{"world", "b1", "b2", "b3"};

// Digest §4.6, the A1/A2 example of thesis §8.1.3 (its printed table is garbled; rebuilt from
// the rules): b1 moved (A1), verified, b2 moved parallel (A1), turned and fixed to b1 (A2),
// verified.
TEST(MfLinking, ThesisSection813ExampleOfA1AndA2) {
  LinkInput in;
  in.bodies = 3;
  in.situations = 6;
  in.events = {{}, move(2), verify(2, 0), move(3), move(3, 3, {2}), verify(3, 1)};
  in.changes.resize(6);
  const MfArray a = link(in, kNames).array;
  EXPECT_EQ(row(a, 2), (Row{"I", "2,1", "P", "2,3", "2,4", "2,5"}));
  EXPECT_EQ(row(a, 3), (Row{"I", "3,1", "3,2", "3,3", "2,5", "P"}));
}

// Digest §4.6, the TIE example of thesis §8.2.6 (the array is missing from the OCR; these are
// the entries the remarks' rules give, digest [derived]).
TEST(MfLinking, ThesisSection826ExampleOfTieRulesT1ToT8) {
  LinkInput in;
  in.bodies = 4;
  in.situations = 11;
  in.events = {{},
               move(2, 2, {3}),  // i+1 A2: b1 -> b2
               move(2, 2, {1}),  // i+2 T1: b1 -> world, b2 b3 triples
               move(2),          // i+3 T5/T4
               verify(3, 0),     // i+4 T7
               move(2, 2, {4}),  // i+5 T6
               move(2),          // i+6 T4
               verify(4, 1),     // i+7 T2
               move(4, 4, {1}),  // i+8 T1
               verify(2, 2),     // i+9 T7
               verify(3, 3)};    // i+10 T8
  in.changes.resize(11);
  in.changes[1] = {tie(2, 3), tie(2, 4)};
  in.changes[2] = {untie(2, 3)};
  in.changes[4] = {untie(2, 4)};
  in.changes[5] = {tie(2, 3), tie(2, 4)};
  in.changes[8] = {untie(2, 4), untie(2, 3)};
  const LinkResult r = link(in, kNames);
  const MfArray& a = r.array;
  EXPECT_EQ(row(a, 2),
            (Row{"I", "3,2", "1,3", "2,3", "[3,5]", "4,6", "2,6", "[4,8]", "[4,9]", "P", "2,10"}));
  EXPECT_EQ(row(a, 3),
            (Row{"I", "3,1", "[2,3]", "3,3", "P", "3,5", "3,6", "[4,8]", "[4,9]", "[2,10]", "P"}));
  EXPECT_EQ(row(a, 4),
            (Row{"I", "4,1", "[2,3]", "4,3", "[3,5]", "4,5", "4,6", "P", "1,9", "[2,10]", "4,10"}));
  EXPECT_EQ(r.rules[4][2], "T7");   // i+4: verification of b2
  EXPECT_EQ(r.rules[10][2], "T8");  // i+10: b2 again, after b1's piece was verified
  EXPECT_EQ(r.rules[10][1], "T8/T4");
}

// Thesis §5.3.2 and T9, R1: local packages change only the verified body.
TEST(MfLinking, LocalPackagesChangeOnlyTheVerifiedBody) {
  LinkInput in;
  in.bodies = 4;
  in.situations = 4;
  LinkEvent local_ref = verify(3, 0);
  local_ref.inviolate_references = {2};  // the reference b1 holds b2: local
  LinkEvent camera = verify(3, 1);
  camera.camera_bodies = {4};  // b3 is the camera, TIED to b2: R1
  in.events = {{}, {}, local_ref, camera};
  in.changes.resize(4);
  in.changes[0] = {tie(2, 3), tie(3, 4)};
  const LinkResult r = link(in, kNames);
  EXPECT_EQ(r.array.notation(3, 3), "P");
  EXPECT_EQ(r.array.notation(2, 3), "2,2");
  EXPECT_EQ(r.array.notation(4, 4), "4,3");
  ASSERT_EQ(r.scopes.size(), 2U);
  EXPECT_TRUE(r.scopes[0].local);
  EXPECT_THAT(r.scopes[0].reason, HasSubstr("INVIOLATE reference 'b1' is TIED"));
  EXPECT_TRUE(r.scopes[1].local);
  EXPECT_THAT(r.scopes[1].reason, HasSubstr("R1"));
}

// Digest §4.5 rules 1-3 on synthetic entries.
TEST(MfSimplification, RulesOneTwoAndThree) {
  MfArray a(3, 4);  // world, a (2), b (3)
  a.at(2, 2) = MfEntry::points_to(2, 1);
  a.at(2, 3) = MfEntry::verified(0);
  a.at(2, 4) = MfEntry::points_to(2, 3);
  a.at(3, 2) = MfEntry::points_to(3, 1);
  a.at(3, 3) = MfEntry::triple_of(3, 3, 2);  // [(3,2),(2,2),(2,3)]
  a.at(3, 4) = MfEntry::triple_of(3, 4, 2);  // [(3,3),(2,3),(2,4)], (2,4) points to (2,3)
  const MfArray s = simplify(a);
  EXPECT_EQ(s.notation(2, 2), "I");  // rule 1
  EXPECT_EQ(s.notation(2, 3), "P");
  EXPECT_EQ(s.notation(2, 4), "2,3");  // a pointer to P is kept
  EXPECT_EQ(s.notation(3, 2), "I");
  EXPECT_EQ(s.notation(3, 3), "2,3");  // rule 2: p1, p2 are I -> p3
  EXPECT_EQ(s.notation(3, 4), "3,3");  // rule 3: p3 points to p2 -> p1
  EXPECT_FALSE(resolves_to_identity(s, {3, 4}));
  MfArray b(3, 3);
  b.at(2, 2) = MfEntry::verified(0);
  b.at(3, 2) = MfEntry::points_to(3, 1);
  b.at(3, 3) = MfEntry::triple_of(3, 3, 1);    // [(3,2),(1,2),(1,3)]: p2, p3 are the world
  EXPECT_EQ(simplify(b).notation(3, 3), "I");  // rule 3 then rule 1
}

// The run-time equations in column form against the thesis's row form, on random poses.
class MfEquations : public ::testing::Test {
 protected:
  Pose random_pose() {
    Pose p = Pose::Identity();
    p.linear() =
        Eigen::Quaterniond(n_(rng_), n_(rng_), n_(rng_), n_(rng_)).normalized().toRotationMatrix();
    p.translation() = 50.0 * Eigen::Vector3d(n_(rng_), n_(rng_), n_(rng_));
    return p;
  }
  static Eigen::Matrix4d R(const Pose& p) { return to_thesis(p); }  // row form
  std::mt19937 rng_{11};
  std::normal_distribution<double> n_{0.0, 1.0};
};

TEST_F(MfEquations, ColumnFormsEqualTheThesisRowForms) {
  for (int i = 0; i < 20; ++i) {
    const Pose pn_a = random_pose(), pn_b = random_pose(), fm_b = random_pose();
    const Pose pv = random_pose();
    // (7.2) FM = PV ** PN^-1
    EXPECT_TRUE(R(mf_equations::from_verified(pn_a, pv)).isApprox(R(pv) * R(pn_a).inverse(), 1e-9));
    // (7.1) PV = FM ** PN
    EXPECT_TRUE(R(pn_a * mf_equations::from_verified(pn_a, pv)).isApprox(R(pv), 1e-9));
    // (7.11) FM_a = PN_a ** PN_b^-1 ** FM_b ** PN_b ** PN_a^-1
    EXPECT_TRUE(
        R(mf_equations::specified(pn_a, pn_b, fm_b))
            .isApprox(R(pn_a) * R(pn_b).inverse() * R(fm_b) * R(pn_b) * R(pn_a).inverse(), 1e-9));
    // (8.11) FM_b(i+1) = FM_bi ** PN_bi ** (FM_ai ** PN_ai)^-1 ** FM_a(i+1) ** PN_a(i+1) **
    //        PN_b(i+1)^-1
    const Pose fm_bi = random_pose(), pn_bi = random_pose(), fm_ai = random_pose();
    const Pose pn_ai = random_pose(), fm_aj = random_pose(), pn_aj = random_pose();
    const Pose pn_bj = random_pose();
    EXPECT_TRUE(R(mf_equations::triple(fm_bi, pn_bi, fm_ai, pn_ai, fm_aj, pn_aj, pn_bj))
                    .isApprox(R(fm_bi) * R(pn_bi) * (R(fm_ai) * R(pn_ai)).inverse() * R(fm_aj) *
                                  R(pn_aj) * R(pn_bj).inverse(),
                              1e-9));
  }
}

// Appendix III (digest §4.4 A2): if PV_b PV_c^-1 = PN_b PN_c^-1, the FM of a computed from b
// by (7.11) equals the one computed from c. Appendix IV (TIEs) is the same identity for (8.11)
// with simplification rule 2.
TEST_F(MfEquations, AppendixIIIBothReferencesGiveTheSameFactor) {
  for (int i = 0; i < 20; ++i) {
    const Pose pn_a = random_pose(), pn_b = random_pose(), pn_c = random_pose();
    const Pose fm_b = random_pose();
    const Pose pv_b = pn_b * fm_b;
    const Pose pv_c = pv_b * pn_b.inverse() * pn_c;  // keeps b relative to c as planned
    const Pose fm_c = pn_c.inverse() * pv_c;
    EXPECT_THAT(mf_equations::specified(pn_a, pn_b, fm_b),
                IsNearPose(mf_equations::specified(pn_a, pn_c, fm_c), 1e-9));
    // Rule 2: with FM_bi = FM_ai = I and b TIED to a (PN_b(i+1) PN_a(i+1)^-1 = PN_bi PN_ai^-1)
    // the triple equals the pointer p3 (7.11).
    const Pose pn_aj = random_pose();
    const Pose pn_bj = pn_aj * pn_a.inverse() * pn_b;  // b keeps its pose relative to a
    EXPECT_THAT(
        mf_equations::triple(Pose::Identity(), pn_b, Pose::Identity(), pn_a, fm_c, pn_aj, pn_bj),
        IsNearPose(mf_equations::specified(pn_bj, pn_aj, fm_c), 1e-9));
  }
}

}  // namespace
}  // namespace cell::rapt
