// Multi-host profiles: hosts, host selection, the generated Cyclone DDS configuration, DDS
// Security identities and the systemd units (deploy/three-pcs.yaml is checked as shipped).
#include <sys/stat.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/service/paths.hpp"
#include "cell/testing/matchers.hpp"
#include "deploy_gen.hpp"
#include "profile.hpp"
#include "supervisor.hpp"
#include "temp_dir.hpp"

namespace cell::launcher {
namespace {

using ::cell::launcher::testing::TempDir;
using ::cell::testing::IsErrWith;
using ::cell::testing::IsOk;
using ::testing::Contains;
using ::testing::HasSubstr;
using ::testing::Not;

constexpr const char* kTwoHosts = R"(bus: {partition: lab}
hosts:
  cams: {address: 10.1.0.1}
  ctrl: {address: 10.1.0.2, interface: eth1}
services:
  - {name: camera.a, exec: cell-camera, host: cams}
  - {name: vision, exec: fake-svc, host: cams}
  - {name: motion, exec: fake-svc, host: ctrl}
)";

class DeployTest : public ::testing::Test {
 protected:
  DeployTest() {
    setenv("CELL_HOME", home_.path().c_str(), 1);
    std::filesystem::create_directories(home_.path() + "/bin");
    for (const char* exe : {"bin/fake-svc", "bin/cell-camera"}) {
      const std::string path = home_.write(exe, "#!/bin/sh\nexit 0\n");
      chmod(path.c_str(), 0755);
    }
  }
  ~DeployTest() override { unsetenv("CELL_HOME"); }

  Result<Profile> load(const std::string& yaml) { return load_profile(home_.write("p.yaml", yaml)); }

  TempDir home_;
};

TEST_F(DeployTest, HostsAreReadAndEveryServiceMustNameOne) {
  auto p = load(kTwoHosts);
  ASSERT_THAT(p, IsOk());
  ASSERT_EQ(p->hosts.size(), 2U);
  EXPECT_EQ(p->hosts[1].name, "ctrl");
  EXPECT_EQ(p->hosts[1].address, "10.1.0.2");
  EXPECT_EQ(p->hosts[1].interface, "eth1");
  EXPECT_FALSE(p->bus.multicast);
  EXPECT_FALSE(p->bus.images_across_hosts);

  EXPECT_THAT(load("hosts:\n  a: {address: 10.0.0.1}\nservices:\n  - {name: x, exec: y}\n"),
              IsErrWith(Errc::kConfig, "service 'x' must run on one of the profile's hosts (a), "
                                       "not 'local'"));
  EXPECT_THAT(load("hosts:\n  a: {address: 10.0.0.1}\n"
                   "services:\n  - {name: x, exec: y, host: b}\n"),
              IsErrWith(Errc::kConfig, "p.yaml:4:30: key 'services[0].host'"));
  EXPECT_THAT(load("hosts:\n  a: {address: 10.0.0.300}\nservices:\n  - {name: x, exec: y, "
                   "host: a}\n"),
              IsErrWith(Errc::kConfig, "'10.0.0.300' is not an IPv4 address"));
  EXPECT_THAT(load("hosts:\n  a: {interface: eth0}\nservices:\n  - {name: x, exec: y, host: a}\n"),
              IsErrWith(Errc::kConfig, "missing required key 'hosts.a.address'"));
}

TEST_F(DeployTest, HostSelectionNamesTheChoices) {
  auto p = load(kTwoHosts);
  ASSERT_THAT(p, IsOk());
  EXPECT_EQ(select_host(*p, "ctrl").value_or("?"), "ctrl");
  EXPECT_THAT(select_host(*p, "ops"),
              IsErrWith(Errc::kConfig, "--host ops: no such host in the profile (it has: cams, "
                                       "ctrl)"));
  EXPECT_THAT(select_host(*p, ""), IsErrWith(Errc::kConfig, "say which one this machine"));
  auto single = load("services:\n  - {name: x, exec: fake-svc}\n");
  ASSERT_THAT(single, IsOk());
  EXPECT_EQ(select_host(*single, "").value_or("?"), "");
  EXPECT_THAT(select_host(*single, "ctrl"), IsErrWith(Errc::kConfig, "no `hosts:` section"));
}

TEST_F(DeployTest, EnvironmentMovesAHostAndRejectsGarbage) {
  auto p = load(kTwoHosts);
  ASSERT_THAT(p, IsOk());
  setenv("CELL_HOST_CTRL_ADDRESS", "192.168.7.2", 1);
  EXPECT_THAT(apply_environment(*p), IsOk());
  EXPECT_EQ(p->host("ctrl")->address, "192.168.7.2");
  setenv("CELL_HOST_CTRL_ADDRESS", "ctrl-pc", 1);
  EXPECT_THAT(apply_environment(*p),
              IsErrWith(Errc::kConfig, "CELL_HOST_CTRL_ADDRESS must be an IPv4 address, got "
                                       "'ctrl-pc'"));
  unsetenv("CELL_HOST_CTRL_ADDRESS");
}

TEST_F(DeployTest, HostConfigPinsTheInterfacePeersEveryHostAndKeepsImagesHome) {
  auto p = load(kTwoHosts);
  ASSERT_THAT(p, IsOk());
  const std::string ctrl = host_dds_config(*p, "ctrl");
  EXPECT_THAT(ctrl, HasSubstr("<NetworkInterface address=\"10.1.0.2\""));
  EXPECT_THAT(ctrl, HasSubstr("<AllowMulticast>false</AllowMulticast>"));
  EXPECT_THAT(ctrl, HasSubstr("<Peer address=\"10.1.0.1\"/>"));
  EXPECT_THAT(ctrl, HasSubstr("<Peer address=\"10.1.0.2\"/>"));
  EXPECT_THAT(ctrl, HasSubstr("max=\"8192KiB\""));
  // No camera on ctrl: the raw image topic of the profile's partition never reaches it.
  EXPECT_THAT(ctrl, HasSubstr("<IgnoredPartition DCPSPartitionTopic=\"lab.cell/vision/image\"/>"));
  // The camera's own host keeps its images (vision reads them there).
  EXPECT_THAT(host_dds_config(*p, "cams"), Not(HasSubstr("IgnoredPartition")));
  p->bus.images_across_hosts = true;
  EXPECT_THAT(host_dds_config(*p, "ctrl"), Not(HasSubstr("IgnoredPartition")));
}

TEST_F(DeployTest, PlanForAHostStartsOnlyItsShareWithItsConfig) {
  auto p = load(kTwoHosts);
  ASSERT_THAT(p, IsOk());
  auto plan = make_plan(*p, {}, home_.path() + "/bin", "cams");
  ASSERT_THAT(plan, IsOk());
  ASSERT_EQ(plan->services.size(), 2U);
  EXPECT_EQ(plan->services[0].name, "camera.a");
  EXPECT_EQ(plan->dds_config, home_.path() + "/run/dds/cams.xml");
  EXPECT_THAT(plan->services[0].env,
              Contains("CYCLONEDDS_URI=file://" + home_.path() + "/run/dds/cams.xml"));
  EXPECT_THAT(plan->not_here, Contains("motion (host ctrl)"));
  ASSERT_THAT(write_dds_config(*plan), IsOk());
  std::ifstream in(plan->dds_config);
  std::stringstream text;
  text << in.rdbuf();
  EXPECT_EQ(text.str(), host_dds_config(*p, "cams"));
}

TEST_F(DeployTest, SecureModeGivesEachServiceItsIdentityOrRefusesToStart) {
  auto p = load(std::string(kTwoHosts) + "security: {enabled: true, dir: sec}\n");
  ASSERT_THAT(p, IsOk());
  auto missing = make_plan(*p, {}, home_.path() + "/bin", "ctrl");
  ASSERT_FALSE(missing.has_value());
  EXPECT_THAT(missing.error().message,
              HasSubstr("service 'motion': security is enabled but its DDS identity '" +
                        home_.path() + "/sec/motion.xml' cannot be read"));
  EXPECT_THAT(missing.error().message, HasSubstr("deploy/security/make-pki.sh --out"));
  std::filesystem::create_directories(home_.path() + "/sec");
  home_.write("sec/motion.xml", "<CycloneDDS/>\n");
  auto plan = make_plan(*p, {}, home_.path() + "/bin", "ctrl");
  ASSERT_THAT(plan, IsOk());
  EXPECT_THAT(plan->services[0].env,
              Contains("CYCLONEDDS_URI=file://" + home_.path() + "/run/dds/ctrl.xml,file://" +
                       home_.path() + "/sec/motion.xml"));
}

TEST_F(DeployTest, SystemdUnitsRunWhatCellUpRunsAndPassSystemdAnalyze) {
  auto p = load(std::string(kTwoHosts).replace(
      std::string(kTwoHosts).find("host: ctrl}"), 11,
      "host: ctrl, limits: {memory_mib: 512, cpu_percent: 150}}"));
  ASSERT_THAT(p, IsOk());
  auto plan = make_plan(*p, {}, home_.path() + "/bin", "ctrl");
  ASSERT_THAT(plan, IsOk());
  const auto files = systemd_units(*plan);
  ASSERT_EQ(files.size(), 2U);
  EXPECT_EQ(files[0].name, "cell-motion.service");
  EXPECT_EQ(files[1].name, "cell-ctrl.target");
  const std::string& unit = files[0].text;
  EXPECT_THAT(unit, HasSubstr("ExecStart=" + home_.path() + "/bin/fake-svc \"--id\" \"motion\""));
  EXPECT_THAT(unit, HasSubstr("Environment=\"CYCLONEDDS_URI=file://" + home_.path() +
                              "/run/dds/ctrl.xml\""));
  EXPECT_THAT(unit, HasSubstr("Restart=always\nRestartSec=500ms\n"));
  EXPECT_THAT(unit, HasSubstr("RestartPreventExitStatus=2"));
  EXPECT_THAT(unit, HasSubstr("MemoryMax=512M\nCPUQuota=150%\n"));
  EXPECT_THAT(unit, HasSubstr("WantedBy=cell-ctrl.target"));
  EXPECT_THAT(files[1].text, HasSubstr("Wants=cell-motion.service\n"));

  // systemd's own checker: no complaint about any line (it prints what it ignores).
  TempDir out;
  for (const auto& f : files) {
    out.write(f.name, f.text);
  }
  const std::string command = "cd " + out.path() +
                              " && systemd-analyze verify ./cell-ctrl.target ./cell-motion.service "
                              "2>&1";
  FILE* pipe = popen(command.c_str(), "r");
  ASSERT_NE(pipe, nullptr);
  std::string said;
  char buf[512];
  while (fgets(buf, sizeof buf, pipe) != nullptr) {
    said += buf;
  }
  const int rc = pclose(pipe);
  EXPECT_EQ(rc, 0) << said;
  EXPECT_EQ(said, "") << "systemd-analyze verify complained";
}

TEST(ShippedProfiles, ThreePcsPutsEveryServiceOfTheLocalCellOnAHost) {
  const std::string dir = service::resolve_path("deploy");
  auto local = load_profile(dir + "/local.yaml");
  auto three = load_profile(dir + "/three-pcs.yaml");
  ASSERT_THAT(local, IsOk());
  ASSERT_THAT(three, IsOk());
  ASSERT_EQ(three->hosts.size(), 3U);
  ASSERT_EQ(three->services.size(), local->services.size());
  for (std::size_t i = 0; i < local->services.size(); ++i) {
    EXPECT_EQ(three->services[i].name, local->services[i].name);
    EXPECT_EQ(three->services[i].config, local->services[i].config);
  }
  for (const auto& s : three->services) {
    const bool vision = s.name.starts_with("camera.") || s.name == "vision" ||
                        s.name == "calibration";
    const bool ops = s.name == "task" || s.name == "monitor" || s.name == "echo";
    EXPECT_EQ(s.host, vision ? "vision" : ops ? "operations" : "control") << s.name;
  }
  EXPECT_THAT(host_dds_config(*three, "operations"), HasSubstr("IgnoredPartition"));
  EXPECT_THAT(host_dds_config(*three, "vision"), Not(HasSubstr("IgnoredPartition")));
}

}  // namespace
}  // namespace cell::launcher
