#include <unistd.h>

#include <cstdlib>
#include <sstream>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "cell/service/health.hpp"
#include "cell/testing/env.hpp"
#include "cli_run.hpp"
#include "session.hpp"
#include "table.hpp"

namespace cell::cellctl {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;
using namespace std::chrono_literals;

using testing::CliRun;
using testing::cellctl;

/// A bus of our own with one or two services on it (HealthReporters in this process).
class CellctlTest : public ::testing::Test {
 protected:
  CellctlTest()
      : domain_(cell::testing::test_domain_id()),
        partition_(cell::testing::unique_partition()),
        participant_(domain_, partition_) {}

  void add_service(const std::string& id,
                   cell_health_HealthState state,
                   const std::string& detail = {}) {
    service::CommonConfig config;
    config.service_id = id;
    config.heartbeat_period_s = 0.2;
    config.stall_timeout_s = 60.0;
    services_.push_back(std::make_unique<service::HealthReporter>(participant_, config, "echo"));
    services_.back()->set(state, detail);
  }

  std::vector<std::string> bus_args() const {
    return {"--domain", std::to_string(domain_), "--partition", partition_};
  }

  std::vector<std::string> with_bus(std::vector<std::string> args) const {
    auto all = bus_args();
    all.insert(all.end(), args.begin(), args.end());
    return all;
  }

  std::uint32_t domain_;
  std::string partition_;
  bus::Participant participant_;
  std::vector<std::unique_ptr<service::HealthReporter>> services_;
};

TEST(Cellctl, UsageErrorsExitTwo) {
  EXPECT_EQ(cellctl({}).code, kExitUsage);
  const CliRun unknown = cellctl({"frobnicate"});
  EXPECT_EQ(unknown.code, kExitUsage);
  EXPECT_THAT(unknown.err, HasSubstr("frobnicate"));
  const CliRun domain = cellctl({"--domain", "231", "ping"});
  EXPECT_EQ(domain.code, kExitUsage);
  EXPECT_THAT(domain.err, HasSubstr("--domain must be 0..230, got 231"));
  const CliRun timeout = cellctl({"--timeout", "0", "ping"});
  EXPECT_EQ(timeout.code, kExitUsage);
  EXPECT_THAT(timeout.err, HasSubstr("--timeout"));
  EXPECT_EQ(cellctl({"--help"}).code, kExitOk);
}

TEST(Cellctl, GarbageInTheEnvironmentIsAUsageErrorNamingTheVariable) {
  setenv("CELL_DOMAIN_ID", "seven", 1);
  const CliRun run = cellctl({"ping"});
  unsetenv("CELL_DOMAIN_ID");
  EXPECT_EQ(run.code, kExitUsage);
  EXPECT_THAT(run.err, HasSubstr("environment CELL_DOMAIN_ID must be 0..230, got 'seven'"));
}

TEST_F(CellctlTest, PingWithNobodyNamesTheDomainAndPartition) {
  const CliRun run = cellctl(with_bus({"--timeout", "0.3", "ping"}));
  EXPECT_EQ(run.code, kExitFailure);
  EXPECT_THAT(run.err, HasSubstr(fmt::format("no service found on domain {}, partition '{}'",
                                             domain_, partition_)));
  // Global options work after the subcommand too.
  const CliRun json_run = cellctl(with_bus({"ping", "--json", "--timeout", "0.3"}));
  EXPECT_EQ(json_run.code, kExitFailure);
  const auto doc = nlohmann::json::parse(json_run.out);
  EXPECT_TRUE(doc["services"].empty());
  EXPECT_THAT(doc["error"].get<std::string>(), HasSubstr(partition_));
}

TEST_F(CellctlTest, PingListsEveryServiceAsJson) {
  add_service("alpha", cell_health_HEALTH_SERVING);
  add_service("beta", cell_health_HEALTH_DEGRADED, "camera missing");
  const CliRun run = cellctl(with_bus({"--json", "--timeout", "5", "ping"}));
  ASSERT_EQ(run.code, kExitOk) << run.err;
  const auto doc = nlohmann::json::parse(run.out);
  EXPECT_EQ(doc["domain"].get<std::uint32_t>(), domain_);
  EXPECT_EQ(doc["partition"].get<std::string>(), partition_);
  ASSERT_EQ(doc["services"].size(), 2U) << run.out;
  const auto& alpha = doc["services"][0];
  EXPECT_EQ(alpha["id"], "alpha");
  EXPECT_EQ(alpha["kind"], "echo");
  EXPECT_EQ(alpha["pid"].get<int>(), getpid());
  EXPECT_EQ(alpha["state"], "serving");
  EXPECT_FALSE(alpha["lost"].get<bool>());
  EXPECT_GE(alpha["uptime_s"].get<double>(), 0.0);
  EXPECT_FALSE(alpha.contains("rtt_ms"));
  const auto& beta = doc["services"][1];
  EXPECT_EQ(beta["id"], "beta");
  EXPECT_EQ(beta["state"], "degraded");
  EXPECT_EQ(beta["detail"], "camera missing");
}

TEST_F(CellctlTest, PingRttReportsARoundTripPerService) {
  add_service("alpha", cell_health_HEALTH_SERVING);
  add_service("beta", cell_health_HEALTH_SERVING);
  const CliRun run = cellctl(with_bus({"--json", "--timeout", "5", "ping", "--rtt"}));
  ASSERT_EQ(run.code, kExitOk) << run.err;
  const auto doc = nlohmann::json::parse(run.out);
  ASSERT_EQ(doc["services"].size(), 2U);
  for (const auto& s : doc["services"]) {
    ASSERT_TRUE(s["rtt_ms"].is_number()) << s.dump();
    EXPECT_GT(s["rtt_ms"].get<double>(), 0.0);
    EXPECT_LT(s["rtt_ms"].get<double>(), 5000.0);
  }
}

TEST_F(CellctlTest, TableOutputCarriesUnitsAndTheEnvironmentSelectsTheBus) {
  add_service("alpha", cell_health_HEALTH_SERVING);
  setenv("CELL_DOMAIN_ID", std::to_string(domain_).c_str(), 1);
  setenv("CELL_PARTITION", partition_.c_str(), 1);
  const CliRun run = cellctl({"--timeout", "5", "ping", "--rtt"});
  unsetenv("CELL_DOMAIN_ID");
  unsetenv("CELL_PARTITION");
  ASSERT_EQ(run.code, kExitOk) << run.err;
  EXPECT_THAT(run.out, HasSubstr(fmt::format("1 service(s) on domain {}, partition '{}'", domain_,
                                             partition_)));
  EXPECT_THAT(run.out, HasSubstr("SERVICE  KIND  HOST"));
  EXPECT_THAT(run.out, HasSubstr("alpha"));
  EXPECT_THAT(run.out, HasSubstr(" s  "));  // uptime in seconds
  EXPECT_THAT(run.out, HasSubstr(" ms"));   // round trip in milliseconds
  EXPECT_THAT(run.out, Not(HasSubstr("{")));
}

TEST(Table, AlignsColumnsAndTrimsTrailingBlanks) {
  Table table({"A", "LONGER"});
  table.add_column("C");
  table.add_row({"xyz", "1", ""});
  table.add_row({"q"});
  std::ostringstream out;
  table.print(out);
  EXPECT_EQ(out.str(), "A    LONGER  C\nxyz  1\nq\n");
}

}  // namespace
}  // namespace cell::cellctl
