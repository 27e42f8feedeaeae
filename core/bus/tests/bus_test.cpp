#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <thread>

#include "cell/bus/reader.hpp"
#include "cell/bus/request_reply.hpp"
#include "cell/bus/topics.hpp"
#include "cell/bus/view.hpp"
#include "cell/bus/writer.hpp"
#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"

namespace cell::bus {
namespace {

using ::cell::testing::IsErr;
using ::cell::testing::IsOk;
using namespace std::chrono_literals;

class BusTest : public ::testing::Test {
 protected:
  BusTest() : participant_(cell::testing::test_domain_id(), cell::testing::unique_partition()) {}
  Participant participant_;
};

cell_robot_RobotState make_state(const std::string& id, const std::vector<double>& joints,
                                 const std::string& fault) {
  cell_robot_RobotState s{};
  s.robot_id = borrow(id);
  borrow(s.position_rad_or_mm, joints);
  s.fault_text = borrow(fault);
  s.header.seq = 7;
  return s;
}

TEST_F(BusTest, WriterToReaderCarriesStringsAndSequences) {
  Topic<cell_robot_RobotState> topic(participant_, topics::kRobotStateLatest);
  Writer<cell_robot_RobotState> writer(participant_, topic, topics::kRobotStateLatest);
  Reader<cell_robot_RobotState> reader(participant_, topic, topics::kRobotStateLatest);
  ASSERT_TRUE(writer.wait_for_readers(1, 5s));

  const std::string id = "ibm7545";
  const std::vector<double> joints{0.1, -0.2, 150.0, 3.0};
  const std::string fault = "J1 positive overrun";
  ASSERT_THAT(writer.write(make_state(id, joints, fault)), IsOk());
  ASSERT_TRUE(reader.wait_for_data(5s));

  int seen = 0;
  auto n = reader.take_each([&](const cell_robot_RobotState& s, const dds_sample_info_t&) {
    EXPECT_EQ(str(s.robot_id), "ibm7545");
    EXPECT_EQ(to_vector(s.position_rad_or_mm), joints);
    EXPECT_EQ(str(s.fault_text), fault);
    EXPECT_EQ(s.header.seq, 7U);
    ++seen;
  });
  ASSERT_THAT(n, IsOk());
  EXPECT_EQ(*n, 1U);
  EXPECT_EQ(seen, 1);
}

TEST_F(BusTest, CopiesOutliveTheReaderAndFreeThemselves) {
  std::vector<Owned<cell_robot_RobotState>> copies;
  {
    Topic<cell_robot_RobotState> topic(participant_, topics::kRobotStateLatest);
    Writer<cell_robot_RobotState> writer(participant_, topic, qos::command().get());
    Reader<cell_robot_RobotState> reader(participant_, topic, qos::command().get());
    ASSERT_TRUE(writer.wait_for_readers(1, 5s));
    const std::vector<double> joints(100, 1.5);
    for (int i = 0; i < 3; ++i) {
      ASSERT_THAT(writer.write(make_state("r" + std::to_string(i), joints, "")), IsOk());
    }
    ASSERT_TRUE(cell::testing::eventually(
        [&] {
          auto batch = reader.take_copies(8);
          for (auto& c : *batch) {
            copies.push_back(std::move(c));
          }
          return copies.size() == 3;
        },
        5s));
  }
  EXPECT_EQ(str(copies[2]->robot_id), "r2");
  EXPECT_EQ(span(copies[2]->position_rad_or_mm).size(), 100U);
}

TEST_F(BusTest, TransientLocalStateReachesALateReader) {
  Topic<cell_robot_RobotState> topic(participant_, topics::kRobotStateLatest);
  Writer<cell_robot_RobotState> writer(participant_, topic, topics::kRobotStateLatest);
  const std::vector<double> joints{1.0};
  ASSERT_THAT(writer.write(make_state("early", joints, "")), IsOk());
  Reader<cell_robot_RobotState> late(participant_, topic, topics::kRobotStateLatest);
  ASSERT_TRUE(late.wait_for_data(5s));
  auto copies = late.take_copies();
  ASSERT_THAT(copies, IsOk());
  ASSERT_EQ(copies->size(), 1U);
  EXPECT_EQ(str((*copies)[0]->robot_id), "early");
}

TEST_F(BusTest, PartitionsIsolateCellsOnOneDomain) {
  Participant other(participant_.domain_id(), cell::testing::unique_partition());
  Topic<cell_robot_RobotState> topic(participant_, topics::kRobotStateLatest);
  Topic<cell_robot_RobotState> other_topic(other, topics::kRobotStateLatest);
  Writer<cell_robot_RobotState> writer(participant_, topic, topics::kRobotStateLatest);
  Reader<cell_robot_RobotState> reader(other, other_topic, topics::kRobotStateLatest);
  EXPECT_FALSE(writer.wait_for_readers(1, 1500ms));
  EXPECT_EQ(reader.matched_writers(), 0U);
}

TEST_F(BusTest, ReaderSeesLivelinessLossOfASilentWriter) {
  Topic<cell_health_ServiceHeartbeat> topic(participant_, topics::kHeartbeat);
  Reader<cell_health_ServiceHeartbeat> reader(participant_, topic, topics::kHeartbeat);
  const std::string id = "svc";
  {
    Participant writer_side(participant_.domain_id(), participant_.partition());
    Topic<cell_health_ServiceHeartbeat> wtopic(writer_side, topics::kHeartbeat);
    Writer<cell_health_ServiceHeartbeat> writer(writer_side, wtopic, qos::heartbeat(0.3).get());
    cell_health_ServiceHeartbeat beat{};
    beat.service_id = borrow(id);
    ASSERT_TRUE(writer.wait_for_readers(1, 5s));
    ASSERT_THAT(writer.write(beat), IsOk());
    ASSERT_TRUE(reader.wait_for_data(5s));
    auto alive = [&] {
      std::size_t n = 0;
      (void)reader.read_each([&](const auto&, const auto&) { ++n; },
                             DDS_ANY_SAMPLE_STATE | DDS_ANY_VIEW_STATE | DDS_ALIVE_INSTANCE_STATE);
      return n;
    };
    EXPECT_EQ(alive(), 1U);
    // Stop writing: the 0.3 s lease expires although the writer still exists.
    EXPECT_TRUE(cell::testing::eventually([&] { return alive() == 0; }, 3s));
  }
}

TEST_F(BusTest, RequesterGetsItsOwnReplyAndTimesOutWithoutServer) {
  Topic<cell_health_PingRequest> req_topic(participant_, topics::kPingRequest);
  Topic<cell_health_PingReply> rep_topic(participant_, topics::kPingReply);
  Reader<cell_health_PingRequest> server_in(participant_, req_topic, topics::kPingRequest);
  Writer<cell_health_PingReply> server_out(participant_, rep_topic, topics::kPingReply);

  std::atomic<bool> stop{false};
  std::thread server([&] {
    while (!stop) {
      if (!server_in.wait_for_data(50ms)) {
        continue;
      }
      (void)server_in.take_each([&](const cell_health_PingRequest& req, const auto&) {
        cell_health_PingReply rep{};
        rep.request_id = req.request_id;
        const std::string sid = "server";
        rep.service_id = borrow(sid);
        rep.sent_ns = req.sent_ns;
        (void)server_out.write(rep);
      });
    }
  });

  Requester<cell_health_PingRequest, cell_health_PingReply> a(
      participant_, topics::kPingRequest, topics::kPingReply, "a");
  Requester<cell_health_PingRequest, cell_health_PingReply> b(
      participant_, topics::kPingRequest, topics::kPingReply, "b");
  for (int i = 1; i <= 3; ++i) {
    cell_health_PingRequest ra{};
    ra.sent_ns = 1000 + i;
    cell_health_PingRequest rb{};
    rb.sent_ns = 2000 + i;
    auto sa = a.send(ra, 5s);
    auto sb = b.send(rb, 5s);
    ASSERT_THAT(sa, IsOk());
    ASSERT_THAT(sb, IsOk());
    auto reply_b = b.wait_reply(*sb, std::chrono::steady_clock::now() + 5s);
    auto reply_a = a.wait_reply(*sa, std::chrono::steady_clock::now() + 5s);
    ASSERT_THAT(reply_a, IsOk());
    ASSERT_THAT(reply_b, IsOk());
    EXPECT_EQ((*reply_a)->sent_ns, 1000 + i);
    EXPECT_EQ((*reply_b)->sent_ns, 2000 + i);
    EXPECT_EQ(str((*reply_a)->service_id), "server");
  }
  stop = true;
  server.join();

  Participant lonely(participant_.domain_id(), cell::testing::unique_partition());
  Requester<cell_health_PingRequest, cell_health_PingReply> c(lonely, topics::kPingRequest,
                                                               topics::kPingReply, "c");
  cell_health_PingRequest rc{};
  auto r = c.call(rc, 300ms);
  EXPECT_THAT(r, IsErr(Errc::kTimeout));
  EXPECT_THAT(r.error().message, ::testing::HasSubstr("cell/health/ping"));
}

// Regression: Cyclone 0.10.2 reuses a reader's cached loan with the size of the largest loan
// ever taken; reads and takes of different batch sizes on one reader overflowed the smaller
// buffer. Many instances, a read then takes on the same reader.
TEST_F(BusTest, ReadThenTakeOfManyInstancesOnOneReader) {
  Topic<cell_robot_RobotState> topic(participant_, topics::kRobotStateLatest);
  Writer<cell_robot_RobotState> writer(participant_, topic, topics::kRobotStateLatest);
  Reader<cell_robot_RobotState> reader(participant_, topic, topics::kRobotStateLatest);
  ASSERT_TRUE(writer.wait_for_readers(1, 5s));
  const std::vector<double> joints{1.0, 2.0};
  for (int i = 0; i < 150; ++i) {
    ASSERT_THAT(writer.write(make_state("robot" + std::to_string(i), joints, "")), IsOk());
  }
  std::size_t read = 0;
  ASSERT_TRUE(cell::testing::eventually(
      [&] {
        auto n = reader.read_each([](const auto&, const auto&) {});
        read = n ? *n : 0;
        return read == 64;  // a read returns one batch
      },
      5s));
  std::size_t taken = 0;
  ASSERT_TRUE(cell::testing::eventually(
      [&] {
        auto n = reader.take_each([&](const cell_robot_RobotState& s, const auto&) {
          EXPECT_EQ(span(s.position_rad_or_mm).size(), 2U);
        });
        taken += n ? *n : 0;
        return taken == 150;
      },
      5s));
}

// A command reaches a server discovered a moment after it was written, but not one that
// appears after its lifespan: a restarted gateway must not replay a stale move.
TEST_F(BusTest, CommandsReachLateServersWithinTheirLifespanOnly) {
  Topic<cell_robot_RobotCommand> topic(participant_, topics::kRobotCommand);
  Writer<cell_robot_RobotCommand> writer(participant_, topic, qos::command(0.5).get());
  const std::string robot = "ibm7545";
  cell_robot_RobotCommand c{};
  c.robot_id = borrow(robot);
  c.kind = cell_robot_CMD_HOME;
  ASSERT_THAT(writer.write(c), IsOk());
  {
    Participant late(participant_.domain_id(), participant_.partition());
    Topic<cell_robot_RobotCommand> late_topic(late, topics::kRobotCommand);
    Reader<cell_robot_RobotCommand> reader(late, late_topic, qos::command(0.5).get());
    ASSERT_TRUE(reader.wait_for_data(3s));
    auto got = reader.take_copies();
    ASSERT_THAT(got, IsOk());
    ASSERT_EQ(got->size(), 1U);
    EXPECT_EQ((*got)[0]->kind, cell_robot_CMD_HOME);
  }
  std::this_thread::sleep_for(700ms);  // past the 0.5 s lifespan
  Participant later(participant_.domain_id(), participant_.partition());
  Topic<cell_robot_RobotCommand> later_topic(later, topics::kRobotCommand);
  Reader<cell_robot_RobotCommand> reader(later, later_topic, qos::command(0.5).get());
  ASSERT_TRUE(reader.wait_for_writers(1, 3s));
  EXPECT_FALSE(reader.wait_for_data(500ms));
}

TEST(Participant, BadDomainIsASetupError) {
  EXPECT_THROW(Participant(9999, "p"), BusError);
  EXPECT_THROW(Participant(1, ""), BusError);
}

}  // namespace
}  // namespace cell::bus
