#pragma once

#include <optional>
#include <vector>

#include "cell/rapt/model.hpp"
#include "cell/rapt/relation.hpp"
#include "cell/rapt/source.hpp"

/// Nominal inference: the cycle finder (digest 003 §1.5, thesis §3.3.3).
///
/// The network's nodes are body instances (body, situation); its arcs are the relations of
/// each situation, the relations implied by actions (an explicit MOVE/TURN fixes the instance
/// after it to the one before; an implicit one gives LIN, LINLIN or ROT; a general MOVE gives
/// nothing), the identity between the instances of an unmoved body, the TIE links (a body tied
/// to the mover keeps its pose relative to it) and the relations of active subassemblies.
/// The engine repeats until nothing changes:
///   1. combination rules (Table 1) on every 2-cycle, i.e. several arcs between the same two
///      nodes, with compatibility checks within the tolerances;
///   2. merging: every FIX removes a node, the higher body number always merging into the
///      lower, so the world (body 1) stays the root;
///   3. when nothing combines, creation rules (Table 2) along chains p1-p2-p3 that lie on a
///      cycle, which shrinks it toward a 2-cycle.
/// Success is a network reduced to the world: every instance's world_T_body is known.
namespace cell::rapt {

/// Options of the engine.
struct NominalOptions {
  Tolerances tolerances;   ///< compatibility checks
  int max_rounds = 10000;  ///< bound on passes (never reached by sane programs)
  int max_created = 2000;  ///< bound on relations made by creation rules
};

/// Nominal positions of every body instance.
struct NominalSolution {
  int bodies = 0;
  int situations = 0;
  /// world_T_body of (body, situation) at index (body-1)*situations + (situation-1);
  /// nullopt when the program leaves it undetermined.
  std::vector<std::optional<Pose>> poses;
  int combinations = 0;  ///< combination rules applied
  int creations = 0;     ///< creation rules applied
  int merges = 0;        ///< FIX merges (including unmoved bodies and explicit actions)

  /// world_T_body of a body in a situation (nullopt when undetermined or out of range).
  const std::optional<Pose>& pose(int body, int situation) const;
  /// True when every instance is determined.
  bool complete() const;
};

/// Runs the cycle finder on `program`. Every inconsistency ("the relations at 12:1 and 14:1
/// are incompatible in situation 3: the positions disagree by 2.5 mm") and every instance left
/// undetermined ("the position of b1 in situations 2-3 is not determined: ...", naming the
/// relations that remain and why they could not be combined) is reported to `diags` at the
/// position of the statements concerned. Pure apart from `diags`; allocation proportional to
/// bodies x situations + relations.
/// A stated relation as the solver's Relation between its two bodies' frames (a = decl.a's
/// body number, b = decl.b's): COPLANAR, ALIGNED and PARALLEL with their direction flipped.
Relation relation_of(const Program& program, const RelationDecl& decl);

/// How far two bodies at world_T_a and world_T_b (decl.a's body and decl.b's) are from
/// satisfying a stated relation: {largest angular residual [rad], largest linear residual
/// [mm]} (relation.hpp residual()). Checks an assembly's final situation by measured poses.
std::pair<double, double> relation_residual(const Program& program,
                                            const RelationDecl& decl,
                                            const Pose& world_T_a,
                                            const Pose& world_T_b);

NominalSolution infer_nominal(const Program& program,
                              Diagnostics& diags,
                              const NominalOptions& options = {});

}  // namespace cell::rapt
