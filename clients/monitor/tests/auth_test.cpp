#include "auth.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/testing/matchers.hpp"

namespace cell::monitor {
namespace {

using ::cell::testing::IsErr;
using ::testing::HasSubstr;
using ::testing::StartsWith;

constexpr int kFast = 1000;  // iterations for tests (production: kDefaultIterations)

TEST(Password, HashesVerifyAndDifferBySalt) {
  auto a = hash_password("s3cret", kFast);
  auto b = hash_password("s3cret", kFast);
  ASSERT_TRUE(a && b);
  EXPECT_THAT(*a, StartsWith("pbkdf2-sha256$1000$"));
  EXPECT_NE(*a, *b);
  EXPECT_TRUE(verify_password("s3cret", *a));
  EXPECT_TRUE(verify_password("s3cret", *b));
  EXPECT_FALSE(verify_password("s3cret ", *a));
  EXPECT_FALSE(verify_password("", *a));
}

// PBKDF2-HMAC-SHA256("password", "salt", 1000 iterations, 32 bytes), computed independently
// with Python's hashlib.pbkdf2_hmac.
TEST(Password, MatchesAnIndependentPbkdf2) {
  // salt "salt" = c2FsdA== in base64.
  EXPECT_TRUE(verify_password(
      "password", "pbkdf2-sha256$1000$c2FsdA==$YywoEuRtRgQQK6dhjp1tfS+BKPYma0oDJk0qBGC33LM="));
  EXPECT_FALSE(verify_password(
      "passw0rd", "pbkdf2-sha256$1000$c2FsdA==$YywoEuRtRgQQK6dhjp1tfS+BKPYma0oDJk0qBGC33LM="));
}

TEST(Password, MalformedHashesNeverMatch) {
  for (const char* bad : {"", "plain", "pbkdf2-sha256$", "pbkdf2-sha256$1000$$",
                          "pbkdf2-sha256$10$c2FsdA==$YywoEuRtRgQQK6dhjp1tfS+BKPYma0oDJk0qBGC33LM=",
                          "pbkdf2-sha256$x$c2FsdA==$Yywo", "pbkdf2-sha256$1000$c2FsdA==$***",
                          "pbkdf2-sha256$1000$c2FsdA==$YywoEuRt$extra",
                          "pbkdf2-sha256$99999999999$c2FsdA==$YywoEuRtRgQQK6dhjp1tfS+BKPYma0oDJk0qBGC33LM="}) {
    EXPECT_FALSE(verify_password("password", bad)) << bad;
  }
  EXPECT_THAT(hash_password("x", 10), IsErr(Errc::kInvalidArgument));
  EXPECT_THAT(hash_password("", kFast), IsErr(Errc::kInvalidArgument));
}

Authenticator make_auth() {
  return Authenticator({{"ada", "operator", hash_password("pw-ada", kFast).value()},
                        {"vic", "viewer", hash_password("pw-vic", kFast).value()}},
                       std::chrono::seconds(60));
}

TEST(Authenticator, SignsInAndOutWithRandomTokens) {
  auto auth = make_auth();
  auto t1 = auth.sign_in("ada", "pw-ada");
  auto t2 = auth.sign_in("ada", "pw-ada");
  ASSERT_TRUE(t1 && t2);
  EXPECT_EQ(t1->size(), 64U);
  EXPECT_NE(*t1, *t2);
  auto s = auth.session(*t1);
  ASSERT_TRUE(s);
  EXPECT_EQ(s->user, "ada");
  EXPECT_EQ(s->role, "operator");
  EXPECT_EQ(auth.session(*auth.sign_in("vic", "pw-vic"))->role, "viewer");
  auth.sign_out(*t1);
  EXPECT_FALSE(auth.session(*t1));
  EXPECT_TRUE(auth.session(*t2));
  EXPECT_FALSE(auth.session("not-a-token"));
  EXPECT_FALSE(auth.session(std::string(64, 'a')));
}

TEST(Authenticator, WrongPasswordAndUnknownUserLookTheSame) {
  auto auth = make_auth();
  auto a = auth.sign_in("ada", "nope");
  auto b = auth.sign_in("mallory", "nope");
  ASSERT_FALSE(a);
  ASSERT_FALSE(b);
  EXPECT_EQ(a.error().message, b.error().message);
  EXPECT_EQ(a.error().message, "unknown user or wrong password");
}

TEST(Authenticator, SessionsExpire) {
  auto auth = make_auth();
  auto t = auth.sign_in("ada", "pw-ada");
  ASSERT_TRUE(t);
  auth.advance_clock_for_test(std::chrono::seconds(59));
  EXPECT_TRUE(auth.session(*t));
  auth.advance_clock_for_test(std::chrono::seconds(2));
  EXPECT_FALSE(auth.session(*t));
  EXPECT_EQ(auth.session_count(), 0U);
}

TEST(Authenticator, LocksAUserOutAfterFiveFailures) {
  auto auth = make_auth();
  for (int i = 0; i < 5; ++i) {
    EXPECT_THAT(auth.sign_in("ada", "guess"), IsErr(Errc::kInvalidArgument));
  }
  auto locked = auth.sign_in("ada", "pw-ada");  // even the right password
  ASSERT_FALSE(locked);
  EXPECT_EQ(locked.error().code, Errc::kNotReady);
  EXPECT_THAT(locked.error().message, HasSubstr("too many failed sign-ins"));
  EXPECT_TRUE(auth.sign_in("vic", "pw-vic"));  // other users are not affected
  auth.advance_clock_for_test(std::chrono::seconds(61));
  EXPECT_TRUE(auth.sign_in("ada", "pw-ada"));
}

TEST(Cookie, FindsTheNamedValue) {
  EXPECT_EQ(cookie_value("a=1; cell_session=abc; b=2", "cell_session"), "abc");
  EXPECT_EQ(cookie_value("cell_session=xyz", "cell_session"), "xyz");
  EXPECT_EQ(cookie_value("xcell_session=no; a=1", "cell_session"), "");
  EXPECT_EQ(cookie_value("", "cell_session"), "");
  EXPECT_EQ(cookie_value(";;;", "cell_session"), "");
}

}  // namespace
}  // namespace cell::monitor
