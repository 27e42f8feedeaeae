#include "profile.hpp"

#include <cstdlib>

#include <filesystem>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"
#include "temp_dir.hpp"

namespace cell::launcher {
namespace {

using ::cell::launcher::testing::TempDir;
using ::cell::testing::IsErrWith;
using ::cell::testing::IsOk;
using ::testing::ElementsAre;
using ::testing::HasSubstr;
using ::testing::Pair;

constexpr const char* kFull = R"(profile: bench
bus:
  domain_id: 12
  partition: lab
  cyclonedds_config: /etc/cyclone.xml
run_dir: /var/run/cell
restart:
  backoff_initial_s: 0.25
  backoff_max_s: 4
  stable_after_s: 20
stop_grace_s: 2.5
services:
  - name: echo
    exec: cell-echo
    config: config/echo.yaml
    args: [--log-level, debug]
    env: {FOO: bar, LEVEL: 3}
  - {name: vision.cam-1, exec: bin/cell-vision, host: opspc}
)";

TEST(Profile, ReadsEveryKey) {
  TempDir dir;
  auto profile = load_profile(dir.write("bench.yaml", kFull));
  ASSERT_THAT(profile, IsOk());
  EXPECT_EQ(profile->name, "bench");
  EXPECT_EQ(profile->path, dir.path() + "/bench.yaml");
  EXPECT_EQ(profile->bus.domain_id, 12U);
  EXPECT_EQ(profile->bus.partition, "lab");
  EXPECT_EQ(profile->bus.cyclonedds_config, "/etc/cyclone.xml");
  EXPECT_EQ(profile->run_dir, "/var/run/cell");
  EXPECT_DOUBLE_EQ(profile->restart.backoff_initial_s, 0.25);
  EXPECT_DOUBLE_EQ(profile->restart.backoff_max_s, 4.0);
  EXPECT_DOUBLE_EQ(profile->restart.stable_after_s, 20.0);
  EXPECT_DOUBLE_EQ(profile->stop_grace_s, 2.5);
  ASSERT_EQ(profile->services.size(), 2U);
  const ServiceSpec& echo = profile->services[0];
  EXPECT_EQ(echo.name, "echo");
  EXPECT_EQ(echo.exec, "cell-echo");
  EXPECT_EQ(echo.config, "config/echo.yaml");
  EXPECT_THAT(echo.args, ElementsAre("--log-level", "debug"));
  EXPECT_THAT(echo.env, ElementsAre(Pair("FOO", "bar"), Pair("LEVEL", "3")));
  EXPECT_EQ(echo.host, "local");
  EXPECT_THAT(echo.where, HasSubstr("bench.yaml:13:5"));
  EXPECT_EQ(profile->services[1].name, "vision.cam-1");
  EXPECT_EQ(profile->services[1].host, "opspc");
  EXPECT_TRUE(profile->services[1].config.empty());
}

TEST(Profile, DefaultsApplyAndNameComesFromTheFile) {
  TempDir dir;
  auto profile = load_profile(dir.write("mini.yaml", "services:\n  - {name: a, exec: x}\n"));
  ASSERT_THAT(profile, IsOk());
  EXPECT_EQ(profile->name, "mini");
  EXPECT_EQ(profile->bus.domain_id, 0U);
  EXPECT_EQ(profile->bus.partition, "cell");
  EXPECT_EQ(profile->bus.cyclonedds_config, "config/dds/loopback.xml");
  EXPECT_EQ(profile->run_dir, "run");
  EXPECT_DOUBLE_EQ(profile->restart.backoff_initial_s, 0.5);
  EXPECT_DOUBLE_EQ(profile->restart.backoff_max_s, 30.0);
  EXPECT_DOUBLE_EQ(profile->restart.stable_after_s, 10.0);
  EXPECT_DOUBLE_EQ(profile->stop_grace_s, 5.0);
}

TEST(Profile, TheShippedLocalProfileLoads) {
  auto profile = load_profile(cell::testing::source_dir() + "/deploy/local.yaml");
  ASSERT_THAT(profile, IsOk());
  EXPECT_EQ(profile->name, "local");
  ASSERT_FALSE(profile->services.empty());
  // Every service names an executable this build makes and a config file that exists.
  for (const auto& svc : profile->services) {
    EXPECT_TRUE(std::filesystem::exists(cell::testing::bin_path(svc.exec)))
        << svc.name << ": " << svc.exec << " was not built";
    EXPECT_TRUE(std::filesystem::exists(cell::testing::source_dir() + "/" + svc.config))
        << svc.name << ": " << svc.config << " is missing";
  }
}

TEST(Profile, UnknownKeyIsNamedWithFileLineAndColumn) {
  TempDir dir;
  const std::string path =
      dir.write("p.yaml", "services:\n  - {name: a, exec: x}\nrestart:\n  backof_max_s: 3\n");
  EXPECT_THAT(load_profile(path),
              IsErrWith(Errc::kConfig, path + ":4:3: unknown key 'restart.backof_max_s'"));
}

TEST(Profile, WrongTypeIsNamedWithFileLineAndKey) {
  TempDir dir;
  const std::string path =
      dir.write("p.yaml", "stop_grace_s: soon\nservices:\n  - {name: a, exec: x, args: 3}\n");
  const auto profile = load_profile(path);
  EXPECT_THAT(profile, IsErrWith(Errc::kConfig, path + ":1:15: key 'stop_grace_s': expected a "
                                                       "finite number, got 'soon'"));
  EXPECT_THAT(profile, IsErrWith(Errc::kConfig, "key 'services[0].args': expected a list"));
}

TEST(Profile, MissingOrEmptyServicesIsAnError) {
  TempDir dir;
  EXPECT_THAT(load_profile(dir.write("a.yaml", "profile: x\n")),
              IsErrWith(Errc::kConfig, "missing required list 'services'"));
  const std::string empty = dir.write("b.yaml", "profile: x\nservices: []\n");
  EXPECT_THAT(load_profile(empty),
              IsErrWith(Errc::kConfig, empty + ":2:11: key 'services': must list at least one"));
  EXPECT_THAT(load_profile(dir.write("c.yaml", "services: echo\n")),
              IsErrWith(Errc::kConfig, "key 'services': expected a list"));
}

TEST(Profile, ServiceEntriesAreCheckedOneByOne) {
  TempDir dir;
  const std::string path = dir.write("p.yaml",
                                     "services:\n"
                                     "  - {name: a, exec: x}\n"
                                     "  - {name: a, exec: y}\n"
                                     "  - {name: 'b c', exec: z}\n"
                                     "  - {exec: w}\n"
                                     "  - {name: d, exec: v, env: {'1BAD': x}}\n"
                                     "  - plain\n");
  const auto profile = load_profile(path);
  ASSERT_FALSE(profile.has_value());
  const std::string& m = profile.error().message;
  EXPECT_THAT(m, HasSubstr(path +
                           ":3:12: key 'services[1].name': duplicate service name 'a' "
                           "(first at " +
                           path + ":2:5)"));
  EXPECT_THAT(m, HasSubstr("key 'services[2].name': 'b c' is not a valid service name"));
  EXPECT_THAT(m, HasSubstr("missing required key 'services[3].name'"));
  EXPECT_THAT(m, HasSubstr("key 'services[4].env.1BAD': not a valid environment variable"));
  EXPECT_THAT(m, HasSubstr(path + ":7:5: 'services[5]' must be a map"));
}

TEST(Profile, DurationsAndDomainAreRangeChecked) {
  TempDir dir;
  const std::string path = dir.write("p.yaml",
                                     "bus: {domain_id: 231, partition: ''}\n"
                                     "restart: {backoff_initial_s: 2, backoff_max_s: 1, "
                                     "stable_after_s: -1}\n"
                                     "stop_grace_s: 0\n"
                                     "services: [{name: a, exec: x}]\n");
  const auto profile = load_profile(path);
  ASSERT_FALSE(profile.has_value());
  const std::string& m = profile.error().message;
  EXPECT_THAT(m, HasSubstr("key 'bus.domain_id': must be 0..230, got 231"));
  EXPECT_THAT(m, HasSubstr("key 'bus.partition': must not be empty"));
  EXPECT_THAT(m, HasSubstr("key 'restart.backoff_max_s': must be >= backoff_initial_s (2), got 1"));
  EXPECT_THAT(m, HasSubstr("key 'restart.stable_after_s': must be >= 0, got -1"));
  EXPECT_THAT(m, HasSubstr("key 'stop_grace_s': must be in (0, 600], got 0"));
}

TEST(Profile, MissingFileAndSyntaxErrorsAreReported) {
  TempDir dir;
  EXPECT_THAT(load_profile(dir.path() + "/nope.yaml"),
              IsErrWith(Errc::kConfig, "nope.yaml: cannot open"));
  const std::string path = dir.write("bad.yaml", "services: [\n");
  EXPECT_THAT(load_profile(path), IsErrWith(Errc::kConfig, "YAML syntax error"));
}

TEST(Profile, EnvironmentOverridesTheBusSection) {
  TempDir dir;
  auto profile = load_profile(dir.write("p.yaml", kFull));
  ASSERT_THAT(profile, IsOk());
  setenv("CELL_DOMAIN_ID", "42", 1);
  setenv("CELL_PARTITION", "test-x", 1);
  EXPECT_THAT(apply_environment(*profile), IsOk());
  EXPECT_EQ(profile->bus.domain_id, 42U);
  EXPECT_EQ(profile->bus.partition, "test-x");
  setenv("CELL_DOMAIN_ID", "4x", 1);
  EXPECT_THAT(apply_environment(*profile),
              IsErrWith(Errc::kConfig, "environment CELL_DOMAIN_ID must be 0..230, got '4x'"));
  unsetenv("CELL_DOMAIN_ID");
  unsetenv("CELL_PARTITION");
}

TEST(Profile, RelativePathsResolveAgainstCellHome) {
  setenv("CELL_HOME", "/opt/cell", 1);
  EXPECT_EQ(home_path("config/echo.yaml"), "/opt/cell/config/echo.yaml");
  EXPECT_EQ(home_path("/abs/x.yaml"), "/abs/x.yaml");
  Profile profile;
  profile.run_dir = "run";
  EXPECT_EQ(run_dir_of(profile), "/opt/cell/run");
  unsetenv("CELL_HOME");
  EXPECT_TRUE(is_local_host("local"));
  EXPECT_TRUE(is_local_host(this_host()));
  EXPECT_FALSE(is_local_host("surely-not-" + this_host()));
}

}  // namespace
}  // namespace cell::launcher
