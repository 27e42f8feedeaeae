#include "task_service.hpp"

#include <algorithm>
#include <stdexcept>

#include <fmt/format.h>

#include "cell/task/job_state.hpp"
#include "cell/bus/request_reply.hpp"
#include "cell/bus/topics.hpp"
#include "cell/bus/view.hpp"
#include "cell/common/log.hpp"
#include "cell/common/time.hpp"
#include "cell/kinematics/robot_config.hpp"
#include "cell/world/scene.hpp"

namespace cell::task_service {
namespace {

using namespace std::chrono_literals;
using json = nlohmann::json;

constexpr dds_attach_t kStop = 1;
constexpr dds_attach_t kRequest = 2;
constexpr dds_attach_t kCommand = 3;

std::string state_name(cell_task_JobState s) { return std::string(task::job_state_name(s)); }

cell_task_JobState state_from(const std::string& s) {
  for (const auto st : {cell_task_JOB_QUEUED, cell_task_JOB_REJECTED, cell_task_JOB_RUNNING,
                        cell_task_JOB_PAUSED, cell_task_JOB_SUCCEEDED, cell_task_JOB_FAILED,
                        cell_task_JOB_CANCELLED}) {
    if (state_name(st) == s) {
      return st;
    }
  }
  return cell_task_JOB_FAILED;
}

bool final_state(cell_task_JobState s) {
  return s == cell_task_JOB_SUCCEEDED || s == cell_task_JOB_FAILED ||
         s == cell_task_JOB_CANCELLED || s == cell_task_JOB_REJECTED;
}

cell_task_JobKind idl_kind(task::JobKind k) {
  switch (k) {
    case task::JobKind::kTablePickPlace:
      return cell_task_JOB_TABLE_PICK_PLACE;
    case task::JobKind::kConveyorPick:
      return cell_task_JOB_CONVEYOR_PICK;
    case task::JobKind::kAssembly:
      return cell_task_JOB_ASSEMBLY;
  }
  return cell_task_JOB_TABLE_PICK_PLACE;
}


/// Storage for one JobStatus sample's strings and sequences.
struct StatusWire {
  std::string step;
  std::string robot;
  std::string name;
  std::string job_id;
  std::string client_id;
  std::string frame;
  std::vector<std::string> reason_text;
  std::vector<char*> reasons;
  std::vector<std::string> part_text;
  std::vector<cell_task_PartResult> parts;
  std::vector<std::string> counter_names;
  std::vector<cell_task_JobCounter> counters;
};

}  // namespace

TaskService::TaskService(service::Context& ctx, const TaskConfig& config)
    : ctx_(ctx),
      config_(config),
      catalogue_(world::Catalogue::standard()),
      journal_([&] {
        auto j = Journal::open(config.journal);
        if (!j) {
          throw std::runtime_error(j.error().message);
        }
        return std::move(*j);
      }()),
      request_topic_(ctx.participant(), bus::topics::kJobRequest),
      command_topic_(ctx.participant(), bus::topics::kJobCommand),
      status_topic_(ctx.participant(), bus::topics::kJobStatus),
      command_reply_topic_(ctx.participant(), bus::topics::kJobCommandReply),
      request_reader_(ctx.participant(), request_topic_, bus::topics::kJobRequest),
      command_reader_(ctx.participant(), command_topic_, bus::topics::kJobCommand),
      status_writer_(ctx.participant(), status_topic_, bus::topics::kJobStatus),
      command_reply_writer_(ctx.participant(), command_reply_topic_,
                            bus::topics::kJobCommandReply) {
  for (const auto& entry : config_.robots) {
    auto model = kinematics::load_robot(entry.config);
    if (!model) {
      throw std::runtime_error(model.error().message);
    }
    if (model->id() != entry.id) {
      throw std::runtime_error(fmt::format("robots: id '{}' but {} describes robot '{}'",
                                           entry.id, entry.config, model->id()));
    }
    robots_.emplace(entry.id, std::move(*model));
  }
  for (const auto& path : config_.scenes) {
    auto scene = world::load_scene_file(path, catalogue_);
    if (!scene) {
      throw std::runtime_error(scene.error().message);
    }
    for (const auto& cls : scene->classes) {
      if (!catalogue_.find(cls.name)) {
        (void)catalogue_.add(cls);
      }
    }
  }
  resume_from_journal();
  for (const auto& entry : config_.robots) {
    auto w = std::make_unique<Worker>();
    w->robot_id = entry.id;
    w->links = std::make_unique<Links>(ctx.participant(),
                                       fmt::format("{}.{}", config_.common.service_id, entry.id));
    workers_.push_back(std::move(w));
  }
  for (auto& w : workers_) {
    Worker* worker = w.get();
    worker->thread = std::thread([this, worker] { worker_loop(*worker); });
  }
  log::info("task", "serving",
            {{"journal", journal_.path()},
             {"robots", std::to_string(robots_.size())},
             {"jobs_resumed", std::to_string(jobs_.size())}});
}

TaskService::~TaskService() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
    for (auto& [id, e] : jobs_) {
      e->control.stop = true;
    }
  }
  work_.notify_all();
  for (auto& w : workers_) {
    if (w->thread.joinable()) {
      w->thread.join();
    }
  }
}

const kinematics::RobotModel* TaskService::robot(std::string_view id) const {
  auto it = robots_.find(id);
  return it != robots_.end() ? &it->second : nullptr;
}

task::CellFacts TaskService::facts() const {
  task::CellFacts f;
  f.robots = [this](std::string_view id) { return robot(id); };
  f.catalogue = &catalogue_;
  for (const auto& c : config_.cameras) {
    f.cameras.push_back(c.id);
  }
  for (const auto& b : config_.belts) {
    f.belts.push_back(b.id);
  }
  f.working_plane_z_mm = [this](std::string_view camera) -> std::optional<double> {
    for (const auto& c : config_.cameras) {
      if (c.id == camera) {
        return c.working_plane_z_mm;
      }
    }
    return std::nullopt;
  };
  return f;
}

void TaskService::run(service::Context& ctx) {
  bus::WaitSet waitset(ctx.participant());
  waitset.attach(ctx.stop_guard().get(), kStop);
  waitset.attach(request_reader_.condition(), kRequest);
  waitset.attach(command_reader_.condition(), kCommand);
  ctx.health().set(cell_health_HEALTH_SERVING);
  auto next_status = Clock::now();
  for (;;) {
    const bus::Fired fired = waitset.wait(100ms);
    if (fired.contains(kStop) || ctx.stopping()) {
      break;
    }
    take_requests();
    take_commands();
    if (Clock::now() >= next_status) {
      publish_running();
      next_status = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                       std::chrono::duration<double>(config_.status_period_s));
    }
    ctx.health().tick();
  }
  ctx.health().set(cell_health_HEALTH_STOPPING);
  // Jobs in progress stay "running" in the journal: a restart resumes them.
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
    for (auto& [id, e] : jobs_) {
      e->control.stop = true;
    }
  }
  work_.notify_all();
  for (auto& w : workers_) {
    if (w->thread.joinable()) {
      w->thread.join();
    }
  }
}

void TaskService::take_requests() {
  for (;;) {
    auto batch = request_reader_.take_copies(16);
    if (!batch || batch->empty()) {
      return;
    }
    for (const auto& r : *batch) {
      handle_request(r.get());
    }
  }
}

void TaskService::reject(const cell_task_JobRequest& request,
                         const std::vector<std::string>& reasons, bool duplicate) {
  Entry e;
  e.job_id = std::string(bus::str(request.job_id));
  if (duplicate) {
    // The id belongs to another job, whose status must not be overwritten: the refusal goes
    // out under its own key (the requester matches replies by request id).
    e.job_id += fmt::format("~rejected~{}", request.request_id.seq);
  }
  e.client_id = std::string(bus::str(request.request_id.client_id));
  e.request_seq = request.request_id.seq;
  e.state = cell_task_JOB_REJECTED;
  e.reasons = reasons;
  e.step = "rejected";
  e.accepted_ns = wall_time_ns();
  log::warn("task", "job rejected",
            {{"job", e.job_id}, {"reasons", fmt::format("{}", fmt::join(reasons, " | "))}});
  std::lock_guard lock(mutex_);
  publish(e);
  // Refusals are kept on the topic for a while (a late reader still sees why), then dropped.
  rejected_.push_back(e.job_id);
  while (rejected_.size() > 64) {
    cell_task_JobStatus key{};
    key.job_id = bus::borrow(rejected_.front());
    if (jobs_.count(rejected_.front()) == 0) {
      (void)status_writer_.unregister(key);
    }
    rejected_.pop_front();
  }
}

void TaskService::handle_request(const cell_task_JobRequest& request) {
  const std::string job_id(bus::str(request.job_id));
  std::vector<std::string> reasons;
  if (job_id.empty()) {
    reject(request, {"job_id is empty: every job needs a unique id"});
    return;
  }
  if (job_id.size() > 200 || job_id.find_first_of("\n\r\t/") != std::string::npos) {
    reject(request, {"job_id must be at most 200 characters without '/', tabs or newlines"});
    return;
  }
  {
    std::lock_guard lock(mutex_);
    if (auto it = jobs_.find(job_id); it != jobs_.end()) {
      const Entry& existing = *it->second;
      if (existing.client_id == bus::str(request.request_id.client_id) &&
          existing.request_seq == request.request_id.seq) {
        publish(existing);  // the same request again: answer it again
        return;
      }
    }
  }
  if (auto found = journal_.find(job_id); found && *found) {
    reject(request,
           {fmt::format("job '{}' exists already (state {}): a job id is used once", job_id,
                        (*found)->state)},
           true);
    return;
  }
  const std::string spec_yaml(bus::str(request.spec_yaml));
  if (spec_yaml.size() > 1'000'000) {
    reject(request, {fmt::format("spec_yaml is {} bytes; at most 1 MB", spec_yaml.size())});
    return;
  }
  auto spec = task::parse_job_spec(spec_yaml, fmt::format("<job {}>", job_id),
                                   [this](std::string_view id) { return robot(id); });
  if (!spec) {
    reject(request, split_lines(spec.error().message));
    return;
  }
  const std::string robot_id(bus::str(request.robot_id));
  if (!robot_id.empty() && robot_id != spec->robot) {
    reasons.push_back(fmt::format("the request names robot '{}' but its spec robot '{}'",
                                  robot_id, spec->robot));
  }
  if (bus::raw(request.kind) != idl_kind(spec->kind)) {  // any value may come off the wire
    reasons.push_back(fmt::format("the request's kind ({}) differs from its spec's '{}'",
                                  bus::raw(request.kind), task::to_string(spec->kind)));
  }
  if (auto s = task::check_job(*spec, facts()); !s) {
    for (auto& line : split_lines(s.error().message)) {
      reasons.push_back(std::move(line));
    }
  }
  if (const auto* a = spec->assembly(); a != nullptr) {
    if (const kinematics::RobotModel* model = facts().robots(spec->robot); model != nullptr) {
      if (auto s = check_assembly(*a, *model); !s) {
        for (auto& line : split_lines(s.error().message)) {
          reasons.push_back(std::move(line));
        }
      }
    }
  }
  if (!reasons.empty()) {
    reject(request, reasons);
    return;
  }
  auto entry = std::make_unique<Entry>();
  entry->job_id = job_id;
  entry->client_id = std::string(bus::str(request.request_id.client_id));
  entry->request_seq = request.request_id.seq;
  entry->priority = request.priority;
  entry->operator_id = std::string(bus::str(request.operator_id));
  entry->spec_yaml = spec_yaml;
  entry->spec = std::move(*spec);
  entry->accepted_ns = wall_time_ns();
  JournalJob j;
  j.job_id = job_id;
  j.kind = std::string(task::to_string(entry->spec.kind));
  j.robot_id = entry->spec.robot;
  j.spec_yaml = spec_yaml;
  j.request_json = json{{"client_id", entry->client_id},
                        {"seq", entry->request_seq},
                        {"priority", entry->priority},
                        {"operator", entry->operator_id}}
                       .dump();
  j.accepted_ns = entry->accepted_ns;
  if (auto s = journal_.accept(j); !s) {
    reject(request, {s.error().message});
    return;
  }
  log::info("task", "job accepted",
            {{"job", job_id},
             {"kind", std::string(task::to_string(entry->spec.kind))},
             {"robot", entry->spec.robot}});
  ctx_.events().publish(cell_health_SEVERITY_INFO, "job.accepted",
                        fmt::format("job '{}' ({}) accepted for robot '{}'", job_id,
                                    task::to_string(entry->spec.kind), entry->spec.robot),
                        entry->spec.robot, job_id);
  {
    std::lock_guard lock(mutex_);
    publish(*entry);
    jobs_[job_id] = std::move(entry);
  }
  work_.notify_all();
}

void TaskService::take_commands() {
  for (;;) {
    auto batch = command_reader_.take_copies(16);
    if (!batch || batch->empty()) {
      return;
    }
    for (const auto& c : *batch) {
      const std::string job_id(bus::str(c->job_id));
      std::string refusal;
      {
        std::lock_guard lock(mutex_);
        auto it = jobs_.find(job_id);
        if (it == jobs_.end()) {
          refusal = fmt::format("no job '{}' is known", job_id);
        } else {
          Entry& e = *it->second;
          if (final_state(e.state)) {
            refusal = fmt::format("job '{}' is {} already", job_id, state_name(e.state));
          } else {
            switch (bus::raw(c->kind)) {  // any value may come off the wire
              case cell_task_JOB_PAUSE:
                e.control.pause = true;
                if (e.state == cell_task_JOB_RUNNING || e.state == cell_task_JOB_QUEUED) {
                  e.state = cell_task_JOB_PAUSED;
                }
                (void)journal_.set_state(job_id, "paused");
                break;
              case cell_task_JOB_RESUME:
                if (!e.control.pause.load()) {
                  refusal = e.robot_pause
                                ? fmt::format("job '{}' waits for its robot: reset the robot",
                                              job_id)
                                : fmt::format("job '{}' is not paused", job_id);
                } else {
                  e.control.pause = false;
                  e.state = e.steps > 0 || e.step != "queued" ? cell_task_JOB_RUNNING
                                                              : cell_task_JOB_QUEUED;
                  (void)journal_.set_state(job_id, state_name(e.state));
                }
                break;
              case cell_task_JOB_CANCEL:
                e.control.cancel = true;
                if (e.state == cell_task_JOB_QUEUED ||
                    (e.state == cell_task_JOB_PAUSED && e.step == "queued")) {
                  e.state = cell_task_JOB_CANCELLED;
                  e.step = "cancelled before it started";
                  (void)journal_.set_state(job_id, "cancelled");
                  remember_finished(job_id);
                }
                break;
              case cell_task_JOB_CONFIRM:
              default:
                refusal = "no job of this service asks for a confirmation";
                break;
            }
            if (refusal.empty()) {
              publish(e);
            }
          }
        }
      }
      cell_task_JobCommandReply reply{};
      reply.request_id = c->request_id;
      reply.job_id = bus::borrow(job_id);
      reply.status.accepted = refusal.empty();
      const std::string code = refusal.empty() ? "" : "invalid_argument";
      reply.status.error_code = bus::borrow(code);
      reply.status.reason = bus::borrow(refusal);
      (void)command_reply_writer_.write(reply);
      log::info(
          "task", refusal.empty() ? "job command applied" : "job command refused",
          {{"job", job_id}, {"command", std::to_string(bus::raw(c->kind))}, {"reason", refusal}});
    }
  }
}

void TaskService::resume_from_journal() {
  auto unfinished = journal_.unfinished();
  if (!unfinished) {
    throw std::runtime_error(unfinished.error().message);
  }
  for (const JournalJob& j : *unfinished) {
    auto entry = std::make_unique<Entry>();
    entry->job_id = j.job_id;
    const json request = json::parse(j.request_json, nullptr, false);
    if (request.is_object()) {
      entry->client_id = request.value("client_id", std::string());
      entry->request_seq = request.value("seq", std::uint64_t{0});
      entry->priority = request.value("priority", 0);
      entry->operator_id = request.value("operator", std::string());
    }
    entry->spec_yaml = j.spec_yaml;
    entry->accepted_ns = j.accepted_ns;
    entry->steps = static_cast<std::uint32_t>(j.steps);
    entry->progress_json = json::parse(j.progress_json, nullptr, false);
    if (!entry->progress_json.is_object()) {
      entry->progress_json = json::object();
    }
    auto spec = task::parse_job_spec(j.spec_yaml, fmt::format("<job {}>", j.job_id),
                                     [this](std::string_view id) { return robot(id); });
    // A job that cannot be resumed is failed with the reasons; the other jobs go on.
    const auto set_aside = [&](std::vector<std::string> reasons) {
      entry->state = cell_task_JOB_FAILED;
      entry->reasons = std::move(reasons);
      (void)journal_.set_state(j.job_id, "failed");
      std::lock_guard lock(mutex_);
      publish(*entry);
      jobs_[j.job_id] = std::move(entry);
      remember_finished(j.job_id);
    };
    if (!spec) {
      set_aside(split_lines("the journaled spec no longer parses: " + spec.error().message));
      continue;
    }
    entry->spec = std::move(*spec);
    // Parts and counters travel in the progress (job_run.cpp): not resumed blind.
    if (auto read = read_progress(entry->progress_json, entry->parts, entry->counters); !read) {
      log::warn("task", "journaled job set aside: its progress could not be read",
                {{"job", j.job_id}, {"reason", read.error().message}});
      set_aside({"the journaled progress could not be read: " + read.error().message});
      continue;
    }
    entry->state = state_from(j.state);
    entry->step = entry->steps > 0 ? "resuming after a restart" : "queued";
    if (entry->state == cell_task_JOB_PAUSED) {
      entry->control.pause = true;
    }
    log::info("task", "job resumed from the journal",
              {{"job", j.job_id}, {"state", j.state}, {"steps", std::to_string(j.steps)}});
    std::lock_guard lock(mutex_);
    publish(*entry);
    jobs_[j.job_id] = std::move(entry);
  }
  // The history: the last finished jobs, so that a late client sees them.
  auto recent = journal_.recent(config_.keep_finished);
  if (recent) {
    std::lock_guard lock(mutex_);
    for (auto it = recent->rbegin(); it != recent->rend(); ++it) {
      if (jobs_.count(it->job_id) != 0) {
        continue;
      }
      const cell_task_JobState st = state_from(it->state);
      if (!final_state(st)) {
        continue;
      }
      auto entry = std::make_unique<Entry>();
      entry->job_id = it->job_id;
      entry->state = st;
      entry->step = it->state;
      entry->spec_yaml = it->spec_yaml;
      entry->accepted_ns = it->accepted_ns;
      entry->steps = static_cast<std::uint32_t>(it->steps);
      if (auto spec = task::parse_job_spec(it->spec_yaml, it->job_id,
                                           [this](std::string_view id) { return robot(id); });
          spec) {
        entry->spec = std::move(*spec);
      }
      // Its parts and counters, from the progress of its last step. (A range-for over
      // `progress.value("_counters", ...).items()` read a destroyed temporary here, and a
      // finished conveyor job made every later start crash.) A finished job whose progress
      // cannot be read is still listed, with the reason instead of its parts.
      const json progress = json::parse(it->progress_json, nullptr, false);
      if (auto read = read_progress(progress, entry->parts, entry->counters); !read) {
        entry->reasons.push_back("its journaled parts and counters could not be read: " +
                                 read.error().message);
        log::warn("task", "finished job listed without its parts: its progress could not be read",
                  {{"job", it->job_id}, {"reason", read.error().message}});
      }
      publish(*entry);
      jobs_[it->job_id] = std::move(entry);
      finished_.push_back(it->job_id);
    }
  }
}

TaskService::Entry* TaskService::next_job(const std::string& robot_id) {
  Entry* best = nullptr;
  for (auto& [id, e] : jobs_) {
    if (e->spec.robot != robot_id || final_state(e->state)) {
      continue;
    }
    const bool resumable = e->steps > 0 || e->state == cell_task_JOB_RUNNING;
    if (e->control.pause.load() && !resumable) {
      continue;  // paused before it started: leave it queued
    }
    if (best == nullptr) {
      best = e.get();
      continue;
    }
    // Started jobs first (they hold the robot's state), then priority, then age.
    const bool best_started = best->steps > 0;
    const bool started = e->steps > 0;
    if (started != best_started) {
      if (started) {
        best = e.get();
      }
      continue;
    }
    if (e->priority != best->priority) {
      if (e->priority > best->priority) {
        best = e.get();
      }
      continue;
    }
    if (e->accepted_ns < best->accepted_ns) {
      best = e.get();
    }
  }
  return best;
}

void TaskService::worker_loop(Worker& worker) {
  const kinematics::RobotModel& model = *robot(worker.robot_id);
  for (;;) {
    Entry* entry = nullptr;
    {
      std::unique_lock lock(mutex_);
      work_.wait_for(lock, 200ms);
      if (stopping_) {
        return;
      }
      entry = next_job(worker.robot_id);
      if (entry == nullptr) {
        continue;
      }
      if (!entry->control.pause.load()) {
        entry->state = cell_task_JOB_RUNNING;
      }
      entry->step = entry->steps > 0 ? "resuming" : "starting";
      (void)journal_.set_state(entry->job_id, state_name(entry->state));
      publish(*entry);
    }
    log::info("task", "job started", {{"job", entry->job_id}, {"robot", worker.robot_id}});
    JobRun::Hooks hooks;
    hooks.journal = [this, entry](const std::string& name, const json& detail,
                                  const json& progress) -> Status {
      CELL_TRY(journal_.step(entry->job_id, "running", name, detail.dump(), progress.dump()));
      std::lock_guard lock(mutex_);
      entry->progress_json = progress;
      ++entry->steps;
      return ok_status();
    };
    hooks.publish = [this, entry](const JobRun& run) {
      std::lock_guard lock(mutex_);
      entry->step = run.paused() ? run.pause_reason() : run.step_text();
      entry->progress = run.fraction();
      entry->parts = run.parts();
      entry->counters = run.counters();
      entry->robot_pause = run.paused() && !entry->control.pause.load();
      if (!final_state(entry->state)) {
        entry->state = run.paused() ? cell_task_JOB_PAUSED : cell_task_JOB_RUNNING;
      }
      publish(*entry);
    };
    JobRun run(entry->job_id, entry->spec, model, config_, catalogue_, *worker.links,
               entry->control, entry->progress_json, hooks);
    ExecResult result;
    try {
      switch (entry->spec.kind) {
        case task::JobKind::kTablePickPlace:
          result = run_table_job(run);
          break;
        case task::JobKind::kConveyorPick:
          result = run_conveyor_job(run);
          break;
        case task::JobKind::kAssembly:
          result = run_assembly_job(run);
          break;
      }
    } catch (const std::exception& e) {
      // A bug, not an input: fail the job with the reason rather than the service.
      result = ExecResult::failed(fmt::format("internal error: {}", e.what()));
    }
    std::lock_guard lock(mutex_);
    entry->parts = run.parts();
    entry->counters = run.counters();
    finish(*entry, result);
    if (result.kind == ExecResult::Kind::kStopped) {
      return;
    }
  }
}

void TaskService::finish(Entry& e, const ExecResult& result) {
  switch (result.kind) {
    case ExecResult::Kind::kDone:
      e.state = cell_task_JOB_SUCCEEDED;
      e.step = "done";
      e.progress = 1.0;
      break;
    case ExecResult::Kind::kFailed:
      e.state = cell_task_JOB_FAILED;
      e.step = "failed";
      e.reasons.push_back(result.reason);
      break;
    case ExecResult::Kind::kCancelled:
      e.state = cell_task_JOB_CANCELLED;
      e.step = "cancelled";
      break;
    case ExecResult::Kind::kStopped:
      // Left running in the journal: the next start resumes it.
      log::info("task", "job interrupted by the service stop; it resumes at the next start",
                {{"job", e.job_id}});
      return;
  }
  (void)journal_.set_state(e.job_id, state_name(e.state));
  log::info("task", "job finished",
            {{"job", e.job_id}, {"state", state_name(e.state)}, {"reason", result.reason}});
  ctx_.events().publish(
      e.state == cell_task_JOB_SUCCEEDED ? cell_health_SEVERITY_INFO
                                          : cell_health_SEVERITY_WARNING,
      "job." + state_name(e.state),
      fmt::format("job '{}' {}{}", e.job_id, state_name(e.state),
                  result.reason.empty() ? "" : ": " + result.reason),
      e.spec.robot, e.job_id);
  publish(e);
  remember_finished(e.job_id);
}

void TaskService::remember_finished(const std::string& job_id) {
  finished_.push_back(job_id);
  while (finished_.size() > static_cast<std::size_t>(config_.keep_finished)) {
    const std::string old = finished_.front();
    finished_.pop_front();
    auto it = jobs_.find(old);
    if (it == jobs_.end()) {
      continue;
    }
    cell_task_JobStatus key{};
    key.job_id = bus::borrow(old);
    (void)status_writer_.unregister(key);
    jobs_.erase(it);
  }
}

void TaskService::publish_running() {
  std::lock_guard lock(mutex_);
  for (auto& [id, e] : jobs_) {
    if (e->state == cell_task_JOB_RUNNING) {
      e->elapsed_s += config_.status_period_s;
      publish(*e);
    }
  }
}

void TaskService::publish(const Entry& e) {
  StatusWire w;
  w.job_id = e.job_id;
  w.client_id = e.client_id;
  w.step = e.step;
  w.robot = e.spec.robot;
  w.name = e.spec.name;
  w.frame = e.spec.robot + "/base";
  w.reason_text = e.reasons;
  for (auto& r : w.reason_text) {
    w.reasons.push_back(bus::borrow(r));
  }
  w.part_text.reserve(e.parts.size() * 2);
  std::uint32_t done = 0;
  std::uint32_t failed = 0;
  for (const PartRecord& p : e.parts) {
    w.part_text.push_back(p.class_name);
    w.part_text.push_back(p.detail);
  }
  for (std::size_t i = 0; i < e.parts.size(); ++i) {
    const PartRecord& p = e.parts[i];
    cell_task_PartResult r{};
    r.index = p.index;
    r.class_name = bus::borrow(w.part_text[2 * i]);
    r.picked_at = {p.picked_x_mm, p.picked_y_mm, p.picked_yaw_rad};
    r.placed_at = {p.placed_x_mm, p.placed_y_mm, p.placed_yaw_rad};
    r.outcome = p.outcome;
    r.detail = bus::borrow(w.part_text[2 * i + 1]);
    w.parts.push_back(r);
    if (p.outcome == cell_task_PART_PLACED) {
      ++done;
    } else if (p.outcome != cell_task_PART_PENDING) {
      ++failed;
    }
  }
  for (const auto& [name, value] : e.counters) {
    w.counter_names.push_back(name);
  }
  std::size_t k = 0;
  for (const auto& [name, value] : e.counters) {
    w.counters.push_back(cell_task_JobCounter{bus::borrow(w.counter_names[k++]), value});
  }
  cell_task_JobStatus s{};
  s.job_id = bus::borrow(w.job_id);
  s.request_id.client_id = bus::borrow(w.client_id);
  s.request_id.seq = e.request_seq;
  s.header.stamp_ns = wall_time_ns();
  s.header.frame_id = bus::borrow(w.frame);
  s.kind = idl_kind(e.spec.kind);
  s.state = e.state;
  s.progress = e.progress;
  s.step = bus::borrow(w.step);
  s.reasons._buffer = w.reasons.data();
  s.reasons._length = static_cast<std::uint32_t>(w.reasons.size());
  s.reasons._maximum = s.reasons._length;
  s.reasons._release = false;
  bus::borrow(s.parts, w.parts);
  s.parts_done = done;
  s.parts_failed = failed;
  s.robot_id = bus::borrow(w.robot);
  s.name = bus::borrow(w.name);
  bus::borrow(s.counters, w.counters);
  s.elapsed_s = e.elapsed_s;
  s.accepted_stamp_ns = e.accepted_ns;
  s.step_index = e.steps;
  (void)status_writer_.write(s);
}

}  // namespace cell::task_service
