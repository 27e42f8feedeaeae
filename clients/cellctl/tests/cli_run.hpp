#pragma once

#include <cmath>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "session.hpp"

namespace cell::cellctl::testing {

/// One in-process cellctl run: exit code and what it printed.
struct CliRun {
  int code = -1;
  std::string out;
  std::string err;
};

/// Runs cellctl with `args` (without the program name) in this process.
inline CliRun cellctl(std::vector<std::string> args) {
  args.insert(args.begin(), "cellctl");
  std::vector<const char*> argv;
  argv.reserve(args.size());
  for (const auto& a : args) {
    argv.push_back(a.c_str());
  }
  std::ostringstream out;
  std::ostringstream err;
  CliRun run;
  run.code = cell::cellctl::run(static_cast<int>(argv.size()), argv.data(), out, err);
  run.out = out.str();
  run.err = err.str();
  return run;
}

/// The value of joint `name` in cellctl's JSON joint list ([{"name": .., "value": ..}, ...]);
/// a test failure and NaN when the list has no such joint.
inline double value_of(const nlohmann::json& joints, const std::string& name) {
  for (const auto& j : joints) {
    if (j["name"] == name) {
      return j["value"].get<double>();
    }
  }
  ADD_FAILURE() << "no joint " << name << " in " << joints.dump();
  return NAN;
}

}  // namespace cell::cellctl::testing
