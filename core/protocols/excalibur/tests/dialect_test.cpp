#include "cell/protocols/excalibur/dialect.hpp"

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <numbers>
#include <sstream>

#include "cell/geometry/angles.hpp"
#include "cell/kinematics/robot_config.hpp"
#include "cell/protocols/excalibur/angles.hpp"
#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"
#include "cell/testing/tolerances.hpp"
#include "shipped_dialect.hpp"

namespace cell::protocols::excalibur {
namespace {

using ::cell::testing::IsErrWith;
using ::cell::testing::IsOk;
using ::testing::HasSubstr;

using ::cell::testing::kTolDeg;
using geometry::kDeg;

std::string shipped_text() {
  std::ifstream in(CELL_EXCALIBUR_DIALECT);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

using test::shipped;

/// The shipped file with `from` replaced by `to` (which must occur).
Result<Dialect> edited(const std::string& from, const std::string& to) {
  std::string text = shipped_text();
  const auto at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  text.replace(at, from.size(), to);
  auto doc = config::load_string(text, "dialect.yaml");
  if (!doc) {
    return std::move(doc).error();
  }
  return Dialect::parse(*doc);
}

TEST(Checksum, MatchesTheStandardCheckValues) {
  EXPECT_EQ(checksum(ChecksumKind::kCrc16, "123456789"), 0x29B1);  // CRC-16/CCITT-FALSE check
  EXPECT_EQ(checksum(ChecksumKind::kXor8, "AB"), 0x41 ^ 0x42);
  EXPECT_EQ(checksum(ChecksumKind::kSum8, "AB"), (0x41 + 0x42) & 0xFF);
  EXPECT_EQ(checksum(ChecksumKind::kNone, "AB"), 0);
}

TEST(Dialect, LoadsTheShippedFile) {
  const Dialect d = shipped();
  EXPECT_EQ(d.name(), "excalibur-assumed-v1");
  EXPECT_EQ(d.framing().checksum, ChecksumKind::kCrc16);
  EXPECT_EQ(d.framing().host_terminator, "\r");
  EXPECT_DOUBLE_EQ(d.defaults().tolerance_deg, 1.0);
  EXPECT_TRUE(d.has(CommandKind::kGripperOpen));
  EXPECT_NEAR(d.timing().command_delay_s, 0.015, 1e-12);
  // "MA -999.99 12.50 -150.25 0.00 5.00 7.00*XXXX\r\n" is the longest message.
  EXPECT_EQ(d.longest_message_chars(), 46U);
}

TEST(Dialect, FormatsAMoveWithTwoDecimalsAndACrc) {
  const Dialect d = shipped();
  Command move{CommandKind::kMoveJoints, {10, 0, 0, 5, 5, 5}, Mode::kHost, 0, 0};
  auto line = d.format(move);
  ASSERT_THAT(line, IsOk());
  const std::string body = "MJ 10.00 0.00 0.00 5.00 5.00 5.00";
  EXPECT_EQ(*line, fmt::format("{}*{:04X}", body, checksum(ChecksumKind::kCrc16, body)));
}

TEST(Dialect, EveryCommandRoundTripsThroughTheControllerSide) {
  const Dialect d = shipped();
  for (std::size_t k = 0; k < kCommandKinds; ++k) {
    Command c;
    c.kind = static_cast<CommandKind>(k);
    c.angles_deg = {-175.25, -30.0, 150.0, 0.01, -0.01, 179.99};
    c.mode = Mode::kPlayback;
    c.tolerance_deg = 0.75;
    c.timeout_s = 12.5;
    auto line = d.format(c);
    ASSERT_THAT(line, IsOk()) << to_string(c.kind);
    ErrorReason reason{};
    auto back = d.parse_command(*line, reason);
    ASSERT_THAT(back, IsOk()) << *line;
    EXPECT_EQ(back->kind, c.kind);
    if (c.kind == CommandKind::kMoveJoints) {
      for (std::size_t j = 0; j < kJointCount; ++j) {
        EXPECT_NEAR(back->angles_deg[j], c.angles_deg[j], kTolDeg);
      }
    }
    if (c.kind == CommandKind::kSetMode) {
      EXPECT_EQ(back->mode, Mode::kPlayback);
      EXPECT_THAT(*line, HasSubstr("SM P*"));
    }
    if (c.kind == CommandKind::kSetTolerance) {
      EXPECT_NEAR(back->tolerance_deg, 0.75, kTolDeg);
    }
    if (c.kind == CommandKind::kSetTimeout) {
      EXPECT_NEAR(back->timeout_s, 12.5, kTolDeg);
    }
  }
}

TEST(Dialect, EveryMessageRoundTripsThroughTheHostSide) {
  const Dialect d = shipped();
  for (std::size_t k = 0; k < kMessageKinds; ++k) {
    Message m;
    m.kind = static_cast<MessageKind>(k);
    m.angles_deg = {1.5, -2.25, 150.0, 0.0, -90.0, 45.75};
    m.code = 3;
    auto line = d.format(m);
    ASSERT_THAT(line, IsOk());
    auto back = d.parse(*line);
    ASSERT_THAT(back, IsOk()) << *line;
    EXPECT_EQ(back->kind, m.kind);
    EXPECT_EQ(d.looks_unsolicited(*line), is_unsolicited(m.kind)) << *line;
    if (m.kind == MessageKind::kJoints || m.kind == MessageKind::kMaster) {
      EXPECT_EQ(back->angles_deg, m.angles_deg);
    }
    if (m.kind == MessageKind::kError || m.kind == MessageKind::kMoveNotAchieved ||
        m.kind == MessageKind::kLineError) {
      EXPECT_EQ(back->code, 3);
    }
  }
}

TEST(Dialect, AcceptsExtraBlanksWhereTheTemplateHasASpace) {
  const Dialect d = shipped();
  const std::string body = "JA  1.00\t2.00 3.00 4.00 5.00   6.00";
  auto m = d.parse(fmt::format("{}*{:04X}", body, checksum(ChecksumKind::kCrc16, body)));
  ASSERT_THAT(m, IsOk());
  EXPECT_DOUBLE_EQ(m->angles_deg[5], 6.0);
}

std::string with_crc(const std::string& body) {
  return fmt::format("{}*{:04X}", body, checksum(ChecksumKind::kCrc16, body));
}

TEST(Dialect, GarbageGivesClearErrorsNamingWhatAndWhere) {
  const Dialect d = shipped();
  EXPECT_THAT(d.parse("OK*1234"), IsErrWith(Errc::kProtocol, "checksum mismatch"));
  EXPECT_THAT(d.parse("OK"), IsErrWith(Errc::kProtocol, "no checksum"));
  EXPECT_THAT(d.parse("OK*12G4"), IsErrWith(Errc::kProtocol, "4 hex digits"));
  EXPECT_THAT(d.parse("O\x07K*1234"),
              IsErrWith(Errc::kProtocol, "non-printable byte 0x07 at column 2"));
  EXPECT_THAT(d.parse(with_crc("XY 12")), IsErrWith(Errc::kProtocol, "unknown message"));
  EXPECT_THAT(d.parse(with_crc("JA 1.00 2.00 3.0 4.00 5.00 6.00")),
              IsErrWith(Errc::kProtocol,
                        "expected a number with 2 decimals for {q3} at column 14, got \"3.0\""));
  EXPECT_THAT(d.parse(with_crc("JA 1.00 2.00 3x.00 4.00 5.00 6.00")),
              IsErrWith(Errc::kProtocol, "for {q3} at column 14"));
  EXPECT_THAT(d.parse(with_crc("JA 1.00 2.00 3.00 4.00 5.00")),
              IsErrWith(Errc::kProtocol, "expected a blank at column 28"));
  EXPECT_THAT(d.parse(with_crc("JA 1.00 2.00 3.00 4.00 5.00 6.00 7.00")),
              IsErrWith(Errc::kProtocol, "unexpected \"7.00\" at column 34"));
  EXPECT_THAT(d.parse(with_crc("ER x")),
              IsErrWith(Errc::kProtocol, "expected an integer for {code}"));
  EXPECT_THAT(d.parse(std::string(200, 'A')), IsErrWith(Errc::kProtocol, "more than 80"));
  EXPECT_THAT(d.parse(""), IsErrWith(Errc::kProtocol, "empty line"));
  ErrorReason reason{};
  EXPECT_THAT(d.parse_command("MJ 1.00*0000", reason), IsErrWith(Errc::kProtocol, "checksum"));
  EXPECT_EQ(reason, ErrorReason::kChecksum);
  EXPECT_THAT(d.parse_command(with_crc("MJ 1.00 2.00"), reason),
              IsErrWith(Errc::kProtocol, "expected a blank"));
  EXPECT_EQ(reason, ErrorReason::kSyntax);
  EXPECT_THAT(
      d.parse_command(with_crc("SM X"), reason),
      IsErrWith(Errc::kProtocol, "expected a mode word (H, M, T, P) at column 4, got \"X\""));
  EXPECT_THAT(d.parse_command(with_crc("ZZ"), reason),
              IsErrWith(Errc::kProtocol, "unknown command (expected one of: MJ, QJ, QM, SM"));
}

TEST(Dialect, ADamagedUnsolicitedMessageStillLooksUnsolicited) {
  const Dialect d = shipped();
  EXPECT_TRUE(d.looks_unsolicited("!NB 1*ZZZZ"));
  EXPECT_TRUE(d.looks_unsolicited("!"));
  EXPECT_FALSE(d.looks_unsolicited("OK*1234"));
  EXPECT_FALSE(d.looks_unsolicited("JA 1.00"));
}

TEST(Dialect, RefusesValuesThatDoNotFitTheWire) {
  const Dialect d = shipped();
  Command move{CommandKind::kMoveJoints, {1000.0, 0, 0, 0, 0, 0}, Mode::kHost, 0, 0};
  EXPECT_THAT(d.format(move), IsErrWith(Errc::kInvalidArgument, "q1 = 1000 does not fit"));
  move.angles_deg[0] = std::nan("");
  EXPECT_THAT(d.format(move), IsErrWith(Errc::kInvalidArgument, "does not fit"));
}

TEST(Dialect, ErrorCodesHaveMeanings) {
  const Dialect d = shipped();
  EXPECT_EQ(d.describe_error(2), "checksum error (code 2)");
  EXPECT_EQ(d.describe_error(77), "unknown error code 77");
  ErrorReason reason{};
  ASSERT_TRUE(d.error_reason(3, reason));
  EXPECT_EQ(reason, ErrorReason::kOverrun);
  EXPECT_TRUE(is_line_error(reason));
  EXPECT_FALSE(is_line_error(ErrorReason::kMode));
  EXPECT_EQ(d.describe_not_achieved(1), "target outside the controller's joint limits (code 1)");
  EXPECT_EQ(d.code_of(NotAchievedReason::kTimeout), 2);
}

TEST(Dialect, AnotherSiteCanChangeTheSyntaxWithoutRecompiling) {
  auto d = edited("move_joints: \"MJ {q1} {q2} {q3} {q4} {q5} {q6}\"",
                  "move_joints: \"GOTO {q1},{q2},{q3},{q4},{q5},{q6}\"");
  ASSERT_THAT(d, IsOk());
  Command move{CommandKind::kMoveJoints, {10, 0, 0, 5, 5, 5}, Mode::kHost, 0, 0};
  auto line = d->format(move);
  ASSERT_THAT(line, IsOk());
  EXPECT_THAT(*line, ::testing::StartsWith("GOTO 10.00,0.00,0.00,5.00,5.00,5.00*"));
  auto none = edited("checksum: crc16", "checksum: none");
  ASSERT_THAT(none, IsOk());
  EXPECT_EQ(*none->format(Command{}), "QJ");
  auto plain = edited("plus_sign: false", "plus_sign: true");
  ASSERT_THAT(plain, IsOk());
  EXPECT_THAT(*plain->format(move), ::testing::StartsWith("MJ +10.00 +0.00"));
}

TEST(Dialect, WithoutGripperCommandsTheGripperIsNotReady) {
  auto d = edited("  gripper_open: \"GO\"", "");
  ASSERT_THAT(d, IsOk());
  EXPECT_FALSE(d->has(CommandKind::kGripperOpen));
  EXPECT_THAT(d->format(Command{CommandKind::kGripperOpen, {}, Mode::kHost, 0, 0}),
              IsErrWith(Errc::kNotReady, "no 'gripper_open' command"));
}

TEST(Dialect, StrictLoadingNamesFileLineColumnAndKey) {
  auto d = edited("  max_line_chars: 80", "  max_line_chars: 80\n  baud: 9600");
  EXPECT_THAT(d, IsErrWith(Errc::kConfig, "dialect.yaml:28:3: unknown key 'framing.baud'"));
  d = edited("query_joints: \"QJ\"", "query_joints: \"QJ {q1}\"");
  EXPECT_THAT(d, IsErrWith(Errc::kConfig,
                           "key 'commands.query_joints': template \"QJ {q1}\": "
                           "placeholder {q1} is not used by this line"));
  d = edited("\"MJ {q1} {q2} {q3} {q4} {q5} {q6}\"", "\"MJ {q1} {q2} {q3} {q4} {q5}\"");
  EXPECT_THAT(d, IsErrWith(Errc::kConfig, "missing placeholder {q6}"));
  d = edited("\"SM {mode}\"", "\"SM {mood}\"");
  EXPECT_THAT(d, IsErrWith(Errc::kConfig, "unknown placeholder {mood}"));
  d = edited("checksum: crc16", "checksum: md5");
  EXPECT_THAT(d, IsErrWith(Errc::kConfig, "must be one of none, xor8, sum8, crc16; got 'md5'"));
  d = edited("  manual: M", "  manual: H");
  EXPECT_THAT(d, IsErrWith(Errc::kConfig, "'H' is already the word of another mode"));
  d = edited("  checksum: 2 ", "  checksum: 1 ");
  EXPECT_THAT(d, IsErrWith(Errc::kConfig, "code 1 is used twice in error_codes"));
  d = edited("ready: \"!RD\"", "ready: \"RD\"");
  EXPECT_THAT(d, IsErrWith(Errc::kConfig, "must start with unsolicited_prefix '!'"));
  d = edited("master: \"MA {q1}", "master: \"JA {q1}");
  EXPECT_THAT(d, IsErrWith(Errc::kConfig, "does not parse back as itself (parsed as joints)"));
  d = edited("default_tolerance_deg: 1.0", "default_tolerance_deg: 50");
  EXPECT_THAT(d, IsErrWith(Errc::kConfig, "key 'controller.default_tolerance_deg'"));
  EXPECT_THAT(Dialect::load("/nonexistent/dialect.yaml"), IsErrWith(Errc::kConfig, "cannot open"));
}

// Digest 001 §2.3 and case 9: (10, 0, 0, 5, 5, 5)* <-> (10, 30, -150, 5, 5, 5), on the wire.
TEST(ControllerAngles, ConvertOnEveryCommandAndQueryDigestCase9) {
  auto robot =
      kinematics::load_robot(cell::testing::source_dir() + "/config/robots/excalibur.yaml");
  ASSERT_THAT(robot, IsOk());
  const kinematics::ExcaliburModel& model = *robot->excalibur();
  kinematics::JointVector q(6);
  q << 10 * kDeg, 30 * kDeg, -150 * kDeg, 5 * kDeg, 5 * kDeg, 5 * kDeg;
  const ControllerAngles star = to_wire(model, q);
  const ControllerAngles expected = {10, 0, 0, 5, 5, 5};
  for (std::size_t j = 0; j < kJointCount; ++j) {
    EXPECT_NEAR(star[j], expected[j], 1e-12) << j;
  }
  const Dialect d = shipped();
  auto line = d.format(Command{CommandKind::kMoveJoints, star, Mode::kHost, 0, 0});
  ASSERT_THAT(line, IsOk());
  EXPECT_THAT(*line, ::testing::StartsWith("MJ 10.00 0.00 0.00 5.00 5.00 5.00*"));
  // And back: the controller reports q* = (10, 0, 0, 5, 5, 5).
  auto reply = d.parse(with_crc("JA 10.00 0.00 0.00 5.00 5.00 5.00"));
  ASSERT_THAT(reply, IsOk());
  const kinematics::JointVector back = from_wire(model, reply->angles_deg);
  const double expected_dh[] = {10, 30, -150, 5, 5, 5};
  for (int j = 0; j < 6; ++j) {
    EXPECT_NEAR(back[j] / kDeg, expected_dh[j], 1e-12) << j;
  }
  // Digest case 1: q = 0 is q* = (0, -30, 150, 0, 0, 0).
  const ControllerAngles zero = to_wire(model, kinematics::JointVector::Zero(6));
  EXPECT_NEAR(zero[1], -30.0, 1e-12);
  EXPECT_NEAR(zero[2], 150.0, 1e-12);
}

TEST(ControllerAngles, MaxDifferenceNamesTheJoint) {
  std::size_t joint = 99;
  EXPECT_DOUBLE_EQ(max_difference_deg({0, 0, 1.2, 0, 0, 0}, {0, 0, 0, 0.8, 0, 0}, &joint), 1.2);
  EXPECT_EQ(joint, 2U);
}

TEST(QuoteLine, EscapesWhatPeopleCannotSee) {
  EXPECT_EQ(quote_line("OK\r\n\x01\"\\"), "\"OK\\r\\n\\x01\\\"\\\\\"");
}

}  // namespace
}  // namespace cell::protocols::excalibur
