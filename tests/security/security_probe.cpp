// security_probe: one DDS participant of the security test (security_cell_test.cpp), run as its
// own process because Cyclone reads CYCLONEDDS_URI (and with it the identity) once per process
// and domain. Bus: CELL_DOMAIN_ID, CELL_PARTITION, CYCLONEDDS_URI from the environment.
//
//   security_probe listen --seconds S          heartbeats and job statuses it can read in S s
//   security_probe submit --job-id ID --seconds S   a table JobRequest, waits for the answer
//
// Prints one JSON object on stdout. Exit: 0 done; 3 participant creation failed (BusError);
// 4 a writer or reader was refused (BusError, DDS_RETCODE_NOT_ALLOWED_BY_SECURITY = -13 when
// access control denies it); 5 no answer in time; 2 usage.
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <iostream>
#include <set>
#include <string>
#include <thread>

#include <nlohmann/json.hpp>

#include "cell/bus/participant.hpp"
#include "cell/bus/reader.hpp"
#include "cell/bus/request_reply.hpp"
#include "cell/bus/topic.hpp"
#include "cell/bus/topics.hpp"
#include "cell/bus/view.hpp"
#include "cell/bus/writer.hpp"

namespace {

using json = nlohmann::json;
using namespace std::chrono_literals;
namespace bus = cell::bus;

constexpr int kExitUsage = 2;
constexpr int kExitParticipant = 3;
constexpr int kExitRefused = 4;
constexpr int kExitNoAnswer = 5;

int print(const json& doc, int code) {
  std::cout << doc.dump() << std::endl;
  return code;
}

std::string env_or(const char* key, const std::string& fallback) {
  const char* value = std::getenv(key);
  return value != nullptr && *value != '\0' ? value : fallback;
}

int listen(const bus::Participant& participant, std::chrono::milliseconds duration) {
  json doc{{"participant", "created"}};
  std::set<std::string> from;
  std::size_t heartbeats = 0;
  std::size_t statuses = 0;
  std::set<std::string> jobs;
  try {
    bus::Topic<cell_health_ServiceHeartbeat> hb_topic(participant, bus::topics::kHeartbeat);
    bus::Reader<cell_health_ServiceHeartbeat> hb(participant, hb_topic, bus::topics::kHeartbeat);
    bus::Topic<cell_task_JobStatus> js_topic(participant, bus::topics::kJobStatus);
    bus::Reader<cell_task_JobStatus> js(participant, js_topic, bus::topics::kJobStatus);
    const auto deadline = std::chrono::steady_clock::now() + duration;
    while (std::chrono::steady_clock::now() < deadline) {
      (void)hb.take_each([&](const cell_health_ServiceHeartbeat& s, const dds_sample_info_t&) {
        ++heartbeats;
        from.insert(std::string(bus::str(s.service_id)));
      });
      (void)js.take_each([&](const cell_task_JobStatus& s, const dds_sample_info_t&) {
        ++statuses;
        jobs.insert(std::string(bus::str(s.job_id)));
      });
      std::this_thread::sleep_for(50ms);
    }
  } catch (const bus::BusError& e) {
    doc["reader"] = "refused";
    doc["code"] = e.code();
    doc["error"] = e.what();
    return print(doc, kExitRefused);
  }
  doc["heartbeats"] = heartbeats;
  doc["heartbeat_from"] = from;
  doc["job_status"] = statuses;
  doc["jobs"] = jobs;
  return print(doc, 0);
}

int submit(const bus::Participant& participant, const std::string& job_id,
           std::chrono::milliseconds timeout) {
  json doc{{"participant", "created"}, {"job_id", job_id}};
  try {
    bus::Requester<cell_task_JobRequest, cell_task_JobStatus> requester(
        participant, bus::topics::kJobRequest, bus::topics::kJobStatus,
        bus::make_client_id("security_probe"));
    doc["writer"] = "created";
    // A table job on the 7545 (config/jobs/table_ics.yaml's kind): the test runs no gateway, so
    // the task service may refuse or fail it; what counts is that its answer comes back.
    const std::string spec = "kind: table_pick_place\nrobot: ibm7545\ncamera: ibm7545_eye\n";
    const std::string robot = "ibm7545";
    const std::string camera = "ibm7545_eye";
    const std::string program = "security_probe";
    const std::string operator_id = env_or("USER", "probe");
    cell_task_JobRequest request{};
    request.job_id = bus::borrow(job_id);
    request.kind = cell_task_JOB_TABLE_PICK_PLACE;
    request.robot_id = bus::borrow(robot);
    request.camera_id = bus::borrow(camera);
    request.spec_yaml = bus::borrow(spec);
    request.program_name = bus::borrow(program);
    request.operator_id = bus::borrow(operator_id);
    auto reply = requester.call(request, timeout);
    if (!reply) {
      doc["answer"] = "none";
      doc["error"] = reply.error().message;
      return print(doc, kExitNoAnswer);
    }
    const cell_task_JobStatus& status = reply->get();
    doc["answer"] = static_cast<int>(status.state);
    doc["answer_job_id"] = std::string(bus::str(status.job_id));
    json reasons = json::array();
    for (const char* r : bus::span(status.reasons)) {
      reasons.push_back(std::string(bus::str(r)));
    }
    doc["reasons"] = reasons;
    doc["rejected"] = status.state == cell_task_JOB_REJECTED;
  } catch (const bus::BusError& e) {
    doc["writer"] = "refused";
    doc["code"] = e.code();
    doc["error"] = e.what();
    return print(doc, kExitRefused);
  }
  return print(doc, 0);
}

}  // namespace

static int main_body(int argc, char** argv) {
  if (argc < 2) {
    std::cerr << "usage: security_probe listen|submit [--seconds S] [--job-id ID]\n";
    return kExitUsage;
  }
  const std::string mode = argv[1];
  double seconds = 4.0;
  std::string job_id = "security-probe-job";
  for (int i = 2; i + 1 < argc; i += 2) {
    const std::string key = argv[i];
    if (key == "--seconds") {
      seconds = std::atof(argv[i + 1]);
    } else if (key == "--job-id") {
      job_id = argv[i + 1];
    } else {
      std::cerr << "security_probe: unknown option '" << key << "'\n";
      return kExitUsage;
    }
  }
  if (mode != "listen" && mode != "submit") {
    std::cerr << "security_probe: unknown mode '" << mode << "' (listen or submit)\n";
    return kExitUsage;
  }
  const auto duration = std::chrono::milliseconds(static_cast<long>(seconds * 1000.0));
  const auto domain = static_cast<std::uint32_t>(std::atoi(env_or("CELL_DOMAIN_ID", "0").c_str()));
  const std::string partition = env_or("CELL_PARTITION", "cell");
  try {
    bus::Participant participant(domain, partition);
    return mode == "listen" ? listen(participant, duration) : submit(participant, job_id, duration);
  } catch (const bus::BusError& e) {
    return print(json{{"participant", "failed"},
                      {"code", e.code()},
                      {"error", e.what()},
                      {"hint",
                       "with DDS Security: the identity certificate, its key, the governance or "
                       "the permissions named in CYCLONEDDS_URI failed to load or verify "
                       "(Cyclone logs the reason on stderr)"},
                      {"cyclonedds_uri", env_or("CYCLONEDDS_URI", "")}},
                 kExitParticipant);
  }
}

// Nothing escapes main: an exception is printed and fails the run.
int main(int argc, char** argv) {
  try {
    return main_body(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "security_probe: %s\n", e.what());
  } catch (...) {
    std::fprintf(stderr, "security_probe: an exception not derived from std::exception\n");
  }
  return 1;
}
