#pragma once
// The three-PC network lab: three host network namespaces (vision, control, operations), each
// with a tun device `cell0` opened by cell-netlab-router (tests/netlab/router.cpp), which
// forwards IPv4 between them with a configurable one-way delay and per-link counters. Loss and
// partitions are nftables rules inside the host namespaces. Namespace names carry this process's
// pid (`cn<pid>-vision`), so parallel runs never collide; the destructor tears everything down,
// and a new lab first removes the namespaces of labs whose process has died (a test killed by
// ctest's timeout cannot run its destructor).
//
// Needs root, /dev/net/tun, `ip` and `nft`. Not thread-safe.

#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <chrono>
#include <csignal>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "cell/process/child.hpp"
#include "cell/testing/env.hpp"

namespace cell::netlab {

using nlohmann::json;
using namespace std::chrono_literals;

/// One host of the lab: its name in the profile, hostname, address on cell0.
struct HostSpec {
  std::string name;
  std::string hostname;
  std::string address;
};

inline const std::vector<HostSpec>& lab_hosts() {
  static const std::vector<HostSpec> hosts = {{"vision", "vision-pc", "10.77.0.1"},
                                              {"control", "control-pc", "10.77.0.2"},
                                              {"operations", "operations-pc", "10.77.0.3"}};
  return hosts;
}

struct ShellRun {
  int code = -1;
  std::string output;
};

/// Runs `sh -c command` to completion (60 s at most); merged output.
inline ShellRun shell(const std::string& command) {
  process::SpawnOptions options;
  options.executable = "/bin/sh";
  options.args = {"-c", command};
  auto child = process::Child::spawn(options);
  if (!child) {
    return {-1, "cannot start /bin/sh for '" + command + "': " + child.error().message};
  }
  auto exit = child->wait_for(60s);
  if (!exit) {
    exit = child->stop(1s);
    return {-1, "'" + command + "' did not finish within 60 s: " + child->output()};
  }
  return {exit->exited ? exit->code : 128 + exit->signal, child->output()};
}

/// A Cyclone DDS configuration for one lab host, written by hand (the connectivity proof does
/// not depend on the launcher's generator): cell0's address, no multicast, the three peers.
inline std::string hand_written_dds_xml(const std::string& address) {
  std::string peers;
  for (const HostSpec& h : lab_hosts()) {
    peers += fmt::format("        <Peer address=\"{}\"/>\n", h.address);
  }
  return fmt::format(R"(<?xml version="1.0" encoding="UTF-8"?>
<CycloneDDS xmlns="https://cdds.io/config">
  <Domain Id="any">
    <General>
      <Interfaces>
        <NetworkInterface address="{}" priority="default" multicast="false"/>
      </Interfaces>
      <AllowMulticast>false</AllowMulticast>
      <MaxMessageSize>1400B</MaxMessageSize>
    </General>
    <Discovery>
      <ParticipantIndex>auto</ParticipantIndex>
      <MaxAutoParticipantIndex>60</MaxAutoParticipantIndex>
      <Peers>
{}      </Peers>
    </Discovery>
  </Domain>
</CycloneDDS>
)",
                     address, peers);
}

class Lab {
 public:
  /// Builds the lab; on any failure records a test failure (ADD_FAILURE) and ok() is false.
  Lab() : prefix_(fmt::format("cn{}", ::getpid())) {
    remove_stale_labs();
    std::string pattern = "/tmp/cell-netlab-XXXXXX";
    dir_ = mkdtemp(pattern.data()) != nullptr ? pattern : "/tmp/cell-netlab-" + prefix_;
    std::filesystem::create_directories(dir_);
    for (const HostSpec& h : lab_hosts()) {
      if (!must(fmt::format("ip netns add {}", ns(h.name)))) {
        return;
      }
      created_.push_back(ns(h.name));
      if (!must(fmt::format("ip -n {} link set lo up", ns(h.name)))) {
        return;
      }
    }
    process::SpawnOptions options;
    options.executable = cell::testing::bin_path("cell-netlab-router");
    options.args = {"--control", control_path(), "--rt"};
    for (const HostSpec& h : lab_hosts()) {
      options.args.push_back("--host");
      options.args.push_back(fmt::format("{}={}={}", h.name, ns(h.name), h.address));
    }
    auto router = process::Child::spawn(options);
    if (!router) {
      ADD_FAILURE() << "netlab: cannot start cell-netlab-router: " << router.error().message;
      return;
    }
    router_ = std::move(*router);
    std::string out;
    const bool ready = cell::testing::eventually(
        [&] {
          (void)router_.read_available(out);
          return out.find("ready") != std::string::npos || !router_.running() ||
                 router_.poll().has_value();
        },
        10s);
    if (!ready || out.find("ready") == std::string::npos) {
      ADD_FAILURE() << "netlab: cell-netlab-router did not get ready within 10 s: " << out;
      return;
    }
    for (const HostSpec& h : lab_hosts()) {
      if (!must(fmt::format("ip -n {0} addr add {1}/24 dev cell0 && ip -n {0} link set cell0 up",
                            ns(h.name), h.address))) {
        return;
      }
    }
    ok_ = true;
  }

  ~Lab() {
    for (auto it = children_.rbegin(); it != children_.rend(); ++it) {
      if (it->second.running()) {
        (void)it->second.stop(10s);
      }
    }
    if (router_.running()) {
      (void)router_.stop(2s);
    }
    for (const std::string& n : created_) {
      const ShellRun r = shell("ip netns del " + n);
      if (r.code != 0) {
        std::fprintf(stderr, "netlab: ip netns del %s failed: %s\n", n.c_str(), r.output.c_str());
      }
    }
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }

  Lab(const Lab&) = delete;
  Lab& operator=(const Lab&) = delete;

  bool ok() const { return ok_; }
  const std::string& dir() const { return dir_; }
  std::string ns(const std::string& host) const { return prefix_ + "-" + host; }
  std::string control_path() const { return dir_ + "/router.sock"; }

  static const HostSpec& host(const std::string& name) {
    for (const HostSpec& h : lab_hosts()) {
      if (h.name == name) {
        return h;
      }
    }
    ADD_FAILURE() << "netlab: no host named '" << name << "'";
    return lab_hosts().front();
  }

  /// One command line to the router, its one-line answer ("" and a test failure on error).
  /// Not const: commands such as `reset` and `delay` change the router this lab owns.
  // NOLINTNEXTLINE(readability-make-member-function-const): reset/delay mutate the lab
  std::string router(const std::string& line) {
    const int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::snprintf(addr.sun_path, sizeof addr.sun_path, "%s", control_path().c_str());
    if (fd < 0 || ::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
      ADD_FAILURE() << "netlab: cannot connect to the router at " << control_path() << ": "
                    << std::strerror(errno);
      if (fd >= 0) {
        ::close(fd);
      }
      return {};
    }
    const std::string text = line + "\n";
    (void)!::write(fd, text.data(), text.size());
    std::string reply;
    char buf[4096];
    for (;;) {
      const ssize_t n = ::read(fd, buf, sizeof buf);
      if (n <= 0) {
        break;
      }
      reply.append(buf, static_cast<std::size_t>(n));
      if (reply.find('\n') != std::string::npos) {
        break;
      }
    }
    ::close(fd);
    if (reply.rfind("error", 0) == 0 || reply.empty()) {
      ADD_FAILURE() << "netlab: router answered '" << reply << "' to '" << line << "'";
    }
    return reply.substr(0, reply.find('\n'));
  }

  json stats() { return json::parse(router("stats"), nullptr, false); }

  /// Bytes the router carried from `from` to `to` (per link, as counted by the router).
  static std::uint64_t link_bytes(const json& stats, const std::string& from,
                                  const std::string& to) {
    for (const json& l : stats.value("links", json::array())) {
      if (l.value("from", "") == from && l.value("to", "") == to) {
        return l.value("bytes", std::uint64_t{0});
      }
    }
    return 0;
  }

  void set_delay_ms(double ms) {
    EXPECT_EQ(router(fmt::format("delay {}", ms)).rfind("ok", 0), 0U);
  }

  /// Drops everything in and out of `host`'s cell0 (nftables in its namespace).
  void partition(const std::string& host) {
    (void)must(nft(host,
                   "add table inet netlab_cut; "
                   "add chain inet netlab_cut in { type filter hook input priority -10; }; "
                   "add chain inet netlab_cut out { type filter hook output priority -10; }; "
                   "add rule inet netlab_cut in iifname cell0 drop; "
                   "add rule inet netlab_cut out oifname cell0 drop"));
  }
  void heal(const std::string& host) { (void)must(nft(host, "delete table inet netlab_cut")); }

  /// Drops `percent` % of the packets arriving on every host's cell0 (one draw per hop).
  void set_loss(int percent) {
    for (const HostSpec& h : lab_hosts()) {
      (void)must(nft(h.name, fmt::format(
                                 "add table inet netlab_loss; "
                                 "add chain inet netlab_loss in {{ type filter hook input "
                                 "priority -5; }}; "
                                 "add rule inet netlab_loss in iifname cell0 numgen random mod "
                                 "100 < {} drop",
                                 percent)));
    }
  }
  void clear_loss() {
    for (const HostSpec& h : lab_hosts()) {
      (void)must(nft(h.name, "delete table inet netlab_loss"));
    }
  }

  /// Starts `argv` in `host`'s namespace under its own UTS namespace with the host's hostname.
  process::Child& start_in(const std::string& host, const std::string& label,
                           const std::vector<std::string>& argv,
                           const std::vector<std::string>& env = {}) {
    process::SpawnOptions options;
    options.executable = "ip";
    options.args = {"netns", "exec", ns(host), "unshare", "--uts", "sh", "-c",
                    "hostname \"$0\" && exec \"$@\"", Lab::host(host).hostname};
    options.args.insert(options.args.end(), argv.begin(), argv.end());
    options.env = env;
    auto child = process::Child::spawn(options);
    EXPECT_TRUE(child) << "netlab: cannot start " << label << " in " << ns(host) << ": "
                       << (child ? "" : child.error().message);
    children_.emplace_back(label, child ? std::move(*child) : process::Child());
    return children_.back().second;
  }

  /// Runs `argv` in `host`'s namespace to completion; exit code and merged output.
  ShellRun run_in(const std::string& host, const std::vector<std::string>& argv,
                  const std::vector<std::string>& env = {},
                  std::chrono::milliseconds timeout = 60s) const {
    process::SpawnOptions options;
    options.executable = "ip";
    options.args = {"netns", "exec", ns(host), "unshare", "--uts", "sh", "-c",
                    "hostname \"$0\" && exec \"$@\"", Lab::host(host).hostname};
    options.args.insert(options.args.end(), argv.begin(), argv.end());
    options.env = env;
    auto child = process::Child::spawn(options);
    if (!child) {
      return {-1, child.error().message};
    }
    auto exit = child->wait_for(timeout);
    if (!exit) {
      (void)child->stop(1s);
      return {-1, fmt::format("{} in {} did not finish within {} ms: {}", argv.front(), ns(host),
                              timeout.count(), child->output())};
    }
    return {exit->exited ? exit->code : 128 + exit->signal, child->output()};
  }

  /// UDP round trips from `from` to `to` (cell-netlab-probe; an echo is started in `to` once).
  struct Probe {
    int code = -1;
    int received = 0;
    double loss_percent = 100.0;
    double rtt_median_ms = 0.0;
    std::string output;
  };
  Probe probe(const std::string& from, const std::string& to, int count, int interval_ms = 10,
              int timeout_ms = 1000) {
    if (echoes_.insert(to).second) {
      process::Child& echo = start_in(to, "echo-" + to,
                                      {cell::testing::bin_path("cell-netlab-probe"), "echo",
                                       "--port", "7777"});
      std::string out;
      if (!cell::testing::eventually(
              [&] {
                (void)echo.read_available(out);
                return out.find("echo on") != std::string::npos;
              },
              10s)) {
        ADD_FAILURE() << "netlab: the UDP echo in " << ns(to) << " did not start: " << out;
      }
    }
    const ShellRun r = run_in(from, {cell::testing::bin_path("cell-netlab-probe"), "ping", "--to",
                                     host(to).address, "--port", "7777", "--count",
                                     std::to_string(count), "--interval-ms",
                                     std::to_string(interval_ms), "--timeout-ms",
                                     std::to_string(timeout_ms)},
                              {}, std::chrono::milliseconds(count * interval_ms + timeout_ms) + 30s);
    Probe p;
    p.code = r.code;
    p.output = r.output;
    std::smatch m;
    if (std::regex_search(r.output, m, std::regex(R"(received (\d+) loss ([0-9.]+)% rtt_median_ms ([0-9.]+))"))) {
      p.received = std::stoi(m[1].str());
      p.loss_percent = std::stod(m[2].str());
      p.rtt_median_ms = std::stod(m[3].str());
    }
    return p;
  }

  /// Output of every process started in the lab (for failure messages).
  std::string logs() {
    std::string out;
    for (auto& [label, c] : children_) {
      std::string text;
      (void)c.read_available(text);
      out += fmt::format("---- {}\n{}{}", label, c.output(), text);
    }
    return out;
  }

 private:
  std::string nft(const std::string& host, const std::string& script) {
    const std::string path = fmt::format("{}/nft-{}-{}.nft", dir_, host, nft_count_++);
    std::string text = script;
    for (auto& c : text) {
      if (c == ';') {
        c = '\n';
      }
    }
    std::ofstream(path) << text << "\n";
    return fmt::format("ip netns exec {} nft -f {}", ns(host), path);
  }

  bool must(const std::string& command) {
    const ShellRun r = shell(command);
    if (r.code != 0) {
      ADD_FAILURE() << "netlab: '" << command << "' failed (exit " << r.code << "): " << r.output;
      return false;
    }
    return true;
  }

  /// Namespaces cn<pid>-* whose pid no longer runs: left by a killed test.
  static void remove_stale_labs() {
    const ShellRun list = shell("ip netns list");
    std::istringstream in(list.output);
    std::string line;
    while (std::getline(in, line)) {
      const std::string name = line.substr(0, line.find(' '));
      if (name.size() < 4 || name.rfind("cn", 0) != 0) {
        continue;
      }
      const auto dash = name.find('-');
      const std::string digits = name.substr(2, dash == std::string::npos ? 0 : dash - 2);
      if (digits.empty() || digits.find_first_not_of("0123456789") != std::string::npos) {
        continue;
      }
      const pid_t pid = static_cast<pid_t>(std::stol(digits));
      if (pid != ::getpid() && ::kill(pid, 0) != 0 && errno == ESRCH) {
        (void)shell("ip netns del " + name);
      }
    }
  }

  std::string prefix_;
  std::string dir_;
  std::vector<std::string> created_;
  process::Child router_;
  std::vector<std::pair<std::string, process::Child>> children_;
  std::set<std::string> echoes_;
  bool ok_ = false;
  int nft_count_ = 0;
};

/// Appends one reliability row to $CELL_RELIABILITY_OUT/netlab.jsonl when the variable is set.
inline void record_row(const std::string& scenario, const std::string& load,
                       const std::string& faults, const std::string& outcome,
                       const std::string& lost, double duration_s) {
  const char* out = std::getenv("CELL_RELIABILITY_OUT");
  if (out == nullptr || *out == '\0') {
    return;
  }
  std::filesystem::create_directories(out);
  const json row = {{"suite", "netlab"},   {"scenario", scenario}, {"load", load},
                    {"faults", faults},    {"outcome", outcome},   {"lost", lost},
                    {"duration_s", duration_s}};
  std::ofstream(std::string(out) + "/netlab.jsonl", std::ios::app) << row.dump() << "\n";
}

}  // namespace cell::netlab
