#include "cell/rapt/parser.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/rapt/lexer.hpp"
#include "support.hpp"

namespace cell::rapt {
namespace {

using testing::has_diagnostic;
using ::testing::HasSubstr;

TEST(Lexer, TokensCarryLineAndColumnAndRemarksVanishAcrossLines) {
  Diagnostics d;
  const auto t = lex("p1=POINT/ -20, 0.5,1e1;\n  remark two\n lines;  TerApt;", d);
  ASSERT_FALSE(d.has_errors()) << d.format_all();
  ASSERT_EQ(t.size(), 13U);
  EXPECT_EQ(t[0].kind, TokenKind::kIdent);
  EXPECT_EQ(t[0].text, "p1");
  EXPECT_EQ(t[2].loc, (SourceLoc{1, 4}));
  EXPECT_TRUE(keyword_is(t[2], "point"));  // case-insensitive
  EXPECT_EQ(t[4].kind, TokenKind::kNumber);
  EXPECT_DOUBLE_EQ(t[4].number, -20.0);
  EXPECT_EQ(t[4].loc, (SourceLoc{1, 11}));
  EXPECT_DOUBLE_EQ(t[6].number, 0.5);
  EXPECT_DOUBLE_EQ(t[8].number, 10.0);
  EXPECT_EQ(t[9].kind, TokenKind::kSemicolon);
  // The remark (two lines, its ';' included) is gone: next is TerApt on line 3.
  EXPECT_TRUE(keyword_is(t[10], "terapt"));
  EXPECT_EQ(t[10].loc, (SourceLoc{3, 10}));
  EXPECT_EQ(t.back().kind, TokenKind::kEnd);
}

TEST(Lexer, ReportsBadCharactersAndUnterminatedRemarksWithPositions) {
  Diagnostics d;
  (void)lex("a $ b;\n remark no end", d);
  EXPECT_EQ(d.error_count(), 2U) << d.format_all();
  EXPECT_TRUE(has_diagnostic(d, 1, 3, "unexpected character '$'"));
  EXPECT_TRUE(has_diagnostic(d, 2, 2, "REMARK is not terminated"));
}

TEST(Lexer, RejectsNumbersOutOfRange) {
  Diagnostics d;
  (void)lex("p=point/1e999,0,0;", d);
  EXPECT_TRUE(has_diagnostic(d, 1, 9, "out of range")) << d.format_all();
}

TEST(Parser, ParsesEveryStatementFormOfTheThesis) {
  const char* src = R"(
BODY/b1;
  p1=point/0,0,0; p2=point/20,0,0; p3=point/20,-20,0; c1=circle/center,p1,radius,10;
  f1=face/p1,p2,p3,zsmall; f6=face/horiz,25,zsmall;
  l1=line/p2,p3; e1=edge/l1,ysmall; s1=shaft/axis,l1,radius,5,ysmall; h1=hole/c1,zlarge;
  ball=sphface/p1,5; v1=vertex/p2;
TERBOD;
link=subass/temp; fits/s1 of b1, h1 of b1; tersub; issub/link; nosub/link; notsub/link;
cam1=camera/position,p0,theta,0,phi,75,psi,0,focus,75;
cam2=camera/tv1,p0,THETA,0,PHI,75,PSI,0,75;
cam3=camera/tv2,b1,33.1;
setcamera/cam1; agent/b1; tied/b1,b2; untied/b1,b2;
against/f1 of b1, f2; coplanar/f1,f2; fits/a,b; aligned/a,b; parax/a,b; parallel/a,b;
move/b1; move/b1,perpto,f1 of b1,200; move/b1,parlel,f1 of b1; move/b1,parallel,f6 of b1,30;
turn/b1,about,h1 of b1,45; turn/b1,about,h1 of b1;
tolerance/b3,trans,5; combine; tolerance/tran,5; inviolate/against,f1 of world,f7 of b3;
look/e1 of b3; look/e2 of b1,cam5; tercom;
TERAPT;)";
  Diagnostics d;
  const ast::Program p = parse(src, d);
  EXPECT_FALSE(d.has_errors()) << d.format_all();
  ASSERT_EQ(p.statements.size(), 47U);
  const auto& face = std::get<ast::FaceDef>(p.statements[5].body);
  EXPECT_EQ(face.form, ast::FaceDef::Form::kThreePoints);
  EXPECT_EQ(face.dir, Direction::kZSmall);
  const auto& horiz = std::get<ast::FaceDef>(p.statements[6].body);
  EXPECT_EQ(horiz.form, ast::FaceDef::Form::kHoriz);
  EXPECT_DOUBLE_EQ(horiz.height, 25.0);
  const auto& cam = std::get<ast::CameraDef>(p.statements[20].body);
  EXPECT_FALSE(cam.general);
  EXPECT_FALSE(cam.physical.has_value());  // POSITION
  EXPECT_DOUBLE_EQ(cam.phi_deg, 75.0);
  const auto& cam2 = std::get<ast::CameraDef>(p.statements[21].body);
  EXPECT_EQ(cam2.physical->text, "tv1");
  const auto& cam3 = std::get<ast::CameraDef>(p.statements[22].body);
  EXPECT_TRUE(cam3.general);
  EXPECT_EQ(cam3.place.text, "b1");
  const auto& rel = std::get<ast::RelationStmt>(p.statements[27].body);
  EXPECT_EQ(rel.a.display(), "f1 of b1");
  EXPECT_EQ(rel.b.display(), "f2");
  const auto& move = std::get<ast::ActionStmt>(p.statements[34].body);
  EXPECT_EQ(move.mode, ast::ActionMode::kPerpto);
  EXPECT_DOUBLE_EQ(*move.amount, 200.0);
  const auto& par = std::get<ast::ActionStmt>(p.statements[36].body);
  EXPECT_EQ(par.mode, ast::ActionMode::kParlel);  // PARALLEL spelling
  const auto& local = std::get<ast::Tolerance>(p.statements[41].body);
  EXPECT_FALSE(local.body.has_value());
  const auto& inv = std::get<ast::Inviolate>(p.statements[42].body);
  EXPECT_EQ(inv.a.display(), "f1 of world");
}

TEST(Parser, ReportsEveryErrorOfTheFileWithWhatWasExpected) {
  const char* src =
      "body/b1;\n"
      "p1=point/0,0;\n"   // missing z
      "p2=point/1,2,3\n"  // missing ';' (the next statement is swallowed)
      "p3=point/1,2,3;\n"
      "f1=face/p1,p2,p3,sideways;\n"  // bad direction
      "frobnicate/x;\n"               // unknown statement
      "terbod;\n"
      "terapt;\n"
      "move/b1;\n";  // after TERAPT
  Diagnostics d;
  const ast::Program p = parse(src, d);
  EXPECT_EQ(d.error_count(), 5U) << d.format_all();
  EXPECT_TRUE(has_diagnostic(d, 2, 13, "expected ',' after the y coordinate, got ';'"));
  EXPECT_TRUE(has_diagnostic(d, 4, 1, "expected ';' at the end of the statement, got 'p3'"));
  EXPECT_TRUE(has_diagnostic(d, 5, 18, "expected a direction (XLARGE"));
  EXPECT_TRUE(has_diagnostic(d, 6, 1, "unknown statement 'frobnicate'"));
  EXPECT_TRUE(has_diagnostic(d, 9, 1, "statement after TERAPT"));
  // The good statements survive: body, terbod, terapt.
  EXPECT_EQ(p.statements.size(), 3U);
  EXPECT_THAT(d.format_all(), HasSubstr("<input>:2:13: error: expected ','"));
}

TEST(Parser, MissingTerAptIsAnErrorAtTheEnd) {
  Diagnostics d;
  (void)parse("body/b1; terbod;\n", d);
  EXPECT_TRUE(has_diagnostic(d, 2, 1, "missing TERAPT")) << d.format_all();
}

}  // namespace
}  // namespace cell::rapt
