#pragma once

#include <condition_variable>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "cell/bus/reader.hpp"
#include "cell/bus/topic.hpp"
#include "cell/bus/writer.hpp"
#include "cell/kinematics/robot_model.hpp"
#include "cell/service/runtime.hpp"
#include "cell/task/job_spec.hpp"
#include "cell/world/part_class.hpp"
#include "job_run.hpp"
#include "journal.hpp"
#include "links.hpp"
#include "task_config.hpp"

namespace cell::task_service {

/// The task service: accepts jobs from remote clients, runs them one at a time per robot, and
/// reports them. Every JobRequest is answered on cell/task/job_status (queued with the job id,
/// or rejected with every reason); every JobCommand on cell/task/job_command_reply. Accepted
/// jobs and completed steps are journaled (journal.hpp) before they are acknowledged; a
/// restarted service resumes every unfinished job from its last step.
///
/// Threads: the service thread (intake, commands, periodic status) and one worker per robot
/// (its own bus links, its executor). Job entries are shared under `mutex_`; a job's Control
/// flags are atomics the service sets and the worker polls.
///
/// Topics: in cell/task/job_request, cell/task/job_command (command); out cell/task/job_status
/// (state, keyed by job_id), cell/task/job_command_reply (recent), cell/health/event; through
/// the workers' links (links.hpp) the motion, vision, robot and belt topics.
class TaskService {
 public:
  TaskService(service::Context& ctx, const TaskConfig& config);
  ~TaskService();
  TaskService(const TaskService&) = delete;
  TaskService& operator=(const TaskService&) = delete;

  void run(service::Context& ctx);

 private:
  struct Entry {
    std::string job_id;
    std::string client_id;  ///< of the request (JobStatus.request_id echoes it)
    std::uint64_t request_seq = 0;
    std::int32_t priority = 0;
    std::string operator_id;
    std::string spec_yaml;
    task::JobSpec spec;
    cell_task_JobState state = cell_task_JOB_QUEUED;
    std::vector<std::string> reasons;
    std::string step = "queued";
    double progress = 0.0;
    std::vector<PartRecord> parts;
    std::map<std::string, std::uint32_t> counters;
    nlohmann::json progress_json = nlohmann::json::object();
    std::int64_t accepted_ns = 0;
    std::uint32_t steps = 0;
    double elapsed_s = 0.0;
    Control control;
    bool robot_pause = false;  ///< paused because the robot faulted (not by an operator)
  };

  struct Worker {
    std::string robot_id;
    std::unique_ptr<Links> links;
    std::thread thread;
  };

  const kinematics::RobotModel* robot(std::string_view id) const;
  task::CellFacts facts() const;
  void take_requests();
  void take_commands();
  void handle_request(const cell_task_JobRequest& request);
  void reject(const cell_task_JobRequest& request, const std::vector<std::string>& reasons,
              bool duplicate = false);
  void resume_from_journal();
  void worker_loop(Worker& worker);
  Entry* next_job(const std::string& robot_id);
  void finish(Entry& entry, const ExecResult& result);
  void publish(const Entry& entry);  ///< caller holds mutex_
  void publish_running();
  void remember_finished(const std::string& job_id);

  service::Context& ctx_;
  TaskConfig config_;
  std::map<std::string, kinematics::RobotModel, std::less<>> robots_;
  world::Catalogue catalogue_;
  Journal journal_;

  bus::Topic<cell_task_JobRequest> request_topic_;
  bus::Topic<cell_task_JobCommand> command_topic_;
  bus::Topic<cell_task_JobStatus> status_topic_;
  bus::Topic<cell_task_JobCommandReply> command_reply_topic_;
  bus::Reader<cell_task_JobRequest> request_reader_;
  bus::Reader<cell_task_JobCommand> command_reader_;
  bus::Writer<cell_task_JobStatus> status_writer_;
  bus::Writer<cell_task_JobCommandReply> command_reply_writer_;

  mutable std::mutex mutex_;  ///< guards jobs_, finished_ and the status writer's use
  std::condition_variable work_;
  std::map<std::string, std::unique_ptr<Entry>, std::less<>> jobs_;
  std::deque<std::string> finished_;
  std::deque<std::string> rejected_;  ///< keys of refusals still on the status topic
  std::atomic<bool> stopping_{false};
  std::vector<std::unique_ptr<Worker>> workers_;
};

}  // namespace cell::task_service
