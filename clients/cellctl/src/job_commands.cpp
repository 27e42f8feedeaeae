// `cellctl submit|jobs|job|cancel|pause|resume|watch`: jobs of the task service
// (cell/task/job_request answered on cell/task/job_status; cell/task/job_command answered on
// cell/task/job_command_reply). Statuses are transient-local, so `jobs` sees every job the
// service keeps, including finished ones.
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <thread>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <yaml-cpp/yaml.h>

#include "cell/task/job_state.hpp"
#include "cell/bus/reader.hpp"
#include "cell/bus/request_reply.hpp"
#include "cell/bus/topics.hpp"
#include "cell/bus/view.hpp"
#include "cell/common/time.hpp"
#include "commands.hpp"

namespace cell::cellctl {
namespace {

using nlohmann::json;
using Clock = std::chrono::steady_clock;

std::string_view state_name(cell_task_JobState s) { return task::job_state_name(s); }

std::string_view kind_name(cell_task_JobKind k) {
  switch (k) {
    case cell_task_JOB_TABLE_PICK_PLACE:
      return "table_pick_place";
    case cell_task_JOB_CONVEYOR_PICK:
      return "conveyor_pick";
    case cell_task_JOB_ASSEMBLY:
      return "assembly";
    case cell_task_JOB_TASK_FILE:
      return "task_file";
  }
  return "unknown";
}

std::string_view outcome_name(cell_task_PartOutcome o) {
  switch (o) {
    case cell_task_PART_PENDING:
      return "pending";
    case cell_task_PART_PLACED:
      return "placed";
    case cell_task_PART_SKIPPED_UNREACHABLE:
      return "unreachable";
    case cell_task_PART_SKIPPED_GRIP_BLOCKED:
      return "grip_blocked";
    case cell_task_PART_SKIPPED_OUTSIDE_WINDOW:
      return "outside_window";
    case cell_task_PART_LOCATE_FAILED:
      return "locate_failed";
    case cell_task_PART_MISSED:
      return "missed";
  }
  return "unknown";
}

bool final_state(cell_task_JobState s) {
  return s == cell_task_JOB_SUCCEEDED || s == cell_task_JOB_FAILED ||
         s == cell_task_JOB_CANCELLED || s == cell_task_JOB_REJECTED;
}

constexpr double kPi = 3.14159265358979323846;

json status_json(const cell_task_JobStatus& s, bool with_parts) {
  json out{{"job_id", std::string(bus::str(s.job_id))},
           {"name", std::string(bus::str(s.name))},
           {"kind", std::string(kind_name(s.kind))},
           {"robot", std::string(bus::str(s.robot_id))},
           {"state", std::string(state_name(s.state))},
           {"step", std::string(bus::str(s.step))},
           {"progress", s.progress},
           {"parts_done", s.parts_done},
           {"parts_failed", s.parts_failed},
           {"elapsed_s", s.elapsed_s},
           {"steps", s.step_index}};
  json reasons = json::array();
  for (const char* r : bus::span(s.reasons)) {
    reasons.push_back(std::string(bus::str(r)));
  }
  out["reasons"] = reasons;
  json counters = json::object();
  for (const auto& c : bus::span(s.counters)) {
    counters[std::string(bus::str(c.name))] = c.value;
  }
  out["counters"] = counters;
  if (with_parts) {
    json parts = json::array();
    for (const auto& p : bus::span(s.parts)) {
      parts.push_back({{"index", p.index},
                       {"class", std::string(bus::str(p.class_name))},
                       {"outcome", std::string(outcome_name(p.outcome))},
                       {"picked_at", {{"x_mm", p.picked_at.x_mm},
                                      {"y_mm", p.picked_at.y_mm},
                                      {"yaw_deg", p.picked_at.rz_rad * 180 / kPi}}},
                       {"placed_at", {{"x_mm", p.placed_at.x_mm},
                                      {"y_mm", p.placed_at.y_mm},
                                      {"yaw_deg", p.placed_at.rz_rad * 180 / kPi}}},
                       {"detail", std::string(bus::str(p.detail))}});
    }
    out["parts"] = parts;
  }
  return out;
}

std::string bar(double fraction) {
  const int n = static_cast<int>(std::lround(std::clamp(fraction, 0.0, 1.0) * 30));
  return "[" + std::string(static_cast<std::size_t>(n), '#') +
         std::string(static_cast<std::size_t>(30 - n), '.') + "]";
}

std::string line_of(const cell_task_JobStatus& s) {
  std::string counters;
  for (const auto& c : bus::span(s.counters)) {
    counters += fmt::format(" {}={}", bus::str(c.name), c.value);
  }
  return fmt::format("{} {} {:3.0f}% {} parts {} done, {} failed; {}{}", bus::str(s.job_id),
                     bar(s.progress), s.progress * 100, state_name(s.state), s.parts_done,
                     s.parts_failed, bus::str(s.step), counters);
}

/// Every job status the service keeps (transient-local), newest per job.
std::map<std::string, bus::Owned<cell_task_JobStatus>> read_statuses(Session& session,
                                                                      bool& served) {
  bus::Topic<cell_task_JobStatus> topic(session.participant(), bus::topics::kJobStatus);
  bus::Reader<cell_task_JobStatus> reader(session.participant(), topic, bus::topics::kJobStatus);
  served = reader.wait_for_writers(1, session.timeout());
  std::map<std::string, bus::Owned<cell_task_JobStatus>> out;
  if (!served) {
    return out;
  }
  // The historical data arrives just after the match: read until it stops coming.
  auto quiet_since = Clock::now();
  const auto until = Clock::now() + session.timeout();
  while (Clock::now() < until && Clock::now() - quiet_since < std::chrono::milliseconds(200)) {
    auto batch = reader.take_copies(64);
    if (batch && !batch->empty()) {
      for (auto& s : *batch) {
        out[std::string(bus::str(s->job_id))] = std::move(s);
      }
      quiet_since = Clock::now();
    }
    (void)reader.wait_for_data(std::chrono::milliseconds(50));
  }
  return out;
}

struct SubmitArgs {
  std::string file;
  std::string job_id;
  int priority = 0;
  std::string operator_id = "cellctl";
  bool wait = false;
  double wait_s = 3600;
};

volatile std::sig_atomic_t g_interrupted = 0;

int submit(Session& session, const SubmitArgs& args) {
  std::ifstream f(args.file);
  if (!f) {
    return session.fail(fmt::format("{}: cannot open", args.file), kExitUsage);
  }
  std::stringstream text;
  text << f.rdbuf();
  const std::string spec = text.str();
  std::string kind;
  std::string robot;
  try {
    const YAML::Node root = YAML::Load(spec);
    if (!root.IsMap()) {
      return session.fail(fmt::format("{}: a job file is a YAML mapping", args.file), kExitUsage);
    }
    kind = root["kind"] ? root["kind"].as<std::string>("") : "";
    robot = root["robot"] ? root["robot"].as<std::string>("") : "";
  } catch (const YAML::Exception& e) {
    return session.fail(fmt::format("{}:{}:{}: {}", args.file, e.mark.line + 1, e.mark.column + 1,
                                    e.msg),
                        kExitUsage);
  }
  cell_task_JobKind idl_kind = cell_task_JOB_TABLE_PICK_PLACE;
  if (kind == "conveyor_pick") {
    idl_kind = cell_task_JOB_CONVEYOR_PICK;
  } else if (kind == "assembly") {
    idl_kind = cell_task_JOB_ASSEMBLY;
  }
  const std::string job_id =
      !args.job_id.empty()
          ? args.job_id
          : fmt::format("{}-{}", std::filesystem::path(args.file).stem().string(),
                        wall_time_ns() / 1'000'000);
  cell_task_JobRequest request{};
  request.job_id = bus::borrow(job_id);
  request.kind = idl_kind;
  request.robot_id = bus::borrow(robot);
  request.spec_yaml = bus::borrow(spec);
  const std::string program = args.file;
  request.program_name = bus::borrow(program);
  request.priority = args.priority;
  request.operator_id = bus::borrow(args.operator_id);
  bus::Requester<cell_task_JobRequest, cell_task_JobStatus> requester(
      session.participant(), bus::topics::kJobRequest, bus::topics::kJobStatus,
      bus::make_client_id("cellctl"));
  auto reply = requester.call(request, session.timeout() + std::chrono::seconds(3));
  if (!reply) {
    return session.fail(fmt::format("submit '{}': {} (is the task service running on {}?)",
                                    job_id, reply.error().message, session.describe_bus()));
  }
  const cell_task_JobStatus& first = reply->get();
  if (first.state == cell_task_JOB_REJECTED) {
    if (session.json()) {
      session.out() << status_json(first, false).dump(2) << "\n";
    } else {
      session.err() << fmt::format("job '{}' rejected:\n", job_id);
      for (const char* r : bus::span(first.reasons)) {
        session.err() << "  " << bus::str(r) << "\n";
      }
    }
    return kExitFailure;
  }
  if (!args.wait) {
    if (session.json()) {
      session.out() << status_json(first, false).dump(2) << "\n";
    } else {
      session.out() << fmt::format("job '{}' accepted ({})\n", job_id, state_name(first.state));
    }
    return kExitOk;
  }
  if (!session.json()) {
    session.err() << fmt::format("job '{}' accepted; waiting (Ctrl-C stops waiting, not the "
                                 "job)\n",
                                 job_id);
  }
  // Follow the job's status until it ends.
  bus::Reader<cell_task_JobStatus>& statuses = requester.replies();
  bus::Topic<cell_task_JobStatus> topic(session.participant(), bus::topics::kJobStatus);
  bus::Reader<cell_task_JobStatus> all(session.participant(), topic, bus::topics::kJobStatus);
  (void)statuses;
  g_interrupted = 0;
  std::signal(SIGINT, [](int) { g_interrupted = 1; });
  const auto deadline = Clock::now() + std::chrono::milliseconds(
                                           static_cast<std::int64_t>(args.wait_s * 1000));
  std::string last_line;
  const bool tty = ::isatty(STDERR_FILENO) != 0;
  while (Clock::now() < deadline && g_interrupted == 0) {
    auto batch = all.take_copies(32);
    if (batch) {
      for (auto& s : *batch) {
        if (bus::str(s->job_id) != job_id) {
          continue;
        }
        if (!session.json()) {
          const std::string line = line_of(s.get());
          if (line != last_line) {
            session.err() << (tty ? "\r\033[K" : "") << line << (tty ? "" : "\n") << std::flush;
            last_line = line;
          }
        }
        if (final_state(s->state)) {
          if (!session.json() && tty) {
            session.err() << "\n";
          }
          if (session.json()) {
            session.out() << status_json(s.get(), true).dump(2) << "\n";
          } else {
            session.out() << fmt::format("job '{}' {}: {} parts placed, {} not\n", job_id,
                                         state_name(s->state), s->parts_done, s->parts_failed);
            for (const char* r : bus::span(s->reasons)) {
              session.out() << "  " << bus::str(r) << "\n";
            }
          }
          return s->state == cell_task_JOB_SUCCEEDED ? kExitOk : kExitFailure;
        }
      }
    }
    (void)all.wait_for_data(std::chrono::milliseconds(100));
  }
  return session.fail(g_interrupted != 0
                          ? fmt::format("stopped waiting; job '{}' goes on", job_id)
                          : fmt::format("job '{}' did not end within {} s", job_id, args.wait_s));
}

int list_jobs(Session& session) {
  bool served = false;
  auto statuses = read_statuses(session, served);
  if (!served) {
    return session.fail(fmt::format("no task service on {}", session.describe_bus()));
  }
  if (session.json()) {
    json out = json::array();
    for (const auto& [id, s] : statuses) {
      out.push_back(status_json(s.get(), false));
    }
    session.out() << out.dump(2) << "\n";
    return kExitOk;
  }
  session.out() << fmt::format("{:<32} {:<10} {:<17} {:<13} {:>6} {:>5} {:>6}  {}\n", "JOB",
                               "STATE", "KIND", "ROBOT", "DONE", "PARTS", "FAILED", "STEP");
  for (const auto& [id, s] : statuses) {
    session.out() << fmt::format("{:<32} {:<10} {:<17} {:<13} {:>5.0f}% {:>5} {:>6}  {}\n", id,
                                 state_name(s->state), kind_name(s->kind), bus::str(s->robot_id),
                                 s->progress * 100, s->parts_done, s->parts_failed,
                                 bus::str(s->step));
  }
  return kExitOk;
}

int show_job(Session& session, const std::string& job_id) {
  bool served = false;
  auto statuses = read_statuses(session, served);
  if (!served) {
    return session.fail(fmt::format("no task service on {}", session.describe_bus()));
  }
  auto it = statuses.find(job_id);
  if (it == statuses.end()) {
    return session.fail(fmt::format("no job '{}' (cellctl jobs lists them)", job_id));
  }
  const cell_task_JobStatus& s = it->second.get();
  if (session.json()) {
    session.out() << status_json(s, true).dump(2) << "\n";
    return kExitOk;
  }
  session.out() << line_of(s) << "\n";
  for (const char* r : bus::span(s.reasons)) {
    session.out() << "  reason: " << bus::str(r) << "\n";
  }
  session.out() << fmt::format("  {:>4} {:<12} {:<15} {:>28} {:>28}  {}\n", "PART", "CLASS",
                               "OUTCOME", "PICKED x, y [mm], yaw [deg]",
                               "PLACED x, y [mm], yaw [deg]", "DETAIL");
  for (const auto& p : bus::span(s.parts)) {
    session.out() << fmt::format(
        "  {:>4} {:<12} {:<15} {:>9.2f} {:>9.2f} {:>8.2f} {:>9.2f} {:>9.2f} {:>8.2f}  {}\n",
        p.index, bus::str(p.class_name), outcome_name(p.outcome), p.picked_at.x_mm,
        p.picked_at.y_mm, p.picked_at.rz_rad * 180 / kPi, p.placed_at.x_mm, p.placed_at.y_mm,
        p.placed_at.rz_rad * 180 / kPi, bus::str(p.detail));
  }
  return kExitOk;
}

int job_command(Session& session, const std::string& job_id, cell_task_JobCommandKind kind,
                const char* what) {
  bus::Requester<cell_task_JobCommand, cell_task_JobCommandReply> requester(
      session.participant(), bus::topics::kJobCommand, bus::topics::kJobCommandReply,
      bus::make_client_id("cellctl"));
  cell_task_JobCommand c{};
  c.job_id = bus::borrow(job_id);
  c.kind = kind;
  const std::string op = "cellctl";
  c.operator_id = bus::borrow(op);
  auto reply = requester.call(c, session.timeout() + std::chrono::seconds(1));
  if (!reply) {
    return session.fail(fmt::format("{} '{}': {} (is the task service running on {}?)", what,
                                    job_id, reply.error().message, session.describe_bus()));
  }
  const bool ok = (*reply)->status.accepted;
  if (session.json()) {
    json out{{"job_id", job_id}, {"command", what}, {"accepted", ok}};
    if (!ok) {
      out["reason"] = std::string(bus::str((*reply)->status.reason));
    }
    session.out() << out.dump(2) << "\n";
  } else if (ok) {
    session.out() << fmt::format("{} '{}': accepted\n", what, job_id);
  }
  if (!ok) {
    return session.fail(fmt::format("{} '{}' refused: {}", what, job_id,
                                    bus::str((*reply)->status.reason)));
  }
  return kExitOk;
}

int watch(Session& session, double for_s) {
  bus::Topic<cell_task_JobStatus> topic(session.participant(), bus::topics::kJobStatus);
  bus::Reader<cell_task_JobStatus> reader(session.participant(), topic, bus::topics::kJobStatus);
  g_interrupted = 0;
  std::signal(SIGINT, [](int) { g_interrupted = 1; });
  const auto until = for_s > 0 ? Clock::now() + std::chrono::milliseconds(
                                                    static_cast<std::int64_t>(for_s * 1000))
                               : Clock::time_point::max();
  std::map<std::string, std::string> last;
  while (g_interrupted == 0 && Clock::now() < until) {
    auto batch = reader.take_copies(64);
    if (batch) {
      for (auto& s : *batch) {
        const std::string id(bus::str(s->job_id));
        if (session.json()) {
          session.out() << status_json(s.get(), false).dump() << "\n" << std::flush;
          continue;
        }
        const std::string line = line_of(s.get());
        if (last[id] != line) {
          session.out() << line << "\n" << std::flush;
          last[id] = line;
        }
      }
    }
    (void)reader.wait_for_data(std::chrono::milliseconds(100));
  }
  return kExitOk;
}

}  // namespace

void add_job_commands(CLI::App& app, Commands& commands) {
  auto submit_args = std::make_shared<SubmitArgs>();
  CLI::App* sub = app.add_subcommand("submit", "submit a job file (config/jobs/*.yaml)");
  sub->add_option("file", submit_args->file, "the job's YAML file")->required();
  sub->add_option("--id", submit_args->job_id, "job id (default: <file stem>-<ms since epoch>)");
  sub->add_option("--priority", submit_args->priority, "higher runs first (default 0)");
  sub->add_option("--operator", submit_args->operator_id, "who submits it");
  sub->add_flag("--wait", submit_args->wait,
                "follow the job with a progress bar until it ends; exit 0 only if it succeeded");
  sub->add_option("--wait-s", submit_args->wait_s, "give up waiting after this long [s]");
  commands.add(sub, [submit_args](Session& s) { return submit(s, *submit_args); });

  CLI::App* jobs = app.add_subcommand("jobs", "list the task service's jobs");
  commands.add(jobs, [](Session& s) { return list_jobs(s); });

  auto job_id = std::make_shared<std::string>();
  CLI::App* job = app.add_subcommand("job", "one job with its parts and counters");
  job->add_option("id", *job_id, "job id")->required();
  commands.add(job, [job_id](Session& s) { return show_job(s, *job_id); });

  for (const auto& [name, kind, help] :
       {std::tuple{"cancel", cell_task_JOB_CANCEL, "cancel a job (the robot stops)"},
        std::tuple{"pause", cell_task_JOB_PAUSE, "pause a job after its current motion"},
        std::tuple{"resume", cell_task_JOB_RESUME, "resume a paused job"}}) {
    auto id = std::make_shared<std::string>();
    CLI::App* c = app.add_subcommand(name, help);
    c->add_option("id", *id, "job id")->required();
    const char* what = name;
    const cell_task_JobCommandKind k = kind;
    commands.add(c, [id, k, what](Session& s) { return job_command(s, *id, k, what); });
  }

  auto for_s = std::make_shared<double>(0.0);
  CLI::App* w = app.add_subcommand("watch", "live status lines of every job (Ctrl-C ends)");
  w->add_option("--for", *for_s, "stop after this many seconds (0: until Ctrl-C)");
  commands.add(w, [for_s](Session& s) { return watch(s, *for_s); });
}

}  // namespace cell::cellctl
