// Unit tests of bus_bench's pure parts: statistics, ddsperf output parsing, the stream's
// delivery accounting and the publisher report. The cross-process measurement itself is
// covered by the bus_bench.smoke ctest.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cstdint>
#include <numeric>
#include <string>
#include <vector>

#include "affinity.hpp"
#include "cell/testing/matchers.hpp"
#include "ddsperf.hpp"
#include "report.hpp"
#include "stats.hpp"
#include "stream.hpp"

namespace cell::bench {
namespace {

using ::cell::testing::IsErrWith;

constexpr double kTolUs = 1e-9;

// A line as ddsperf 0.10.2 prints it (captured on this machine).
constexpr const char* kPingLine =
    "[8328] 2.000  vm:8327 size 16 mean 39.510us min 5.665us 50% 36.237us 90% 55.662us "
    "99% 127.603us max 1523.776us cnt 12597";

TEST(Percentile, NearestRankOnOneToHundred) {
  std::vector<std::int64_t> sorted(100);
  std::iota(sorted.begin(), sorted.end(), 1);
  EXPECT_EQ(percentile_ns(sorted, 0.50), 50);
  EXPECT_EQ(percentile_ns(sorted, 0.90), 90);
  EXPECT_EQ(percentile_ns(sorted, 0.99), 99);
  EXPECT_EQ(percentile_ns(sorted, 1.00), 100);
  EXPECT_EQ(percentile_ns(sorted, 0.001), 1);
}

TEST(Percentile, EmptyIsZero) { EXPECT_EQ(percentile_ns({}, 0.5), 0); }

TEST(Summarize, SortsAndConvertsNanosecondsToMicroseconds) {
  std::vector<std::int64_t> ns = {3000, 1000, 2000, 10000};
  const Summary s = summarize(ns);
  EXPECT_EQ(s.count, 4U);
  EXPECT_NEAR(s.min_us, 1.0, kTolUs);
  EXPECT_NEAR(s.p50_us, 2.0, kTolUs);
  EXPECT_NEAR(s.p90_us, 10.0, kTolUs);
  EXPECT_NEAR(s.max_us, 10.0, kTolUs);
  EXPECT_NEAR(s.mean_us, 4.0, kTolUs);
  EXPECT_EQ(ns.front(), 1000);  // sorted in place
}

TEST(Summarize, EmptyGivesZeros) {
  std::vector<std::int64_t> none;
  const Summary s = summarize(none);
  EXPECT_EQ(s.count, 0U);
  EXPECT_EQ(s.p50_us, 0.0);
}

TEST(SummarizeWindowed, AveragesPerWindowPercentilesWeightedByCount) {
  // Window 1: 1000 round trips of 1 us (1 ms elapsed); window 2: 10 of 100 us (1 ms).
  std::vector<std::int64_t> series(1000, 1000);
  series.insert(series.end(), 10, 100000);
  const Summary w = summarize_windowed(series, 1'000'000);
  EXPECT_EQ(w.count, 1010U);
  EXPECT_NEAR(w.min_us, 1.0, kTolUs);
  EXPECT_NEAR(w.max_us, 100.0, kTolUs);
  EXPECT_NEAR(w.mean_us, (1000 * 1.0 + 10 * 100.0) / 1010, kTolUs);
  EXPECT_NEAR(w.p50_us, (1000 * 1.0 + 10 * 100.0) / 1010, kTolUs);
  EXPECT_EQ(series.front(), 1000);  // left in measurement order
  // One window: the same as the pooled summary.
  std::vector<std::int64_t> copy = series;
  const Summary pooled = summarize(copy);
  const Summary one = summarize_windowed(series, 1'000'000'000);
  EXPECT_NEAR(one.p50_us, pooled.p50_us, kTolUs);
  EXPECT_NEAR(one.p99_us, pooled.p99_us, kTolUs);
}

TEST(DdsperfLine, ParsesEveryField) {
  const auto line = parse_ddsperf_line(kPingLine);
  ASSERT_TRUE(line) << line.error().message;
  EXPECT_NEAR(line->t_s, 2.0, kTolUs);
  EXPECT_EQ(line->size_bytes, 16U);
  EXPECT_NEAR(line->mean_us, 39.510, kTolUs);
  EXPECT_NEAR(line->min_us, 5.665, kTolUs);
  EXPECT_NEAR(line->p50_us, 36.237, kTolUs);
  EXPECT_NEAR(line->p90_us, 55.662, kTolUs);
  EXPECT_NEAR(line->p99_us, 127.603, kTolUs);
  EXPECT_NEAR(line->max_us, 1523.776, kTolUs);
  EXPECT_EQ(line->count, 12597U);
}

TEST(DdsperfLine, RejectsOtherLinesAndQuotesThem) {
  const std::string rss = "[8328] 2.000  rss:7.4MB vcsw:29247 ivcsw:14650 recvUC:4%+15%";
  EXPECT_THAT(parse_ddsperf_line(rss), IsErrWith(Errc::kInvalidArgument, rss));
  const std::string cut = "[1] 1.000  vm:2 size 16 mean 39.510us min 5.665us 50% 36.237us";
  EXPECT_THAT(parse_ddsperf_line(cut), IsErrWith(Errc::kInvalidArgument, "of 8"));
}

TEST(DdsperfOutput, KeepsOnlyLatencyLinesAndCountsParticipants) {
  const std::string output = std::string("[8328] participant vm:8328: new (self)\n") +
                             "[8328] participant vm:8327: new\n" + kPingLine + "\n" +
                             "[8328] 2.000  rss:7.4MB vcsw:29247 ivcsw:14650\n" + kPingLine +
                             "\n[8328] participant vm:8327: gone\n";
  EXPECT_EQ(parse_ddsperf_output(output).size(), 2U);
  EXPECT_EQ(ddsperf_participants(output), 2U);
  EXPECT_EQ(ddsperf_participants(output + "[8328] participant vm:9999: new\n"), 3U);
}

TEST(DdsperfRoundTrip, DoublesHalfRoundTripsAndWeightsByCount) {
  DdsperfLine a;
  a.count = 1000;
  a.min_us = 5.0;
  a.max_us = 100.0;
  a.mean_us = 10.0;
  a.p50_us = 8.0;
  a.p90_us = 12.0;
  a.p99_us = 20.0;
  DdsperfLine b = a;
  b.count = 3000;
  b.min_us = 4.0;
  b.max_us = 50.0;
  b.mean_us = 20.0;
  b.p50_us = 16.0;
  const auto rt = round_trip_from_ddsperf({a, b});
  ASSERT_TRUE(rt) << rt.error().message;
  EXPECT_EQ(rt->count, 4000U);
  EXPECT_NEAR(rt->min_us, 8.0, kTolUs);
  EXPECT_NEAR(rt->max_us, 200.0, kTolUs);
  EXPECT_NEAR(rt->mean_us, 2.0 * (1000 * 10.0 + 3000 * 20.0) / 4000, kTolUs);
  EXPECT_NEAR(rt->p50_us, 2.0 * (1000 * 8.0 + 3000 * 16.0) / 4000, kTolUs);
  EXPECT_NEAR(rt->p90_us, 24.0, kTolUs);
}

TEST(DdsperfRoundTrip, NoLinesIsAnError) {
  EXPECT_THAT(round_trip_from_ddsperf({}),
              IsErrWith(Errc::kInvalidArgument, "no ddsperf round trips"));
}

TEST(StreamDelivery, CountsLostGapsDuplicatesAndReordering) {
  StreamResult r;
  // 1..10 sent; 4 and 5 lost, 7 arrives after 8, 9 twice, 10 lost at the tail.
  count_delivery({1, 2, 3, 6, 8, 7, 9, 9}, 10, r);
  EXPECT_EQ(r.lost, 3U);  // 4, 5, 10
  EXPECT_EQ(r.first_lost, 4U);
  EXPECT_EQ(r.gaps, 3U);          // 3->6, 6->8, tail
  EXPECT_EQ(r.duplicates, 1U);    // 9
  EXPECT_EQ(r.out_of_order, 1U);  // 7
}

TEST(StreamDelivery, CompleteStreamLosesNothing) {
  std::vector<std::uint64_t> seqs(1000);
  std::iota(seqs.begin(), seqs.end(), 1);
  StreamResult r;
  count_delivery(seqs, 1000, r);
  EXPECT_EQ(r.lost + r.gaps + r.duplicates + r.out_of_order + r.first_lost, 0U);
}

TEST(StreamProfileText, RoundTripsAndRejectsUnknown) {
  for (const StreamProfile p : {StreamProfile::kStream, StreamProfile::kReliableStream}) {
    const auto parsed = parse_stream_profile(to_string(p));
    ASSERT_TRUE(parsed) << parsed.error().message;
    EXPECT_EQ(*parsed, p);
  }
  EXPECT_THAT(parse_stream_profile("fast"), IsErrWith(Errc::kInvalidArgument, "'fast'"));
}

TEST(PublisherReport, SurvivesFormatAndParseAmidOtherOutput) {
  StreamPublisherReport report;
  report.sent = 10000;
  report.write_errors = 2;
  report.overruns = 3;
  report.period_jitter.count = 9999;
  report.period_jitter.p99_us = 42.5;
  report.write.mean_us = 3.25;
  const std::string output =
      "ts=... lvl=warn something\n" + format_publisher_report(report) + "\nmore text\n";
  const auto parsed = parse_publisher_report(output);
  ASSERT_TRUE(parsed) << parsed.error().message;
  EXPECT_EQ(parsed->sent, 10000U);
  EXPECT_EQ(parsed->write_errors, 2U);
  EXPECT_EQ(parsed->overruns, 3U);
  EXPECT_EQ(parsed->period_jitter.count, 9999U);
  EXPECT_NEAR(parsed->period_jitter.p99_us, 42.5, kTolUs);
  EXPECT_NEAR(parsed->write.mean_us, 3.25, kTolUs);
}

TEST(PublisherReport, MissingOrBrokenLineIsAProtocolError) {
  EXPECT_THAT(parse_publisher_report("crashed\n"),
              IsErrWith(Errc::kProtocol, "no 'BUS_BENCH_STREAM_PUB"));
  EXPECT_THAT(parse_publisher_report("BUS_BENCH_STREAM_PUB {\"sent\": 1}\n"),
              IsErrWith(Errc::kProtocol, "unreadable publisher report"));
}

Summary with_p50(double p50_us, std::size_t count = 10) {
  Summary s;
  s.count = count;
  s.p50_us = p50_us;
  return s;
}

TEST(MedianOf, WeighsRepetitionsEquallyFieldByField) {
  const Summary m = median_of({with_p50(10.0, 100), with_p50(30.0, 5), with_p50(20.0, 1000)});
  EXPECT_EQ(m.count, 1105U);
  EXPECT_NEAR(m.p50_us, 20.0, kTolUs);
  EXPECT_NEAR(median_of({with_p50(10.0), with_p50(20.0)}).p50_us, 15.0, kTolUs);
  EXPECT_EQ(median_of({}).count, 0U);
}

TEST(Criterion, PassFailAndNotApplicable) {
  BenchReport report;
  EXPECT_EQ(criterion(report), "n/a");
  SizeComparison size;
  size.cell_runs = {with_p50(60.0)};
  report.sizes.push_back(size);
  EXPECT_EQ(criterion(report), "n/a");  // no ddsperf numbers
  report.sizes.back().ddsperf_runs = {with_p50(50.0)};
  EXPECT_EQ(criterion(report), "PASS");  // 1.2x
  ASSERT_TRUE(p50_ratio(report.sizes.back()));
  EXPECT_NEAR(*p50_ratio(report.sizes.back()), 1.2, kTolUs);
  report.sizes.back().cell_runs = {with_p50(80.0), with_p50(70.0), with_p50(10.0)};  // 1.4x
  EXPECT_EQ(criterion(report), "PASS");
  report.sizes.back().cell_runs = {with_p50(80.0)};  // 1.6x
  EXPECT_EQ(criterion(report), "FAIL");
}

TEST(Placement, ParsesNamesAndRejectsUnknown) {
  for (const Placement p : {Placement::kNone, Placement::kSame, Placement::kSplit}) {
    const auto parsed = parse_placement(to_string(p));
    ASSERT_TRUE(parsed) << parsed.error().message;
    EXPECT_EQ(*parsed, p);
  }
  EXPECT_THAT(parse_placement("numa"), IsErrWith(Errc::kInvalidArgument, "'numa'"));
}

TEST(Placement, PlansCpusFromTheAllowedSet) {
  const auto none = plan_cpus(Placement::kNone, {0, 1});
  ASSERT_TRUE(none);
  EXPECT_EQ(none->ping_cpu, -1);
  EXPECT_EQ(none->pong_cpu, -1);
  const auto same = plan_cpus(Placement::kSame, {2, 5});
  ASSERT_TRUE(same);
  EXPECT_EQ(same->ping_cpu, 5);
  EXPECT_EQ(same->pong_cpu, 5);
  const auto split = plan_cpus(Placement::kSplit, {2, 5});
  ASSERT_TRUE(split);
  EXPECT_EQ(split->ping_cpu, 2);
  EXPECT_EQ(split->pong_cpu, 5);
  EXPECT_THAT(plan_cpus(Placement::kSplit, {3}),
              IsErrWith(Errc::kInvalidArgument, "needs two CPUs"));
  EXPECT_THAT(plan_cpus(Placement::kSame, {}), IsErrWith(Errc::kInvalidArgument, "no CPU"));
}

TEST(Placement, OnCpuPinsOnlyForTheCallAndRestores) {
  const std::vector<int> before = allowed_cpus();
  ASSERT_FALSE(before.empty());
  const auto seen = on_cpu(before.back(), [] { return Result<std::vector<int>>(allowed_cpus()); });
  ASSERT_TRUE(seen) << seen.error().message;
  EXPECT_EQ(*seen, std::vector<int>{before.back()});
  EXPECT_EQ(allowed_cpus(), before);
  EXPECT_THAT(on_cpu(CPU_SETSIZE + 1, [] { return ok_status(); }),
              IsErrWith(Errc::kInvalidArgument, "out of range"));
}

}  // namespace
}  // namespace cell::bench
