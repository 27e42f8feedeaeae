// Transports: shared memory between a creator and an opener (as sim-7545 and the gateway),
// stale-segment takeover, and the physical transport's errors (never maps the real /dev/mem).
#include "cell/dpr7545/transport.hpp"

#include <fcntl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/dpr7545/dpr.hpp"
#include "cell/dpr7545/sim_control.hpp"
#include "cell/testing/matchers.hpp"

namespace cell::dpr7545 {
namespace {

using ::cell::testing::IsErr;
using ::cell::testing::IsErrWith;
using ::cell::testing::IsOk;

std::string unique_name(const char* what) {
  static int n = 0;
  return fmt::format("/cell-dpr7545-test-{}-{}-{}", ::getpid(), what, ++n);
}

TEST(ShmTransport, CreatorAndOpenerShareTheWindow) {
  const std::string name = unique_name("share");
  auto slave = create_shm(name);
  ASSERT_THAT(slave, IsOk());
  auto master = open_shm(name);
  ASSERT_THAT(master, IsOk());
  EXPECT_EQ((*master)->describe(), "shm:" + name);
  const Dpr slave_dpr((*slave)->window());
  const Dpr master_dpr((*master)->window());
  slave_dpr.set_position(2, 76192);
  EXPECT_EQ(master_dpr.position(2), 76192);
  master_dpr.set_torque(1, 0x9F4);
  EXPECT_EQ(slave_dpr.torque(1), 0x9F4);
  EXPECT_FALSE((*master)->replaced());
  EXPECT_EQ(SimControl((*master)->window()).owner_pid(), static_cast<std::uint32_t>(::getpid()));
}

TEST(ShmTransport, CreatorUnlinksTheNameWhenDestroyed) {
  const std::string name = unique_name("unlink");
  {
    auto slave = create_shm(name);
    ASSERT_THAT(slave, IsOk());
  }
  EXPECT_THAT(open_shm(name), IsErrWith(Errc::kNotReady, "is cell-sim-7545 running"));
}

TEST(ShmTransport, OpenerSeesWhenTheSegmentWasReplaced) {
  const std::string name = unique_name("replace");
  auto first = create_shm(name);
  ASSERT_THAT(first, IsOk());
  auto master = open_shm(name);
  ASSERT_THAT(master, IsOk());
  first->reset();  // the simulator stops: its name goes
  EXPECT_TRUE((*master)->replaced());
  auto second = create_shm(name);
  ASSERT_THAT(second, IsOk());
  EXPECT_TRUE((*master)->replaced());
  auto again = open_shm(name);
  ASSERT_THAT(again, IsOk());
  EXPECT_FALSE((*again)->replaced());
}

TEST(ShmTransport, StaleSegmentOfADeadOwnerIsTakenOver) {
  const std::string name = unique_name("stale");
  // A segment left behind by a process that is gone: record a pid that cannot be alive.
  const int fd = ::shm_open(name.c_str(), O_RDWR | O_CREAT | O_EXCL, 0600);
  ASSERT_GE(fd, 0);
  ASSERT_EQ(::ftruncate(fd, static_cast<off_t>(kWindowSize)), 0);
  void* memory = ::mmap(nullptr, kWindowSize, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
  ASSERT_NE(memory, MAP_FAILED);
  SimControl({static_cast<std::byte*>(memory), kWindowSize}).initialise(0x7FFFFFF0);
  Dpr({static_cast<std::byte*>(memory), kWindowSize}).set_error(0x1000);
  ::munmap(memory, kWindowSize);
  ::close(fd);
  auto slave = create_shm(name);
  ASSERT_THAT(slave, IsOk());
  EXPECT_EQ(Dpr((*slave)->window()).error(), 0);  // a fresh, zero-filled window
}

TEST(ShmTransport, LiveOwnerIsNotEvicted) {
  const std::string name = unique_name("live");
  auto first = create_shm(name);
  ASSERT_THAT(first, IsOk());
  // Pretend another live process (our parent, pid 1 is always alive) owns it.
  SimControl((*first)->window()).initialise(1);
  EXPECT_THAT(create_shm(name), IsErrWith(Errc::kIo, "in use by process 1"));
  SimControl((*first)->window()).initialise(static_cast<std::uint32_t>(::getpid()));
}

TEST(ShmTransport, RejectsBadNamesAndSmallSegments) {
  EXPECT_THAT(create_shm("no-slash"), IsErrWith(Errc::kInvalidArgument, "must start with '/'"));
  EXPECT_THAT(open_shm("/a/b"), IsErr(Errc::kInvalidArgument));
  EXPECT_THAT(open_shm("/"), IsErrWith(Errc::kInvalidArgument, "2 to 255"));
  const std::string name = unique_name("small");
  const int fd = ::shm_open(name.c_str(), O_RDWR | O_CREAT | O_EXCL, 0600);
  ASSERT_GE(fd, 0);
  ASSERT_EQ(::ftruncate(fd, 0x48), 0);
  ::close(fd);
  EXPECT_THAT(open_shm(name), IsErrWith(Errc::kIo, "has 72 bytes, the DPR window needs 8192"));
  ::shm_unlink(name.c_str());
}

TEST(PhysicalTransport, FailsClearlyWhenTheDeviceCannotBeOpened) {
  const auto t = open_physical("/nonexistent/mem", kDefaultPhysicalBase);
  ASSERT_THAT(t, IsErrWith(Errc::kIo, "cannot open /nonexistent/mem"));
  EXPECT_THAT(t.error().message, ::testing::HasSubstr("0xc8000"));
  EXPECT_THAT(t.error().message, ::testing::HasSubstr("CAP_SYS_RAWIO"));
}

TEST(PhysicalTransport, RejectsAnUnalignedBase) {
  EXPECT_THAT(open_physical("/dev/mem", 0xC8010),
              IsErrWith(Errc::kInvalidArgument, "0xc8010 is not page-aligned"));
}

}  // namespace
}  // namespace cell::dpr7545
