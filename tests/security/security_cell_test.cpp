// DDS Security end to end (deploy/security/README.md): a PKI made by deploy/security/make-pki.sh
// in a temporary directory, a small real cell (cell-task, cell-echo) on a private domain and
// partition, each process with CYCLONEDDS_URI=file://config/dds/loopback.xml,file://<pki>/<id>.xml
// (the launcher's form), and participants of several identities run as security_probe / cellctl
// processes (Cyclone reads the identity once per process). Proves: no certificate sees nothing
// and is heard by no one; the monitor role reads but cannot publish job requests; tampered
// permissions stop a participant at creation; the operator gets the task service's answers.
// With CELL_RELIABILITY_OUT set, one JSON row per case goes to $CELL_RELIABILITY_OUT/security.jsonl.
#include <sys/stat.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "cell/process/child.hpp"
#include "cell/testing/env.hpp"

namespace {

using json = nlohmann::json;
using namespace std::chrono_literals;
namespace process = cell::process;
using cell::testing::eventually;
using cell::testing::ToolRun;
using ::testing::HasSubstr;

constexpr int kExitParticipant = 3;  // security_probe, cell-echo: DDS setup failed
constexpr int kExitRefused = 4;      // security_probe: a writer or reader was refused
constexpr int kNotAllowedBySecurity = -13;  // DDS_RETCODE_NOT_ALLOWED_BY_SECURITY

std::string read_text(const std::string& path) {
  std::ifstream f(path);
  return std::string((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
}

/// The JSON object a probe or a cellctl --json run printed (output merged: from the first '{').
json parsed(const ToolRun& run) {
  const auto begin = run.output.find('{');
  const auto end = run.output.rfind('}');
  if (begin == std::string::npos || end == std::string::npos || end < begin) {
    return json();
  }
  return json::parse(run.output.substr(begin, end - begin + 1), nullptr, false);
}

/// One row of the reliability results ($CELL_RELIABILITY_OUT/security.jsonl), when asked for.
void report(const std::string& scenario, const std::string& load, const std::string& faults,
            const std::string& outcome, const std::string& lost, double duration_s) {
  const char* dir = std::getenv("CELL_RELIABILITY_OUT");
  if (dir == nullptr || *dir == '\0') {
    return;
  }
  std::filesystem::create_directories(dir);
  std::ofstream out(std::string(dir) + "/security.jsonl", std::ios::app);
  out << json{{"suite", "security"},   {"scenario", scenario}, {"load", load},
              {"faults", faults},      {"outcome", outcome},   {"lost", lost},
              {"duration_s", duration_s}}
             .dump()
      << "\n";
}

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

class SecureCell : public ::testing::Test {
 protected:
  SecureCell()
      : domain_(cell::testing::test_domain_id()), partition_(cell::testing::unique_partition()) {
    std::string pattern = "/tmp/cell-security-test-XXXXXX";
    dir_ = mkdtemp(pattern.data()) != nullptr ? pattern : "/tmp/cell-security-test-fallback";
    pki_ = dir_ + "/pki";
    net_ = cell::testing::source_dir() + "/config/dds/loopback.xml";
  }

  ~SecureCell() override {
    for (auto it = children_.rbegin(); it != children_.rend(); ++it) {
      auto& [name, child] = *it;
      if (child.running()) {
        const auto exit = child.stop(10s);
        if (!exit.exited || exit.code != 0) {
          ADD_FAILURE() << name << " ended with " << exit.describe() << ":\n" << child.output();
        }
      }
    }
    if (HasFailure()) {
      std::printf("%s", logs().c_str());
    }
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }

  /// Runs make-pki.sh for `identities`; returns its run (output kept for failure messages).
  ToolRun make_pki(const std::vector<std::string>& args) {
    process::SpawnOptions options;
    options.executable = cell::testing::source_dir() + "/deploy/security/make-pki.sh";
    options.args = args;
    auto child = process::Child::spawn(options);
    if (!child) {
      ADD_FAILURE() << "make-pki.sh: " << child.error().message;
      return {};
    }
    auto info = child->wait_for(60s);
    if (!info) {
      ADD_FAILURE() << "make-pki.sh did not finish within 60 s:\n" << child->output();
      info = child->stop(500ms);
    }
    return ToolRun{*info, child->output()};
  }

  /// The bus environment with CYCLONEDDS_URI = the network config followed by `fragments`.
  std::vector<std::string> env_with(const std::vector<std::string>& fragments) const {
    std::vector<std::string> env = cell::testing::bus_env(domain_, partition_);
    std::string uri = "CYCLONEDDS_URI=file://" + net_;
    for (const auto& f : fragments) {
      uri += ",file://" + f;
    }
    std::replace_if(
        env.begin(), env.end(), [](const std::string& e) { return e.rfind("CYCLONEDDS_URI=", 0) == 0; },
        uri);
    env.push_back("CELL_HOME=" + cell::testing::source_dir());
    return env;
  }

  /// The environment of identity `id` (its make-pki.sh fragment), or of no identity ("").
  std::vector<std::string> env_of(const std::string& id) const {
    return id.empty() ? env_with({}) : env_with({pki_ + "/" + id + ".xml"});
  }

  process::Child& start(const std::string& name, const std::string& exec,
                        const std::vector<std::string>& args, const std::vector<std::string>& env) {
    process::SpawnOptions options;
    options.executable = cell::testing::bin_path(exec);
    options.args = args;
    options.env = env;
    auto child = process::Child::spawn(options);
    EXPECT_TRUE(child) << child.error().message;
    children_.emplace_back(name, child ? std::move(*child) : process::Child());
    return children_.back().second;
  }

  /// cell-task (journal in the temp dir) and cell-echo, each with its own identity.
  void start_cell(bool secured) {
    std::string text = read_text(cell::testing::source_dir() + "/config/task.yaml");
    const std::string key = "journal: run/task/journal.sqlite";
    const auto at = text.find(key);
    ASSERT_NE(at, std::string::npos) << "config/task.yaml has no '" << key << "' line";
    text.replace(at, key.size(), "journal: " + dir_ + "/journal.sqlite");
    const std::string task_config = dir_ + "/task.yaml";
    std::ofstream(task_config) << text;
    start("task", "cell-task", {"--config", task_config, "--id", "task"},
          env_of(secured ? "task" : ""));
    start("echo", "cell-echo",
          {"--config", cell::testing::source_dir() + "/config/echo.yaml", "--id", "echo"},
          env_of(secured ? "echo" : ""));
  }

  ToolRun probe(const std::vector<std::string>& args, const std::vector<std::string>& env) {
    return cell::testing::run_tool("security_probe", args, env, 30s);
  }

  ToolRun cellctl(std::vector<std::string> args, const std::vector<std::string>& env) {
    args.insert(args.begin(), {"--timeout", "5"});
    return cell::testing::run_tool("cellctl", args, env, 30s);
  }

  std::string logs() {
    std::string out;
    for (auto& [name, c] : children_) {
      std::string text;
      (void)c.read_available(text);
      out.append("---- ").append(name).append("\n").append(c.output()).append(text);
    }
    return out;
  }

  std::uint32_t domain_;
  std::string partition_;
  std::string dir_;
  std::string pki_;
  std::string net_;
  std::vector<std::pair<std::string, process::Child>> children_;
};

// make-pki.sh alone: the files and modes it promises, idempotence, and its refusals.
TEST_F(SecureCell, MakePkiMakesSignedMaterialAndRefusesBadInput) {
  const auto t0 = std::chrono::steady_clock::now();
  ToolRun run = make_pki({"--out", pki_, "echo", "viewer", "someone=operations"});
  ASSERT_EQ(run.exit.code, 0) << run.output;
  EXPECT_THAT(run.output, HasSubstr("identity viewer: role monitor"));
  for (const char* f : {"ca_cert.pem", "private/ca_key.pem", "governance.p7s", "echo_cert.pem",
                        "private/echo_key.pem", "echo_permissions.p7s", "echo.xml",
                        "someone_permissions.p7s", "viewer.xml"}) {
    EXPECT_TRUE(std::filesystem::is_regular_file(pki_ + "/" + f)) << f << " missing";
  }
  struct stat st {};
  ASSERT_EQ(stat((pki_ + "/private").c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0700U);

  // The fragment holds the Security part only, with absolute file: paths.
  const std::string fragment = read_text(pki_ + "/viewer.xml");
  EXPECT_THAT(fragment, HasSubstr("<Security>"));
  EXPECT_THAT(fragment, HasSubstr("file:" + pki_ + "/viewer_permissions.p7s"));
  EXPECT_THAT(fragment, ::testing::Not(HasSubstr("<General>")));
  // Grant subject in RFC 2253 form, full timestamps; the monitor role publishes nothing.
  const std::string viewer = read_text(pki_ + "/viewer_permissions.xml");
  EXPECT_THAT(viewer, HasSubstr("<subject_name>CN=viewer,O=cell</subject_name>"));
  EXPECT_THAT(viewer, ::testing::ContainsRegex("<not_after>[0-9]{4}-[0-9]{2}-[0-9]{2}T[0-9:]{8}Z"));
  EXPECT_THAT(viewer, ::testing::Not(HasSubstr("<publish>")));
  const std::string someone = read_text(pki_ + "/someone_permissions.xml");
  EXPECT_THAT(someone, HasSubstr("<topic>cell/task/job_request</topic>"));
  EXPECT_THAT(someone, ::testing::Not(HasSubstr("<topic>cell/robot/state</topic>")));

  // Idempotent: a second run keeps the CA, the keys and the signatures.
  const std::string ca = read_text(pki_ + "/ca_cert.pem");
  const std::string signed_echo = read_text(pki_ + "/echo_permissions.p7s");
  run = make_pki({"--out", pki_, "echo", "viewer", "someone=operations"});
  ASSERT_EQ(run.exit.code, 0) << run.output;
  EXPECT_THAT(run.output, HasSubstr("CA: keeping"));
  EXPECT_EQ(read_text(pki_ + "/ca_cert.pem"), ca);
  EXPECT_EQ(read_text(pki_ + "/echo_permissions.p7s"), signed_echo);
  // --force: a new CA.
  run = make_pki({"--out", pki_, "--force", "echo"});
  ASSERT_EQ(run.exit.code, 0) << run.output;
  EXPECT_NE(read_text(pki_ + "/ca_cert.pem"), ca);

  run = make_pki({"--out", pki_, "echo=wizard"});
  EXPECT_EQ(run.exit.code, 2);
  EXPECT_THAT(run.output, HasSubstr("unknown role 'wizard' for identity 'echo'"));
  run = make_pki({"--out", pki_, "../etc"});
  EXPECT_EQ(run.exit.code, 2);
  EXPECT_THAT(run.output, HasSubstr("bad identity name '../etc'"));
  run = make_pki({"--out", pki_, "stranger"});
  EXPECT_EQ(run.exit.code, 2);
  EXPECT_THAT(run.output, HasSubstr("no role for identity 'stranger'"));
  run = make_pki({"echo"});
  EXPECT_EQ(run.exit.code, 2);
  EXPECT_THAT(run.output, HasSubstr("--out DIR is required"));
  report("make_pki", "make-pki.sh: 3 identities, rerun, --force, 4 bad invocations",
         "unknown role, bad identity name, unmapped name, no --out",
         HasFailure() ? "failed" : "passed: files, modes, idempotent, errors named",
         "nothing lost", seconds_since(t0));
}

TEST_F(SecureCell, RolesAreEnforcedOnTheBus) {
  auto t0 = std::chrono::steady_clock::now();
  const ToolRun pki = make_pki({"--out", pki_, "task", "echo", "operator", "viewer"});
  ASSERT_EQ(pki.exit.code, 0) << pki.output;
  start_cell(true);

  // (d) The operator: cellctl sees both services, submits a job and gets the task service's
  // answer over the secured bus (accepted, or rejected with reasons: no gateway runs here).
  const auto op = env_of("operator");
  ToolRun ping;
  ASSERT_TRUE(eventually(
      [&] {
        ping = cellctl({"--json", "ping"}, op);
        const json doc = parsed(ping);
        return ping.exit.code == 0 && doc.contains("services") && doc["services"].size() >= 2;
      },
      30s))
      << ping.output << logs();
  const ToolRun submitted = probe({"submit", "--job-id", "operator-job", "--seconds", "15"}, op);
  const json answer = parsed(submitted);
  EXPECT_EQ(submitted.exit.code, 0) << submitted.output;
  EXPECT_EQ(answer.value("writer", ""), "created") << submitted.output;
  EXPECT_EQ(answer.value("answer_job_id", ""), "operator-job") << submitted.output;
  if (answer.value("rejected", false)) {
    EXPECT_FALSE(answer["reasons"].empty()) << "a rejection names its reasons: " << submitted.output;
  }
  const ToolRun via_cellctl = cellctl(
      {"submit", cell::testing::source_dir() + "/config/jobs/table_ics.yaml", "--id", "cellctl-job"},
      op);
  EXPECT_THAT(via_cellctl.output, ::testing::AnyOf(HasSubstr("job 'cellctl-job' accepted"),
                                                   HasSubstr("job 'cellctl-job' rejected")))
      << via_cellctl.output;
  ToolRun jobs;
  EXPECT_TRUE(eventually(
      [&] {
        jobs = cellctl({"jobs"}, op);
        return jobs.exit.code == 0 && jobs.output.find("operator-job") != std::string::npos &&
               jobs.output.find("cellctl-job") != std::string::npos;
      },
      15s))
      << jobs.output;
  const ToolRun rtt = cellctl({"ping", "--rtt"}, op);
  EXPECT_EQ(rtt.exit.code, 0) << rtt.output;
  report("operator_submits", "cell-task + cell-echo secured; operator: ping, 2 job requests, jobs",
         "none", HasFailure() ? "failed" : "passed: both jobs answered over the secured bus",
         "nothing lost", seconds_since(t0));

  // (a) No certificate: discovers nothing, reads nothing, and is heard by no one.
  t0 = std::chrono::steady_clock::now();
  const ToolRun plain = probe({"listen", "--seconds", "4"}, env_of(""));
  const json plain_doc = parsed(plain);
  ASSERT_EQ(plain.exit.code, 0) << plain.output;
  EXPECT_EQ(plain_doc.value("heartbeats", -1), 0) << plain.output;
  EXPECT_EQ(plain_doc.value("job_status", -1), 0) << plain.output;
  const ToolRun plain_submit =
      probe({"submit", "--job-id", "plain-job", "--seconds", "3"}, env_of(""));
  EXPECT_EQ(plain_submit.exit.code, 5) << "no server may match an unauthenticated writer: "
                                       << plain_submit.output;
  const ToolRun plain_ping = cellctl({"ping"}, env_of(""));
  EXPECT_NE(plain_ping.exit.code, 0) << plain_ping.output;
  report("no_certificate", "listen 4 s for heartbeats and job status; a job request; cellctl ping",
         "participant without a certificate",
         HasFailure() ? "failed"
                      : "passed: 0 heartbeats, 0 job statuses, request unmatched, ping finds none",
         "nothing leaked", seconds_since(t0));

  // (b) The viewer (monitor role): reads heartbeats and job status; its job request is refused
  // at writer creation.
  t0 = std::chrono::steady_clock::now();
  const auto viewer = env_of("viewer");
  ToolRun listened;
  json seen;
  EXPECT_TRUE(eventually(
      [&] {
        listened = probe({"listen", "--seconds", "3"}, viewer);
        seen = parsed(listened);
        return listened.exit.code == 0 && seen.value("heartbeats", 0) > 0 &&
               seen.value("job_status", 0) > 0;
      },
      20s))
      << listened.output;
  EXPECT_THAT(seen.value("heartbeat_from", json::array()).dump(), HasSubstr("\"task\""));
  EXPECT_THAT(seen.value("jobs", json::array()).dump(), HasSubstr("operator-job"));
  const ToolRun refused = probe({"submit", "--job-id", "viewer-job", "--seconds", "3"}, viewer);
  const json refused_doc = parsed(refused);
  EXPECT_EQ(refused.exit.code, kExitRefused) << refused.output;
  EXPECT_EQ(refused_doc.value("writer", ""), "refused") << refused.output;
  EXPECT_EQ(refused_doc.value("code", 0), kNotAllowedBySecurity) << refused.output;
  const ToolRun viewer_ping = cellctl({"ping"}, viewer);
  EXPECT_EQ(viewer_ping.exit.code, 0) << "heartbeats only: " << viewer_ping.output;
  const ToolRun viewer_rtt = cellctl({"ping", "--rtt"}, viewer);
  EXPECT_NE(viewer_rtt.exit.code, 0) << "a viewer may not publish pings: " << viewer_rtt.output;
  report("viewer_read_only", "viewer: listen for heartbeats and job status; a job request; ping",
         "monitor-role identity publishes",
         HasFailure() ? "failed"
                      : "passed: reads " + std::to_string(seen.value("heartbeats", 0)) +
                            " heartbeats; job request writer refused with -13",
         "nothing lost", seconds_since(t0));

  // (c) Tampered permissions (one byte of the signed text flipped): no participant at all.
  t0 = std::chrono::steady_clock::now();
  std::string permissions = read_text(pki_ + "/viewer_permissions.p7s");
  const auto at = permissions.find("<not_after>");
  ASSERT_NE(at, std::string::npos);
  permissions[at + 14] = permissions[at + 14] == '9' ? '8' : '9';  // a digit of the year
  std::ofstream(pki_ + "/tampered_permissions.p7s") << permissions;
  std::string fragment = read_text(pki_ + "/viewer.xml");
  const std::string signed_path = pki_ + "/viewer_permissions.p7s";
  fragment.replace(fragment.find(signed_path), signed_path.size(),
                   pki_ + "/tampered_permissions.p7s");
  std::ofstream(pki_ + "/tampered.xml") << fragment;
  // Cyclone says why only at Tracing warning or above: a third fragment, as a user would add.
  const std::string trace = dir_ + "/trace.xml";
  std::ofstream(trace) << "<CycloneDDS xmlns=\"https://cdds.io/config\"><Domain Id=\"any\"><Tracing>"
                          "<Verbosity>warning</Verbosity><OutputFile>stderr</OutputFile>"
                          "</Tracing></Domain></CycloneDDS>\n";
  const auto tampered_env = env_with({pki_ + "/tampered.xml", trace});
  const ToolRun tampered = probe({"listen", "--seconds", "1"}, tampered_env);
  EXPECT_EQ(tampered.exit.code, kExitParticipant) << tampered.output;
  EXPECT_EQ(parsed(tampered).value("participant", ""), "failed") << tampered.output;
  EXPECT_THAT(tampered.output, HasSubstr("create participant on domain")) << tampered.output;
  EXPECT_THAT(tampered.output, HasSubstr("validating local permissions")) << tampered.output;
  const ToolRun tampered_echo = cell::testing::run_tool(
      "cell-echo",
      {"--config", cell::testing::source_dir() + "/config/echo.yaml", "--id", "echo-tampered"},
      tampered_env, 20s);
  EXPECT_TRUE(tampered_echo.exit.exited && tampered_echo.exit.code == kExitParticipant)
      << tampered_echo.exit.describe() << "\n" << tampered_echo.output;
  report("tampered_permissions", "probe and cell-echo with a tampered permissions document",
         "one byte of the signed not_after flipped",
         HasFailure() ? "failed" : "passed: participant creation refused (probe exit 3, echo exit 3)",
         "nothing lost", seconds_since(t0));

  // Nothing the refused or unauthenticated participants sent reached the task service.
  jobs = cellctl({"--json", "jobs"}, op);
  EXPECT_EQ(jobs.exit.code, 0) << jobs.output;
  EXPECT_THAT(jobs.output, HasSubstr("operator-job"));
  EXPECT_THAT(jobs.output, ::testing::Not(HasSubstr("viewer-job")));
  EXPECT_THAT(jobs.output, ::testing::Not(HasSubstr("plain-job")));
  // The secured services still run: none of their own endpoints was refused.
  for (auto& [name, child] : children_) {
    EXPECT_TRUE(child.running()) << name << " stopped:\n" << child.output();
  }
}

// The cost: cellctl ping --rtt, median of several runs, on a plain and on a secured cell.
TEST_F(SecureCell, RoundTripPlainVersusSecured) {
  const auto t0 = std::chrono::steady_clock::now();
  const ToolRun pki = make_pki({"--out", pki_, "echo", "operator"});
  ASSERT_EQ(pki.exit.code, 0) << pki.output;
  auto median_rtt_ms = [&](bool secured) {
    start("echo", "cell-echo",
          {"--config", cell::testing::source_dir() + "/config/echo.yaml", "--id", "echo"},
          env_of(secured ? "echo" : ""));
    const auto client = env_of(secured ? "operator" : "");
    std::vector<double> rtts;
    EXPECT_TRUE(eventually([&] { return cellctl({"ping"}, client).exit.code == 0; }, 20s));
    for (int i = 0; i < 7; ++i) {
      const ToolRun run = cellctl({"--json", "ping", "--rtt"}, client);
      const json doc = parsed(run);
      if (run.exit.code == 0 && doc.contains("services") && !doc["services"].empty()) {
        rtts.push_back(doc["services"][0].value("rtt_ms", -1.0));
      } else {
        ADD_FAILURE() << run.output;
      }
    }
    children_.back().second.stop(10s);
    children_.pop_back();
    std::sort(rtts.begin(), rtts.end());
    return rtts.empty() ? -1.0 : rtts[rtts.size() / 2];
  };
  const double plain_ms = median_rtt_ms(false);
  const double secured_ms = median_rtt_ms(true);
  std::printf("cellctl ping --rtt median of 7: plain %.3f ms, secured %.3f ms\n", plain_ms,
              secured_ms);
  EXPECT_GT(plain_ms, 0.0);
  EXPECT_GT(secured_ms, 0.0);
  EXPECT_LT(secured_ms, 100.0) << "a secured ping on loopback takes well under 100 ms";
  char outcome[160];
  std::snprintf(outcome, sizeof outcome, "%s: rtt median plain %.3f ms, secured %.3f ms",
                HasFailure() ? "failed" : "passed", plain_ms, secured_ms);
  report("rtt_plain_vs_secured", "cell-echo; 7 x cellctl ping --rtt, plain then secured", "none",
         outcome, "nothing lost", seconds_since(t0));
}

}  // namespace
