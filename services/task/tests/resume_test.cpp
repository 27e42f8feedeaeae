// A task service started on a journal that already holds finished jobs of every kind: it starts,
// and every job is on the status topic with the parts and counters its last step journaled.
// (Issue 22: the history's counters were read through a destroyed temporary; after one conveyor
// job cell-task crash-looped at every start. The sanitizer build reports that read here.)
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "cell/bus/participant.hpp"
#include "cell/bus/reader.hpp"
#include "cell/bus/topic.hpp"
#include "cell/bus/topics.hpp"
#include "cell/bus/view.hpp"
#include "cell/config/yaml.hpp"
#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"
#include "cell/testing/service_harness.hpp"
#include "job_run.hpp"
#include "journal.hpp"
#include "task_config.hpp"
#include "task_service.hpp"

namespace cell::task_service {
namespace {

using ::cell::testing::IsOk;
using ::testing::HasSubstr;
using nlohmann::json;
using namespace std::chrono_literals;

std::string shipped_job(const std::string& name) {
  std::ifstream in(cell::testing::source_dir() + "/config/jobs/" + name);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

/// One finished job as the journal keeps it.
struct Finished {
  std::string id;
  std::string kind;
  std::string robot;
  std::string spec_file;
  std::string state;
  std::map<std::string, std::uint32_t> counters;
  std::vector<PartRecord> parts;
  cell_task_JobState idl_state;
  cell_task_JobKind idl_kind;
};

PartRecord part(std::uint32_t index, const std::string& cls, cell_task_PartOutcome outcome) {
  PartRecord p;
  p.index = index;
  p.class_name = cls;
  p.picked_x_mm = 100.0 + index;
  p.picked_y_mm = 500.0;
  p.placed_x_mm = -310.0;
  p.placed_y_mm = 250.0 + 30.0 * index;
  p.outcome = outcome;
  p.detail = outcome == cell_task_PART_PLACED ? "" : "a grasp closed on nothing";
  return p;
}

/// The progress JobRun::step journals: the executor's own keys, then parts and counters.
json progress_of(const Finished& f) {
  json parts = json::array();
  for (const auto& p : f.parts) {
    parts.push_back(to_json(p));
  }
  return json{{"next_part", f.parts.size()}, {"_parts", parts}, {"_counters", f.counters}};
}

class TaskResumeTest : public ::testing::Test {
 protected:
  TaskResumeTest()
      : dir_(fmt::format("/tmp/cell-task-resume-{}-{}", ::getpid(), ++counter_)),
        domain_(cell::testing::test_domain_id()),
        partition_(cell::testing::unique_partition()) {
    std::filesystem::create_directories(dir_);
  }
  ~TaskResumeTest() override { std::filesystem::remove_all(dir_); }

  std::string journal_path() const { return dir_ + "/journal.sqlite"; }

  /// Journals `f` as the service does: accepted, one completed step, its final state.
  void journal(Journal& j, const Finished& f) {
    JournalJob job;
    job.job_id = f.id;
    job.kind = f.kind;
    job.robot_id = f.robot;
    job.spec_yaml = shipped_job(f.spec_file);
    job.request_json = R"({"client_id":"cellctl-1","seq":7})";
    ASSERT_THAT(j.accept(job), IsOk());
    ASSERT_THAT(j.step(f.id, "running", "part done", "{}", progress_of(f).dump()), IsOk());
    ASSERT_THAT(j.set_state(f.id, f.state), IsOk());
  }

  TaskConfig config() const {
    auto doc = config::load_file(cell::testing::source_dir() + "/config/task.yaml");
    EXPECT_THAT(doc, IsOk());
    auto c = load_config(*doc);
    EXPECT_THAT(c, IsOk());
    c->journal = journal_path();
    return *c;
  }

  /// Every JobStatus on the topic within `wait`, by job id (the last sample of each).
  std::map<std::string, json> statuses(std::size_t expected, std::chrono::seconds wait) {
    bus::Participant client(domain_, partition_);
    bus::Topic<cell_task_JobStatus> topic(client, bus::topics::kJobStatus);
    bus::Reader<cell_task_JobStatus> reader(client, topic, bus::topics::kJobStatus);
    std::map<std::string, json> seen;
    cell::testing::eventually(
        [&] {
          reader.wait_for_data(100ms);
          for (auto& s : *reader.take_copies(64)) {
            json j{{"state", static_cast<int>(s->state)},
                   {"kind", static_cast<int>(s->kind)},
                   {"parts", json::array()},
                   {"counters", json::object()},
                   {"reasons", json::array()}};
            for (const auto& p : bus::span(s->parts)) {
              j["parts"].push_back({{"index", p.index},
                                    {"class", std::string(bus::str(p.class_name))},
                                    {"outcome", static_cast<int>(p.outcome)},
                                    {"placed_y_mm", p.placed_at.y_mm}});
            }
            for (const auto& c : bus::span(s->counters)) {
              j["counters"][std::string(bus::str(c.name))] = c.value;
            }
            for (const char* r : bus::span(s->reasons)) {
              j["reasons"].push_back(std::string(r));
            }
            seen[std::string(bus::str(s->job_id))] = j;
          }
          return seen.size() >= expected;
        },
        wait);
    return seen;
  }

  static inline int counter_ = 0;
  std::string dir_;
  std::uint32_t domain_;
  std::string partition_;
};

TEST_F(TaskResumeTest, StartsOnFinishedJobsOfEveryKindAndListsEachWithItsPartsAndCounters) {
  const std::vector<Finished> jobs = {
      {"table-1", "table_pick_place", "ibm7545", "table_ics.yaml", "succeeded",
       {{"grasps", 3}, {"retries", 1}},
       {part(0, "ic_6x19", cell_task_PART_PLACED), part(1, "dip8", cell_task_PART_PLACED),
        part(2, "dip8", cell_task_PART_MISSED)},
       cell_task_JOB_SUCCEEDED, cell_task_JOB_TABLE_PICK_PLACE},
      {"belt-1", "conveyor_pick", "scara_picker", "conveyor_ics.yaml", "succeeded",
       {{"picked", 15}, {"locate_failed", 2}, {"outside_window", 1}},
       {part(0, "dip14", cell_task_PART_PLACED), part(1, "dip14", cell_task_PART_PLACED)},
       cell_task_JOB_SUCCEEDED, cell_task_JOB_CONVEYOR_PICK},
      {"assembly-1", "assembly", "excalibur", "assembly_blocks.yaml", "failed",
       {{"looks", 2}},
       {part(0, "block", cell_task_PART_MISSED)},
       cell_task_JOB_FAILED, cell_task_JOB_ASSEMBLY},
      {"belt-2", "conveyor_pick", "scara_picker", "conveyor_ics_fast.yaml", "cancelled",
       {{"picked", 4}, {"grip_blocked", 3}},
       {},
       cell_task_JOB_CANCELLED, cell_task_JOB_CONVEYOR_PICK},
  };
  {
    auto j = Journal::open(journal_path());
    ASSERT_THAT(j, IsOk());
    for (const auto& f : jobs) {
      journal(*j, f);
    }
  }
  // Twice: the service starts on that journal, and starts again after it has run on it.
  for (int start = 0; start < 2; ++start) {
    SCOPED_TRACE(fmt::format("start {}", start + 1));
    cell::testing::ServiceHarness<TaskConfig, TaskService> task(domain_, partition_, config(),
                                                                "task");
    const auto seen = statuses(jobs.size(), 10s);
    ASSERT_EQ(seen.size(), jobs.size());
    for (const auto& f : jobs) {
      ASSERT_EQ(seen.count(f.id), 1U) << f.id;
      const json& s = seen.at(f.id);
      EXPECT_EQ(s["state"], static_cast<int>(f.idl_state)) << f.id;
      EXPECT_EQ(s["kind"], static_cast<int>(f.idl_kind)) << f.id;
      EXPECT_EQ(s["reasons"], json::array()) << f.id;
      json counters = json::object();
      for (const auto& [name, value] : f.counters) {
        counters[name] = value;
      }
      EXPECT_EQ(s["counters"], counters) << f.id;
      ASSERT_EQ(s["parts"].size(), f.parts.size()) << f.id;
      for (std::size_t i = 0; i < f.parts.size(); ++i) {
        EXPECT_EQ(s["parts"][i]["class"], f.parts[i].class_name);
        EXPECT_EQ(s["parts"][i]["outcome"], static_cast<int>(f.parts[i].outcome));
        EXPECT_DOUBLE_EQ(s["parts"][i]["placed_y_mm"].get<double>(), f.parts[i].placed_y_mm);
      }
    }
  }
}

// A row the service cannot read is reported and set aside; the others are served.
TEST_F(TaskResumeTest, AJobWhoseProgressCannotBeReadIsReportedAndTheRestAreServed) {
  {
    auto j = Journal::open(journal_path());
    ASSERT_THAT(j, IsOk());
    Finished good{"belt-ok", "conveyor_pick", "scara_picker", "conveyor_ics.yaml", "succeeded",
                  {{"picked", 9}}, {}, cell_task_JOB_SUCCEEDED, cell_task_JOB_CONVEYOR_PICK};
    journal(*j, good);
    // A finished job whose counter is not a number, and an unfinished one whose part is not
    // an object: neither may stop the service.
    JournalJob bad;
    bad.job_id = "belt-bad";
    bad.kind = "conveyor_pick";
    bad.robot_id = "scara_picker";
    bad.spec_yaml = shipped_job("conveyor_ics.yaml");
    ASSERT_THAT(j->accept(bad), IsOk());
    ASSERT_THAT(j->step("belt-bad", "running", "x", "{}", R"({"_counters":{"picked":"many"}})"),
                IsOk());
    ASSERT_THAT(j->set_state("belt-bad", "succeeded"), IsOk());
    bad.job_id = "table-bad";
    bad.kind = "table_pick_place";
    bad.robot_id = "ibm7545";
    bad.spec_yaml = shipped_job("table_ics.yaml");
    ASSERT_THAT(j->accept(bad), IsOk());
    ASSERT_THAT(j->step("table-bad", "paused", "x", "{}", R"({"_parts":[17]})"), IsOk());
  }
  cell::testing::ServiceHarness<TaskConfig, TaskService> task(domain_, partition_, config(),
                                                              "task");
  const auto seen = statuses(3, 10s);
  ASSERT_EQ(seen.size(), 3U);
  EXPECT_EQ(seen.at("belt-ok")["counters"], (json{{"picked", 9}}));
  EXPECT_EQ(seen.at("belt-bad")["state"], static_cast<int>(cell_task_JOB_SUCCEEDED));
  EXPECT_THAT(seen.at("belt-bad")["reasons"].dump(), HasSubstr("could not be read"));
  EXPECT_EQ(seen.at("table-bad")["state"], static_cast<int>(cell_task_JOB_FAILED));
  EXPECT_THAT(seen.at("table-bad")["reasons"].dump(), HasSubstr("could not be read"));
  // The journal says so too: the unreadable unfinished job is not resumed at the next start.
  auto j = Journal::open(journal_path());
  ASSERT_THAT(j, IsOk());
  auto row = j->find("table-bad");
  ASSERT_THAT(row, IsOk());
  ASSERT_TRUE(row->has_value());
  EXPECT_EQ((*row)->state, "failed");
}

}  // namespace
}  // namespace cell::task_service
