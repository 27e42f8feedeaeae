#pragma once

#include <optional>
#include <string>
#include <vector>

#include "cell/common/result.hpp"
#include "cell/rapt/camera.hpp"
#include "cell/rapt/compiler.hpp"
#include "cell/rapt/lsq.hpp"

/// The RAPT run time (digest 003 §4.3, thesis §7.4-§7.5): given the image end points measured
/// for each LOOK, evaluate each vision package's symbolic position, fill the modifying factors
/// (P entries by (7.2), pointers by equality or (7.11), triples by (8.11)), and produce the
/// actual position of every body in every situation and the corrected action of every move.
namespace cell::rapt {

/// The measured image of one LOOK's edge: two end points, in the camera's image units.
struct Reading {
  int situation = 0;
  std::string body;    ///< the verified body's name
  std::string edge;    ///< the edge's name
  std::string camera;  ///< the camera's name
  ImagePoint p1 = ImagePoint::Zero();
  ImagePoint p2 = ImagePoint::Zero();
  std::string where;  ///< where it was read ("readings.yaml:4:5"), for messages
};

/// Options of a run.
struct RunOptions {
  /// Also evaluate every package by least squares over all its LOOKs (lsq.hpp).
  bool least_squares = false;
  /// Evaluate situations 1..through_situation only (0: all). Packages of later situations
  /// need no readings and are not evaluated, and the FMs of later situations are left as the
  /// identity (actual = nominal) with no actions: a live run (services/task) measures each
  /// package when the robot reaches it, with everything before it corrected.
  int through_situation = 0;
};

/// A package's run-time outcome.
struct PackageOutcome {
  int package = -1;
  bool evaluated = false;  ///< false when the package cannot fix its body (ignored)
  std::string note;
  Pose verified = Pose::Identity();  ///< PV: world_T_body from the symbolic route
  Pose fm = Pose::Identity();        ///< FM = PN^-1 * PV (column form, body nominal frame)
  /// Run-time predictions and windows of each LOOK at FM*PN of the body and camera in the
  /// situation before (thesis §7.7); empty when not evaluated.
  std::vector<std::array<ImagePoint, 2>> predicted;
  std::vector<Window> windows;
  std::optional<LsqReport> lsq;  ///< when RunOptions::least_squares
};

/// The actual motion of one moved body between situation s-1 and s. Motions are in world
/// axes and left-multiply: world_T_after = motion * world_T_before (the transposes of the
/// thesis's row-form TN, TA, TC, Ta1, Ta2).
struct ActionOutcome {
  int situation = 0;  ///< the action produces this situation
  int body = 0;
  Pose nominal = Pose::Identity();       ///< TN (7.12)
  Pose actual = Pose::Identity();        ///< TA (7.13): the one-step corrected action
  Pose correction = Pose::Identity();    ///< TC (7.15): two-step method 1, first step
                                         ///< (then TN: TA = TN * TC in column form)
  Pose intermediate = Pose::Identity();  ///< PN' (7.17): method 2's intermediate pose
  Pose step1 = Pose::Identity();         ///< Ta1: method 2, PV(s-1) -> PN'
  Pose step2 = Pose::Identity();         ///< Ta2 (7.18): method 2, PN' -> PV(s)
};

/// Everything a run produced.
struct RunResult {
  int bodies = 0;
  int situations = 0;
  std::vector<PackageOutcome> packages;
  std::vector<Pose> fm;      ///< per instance, index (body-1)*situations + (situation-1)
  std::vector<Pose> actual;  ///< PV = PN * FM per instance (world_T_body)
  std::vector<ActionOutcome> actions;

  const Pose& fm_of(int body, int situation) const;
  const Pose& actual_pose(int body, int situation) const;
};

/// Runs a compiled program on measurements. Every reading must match a LOOK (situation, body,
/// edge, camera), and every LOOK a fixable package uses must have a reading; otherwise
/// kInvalidArgument listing every problem, each with the reading's position or the LOOK's
/// line:column. Evaluation errors (coincident end points, a face no rotation can satisfy) are
/// kOutOfRange/kInvalidArgument naming the LOOK. Pure; allocation proportional to the array.
Result<RunResult> run(const CompiledProgram& cp,
                      const std::vector<Reading>& readings,
                      const RunOptions& options = {});

/// Loads a readings file:
///   readings:
///     - {situation: 3, body: b3, edge: e1, camera: cam1, p1_mm: [-17, 8], p2_mm: [-19, 25]}
/// (p1_mm, p2_mm: image end points in the camera's image units, mm for the thesis programs).
/// Errors: kIo / kConfig with "file:line:col: key 'readings[2].p1_mm': ..." for each problem.
Result<std::vector<Reading>> load_readings(const std::string& path);

/// Parses readings from YAML text (`origin` names it in messages).
Result<std::vector<Reading>> parse_readings(const std::string& text, const std::string& origin);

}  // namespace cell::rapt
