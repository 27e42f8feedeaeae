#pragma once

#include <Eigen/Geometry>
#include <map>
#include <optional>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "cell/rapt/ast.hpp"
#include "cell/rapt/frames.hpp"
#include "cell/rapt/source.hpp"

/// The RAPT program model produced by semantic analysis (sema.hpp): bodies with their
/// features and frames, cameras, and the situation sequence with its tables (actions, ties,
/// subassemblies, unmoved bodies, vision packages). Immutable once built; share it freely.
///
/// Numbering follows the thesis: bodies are numbered from 1 with the world first (Appendix V:
/// world = 1, b1 = 2, b2 = 3, b3 = 4); situations are numbered from 1. Vectors here are
/// 0-based, so body number n is `bodies[n - 1]` and situation s is `situations[s - 1]`.
namespace cell::rapt {

/// Body number of the world (always 1).
inline constexpr int kWorld = 1;

/// A feature of a body (thesis §3.2.1.3). Its frame body_T_feature follows digest §1.4: a face
/// has X along the outward normal and the origin in the face (its first point); a shaft, hole
/// or edge has X along the axis (sign from the x/y/z large/small rule) and the origin at the
/// first point of its line (the circle centre for the circle forms); a sphface or vertex has
/// the origin at the centre and X = the body's x axis.
struct Feature {
  std::string name;
  FeatureType type = FeatureType::kFace;
  int body = kWorld;  ///< body number
  Pose body_T_feature = Pose::Identity();
  double radius = 0.0;  ///< shafts, holes, sphfaces [mm]; 0 for edges and vertices
  double length = 0.0;  ///< shafts, holes, edges made from a line [mm]; 0 if infinite
  SourceLoc loc;

  /// The feature's X axis in body coordinates (unit).
  Eigen::Vector3d axis() const { return body_T_feature.linear().col(0); }
  /// The feature's origin in body coordinates [mm].
  Eigen::Vector3d origin() const { return body_T_feature.translation(); }
  /// True for shafts, holes and edges.
  bool cylindrical() const noexcept;
  /// True for sphfaces and vertices.
  bool spherical() const noexcept;
  /// The two end points of a finite edge in body coordinates, as the thesis's window suggester
  /// computes them (digest §2.2, [verified]): the origin and origin + length * X. Note: this
  /// is NOT always the line's second point (Appendix V b2 e2 = edge/l2,ylarge with l2 running
  /// toward -y gives the end point (25, +30, 0)).
  std::pair<Eigen::Vector3d, Eigen::Vector3d> edge_end_points() const;
};

/// A named geometric primitive of a body (only used to build features).
struct Point {
  Eigen::Vector3d xyz = Eigen::Vector3d::Zero();
  SourceLoc loc;
};
/// A line segment from `from` to `to` (body coordinates).
struct Line {
  Eigen::Vector3d from = Eigen::Vector3d::Zero();
  Eigen::Vector3d to = Eigen::Vector3d::Zero();
  SourceLoc loc;
};
/// A circle parallel to the body's X-Y plane (RAPT v1.1a).
struct Circle {
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  double radius = 0.0;
  SourceLoc loc;
};

/// A body: the world (number 1) or a BODY/ ... TERBOD block.
struct Body {
  std::string name;
  int number = kWorld;
  SourceLoc loc;
  std::vector<Feature> features;
  std::unordered_map<std::string, int> feature_index;  ///< name -> index in features
  std::unordered_map<std::string, Point> points;
  std::unordered_map<std::string, Line> lines;
  std::unordered_map<std::string, Circle> circles;
};

/// A feature of a body: (body number, index in Body::features).
struct FeatureId {
  int body = 0;
  int index = -1;
  bool valid() const noexcept { return body > 0 && index >= 0; }
  friend bool operator==(const FeatureId&, const FeatureId&) = default;
};

/// One input relation as written (Table 3.1), with its resolved features.
struct RelationDecl {
  RelKeyword kind = RelKeyword::kAgainst;
  FeatureId a;
  FeatureId b;
  SourceLoc loc;
};

/// What produced a situation.
enum class ActionKind : std::uint8_t {
  kStart,   ///< situation 1
  kMove,    ///< MOVE (general, explicit or implicit)
  kTurn,    ///< TURN (explicit or implicit)
  kVision,  ///< a COMBINE ... TERCOM package (changes knowledge, not nominal positions)
};

/// The action between situation s-1 and s (the "action table", thesis §7.6.2).
struct Action {
  ActionKind kind = ActionKind::kStart;
  int body = 0;  ///< moved body (kMove/kTurn), verified (kVision)
  ast::ActionMode mode = ast::ActionMode::kGeneral;
  std::optional<FeatureId> feature;  ///< PERPTO/PARLEL/ABOUT feature
  std::optional<double> amount;      ///< mm (MOVE) or rad (TURN); none if implicit
  int package = -1;                  ///< kVision: index in Program::packages
  SourceLoc loc;
};

/// TIED / UNTIED declared in a situation (effective for the next action).
struct TieChange {
  bool tied = true;
  int a = 0;
  int b = 0;
  SourceLoc loc;
};

/// ISSUB / NOSUB declared in a situation (effective for the next action).
struct SubassChange {
  bool on = true;
  int subassembly = -1;
  SourceLoc loc;
};

/// A world state between two actions.
struct Situation {
  int number = 1;
  Action action;                        ///< the action that produced it
  std::vector<RelationDecl> relations;  ///< relations stated in this situation
  std::vector<TieChange> tie_changes;
  std::vector<SubassChange> subass_changes;
};

/// A camera (thesis §5.6). Immovable: fixed pose from its lens centre and THETA/PHI/PSI.
/// General: the frame of a body (lens axis = body X, lens centre = body origin).
struct Camera {
  std::string name;
  std::string physical;  ///< the physical camera's name ("" for POSITION)
  bool general = false;
  int body = 0;                            ///< general cameras: the camera body
  Pose world_T_camera = Pose::Identity();  ///< immovable cameras; X = lens axis
  double focus = 0.0;                      ///< focal length F, image units (mm)
  SourceLoc loc;
};

/// INVIOLATE/AGAINST, <reference>, <verified face> (only AGPP is implemented, thesis §5.3).
struct InviolateDecl {
  FeatureId reference;  ///< the world's or a world-fixed body's face
  FeatureId verified;   ///< a face of the verified body
  SourceLoc loc;
};

/// LOOK/<edge of body> [, camera].
struct LookDecl {
  FeatureId edge;
  int camera = -1;  ///< index in Program::cameras
  SourceLoc loc;
};

/// One COMBINE ... TERCOM vision package; it creates situation `situation`.
struct Package {
  int situation = 0;
  int body = 0;  ///< the verified body BV
  std::vector<InviolateDecl> inviolates;
  std::vector<LookDecl> looks;
  std::optional<double> local_tolerance;  ///< TOLERANCE/TRAN inside the package [mm]
  SourceLoc loc;                          ///< COMBINE
};

/// A subassembly (thesis §3.2.5): relations that hold while it exists.
struct Subassembly {
  std::string name;
  bool permanent = true;
  std::vector<RelationDecl> relations;
  std::vector<int> bodies;  ///< members (bodies of its relations)
  SourceLoc loc;
};

/// A whole analysed program.
struct Program {
  std::string file;
  std::vector<Body> bodies;           ///< bodies[0] is the world
  std::vector<Situation> situations;  ///< situations[0] is situation 1
  std::vector<Camera> cameras;
  std::vector<Package> packages;
  std::vector<Subassembly> subassemblies;
  std::vector<int> agents;                 ///< AGENT bodies
  std::map<int, double> global_tolerance;  ///< TOLERANCE/<body>,TRAN,d [mm]

  /// Tie table: for each situation s (index s-1), the TIEs in force after its declarations,
  /// i.e. during the action from s to s+1. Pairs are (lower, higher) body numbers.
  std::vector<std::vector<std::pair<int, int>>> ties_after;
  /// Subassemblies active after each situation's declarations (indices into subassemblies).
  std::vector<std::vector<int>> subass_after;
  /// For each situation s (index s-1): the bodies the action into s moves (the mover, bodies
  /// tied to it, members of its active subassemblies). Empty for situation 1 and vision
  /// packages. Every other body is in the unmoved body table of s.
  std::vector<std::vector<int>> moved;

  int body_count() const noexcept { return static_cast<int>(bodies.size()); }
  int situation_count() const noexcept { return static_cast<int>(situations.size()); }
  const Body& body(int number) const { return bodies.at(static_cast<std::size_t>(number - 1)); }
  const Situation& situation(int s) const { return situations.at(static_cast<std::size_t>(s - 1)); }
  const Feature& feature(FeatureId id) const {
    return body(id.body).features.at(static_cast<std::size_t>(id.index));
  }
  /// "e1 of b3".
  std::string feature_name(FeatureId id) const;
  /// Body number by (lower-case) name, or 0.
  int find_body(std::string_view name) const;
  /// True when `body` moves in the action into situation s.
  bool is_moved(int body, int s) const;
  /// The unmoved bodies of situation s (thesis §3.2.6), world excluded.
  std::vector<int> unmoved(int s) const;
};

}  // namespace cell::rapt
