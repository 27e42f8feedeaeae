#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "cell/testing/env.hpp"
#include "cli_run.hpp"
#include "session.hpp"

namespace cell::cellctl {
namespace {

using testing::cellctl;
using testing::CliRun;
using ::testing::HasSubstr;

std::string config(const std::string& name) {
  return cell::testing::source_dir() + "/config/rapt/" + name;
}

/// A file under a fresh temporary directory, removed with the fixture.
class RaptCommandsTest : public ::testing::Test {
 protected:
  RaptCommandsTest() {
    char pattern[] = "/tmp/cellctl-rapt-XXXXXX";
    dir_ = mkdtemp(pattern);
  }
  ~RaptCommandsTest() override {
    for (const std::string& f : files_) {
      std::remove(f.c_str());
    }
    rmdir(dir_.c_str());
  }
  std::string write(const std::string& name, const std::string& text) {
    std::string path = dir_ + "/" + name;
    std::ofstream(path) << text;
    files_.push_back(path);
    return path;
  }
  std::string dir_;
  std::vector<std::string> files_;
};

TEST_F(RaptCommandsTest, CheckIsSilentOnAGoodProgramAndListsEveryErrorOfABadOne) {
  const CliRun ok = cellctl({"rapt", "check", config("appendix_vi.rapt")});
  EXPECT_EQ(ok.code, kExitOk) << ok.err;
  EXPECT_EQ(ok.out, "");
  EXPECT_EQ(ok.err, "");
  const std::string bad = write("bad.rapt",
                                "body/b1; p1=point/0,0; terbod;\n"
                                "against/f1 of b1, f2 of b9;\n"
                                "terapt;\n");
  const CliRun r = cellctl({"rapt", "check", bad});
  EXPECT_EQ(r.code, kExitFailure);
  EXPECT_THAT(r.err, HasSubstr(bad + ":1:22: error: expected ',' after the y coordinate"));
  EXPECT_THAT(r.err, HasSubstr(bad + ":2:9: error: unknown feature 'f1' of body 'b1'"));
  EXPECT_THAT(r.err, HasSubstr(bad + ":2:25: error: unknown body 'b9'"));
  EXPECT_THAT(r.err, HasSubstr("3 error(s)"));
  const CliRun missing = cellctl({"rapt", "check", dir_ + "/nope.rapt"});
  EXPECT_EQ(missing.code, kExitUsage);
  EXPECT_THAT(missing.err, HasSubstr("cannot open"));
}

// The Appendix V program as JSON: nominal poses (column convention), the MF array in the
// thesis's notation before and after simplification, and every LOOK's prediction.
TEST_F(RaptCommandsTest, CompileJsonHasPosesMfArrayAndLookPredictions) {
  const CliRun r = cellctl({"rapt", "compile", config("appendix_v.rapt"), "--json"});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  const auto doc = nlohmann::json::parse(r.out);
  ASSERT_EQ(doc["bodies"].size(), 4U);
  EXPECT_EQ(doc["bodies"][3]["name"], "b3");
  // b3 in situation 3: columns are the axes (X = (1,0,0), Y = (0,-1,0), Z = (0,0,-1)),
  // translation (0, -150, 140) in the last column.
  const auto& b3 = doc["nominal"][3];
  ASSERT_EQ(b3["body"], "b3");
  const auto& m = b3["situations"][2]["world_T_body"];
  EXPECT_EQ(b3["situations"][2]["situation"], 3);
  EXPECT_DOUBLE_EQ(m[1][1].get<double>(), -1.0);
  EXPECT_DOUBLE_EQ(m[1][3].get<double>(), -150.0);
  EXPECT_DOUBLE_EQ(m[2][3].get<double>(), 140.0);
  EXPECT_DOUBLE_EQ(m[3][3].get<double>(), 1.0);
  const auto& before = doc["mf_array"]["before_simplification"][1];
  EXPECT_EQ(before["body"], "b1");
  EXPECT_EQ(before["entries"][5], "[4,6]");
  EXPECT_EQ(before["named"][5], "[b3,6]");
  EXPECT_EQ(doc["mf_array"]["after_simplification"][2]["entries"][12], "I");
  ASSERT_EQ(doc["looks"].size(), 8U);
  const auto& look = doc["looks"][4];  // situation 11, e2 of b2 through cam6
  EXPECT_EQ(look["situation"], 11);
  EXPECT_EQ(look["edge"], "e2");
  EXPECT_EQ(look["camera"], "cam6");
  EXPECT_NEAR(look["predicted"][1][0].get<double>(), 20.55556, 1e-5);
  EXPECT_NEAR(look["window"]["p2"][1].get<double>(), 13.98, 0.01);
  EXPECT_EQ(doc["packages"][0]["fixable"], true);
  EXPECT_THAT(doc["packages"][0]["route"].get<std::string>(), HasSubstr("agpp_agpp_lin"));
  EXPECT_EQ(doc["diagnostics"].size(), 1U);  // the situation 13 multi-reference warning
  // The text form prints the arrays as the thesis does.
  const CliRun text = cellctl({"rapt", "compile", config("appendix_v.rapt")});
  EXPECT_EQ(text.code, kExitOk);
  EXPECT_THAT(text.out, HasSubstr("MF array after simplification:"));
  EXPECT_THAT(text.out, HasSubstr("[4,16]"));
}

TEST_F(RaptCommandsTest, RunJsonHasVerifiedAndActualPosesAndCorrectedActions) {
  const CliRun r = cellctl({"rapt", "run", config("appendix_v.rapt"), "--readings",
                            config("appendix_v_readings.yaml"), "--lsq", "--json"});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  const auto doc = nlohmann::json::parse(r.out);
  const auto& pkg = doc["packages"][0];
  EXPECT_EQ(pkg["evaluated"], true);
  EXPECT_NEAR(pkg["verified_world_T_body"][1][3].get<double>(), -147.632, 1e-3);
  EXPECT_NEAR(pkg["fm"][1][3].get<double>(), -2.368, 1e-3);  // in b3's frame
  EXPECT_EQ(pkg["least_squares"]["free_parameters"], 1);
  // b1 in situation 4 follows the verified b3 (pointer 4,4, thesis (7.11)).
  const auto& b1 = doc["actual"][1];
  EXPECT_EQ(b1["body"], "b1");
  EXPECT_NEAR(b1["situations"][3]["world_T_body"][1][3].get<double>(), -142.632, 1e-3);
  ASSERT_FALSE(doc["actions"].empty());
  EXPECT_TRUE(doc["actions"][0].contains("method2_step2"));
  const CliRun text = cellctl(
      {"rapt", "run", config("appendix_v.rapt"), "--readings", config("appendix_v_readings.yaml")});
  EXPECT_EQ(text.code, kExitOk);
  EXPECT_THAT(text.out, HasSubstr("situation 3: b3 nominal"));
}

TEST_F(RaptCommandsTest, RunReportsReadingsThatMatchNoLook) {
  const std::string readings =
      write("r.yaml",
            "readings:\n"
            "  - {situation: 3, body: b3, edge: e7, camera: cam1, p1_mm: [1, 2], p2_mm: [3, 4]}\n");
  const CliRun r = cellctl({"rapt", "run", config("appendix_v.rapt"), "--readings", readings});
  EXPECT_EQ(r.code, kExitFailure);
  EXPECT_THAT(r.err, HasSubstr(readings + ":2:5: no LOOK of e7 of b3 with camera cam1"));
  EXPECT_THAT(r.err, HasSubstr("no reading for LOOK/e1 of b3, cam1 in situation 3"));
  const CliRun usage = cellctl({"rapt", "run", config("appendix_v.rapt")});
  EXPECT_EQ(usage.code, kExitUsage);  // --readings is required
}

}  // namespace
}  // namespace cell::cellctl
