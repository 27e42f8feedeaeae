// The three-PC lab itself (netlab.hpp, router.cpp): DDS crosses the router between two host
// namespaces with a hand-written Cyclone configuration (ddsperf ping/pong), the router adds the
// one-way delay it is told to (50 ms +- 1 ms), a partition cuts a host off and healing restores
// it, and every namespace has its own hostname.
#include <algorithm>
#include <regex>

#include <gmock/gmock.h>

#include "netlab.hpp"

namespace cell::netlab {
namespace {

using ::testing::HasSubstr;

// The router's timer thread on a shared 2-core machine: a packet released up to 1.7 ms late
// was seen under load (a release later than 5 ms would be a router defect, not load).
constexpr double kDelayTolMs = 5.0;

/// ddsperf's ping statistics: each line "... [pid] ... mean XXus ..." or the table with
/// "min mean 50% 90% 99% max" in microseconds; returns the medians found (us).
std::vector<double> ddsperf_medians_us(const std::string& output) {
  std::vector<double> out;
  // ddsperf 0.10, once a second: "[pid] 2.000  peer size 12 mean 284us min 106us 50% 191us ..."
  static const std::regex line(R"( 50%\s+([0-9.]+)us)");
  for (auto it = std::sregex_iterator(output.begin(), output.end(), line);
       it != std::sregex_iterator(); ++it) {
    out.push_back(std::stod((*it)[1].str()));
  }
  return out;
}

/// The median of the per-second medians after the first second (discovery settling).
double settled_median_us(std::vector<double> v) {
  if (v.size() > 1) {
    v.erase(v.begin());
  }
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

class NetlabTest : public ::testing::Test {
 protected:
  std::string write_xml(const std::string& host) {
    std::string path = lab_.dir() + "/" + host + ".xml";
    std::ofstream(path) << hand_written_dds_xml(Lab::host(host).address);
    return path;
  }

  /// Round-trip medians (us) of ddsperf ping in vision against pong in control, `seconds` long.
  std::vector<double> ping_pong(int seconds, std::string& output) {
    const std::string domain = std::to_string(cell::testing::test_domain_id());
    process::Child& pong = lab_.start_in(
        "control", "ddsperf-pong", {"ddsperf", "-i", domain, "pong"},
        {"CYCLONEDDS_URI=file://" + write_xml("control")});
    const ShellRun ping = lab_.run_in(
        "vision",
        {"ddsperf", "-i", domain, "-Qminmatch:1", "-Qinitwait:20", "-D",
         std::to_string(seconds), "ping", "8Hz"},
        {"CYCLONEDDS_URI=file://" + write_xml("vision")}, std::chrono::seconds(seconds + 40));
    (void)pong.stop(3s);
    output = ping.output + "\n---- pong\n" + pong.output();
    EXPECT_EQ(ping.code, 0) << output;
    return ddsperf_medians_us(ping.output);
  }

  Lab lab_;
};

TEST_F(NetlabTest, DdsperfCrossesTheRouterAndTheDelayIsWhatWasAsked) {
  ASSERT_TRUE(lab_.ok());
  const auto t0 = std::chrono::steady_clock::now();
  // Each namespace answers for its own address only through cell0 (nothing else is configured).
  const Lab::Probe route = lab_.probe("vision", "control", 5);
  EXPECT_EQ(route.received, 5) << route.output;

  std::string output;
  const std::vector<double> base = ping_pong(6, output);
  ASSERT_GE(base.size(), 2U) << "no round trips between vision and control:\n" << output;
  const json before = lab_.stats();
  EXPECT_GT(Lab::link_bytes(before, "vision", "control"), 0U) << before.dump();
  EXPECT_GT(Lab::link_bytes(before, "control", "vision"), 0U) << before.dump();
  // Operations runs no DDS: it sees only the peers' discovery attempts, far less than the
  // ping/pong link carries.
  EXPECT_LT(Lab::link_bytes(before, "vision", "operations"),
            Lab::link_bytes(before, "vision", "control"))
      << before.dump();

  lab_.set_delay_ms(50);
  EXPECT_EQ(lab_.router("reset"), "ok reset");
  const std::vector<double> delayed = ping_pong(6, output);
  ASSERT_GE(delayed.size(), 2U) << "no round trips with 50 ms delay:\n" << output;
  const json after = lab_.stats();
  // The router's own account: no packet released early, and on time as a rule. A user-space
  // router on a kernel without real-time scheduling is sometimes not woken when a release is
  // due: one host stall held a burst 65 ms once (max_late_ms 15), so the share of late packets
  // is what counts, and the worst only against an order-of-magnitude bound.
  EXPECT_GE(after["min_held_ms"].get<double>(), 50.0 - kDelayTolMs) << after.dump();
  EXPECT_LE(after["mean_late_ms"].get<double>(), 1.0) << after.dump();
  EXPECT_LE(after["late_over_1ms"].get<double>(), 0.05 * after["released"].get<double>())
      << after.dump();
  EXPECT_LE(after["max_held_ms"].get<double>(), 50.0 + 200.0) << after.dump();
  // And as DDS sees it: ddsperf reports half the round trip, which grew by one one-way delay
  // per direction, so its latency grows by the delay itself.
  const double base_ms = settled_median_us(base) / 1000.0;
  const double delayed_ms = settled_median_us(delayed) / 1000.0;
  const double added_ms = delayed_ms - base_ms;
  std::printf("ddsperf latency median (half round trip): %.3f ms without delay, %.3f ms with "
              "50 ms one way (added %.3f ms); router held packets %.3f..%.3f ms, mean lateness "
              "%.3f ms\n",
              base_ms, delayed_ms, added_ms,
              after["min_held_ms"].get<double>(), after["max_held_ms"].get<double>(),
              after["mean_late_ms"].get<double>());
  EXPECT_NEAR(added_ms, 50.0, kDelayTolMs) << output;
  record_row("lab: ddsperf ping/pong vision<->control", "ddsperf ping 8 Hz, 2 x 6 s",
             "router one-way delay 0 then 50 ms",
             fmt::format("{}: ddsperf latency +{:.2f} ms (expected 50 +- {:g}), held {:.2f}..{:.2f} "
                         "ms",
                         HasFailure() ? "failed" : "passed", added_ms, kDelayTolMs,
                         after["min_held_ms"].get<double>(), after["max_held_ms"].get<double>()),
             "nothing lost (ddsperf reliable ping/pong)",
             std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
}

TEST_F(NetlabTest, APartitionCutsTheHostOffAndHealingRestoresIt) {
  ASSERT_TRUE(lab_.ok());
  EXPECT_EQ(lab_.probe("operations", "control", 5).received, 5);
  lab_.partition("control");
  const Lab::Probe cut = lab_.probe("operations", "control", 5);
  EXPECT_EQ(cut.received, 0) << "control answered through a partition: " << cut.output;
  const Lab::Probe other = lab_.probe("operations", "vision", 5);
  EXPECT_EQ(other.received, 5) << "the partition of control cut vision off too: " << other.output;
  lab_.heal("control");
  const Lab::Probe healed = lab_.probe("operations", "control", 5);
  EXPECT_EQ(healed.received, 5) << healed.output;
  // Each host namespace gets its own hostname for the processes started in it.
  process::Child& name = lab_.start_in("control", "hostname", {"hostname"});
  ASSERT_TRUE(name.wait_for(10s).has_value());
  EXPECT_THAT(name.output(), HasSubstr("control-pc"));
}

TEST_F(NetlabTest, LossDropsAboutTheAskedShare) {
  ASSERT_TRUE(lab_.ok());
  lab_.set_loss(5);
  // 1000 round trips vision -> control: each crosses control's ingress, its reply vision's:
  // 1 - 0.95^2 = 9.75 % lost. Bounds 5..15 % are >5 binomial standard deviations (0.94 %).
  const Lab::Probe r = lab_.probe("vision", "control", 1000, 2);
  ASSERT_EQ(r.code, 0) << r.output;
  const double lost = r.loss_percent;
  std::printf("5%% loss per hop: %.1f%% of 1000 round trips lost\n", lost);
  EXPECT_GT(lost, 5.0) << r.output;
  EXPECT_LT(lost, 15.0) << r.output;
  lab_.clear_loss();
  const Lab::Probe clean = lab_.probe("vision", "control", 200, 2);
  EXPECT_EQ(clean.received, 200) << clean.output;
}

}  // namespace
}  // namespace cell::netlab
