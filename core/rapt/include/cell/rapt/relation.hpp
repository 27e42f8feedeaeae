#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "cell/rapt/frames.hpp"
#include "cell/rapt/source.hpp"

/// The cycle finder's relations (digest 003 §1.5, thesis §3.3.3, Appendix I) and the geometry
/// behind its combination and creation rules.
///
/// A relation (r, F1, F2) between network nodes A and B (body instances, or merged groups of
/// them) says, in the thesis's words, f2 ** p2 = rel(v) ** f1 ** p1. In our column form, with
/// the features' frames a_T_fa and b_T_fb:
///     a_T_b  is in  a_T_fa * S_r * fb_T_b
/// where S_r is the set of relative feature placements the type allows (X = normal/axis):
///
///   | type   | S_r                                   | meaning                            |
///   |--------|---------------------------------------|------------------------------------|
///   | FIX    | {I}                                   | frames coincide                    |
///   | LIN    | Trans(x,0,0)                          | X collinear, Y parallel            |
///   | LINLIN | Trans(0,y,z)                          | AGPP without rotation              |
///   | ROT    | Rx(th)                                | X collinear, origins coincide      |
///   | FITS   | Trans(x,0,0) Rx(th) M                 | axes collinear, opposed            |
///   | AGPP   | Trans(0,y,z) Rx(th) M                 | coplanar faces, opposed normals    |
///   | PARAX  | Trans(x,y,z) Rx(th) M                 | X parallel, opposed                |
///   | AGPC   | plane fa, cylinder fb: axis in the plane offset by the radius, axis _|_ normal |
///   | AGPS   | plane fa, sphere fb: centre on the plane offset by the radius             |
///   | AGSS   | spheres: centre distance = sum of radii                                   |
///
/// (M = flip_x(), the thesis's half turn about Y.) Every type is equivalent to a small set of
/// primitive constraints on the unknown a_T_b = (R, t): rotation constraints (R fixed, R v = w,
/// R v _|_ w) and point constraints (a point of B on a point/line/plane of A, ...). The
/// combination rules of Table 1 are the intersection of two relations' sets and the creation
/// rules of Table 2 the product along a chain; both are computed here by one solver over those
/// primitives and the result is classified back into one of the ten types (the rule tables in
/// rule_tables.hpp decide which pairs may be combined and which results are admissible).
namespace cell::rapt {

/// The ten relation types of the cycle finder, in Appendix I order.
enum class RelType : std::uint8_t {
  kAgpp,
  kFits,
  kAgpc,
  kAgps,
  kAgss,
  kParax,
  kLin,
  kLinlin,
  kRot,
  kFix
};

/// Number of relation types.
inline constexpr int kRelTypeCount = 10;

/// "AGPP", "FITS", ...
const char* to_string(RelType t) noexcept;

/// Degrees of freedom of a relation type (Appendix I): translational ("spatial"), rotational.
struct Dof {
  int translational = 0;
  int rotational = 0;
};
/// Appendix I's table.
Dof dof(RelType t) noexcept;

/// A relation between two network nodes. Frames are in the nodes' frames (mm).
struct Relation {
  RelType type = RelType::kFix;
  int a = -1;  ///< first node
  int b = -1;  ///< second node
  Pose a_T_fa = Pose::Identity();
  Pose b_T_fb = Pose::Identity();
  /// AGPC/AGPS: distance of the cylinder axis / sphere centre from the plane along its normal
  /// (the radius); AGSS: distance between the centres (sum of radii) [mm].
  double offset = 0.0;
  /// AGPC/AGPS only: true when the plane is fb (node b's feature), false when it is fa.
  bool plane_on_b = false;
  /// True when produced by a creation rule marked '*' (looser than the truth).
  bool looser = false;
  /// The statements this relation derives from (for messages).
  std::vector<SourceLoc> sources;
};

/// The same relation seen from b to a (a_T_b in S becomes b_T_a in the swapped set; exact for
/// every type).
Relation reversed(const Relation& r);

/// Tolerances of the compatibility checks ("within a range pre-specified by the user",
/// thesis §3.3.3.3).
struct Tolerances {
  double linear_mm = 1e-3;    ///< distances
  double angular_rad = 1e-6;  ///< angles
};

/// What a combination or creation produced.
enum class Outcome : std::uint8_t {
  kOk,             ///< `relation` holds the result
  kTwoSolutions,   ///< two discrete results, "(2)" in the tables: reasoning cannot go on
  kInexpressible,  ///< the result is not one of the ten types ("-" in the tables)
  kIncompatible,   ///< the relations contradict each other beyond the tolerances
};

/// Result of `intersect` or `compose`.
struct SolveResult {
  Outcome outcome = Outcome::kInexpressible;
  Relation relation;          ///< valid when outcome == kOk (between the inputs' outer nodes)
  std::string detail;         ///< why, for kIncompatible/kInexpressible/kTwoSolutions
  double residual_mm = 0.0;   ///< kIncompatible: the largest linear residual
  double residual_rad = 0.0;  ///< kIncompatible: the largest angular residual
};

/// Combination (Table 1): the relation equivalent to `r1` AND `r2`, which must join the same
/// two nodes (in either orientation; the result is oriented like r1). The result's features
/// are virtual features (thesis §3.3.3.3) chosen so that the type's S_r reproduces the
/// intersection exactly. Pure; allocation: the result's vectors.
SolveResult intersect(const Relation& r1, const Relation& r2, const Tolerances& tol);

/// Creation (Table 2): the relation implied between r12.a and r23.b by the chain
/// r12 (a -> mid) and r23 (mid -> b) with r12.b == r23.a. Only the seven "group" types (FIX,
/// LIN, LINLIN, ROT, FITS, AGPP, PARAX) compose; a result that is not a type of its own is
/// loosened to PARAX and marked `looser` (Table 2's '*'), or kInexpressible when even that
/// does not hold (rotations about non-parallel axes).
SolveResult compose(const Relation& r12, const Relation& r23, const Tolerances& tol);

/// How far the known relative pose a_T_b is from satisfying `r`: {largest angular residual
/// [rad], largest linear residual [mm]}. Used for the compatibility check of a relation whose
/// two nodes are already merged.
std::pair<double, double> residual(const Relation& r, const Pose& a_T_b);

/// For a FIX relation: the relative pose a_T_b it fixes.
Pose fixed_pose(const Relation& r);

}  // namespace cell::rapt
