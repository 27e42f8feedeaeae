// The bridge on a private bus, in-process, spoken to over HTTP on loopback like a browser
// would: sign-in, the 401 for anyone else, JobRequests reaching the bus, the live stream.
#include "monitor_service.hpp"

#include <arpa/inet.h>
#include <httplib.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <thread>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/bus/view.hpp"
#include "cell/common/time.hpp"
#include "cell/motion/wire.hpp"
#include "cell/testing/env.hpp"
#include "cell/testing/service_harness.hpp"

namespace cell::monitor {
namespace {

using namespace std::chrono_literals;
using ::cell::testing::eventually;
using ::testing::HasSubstr;
using nlohmann::json;

MonitorConfig test_config(const std::string& tasks_dir) {
  MonitorConfig c;
  c.common.service_id = "monitor";
  c.port = 0;
  c.web_root = "/nonexistent";  // the fallback page
  c.users = {{"ada", "operator", hash_password("pw-ada", 1000).value()},
             {"vic", "viewer", hash_password("pw-vic", 1000).value()}};
  RobotEntry r;
  r.id = "ibm7545";
  r.config = cell::testing::source_dir() + "/config/robots/ibm7545.yaml";
  r.world_T_base.translation() << 0, 0, 981.51;
  c.robots.push_back(r);
  JobTemplate t;
  t.name = "table_ics";
  t.kind = "table_pick_place";
  t.robot_id = "ibm7545";
  t.camera_id = "ibm7545_eye";
  t.spec_yaml = "count: 3\n";
  c.job_templates.push_back(t);
  c.tasks_dir = tasks_dir;
  return c;
}

class MonitorServiceTest : public ::testing::Test {
 protected:
  MonitorServiceTest()
      : domain_(cell::testing::test_domain_id()),
        partition_(cell::testing::unique_partition()),
        tasks_dir_(::testing::TempDir() + "/monitor-tasks-" + std::to_string(getpid())),
        monitor_(domain_, partition_, test_config(tasks_dir_), "monitor"),
        client_(domain_, partition_),
        job_topic_(client_, bus::topics::kJobRequest),
        jobs_(client_, job_topic_, bus::topics::kJobRequest),
        state_topic_(client_, bus::topics::kRobotState),
        states_(client_, state_topic_, bus::topics::kRobotState),
        http_("127.0.0.1", monitor_.service().port()) {
    std::filesystem::create_directories(tasks_dir_);
    http_.set_read_timeout(10, 0);
  }
  ~MonitorServiceTest() override { std::filesystem::remove_all(tasks_dir_); }

  /// Signs in and returns the Cookie header value.
  std::string sign_in(const std::string& user, const std::string& password) {
    auto r = http_.Post("/api/login", json{{"user", user}, {"password", password}}.dump(),
                        "application/json");
    if (!r || r->status != 200) {
      return {};
    }
    const std::string set = r->get_header_value("Set-Cookie");
    EXPECT_THAT(set, HasSubstr("HttpOnly"));
    EXPECT_THAT(set, HasSubstr("SameSite=Strict"));
    return set.substr(0, set.find(';'));
  }

  httplib::Result post(const std::string& path, const json& body, const std::string& cookie,
                       const std::string& type = "application/json") {
    httplib::Headers headers;
    if (!cookie.empty()) {
      headers.emplace("Cookie", cookie);
    }
    return http_.Post(path, headers, body.dump(), type);
  }

  void publish_state(double j1_deg, std::int64_t stamp_ns) {
    std::vector<double> q{j1_deg * M_PI / 180, 105 * M_PI / 180, 0, 0};
    const std::string id = "ibm7545";
    cell_robot_RobotState s{};
    s.robot_id = bus::borrow(id);
    s.header.stamp_ns = stamp_ns;
    bus::borrow(s.position_rad_or_mm, q);
    bus::borrow(s.setpoint_rad_or_mm, q);
    s.base_T_tool = motion::to_idl(Eigen::Isometry3d::Identity());
    s.mode = cell_robot_MODE_IDLE;
    ASSERT_TRUE(states_.write(s));
  }

  std::uint32_t domain_;
  std::string partition_;
  std::string tasks_dir_;
  cell::testing::ServiceHarness<MonitorConfig, MonitorService> monitor_;
  bus::Participant client_;
  bus::Topic<cell_task_JobRequest> job_topic_;
  bus::Reader<cell_task_JobRequest> jobs_;
  bus::Topic<cell_robot_RobotState> state_topic_;
  bus::Writer<cell_robot_RobotState> states_;
  httplib::Client http_;
};

TEST_F(MonitorServiceTest, UnauthenticatedCommandsGet401AndNothingReachesTheBus) {
  ASSERT_TRUE(jobs_.wait_for_writers(1, 10s));
  for (const char* path : {"/api/job/submit", "/api/job/command", "/api/motion",
                           "/api/robot/command", "/api/goto_part", "/api/teach/record"}) {
    auto r = post(path, json{{"template", "table_ics"}, {"robot", "ibm7545"}}, "");
    ASSERT_TRUE(r) << path;
    EXPECT_EQ(r->status, 401) << path;
    EXPECT_THAT(r->body, HasSubstr("sign in as an operator"));
  }
  auto forged = post("/api/job/submit", json{{"template", "table_ics"}},
                     "cell_session=" + std::string(64, 'f'));
  ASSERT_TRUE(forged);
  EXPECT_EQ(forged->status, 401);
  EXPECT_FALSE(jobs_.wait_for_data(1000ms));  // no JobRequest was published
}

TEST_F(MonitorServiceTest, ASignedInOperatorsJobReachesTheBusAndItsAnswerComesBack) {
  const std::string cookie = sign_in("ada", "pw-ada");
  ASSERT_FALSE(cookie.empty());
  // Nobody serves jobs yet: the operator is told so, nothing is left waiting.
  auto none = post("/api/job/submit", json{{"template", "table_ics"}, {"job_id", "job-0"}}, cookie);
  ASSERT_TRUE(none);
  EXPECT_EQ(none->status, 503);
  EXPECT_THAT(none->body, HasSubstr("no task service"));

  // A stand-in task service: queues job-42, rejects job-43 with a reason.
  bus::Topic<cell_task_JobStatus> status_topic(client_, bus::topics::kJobStatus);
  bus::Writer<cell_task_JobStatus> statuses(client_, status_topic, bus::topics::kJobStatus);
  std::vector<std::string> seen;
  std::atomic<bool> stop{false};
  std::thread task_service([&] {
    while (!stop) {
      if (!jobs_.wait_for_data(100ms)) {
        continue;
      }
      (void)jobs_.take_each([&](const cell_task_JobRequest& job, const dds_sample_info_t&) {
        const std::string id(bus::str(job.job_id));
        seen.push_back(fmt::format("{} {} {} {} {} {}", id, static_cast<int>(job.kind),
                                   bus::str(job.robot_id), bus::str(job.camera_id),
                                   bus::str(job.spec_yaml), bus::str(job.operator_id)));
        const std::string reason = "no camera 'ibm7545_eye' on the bus";
        const char* reasons[] = {reason.c_str()};
        cell_task_JobStatus st{};
        st.job_id = const_cast<char*>(id.c_str());
        st.request_id = job.request_id;
        st.state = id == "job-43" ? cell_task_JOB_REJECTED : cell_task_JOB_QUEUED;
        if (id == "job-43") {
          st.reasons._buffer = const_cast<char**>(reasons);
          st.reasons._length = st.reasons._maximum = 1;
        }
        (void)statuses.write(st);
      });
    }
  });
  ASSERT_TRUE(statuses.wait_for_readers(1, 10s));
  auto r = post("/api/job/submit", json{{"template", "table_ics"}, {"job_id", "job-42"}}, cookie);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 200) << r->body;
  EXPECT_EQ(json::parse(r->body)["status"]["state"], "queued");
  auto rejected =
      post("/api/job/submit", json{{"template", "table_ics"}, {"job_id", "job-43"}}, cookie);
  ASSERT_TRUE(rejected);
  EXPECT_EQ(rejected->status, 409);
  EXPECT_THAT(rejected->body, HasSubstr("rejected: no camera 'ibm7545_eye' on the bus"));
  stop = true;
  task_service.join();
  ASSERT_EQ(seen.size(), 2U);
  EXPECT_EQ(seen[0], fmt::format("job-42 {} ibm7545 ibm7545_eye count: 3\n ada",
                                 static_cast<int>(cell_task_JOB_TABLE_PICK_PLACE)));
}

TEST_F(MonitorServiceTest, JobCommandsNeedAnAnswerFromTheTaskService) {
  const std::string cookie = sign_in("ada", "pw-ada");
  auto none = post("/api/job/command", json{{"job_id", "job-42"}, {"command", "pause"}}, cookie);
  ASSERT_TRUE(none);
  EXPECT_EQ(none->status, 504);
  EXPECT_THAT(none->body, HasSubstr("is the task service running?"));
  bus::Topic<cell_task_JobCommand> command_topic(client_, bus::topics::kJobCommand);
  bus::Reader<cell_task_JobCommand> commands(client_, command_topic, bus::topics::kJobCommand);
  bus::Topic<cell_task_JobCommandReply> reply_topic(client_, bus::topics::kJobCommandReply);
  bus::Writer<cell_task_JobCommandReply> replies(client_, reply_topic,
                                                 bus::topics::kJobCommandReply);
  std::atomic<bool> stop{false};
  std::thread task_service([&] {
    while (!stop) {
      if (!commands.wait_for_data(100ms)) {
        continue;
      }
      (void)commands.take_each([&](const cell_task_JobCommand& c, const dds_sample_info_t&) {
        const std::string reason = "job 'job-42' is not paused";
        cell_task_JobCommandReply reply{};
        reply.request_id = c.request_id;
        reply.job_id = c.job_id;
        reply.status.accepted = c.kind != cell_task_JOB_RESUME;
        reply.status.reason = const_cast<char*>(reply.status.accepted ? "" : reason.c_str());
        (void)replies.write(reply);
      });
    }
  });
  ASSERT_TRUE(replies.wait_for_readers(1, 10s));
  auto paused = post("/api/job/command", json{{"job_id", "job-42"}, {"command", "pause"}}, cookie);
  ASSERT_TRUE(paused);
  EXPECT_EQ(paused->status, 200) << paused->body;
  auto resumed =
      post("/api/job/command", json{{"job_id", "job-42"}, {"command", "resume"}}, cookie);
  ASSERT_TRUE(resumed);
  EXPECT_EQ(resumed->status, 409);
  EXPECT_THAT(resumed->body, HasSubstr("resume refused: job 'job-42' is not paused"));
  auto bad = post("/api/job/command", json{{"job_id", "../x"}, {"command", "pause"}}, cookie);
  EXPECT_EQ(bad->status, 400);
  stop = true;
  task_service.join();
}

TEST_F(MonitorServiceTest, ViewersForeignOriginsAndBadBodiesAreRefused) {
  const std::string viewer = sign_in("vic", "pw-vic");
  ASSERT_FALSE(viewer.empty());
  auto r = post("/api/job/submit", json{{"template", "table_ics"}}, viewer);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 403);
  const std::string op = sign_in("ada", "pw-ada");
  httplib::Headers headers{{"Cookie", op}, {"Origin", "http://evil.example"}};
  auto cross = http_.Post("/api/job/submit", headers, R"({"template":"table_ics"})",
                          "application/json");
  ASSERT_TRUE(cross);
  EXPECT_EQ(cross->status, 403);
  auto form = post("/api/job/submit", json{{"template", "table_ics"}}, op,
                   "application/x-www-form-urlencoded");
  ASSERT_TRUE(form);
  EXPECT_EQ(form->status, 415);
  httplib::Headers h{{"Cookie", op}};
  for (const char* body : {"{", "[1,2]", "null", "\"x\"", "{\"template\": 7}"}) {
    auto bad = http_.Post("/api/job/submit", h, body, "application/json");
    ASSERT_TRUE(bad) << body;
    EXPECT_EQ(bad->status, 400) << body;
  }
  auto unknown = post("/api/motion", json{{"robot", "r2d2"}, {"stop", true}}, op);
  ASSERT_TRUE(unknown);
  EXPECT_EQ(unknown->status, 400);
  EXPECT_THAT(unknown->body, HasSubstr("unknown robot 'r2d2'"));
  auto wrong = http_.Post("/api/login", R"({"user":"ada","password":"nope"})", "application/json");
  ASSERT_TRUE(wrong);
  EXPECT_EQ(wrong->status, 401);
  // Still serving after all that.
  auto status = http_.Get("/api/status");
  ASSERT_TRUE(status);
  EXPECT_EQ(status->status, 200);
}

/// Sends raw bytes to the bridge and returns what it answers (until it closes or 3 s pass).
std::string raw_exchange(int port, const std::string& bytes) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(static_cast<std::uint16_t>(port));
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
    ::close(fd);
    return "connect failed";
  }
  timeval tv{3, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  // No half-close: cpp-httplib takes a half-closed socket for a dead one and does not answer.
  (void)::send(fd, bytes.data(), bytes.size(), MSG_NOSIGNAL);
  std::string out;
  char buf[4096];
  for (;;) {
    const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
    if (n < 0 && errno == EINTR) {
      continue;
    }
    if (n <= 0) {
      if (n < 0) {
        out += fmt::format("<recv: {}>", std::strerror(errno));
      }
      break;
    }
    out.append(buf, static_cast<std::size_t>(n));
  }
  ::close(fd);
  return out;
}

TEST_F(MonitorServiceTest, MalformedHttpIsAnsweredAndTheBridgeKeepsServing) {
  const int port = monitor_.service().port();
  EXPECT_THAT(raw_exchange(port, "GARBAGE\r\n\r\n"), HasSubstr("400"));
  EXPECT_THAT(raw_exchange(port, "GET /api/status HTTP/1.1\r\nHost: x\r\nConnection: close\r\n" +
                                     std::string(20000, 'A') + "\r\n\r\n"),
              HasSubstr("HTTP/1.1 4"));
  // Binary noise: cpp-httplib hangs up without an answer (nothing else to say to it).
  EXPECT_THAT(raw_exchange(port, std::string("\0\x01\xff\xfe\r\n\r\n", 8)),
              ::testing::AnyOf(::testing::IsEmpty(), HasSubstr("400")));
  const std::string big = "{\"user\": \"" + std::string(200000, 'a') + "\"}";
  EXPECT_THAT(raw_exchange(port, fmt::format("POST /api/login HTTP/1.1\r\nHost: x\r\n"
                                             "Content-Length: {}\r\nContent-Type: "
                                             "application/json\r\n\r\n{}",
                                             big.size(), big)),
              HasSubstr("413"));
  EXPECT_THAT(raw_exchange(port, "POST /api/login HTTP/1.1\r\nHost: x\r\nConnection: close\r\n"
                                 "Content-Length: 5\r\nContent-Type: application/json\r\n\r\n"
                                 "\xff\xfe{]]"),
              HasSubstr("400"));
  // Bad types everywhere in a signed-in command: 400s naming the field, never a crash.
  const std::string op = sign_in("ada", "pw-ada");
  for (const json& body : {json{{"robot", "ibm7545"}, {"preview", "yes"}, {"part", "ic1"}},
                           json{{"robot", "ibm7545"}, {"speed", "fast"}, {"part", "ic1"}},
                           json{{"robot", 7}},
                           json{{"robot", "ibm7545"}, {"camera", "c"}, {"index", "one"}}}) {
    auto r = post("/api/goto_part", body, op);
    ASSERT_TRUE(r) << body.dump();
    EXPECT_EQ(r->status, 400) << body.dump() << " -> " << r->body;
  }
  auto teach = post("/api/teach/run", json{{"preview", 3}}, op);
  ASSERT_TRUE(teach);
  EXPECT_EQ(teach->status, 400);
  EXPECT_THAT(teach->body, HasSubstr("'preview' must be true or false"));
  auto status = http_.Get("/api/status");
  ASSERT_TRUE(status);
  EXPECT_EQ(status->status, 200);
}

TEST_F(MonitorServiceTest, ConfigCarriesTheRobotModelsForTheBrowsersKinematics) {
  auto r = http_.Get("/api/config");
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 200);
  const json c = json::parse(r->body);
  ASSERT_EQ(c["robots"].size(), 1U);
  const json& robot = c["robots"][0];
  EXPECT_EQ(robot["id"], "ibm7545");
  EXPECT_EQ(robot["kind"], "scara");
  EXPECT_DOUBLE_EQ(robot["scara"]["link1_mm"].get<double>(), 400.0);
  EXPECT_EQ(robot["scara"]["z_down"], true);
  EXPECT_DOUBLE_EQ(robot["world_T_base"]["p"][2].get<double>(), 981.51);
  EXPECT_EQ(c["job_templates"][0]["name"], "table_ics");
  auto page = http_.Get("/");
  ASSERT_TRUE(page);
  EXPECT_THAT(page->body, HasSubstr("npm ci"));
  EXPECT_EQ(page->get_header_value("X-Frame-Options"), "DENY");
}

TEST_F(MonitorServiceTest, TheStreamCarriesRobotStatesPromptly) {
  ASSERT_TRUE(states_.wait_for_readers(1, 10s));
  std::atomic<bool> done{false};
  std::string received;
  std::mutex mutex;
  std::thread reader([&] {
    httplib::Client sse("127.0.0.1", monitor_.service().port());
    sse.set_read_timeout(10, 0);
    sse.Get("/api/stream", [&](const char* data, std::size_t n) {
      std::lock_guard lock(mutex);
      received.append(data, n);
      return !done.load();
    });
  });
  ASSERT_TRUE(eventually([&] { return monitor_.service().hub().client_count() == 1; }, 5s));
  // A stream of states; the browser must see the newest one (coalesced, not queued behind).
  for (int i = 0; i < 50; ++i) {
    publish_state(40.0 + i * 0.1, wall_time_ns());
    std::this_thread::sleep_for(2ms);
  }
  const std::string newest = fmt::format("{}", (40.0 + 49 * 0.1) * M_PI / 180);
  EXPECT_TRUE(eventually(
      [&] {
        std::lock_guard lock(mutex);
        return received.find("event: robots") != std::string::npos &&
               received.find(newest.substr(0, 8)) != std::string::npos;
      },
      5s))
      << received.substr(0, 2000);
  {
    std::lock_guard lock(mutex);
    EXPECT_THAT(received, HasSubstr("\"id\":\"ibm7545\""));
    EXPECT_THAT(received, HasSubstr("\"mode\":\"idle\""));
  }
  done = true;
  publish_state(50.0, wall_time_ns());  // wakes the stream so the reader can end
  reader.join();
}

TEST_F(MonitorServiceTest, TeachRecordsTheLiveJointsAndSavesAFile) {
  const std::string op = sign_in("ada", "pw-ada");
  ASSERT_TRUE(states_.wait_for_readers(1, 10s));
  auto created = post("/api/teach/create", json{{"robot", "ibm7545"}, {"name", "t1"}}, op);
  ASSERT_TRUE(created);
  ASSERT_EQ(created->status, 200) << created->body;
  auto early = post("/api/teach/record", json::object(), op);
  ASSERT_TRUE(early);
  EXPECT_EQ(early->status, 409);  // no robot state yet
  EXPECT_THAT(early->body, HasSubstr("no state from robot 'ibm7545'"));
  publish_state(44.0, wall_time_ns());
  ASSERT_TRUE(eventually(
      [&] {
        auto r = post("/api/teach/record", json{{"name", "a"}}, op);
        return r && r->status == 200;
      },
      5s));
  ASSERT_EQ(post("/api/teach/gripper", json{{"action", "close"}}, op)->status, 200);
  auto bad = post("/api/teach/gripper", json{{"action", "squeeze"}}, op);
  EXPECT_EQ(bad->status, 400);
  auto del = post("/api/teach/delete", json{{"index", 9}}, op);
  EXPECT_EQ(del->status, 400);
  EXPECT_THAT(del->body, HasSubstr("step 10 is out of range"));
  auto traversal = post("/api/teach/save", json{{"file", "../../etc/passwd"}}, op);
  EXPECT_EQ(traversal->status, 400);
  auto saved = post("/api/teach/save", json::object(), op);
  ASSERT_EQ(saved->status, 200) << saved->body;
  const json state = json::parse(saved->body)["state"];
  EXPECT_EQ(state["file"], "t1.yaml");
  ASSERT_EQ(state["task"]["steps"].size(), 2U);
  EXPECT_NEAR(state["task"]["steps"][0]["joints"][0].get<double>(), 44.0 * M_PI / 180, 1e-9);
  EXPECT_TRUE(std::filesystem::exists(tasks_dir_ + "/t1.yaml"));
  // Off-line preview of the whole task from the start: joints along the way, no bus needed.
  ASSERT_EQ(post("/api/teach/seek", json{{"position", 0}}, op)->status, 200);
  auto preview = post("/api/teach/run", json{{"preview", true}}, op);
  ASSERT_EQ(preview->status, 200) << preview->body;
  const json p = json::parse(preview->body);
  ASSERT_EQ(p["steps"].size(), 2U);
  EXPECT_EQ(p["steps"][1]["gripper"], "close");
}

}  // namespace
}  // namespace cell::monitor
