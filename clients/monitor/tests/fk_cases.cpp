// monitor_fk_cases SOURCE_DIR: the robot models exactly as /api/config serves them to the page
// (codec's robot_model_json) and core/kinematics' forward kinematics of random joint vectors
// within each robot's limits, as JSON on stdout. web/tests/fk_agreement.test.mjs computes the
// browser's FK of the same joints and compares (ctest monitor_web.fk_agrees_with_core_kinematics).
#include <cstdio>
#include <exception>
#include <iostream>
#include <random>
#include <string>

#include <fmt/format.h>

#include "cell/kinematics/robot_config.hpp"
#include "codec.hpp"

static int main_body(int argc, char** argv) {
  using namespace cell;
  if (argc != 2) {
    std::cerr << "usage: monitor_fk_cases SOURCE_DIR\n";
    return 2;
  }
  constexpr int kCasesPerRobot = 2000;
  std::mt19937_64 rng(1992);
  nlohmann::json robots = nlohmann::json::array();
  nlohmann::json cases = nlohmann::json::array();
  for (const char* id : {"ibm7545", "scara_picker", "excalibur"}) {
    const std::string path = fmt::format("{}/config/robots/{}.yaml", argv[1], id);
    auto model = kinematics::load_robot(path);
    if (!model) {
      std::cerr << "monitor_fk_cases: " << model.error().message << "\n";
      return 1;
    }
    robots.push_back(monitor::robot_model_json(*model, Eigen::Isometry3d::Identity()));
    for (int n = 0; n < kCasesPerRobot; ++n) {
      kinematics::JointVector q(model->dof());
      for (int k = 0; k < model->dof(); ++k) {
        const auto& joint = model->joints()[static_cast<std::size_t>(k)];
        // Within the limits, plus a margin beyond them: FK must agree everywhere.
        const double span = joint.upper - joint.lower;
        q[k] = std::uniform_real_distribution<double>(joint.lower - 0.1 * span,
                                                      joint.upper + 0.1 * span)(rng);
      }
      auto base_T_tool = model->forward(q);
      if (!base_T_tool) {
        std::cerr << "monitor_fk_cases: " << base_T_tool.error().message << "\n";
        return 1;
      }
      nlohmann::json qj = nlohmann::json::array();
      for (int k = 0; k < q.size(); ++k) {
        qj.push_back(q[k]);
      }
      nlohmann::json m = nlohmann::json::array();  // row-major 4x4, as kinematics.js
      for (int r = 0; r < 4; ++r) {
        for (int c = 0; c < 4; ++c) {
          m.push_back(base_T_tool->matrix()(r, c));
        }
      }
      cases.push_back({{"robot", id}, {"q", qj}, {"base_T_tool", m}});
    }
  }
  std::cout << monitor::to_text({{"robots", robots}, {"cases", cases}}) << "\n";
  return 0;
}

// Nothing escapes main: an exception is printed and fails the run.
int main(int argc, char** argv) {
  try {
    return main_body(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "monitor_fk_cases: %s\n", e.what());
  } catch (...) {
    std::fprintf(stderr, "monitor_fk_cases: an exception not derived from std::exception\n");
  }
  return 1;
}
