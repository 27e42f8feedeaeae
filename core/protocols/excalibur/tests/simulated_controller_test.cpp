#include "cell/protocols/excalibur/simulated_controller.hpp"

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sched.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <set>
#include <thread>

#include "cell/protocols/excalibur/serial_port.hpp"
#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"

namespace cell::protocols::excalibur {
namespace {

using namespace std::chrono_literals;
using ::cell::testing::IsOk;

ControllerSettings fast_settings() {
  ControllerSettings s;
  s.lower_deg = {-90, -90, -90, -180, -135, -180};
  s.upper_deg = {90, 90, 180, 180, 135, 180};
  s.speed_deg_s = {180, 180, 180, 180, 180, 180};
  s.accuracy_deg = 0.3;
  s.min_char_interval_s = 0.0005;
  s.busy_after_line_s = 0.002;
  return s;
}

/// A host on the simulator's pty: the serial port with the dialect's pacing at 38400 baud.
struct Host {
  Dialect dialect = *Dialect::load(CELL_EXCALIBUR_DIALECT);
  std::unique_ptr<SerialPort> port;

  explicit Host(const std::string& device, int realtime_priority = 0) {
    SerialOptions o;
    o.realtime_priority = realtime_priority;
    o.device = device;
    o.baud = 38400;
    o.emulate_baud = true;
    o.char_delay_s = 0.0005;
    o.command_delay_s = 0.004;
    auto p =
        SerialPort::open(o, [this](std::string_view l) { return dialect.looks_unsolicited(l); });
    EXPECT_THAT(p, IsOk());
    port = std::move(*p);
    // The simulator says "ready" at power-up, while this port opens (which flushes input):
    // the line arrives whole (an unsolicited line), cut (its rest, a damaged reply line), or
    // not at all (flushed whole). Wait for the first two, then drop the reply, as the driver
    // does when it connects; a second is the wait for the third.
    const auto until = std::chrono::steady_clock::now() + 1s;
    ReceivedLine ready;
    while (std::chrono::steady_clock::now() < until && !port->pop_unsolicited(ready)) {
      if (port->wait_reply(10ms)) {
        break;
      }
    }
    port->discard_replies();
  }
  Result<Message> exchange(const Command& c) const {
    port->discard_replies();
    CELL_TRY(port->write_line(*dialect.format(c) + dialect.framing().host_terminator));
    auto line = port->wait_reply(1s);
    if (!line) {
      return std::move(line).error();
    }
    return dialect.parse(line->text);
  }
};

std::filesystem::path temp_link_dir() {
  return std::filesystem::temp_directory_path() / fmt::format("cell-excalibur-test-{}", ::getpid());
}

std::string temp_link() { return (temp_link_dir() / "excalibur.pty").string(); }

/// Removes this process's link directory when the tests are done.
class TempLinkDir : public ::testing::Environment {
 public:
  void TearDown() override {
    std::error_code ec;
    std::filesystem::remove_all(temp_link_dir(), ec);
  }
};
const auto* const kTempLinkDir = ::testing::AddGlobalTestEnvironment(new TempLinkDir);

TEST(SimulatedController, PublishesItsPtyAndTalksTheDialect) {
  const std::string link = temp_link();
  {
    auto sim = SimulatedController::start(*Dialect::load(CELL_EXCALIBUR_DIALECT), fast_settings(),
                                          {.link_path = link, .baud = 38400});
    ASSERT_THAT(sim, IsOk());
    EXPECT_EQ(std::filesystem::read_symlink(link).string(), (*sim)->slave_path());
    Host host(link);
    auto joints = host.exchange(Command{});
    ASSERT_THAT(joints, IsOk());
    EXPECT_EQ(joints->kind, MessageKind::kJoints);
    auto ok =
        host.exchange(Command{CommandKind::kMoveJoints, {20, 10, 0, 0, 0, 0}, Mode::kHost, 0, 0});
    ASSERT_THAT(ok, IsOk());
    EXPECT_EQ(ok->kind, MessageKind::kOk);
    ASSERT_TRUE(cell::testing::eventually([&] { return !(*sim)->status().moving; }, 5s));
    EXPECT_NEAR((*sim)->status().angles_deg[0], 20.0, 0.3 + 1e-9);
    joints = host.exchange(Command{});
    ASSERT_THAT(joints, IsOk());
    EXPECT_NEAR(joints->angles_deg[0], 20.0, 0.3 + 0.01);
  }
  EXPECT_FALSE(std::filesystem::exists(std::filesystem::symlink_status(link)));
}

/// The SCHED_FIFO priorities of this process's threads (0 for the others).
std::multiset<int> fifo_priorities() {
  std::multiset<int> out;
  for (const auto& task : std::filesystem::directory_iterator("/proc/self/task")) {
    const auto tid = static_cast<pid_t>(std::stol(task.path().filename().string()));
    sched_param param{};
    if (::sched_getscheduler(tid) == SCHED_FIFO && ::sched_getparam(tid, &param) == 0) {
      out.insert(param.sched_priority);
    }
  }
  return out;
}

// The controller's thread and the host port's reader run under SCHED_FIFO when asked and
// permitted (root), so a loaded host cannot hold a reply past the gateway's timeout; without
// the privilege the controller says it was refused and both still talk.
TEST(SimulatedController, RealtimePrioritiesReachTheControllerAndThePortReader) {
  const std::string link = temp_link();
  auto sim = SimulatedController::start(*Dialect::load(CELL_EXCALIBUR_DIALECT), fast_settings(),
                                        {.link_path = link, .baud = 38400,
                                         .realtime_priority = 45});
  ASSERT_THAT(sim, IsOk());
  Host host(link, 40);
  auto joints = host.exchange(Command{});
  ASSERT_THAT(joints, IsOk());
  EXPECT_EQ(joints->kind, MessageKind::kJoints);
  const std::multiset<int> fifo = fifo_priorities();
  if (::geteuid() == 0) {
    EXPECT_FALSE((*sim)->realtime_refused());
    EXPECT_EQ(fifo.count(45), 1U);
    EXPECT_EQ(fifo.count(40), 1U);
  } else {
    EXPECT_TRUE((*sim)->realtime_refused());
    EXPECT_TRUE(fifo.empty());
  }
}

TEST(SimulatedController, ReportsAMoveNotAchievedAsAnUnsolicitedMessage) {
  auto sim = SimulatedController::start(*Dialect::load(CELL_EXCALIBUR_DIALECT), fast_settings(),
                                        {.baud = 38400});
  ASSERT_THAT(sim, IsOk());
  Host host((*sim)->slave_path());
  auto ok =
      host.exchange(Command{CommandKind::kMoveJoints, {120, 0, 0, 0, 0, 0}, Mode::kHost, 0, 0});
  ASSERT_THAT(ok, IsOk());
  // (The power-up "ready" may still be on its way: skip it.)
  Result<Message> m = Error{Errc::kTimeout, "none"};
  ReceivedLine line;
  while (host.port->wait_unsolicited(2s) && host.port->pop_unsolicited(line)) {
    m = host.dialect.parse(line.text);
    ASSERT_THAT(m, IsOk());
    if (m->kind != MessageKind::kReady) {
      break;
    }
  }
  ASSERT_THAT(m, IsOk());
  EXPECT_EQ(m->kind, MessageKind::kMoveNotAchieved);
  EXPECT_EQ(m->code, host.dialect.code_of(NotAchievedReason::kLimits));
}

TEST(SimulatedController, AnUnpacedHostOverrunsTheSixEightNine) {
  ControllerSettings s = fast_settings();
  s.min_char_interval_s = 0.002;
  auto sim = SimulatedController::start(*Dialect::load(CELL_EXCALIBUR_DIALECT), s, {.baud = 38400});
  ASSERT_THAT(sim, IsOk());
  Host host((*sim)->slave_path());
  const std::string line = *host.dialect.format(
      Command{CommandKind::kMoveJoints, {20, 10, 0, 0, 0, 0}, Mode::kHost, 0, 0});
  ASSERT_THAT(host.port->write_raw(line + "\r"), IsOk());  // 40 characters at once
  auto reply = host.port->wait_reply(1s);
  ASSERT_THAT(reply, IsOk());
  auto m = host.dialect.parse(reply->text);
  ASSERT_THAT(m, IsOk());
  EXPECT_EQ(m->kind, MessageKind::kError);
  EXPECT_EQ(m->code, host.dialect.code_of(ErrorReason::kOverrun));
  EXPECT_GT((*sim)->status().counters.overruns, 0U);
  EXPECT_EQ((*sim)->status().counters.moves, 0U);
  EXPECT_THAT((*sim)->take_rejections(), ::testing::Contains(::testing::HasSubstr("overrun")));
}

TEST(SimulatedController, NoiseCanBeSwitchedOnAndOffAtRunTime) {
  auto sim = SimulatedController::start(*Dialect::load(CELL_EXCALIBUR_DIALECT), fast_settings(),
                                        {.baud = 38400});
  ASSERT_THAT(sim, IsOk());
  Host host((*sim)->slave_path());
  ASSERT_THAT(host.exchange(Command{}), IsOk());
  ASSERT_THAT((*sim)->set_noise(NoiseSettings{1.0, 0.0}), IsOk());
  int failed = 0;
  for (int i = 0; i < 10; ++i) {
    failed += host.exchange(Command{}).has_value() ? 0 : 1;
  }
  EXPECT_GE(failed, 8);
  EXPECT_THAT((*sim)->set_noise(NoiseSettings{2.0, 0.0}),
              ::cell::testing::IsErrWith(Errc::kInvalidArgument, "probability_per_line"));
  ASSERT_THAT((*sim)->set_noise(NoiseSettings{}), IsOk());
  std::this_thread::sleep_for(100ms);  // let a merged line time out in the controller
  host.port->discard_replies();
  (void)host.exchange(Command{});  // may meet the remains of a damaged line once
  for (int i = 0; i < 5; ++i) {
    EXPECT_THAT(host.exchange(Command{}), IsOk());
  }
}

}  // namespace
}  // namespace cell::protocols::excalibur
