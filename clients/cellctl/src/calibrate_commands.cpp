// `cellctl calibrate intrinsics|hand-eye|belt|planar` and `cellctl calibration
// list|show|rollback|cancel`: CalibrationRequests to cell-calibration (cell/calibration/request),
// followed through their CalibrationProgress (a progress bar on stderr) to the
// CalibrationResult (services/calibration/README.md).
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <iostream>
#include <memory>
#include <numbers>
#include <optional>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "cell/bus/reader.hpp"
#include "cell/bus/request_reply.hpp"
#include "cell/bus/topics.hpp"
#include "cell/bus/view.hpp"
#include "cell/common/time.hpp"
#include "cell/geometry/angles.hpp"
#include "commands.hpp"
#include "robot_args.hpp"
#include "table.hpp"

namespace cell::cellctl {
namespace {

using nlohmann::json;
using Clock = std::chrono::steady_clock;
using geometry::kDeg;

struct CalibrateArgs {
  std::string camera;
  std::string robot;
  std::string belt;
  std::string images;
  std::string board;  // "9x6"
  double square_mm = 0.0;
  bool charuco = false;
  double marker_mm = 0.0;
  std::string dictionary = "DICT_4X4_50";
  int poses = 0;
  std::vector<std::string> stages;  // planar: "J1,J2,X,Y" (deg, deg, mm, mm)
  std::string version;
  bool dry_run = false;
  double wait_s = 900.0;
};

std::string_view procedure_name(cell_calibration_CalibrationProcedure p) {
  switch (p) {
    case cell_calibration_PROCEDURE_INTRINSICS:
      return "intrinsics";
    case cell_calibration_PROCEDURE_HAND_EYE:
      return "hand_eye";
    case cell_calibration_PROCEDURE_BELT:
      return "belt";
    case cell_calibration_PROCEDURE_PLANAR:
      return "planar";
    case cell_calibration_PROCEDURE_LIST:
      return "list";
    case cell_calibration_PROCEDURE_SHOW:
      return "show";
    case cell_calibration_PROCEDURE_ROLLBACK:
      return "rollback";
    case cell_calibration_PROCEDURE_CANCEL:
      return "cancel";
  }
  return "unknown";
}

/// A progress line or bar on stderr: a bar with \r on a terminal, whole lines otherwise.
class ProgressView {
 public:
  explicit ProgressView(Session& session)
      : session_(session), tty_(&session.err() == &std::cerr && ::isatty(2) != 0) {}
  ~ProgressView() { finish(); }

  void show(const cell_calibration_CalibrationProgress& p) {
    const std::string stage(bus::str(p.stage));
    const std::string message(bus::str(p.message));
    std::string line;
    if (p.total > 0) {
      const int width = 24;
      const int filled =
          static_cast<int>(std::lround(width * std::min(1.0, static_cast<double>(p.step) / p.total)));
      line = fmt::format("[{}{}] {:>3}/{:<3} {:<8} {}", std::string(static_cast<std::size_t>(filled), '#'),
                         std::string(static_cast<std::size_t>(width - filled), '.'), p.step, p.total,
                         stage, message);
    } else {
      line = fmt::format("{:<8} {}", stage, message);
    }
    if (tty_) {
      session_.err() << "\r" << line.substr(0, 110) << std::string(line.size() < 110 ? 110 - line.size() : 0, ' ')
                     << std::flush;
      open_ = true;
    } else if (stage != last_stage_ || p.total == 0 || p.step == p.total || p.step % 5 == 0) {
      session_.err() << line << "\n";
    }
    last_stage_ = stage;
  }

  void finish() {
    if (open_) {
      session_.err() << "\n";
      open_ = false;
    }
  }

 private:
  Session& session_;
  bool tty_;
  bool open_ = false;
  std::string last_stage_;
};

/// Sends one request and follows it to its result. Returns the result, or fails the session.
std::optional<bus::Owned<cell_calibration_CalibrationResult>> call(
    Session& session, cell_calibration_CalibrationRequest& request, double wait_s, bool quiet) {
  const bus::Participant& participant = session.participant();
  bus::Requester<cell_calibration_CalibrationRequest, cell_calibration_CalibrationResult> requester(
      participant, bus::topics::kCalibrationRequest, bus::topics::kCalibrationResult,
      bus::make_client_id("cellctl"));
  bus::Topic<cell_calibration_CalibrationProgress> progress_topic(participant,
                                                                  bus::topics::kCalibrationProgress);
  bus::Reader<cell_calibration_CalibrationProgress> progress(participant, progress_topic,
                                                             bus::topics::kCalibrationProgress);
  auto seq = requester.send(request, session.timeout());
  if (!seq) {
    session.fail(fmt::format("{} (is cell-calibration running on {}?)", seq.error().message,
                             session.describe_bus()));
    return std::nullopt;
  }
  ProgressView view(session);
  const auto deadline = Clock::now() + std::chrono::milliseconds(static_cast<long>(wait_s * 1000));
  for (;;) {
    if (auto batch = progress.take_copies(32); batch) {
      for (auto& p : *batch) {
        if (!quiet && bus::same_request(p->request_id, requester.client_id(), *seq)) {
          view.show(p.get());
        }
      }
    }
    auto reply = requester.wait_reply(*seq, std::min(deadline, Clock::now() + std::chrono::milliseconds(100)));
    if (reply) {
      view.finish();
      return std::move(*reply);
    }
    if (Clock::now() >= deadline) {
      view.finish();
      session.fail(fmt::format("no result from cell-calibration within {:.0f} s (it may still be "
                               "running: cellctl calibration cancel)",
                               wait_s));
      return std::nullopt;
    }
  }
}

json views_json(const cell_calibration_CalibrationResult& r) {
  json used = json::array();
  json held = json::array();
  json rejected = json::array();
  for (const auto& v : bus::span(r.views)) {
    json item{{"id", std::string(bus::str(v.view_id))}, {"rms", v.rms_px}};
    if (v.used) {
      used.push_back(item);
    } else if (v.held_out) {
      held.push_back(item);
    } else {
      item["reason"] = std::string(bus::str(v.reason));
      rejected.push_back(item);
    }
  }
  return json{{"used", used}, {"held_out", held}, {"rejected", rejected}};
}

json camera_json(const cell_calibration_CameraCalibration& c) {
  json out{{"camera_id", std::string(bus::str(c.camera_id))},
           {"version", std::string(bus::str(c.version))},
           {"source", std::string(bus::str(c.source))},
           {"robot_id", std::string(bus::str(c.robot_id))},
           {"width_px", c.width_px},
           {"height_px", c.height_px},
           {"working_plane_z_mm", c.working_plane_z_mm}};
  if (c.model == cell_calibration_CAMERA_PINHOLE) {
    out["model"] = "pinhole";
    out["fx_px"] = c.fx_px;
    out["fy_px"] = c.fy_px;
    out["cx_px"] = c.cx_px;
    out["cy_px"] = c.cy_px;
    out["distortion_k1_k2_p1_p2_k3"] = bus::to_vector(c.distortion);
    const auto& p = c.extrinsics;
    const Eigen::Quaterniond q(p.orientation.w, p.orientation.x, p.orientation.y, p.orientation.z);
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    if (q.norm() > 0.5) {
      pose.linear() = q.normalized().toRotationMatrix();
    }
    pose.translation() = Eigen::Vector3d(p.position_mm.x, p.position_mm.y, p.position_mm.z);
    out[c.mounting == cell_calibration_MOUNT_FIXED ? "base_T_camera" : "mount_T_camera"] =
        pose_json(pose);
    out["mounting"] = c.mounting == cell_calibration_MOUNT_FIXED ? "fixed" : "eye_in_hand";
  } else {
    out["model"] = "planar_7545";
    out["planar"] = json{{"c_x_px_per_mm", c.c_x_px_per_mm},
                         {"c_y_px_per_mm", c.c_y_px_per_mm},
                         {"ref_px", {c.ref_u_px, c.ref_v_px}},
                         {"d_t_c_mm", c.d_t_c_mm},
                         {"b_angl_deg", c.b_angl_rad / kDeg},
                         {"angl_err_deg", c.angl_err_rad / kDeg},
                         {"link1_mm", c.link1_mm},
                         {"link2_mm", c.link2_mm}};
  }
  out["rms_px"] = c.rms_px;
  out["holdout_rms_px"] = c.holdout_rms_px;
  out["holdout_mm"] = c.holdout_rms_mm;
  return out;
}

json belt_json(const cell_calibration_BeltCalibration& b) {
  return json{{"belt_id", std::string(bus::str(b.belt_id))},
              {"robot_id", std::string(bus::str(b.robot_id))},
              {"camera_id", std::string(bus::str(b.camera_id))},
              {"version", std::string(bus::str(b.version))},
              {"source", std::string(bus::str(b.source))},
              {"mm_per_count", b.mm_per_count},
              {"direction", {b.direction.x, b.direction.y, b.direction.z}},
              {"origin_mm", {b.origin_mm.x, b.origin_mm.y, b.origin_mm.z}},
              {"rms_mm", b.rms_mm},
              {"holdout_mm", b.holdout_mm}};
}

/// Prints a procedure's result; returns the exit code.
int report(Session& session, const cell_calibration_CalibrationResult& r) {
  const bool ok = r.status.accepted;
  if (session.json()) {
    json out{{"procedure", std::string(procedure_name(r.procedure))},
             {"accepted", ok},
             {"device", std::string(bus::str(r.device_id))},
             {"version", std::string(bus::str(r.version))},
             {"stored", r.stored},
             {"summary", std::string(bus::str(r.summary))},
             {"elapsed_s", r.elapsed_s}};
    if (!ok) {
      out["error_code"] = std::string(bus::str(r.status.error_code));
      out["reason"] = std::string(bus::str(r.status.reason));
    } else {
      out["rms"] = r.rms_px;
      out["holdout_rms_px"] = r.holdout_rms_px;
      out["holdout_mm"] = r.holdout_mm;
      out["views"] = views_json(r);
      out["views_used"] = r.views_used;
      out["views_rejected"] = r.views_rejected;
      if (r.has_camera) {
        out["camera"] = camera_json(r.camera);
        // The intrinsics at the top level too (fx, fy, cx, cy, distortion, RMS, hold-out).
        for (const char* k : {"fx_px", "fy_px", "cx_px", "cy_px", "distortion_k1_k2_p1_p2_k3"}) {
          if (out["camera"].contains(k)) {
            out[k] = out["camera"][k];
          }
        }
        out["rms_px"] = r.rms_px;
      }
      if (r.has_belt) {
        out["belt"] = belt_json(r.belt);
      }
    }
    session.out() << out.dump(2) << "\n";
  } else if (ok) {
    session.out() << bus::str(r.summary) << "\n";
    if (r.stored) {
      session.out() << fmt::format("stored as {} of '{}' and published\n", bus::str(r.version),
                                   bus::str(r.device_id));
    } else {
      session.out() << "not stored (dry run, or no device named)\n";
    }
    for (const auto& v : bus::span(r.views)) {
      if (!v.used && !v.held_out) {
        session.out() << fmt::format("  rejected {}: {}\n", bus::str(v.view_id), bus::str(v.reason));
      }
    }
  }
  if (!ok) {
    return session.fail(fmt::format("{} refused or failed ({}): {} (the current calibration "
                                    "stays)",
                                    bus::str(r.device_id).empty() ? "calibration"
                                                                  : std::string(bus::str(r.device_id)),
                                    bus::str(r.status.error_code), bus::str(r.status.reason)));
  }
  return kExitOk;
}

/// Fills the request's board target from --board/--square (and ChArUco options).
std::optional<std::string> fill_board(const CalibrateArgs& a, cell_calibration_CalibrationRequest& r,
                                      std::string& kind_storage, std::string& dict_storage) {
  if (a.board.empty()) {
    kind_storage.clear();
    dict_storage.clear();
    r.target.kind = bus::borrow(kind_storage);
    r.target.dictionary = bus::borrow(dict_storage);
    return std::nullopt;
  }
  const auto x = a.board.find_first_of("xX");
  int c = 0;
  int rows = 0;
  if (x == std::string::npos || std::sscanf(a.board.c_str(), "%d", &c) != 1 ||
      std::sscanf(a.board.c_str() + x + 1, "%d", &rows) != 1) {
    return fmt::format("--board '{}': expected COLUMNSxROWS of inner corners, e.g. 9x6", a.board);
  }
  if (!(a.square_mm > 0.0)) {
    return std::string("--square: the square side in mm is needed with --board");
  }
  kind_storage = a.charuco ? "charuco" : "chessboard";
  dict_storage = a.dictionary;
  r.target.kind = bus::borrow(kind_storage);
  r.target.columns = static_cast<std::uint32_t>(std::max(c, 0));
  r.target.rows = static_cast<std::uint32_t>(std::max(rows, 0));
  r.target.square_mm = a.square_mm;
  r.target.marker_mm = a.marker_mm;
  r.target.dictionary = bus::borrow(dict_storage);
  return std::nullopt;
}

int run_procedure(Session& session, const CalibrateArgs& a,
                  cell_calibration_CalibrationProcedure procedure) {
  cell_calibration_CalibrationRequest r{};
  r.procedure = procedure;
  r.camera_id = bus::borrow(a.camera);
  r.robot_id = bus::borrow(a.robot);
  r.belt_id = bus::borrow(a.belt);
  r.images_dir = bus::borrow(a.images);
  r.version = bus::borrow(a.version);
  r.pose_count = static_cast<std::uint32_t>(std::max(a.poses, 0));
  r.dry_run = a.dry_run;
  std::string kind;
  std::string dict;
  if (auto bad = fill_board(a, r, kind, dict)) {
    return session.fail(*bad, kExitUsage);
  }
  std::vector<cell_calibration_PlanarReading> readings;
  for (const std::string& s : a.stages) {
    auto values = parse_numbers(s, "--stage");
    if (!values || values->size() != 4) {
      return session.fail(fmt::format("--stage '{}': expected J1,J2,X,Y (deg, deg, mm, mm): stage "
                                      "1's elbow joints with the table point on the Ref_Point "
                                      "pixel, stage 2's end-effector over it",
                                      s),
                          kExitUsage);
    }
    readings.push_back({(*values)[0] * kDeg, (*values)[1] * kDeg, (*values)[2],
                        (*values)[3]});
  }
  bus::borrow(r.readings, readings);
  auto result = call(session, r, a.wait_s, session.json());
  if (!result) {
    return kExitFailure;
  }
  return report(session, result->get());
}

int run_list(Session& session, const CalibrateArgs& a) {
  cell_calibration_CalibrationRequest r{};
  r.procedure = cell_calibration_PROCEDURE_LIST;
  r.camera_id = bus::borrow(a.camera);
  r.belt_id = bus::borrow(a.belt);
  const std::string empty;
  r.robot_id = bus::borrow(empty);
  r.images_dir = bus::borrow(empty);
  r.version = bus::borrow(empty);
  r.target.kind = bus::borrow(empty);
  r.target.dictionary = bus::borrow(empty);
  auto result = call(session, r, std::max(5.0, std::chrono::duration<double>(session.timeout()).count()), true);
  if (!result) {
    return kExitFailure;
  }
  const auto& res = result->get();
  if (!res.status.accepted) {
    return session.fail(fmt::format("list refused: {}", bus::str(res.status.reason)));
  }
  if (session.json()) {
    json out = json::array();
    for (const auto& v : bus::span(res.versions)) {
      out.push_back(json{{"device", std::string(bus::str(v.device_id))},
                         {"kind", std::string(bus::str(v.kind))},
                         {"version", std::string(bus::str(v.version))},
                         {"created_utc", std::string(bus::str(v.created_utc))},
                         {"source", std::string(bus::str(v.source))},
                         {"current", v.current},
                         {"rms", v.rms_px},
                         {"holdout_rms_px", v.holdout_rms_px},
                         {"holdout_mm", v.holdout_mm}});
    }
    session.out() << out.dump(2) << "\n";
    return kExitOk;
  }
  Table table({"", "device", "kind", "version", "rms", "hold-out px", "hold-out mm", "source"});
  for (const auto& v : bus::span(res.versions)) {
    const bool belt = std::string(bus::str(v.kind)) == "belt";
    table.add_row({v.current ? "*" : "", std::string(bus::str(v.device_id)),
                   std::string(bus::str(v.kind)), std::string(bus::str(v.version)),
                   fmt::format("{:.3f} {}", v.rms_px, belt ? "mm" : "px"),
                   belt ? "" : fmt::format("{:.3f}", v.holdout_rms_px),
                   fmt::format("{:.3f}", v.holdout_mm),
                   std::string(bus::str(v.source)).substr(0, 60)});
  }
  table.print(session.out());
  session.out() << bus::str(res.summary) << " (* current)\n";
  return kExitOk;
}

int run_simple(Session& session, const CalibrateArgs& a,
               cell_calibration_CalibrationProcedure procedure) {
  if (procedure != cell_calibration_PROCEDURE_CANCEL && a.camera.empty() == a.belt.empty()) {
    return session.fail("name one device: --camera ID or --belt ID", kExitUsage);
  }
  if (procedure == cell_calibration_PROCEDURE_ROLLBACK && a.version.empty()) {
    return session.fail("--version: the version to go back to (cellctl calibration list)",
                        kExitUsage);
  }
  cell_calibration_CalibrationRequest r{};
  r.procedure = procedure;
  r.camera_id = bus::borrow(a.camera);
  r.belt_id = bus::borrow(a.belt);
  r.version = bus::borrow(a.version);
  const std::string empty;
  r.robot_id = bus::borrow(empty);
  r.images_dir = bus::borrow(empty);
  r.target.kind = bus::borrow(empty);
  r.target.dictionary = bus::borrow(empty);
  auto result = call(session, r, std::max(5.0, std::chrono::duration<double>(session.timeout()).count()), true);
  if (!result) {
    return kExitFailure;
  }
  return report(session, result->get());
}

}  // namespace

void add_calibrate_commands(CLI::App& app, Commands& commands) {
  auto a = std::make_shared<CalibrateArgs>();
  CLI::App* group = app.add_subcommand(
      "calibrate", "run a calibration procedure on cell-calibration (progress on stderr)");
  group->require_subcommand(1);
  auto common = [&](CLI::App* sub) {
    sub->add_flag("--dry-run", a->dry_run, "solve and report, but do not store or publish");
    sub->add_option("--wait", a->wait_s, "seconds to wait for the result (default 900)");
  };
  auto board_options = [&](CLI::App* sub, bool required) {
    auto* b = sub->add_option("--board", a->board, "inner corners COLUMNSxROWS, e.g. 9x6");
    auto* s = sub->add_option("--square", a->square_mm, "square side [mm]");
    if (required) {
      b->required();
      s->required();
    }
    sub->add_flag("--charuco", a->charuco, "a ChArUco board (with --marker and --dict)");
    sub->add_option("--marker", a->marker_mm, "ChArUco marker side [mm]");
    sub->add_option("--dict", a->dictionary, "ChArUco dictionary, default DICT_4X4_50");
  };
  CLI::App* in = group->add_subcommand(
      "intrinsics",
      "camera intrinsics from board images: fx, fy, cx, cy [px], lens, RMS and hold-out RMS [px]");
  in->add_option("--images", a->images, "directory of board images")->required();
  board_options(in, true);
  in->add_option("--camera", a->camera,
                 "camera whose calibration gets the intrinsics (stored and published)");
  common(in);
  commands.add(in, [a](Session& s) {
    return run_procedure(s, *a, cell_calibration_PROCEDURE_INTRINSICS);
  });

  CLI::App* he = group->add_subcommand(
      "hand-eye", "camera to robot: guided through the camera's pose set, or from a data set");
  he->add_option("--camera", a->camera, "camera id")->required();
  he->add_option("--robot", a->robot, "robot id (default: the camera's)");
  he->add_option("--poses", a->poses, "poses to visit (default: the pose set's)");
  he->add_option("--images", a->images, "a recorded data set: images and poses.yaml");
  board_options(he, false);
  common(he);
  commands.add(he, [a](Session& s) {
    return run_procedure(s, *a, cell_calibration_PROCEDURE_HAND_EYE);
  });

  CLI::App* bt = group->add_subcommand(
      "belt", "mm per encoder count and direction of a belt, from markers riding it");
  bt->add_option("--belt", a->belt, "belt id")->required();
  common(bt);
  commands.add(bt, [a](Session& s) { return run_procedure(s, *a, cell_calibration_PROCEDURE_BELT); });

  CLI::App* pl = group->add_subcommand(
      "planar", "the 7545 thesis's planar model: two-stage readings refined on line");
  pl->add_option("--camera", a->camera, "camera id (the 7545's link-2 camera)")->required();
  pl->add_option("--stage", a->stages,
                 "a two-stage reading J1,J2,X,Y [deg, deg, mm, mm] (repeat for 2-3 readings)");
  pl->add_option("--poses", a->poses, "poses to visit (default: the pose set's)");
  pl->add_option("--images", a->images, "a recorded data set instead of the guided capture");
  board_options(pl, false);
  common(pl);
  commands.add(pl, [a](Session& s) {
    return run_procedure(s, *a, cell_calibration_PROCEDURE_PLANAR);
  });

  CLI::App* store = app.add_subcommand("calibration", "the calibration store: list, show, rollback");
  store->require_subcommand(1);
  CLI::App* ls = store->add_subcommand("list", "every stored version (* current)");
  ls->add_option("--camera", a->camera, "only this camera");
  ls->add_option("--belt", a->belt, "only this belt");
  commands.add(ls, [a](Session& s) { return run_list(s, *a); });
  CLI::App* sh = store->add_subcommand("show", "a device's current calibration (or --version)");
  sh->add_option("--camera", a->camera, "camera id");
  sh->add_option("--belt", a->belt, "belt id");
  sh->add_option("--version", a->version, "a stored version (default: the current)");
  commands.add(sh, [a](Session& s) { return run_simple(s, *a, cell_calibration_PROCEDURE_SHOW); });
  CLI::App* rb = store->add_subcommand("rollback", "make an earlier version current again");
  rb->add_option("--camera", a->camera, "camera id");
  rb->add_option("--belt", a->belt, "belt id");
  rb->add_option("--version", a->version, "the version (whole, #N or N)")->required();
  commands.add(rb, [a](Session& s) {
    return run_simple(s, *a, cell_calibration_PROCEDURE_ROLLBACK);
  });
  CLI::App* cn = store->add_subcommand("cancel", "stop the running procedure");
  commands.add(cn, [a](Session& s) { return run_simple(s, *a, cell_calibration_PROCEDURE_CANCEL); });
}

}  // namespace cell::cellctl
