#include "cell/service/directory.hpp"

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <pthread.h>
#include <unistd.h>

#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <optional>

#include "cell/bus/qos.hpp"
#include "cell/bus/topics.hpp"
#include "cell/bus/view.hpp"
#include "cell/bus/writer.hpp"
#include "cell/common/time.hpp"
#include "cell/common/version.hpp"
#include "cell/process/child.hpp"
#include "cell/service/health.hpp"
#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"

namespace cell::service {
namespace {

using ::cell::testing::eventually;
using ::cell::testing::IsErrWith;
using ::cell::testing::IsOk;
using ::testing::ElementsAre;
using ::testing::Field;
using ::testing::HasSubstr;
using namespace std::chrono_literals;

std::string hostname() {
  char host[256] = {};
  gethostname(host, sizeof host - 1);
  return host;
}

/// The body of the re-executed ghost (see WriterThatStopsAssertingIsLost...): one heartbeat,
/// then silence until SIGUSR1, then one more heartbeat and silence until killed.
[[noreturn]] void run_ghost(const char* domain, const char* partition) {
  sigset_t usr1;
  sigemptyset(&usr1);
  sigaddset(&usr1, SIGUSR1);
  pthread_sigmask(SIG_BLOCK, &usr1, nullptr);  // before Cyclone starts its threads
  try {
    bus::Participant participant(static_cast<std::uint32_t>(std::strtoul(domain, nullptr, 10)),
                                 partition);
    bus::Topic<cell_health_ServiceHeartbeat> topic(participant, bus::topics::kHeartbeat);
    bus::Writer<cell_health_ServiceHeartbeat> writer(participant, topic, bus::topics::kHeartbeat);
    const std::string id = "ghost";
    const std::string empty;
    cell_health_ServiceHeartbeat beat{};
    beat.service_id = bus::borrow(id);
    beat.service_kind = bus::borrow(id);
    beat.host = bus::borrow(empty);
    beat.detail = bus::borrow(empty);
    beat.version = bus::borrow(empty);
    beat.pid = static_cast<std::int32_t>(getpid());
    beat.state = cell_health_HEALTH_SERVING;
    beat.stamp_ns = wall_time_ns();
    beat.seq = 1;
    (void)writer.write(beat);
    int sig = 0;
    sigwait(&usr1, &sig);
    beat.seq = 2;
    beat.stamp_ns = wall_time_ns();
    (void)writer.write(beat);
    pause();  // killed by the test (process::Child's destructor)
  } catch (const std::exception& e) {
    std::fprintf(stderr, "ghost: %s\n", e.what());
  }
  std::_Exit(1);
}

/// Runs during static initialisation, before gtest: only in the re-executed ghost.
[[maybe_unused]] const bool kGhost = [] {
  const char* domain = std::getenv("CELL_GHOST_DOMAIN");
  const char* partition = std::getenv("CELL_GHOST_PARTITION");
  if (domain != nullptr && partition != nullptr) {
    run_ghost(domain, partition);
  }
  return false;
}();

/// Services live on their own participant; the directory on another, as across processes.
class DirectoryTest : public ::testing::Test {
 protected:
  DirectoryTest()
      : partition_(cell::testing::unique_partition()),
        services_(cell::testing::test_domain_id(), partition_),
        observer_(cell::testing::test_domain_id(), partition_),
        directory_(observer_, "directory-test") {}

  std::unique_ptr<HealthReporter> reporter(const std::string& id, const std::string& kind) {
    CommonConfig config;
    config.service_id = id;
    config.heartbeat_period_s = 0.1;
    config.stall_timeout_s = 60.0;  // these tests are not about stalls
    return std::make_unique<HealthReporter>(services_, config, kind);
  }

  /// The entry of `id` in a fresh snapshot, if listed.
  std::optional<ServiceEntry> find(const std::string& id) {
    auto snap = directory_.snapshot();
    EXPECT_THAT(snap, IsOk());
    if (snap) {
      for (auto& entry : *snap) {
        if (entry.service_id == id) {
          return entry;
        }
      }
    }
    return std::nullopt;
  }

  std::string partition_;
  bus::Participant services_;
  bus::Participant observer_;
  ServiceDirectory directory_;
};

TEST_F(DirectoryTest, ListsEveryLiveServiceWithItsHeartbeatFields) {
  const std::int64_t before_ns = wall_time_ns();
  auto alpha = reporter("alpha", "echo");
  auto beta = reporter("beta", "vision");
  alpha->set(cell_health_HEALTH_SERVING);
  beta->set(cell_health_HEALTH_DEGRADED, "camera missing");

  auto settled = directory_.wait_settled(10s, {"alpha", "beta"});
  ASSERT_THAT(settled, IsOk());
  EXPECT_THAT(*settled, ElementsAre(Field(&ServiceEntry::service_id, "alpha"),
                                    Field(&ServiceEntry::service_id, "beta")));
  // The states set above are published at once; the first beat may predate them.
  ASSERT_TRUE(eventually(
      [&] {
        const auto a = find("alpha");
        const auto b = find("beta");
        return a && b && a->status() == "serving" && b->status() == "degraded";
      },
      5s));
  const auto beta_entry = find("beta");
  ASSERT_TRUE(beta_entry.has_value());
  EXPECT_EQ(beta_entry->kind, "vision");
  EXPECT_EQ(beta_entry->detail, "camera missing");
  EXPECT_EQ(beta_entry->pid, getpid());
  EXPECT_EQ(beta_entry->host, hostname());
  EXPECT_EQ(beta_entry->version, std::string(version()));
  EXPECT_FALSE(beta_entry->lost);
  EXPECT_GE(beta_entry->uptime_s, 0.0);
  EXPECT_GE(beta_entry->last_heartbeat_ns, before_ns);
  EXPECT_LE(beta_entry->last_heartbeat_ns, wall_time_ns());
  EXPECT_GE(beta_entry->seq, 1U);
}

TEST_F(DirectoryTest, SeesOnlyItsOwnPartition) {
  bus::Participant elsewhere(cell::testing::test_domain_id(), cell::testing::unique_partition());
  CommonConfig config;
  config.service_id = "stranger";
  config.stall_timeout_s = 60.0;
  HealthReporter stranger(elsewhere, config, "echo");
  auto mine = reporter("mine", "echo");

  auto settled = directory_.wait_settled(10s, {"mine"});
  ASSERT_THAT(settled, IsOk());
  EXPECT_THAT(*settled, ElementsAre(Field(&ServiceEntry::service_id, "mine")));
  // Give the stranger every chance to leak in before concluding it does not.
  auto later = directory_.wait_settled(1s, {"mine", "stranger"}, 1s);
  ASSERT_THAT(later, IsOk());
  EXPECT_THAT(*later, ElementsAre(Field(&ServiceEntry::service_id, "mine")));
}

// Cyclone tracks writer liveliness leases for writers of other processes only (a writer in
// this process is delivered to locally, without a lease), so the silent writer runs in a
// child: this very test binary, re-executed with CELL_GHOST_PARTITION set, which turns it into
// a heartbeat writer (see kGhost below) before gtest even starts.
TEST_F(DirectoryTest, WriterThatStopsAssertingIsLostWithinTheLeaseAndComesBack) {
  process::SpawnOptions options;
  // readlink, not "/proc/self/exe" itself: under valgrind that would be valgrind.
  options.executable = std::filesystem::read_symlink("/proc/self/exe").string();
  options.env = {fmt::format("CELL_GHOST_DOMAIN={}", cell::testing::test_domain_id()),
                 "CELL_GHOST_PARTITION=" + partition_};
  auto ghost = process::Child::spawn(options);
  ASSERT_THAT(ghost, IsOk());

  ASSERT_THAT(directory_.wait_settled(10s, {"ghost"}), IsOk());
  const auto alive = find("ghost");
  ASSERT_TRUE(alive.has_value()) << ghost->output();
  EXPECT_EQ(alive->status(), "serving");
  EXPECT_EQ(alive->pid, ghost->pid());

  const auto silent_since = std::chrono::steady_clock::now();
  ASSERT_TRUE(eventually(
      [&] {
        const auto entry = find("ghost");
        return entry && entry->lost;
      },
      8s))
      << "a writer silent past its 3 s liveliness lease must show as lost";
  const double lost_after_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - silent_since).count();
  EXPECT_GE(lost_after_s, 1.5);  // not before the lease (3 s, minus discovery and settling)
  EXPECT_EQ(find("ghost")->status(), "lost");
  EXPECT_EQ(find("ghost")->pid, ghost->pid());  // the last word of the dead stays readable

  ghost->signal(SIGUSR1);  // beats again, seq 2: as a service restarted under the same id
  EXPECT_TRUE(eventually(
      [&] {
        const auto entry = find("ghost");
        return entry && !entry->lost && entry->seq == 2;
      },
      5s));
}

TEST_F(DirectoryTest, CleanlyStoppedServiceIsGone) {
  auto alpha = reporter("alpha", "echo");
  auto beta = reporter("beta", "echo");
  ASSERT_THAT(directory_.wait_settled(10s, {"alpha", "beta"}), IsOk());
  beta.reset();  // publishes stopping, then disposes its instance
  EXPECT_TRUE(eventually([&] { return !find("beta").has_value(); }, 5s));
  EXPECT_TRUE(find("alpha").has_value());
}

TEST_F(DirectoryTest, WaitSettledWithNobodyReturnsEmptyAtTheTimeout) {
  const auto t0 = std::chrono::steady_clock::now();
  auto settled = directory_.wait_settled(400ms);
  const auto waited = std::chrono::steady_clock::now() - t0;
  ASSERT_THAT(settled, IsOk());
  EXPECT_TRUE(settled->empty());
  EXPECT_GE(waited, 400ms);
  EXPECT_LT(waited, 5s);
}

TEST_F(DirectoryTest, PingReportsTheRoundTripOfEveryService) {
  auto alpha = reporter("alpha", "echo");
  auto beta = reporter("beta", "echo");
  ASSERT_THAT(directory_.wait_settled(10s, {"alpha", "beta"}), IsOk());

  auto replies = directory_.ping(10s, {"alpha", "beta"});
  ASSERT_THAT(replies, IsOk());
  ASSERT_THAT(*replies, ElementsAre(Field(&PingResult::service_id, "alpha"),
                                    Field(&PingResult::service_id, "beta")));
  for (const auto& reply : *replies) {
    EXPECT_EQ(reply.pid, getpid());
    EXPECT_EQ(reply.host, hostname());
    EXPECT_GT(reply.rtt_ms, 0.0);
    EXPECT_LT(reply.rtt_ms, 10000.0);
  }

  // Without an expected set it collects until the deadline; a second ping works too.
  auto again = directory_.ping(1s);
  ASSERT_THAT(again, IsOk());
  EXPECT_EQ(again->size(), 2U);
}

TEST_F(DirectoryTest, PingWithNobodyOnTheBusIsATimeoutNamingTheBus) {
  auto replies = directory_.ping(300ms);
  EXPECT_THAT(replies, IsErrWith(Errc::kTimeout, "partition '" + partition_ + "'"));
}

TEST(ServiceEntry, StatusIsLostOrTheReportedState) {
  ServiceEntry entry;
  entry.state = cell_health_HEALTH_DEGRADED;
  EXPECT_EQ(entry.status(), "degraded");
  entry.lost = true;
  EXPECT_EQ(entry.status(), "lost");
}

}  // namespace
}  // namespace cell::service
