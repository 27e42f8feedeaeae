#pragma once

#include <Eigen/Geometry>
#include <array>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "cell/common/result.hpp"
#include "cell/rapt/camera.hpp"
#include "cell/rapt/model.hpp"
#include "cell/rapt/nominal.hpp"
#include "cell/rapt/rule_tables.hpp"
#include "cell/rapt/source.hpp"

/// Vision packages (COMBINE; INVIOLATE/...; LOOK/...; TOLERANCE/...; TERCOM), digest 003 §2-§3:
/// the COMBINE checks, the tolerance combination (5.1)/(5.2), the camera predictions and search
/// windows of every LOOK, and the symbolic reasoning done at compile time.
///
/// Symbolic reasoning (thesis ch. 6, "top-level" implementation): the relations of a package
/// hold between the world and the verified body BV. Stage 1 combines the trusted AGPPs of the
/// INVIOLATEs (AGPP+AGPP -> LIN, or AGPP when parallel; a third gives FIX); stage 2 appends the
/// AGPEs of the LOOKs (AGPP+AGPE -> LIN, LIN+AGPE -> FIX) following Table 6.2. A LOOK whose
/// edge is parallel to the INVIOLATE face normal would give ROTYLIN and is skipped (the next
/// LOOK is tried, and the skipped one may serve later against the LIN); a LOOK whose nominal
/// face contains the LIN direction cannot pin the slide and is skipped too. Since relation
/// types are known at compile time and top-level conditionals are decided from nominal
/// geometry, the route is fixed at compile time: it is kept as a small expression of deferred
/// top-level rule calls whose symbolic arguments (the LOOK faces, and the INVIOLATE reference
/// features of bodies whose modifying factor is not I, (7.20)) are bound at run time. A package
/// that cannot reach FIX is reported at compile time and ignored at run time.
namespace cell::rapt {

/// One node of a package's route.
struct RouteNode {
  enum class Kind : std::uint8_t {
    kInviolate,  ///< the AGPP of INVIOLATE `index` (reference feature as FM*PN, (7.20))
    kLookFace,   ///< the symbolic world face of LOOK `index` (face generator at run time)
    kCall,       ///< a top-level rule function applied to two nodes
  };
  Kind kind = Kind::kInviolate;
  int index = -1;
  SymbolicFunction function = SymbolicFunction::kAgppAgppLin;
  int arg0 = -1;                  ///< node index
  int arg1 = -1;                  ///< node index
  int edge_look = -1;             ///< calls with an AGPE: the LOOK whose edge is used
  RelType type = RelType::kAgpp;  ///< the relation type this node yields
};

/// A package's route: nodes in evaluation order, the last one the root.
struct Route {
  std::vector<RouteNode> nodes;
  RelType reached = RelType::kAgpp;  ///< the type of the root (FIX when the package can fix)
};

/// Compile-time information about one LOOK.
struct CompiledLook {
  LookDecl decl;
  bool used = false;                      ///< the route uses this LOOK
  std::string note;                       ///< why it is not used (ROTYLIN, redundant, ...)
  std::array<ImagePoint, 2> predicted{};  ///< nominal image of the edge's two end points
  Window window;                          ///< search window at the nominal position
};

/// A vision package after compilation.
struct CompiledPackage {
  int index = -1;
  int situation = 0;
  int body = 0;
  SourceLoc loc;
  double tolerance_mm = 0.0;     ///< d: local, else global, else the default
  std::string tolerance_source;  ///< "local", "global", "default"
  Eigen::Vector3d combined_tolerance_mm = Eigen::Vector3d::Zero();  ///< (5.1)/(5.2)
  std::vector<CompiledLook> looks;
  Route route;
  bool fixable = false;
  std::string cannot_fix;  ///< why not, when !fixable
  bool local = false;      ///< set by the MF linker (T3, T9, R1)
  std::string scope_reason;
};

/// Options of the package compiler.
struct VisionOptions {
  double default_tolerance_mm = 10.0;  ///< the "system default" tolerance (thesis §5.4)
  /// A LOOK whose edge is within this angle of the INVIOLATE face normal is treated as
  /// ROTYLIN, and one whose nominal face is within it of the LIN direction as unable to pin the
  /// slide; both are skipped.
  double degenerate_angle_rad = 0.5 * 3.14159265358979323846 / 180.0;
  Tolerances tolerances;  ///< INVIOLATE compatibility at the nominal position
};

/// The combined translational tolerance (thesis §5.5.2): with d the tolerance and the unit
/// normals (X axes) of the INVIOLATE reference faces: none -> (d, d, d); one, or all parallel
/// -> (d(1-a^2), d(1-b^2), d(1-c^2)) (5.2); two independent with unit cross product (a, b, c)
/// -> (|da|, |db|, |dc|) (5.1); three independent -> 0. Exact for axis-aligned faces only, as
/// the thesis says. The cross product is normalised (the thesis's examples are orthogonal).
Eigen::Vector3d combine_tolerance(double d, const std::vector<Eigen::Vector3d>& normals);

/// Compiles package `index` of `program`: COMBINE checks needing positions (INVIOLATE
/// references fixed in the world, INVIOLATEs holding at the nominal position and not
/// conflicting), tolerance, predictions and windows, and the route. Errors (with positions) go
/// to `diags`; "cannot fix" is a warning and leaves `fixable` false.
CompiledPackage compile_package(const Program& program,
                                const NominalSolution& nominal,
                                int index,
                                const VisionOptions& options,
                                Diagnostics& diags);

/// The route as text, e.g. "merge(lin_agpe_fix(agpp_agpp_lin(AGPP[f1 of world, f7 of b3],
/// AGPP[f2 of world, f8 of b3]), face[LOOK e1 of b3, cam1], e1 of b3))".
std::string route_text(const Program& program, const CompiledPackage& package);

/// What the route needs at run time.
struct RouteInputs {
  /// Actual world_T_body of each INVIOLATE's reference body (FM*PN of the situation before).
  std::vector<Pose> world_T_reference;
  /// Actual camera of each LOOK (immovable, or the camera body's FM*PN).
  std::vector<CameraModel> cameras;
  /// Measured image end points of each LOOK (nullopt: not measured).
  std::vector<std::optional<std::pair<ImagePoint, ImagePoint>>> readings;
  /// Nominal world_T_body of the verified body (PN of the package's situation).
  Pose world_T_nominal = Pose::Identity();
};

/// Evaluates a fixable package's route: the verified world_T_body (PV). Errors
/// (kInvalidArgument / kOutOfRange) name the LOOK and what went wrong: a missing reading,
/// coincident end points, a face that no rotation can satisfy, a face parallel to the LIN.
/// Allocation-free apart from a small vector of node values; RT-friendly.
Result<Pose> evaluate_route(const Program& program,
                            const CompiledPackage& package,
                            const RouteInputs& inputs);

}  // namespace cell::rapt
