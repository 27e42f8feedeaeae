// cell-flood: publishes malformed samples on every topic a service of the cell reads, at a
// high rate, for a given duration, from a seeded random generator (issue 11, bad input).
//
//   cell-flood [--seconds S] [--seed N] [--rate-scale X] [--json FILE]
//              [--domain N] [--partition P]
//
// The bus is --domain/--partition, else CELL_DOMAIN_ID/CELL_PARTITION, else 0 / "cell".
// Every sample addressed to a real robot, camera, belt or job carries at least one value that
// must be refused (NaN, Inf, 1e300, a wrong vector length, an out-of-range enum written as an
// integer straight into the C field), so a correct cell answers or drops each one without
// moving a robot. Huge (1 MiB) strings go out at about one per second per topic.
//
// Four threads per topic, each with its own writer, each paced to its share of the target rate
// in 5 ms slices. Writers keep the topic's QoS but block at most 5 ms when their history is
// full of unacknowledged data (RELIABLE + KEEP_ALL): such a write is counted as `throttled`,
// not retried. Cyclone's own serializer refuses a sample whose enum field is outside the enum
// (BAD_PARAMETER, counted as `refused`): out-of-range enums cannot leave a Cyclone writer, so
// they are kept rare. At the end a table of the achieved rate per topic goes to stdout and,
// with --json, the same as JSON to FILE.
//
// Exit codes: 0 ok, 2 usage, 3 DDS setup failed.
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>
#include <memory>
#include <mutex>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include <fmt/format.h>

#include "cell/bus/participant.hpp"
#include "cell/bus/topic.hpp"
#include "cell/bus/topics.hpp"
#include "cell/bus/view.hpp"
#include "cell/bus/writer.hpp"
#include "cell/common/log.hpp"

namespace cell::flood {
namespace {

using Clock = std::chrono::steady_clock;
using Rng = std::mt19937_64;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

/// Writes an integer into an idlc enum field as it would arrive off the wire from a foreign
/// writer: no C++ conversion, so values outside the enumerators really land in the field.
template <typename E>
void set_enum(E& field, std::int32_t value) {
  static_assert(sizeof(E) == sizeof(std::int32_t), "idlc enums are 32-bit");
  std::memcpy(&field, &value, sizeof value);
}

/// Random helpers over one generator (each thread owns its own).
struct Gen {
  explicit Gen(std::uint64_t seed) : rng(seed) {}
  Rng rng;

  std::uint64_t u64() { return rng(); }
  std::size_t below(std::size_t n) { return n == 0 ? 0 : static_cast<std::size_t>(rng() % n); }
  bool chance(double p) { return std::uniform_real_distribution<double>(0, 1)(rng) < p; }
  double uniform(double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(rng); }
  template <typename T>
  const T& pick(const std::vector<T>& v) { return v[below(v.size())]; }

  /// A value that no limit admits: NaN, +-Inf, +-1e300, or the largest doubles.
  double poison() {
    static const std::vector<double> k{kNaN,    kInf,   -kInf, 1e300, -1e300,
                                       std::numeric_limits<double>::max(), -1e30, 1e30, 4e12};
    return pick(k);
  }
  /// Sometimes sane, sometimes poison.
  double maybe(double sane, double p_poison = 0.5) { return chance(p_poison) ? poison() : sane; }
  /// An enum field's value: one of the n enumerators, or (with probability kBadEnum) an
  /// integer outside them. Cyclone's serializer refuses the latter (write returns BAD_PARAMETER,
  /// counted as `refused`), so they are kept rare to leave the rate to samples that arrive.
  std::int32_t enum_value(std::int32_t n) {
    if (!chance(kBadEnum)) {
      return static_cast<std::int32_t>(below(static_cast<std::size_t>(n)));
    }
    return out_of_range(n);
  }
  /// One of `safe`, or (rarely) an integer outside the enum of n enumerators.
  std::int32_t enum_from(const std::vector<std::int32_t>& safe, std::int32_t n) {
    return chance(kBadEnum) ? out_of_range(n) : pick(safe);
  }
  std::int32_t out_of_range(std::int32_t n) {
    static const std::vector<std::int32_t> k{-1, -2147483647 - 1, 2147483647, 1000, 255, 256};
    return chance(0.5) ? pick(k) : n + static_cast<std::int32_t>(below(50));
  }
  static constexpr double kBadEnum = 0.08;
  /// Random bytes 1..255 (a DDS string cannot hold NUL), `n` long.
  std::string bytes(std::size_t n) {
    std::string s(n, 'x');
    for (auto& c : s) {
      c = static_cast<char>(1 + below(255));
    }
    return s;
  }
};

/// The 1 MiB string (printable garbage with some invalid UTF-8), built once, shared read-only.
const std::string& huge_string() {
  static const std::string s = [] {
    Gen g(42);
    std::string out(1 << 20, 'A');
    for (std::size_t i = 0; i < out.size(); ++i) {
      out[i] = (i % 97 == 0) ? static_cast<char>(0xC0 + g.below(0x3F))
                             : static_cast<char>(' ' + g.below(95));
    }
    return out;
  }();
  return s;
}

const std::vector<std::string> kRobots{"ibm7545", "scara_picker", "excalibur"};
const std::vector<std::string> kCameras{"ibm7545_eye", "belt_cam"};
const std::vector<std::string> kServices{
    "sim-7545", "gateway.ibm7545", "gateway.picker", "sim-excalibur", "gateway.excalibur",
    "motion",      "sim-world",       "camera.ibm7545_eye", "camera.belt_cam", "vision",
    "calibration", "task",            "echo",           "monitor"};

/// Strings that have broken parsers before: empty, blanks, control characters, format
/// specifiers, paths, invalid UTF-8, long ones.
std::string garbage_string(Gen& g) {
  static const std::vector<std::string> k{"",
                                          " ",
                                          "\t\n\r",
                                          "%s%s%s%n%x",
                                          "{}{}{0}{:>999999}",
                                          "../../../../etc/passwd",
                                          "/dev/zero",
                                          "\xff\xfe\xfd",
                                          "\xc3\x28",
                                          "robot\nlvl=error svc=forged",
                                          "ibm7545 ",
                                          " IBM7545",
                                          "ibm7545\x01",
                                          "null",
                                          "~",
                                          "-1",
                                          "NaN",
                                          "\"'`$(reboot)`",
                                          std::string(4096, 'Z'),
                                          std::string(70000, 'q')};
  if (g.chance(0.2)) {
    return g.bytes(1 + g.below(300));
  }
  return g.pick(k);
}

/// An id: usually unknown garbage, sometimes one of `valid`.
std::string some_id(Gen& g, const std::vector<std::string>& valid, double p_valid) {
  return g.chance(p_valid) ? g.pick(valid) : garbage_string(g);
}

/// YAML that must be refused as a job spec, world scene or anything else: syntax errors,
/// deep nesting, alias bombs, wrong types, out-of-range numbers, binary.
std::string garbage_yaml(Gen& g) {
  switch (g.below(12)) {
    case 0:
      return std::string(20000, '[');  // unterminated, deeply nested
    case 1:
      return std::string(5000, '[') + std::string(5000, ']');  // deep but closed
    case 2: {  // a billion laughs: 9 levels of 10 aliases
      std::string s = "a0: &a0 [lol]\n";
      for (int i = 1; i <= 9; ++i) {
        s += fmt::format("a{}: &a{} [", i, i);
        for (int j = 0; j < 10; ++j) {
          s += fmt::format("{}*a{}", j == 0 ? "" : ",", i - 1);
        }
        s += "]\n";
      }
      return s + "kind: table_pick_place\nrobot: ibm7545\nplaces: *a9\n";
    }
    case 3:
      return "kind: *undefined_alias\n";
    case 4:
      return "kind: table_pick_place\nrobot: ibm7545\ncount: 1e99999999\nspeed_scale: .nan\n";
    case 5:
      return "kind: conveyor_pick\nrobot: scara_picker\nbelt: belt1\ncount: -4294967297\n"
             "window_mm: [.inf, -.inf]\n";
    case 6:
      return "kind: assembly\nprogram: |\n  " + std::string(3000, '(') + "\n";
    case 7:
      return "? [a, b]\n: {c: d}\n--- \n...\n%YAML 9.9\n";
    case 8:
      return "kind: table_pick_place\nrobot: ibm7545\nkind: conveyor_pick\nkind: assembly\n";
    case 9:
      return g.bytes(1 + g.below(2000));
    case 10:
      return "- - - - - - - - - - - - - - - - - - - - -\n" + garbage_string(g);
    default:
      return "name: " + garbage_string(g) + "\nkind: " + garbage_string(g) +
             "\nrobot: " + garbage_string(g) + "\n";
  }
}

/// A knot or joint vector: wrong length or poisoned (always one of them when `must_poison`).
std::vector<double> bad_joints(Gen& g, bool must_poison) {
  std::size_t n = g.chance(0.3) ? g.pick(std::vector<std::size_t>{0, 1, 3, 5, 7, 64, 5000})
                                : (g.chance(0.5) ? 4 : 6);
  std::vector<double> v(n);
  for (auto& x : v) {
    x = g.uniform(-0.5, 0.5);
  }
  if (!v.empty() && (must_poison || g.chance(0.5))) {
    v[g.below(v.size())] = g.poison();
  } else if (v.empty() || n == 4 || n == 6) {
    v.push_back(kNaN);  // a 4- or 6-vector must not pass: make it wrong length and NaN
  }
  return v;
}

// ---- per-topic statistics and pacing --------------------------------------------------------

/// Threads (each with its own writer) per topic: a reliable writer blocks while its history
/// holds unacknowledged data, so several writers keep a topic flowing while one waits.
constexpr std::size_t kLanes = 4;

struct Stats {
  std::uint64_t written = 0;
  std::uint64_t throttled = 0;  // a reliable write timed out: a reader lagged (flow control)
  std::uint64_t refused = 0;    // Cyclone's serializer refused it (an enum outside its range)
  std::uint64_t failed = 0;
  std::uint64_t huge = 0;
  std::uint64_t bytes = 0;
  std::string first_error;
};

/// One topic's flood: a function that builds one sample and writes it, its rate and stats.
struct Flow {
  std::string topic;
  double rate_hz;
  /// Builds and writes one sample; `huge` asks for a 1 MiB string somewhere in it. Returns
  /// the write's status and adds the payload size it sent to `bytes`.
  std::function<Status(Gen&, bool huge, std::uint64_t& bytes, std::size_t lane)> send;
  std::vector<Stats> lanes;  ///< one per thread (kLanes)
  Stats stats;                                            ///< the lanes summed at the end
};

/// A topic and its writers (one per lane) kept alive for the whole flood.
template <bus::IdlType T>
struct Out {
  Out(const bus::Participant& p, const bus::TopicDef<T>& def) : topic(p, def) {
    const bus::Qos q = qos(def);
    for (std::size_t i = 0; i < kLanes; ++i) {
      writers.push_back(std::make_unique<bus::Writer<T>>(p, topic, q.get()));
    }
  }
  Status write(std::size_t lane, const T& sample) const { return writers[lane]->write(sample); }
  static bus::Qos qos(const bus::TopicDef<T>& def) {
    bus::Qos q = bus::make_qos(def);
    dds_reliability_kind_t kind{};
    dds_duration_t blocking = 0;
    if (dds_qget_reliability(q.get(), &kind, &blocking) && kind == DDS_RELIABILITY_RELIABLE) {
      dds_qset_reliability(q.get(), DDS_RELIABILITY_RELIABLE, DDS_MSECS(5));
    }
    return q;
  }
  bus::Topic<T> topic;
  std::vector<std::unique_ptr<bus::Writer<T>>> writers;
};

bool is_timeout(const Status& s) {
  return !s && s.error().message.find("Timeout") != std::string::npos;
}

bool is_refused(const Status& s) {
  return !s && s.error().message.find("Bad Parameter") != std::string::npos;
}

struct Options {
  double seconds = 30.0;
  std::uint64_t seed = 1;
  double rate_scale = 1.0;
  std::string json_path;
  std::uint32_t domain = 0;
  std::string partition = "cell";
};

int usage(const std::string& what) {
  std::fprintf(stderr,
               "cell-flood: %s\nusage: cell-flood [--seconds S] [--seed N] [--rate-scale X] "
               "[--json FILE] [--domain N] [--partition P]\n",
               what.c_str());
  return 2;
}

int run(int argc, char** argv) {
  log::init("flood");
  Options o;
  if (const char* d = std::getenv("CELL_DOMAIN_ID"); d != nullptr && *d != '\0') {
    o.domain = static_cast<std::uint32_t>(std::strtoul(d, nullptr, 10));
  }
  if (const char* p = std::getenv("CELL_PARTITION"); p != nullptr && *p != '\0') {
    o.partition = p;
  }
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (i + 1 >= argc) {
      return usage(fmt::format("option '{}' needs a value (or is unknown)", a));
    }
    const std::string v = argv[++i];
    char* end = nullptr;
    if (a == "--seconds") {
      o.seconds = std::strtod(v.c_str(), &end);
      if (*end != '\0' || !(o.seconds > 0) || o.seconds > 3600) {
        return usage(fmt::format("--seconds must be in (0, 3600], got '{}'", v));
      }
    } else if (a == "--seed") {
      o.seed = std::strtoull(v.c_str(), &end, 10);
      if (*end != '\0') {
        return usage(fmt::format("--seed must be an unsigned integer, got '{}'", v));
      }
    } else if (a == "--rate-scale") {
      o.rate_scale = std::strtod(v.c_str(), &end);
      if (*end != '\0' || !(o.rate_scale > 0) || o.rate_scale > 100) {
        return usage(fmt::format("--rate-scale must be in (0, 100], got '{}'", v));
      }
    } else if (a == "--json") {
      o.json_path = v;
    } else if (a == "--domain") {
      o.domain = static_cast<std::uint32_t>(std::strtoul(v.c_str(), &end, 10));
      if (*end != '\0' || o.domain > 230) {
        return usage(fmt::format("--domain must be 0..230, got '{}'", v));
      }
    } else if (a == "--partition") {
      o.partition = v;
    } else {
      return usage(fmt::format("unknown option '{}'", a));
    }
  }

  try {
    bus::Participant p(o.domain, o.partition);
    namespace t = bus::topics;
    Out<cell_task_JobRequest> job_request(p, t::kJobRequest);
    Out<cell_task_JobCommand> job_command(p, t::kJobCommand);
    Out<cell_robot_RobotCommand> robot_command(p, t::kRobotCommand);
    Out<cell_robot_RobotState> robot_state(p, t::kRobotState);
    Out<cell_motion_MotionRequest> motion_request(p, t::kMotionRequest);
    Out<cell_motion_Trajectory> trajectory(p, t::kTrajectory);
    Out<cell_motion_AlterCorrection> alter(p, t::kAlter);
    Out<cell_vision_Image> image(p, t::kImage);
    Out<cell_vision_EdgeRequest> edge_request(p, t::kEdgeRequest);
    Out<cell_vision_ImageRequest> image_request(p, t::kImageRequest);
    Out<cell_calibration_CalibrationRequest> calibration_request(p, t::kCalibrationRequest);
    Out<cell_calibration_CameraCalibration> camera_calibration(p, t::kCameraCalibration);
    Out<cell_world_WorldRequest> world_request(p, t::kWorldRequest);
    Out<cell_world_PhotocellEvent> photocell(p, t::kPhotocell);
    Out<cell_world_BeltState> belt_state(p, t::kBeltState);
    Out<cell_health_PingRequest> ping(p, t::kPingRequest);
    Out<cell_health_ServiceHeartbeat> heartbeat(p, t::kHeartbeat);

    const std::string client = fmt::format("flood@{}", static_cast<long>(::getpid()));
    auto request_id = [&client](Gen& g, std::string& storage, bool huge) {
      cell_common_RequestId id{};
      storage = huge ? huge_string() : (g.chance(0.7) ? client : garbage_string(g));
      id.client_id = bus::borrow(storage);
      id.seq = g.chance(0.2) ? 0 : g.u64();
      return id;
    };

    std::vector<Flow> flows;
    const double s = o.rate_scale;

    // task: job requests. Unknown kinds, empty and huge strings, garbage specs, bad robots.
    flows.push_back({t::kJobRequest.name, 400 * s, [&](Gen& g, bool huge, std::uint64_t& bytes, std::size_t lane) {
      std::string rid, job_id, robot, camera, belt, spec, program, op;
      cell_task_JobRequest r{};
      r.request_id = request_id(g, rid, false);
      job_id = g.chance(0.1) ? "" : fmt::format("flood-{}", g.u64());
      if (g.chance(0.05)) job_id = garbage_string(g);
      set_enum(r.kind, g.enum_value(4));
      robot = some_id(g, kRobots, 0.5);
      camera = some_id(g, kCameras, 0.5);
      belt = g.chance(0.5) ? "belt1" : garbage_string(g);
      spec = huge ? huge_string() : garbage_yaml(g);
      program = garbage_string(g);
      op = garbage_string(g);
      r.job_id = bus::borrow(job_id);
      r.robot_id = bus::borrow(robot);
      r.camera_id = bus::borrow(camera);
      r.belt_id = bus::borrow(belt);
      r.spec_yaml = bus::borrow(spec);
      r.program_name = bus::borrow(program);
      r.operator_id = bus::borrow(op);
      r.priority = static_cast<std::int32_t>(g.u64());
      bytes += spec.size() + robot.size() + job_id.size();
      return job_request.write(lane, r);
    }, {}});

    // task: job commands for unknown jobs, with out-of-range kinds.
    flows.push_back({t::kJobCommand.name, 400 * s, [&](Gen& g, bool huge, std::uint64_t& bytes, std::size_t lane) {
      std::string rid, job_id, op;
      cell_task_JobCommand c{};
      c.request_id = request_id(g, rid, false);
      job_id = huge ? huge_string() : (g.chance(0.5) ? fmt::format("unknown-{}", g.u64())
                                                     : garbage_string(g));
      op = garbage_string(g);
      c.job_id = bus::borrow(job_id);
      c.operator_id = bus::borrow(op);
      set_enum(c.kind, g.enum_value(4));
      bytes += job_id.size();
      return job_command.write(lane, c);
    }, {}});

    // gateways: commands for unknown robots (any kind) and for real robots only with a value
    // that must be refused (gains of the wrong length or non-finite, a NaN tolerance, a mode
    // or a kind outside the enum).
    flows.push_back({t::kRobotCommand.name, 500 * s, [&](Gen& g, bool huge, std::uint64_t& bytes, std::size_t lane) {
      std::string rid, robot, op;
      std::vector<double> kp, kv;
      cell_robot_RobotCommand c{};
      c.request_id = request_id(g, rid, huge);
      const bool real = g.chance(0.6);
      robot = real ? g.pick(kRobots) : garbage_string(g);
      op = garbage_string(g);
      c.robot_id = bus::borrow(robot);
      c.operator_id = bus::borrow(op);
      c.halogen_on = g.chance(0.5);
      c.fluorescent_on = g.chance(0.5);
      set_enum(c.mode, real ? g.enum_from({0}, 9) : g.enum_value(9));
      c.tolerance_rad = g.poison();
      kp = bad_joints(g, true);
      kv = bad_joints(g, true);
      bus::borrow(c.kp, kp);
      bus::borrow(c.kv, kv);
      if (real) {
        // CMD_SET_GAINS (7) with bad gains, CMD_SET_TOLERANCE (8) with a non-finite
        // tolerance, or (rarely) a kind outside the enum.
        set_enum(c.kind, g.enum_from({7, 8}, 10));
      } else {
        set_enum(c.kind, g.enum_value(10));
      }
      bytes += rid.size() + (kp.size() + kv.size()) * sizeof(double);
      return robot_command.write(lane, c);
    }, {}});

    // motion, sim-world, cameras: robot states from impostors (unknown robots; real robots
    // with vectors of the wrong length and non-finite values).
    flows.push_back({t::kRobotState.name, 600 * s, [&](Gen& g, bool huge, std::uint64_t& bytes, std::size_t lane) {
      std::string robot, frame, fault, traj;
      cell_robot_RobotState st{};
      robot = huge ? huge_string() : some_id(g, kRobots, 0.3);
      frame = garbage_string(g);
      fault = garbage_string(g);
      traj = garbage_string(g);
      st.robot_id = bus::borrow(robot);
      st.header.frame_id = bus::borrow(frame);
      st.header.stamp_ns = static_cast<std::int64_t>(g.u64());
      const auto q = bad_joints(g, true);
      const auto v = bad_joints(g, false);
      bus::borrow(st.position_rad_or_mm, q);
      bus::borrow(st.velocity_rad_or_mm_per_s, v);
      bus::borrow(st.setpoint_rad_or_mm, q);
      st.base_T_tool.position_mm = {g.poison(), g.poison(), g.poison()};
      st.base_T_tool.orientation = {0, 0, 0, 0};
      set_enum(st.gripper, g.enum_value(5));
      set_enum(st.mode, g.enum_value(9));
      st.fault_text = bus::borrow(fault);
      st.trajectory_id = bus::borrow(traj);
      st.trajectory_progress = g.poison();
      st.cycle_period_s = g.poison();
      bytes += robot.size() + q.size() * 16;
      return robot_state.write(lane, st);
    }, {}});

    // motion: requests with non-finite or absurd targets, wrong joint vectors, unknown robots,
    // kinds outside the enum. A request for a real robot always carries one refusable value.
    flows.push_back({t::kMotionRequest.name, 500 * s, [&](Gen& g, bool huge, std::uint64_t& bytes, std::size_t lane) {
      std::string rid, motion_id, robot, branch;
      cell_motion_MotionRequest m{};
      m.request_id = request_id(g, rid, false);
      motion_id = huge ? huge_string() : fmt::format("flood-{}", g.u64());
      robot = some_id(g, kRobots, 0.6);
      branch = g.chance(0.5) ? "" : garbage_string(g);
      m.motion_id = bus::borrow(motion_id);
      m.robot_id = bus::borrow(robot);
      m.branch = bus::borrow(branch);
      // Kinds 0..8 and 10 with poison; MOTION_STOP (9) is valid for a real robot: never sent.
      set_enum(m.kind, g.enum_from({0, 1, 2, 3, 4, 5, 6, 7, 8, 10}, 11));
      const auto joints = bad_joints(g, true);
      bus::borrow(m.joints_rad_or_mm, joints);
      const double px = g.poison();
      m.target.position_mm = {g.maybe(300), g.maybe(100), px};
      m.target.orientation = g.chance(0.5) ? cell_common_Quaternion{0, 0, 0, 0}
                                           : cell_common_Quaternion{kNaN, 0, 1, 0};
      std::vector<cell_common_Pose> via(g.chance(0.1) ? 20000 : g.below(5));
      for (auto& pose : via) {
        pose.position_mm = {g.poison(), g.maybe(0), g.maybe(0)};
        pose.orientation = {1, 0, 0, 0};
      }
      bus::borrow(m.via, via);
      m.distance_mm = g.poison();
      m.speed_scale = g.chance(0.5) ? g.poison() : -1.0;
      m.preview_only = g.chance(0.3);
      m.alter_cumulative = g.chance(0.5);
      m.alter_world_frame = g.chance(0.5);
      bytes += joints.size() * 8 + via.size() * sizeof(cell_common_Pose) + motion_id.size();
      return motion_request.write(lane, m);
    }, {}});

    // gateways: trajectories (normally only motion publishes them). For a real robot every
    // one is out of range somewhere: no knots, non-finite or 1e300 positions, wrong lengths.
    flows.push_back({t::kTrajectory.name, 400 * s, [&](Gen& g, bool huge, std::uint64_t& bytes, std::size_t lane) {
      std::string rid, robot, traj_id, motion_id, frame;
      cell_motion_Trajectory tr{};
      tr.request_id = request_id(g, rid, false);
      robot = some_id(g, kRobots, 0.6);
      traj_id = huge ? huge_string() : fmt::format("flood-{}", g.u64());
      motion_id = garbage_string(g);
      frame = garbage_string(g);
      tr.robot_id = bus::borrow(robot);
      tr.trajectory_id = bus::borrow(traj_id);
      tr.motion_id = bus::borrow(motion_id);
      tr.header.frame_id = bus::borrow(frame);
      const std::size_t n = g.chance(0.05) ? 20000 : g.below(40);
      std::vector<std::vector<double>> positions(n), velocities(n);
      std::vector<cell_motion_TrajectoryKnot> knots(n);
      double time_s = 0;
      for (std::size_t i = 0; i < n; ++i) {
        positions[i] = bad_joints(g, true);
        velocities[i] = bad_joints(g, false);
        time_s += g.chance(0.2) ? -1.0 : 0.01;
        knots[i].time_from_start_s = g.chance(0.1) ? g.poison() : time_s;
        bus::borrow(knots[i].position_rad_or_mm, positions[i]);
        bus::borrow(knots[i].velocity_rad_or_mm_per_s, velocities[i]);
      }
      bus::borrow(tr.knots, knots);
      std::vector<cell_motion_TrajectoryEvent> events(g.below(4));
      for (auto& e : events) {
        e.time_from_start_s = g.poison();
        set_enum(e.kind, g.enum_value(2));
        e.dwell_s = g.poison();
      }
      bus::borrow(tr.events, events);
      tr.alter_enabled = g.chance(0.5);
      tr.alter_cumulative = g.chance(0.5);
      tr.alter_world_frame = g.chance(0.5);
      bytes += n * 100 + traj_id.size();
      return trajectory.write(lane, tr);
    }, {}});

    // gateways: ALTER corrections with garbage (no trajectory of ours ever runs).
    flows.push_back({t::kAlter.name, 600 * s, [&](Gen& g, bool huge, std::uint64_t& bytes, std::size_t lane) {
      std::string robot, traj;
      cell_motion_AlterCorrection a{};
      robot = some_id(g, kRobots, 0.6);
      traj = huge ? huge_string() : garbage_string(g);
      a.robot_id = bus::borrow(robot);
      a.trajectory_id = bus::borrow(traj);
      a.cycle = g.u64();
      a.translation_mm = {g.poison(), g.maybe(0), g.maybe(0)};
      a.rotation_rad = {g.maybe(0), g.poison(), g.maybe(0)};
      a.velocity_mm_per_s = {g.poison(), g.poison(), g.poison()};
      a.extrapolate_s = g.poison();
      bytes += traj.size() + 80;
      return alter.write(lane, a);
    }, {}});

    // vision (and the monitor): images with wrong sizes, steps and encodings, empty or short
    // data, a 1 MiB body, non-finite eye-in-hand joints.
    flows.push_back({t::kImage.name, 300 * s, [&](Gen& g, bool huge, std::uint64_t& bytes, std::size_t lane) {
      std::string camera, encoding, robot, belt, rid;
      cell_vision_Image im{};
      im.request_id = request_id(g, rid, false);
      camera = some_id(g, kCameras, 0.7);
      static const std::vector<std::string> encodings{"mono8", "rgb8", "bgr8", "mono16", "",
                                                      "jpeg", "MONO8", "rgb8\n"};
      encoding = g.chance(0.9) ? g.pick(encodings) : garbage_string(g);
      static const std::vector<std::uint32_t> sizes{0, 1, 2, 3, 484, 512, 640, 65535,
                                                    2147483647u, 4294967295u};
      im.width_px = g.pick(sizes);
      im.height_px = g.pick(sizes);
      std::vector<std::uint8_t> data;
      const int shape = static_cast<int>(g.below(4));
      if (huge) {
        data.assign(1 << 20, 0x80);
      } else if (shape == 0) {  // consistent header, noise: the pipeline really runs
        im.width_px = 512;
        im.height_px = 484;
        encoding = "mono8";
        data.resize(std::size_t{512} * 484);
        for (auto& b : data) {
          b = static_cast<std::uint8_t>(g.below(256));
        }
      } else {
        data.resize(g.below(4096));
      }
      static const std::vector<std::uint32_t> steps{0, 1, 511, 512, 1536, 4294967295u};
      im.step_bytes = shape == 0 && g.chance(0.5) ? 512 : g.pick(steps);
      bus::borrow(im.data, data);
      const auto joints = bad_joints(g, false);
      bus::borrow(im.robot_joints_rad_or_mm, joints);
      robot = some_id(g, kRobots, 0.5);
      belt = g.chance(0.5) ? "belt1" : garbage_string(g);
      im.encoding = bus::borrow(encoding);
      im.robot_id = bus::borrow(robot);
      im.belt_id = bus::borrow(belt);
      im.camera_id = bus::borrow(camera);
      im.belt_count = static_cast<std::int64_t>(g.u64());
      im.header.seq = g.u64();
      bytes += data.size();
      return image.write(lane, im);
    }, {}});

    // vision: edge requests with non-finite points, absurd half-widths, unknown cameras.
    flows.push_back({t::kEdgeRequest.name, 400 * s, [&](Gen& g, bool huge, std::uint64_t& bytes, std::size_t lane) {
      std::string rid, camera;
      cell_vision_EdgeRequest e{};
      e.request_id = request_id(g, rid, huge);
      camera = some_id(g, kCameras, 0.5);
      e.camera_id = bus::borrow(camera);
      e.predicted_start_px = {g.maybe(10), g.maybe(10)};
      e.predicted_end_px = {g.maybe(10), g.poison()};
      e.search_halfwidth_px = g.chance(0.5) ? g.poison() : -5.0;
      e.image_sequence = g.chance(0.5) ? g.u64() : 0;
      bytes += rid.size() + 64;
      return edge_request.write(lane, e);
    }, {}});

    // cameras: image requests for unknown cameras, triggers outside the enum.
    flows.push_back({t::kImageRequest.name, 400 * s, [&](Gen& g, bool huge, std::uint64_t& bytes, std::size_t lane) {
      std::string rid, camera;
      cell_vision_ImageRequest r{};
      r.request_id = request_id(g, rid, huge);
      // A real camera renders a frame for TRIGGER_NOW (a valid request): only a few of those,
      // with garbage request ids; the rest name cameras that do not exist.
      const bool real = g.chance(0.03);
      camera = real ? g.pick(kCameras) : garbage_string(g);
      r.camera_id = bus::borrow(camera);
      set_enum(r.trigger, real ? g.enum_from({0}, 2) : g.enum_value(2));
      r.with_truth = g.chance(0.5);
      bytes += rid.size() + camera.size();
      return image_request.write(lane, r);
    }, {}});

    // calibration: procedures outside the enum, unknown devices, missing or hostile image
    // directories, garbage versions, non-finite planar readings.
    flows.push_back({t::kCalibrationRequest.name, 300 * s,
                     [&](Gen& g, bool huge, std::uint64_t& bytes, std::size_t lane) {
      std::string rid, camera, robot, belt, dir, version, kind, dict;
      cell_calibration_CalibrationRequest c{};
      c.request_id = request_id(g, rid, false);
      // Procedures that would move a robot (hand-eye, belt, planar) or touch the store
      // (rollback) only for devices that do not exist; list/show for anything.
      const std::int32_t proc = g.enum_value(8);
      set_enum(c.procedure, proc);
      const bool may_be_real = proc == 4 || proc == 5 || proc == 0;
      camera = may_be_real ? some_id(g, kCameras, 0.5) : "no_such_camera_" + garbage_string(g);
      robot = "no_such_robot_" + garbage_string(g);
      belt = "no_such_belt_" + garbage_string(g);
      static const std::vector<std::string> dirs{"/nonexistent", "/dev", "/proc/self",
                                                 "../../../../", "", "/etc/passwd"};
      dir = huge ? huge_string() : (g.chance(0.8) ? g.pick(dirs) : garbage_string(g));
      if (proc == 0 && dir.empty()) {
        dir = "/nonexistent";  // intrinsics from "" would be the procedure's own images
      }
      version = garbage_string(g);
      kind = garbage_string(g);
      dict = garbage_string(g);
      c.camera_id = bus::borrow(camera);
      c.robot_id = bus::borrow(robot);
      c.belt_id = bus::borrow(belt);
      c.images_dir = bus::borrow(dir);
      c.version = bus::borrow(version);
      c.target.kind = bus::borrow(kind);
      c.target.dictionary = bus::borrow(dict);
      c.target.columns = static_cast<std::uint32_t>(g.pick(std::vector<std::uint64_t>{0, 1, 4294967295u}));
      c.target.rows = static_cast<std::uint32_t>(g.below(3));
      c.target.square_mm = g.poison();
      c.target.marker_mm = g.poison();
      c.pose_count = static_cast<std::uint32_t>(g.u64());
      c.dry_run = true;
      std::vector<cell_calibration_PlanarReading> readings(g.below(5));
      for (auto& r : readings) {
        r = {g.poison(), g.maybe(0), g.maybe(0), g.poison()};
      }
      bus::borrow(c.readings, readings);
      bytes += dir.size() + rid.size();
      return calibration_request.write(lane, c);
    }, {}});

    // vision, motion, task: camera calibrations from an impostor, unknown cameras or real
    // ones with non-finite intrinsics, a zero quaternion and sizes of zero.
    flows.push_back({t::kCameraCalibration.name, 50 * s,
                     [&](Gen& g, bool huge, std::uint64_t& bytes, std::size_t lane) {
      std::string camera, robot, version, frame, source;
      cell_calibration_CameraCalibration c{};
      camera = huge ? huge_string() : some_id(g, kCameras, 0.5);
      robot = some_id(g, kRobots, 0.5);
      version = garbage_string(g);
      frame = garbage_string(g);
      source = garbage_string(g);
      c.camera_id = bus::borrow(camera);
      c.robot_id = bus::borrow(robot);
      c.version = bus::borrow(version);
      c.mount_frame = bus::borrow(frame);
      c.source = bus::borrow(source);
      set_enum(c.model, g.enum_value(2));
      set_enum(c.mounting, g.enum_value(2));
      c.width_px = static_cast<std::uint32_t>(g.below(2));
      c.height_px = 4294967295u;
      c.fx_px = g.poison();
      c.fy_px = 0;
      c.cx_px = g.poison();
      c.cy_px = g.poison();
      const auto dist = bad_joints(g, true);
      bus::borrow(c.distortion, dist);
      c.extrinsics.position_mm = {g.poison(), 0, 0};
      c.extrinsics.orientation = {0, 0, 0, 0};
      c.working_plane_z_mm = g.poison();
      c.c_x_px_per_mm = 0;
      c.c_y_px_per_mm = g.poison();
      c.link1_mm = g.poison();
      c.camera_height_mm = -1;
      bytes += camera.size() + 300;
      return camera_calibration.write(lane, c);
    }, {}});

    // sim-world: requests outside the enum, garbage scenes, poisoned spawns (meshes whose
    // faces point past their vertices), unknown part ids and belts, absurd scatter counts.
    flows.push_back({t::kWorldRequest.name, 300 * s, [&](Gen& g, bool huge, std::uint64_t& bytes, std::size_t lane) {
      std::string rid, scene, scene_name, belt;
      cell_world_WorldRequest w{};
      w.request_id = request_id(g, rid, false);
      // WORLD_QUERY (0) is valid and never sent; RESET (1) always with a scene that is not.
      set_enum(w.kind, g.enum_from({1, 2, 3, 4, 5}, 6));
      scene = huge ? huge_string() : garbage_yaml(g);
      scene_name = garbage_string(g);
      belt = g.chance(0.5) ? "belt1" : garbage_string(g);
      w.scene_yaml = bus::borrow(scene);
      w.scene_name = bus::borrow(scene_name);
      w.belt_id = bus::borrow(belt);
      w.speed_mm_per_s = g.poison();
      w.count = g.chance(0.5) ? 4294967295u : static_cast<std::uint32_t>(g.u64());
      w.seed = g.u64();
      std::vector<std::string> class_storage(g.below(4));
      for (auto& c : class_storage) {
        c = g.chance(0.5) ? "dip14" : garbage_string(g);
      }
      std::vector<char*> classes;
      classes.reserve(class_storage.size());
      for (auto& c : class_storage) {
        classes.push_back(bus::borrow(c));
      }
      bus::borrow(w.classes, classes);
      std::vector<std::string> id_storage(g.chance(0.05) ? 10000 : g.below(5));
      for (auto& id : id_storage) {
        id = fmt::format("no-such-part-{}", g.u64());
      }
      std::vector<char*> ids;
      ids.reserve(id_storage.size());
      for (auto& id : id_storage) {
        ids.push_back(bus::borrow(id));
      }
      bus::borrow(w.part_ids, ids);
      std::vector<cell_world_WorldPart> parts(g.below(4));
      std::vector<std::string> strings(parts.size() * 3);
      std::vector<cell_common_Vector3> vertices{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
      std::vector<std::uint32_t> face_sizes{3, 4294967295u, 0};
      std::vector<std::uint32_t> face_indices{0, 1, 2000000000u};
      for (std::size_t i = 0; i < parts.size(); ++i) {
        auto& part = parts[i];
        strings[3 * i] = garbage_string(g);
        strings[3 * i + 1] = g.chance(0.5) ? "dip14" : garbage_string(g);
        strings[3 * i + 2] = g.chance(0.5) ? "table" : garbage_string(g);
        part.part_id = bus::borrow(strings[3 * i]);
        part.class_name = bus::borrow(strings[3 * i + 1]);
        part.support = bus::borrow(strings[3 * i + 2]);
        set_enum(part.shape, g.enum_value(7));
        part.length_mm = g.poison();
        part.width_mm = g.chance(0.5) ? -10.0 : g.poison();
        part.height_mm = g.poison();
        part.pins = static_cast<std::uint32_t>(g.u64());
        part.reflectance = g.poison();
        part.world_T_part.position_mm = {g.poison(), g.poison(), g.poison()};
        part.world_T_part.orientation = {0, 0, 0, 0};
        part.part_T_grasp.orientation = {kNaN, 0, 0, 0};
        bus::borrow(part.mesh.vertices_mm, vertices);
        bus::borrow(part.mesh.face_sizes, face_sizes);
        bus::borrow(part.mesh.face_indices, face_indices);
      }
      bus::borrow(w.parts, parts);
      bytes += scene.size() + id_storage.size() * 24 + parts.size() * 200;
      return world_request.write(lane, w);
    }, {}});

    // cameras, task: photocell edges for unknown belts, and for belt1 with absurd counts.
    flows.push_back({t::kPhotocell.name, 200 * s, [&](Gen& g, bool huge, std::uint64_t& bytes, std::size_t lane) {
      std::string belt, part, frame;
      cell_world_PhotocellEvent e{};
      belt = huge ? huge_string() : "no_such_belt_" + garbage_string(g);
      part = garbage_string(g);
      frame = garbage_string(g);
      e.belt_id = bus::borrow(belt);
      e.part_id = bus::borrow(part);
      e.header.frame_id = bus::borrow(frame);
      e.header.stamp_ns = static_cast<std::int64_t>(g.u64());
      e.blocked = g.chance(0.5);
      e.encoder_count = static_cast<std::int64_t>(g.u64());
      bytes += belt.size() + part.size();
      return photocell.write(lane, e);
    }, {}});

    // cameras, task, calibration: belt states for unknown belts with non-finite values.
    flows.push_back({t::kBeltState.name, 300 * s, [&](Gen& g, bool huge, std::uint64_t& bytes, std::size_t lane) {
      std::string belt, frame;
      cell_world_BeltState b{};
      belt = huge ? huge_string() : "no_such_belt_" + garbage_string(g);
      frame = garbage_string(g);
      b.belt_id = bus::borrow(belt);
      b.header.frame_id = bus::borrow(frame);
      b.travel_mm = g.poison();
      b.speed_mm_per_s = g.poison();
      b.encoder_count = static_cast<std::int64_t>(g.u64());
      b.photocell_blocked = g.chance(0.5);
      b.origin_mm = {g.poison(), 0, 0};
      b.direction = {0, 0, 0};
      b.length_mm = g.poison();
      b.width_mm = -1;
      b.photocell_at_mm = g.poison();
      bytes += belt.size() + 100;
      return belt_state.write(lane, b);
    }, {}});

    // every service: pings with garbage and huge targets (and "" for everyone sometimes).
    flows.push_back({t::kPingRequest.name, 300 * s, [&](Gen& g, bool huge, std::uint64_t& bytes, std::size_t lane) {
      std::string rid, target;
      cell_health_PingRequest r{};
      r.request_id = request_id(g, rid, huge && g.chance(0.5));
      target = huge ? huge_string()
                    : (g.chance(0.05) ? "" : (g.chance(0.3) ? g.pick(kServices)
                                                             : garbage_string(g)));
      r.target_service_id = bus::borrow(target);
      r.sent_ns = static_cast<std::int64_t>(g.u64());
      bytes += rid.size() + target.size();
      return ping.write(lane, r);
    }, {}});

    // launcher status, monitor, task: heartbeats from an impostor, under real service ids and
    // garbage ones, with states outside the enum and huge details.
    flows.push_back({t::kHeartbeat.name, 200 * s, [&](Gen& g, bool huge, std::uint64_t& bytes, std::size_t lane) {
      std::string id, kind, host, detail, version;
      cell_health_ServiceHeartbeat h{};
      id = g.chance(0.3) ? g.pick(kServices) : "impostor-" + garbage_string(g);
      kind = garbage_string(g);
      host = garbage_string(g);
      detail = huge ? huge_string() : garbage_string(g);
      version = garbage_string(g);
      h.service_id = bus::borrow(id);
      h.service_kind = bus::borrow(kind);
      h.host = bus::borrow(host);
      h.detail = bus::borrow(detail);
      h.version = bus::borrow(version);
      h.pid = g.chance(0.5) ? -1 : 0;
      set_enum(h.state, g.enum_value(5));
      h.uptime_s = g.poison();
      h.stamp_ns = static_cast<std::int64_t>(g.u64());
      h.seq = g.u64();
      bytes += detail.size() + id.size();
      return heartbeat.write(lane, h);
    }, {}});

    for (Flow& f : flows) {
      f.lanes.assign(kLanes, Stats{});
    }
    (void)huge_string();  // build it before the clock starts
    log::info("flood_start", "flooding every topic a service reads",
              {{"seconds", fmt::format("{}", o.seconds)},
               {"seed", fmt::format("{}", o.seed)},
               {"topics", fmt::format("{}", flows.size())},
               {"domain", fmt::format("{}", o.domain)},
               {"partition", o.partition}});
    // Let discovery match our writers before the clock starts (requests are transient-local
    // for 2 s anyway; streams would be lost before matching).
    std::this_thread::sleep_for(std::chrono::milliseconds(1500));

    const auto start = Clock::now();
    const auto stop_at = start + std::chrono::milliseconds(static_cast<std::int64_t>(o.seconds * 1000));
    std::vector<std::thread> threads;
    for (std::size_t i = 0; i < flows.size(); ++i) {
      for (std::size_t lane = 0; lane < kLanes; ++lane) {
        threads.emplace_back([&, i, lane] {
          Flow& f = flows[i];
          Stats& stats = f.lanes[lane];
          Gen g(o.seed * 1000003u + i * kLanes + lane);
          constexpr auto kSlice = std::chrono::milliseconds(5);
          const double per_slice = f.rate_hz * 0.005 / static_cast<double>(kLanes);
          double owed = 0;
          auto next = Clock::now();
          // About one huge sample per second per topic, the lanes taking turns.
          const auto huge_period = std::chrono::seconds(kLanes);
          auto next_huge = Clock::now() + std::chrono::milliseconds(200 + 50 * i) +
                           std::chrono::seconds(lane);
          while (Clock::now() < stop_at) {
            owed += per_slice;
            while (owed >= 1.0 && Clock::now() < stop_at) {
              owed -= 1.0;
              bool huge = false;
              if (Clock::now() >= next_huge) {
                huge = true;
                next_huge += huge_period;
              }
              std::uint64_t bytes = 0;
              const Status st = f.send(g, huge, bytes, lane);
              if (st) {
                ++stats.written;
                stats.bytes += bytes;
                stats.huge += huge ? 1 : 0;
              } else if (is_timeout(st)) {
                ++stats.throttled;
              } else if (is_refused(st)) {
                ++stats.refused;
              } else {
                ++stats.failed;
                if (stats.first_error.empty()) {
                  stats.first_error = st.error().message;
                }
              }
            }
            next += kSlice;
            const auto now = Clock::now();
            if (next < now - std::chrono::milliseconds(50)) {
              next = now;  // fell behind (blocked writes): do not burst to catch up
              owed = std::min(owed, per_slice);
            }
            std::this_thread::sleep_until(next);
          }
        });
      }
    }
    for (auto& th : threads) {
      th.join();
    }
    for (Flow& f : flows) {
      for (const Stats& l : f.lanes) {
        f.stats.written += l.written;
        f.stats.throttled += l.throttled;
        f.stats.refused += l.refused;
        f.stats.failed += l.failed;
        f.stats.huge += l.huge;
        f.stats.bytes += l.bytes;
        if (f.stats.first_error.empty()) {
          f.stats.first_error = l.first_error;
        }
      }
    }
    const double elapsed_s = std::chrono::duration<double>(Clock::now() - start).count();

    std::uint64_t total = 0, total_throttled = 0, total_refused = 0, total_failed = 0;
    std::uint64_t total_huge = 0;
    std::string json = fmt::format("{{\"seconds\": {:.3f}, \"seed\": {}, \"topics\": [", elapsed_s,
                                   o.seed);
    std::printf("%-30s %10s %10s %9s %9s %7s %6s %8s\n", "topic", "written", "rate_hz",
                "throttled", "refused", "failed", "huge", "MiB");
    for (std::size_t i = 0; i < flows.size(); ++i) {
      const Flow& f = flows[i];
      const double rate = static_cast<double>(f.stats.written) / elapsed_s;
      std::printf("%-30s %10llu %10.1f %9llu %9llu %7llu %6llu %8.1f\n", f.topic.c_str(),
                  static_cast<unsigned long long>(f.stats.written), rate,
                  static_cast<unsigned long long>(f.stats.throttled),
                  static_cast<unsigned long long>(f.stats.refused),
                  static_cast<unsigned long long>(f.stats.failed),
                  static_cast<unsigned long long>(f.stats.huge),
                  static_cast<double>(f.stats.bytes) / (1 << 20));
      if (!f.stats.first_error.empty()) {
        std::printf("  first error on %s: %s\n", f.topic.c_str(), f.stats.first_error.c_str());
      }
      total += f.stats.written;
      total_throttled += f.stats.throttled;
      total_refused += f.stats.refused;
      total_failed += f.stats.failed;
      total_huge += f.stats.huge;
      json += fmt::format(
          "{}{{\"topic\": \"{}\", \"target_hz\": {:.1f}, \"written\": {}, \"rate_hz\": {:.1f}, "
          "\"throttled\": {}, \"refused\": {}, \"failed\": {}, \"huge\": {}, \"bytes\": {}}}",
          i == 0 ? "" : ", ", f.topic, f.rate_hz, f.stats.written, rate, f.stats.throttled,
          f.stats.refused, f.stats.failed, f.stats.huge, f.stats.bytes);
    }
    const double total_rate = static_cast<double>(total) / elapsed_s;
    std::printf("%-30s %10llu %10.1f %9llu %9llu %7llu %6llu\n", "TOTAL",
                static_cast<unsigned long long>(total), total_rate,
                static_cast<unsigned long long>(total_throttled),
                static_cast<unsigned long long>(total_refused),
                static_cast<unsigned long long>(total_failed),
                static_cast<unsigned long long>(total_huge));
    std::fflush(stdout);
    json += fmt::format("], \"written\": {}, \"rate_hz\": {:.1f}, \"throttled\": {}, "
                        "\"refused\": {}, \"failed\": {}, \"huge\": {}}}\n",
                        total, total_rate, total_throttled, total_refused, total_failed,
                        total_huge);
    if (!o.json_path.empty()) {
      std::ofstream out(o.json_path);
      out << json;
      if (!out) {
        log::error("flood_json", "cannot write the JSON report", {{"path", o.json_path}});
        return 1;
      }
    }
    log::info("flood_done", "flood finished",
              {{"written", fmt::format("{}", total)},
               {"rate_hz", fmt::format("{:.1f}", total_rate)}});
  } catch (const bus::BusError& e) {
    log::error("bus", e.what(), {{"domain", fmt::format("{}", o.domain)},
                                 {"partition", o.partition}});
    return 3;
  }
  return 0;
}

}  // namespace
}  // namespace cell::flood

int main(int argc, char** argv) { return cell::flood::run(argc, argv); }
