#include "cell/protocols/excalibur/controller_model.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>

#include "cell/testing/matchers.hpp"
#include "cell/testing/tolerances.hpp"
#include "shipped_dialect.hpp"

namespace cell::protocols::excalibur {
namespace {

using ::cell::testing::IsOk;
using ::testing::HasSubstr;

using ::cell::testing::kTolDeg;

using test::shipped;

ControllerSettings settings() {
  ControllerSettings s;
  s.lower_deg = {-90, -90, -90, -180, -135, -180};
  s.upper_deg = {90, 90, 180, 180, 135, 180};
  s.speed_deg_s = {30, 30, 30, 60, 60, 60};
  s.initial_deg = {0, 0, 0, 0, 0, 0};
  s.master_deg = {10, -5, 20, 0, 0, 0};
  s.accuracy_deg = 0.3;
  s.gripper_time_s = 0.2;
  return s;
}

/// Drives a ControllerModel like a host would, with explicit times.
class ControllerModelTest : public ::testing::Test {
 protected:
  ControllerModelTest() : dialect_(shipped()), model_(dialect_, settings(), 0.0) {
    drain(0.0);  // the power-up "ready"
  }

  /// Sends a command at time t (all bytes in one window of `window_s`), returns its lines.
  std::vector<Message> send(const Command& c, double t, double window_s = 0.001) {
    std::string line = *dialect_.format(c);
    line += dialect_.framing().host_terminator;
    model_.receive(line, t - window_s, t);
    return drain(t + 0.5);
  }
  std::vector<Message> send_text(const std::string& text, double t) {
    model_.receive(text + "\r", t - 0.001, t);
    return drain(t + 0.5);
  }
  /// Advances to `t` and parses everything due.
  std::vector<Message> drain(double t) {
    model_.advance(t);
    std::vector<Message> out;
    std::string line;
    while (model_.pop_output(t, line)) {
      while (!line.empty() && (line.back() == '\r' || line.back() == '\n')) {
        line.pop_back();
      }
      auto m = dialect_.parse(line);
      EXPECT_THAT(m, IsOk()) << line;
      if (m) {
        out.push_back(*m);
      }
    }
    return out;
  }
  static Command move(ControllerAngles q) {
    return Command{CommandKind::kMoveJoints, q, Mode::kHost, 0, 0};
  }
  static Command query() { return Command{CommandKind::kQueryJoints, {}, Mode::kHost, 0, 0}; }

  Dialect dialect_;
  ControllerModel model_;
};

TEST_F(ControllerModelTest, AnswersAQueryWithItsAngles) {
  const auto out = send(query(), 1.0);
  ASSERT_EQ(out.size(), 1U);
  EXPECT_EQ(out[0].kind, MessageKind::kJoints);
  EXPECT_EQ(out[0].angles_deg, (ControllerAngles{0, 0, 0, 0, 0, 0}));
}

TEST_F(ControllerModelTest, AchievesAMoveAtItsSpeedWithinItsAccuracy) {
  const ControllerAngles target = {30, -15, 45, 10, 0, -20};
  auto out = send(move(target), 1.0);
  ASSERT_EQ(out.size(), 1U);
  EXPECT_EQ(out[0].kind, MessageKind::kOk);
  // Slowest joint: 45 deg at 30 deg/s, smoothstep peak 1.5x the mean: 2.25 s (+- accuracy).
  const ControllerAngles mid = model_.angles(2.0);
  EXPECT_GT(mid[2], 5.0);
  EXPECT_LT(mid[2], 40.0);
  EXPECT_TRUE(model_.status(2.0).moving);
  EXPECT_TRUE(drain(3.4).empty());  // achieved silently
  const ControllerStatus s = model_.status(3.4);
  EXPECT_FALSE(s.moving);
  for (std::size_t j = 0; j < kJointCount; ++j) {
    EXPECT_LE(std::abs(s.angles_deg[j] - target[j]), 0.3 + kTolDeg) << j;
  }
  EXPECT_EQ(s.counters.moves, 1U);
}

TEST_F(ControllerModelTest, ATargetOutsideItsLimitsIsNotAchievedAndNothingMoves) {
  const auto out = send(move({95, 0, 0, 0, 0, 0}), 1.0);
  ASSERT_EQ(out.size(), 2U);
  EXPECT_EQ(out[0].kind, MessageKind::kOk);
  EXPECT_EQ(out[1].kind, MessageKind::kMoveNotAchieved);
  EXPECT_EQ(out[1].code, dialect_.code_of(NotAchievedReason::kLimits));
  EXPECT_EQ(model_.angles(5.0), (ControllerAngles{0, 0, 0, 0, 0, 0}));
}

TEST_F(ControllerModelTest, AMoveSlowerThanTheTimeoutIsNotAchievedAtTheDeadline) {
  ASSERT_EQ(send(Command{CommandKind::kSetTimeout, {}, Mode::kHost, 0, 1.0}, 0.5)[0].kind,
            MessageKind::kOk);
  ASSERT_EQ(send(move({80, 0, 0, 0, 0, 0}), 1.0)[0].kind, MessageKind::kOk);  // 4 s move
  EXPECT_TRUE(drain(1.9).empty());
  const auto out = drain(2.1);
  ASSERT_EQ(out.size(), 1U);
  EXPECT_EQ(out[0].kind, MessageKind::kMoveNotAchieved);
  EXPECT_EQ(out[0].code, dialect_.code_of(NotAchievedReason::kTimeout));
  const double stopped = model_.angles(2.1)[0];
  EXPECT_GT(stopped, 1.0);
  EXPECT_LT(stopped, 79.0);
  EXPECT_DOUBLE_EQ(model_.angles(9.0)[0], stopped);  // frozen where the timeout hit
}

TEST_F(ControllerModelTest, ATighterToleranceThanTheAccuracyEndsInATimeout) {
  ControllerSettings s = settings();
  s.accuracy_deg = 2.0;
  ControllerModel model(dialect_, s, 0.0);
  std::string line =
      *dialect_.format(Command{CommandKind::kSetTolerance, {}, Mode::kHost, 0.05, 0});
  model.receive(line + "\r", 0.0, 0.1);
  line = *dialect_.format(move({10, 10, 10, 10, 10, 10}));
  model.receive(line + "\r", 0.1, 0.2);
  model.advance(11.0);
  const ControllerStatus st = model.status(11.0);
  EXPECT_EQ(st.counters.not_achieved, 1U);  // tried, re-settled, gave up at the 10 s default
}

TEST_F(ControllerModelTest, ARandomStopIsReportedAndTheArmStaysWhereItStopped) {
  model_.set_move_not_achieved_probability(1.0);
  auto out = send(move({30, 0, 0, 0, 0, 0}), 1.0);
  for (const Message& m : drain(5.0)) {
    out.push_back(m);
  }
  ASSERT_EQ(out.size(), 2U);
  EXPECT_EQ(out[0].kind, MessageKind::kOk);
  EXPECT_EQ(out[1].kind, MessageKind::kMoveNotAchieved);
  EXPECT_EQ(out[1].code, dialect_.code_of(NotAchievedReason::kStopped));
  EXPECT_LT(model_.angles(5.0)[0], 29.5);  // stopped at 10..90 % of the way
}

TEST_F(ControllerModelTest, ANewMoveReplacesTheOneInProgress) {
  ASSERT_EQ(send(move({60, 0, 0, 0, 0, 0}), 1.0)[0].kind, MessageKind::kOk);
  ASSERT_EQ(send(move({-10, 0, 0, 0, 0, 0}), 2.0)[0].kind, MessageKind::kOk);
  EXPECT_TRUE(drain(10.0).empty());
  EXPECT_NEAR(model_.angles(10.0)[0], -10.0, 0.3 + kTolDeg);
}

TEST_F(ControllerModelTest, InManualModeTheSlaveFollowsTheMasterAndMovesAreRefused) {
  ASSERT_EQ(send(Command{CommandKind::kSetMode, {}, Mode::kManual, 0, 0}, 1.0)[0].kind,
            MessageKind::kOk);
  const auto refused = send(move({1, 1, 1, 1, 1, 1}), 1.5);
  ASSERT_EQ(refused.size(), 1U);
  EXPECT_EQ(refused[0].kind, MessageKind::kError);
  EXPECT_EQ(refused[0].code, dialect_.code_of(ErrorReason::kMode));
  EXPECT_THAT(model_.status(1.5).last_rejected, HasSubstr("moves need host mode"));
  EXPECT_EQ(model_.angles(5.0), settings().master_deg);
  const auto master = send(Command{CommandKind::kReadMaster, {}, Mode::kHost, 0, 0}, 5.0);
  EXPECT_EQ(master[0].kind, MessageKind::kMaster);
  EXPECT_EQ(master[0].angles_deg, settings().master_deg);
}

TEST_F(ControllerModelTest, TeachRecordsTenSamplesASecondAndPlaybackReplaysThem) {
  ASSERT_EQ(send(Command{CommandKind::kSetMode, {}, Mode::kTeach, 0, 0}, 1.0)[0].kind,
            MessageKind::kOk);
  drain(2.0);
  EXPECT_GE(model_.status(2.0).taught_samples, 10U);  // t = 1.0, 1.1, ..., 2.0 (rounding)
  EXPECT_LE(model_.status(2.0).taught_samples, 11U);
  ASSERT_EQ(send(Command{CommandKind::kSetMode, {}, Mode::kHost, 0, 0}, 2.05)[0].kind,
            MessageKind::kOk);
  ASSERT_EQ(send(move({0, 0, 0, 0, 0, 0}), 2.1)[0].kind, MessageKind::kOk);
  drain(5.0);
  ASSERT_EQ(send(Command{CommandKind::kSetMode, {}, Mode::kPlayback, 0, 0}, 5.0)[0].kind,
            MessageKind::kOk);
  drain(10.0);
  // The recording ends at the master's pose; so does the playback.
  for (std::size_t j = 0; j < kJointCount; ++j) {
    EXPECT_NEAR(model_.angles(10.0)[j], settings().master_deg[j], 1.0) << j;
  }
}

TEST_F(ControllerModelTest, AnswersGarbageWithAnErrorAndDoesNotMove) {
  auto out = send_text("MJ 1x.00 0.00*1234", 1.0);
  ASSERT_EQ(out.size(), 1U);
  EXPECT_EQ(out[0].kind, MessageKind::kError);
  EXPECT_EQ(out[0].code, dialect_.code_of(ErrorReason::kChecksum));
  out = send_text("\x01\x02garbage", 2.0);
  ASSERT_EQ(out.size(), 1U);
  EXPECT_EQ(out[0].code, dialect_.code_of(ErrorReason::kSyntax));
  EXPECT_THAT(model_.status(2.0).last_rejected, HasSubstr("non-printable byte 0x01"));
  EXPECT_EQ(model_.angles(3.0), (ControllerAngles{0, 0, 0, 0, 0, 0}));
  EXPECT_EQ(model_.status(3.0).counters.errors_sent, 2U);
}

TEST_F(ControllerModelTest, RefusesATolerenceOutsideItsRange) {
  const auto out = send(Command{CommandKind::kSetTolerance, {}, Mode::kHost, 50.0, 0}, 1.0);
  ASSERT_EQ(out.size(), 1U);
  EXPECT_EQ(out[0].code, dialect_.code_of(ErrorReason::kRange));
  EXPECT_DOUBLE_EQ(model_.status(1.0).tolerance_deg, 1.0);
}

TEST_F(ControllerModelTest, ResetRestoresPowerUpSettingsAndSaysReady) {
  send(Command{CommandKind::kSetTolerance, {}, Mode::kHost, 0.5, 0}, 1.0);
  send(Command{CommandKind::kSetMode, {}, Mode::kManual, 0, 0}, 1.5);
  const auto out = send(Command{CommandKind::kReset, {}, Mode::kHost, 0, 0}, 2.0);
  ASSERT_EQ(out.size(), 2U);
  EXPECT_EQ(out[0].kind, MessageKind::kOk);
  EXPECT_EQ(out[1].kind, MessageKind::kReady);
  const ControllerStatus s = model_.status(2.0);
  EXPECT_EQ(s.mode, Mode::kHost);
  EXPECT_DOUBLE_EQ(s.tolerance_deg, 1.0);
  EXPECT_EQ(s.counters.resets, 1U);
}

TEST_F(ControllerModelTest, GrippersTakeTheirTime) {
  const std::string line =
      *dialect_.format(Command{CommandKind::kGripperClose, {}, Mode::kHost, 0, 0}) + "\r";
  model_.receive(line, 0.999, 1.0);
  model_.advance(1.1);
  EXPECT_TRUE(model_.status(1.1).gripper_moving);
  model_.advance(1.3);
  EXPECT_FALSE(model_.status(1.3).gripper_moving);
  EXPECT_TRUE(model_.status(1.3).gripper_closed);
}

TEST(ControllerModelPacing, LosesCharactersThatArriveFasterThanTheSixEightNineCanTakeThem) {
  const Dialect dialect = shipped();
  ControllerSettings s = settings();
  s.min_char_interval_s = 0.002;
  s.busy_after_line_s = 0.010;
  ControllerModel model(dialect, s, 0.0);
  const std::string line = *dialect.format(Command{}) + "\r";  // "QJ*XXXX\r"
  // All at once, in a 1 ms window: most characters are lost, the line is an overrun.
  model.receive(line, 0.999, 1.0);
  model.advance(1.5);
  std::string out;
  std::vector<Message> messages;
  while (model.pop_output(1.5, out)) {
    out.resize(out.size() - 2);
    messages.push_back(*dialect.parse(out));
  }
  ASSERT_EQ(messages.size(), 2U);  // ready, then the error
  EXPECT_EQ(messages[1].kind, MessageKind::kError);
  EXPECT_EQ(messages[1].code, dialect.code_of(ErrorReason::kOverrun));
  EXPECT_GT(model.status(1.5).counters.overruns, 0U);
  // Paced at the controller's speed (one character per 2 ms, each read as it arrives): fine.
  double t = 2.0;
  for (char c : line) {
    model.receive(std::string(1, c), t - 0.002, t);
    t += 0.002;
  }
  model.advance(t + 0.5);
  ASSERT_TRUE(model.pop_output(t + 0.5, out));
  out.resize(out.size() - 2);
  EXPECT_EQ(dialect.parse(out)->kind, MessageKind::kJoints);
  // The next command while the controller is still busy with this one (its busy time ends 1 ms
  // before the window closes): only the last character survives, the line is an overrun.
  const double busy_end = t - 0.002 + 0.010;
  model.receive(line, busy_end - 0.009, busy_end + 0.001);
  model.advance(t + 1.0);
  ASSERT_TRUE(model.pop_output(t + 1.0, out));
  out.resize(out.size() - 2);
  EXPECT_EQ(dialect.parse(out)->code, dialect.code_of(ErrorReason::kOverrun));
}

TEST(ControllerModelPacing, AReaderThatWasLateIsNeverTakenForAFastWriter) {
  const Dialect dialect = shipped();
  ControllerSettings s = settings();
  s.min_char_interval_s = 0.002;
  ControllerModel model(dialect, s, 0.0);
  const std::string line = *dialect.format(Command{}) + "\r";
  // 8 characters read together after 20 ms: they may well have come 2 ms apart.
  model.receive(line, 1.0, 1.02);
  model.advance(1.5);
  std::string out;
  ASSERT_TRUE(model.pop_output(1.5, out));  // ready
  ASSERT_TRUE(model.pop_output(1.5, out));
  out.resize(out.size() - 2);
  EXPECT_EQ(dialect.parse(out)->kind, MessageKind::kJoints);
  EXPECT_EQ(model.status(1.5).counters.overruns, 0U);
}

TEST(ControllerModelPacing, ALineLongerThanTheBufferIsALineError) {
  const Dialect dialect = shipped();
  ControllerModel model(dialect, settings(), 0.0);
  model.receive(std::string(100, 'A') + "\r", 0.0, 1.0);
  model.advance(1.5);
  std::string out;
  ASSERT_TRUE(model.pop_output(1.5, out));  // ready
  ASSERT_TRUE(model.pop_output(1.5, out));
  out.resize(out.size() - 2);
  auto m = dialect.parse(out);
  ASSERT_THAT(m, IsOk());
  EXPECT_EQ(m->kind, MessageKind::kLineError);
  EXPECT_EQ(m->code, dialect.code_of(LineErrorReason::kBufferFull));
  EXPECT_FALSE(model.pop_output(1.5, out));  // and no reply to the discarded line
}

TEST(ControllerModelNoise, EveryDamagedLineIsCaughtByTheChecksum) {
  const Dialect dialect = shipped();
  ControllerModel model(dialect, settings(), 0.0);
  model.set_noise(NoiseSettings{1.0, 0.0});  // every line, both ways, one fault
  const std::string line =
      *dialect.format(
          Command{CommandKind::kMoveJoints, {10, 20, 30, 40, 50, 60}, Mode::kHost, 0, 0}) +
      "\r";
  int lines_out = 0;
  int parsed_replies = 0;
  std::string out;
  for (int i = 0; i < 300; ++i) {
    model.receive(line, i, i + 0.5);
    model.advance(i + 0.9);
    while (model.pop_output(i + 0.9, out)) {
      while (!out.empty() && (out.back() == '\r' || out.back() == '\n')) {
        out.pop_back();
      }
      ++lines_out;
      parsed_replies += dialect.parse(out).has_value() ? 1 : 0;
    }
  }
  const ControllerStatus s = model.status(400);
  // A fault that only doubles a terminator leaves the line intact: such moves run, and run to
  // the exact target; no damaged move was ever executed.
  EXPECT_LT(s.counters.moves, 15U);
  if (s.counters.moves > 0) {
    EXPECT_EQ(s.target_deg, (ControllerAngles{10, 20, 30, 40, 50, 60}));
  }
  EXPECT_GT(s.counters.errors_sent, 250U);
  EXPECT_GT(s.counters.noise_faults_in, 280U);  // fewer when a lost terminator joined two lines
  // Output lines are damaged too: only a fault on the terminator leaves a line readable.
  EXPECT_GT(lines_out, 250);
  EXPECT_LT(parsed_replies, lines_out / 4);
}

TEST(ControllerSettings, ValidateNamesTheProblem) {
  ControllerSettings s = settings();
  s.speed_deg_s[3] = 0;
  EXPECT_THAT(s.validate(), ::cell::testing::IsErrWith(Errc::kInvalidArgument, "joint 4: speed"));
  s = settings();
  s.lower_deg[0] = 100;
  EXPECT_THAT(s.validate(), ::cell::testing::IsErrWith(Errc::kInvalidArgument, "joint 1: lower"));
}

}  // namespace
}  // namespace cell::protocols::excalibur
