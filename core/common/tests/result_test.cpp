#include "cell/common/result.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/testing/matchers.hpp"

namespace cell {
namespace {

using ::cell::testing::IsErr;
using ::cell::testing::IsErrWith;
using ::cell::testing::IsOk;

Result<int> parse_positive(int x) {
  if (x <= 0) {
    return Error{Errc::kOutOfRange, "must be > 0, got " + std::to_string(x)};
  }
  return x;
}

Status chain(int x) {
  CELL_TRY(parse_positive(x));
  return ok_status();
}

TEST(Result, HoldsValueOrError) {
  EXPECT_THAT(parse_positive(3), IsOk());
  EXPECT_EQ(*parse_positive(3), 3);
  EXPECT_THAT(parse_positive(-2), IsErrWith(Errc::kOutOfRange, "got -2"));
  EXPECT_EQ(parse_positive(-2).value_or(7), 7);
}

TEST(Result, TryPropagatesTheFirstError) {
  EXPECT_THAT(chain(1), IsOk());
  EXPECT_THAT(chain(0), IsErr(Errc::kOutOfRange));
}

TEST(Result, MovesOutOwnedValues) {
  Result<std::unique_ptr<int>> r(std::make_unique<int>(5));
  std::unique_ptr<int> p = std::move(r).value();
  ASSERT_NE(p, nullptr);
  EXPECT_EQ(*p, 5);
}

TEST(Result, ErrcNamesAreStable) {
  EXPECT_EQ(to_string(Errc::kConfig), "config");
  EXPECT_EQ(to_string(Errc::kTimeout), "timeout");
  EXPECT_EQ(to_string(Errc::kOutOfRange), "out_of_range");
}

TEST(ResultDeathTest, ValueOfAnErrorAborts) {
  EXPECT_DEATH((void)parse_positive(-1).value(), "got -1");
}

}  // namespace
}  // namespace cell
