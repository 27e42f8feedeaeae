#pragma once

#include "cell/rapt/ast.hpp"
#include "cell/rapt/model.hpp"
#include "cell/rapt/source.hpp"

/// Semantic analysis: resolves names, builds bodies, features and their frames, cameras, the
/// situation sequence and its tables, and checks what the thesis requires (Table 3.1 feature
/// pairs, agents, ties to the world, COMBINE package rules, LOOK of finite edges, INVIOLATE
/// of faces). Checks that need nominal positions (an INVIOLATE reference that is not fixed in
/// the world) are done after inference (compiler.hpp).
namespace cell::rapt {

/// Analyses a parsed program. Every problem goes to `diags` with its position (e.g. "unknown
/// feature 'f9' of body 'b1'", "LOOK needs an edge: 'f1 of b1' is a face", "AGAINST between a
/// hole and a face is not allowed (AGAINST takes face-face, face-shaft, ...)"); analysis
/// continues past errors so that one run reports them all. The returned model is complete for
/// the statements that were valid. `file` is recorded in the model.
Program analyze(const ast::Program& ast, const std::string& file, Diagnostics& diags);

}  // namespace cell::rapt
