#include "cell/common/log.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace cell::log {
namespace {

using ::testing::HasSubstr;
using ::testing::MatchesRegex;
using ::testing::StartsWith;

TEST(LogFormat, IsKeyValueWithQuotedMessage) {
  const std::string line = format_line(Level::kWarn, "vision", "reject", "wrong image size",
                                       {{"camera", "eye"}, {"got", "640 x 480"}});
  EXPECT_THAT(line, StartsWith("ts="));
  EXPECT_THAT(line, HasSubstr(" lvl=warn svc=vision event=reject msg=\"wrong image size\""));
  EXPECT_THAT(line, HasSubstr(" camera=eye "));
  EXPECT_THAT(line, HasSubstr(" got=\"640 x 480\""));
  EXPECT_THAT(line, MatchesRegex("ts=[0-9]{4}-[0-9]{2}-[0-9]{2}T[0-9:.]+Z .*"));
}

TEST(LogFormat, EscapesQuotesAndNewlines) {
  const std::string line = format_line(Level::kInfo, "x", "e", "a \"b\"\nc", {{"k", ""}});
  EXPECT_THAT(line, HasSubstr("msg=\"a \\\"b\\\"\\nc\""));
  EXPECT_THAT(line, HasSubstr(" k=\"\""));
}

TEST(LogLevel, ParsesKnownNamesOnly) {
  Level level = Level::kInfo;
  EXPECT_TRUE(parse_level("debug", level));
  EXPECT_EQ(level, Level::kDebug);
  EXPECT_FALSE(parse_level("verbose", level));
  EXPECT_EQ(level, Level::kDebug);
}

TEST(LogFormat, HugeValuesAreCutAndSayHowLongTheyWere) {
  const std::string huge(1 << 20, 'x');
  const std::string accents = std::string(511, 'a') + "\xc3\xa9tail";  // e-acute at 511..512
  const std::string line =
      format_line(Level::kWarn, "task", "reject", huge, {{"spec", accents}, {"ok", "short"}});
  EXPECT_LT(line.size(), 1300U);
  EXPECT_NE(line.find(std::string(512, 'x') + "...(1048576 bytes)\""), std::string::npos) << line;
  EXPECT_NE(line.find("spec=\"" + std::string(511, 'a') + "...(517 bytes)\""), std::string::npos)
      << "a UTF-8 sequence was split";
  EXPECT_NE(line.find(" ok=short"), std::string::npos);
}

}  // namespace
}  // namespace cell::log
