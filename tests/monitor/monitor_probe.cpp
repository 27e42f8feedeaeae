// monitor_probe: the bus's side of the browser test and the monitor benchmark's native peer.
// Takes every RobotState of the robots named on the command line and, when stdin closes,
// prints each as one JSON line on stdout (robot, seq, stamp_ns, received_ns, q [rad | mm],
// base_T_tool as a row-major 4x4). Nothing is written while it records (a pipe that fills up
// would stall the reader and falsify received_ns), except `{"ready": true}` once the reader
// exists and `{"first": ...}` at the first sample. The browser test compares what the page
// rendered with these samples.
//   monitor_probe ROBOT...        (bus from CELL_DOMAIN_ID, CELL_PARTITION, CYCLONEDDS_URI)
#include <poll.h>
#include <unistd.h>

#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <set>
#include <string>

#include <fmt/format.h>

#include "cell/bus/participant.hpp"
#include "cell/bus/reader.hpp"
#include "cell/bus/topic.hpp"
#include "cell/bus/topics.hpp"
#include "cell/bus/view.hpp"
#include "cell/common/time.hpp"
#include "cell/geometry/idl_pose.hpp"

int main(int argc, char** argv) {
  using namespace cell;
  std::set<std::string> robots(argv + 1, argv + argc);
  if (robots.empty()) {
    std::fprintf(stderr, "usage: monitor_probe ROBOT...\n");
    return 2;
  }
  std::signal(SIGPIPE, SIG_IGN);
  const char* domain = std::getenv("CELL_DOMAIN_ID");
  const char* partition = std::getenv("CELL_PARTITION");
  try {
    bus::Participant participant(domain != nullptr ? static_cast<std::uint32_t>(std::atoi(domain)) : 0,
                                 partition != nullptr ? partition : "cell");
    bus::Topic<cell_robot_RobotState> topic(participant, bus::topics::kRobotState);
    bus::Reader<cell_robot_RobotState> states(participant, topic, bus::topics::kRobotState);
    std::fprintf(stdout, "{\"ready\": true}\n");
    std::fflush(stdout);
    std::string out;
    out.reserve(16 << 20);
    bool first = true;
    for (;;) {
      pollfd in{STDIN_FILENO, POLLIN, 0};
      if (::poll(&in, 1, 0) > 0) {
        char c = 0;
        if (::read(STDIN_FILENO, &c, 1) <= 0) {
          // The test closed our stdin: everything recorded, then done.
          return std::fwrite(out.data(), 1, out.size(), stdout) == out.size() ? 0 : 1;
        }
      }
      (void)states.wait_for_data(std::chrono::milliseconds(100));
      const std::int64_t now = wall_time_ns();
      (void)states.take_each([&](const cell_robot_RobotState& s, const dds_sample_info_t&) {
        const std::string id(bus::str(s.robot_id));
        if (robots.count(id) == 0) {
          return;
        }
        std::string q;
        for (const double v : bus::span(s.position_rad_or_mm)) {
          q += fmt::format("{}{:.17g}", q.empty() ? "" : ",", v);
        }
        std::string m;
        if (auto pose = geometry::pose_from_idl(s.base_T_tool)) {
          for (int r = 0; r < 4; ++r) {
            for (int c = 0; c < 4; ++c) {
              m += fmt::format("{}{:.17g}", m.empty() ? "" : ",", pose->matrix()(r, c));
            }
          }
        }
        out += fmt::format(
            "{{\"robot\":\"{}\",\"seq\":{},\"stamp_ns\":{},\"received_ns\":{},\"moving\":{},"
            "\"q\":[{}],\"base_T_tool\":[{}]}}\n",
            id, s.header.seq, s.header.stamp_ns, now, s.moving ? "true" : "false", q, m);
      });
      if (first && !out.empty()) {
        first = false;
        std::fprintf(stdout, "{\"first\": true}\n");
        std::fflush(stdout);
      }
    }
  } catch (const bus::BusError& e) {
    std::fprintf(stderr, "monitor_probe: %s\n", e.what());
    return 3;
  }
}
