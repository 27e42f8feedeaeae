#include "stream_hub.hpp"

#include <thread>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace cell::monitor {
namespace {

using namespace std::chrono_literals;

std::vector<std::string> drain(ClientQueue& q) {
  std::vector<std::shared_ptr<const std::string>> frames;
  q.pop_all(frames, 0ms);
  std::vector<std::string> out;
  out.reserve(frames.size());
  for (const auto& f : frames) {
    out.push_back(*f);
  }
  return out;
}

TEST(StreamMessage, FramesAsServerSentEvents) {
  EXPECT_EQ((StreamMessage{"robots", R"({"a":1})"}).frame(), "event: robots\ndata: {\"a\":1}\n\n");
  // A raw newline would end the event early: it continues on a new data line.
  EXPECT_EQ((StreamMessage{"x", "a\nb\r"}).frame(), "event: x\ndata: a\ndata: b\n\n");
}

TEST(ClientQueue, DropsTheOldestWhenFullAndCountsIt) {
  ClientQueue q(3);
  for (int i = 0; i < 5; ++i) {
    q.push(std::make_shared<const std::string>(std::to_string(i)));
  }
  EXPECT_EQ(q.dropped(), 2U);
  EXPECT_THAT(drain(q), ::testing::ElementsAre("2", "3", "4"));
  EXPECT_EQ(q.size(), 0U);
}

TEST(ClientQueue, WakesTheReaderOnPushAndOnClose) {
  ClientQueue q(8);
  std::thread writer([&] {
    std::this_thread::sleep_for(20ms);
    q.push(std::make_shared<const std::string>("hello"));
  });
  std::vector<std::shared_ptr<const std::string>> frames;
  const auto start = std::chrono::steady_clock::now();
  EXPECT_TRUE(q.pop_all(frames, 5s));
  EXPECT_LT(std::chrono::steady_clock::now() - start, 4s);  // woken, not timed out
  ASSERT_EQ(frames.size(), 1U);
  writer.join();
  q.close();
  frames.clear();
  EXPECT_FALSE(q.pop_all(frames, 5s));  // closed and empty: at once
  q.push(std::make_shared<const std::string>("late"));
  EXPECT_EQ(q.size(), 0U);
}

TEST(StreamHub, NewClientsGetTheStickyStateFirst) {
  StreamHub hub(16, 4);
  hub.publish({"health", "h1"}, "health");
  hub.publish({"event", "e1"});  // not sticky
  hub.publish({"health", "h2"}, "health");
  hub.remember({"robots", "r1"}, "robot/a");
  auto id = hub.connect();
  ASSERT_TRUE(id);
  auto frames = drain(*hub.queue(*id));
  ASSERT_EQ(frames.size(), 2U);
  EXPECT_THAT(frames, ::testing::UnorderedElementsAre("event: health\ndata: h2\n\n",
                                                      "event: robots\ndata: r1\n\n"));
  hub.forget("robot/a");
  auto id2 = hub.connect();
  EXPECT_EQ(drain(*hub.queue(*id2)).size(), 1U);
}

TEST(StreamHub, ASlowClientDoesNotHoldBackAFastOne) {
  StreamHub hub(16, 4);
  auto slow = hub.connect();
  auto fast = hub.connect();
  ASSERT_TRUE(slow && fast);
  std::size_t fast_got = 0;
  for (int i = 0; i < 1000; ++i) {
    hub.publish({"robots", std::to_string(i)});
    fast_got += drain(*hub.queue(*fast)).size();
  }
  EXPECT_EQ(fast_got, 1000U);
  EXPECT_EQ(hub.queue(*slow)->size(), 16U);  // bounded
  EXPECT_EQ(hub.dropped_total(), 1000U - 16U);
  auto last = drain(*hub.queue(*slow));
  EXPECT_EQ(last.back(), "event: robots\ndata: 999\n\n");  // the newest survived
}

TEST(StreamHub, RefusesClientsBeyondTheLimitAndFreesSlots) {
  StreamHub hub(16, 2);
  auto a = hub.connect();
  auto b = hub.connect();
  EXPECT_TRUE(a && b);
  EXPECT_FALSE(hub.connect());
  hub.disconnect(*a);
  EXPECT_EQ(hub.queue(*a), nullptr);
  EXPECT_TRUE(hub.connect());
  EXPECT_EQ(hub.client_count(), 2U);
}

}  // namespace
}  // namespace cell::monitor
