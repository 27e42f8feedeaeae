#pragma once

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "cell/rapt/compiler.hpp"
#include "cell/rapt/runtime.hpp"
#include "cell/testing/env.hpp"

/// Shared fixtures of the rapt tests: the thesis's programs compiled once per process.
namespace cell::rapt::testing {

/// Absolute path of a file in the checkout (CELL_SOURCE_DIR, set by ctest).
inline std::string source_path(const std::string& relative) {
  return cell::testing::source_dir() + "/" + relative;
}

/// Compiles a checkout file; fails the test (and returns nullptr) on errors.
inline std::unique_ptr<CompiledProgram> compile_checkout_file(const std::string& relative) {
  Diagnostics diags(relative);
  auto cp = compile_file(source_path(relative), diags);
  if (!cp) {
    ADD_FAILURE() << cp.error().message;
    return nullptr;
  }
  return std::make_unique<CompiledProgram>(std::move(*cp));
}

/// config/rapt/appendix_v.rapt, compiled once.
inline const CompiledProgram& appendix_v() {
  static const std::unique_ptr<CompiledProgram> cp =
      compile_checkout_file("config/rapt/appendix_v.rapt");
  return *cp;
}

/// config/rapt/appendix_vi.rapt, compiled once.
inline const CompiledProgram& appendix_vi() {
  static const std::unique_ptr<CompiledProgram> cp =
      compile_checkout_file("config/rapt/appendix_vi.rapt");
  return *cp;
}

/// config/rapt/appendix_v_readings.yaml.
inline std::vector<Reading> appendix_v_readings() {
  auto r = load_readings(source_path("config/rapt/appendix_v_readings.yaml"));
  if (!r) {
    ADD_FAILURE() << r.error().message;
    return {};
  }
  return *r;
}

/// Body number by name in a compiled program.
inline int body(const CompiledProgram& cp, const std::string& name) {
  return cp.program.find_body(name);
}

/// A pose from the thesis's row form: rows X, Y, Z axes, then the translation.
inline Pose thesis_pose(const Eigen::Vector3d& x,
                        const Eigen::Vector3d& y,
                        const Eigen::Vector3d& z,
                        const Eigen::Vector3d& t) {
  Pose p = Pose::Identity();
  p.linear().col(0) = x;
  p.linear().col(1) = y;
  p.linear().col(2) = z;
  p.translation() = t;
  return p;
}

/// Compiles source text; returns the diagnostics (and the program when it compiled).
struct Compiled {
  Diagnostics diags{"test.rapt"};
  std::optional<CompiledProgram> program;
};
inline Compiled compile_text(const std::string& text) {
  Compiled out;
  auto cp = compile(text, "test.rapt", out.diags);
  if (cp) {
    out.program = std::move(*cp);
  }
  return out;
}

/// True when some diagnostic of `diags` is at (line, column) and contains `text`.
inline bool has_diagnostic(const Diagnostics& diags,
                           std::uint32_t line,
                           std::uint32_t column,
                           const std::string& text) {
  for (const Diagnostic& d : diags.items()) {
    if (d.loc.line == line && d.loc.column == column && d.message.find(text) != std::string::npos) {
      return true;
    }
  }
  return false;
}

/// Every diagnostic, formatted (for failure messages).
inline std::string all(const Diagnostics& diags) { return diags.format_all(); }

}  // namespace cell::rapt::testing
