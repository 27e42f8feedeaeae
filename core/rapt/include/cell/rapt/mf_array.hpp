#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "cell/rapt/frames.hpp"
#include "cell/rapt/source.hpp"

/// The modifying factor (MF) array (digest 003 §4, thesis ch. 7-8).
///
/// For body b in situation s the actual (verified) position is PV = FM ** PN (thesis (7.1),
/// row form). In our column form: world_T_actual = world_T_nominal * FM, FM acting in the body's
/// nominal frame (frames.hpp). Each entry of the array is, at compile time:
///   I        independent of vision (FM = identity);
///   P        verified by a vision package: the package's symbolic position, evaluated at run
///            time, FM = PN^-1 * PV (thesis (7.2): FM = PV ** PN^-1);
///   B,S      a pointer: to the same body in S = s-1 it means equality (7.6); to another body
///            in the same situation it is interpreted by (7.11);
///   [B,S]    a pointer triple [(A,S-1), (B,S-1), (B,S)] for body A, interpreted by (8.11).
/// Linking rules A1, A2 (with the multi-reference check), T1-T9, S1-S2 and R1 fill the array
/// from an abstract description of the program (LinkInput), so they can be tested on the
/// thesis's own examples; simplification rules 1-3 then replace what resolves to I.
namespace cell::rapt {

/// A reference to an array entry: body number and situation (both 1-based).
struct MfRef {
  int body = 0;       ///< body number (world = 1)
  int situation = 0;  ///< situation number
  friend bool operator==(const MfRef&, const MfRef&) = default;
};

/// One entry of the MF array.
struct MfEntry {
  /// I, P, B,S or [B,S].
  enum class Kind : std::uint8_t { kIdentity, kVerified, kPointer, kTriple };
  Kind kind = Kind::kIdentity;    ///< which of the four
  MfRef pointer;                  ///< kPointer
  std::array<MfRef, 3> triple{};  ///< kTriple: [p1, p2, p3]
  int package = -1;               ///< kVerified: index of the vision package
  friend bool operator==(const MfEntry&, const MfEntry&) = default;

  static MfEntry identity() { return {}; }
  static MfEntry verified(int package);
  static MfEntry points_to(int body, int situation);
  static MfEntry triple_of(int body, int situation, int via_body);  ///< [via,S] of `body`
};

/// The array, indexed by body number and situation (1-based).
class MfArray {
 public:
  MfArray() = default;
  MfArray(int bodies, int situations);

  /// Number of bodies (world included).
  int bodies() const noexcept { return bodies_; }
  /// Number of situations.
  int situations() const noexcept { return situations_; }
  /// The entry of a body in a situation (1-based); out of range is a programmer error
  /// (CELL_CHECK).
  MfEntry& at(int body, int situation);
  /// The entry of a body in a situation (1-based).
  const MfEntry& at(int body, int situation) const;

  /// The thesis's notation of one entry: "I", "P", "3,12", "[4,16]" (numbers as in Appendix
  /// V, world = 1). A triple not of the canonical [(A,S-1),(B,S-1),(B,S)] form prints in full.
  std::string notation(int body, int situation) const;
  /// The same with body names: "b2,12", "[b3,16]".
  std::string named(int body, int situation, const std::vector<std::string>& names) const;

  friend bool operator==(const MfArray&, const MfArray&) = default;

 private:
  int bodies_ = 0;
  int situations_ = 0;
  std::vector<MfEntry> entries_;
};

/// What happened between situation s-1 and s, as the linking rules see it.
struct LinkEvent {
  /// No action (situation 1), a MOVE/TURN, or a vision package.
  enum class Kind : std::uint8_t { kNone, kMove, kVision };
  Kind kind = Kind::kNone;  ///< what happened
  int body = 0;             ///< kMove: the moved body; kVision: the verified body
  // kMove:
  bool specified = false;       ///< relations constrain the destination (thesis §7.3.2)
  int referenced_member = 0;    ///< the moving group's body named in those relations
  std::vector<int> references;  ///< reference bodies, in the order of the relations
  // kVision:
  bool fixable = true;                    ///< the package can fix its body (else it is ignored)
  std::vector<int> inviolate_references;  ///< bodies of the INVIOLATE reference features
  std::vector<int> camera_bodies;         ///< bodies of the general cameras the package uses
  int package = -1;                       ///< kVision: the package index
  SourceLoc loc;                          ///< the action or COMBINE statement, for warnings
};

/// TIED/UNTIED (and ISSUB/NOSUB as groups of links) declared in a situation, effective for the
/// next action.
struct LinkChange {
  bool tied = true;        ///< TIED (true) or UNTIED
  int a = 0;               ///< a body number
  int b = 0;               ///< the other body number
  bool permanent = false;  ///< a permanent subassembly link (never revoked)
};

/// The program as the linking rules see it.
struct LinkInput {
  int bodies = 0;  ///< including the world (body 1)
  int situations = 0;
  std::vector<LinkEvent> events;                 ///< per situation (index s-1); [0] unused
  std::vector<std::vector<LinkChange>> changes;  ///< per situation (index s-1)
};

/// One package's scope as decided by the linker.
struct PackageScope {
  int package = -1;    ///< package index
  bool local = false;  ///< T3: only the verified body changes
  std::string reason;  ///< "INVIOLATE reference b1 is TIED to b3", "T9: ...", "R1: ..."
};

/// What the linker produced: the array before simplification, decisions and warnings.
struct LinkResult {
  MfArray array;                     ///< before simplification
  std::vector<PackageScope> scopes;  ///< one per vision package, in situation order
  /// Warnings (multi-reference check failed, S2 applied), with the event's position.
  std::vector<std::pair<SourceLoc, std::string>> warnings;
  /// For each situation (index s-1), the rule applied to each body ("A1", "A2", "T1", ...).
  std::vector<std::vector<std::string>> rules;
};

/// Applies the initiation phase (situation 1 and the world are I) and the linking rules A1, A2,
/// T1-T9, S1, S2 and R1 (digest §4.4) situation by situation. `body_names` (index = number-1)
/// are used in warnings. Pure.
LinkResult link(const LinkInput& input, const std::vector<std::string>& body_names);

/// Simplification rules 1-3 (digest §4.5) to a fixpoint: a pointer whose target resolves to I
/// becomes I; a triple whose p1 and p2 resolve to I becomes p3; a triple whose p2 and p3
/// resolve to I, or whose p3 points to p2, becomes p1. Pointers to P are kept. Pure.
MfArray simplify(const MfArray& array);

/// True when the entry resolves to I through pointers (following rules 1-3).
bool resolves_to_identity(const MfArray& array, MfRef ref);

/// The thesis's run-time interpretations, column form (world_T_x poses, FM in the body's nominal
/// frame). Each mirrors one equation; tests pin them against the row-form originals.
namespace mf_equations {
/// (7.2)  FM = PV ** PN^-1   ->  FM_col = PN^-1 * PV
Pose from_verified(const Pose& world_T_nominal, const Pose& world_T_verified);
/// (7.11) FM_a = PN_a ** PN_b^-1 ** FM_b ** PN_b ** PN_a^-1
///        -> FM_a_col = PN_a^-1 * PN_b * FM_b * PN_b^-1 * PN_a
Pose specified(const Pose& pn_a, const Pose& pn_b, const Pose& fm_b);
/// (8.11) FM_b(i+1) = FM_bi ** PN_bi ** (FM_ai ** PN_ai)^-1 ** FM_a(i+1) ** PN_a(i+1) **
///        PN_b(i+1)^-1   -> column: PN_b(i+1)^-1 * PV_a(i+1) * PV_ai^-1 * PV_bi
Pose triple(const Pose& fm_b_i,
            const Pose& pn_b_i,
            const Pose& fm_a_i,
            const Pose& pn_a_i,
            const Pose& fm_a_j,
            const Pose& pn_a_j,
            const Pose& pn_b_j);
}  // namespace mf_equations

}  // namespace cell::rapt
