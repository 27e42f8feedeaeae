#include "journal.hpp"

#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/testing/matchers.hpp"

namespace cell::task_service {
namespace {

using ::cell::testing::IsErrWith;
using ::cell::testing::IsOk;

class JournalTest : public ::testing::Test {
 protected:
  JournalTest()
      : dir_(fmt::format("/tmp/cell-journal-test-{}-{}", ::getpid(), ++counter_)),
        path_(dir_ + "/sub/journal.sqlite") {}
  ~JournalTest() override { std::filesystem::remove_all(dir_); }

  static JournalJob job(const std::string& id) {
    JournalJob j;
    j.job_id = id;
    j.kind = "table_pick_place";
    j.robot_id = "ibm7545";
    j.spec_yaml = "kind: table_pick_place\n";
    j.request_json = R"({"client_id":"c","seq":1})";
    return j;
  }

  static inline int counter_ = 0;
  std::string dir_;
  std::string path_;
};

TEST_F(JournalTest, AcceptsStepsAndResumesWhatIsUnfinished) {
  auto j = Journal::open(path_);
  ASSERT_THAT(j, IsOk());
  ASSERT_THAT(j->accept(job("a")), IsOk());
  ASSERT_THAT(j->accept(job("b")), IsOk());
  ASSERT_THAT(j->step("a", "running", "picked", R"({"part":0})", R"({"slot":1})"), IsOk());
  ASSERT_THAT(j->set_state("b", "succeeded"), IsOk());
  auto open = j->unfinished();
  ASSERT_THAT(open, IsOk());
  ASSERT_EQ(open->size(), 1U);
  EXPECT_EQ((*open)[0].job_id, "a");
  EXPECT_EQ((*open)[0].state, "running");
  EXPECT_EQ((*open)[0].progress_json, R"({"slot":1})");
  EXPECT_EQ((*open)[0].steps, 1);
  auto recent = j->recent(10);
  ASSERT_THAT(recent, IsOk());
  EXPECT_EQ(recent->size(), 2U);
}

TEST_F(JournalTest, AJobIdIsUsedOnceAndAStepOfAnUnknownJobFails) {
  auto j = Journal::open(path_);
  ASSERT_THAT(j, IsOk());
  ASSERT_THAT(j->accept(job("a")), IsOk());
  EXPECT_THAT(j->accept(job("a")), IsErrWith(Errc::kInvalidArgument, "exists already"));
  EXPECT_THAT(j->step("nope", "running", "x", "{}", "{}"), IsErrWith(Errc::kConfig, "no such job"));
  auto found = j->find("nope");
  ASSERT_THAT(found, IsOk());
  EXPECT_FALSE(found->has_value());
}

// Durability: a step whose call returned survives the process being killed right after it
// (no clean close, no destructor): the child journals and _exit()s without cleanup.
TEST_F(JournalTest, ACommittedStepSurvivesAKilledProcess) {
  {
    auto j = Journal::open(path_);
    ASSERT_THAT(j, IsOk());
    ASSERT_THAT(j->accept(job("k")), IsOk());
  }
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    auto j = Journal::open(path_);
    for (int i = 0; i < 20; ++i) {
      if (!j || !j->step("k", "running", fmt::format("s{}", i), "{}",
                          fmt::format(R"({{"i":{}}})", i))) {
        ::_exit(1);
      }
    }
    ::kill(::getpid(), SIGKILL);  // no destructor, no sqlite3_close
    ::_exit(2);
  }
  int status = 0;
  ::waitpid(pid, &status, 0);
  ASSERT_TRUE(WIFSIGNALED(status));
  auto j = Journal::open(path_);
  ASSERT_THAT(j, IsOk());
  auto found = j->find("k");
  ASSERT_THAT(found, IsOk());
  ASSERT_TRUE(found->has_value());
  EXPECT_EQ((*found)->steps, 20);
  EXPECT_EQ((*found)->progress_json, R"({"i":19})");
}

TEST_F(JournalTest, AnUnwritablePathIsAClearError) {
  EXPECT_THAT(Journal::open("/proc/cell-no/journal.sqlite"),
              IsErrWith(Errc::kConfig, "/proc/cell-no"));
}

}  // namespace
}  // namespace cell::task_service
