// Every cost functor's Jacobian (Ceres autodiff) against numeric differentiation, with
// ceres::GradientChecker (STYLE.md §9), at realistic parameter values.
#include "costs.hpp"

#include <memory>
#include <numbers>
#include <vector>

#include <ceres/gradient_checker.h>
#include <gtest/gtest.h>

namespace cell::calibration::detail {
namespace {

// Autodiff is exact; the numeric side carries an absolute noise near 1e-12, which makes the
// tiny k3 entries (about 1e-8: r^6 over a narrow field) differ relatively by up to 4e-4. A wrong
// derivative differs by its own size.
constexpr double kPrecision = 1e-3;

bool check(ceres::CostFunction* raw, std::vector<const double*> parameters, std::string* log) {
  std::unique_ptr<ceres::CostFunction> cost(raw);
  // GradientChecker differentiates with Ridders' method; its default first step (1 % of the
  // parameter) is far too coarse for a rotation near pi seen 400 mm away.
  ceres::NumericDiffOptions options;
  options.ridders_relative_initial_step_size = 1e-4;
  const std::vector<const ceres::Manifold*>* euclidean = nullptr;
  ceres::GradientChecker checker(cost.get(), euclidean, options);
  ceres::GradientChecker::ProbeResults results;
  const bool ok = checker.Probe(parameters.data(), kPrecision, &results);
  *log = results.error_log;
  return ok;
}

const double kIntrinsics[kIntrinsicsSize] = {1502.3, 1455.9, 258.4, 237.2, -0.12, 0.08,
                                             0.0006, -0.0004, 0.001};
const double kCameraTBoard[kPoseSize] = {3.05, 0.12, -0.2, -40.0, 25.0, 410.0};

TEST(Costs, BoardReprojectionJacobiansMatchNumeric) {
  std::string log;
  EXPECT_TRUE(check(BoardReprojection::create({300.0, 200.0}, {30.0, 20.0, 0.0}, 0.0),
                    {kIntrinsics, kCameraTBoard}, &log))
      << log;
  EXPECT_TRUE(check(BoardReprojection::create({300.0, 200.0}, {30.0, 20.0, 0.0}, 0.969),
                    {kIntrinsics, kCameraTBoard}, &log))
      << log;
}

TEST(Costs, HandEyeReprojectionJacobiansMatchNumeric) {
  const double mount[kPoseSize] = {0.1, -0.2, 2.5, 300.0, 450.0, 0.0};
  const double mount_T_camera[kPoseSize] = {0.01, 3.12, 0.03, -9.6, -117.2, 191.2};
  const double base_T_target[kPoseSize] = {0.0, 0.0, 0.4, 290.0, 545.0, -228.5};
  const double delta[kPoseSize] = {1e-4, -2e-4, 3e-4, 0.05, -0.02, 0.01};
  std::string log;
  EXPECT_TRUE(check(EyeInHandReprojection::create({250.0, 240.0}, {14.0, 21.0, 0.0}, mount),
                    {kIntrinsics, mount_T_camera, base_T_target, delta}, &log))
      << log;
  const double base_T_camera[kPoseSize] = {3.1, 0.02, -0.01, 352.8, 97.6, 801.2};
  const double mount_T_target[kPoseSize] = {0.005, -0.003, 0.02, -97.0, -72.0, -25.0};
  const double tool[kPoseSize] = {0.0, 0.0, 0.7, 350.0, 100.0, -150.0};
  EXPECT_TRUE(check(EyeToHandReprojection::create({500.0, 520.0}, {40.0, 60.0, 0.0}, tool),
                    {kIntrinsics, base_T_camera, mount_T_target, delta}, &log))
      << log;
  EXPECT_TRUE(check(PoseCorrectionPrior::create(0.05 * std::numbers::pi / 180.0, 0.1, 0.2),
                    {delta}, &log))
      << log;
}

TEST(Costs, PlanarReprojectionJacobiansMatchNumeric) {
  const double deg = std::numbers::pi / 180.0;
  const double planar[kPlanarSize] = {3.56, 3.48, 81.8, 137.7 * deg, 1.8 * deg, 400.0, 250.0};
  const double board[3] = {60.0, 440.0, 0.4};
  std::string log;
  EXPECT_TRUE(check(PlanarReprojection::create({120.0, 300.0}, {30.0, 20.0}, 45.0 * deg,
                                               105.0 * deg, 3.0, 457.0),
                    {planar, board}, &log))
      << log;
  EXPECT_TRUE(check(PlanarPointReprojection::create({120.0, 300.0}, {100.0, 480.0}, 45.0 * deg,
                                                    105.0 * deg, 3.0, 457.0),
                    {planar}, &log))
      << log;
}

}  // namespace
}  // namespace cell::calibration::detail
