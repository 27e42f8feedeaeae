#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cstdlib>
#include <thread>

#include "cell/bus/reader.hpp"
#include "cell/bus/request_reply.hpp"
#include "cell/bus/view.hpp"
#include "cell/service/common_config.hpp"
#include "cell/service/health.hpp"
#include "cell/service/shutdown.hpp"
#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"

namespace cell::service {
namespace {

using ::cell::testing::IsErrWith;
using ::cell::testing::IsOk;
using namespace std::chrono_literals;

class HealthTest : public ::testing::Test {
 protected:
  HealthTest()
      : participant_(cell::testing::test_domain_id(), cell::testing::unique_partition()),
        topic_(participant_, bus::topics::kHeartbeat),
        reader_(participant_, topic_, bus::topics::kHeartbeat) {
    config_.service_id = "svc-under-test";
    config_.heartbeat_period_s = 0.1;
    config_.stall_timeout_s = 0.4;
  }

  /// The newest alive heartbeat of svc-under-test, if any.
  std::optional<cell_health_HealthState> latest_state(std::string* detail = nullptr) {
    std::optional<cell_health_HealthState> state;
    (void)reader_.read_each(
        [&](const cell_health_ServiceHeartbeat& beat, const dds_sample_info_t&) {
          if (bus::str(beat.service_id) == "svc-under-test") {
            state = beat.state;
            if (detail != nullptr) {
              *detail = bus::str(beat.detail);
            }
          }
        },
        DDS_ANY_SAMPLE_STATE | DDS_ANY_VIEW_STATE | DDS_ALIVE_INSTANCE_STATE);
    return state;
  }

  bus::Participant participant_;
  bus::Topic<cell_health_ServiceHeartbeat> topic_;
  bus::Reader<cell_health_ServiceHeartbeat> reader_;
  CommonConfig config_;
};

TEST_F(HealthTest, PublishesStateChangesAndPeriodicBeats) {
  HealthReporter health(participant_, config_, "echo");
  health.tick();
  health.set(cell_health_HEALTH_SERVING);
  ASSERT_TRUE(cell::testing::eventually(
      [&] { return latest_state() == cell_health_HEALTH_SERVING; }, 5s));
  const auto sent = health.heartbeats_sent();
  std::this_thread::sleep_for(350ms);
  EXPECT_GE(health.heartbeats_sent(), sent + 2);  // 0.1 s period
}

TEST_F(HealthTest, StalledMainLoopIsReportedDegradedThenRecovers) {
  HealthReporter health(participant_, config_, "echo");
  health.set(cell_health_HEALTH_SERVING);
  health.tick();
  std::string detail;
  ASSERT_TRUE(cell::testing::eventually(
      [&] { return latest_state(&detail) == cell_health_HEALTH_DEGRADED; }, 5s));
  EXPECT_THAT(detail, ::testing::HasSubstr("main loop stalled"));
  ASSERT_TRUE(cell::testing::eventually(
      [&] {
        health.tick();
        return latest_state() == cell_health_HEALTH_SERVING;
      },
      5s));
}

TEST_F(HealthTest, DisposesItsInstanceOnCleanStop) {
  {
    HealthReporter health(participant_, config_, "echo");
    health.set(cell_health_HEALTH_SERVING);
    ASSERT_TRUE(cell::testing::eventually([&] { return latest_state().has_value(); }, 5s));
  }
  EXPECT_TRUE(cell::testing::eventually([&] { return !latest_state().has_value(); }, 5s));
}

TEST_F(HealthTest, AnswersPingsAddressedToItOrToEveryone) {
  HealthReporter health(participant_, config_, "echo");
  bus::Requester<cell_health_PingRequest, cell_health_PingReply> pinger(
      participant_, bus::topics::kPingRequest, bus::topics::kPingReply, "tester");
  cell_health_PingRequest ping{};
  const std::string target = "svc-under-test";
  ping.target_service_id = bus::borrow(target);
  ping.sent_ns = 42;
  auto reply = pinger.call(ping, 5s);
  ASSERT_THAT(reply, IsOk());
  EXPECT_EQ(bus::str((*reply)->service_id), "svc-under-test");
  EXPECT_EQ((*reply)->sent_ns, 42);
  EXPECT_EQ((*reply)->pid, getpid());

  const std::string nobody = "nobody";
  ping.target_service_id = bus::borrow(nobody);
  auto none = pinger.call(ping, 500ms);
  EXPECT_FALSE(none.has_value());
}

TEST(CommonConfig, ValidateNamesKeyAndValue) {
  CommonConfig c;
  c.service_id = "x";
  c.domain_id = 300;
  EXPECT_THAT(c.validate(), IsErrWith(Errc::kConfig, "service.domain_id must be 0..230, got 300"));
  c.domain_id = 0;
  c.heartbeat_period_s = 5;
  EXPECT_THAT(c.validate(), IsErrWith(Errc::kConfig, "heartbeat_period_s"));
}

TEST(CommonConfig, ReadsTheServiceSectionStrictly) {
  auto doc = config::load_string("service:\n  id: v1\n  domain_id: 7\n  log_level: loud\n",
                                 "v.yaml");
  ASSERT_TRUE(doc);
  config::MapReader root(*doc, doc->root, "");
  CommonConfig c;
  read_common(root, c);
  EXPECT_THAT(root.finish(),
              IsErrWith(Errc::kConfig, "v.yaml:4:14: key 'service.log_level': expected debug"));
  EXPECT_EQ(c.service_id, "v1");
  EXPECT_EQ(c.domain_id, 7U);
}

TEST(CommonConfig, EnvironmentOverridesAndRejectsGarbage) {
  CommonConfig c;
  c.service_id = "x";
  setenv("CELL_DOMAIN_ID", "12", 1);
  setenv("CELL_PARTITION", "cell-b", 1);
  EXPECT_THAT(apply_environment(c), IsOk());
  EXPECT_EQ(c.domain_id, 12U);
  EXPECT_EQ(c.partition, "cell-b");
  setenv("CELL_DOMAIN_ID", "twelve", 1);
  EXPECT_THAT(apply_environment(c), IsErrWith(Errc::kConfig, "CELL_DOMAIN_ID"));
  unsetenv("CELL_DOMAIN_ID");
  unsetenv("CELL_PARTITION");
}

TEST(ShutdownSignal, SignalRunsCallbacksOnce) {
  ShutdownSignal shutdown;
  std::atomic<int> calls{0};
  const int handle = shutdown.on_stop([&] { calls++; });
  kill(getpid(), SIGTERM);
  ASSERT_TRUE(cell::testing::eventually([&] { return shutdown.requested(); }, 5s));
  EXPECT_EQ(shutdown.signal_number(), SIGTERM);
  EXPECT_EQ(calls.load(), 1);
  shutdown.remove(handle);
  shutdown.request();  // already requested: no second call
  EXPECT_EQ(calls.load(), 1);
}

}  // namespace
}  // namespace cell::service
