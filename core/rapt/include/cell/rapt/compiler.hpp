#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "cell/common/result.hpp"
#include "cell/rapt/mf_array.hpp"
#include "cell/rapt/model.hpp"
#include "cell/rapt/nominal.hpp"
#include "cell/rapt/source.hpp"
#include "cell/rapt/vision.hpp"

/// The RAPT compiler: source text -> tokens -> AST -> program model -> nominal positions
/// (cycle finder) -> vision packages (symbolic routes, predictions, windows) -> MF array
/// (linking, then simplification). Everything the run time needs is in CompiledProgram.
namespace cell::rapt {

/// Options of a compilation.
struct CompileOptions {
  NominalOptions nominal;  ///< the cycle finder's tolerances and bounds
  VisionOptions vision;    ///< default tolerance, degenerate-angle threshold
};

/// A compiled program. Immutable; the run time (runtime.hpp) only reads it.
struct CompiledProgram {
  Program program;                        ///< the analysed program (bodies, situations, tables)
  NominalSolution nominal;                ///< PN of every body instance
  std::vector<CompiledPackage> packages;  ///< in program order (index = package index)
  MfArray mf_before;                      ///< after the linking rules
  MfArray mf_after;                       ///< after simplification
  LinkResult link;                        ///< rules applied, package scopes, warnings
  std::vector<std::string> body_names;    ///< index = body number - 1

  /// PN: world_T_body of a body in a situation (the program compiled, so it is known).
  const Pose& nominal_pose(int body, int situation) const;
};

/// The linking rules' view of a program: per situation, the action (move or vision) with
/// whether a MOVE is specified (relations, possibly in later situations while the body does
/// not move again, tie its destination to another body: thesis §7.3.2) and its references;
/// and the TIE / subassembly changes. Exposed for tests.
LinkInput link_input(const Program& program, const std::vector<CompiledPackage>& packages);

/// Compiles RAPT source text; `file` names it in diagnostics. Every error of every stage goes
/// to `diags` (stages after a failing one are skipped so that errors do not cascade; all
/// syntax and semantic errors are still reported together). Returns the program, or kConfig
/// with every error ("file:line:col: error: ...", one per line). Warnings (e.g. a package
/// that cannot fix its body) stay in `diags`.
Result<CompiledProgram> compile(std::string_view source,
                                const std::string& file,
                                Diagnostics& diags,
                                const CompileOptions& options = {});

/// Reads and compiles a file. Errors: kIo when it cannot be read, else as compile().
Result<CompiledProgram> compile_file(const std::string& path,
                                     Diagnostics& diags,
                                     const CompileOptions& options = {});

}  // namespace cell::rapt
