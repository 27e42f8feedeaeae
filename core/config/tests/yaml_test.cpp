#include "cell/config/yaml.hpp"

#include <cmath>
#include <numbers>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/testing/matchers.hpp"

namespace cell::config {
namespace {

using ::cell::testing::IsErr;
using ::cell::testing::IsErrWith;
using ::cell::testing::IsOk;
using ::testing::HasSubstr;

Document parse(const std::string& text) {
  auto doc = load_string(text, "robot.yaml");
  EXPECT_TRUE(doc) << doc.error().message;
  return *doc;
}

TEST(MapReader, ReadsTypedValues) {
  const Document doc = parse("name: ibm7545\nlink1_mm: 400\nhomed: true\nlimits: [1, 2.5]\n");
  MapReader r(doc, doc.root, "");
  std::string name;
  double link = 0;
  bool homed = false;
  std::vector<double> limits;
  r.required("name", name);
  r.required("link1_mm", link);
  r.optional("homed", homed);
  r.optional("limits", limits);
  ASSERT_THAT(r.finish(), IsOk());
  EXPECT_EQ(name, "ibm7545");
  EXPECT_DOUBLE_EQ(link, 400.0);
  EXPECT_TRUE(homed);
  EXPECT_EQ(limits, (std::vector<double>{1.0, 2.5}));
}

TEST(MapReader, NamesFileLineAndKeyOfAWrongType) {
  const Document doc = parse("name: a\nlink1_mm: four hundred\n");
  MapReader r(doc, doc.root, "");
  std::string name;
  double link = 0;
  r.required("name", name);
  r.required("link1_mm", link);
  EXPECT_THAT(r.finish(), IsErrWith(Errc::kConfig,
                                    "robot.yaml:2:11: key 'link1_mm': expected a finite number, "
                                    "got 'four hundred'"));
}

TEST(MapReader, ReportsUnknownKeysWithTheirLocation) {
  const Document doc = parse("service:\n  id: x\n  domian_id: 3\n");
  MapReader r(doc, doc.root, "");
  MapReader s = r.child("service");
  std::string id;
  std::uint32_t domain = 0;
  s.optional("id", id);
  s.optional("domain_id", domain);
  r.absorb(s);
  EXPECT_THAT(r.finish(), IsErrWith(Errc::kConfig, "robot.yaml:3:3: unknown key 'service.domian_id'"));
}

TEST(MapReader, ReportsEveryErrorAtOnce) {
  const Document doc = parse("a: x\nb: -1\nc: 1\n");
  MapReader r(doc, doc.root, "");
  double a = 0;
  std::uint32_t b = 0;
  r.required("a", a);
  r.required("b", b);
  r.required("missing", a);
  const Status s = r.finish();
  ASSERT_THAT(s, IsErr(Errc::kConfig));
  EXPECT_THAT(s.error().message, HasSubstr("key 'a'"));
  EXPECT_THAT(s.error().message, HasSubstr("robot.yaml:2:4: key 'b': expected an unsigned"));
  EXPECT_THAT(s.error().message, HasSubstr("missing required key 'missing'"));
  EXPECT_THAT(s.error().message, HasSubstr("unknown key 'c'"));
}

TEST(MapReader, ConvertsDegreesAtTheEdge) {
  const Document doc = parse("tolerance_deg: 1.0\n");
  MapReader r(doc, doc.root, "");
  double tol_rad = 0;
  r.required_deg("tolerance_deg", tol_rad);
  ASSERT_THAT(r.finish(), IsOk());
  EXPECT_NEAR(tol_rad, std::numbers::pi / 180.0, 1e-15);
}

TEST(MapReader, RejectsNonFiniteNumbers) {
  const Document doc = parse("x: .nan\n");
  MapReader r(doc, doc.root, "");
  double x = 0;
  r.required("x", x);
  EXPECT_THAT(r.finish(), IsErrWith(Errc::kConfig, "expected a finite number"));
}

TEST(LoadFile, MissingFileNamesThePath) {
  EXPECT_THAT(load_file("/nonexistent/cell.yaml"),
              IsErrWith(Errc::kConfig, "/nonexistent/cell.yaml: cannot open"));
}

TEST(LoadString, SyntaxErrorHasLineAndColumn) {
  EXPECT_THAT(load_string("a: [1, 2\nb: 3\n", "bad.yaml"),
              IsErrWith(Errc::kConfig, "bad.yaml:"));
}

TEST(MapReader, SectionThatIsNotAMapIsAnError) {
  const Document doc = parse("service: 5\n");
  MapReader r(doc, doc.root, "");
  MapReader s = r.child("service");
  std::string id;
  s.optional("id", id);
  r.absorb(s);
  EXPECT_THAT(r.finish(), IsErrWith(Errc::kConfig, "'service' must be a map"));
}

}  // namespace
}  // namespace cell::config
