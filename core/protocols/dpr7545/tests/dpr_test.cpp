// The Dpr accessor: word layout (little-endian, low word first), consistent position reads
// under a concurrent writer, and the simulator mailbox.
#include "cell/dpr7545/dpr.hpp"

#include <atomic>
#include <chrono>
#include <cstring>
#include <thread>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/dpr7545/codec.hpp"
#include "cell/dpr7545/sim_control.hpp"
#include "cell/dpr7545/transport.hpp"
#include "cell/testing/matchers.hpp"

namespace cell::dpr7545 {
namespace {

std::uint8_t byte_at(Transport& t, std::size_t offset) {
  return std::to_integer<std::uint8_t>(t.window()[offset]);
}

TEST(Dpr, WordsAreLittleEndianAtTheirOffsets) {
  auto t = make_heap_transport();
  const Dpr dpr(t->window());
  dpr.set_sample_period_us(1000);  // 0x03E8
  EXPECT_EQ(byte_at(*t, 0x00), 0xE8);
  EXPECT_EQ(byte_at(*t, 0x01), 0x03);
  dpr.set_command(kCommandFindHome);
  EXPECT_EQ(byte_at(*t, 0x06), 0x80);
  dpr.set_torque(0, 0x9F4);
  EXPECT_EQ(byte_at(*t, 0x40), 0xF4);
  EXPECT_EQ(byte_at(*t, 0x41), 0x09);
  dpr.set_gripper(kGripperClose);
  EXPECT_EQ(byte_at(*t, 0x2A), 0x80);
}

TEST(Dpr, PositionIsLowWordThenHighWord) {
  auto t = make_heap_transport();
  const Dpr dpr(t->window());
  dpr.set_position(1, 0x0002B03C);  // J2 at 0x14
  EXPECT_EQ(byte_at(*t, 0x14), 0x3C);
  EXPECT_EQ(byte_at(*t, 0x15), 0xB0);
  EXPECT_EQ(byte_at(*t, 0x16), 0x02);
  EXPECT_EQ(byte_at(*t, 0x17), 0x00);
  EXPECT_EQ(dpr.position(1), 176188);
  dpr.set_position(3, -41187);  // R at 0x1C: 0xFFFF5F1D
  EXPECT_EQ(byte_at(*t, 0x1C), 0x1D);
  EXPECT_EQ(byte_at(*t, 0x1F), 0xFF);
  EXPECT_EQ(dpr.position(3), -41187);
  EXPECT_EQ(dpr.position_consistent(3), -41187);
}

TEST(Dpr, SignedWordsRoundTrip) {
  auto t = make_heap_transport();
  const Dpr dpr(t->window());
  dpr.set_velocity(2, -39);
  dpr.set_acceleration(3, 7);
  EXPECT_EQ(dpr.velocity(2), -39);
  EXPECT_EQ(dpr.acceleration(3), 7);
  EXPECT_EQ(dpr.velocity(0), 0);
}

TEST(Dpr, LightingLatchSitsAtTheCardsSecondDecodedRange) {
  auto t = make_heap_transport();
  const Dpr dpr(t->window());
  dpr.write_lighting(lighting_latch(true, true));
  EXPECT_EQ(byte_at(*t, kLightingOffset), 0x03);
  EXPECT_EQ(dpr.read_lighting(), 0x03);
  // The latch is outside the register map: no register changed.
  for (std::size_t i = 0; i < kDprSize; ++i) {
    EXPECT_EQ(byte_at(*t, i), 0) << i;
  }
}

// A writer alternates between two positions whose high words differ, at a slave's cadence (a
// write, then a microsecond of other work), while the reader reads: a consistent read must only
// ever see one of the two, never a mix. What counts is how many reads a write overlapped (the
// writer's count changed while the read ran), not how long the test ran: on a loaded host the
// two threads share a core for a while and few reads overlap, so the reader goes on until
// kOverlaps reads did, whatever the scheduling (a fixed 30 ms window saw 57 of the second
// value once, the writer preempted). (A writer that rewrote the pair every few tens of ns, 200
// empty spins, is no slave: two reads back to back then met the same torn pair.)
TEST(Dpr, ConsistentPositionReadNeverTears) {
  auto t = make_heap_transport();
  const Dpr dpr(t->window());
  constexpr std::int32_t kA = 0x0000FFFF;
  constexpr std::int32_t kB = 0x00010000;
  constexpr int kOverlaps = 2000;
  std::atomic<bool> stop{false};
  std::atomic<int> writes{0};
  dpr.set_position(0, kA);
  std::thread writer([&] {
    bool a = true;
    while (!stop.load(std::memory_order_relaxed)) {
      dpr.set_position(0, a ? kA : kB);
      a = !a;
      writes.fetch_add(1, std::memory_order_acq_rel);
      const auto until = std::chrono::steady_clock::now() + std::chrono::microseconds(1);
      while (std::chrono::steady_clock::now() < until) {
      }
    }
  });
  int torn = 0;
  int seen_a = 0;
  int seen_b = 0;
  int overlapped = 0;
  // Generous: an idle host needs a few ms; two CPU hogs beside the test, well under a second.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while ((overlapped < kOverlaps || seen_a == 0 || seen_b == 0) &&
         std::chrono::steady_clock::now() < deadline) {
    for (int i = 0; i < 100; ++i) {
      const int before = writes.load(std::memory_order_acquire);
      const std::int32_t p = dpr.position_consistent(0);
      overlapped += writes.load(std::memory_order_acquire) != before ? 1 : 0;
      seen_a += p == kA ? 1 : 0;
      seen_b += p == kB ? 1 : 0;
      torn += p != kA && p != kB ? 1 : 0;
    }
  }
  stop = true;
  writer.join();
  EXPECT_EQ(torn, 0);
  // The reads overlapped the writes, and both values were read.
  EXPECT_GE(overlapped, kOverlaps) << "the writer ran during too few reads in 60 s ("
                                   << writes.load() << " writes)";
  EXPECT_GT(seen_a, 0);
  EXPECT_GT(seen_b, 0);
}

TEST(SimControl, MailboxRoundTrip) {
  auto t = make_heap_transport();
  const SimControl control(t->window());
  EXPECT_FALSE(control.valid());
  control.initialise(4242);
  EXPECT_TRUE(control.valid());
  EXPECT_EQ(control.owner_pid(), 4242U);
  EXPECT_FALSE(control.pending().has_value());
  const std::uint32_t seq = control.post(SimFault::kEncoderGlitch, 2, -500);
  EXPECT_FALSE(control.result(seq).has_value());
  const auto request = control.pending();
  ASSERT_TRUE(request.has_value());
  EXPECT_EQ(request->fault, SimFault::kEncoderGlitch);
  EXPECT_EQ(request->joint, 2);
  EXPECT_EQ(request->value, -500);
  control.acknowledge(*request, 0);
  EXPECT_EQ(control.result(seq), 0U);
  EXPECT_FALSE(control.pending().has_value());
  // The block lives outside the DPR register map and the lighting latch.
  EXPECT_GT(kSimControlOffset, kLightingOffset);
  EXPECT_LE(kSimControlOffset + 0x20, kWindowSize);
}

TEST(SimControl, FaultNamesParseAndListTheValidOnes) {
  EXPECT_THAT(parse_sim_fault("deadline-miss"), ::cell::testing::IsOk());
  EXPECT_EQ(*parse_sim_fault("loop-late"), SimFault::kLoopLate);
  EXPECT_EQ(to_string(SimFault::kOverrun), "overrun");
  EXPECT_THAT(parse_sim_fault("meltdown"),
              ::cell::testing::IsErrWith(Errc::kInvalidArgument, "known: deadline-miss"));
}

}  // namespace
}  // namespace cell::dpr7545
