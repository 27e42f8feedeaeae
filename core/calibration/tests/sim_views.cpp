#include "sim_views.hpp"

#include <cmath>
#include <numbers>
#include <optional>

#include <fmt/format.h>
#include <gtest/gtest.h>

#include "cell/kinematics/robot_config.hpp"
#include "cell/render/mount.hpp"
#include "cell/testing/env.hpp"

namespace cell::calibration::testing {

render::CameraDescription camera_file(const std::string& name) {
  auto c = render::load_camera(cell::testing::source_dir() + "/config/cameras/" + name);
  EXPECT_TRUE(c) << c.error().message;
  return *c;
}

kinematics::RobotModel robot_file(const std::string& name) {
  auto r = kinematics::load_robot(cell::testing::source_dir() + "/config/robots/" + name);
  EXPECT_TRUE(r) << r.error().message;
  return *r;
}

render::Chessboard chessboard_target(const BoardSpec& spec, const Eigen::Isometry3d& world_T_board) {
  render::Chessboard board;
  board.id = "board";
  board.squares_x = spec.columns + 1;
  board.squares_y = spec.rows + 1;
  board.square_mm = spec.square_mm;
  board.margin_mm = 12.0;
  board.world_T_board = world_T_board;
  return board;
}

Eigen::Isometry3d board_facing_camera(const BoardSpec& spec, const Eigen::Vector3d& center_camera,
                                      double roll, double tilt_x, double tilt_y) {
  // Facing: board z toward the camera (camera -z), board x along camera x.
  const Eigen::Matrix3d facing = Eigen::Vector3d(1.0, -1.0, -1.0).asDiagonal();
  const Eigen::Matrix3d r = Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitZ()).toRotationMatrix() *
                            facing *
                            Eigen::AngleAxisd(tilt_x, Eigen::Vector3d::UnitX()).toRotationMatrix() *
                            Eigen::AngleAxisd(tilt_y, Eigen::Vector3d::UnitY()).toRotationMatrix();
  const Eigen::Vector3d half((spec.columns + 1) * spec.square_mm / 2.0,
                             (spec.rows + 1) * spec.square_mm / 2.0, 0.0);
  Eigen::Isometry3d camera_T_board = Eigen::Isometry3d::Identity();
  camera_T_board.linear() = r;
  camera_T_board.translation() = center_camera - r * half;
  return camera_T_board;
}

cv::Mat render_view(const render::CameraModel& camera, const render::Lighting& lighting,
                    const render::Scene& scene, const Eigen::Isometry3d& world_T_camera,
                    double noise_sigma, std::uint64_t seed) {
  auto renderer = render::Renderer::create(camera, lighting);
  EXPECT_TRUE(renderer) << renderer.error().message;
  render::RenderOptions options;
  options.noise_sigma = noise_sigma;
  options.seed = seed;
  cv::Mat image;
  auto stats = renderer->render(scene, world_T_camera, options, image);
  EXPECT_TRUE(stats) << stats.error().message;
  return image;
}

void add_corner_noise(BoardObservation& obs, double sigma_px, std::mt19937_64& rng) {
  std::normal_distribution<double> noise(0.0, sigma_px);
  for (auto& p : obs.image_points) {
    p.x() += noise(rng);
    p.y() += noise(rng);
  }
}

std::vector<BoardView> intrinsics_views(const render::CameraDescription& camera,
                                        const BoardSpec& spec, int count, double depth_mm,
                                        double corner_noise_px, std::uint64_t seed,
                                        std::vector<Eigen::Isometry3d>* truth_poses) {
  const render::CameraModel& model = camera.truth.model;
  const Eigen::Isometry3d world_T_camera = Eigen::Isometry3d::Identity();
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  std::vector<BoardView> views;
  constexpr double kDeg = std::numbers::pi / 180.0;
  const double board_w = (spec.columns + 1) * spec.square_mm;
  const double board_h = (spec.rows + 1) * spec.square_mm;
  for (int i = 0; i < count; ++i) {
    // Spread the board over the field: a 3 x 3 grid of centres plus jitter, tilts alternating
    // in sign so that every direction of tilt is seen.
    const double depth = depth_mm * (0.85 + 0.3 * (i % 4) / 3.0);
    const double half_w = (model.width_px() / 2.0) / model.fx_px() * depth;
    const double half_h = (model.height_px() / 2.0) / model.fy_px() * depth;
    const double gx = ((i % 3) - 1.0) + 0.2 * unit(rng);
    const double gy = (((i / 3) % 3) - 1.0) + 0.2 * unit(rng);
    const double tilt_x = (i % 2 == 0 ? 1.0 : -1.0) * (25.0 + 20.0 * std::abs(unit(rng))) * kDeg;
    const double tilt_y = ((i / 2) % 2 == 0 ? 1.0 : -1.0) * (20.0 + 20.0 * std::abs(unit(rng))) *
                          kDeg;
    const double roll = 0.3 * unit(rng);
    // As far toward the edge of the field as the whole board (margin included) still fits,
    // 12 px inside the image: the views cover the field, corners included.
    Eigen::Isometry3d camera_T_board = Eigen::Isometry3d::Identity();
    for (double reach = 1.0; reach > 0.0; reach -= 0.05) {
      const Eigen::Vector3d center(gx * half_w * reach, gy * half_h * reach, depth);
      camera_T_board = board_facing_camera(spec, center, roll, tilt_x, tilt_y);
      bool inside = true;
      const double m = 12.0;
      for (const Eigen::Vector3d& c :
           {Eigen::Vector3d(-m, -m, 0.0), Eigen::Vector3d(board_w + m, -m, 0.0),
            Eigen::Vector3d(board_w + m, board_h + m, 0.0), Eigen::Vector3d(-m, board_h + m, 0.0)}) {
        auto px = model.project(camera_T_board * c);
        inside = inside && px && px->x() > 12.0 && px->y() > 12.0 &&
                 px->x() < model.width_px() - 13.0 && px->y() < model.height_px() - 13.0;
      }
      if (inside) {
        break;
      }
    }
    render::Scene scene;
    scene.table_height_mm = -5000.0;  // far behind the board: a dark background
    scene.table_reflectance = 0.2;
    scene.targets.push_back(chessboard_target(spec, world_T_camera * camera_T_board));
    // The operator's board in an evenly lit room, the camera's lamp on; nothing saturates (a
    // clipped white would bias every corner).
    scene.lights.fluorescent_on = false;
    scene.lights.lamp_on = true;
    render::Lighting lighting = camera.lighting;
    lighting.ambient = 0.7;
    const cv::Mat image = render_view(model, lighting, scene, world_T_camera, 1.0, seed + i);
    auto obs = detect_board(image, spec);
    EXPECT_TRUE(obs) << "view " << i << ": " << obs.error().message;
    if (!obs) {
      continue;
    }
    add_corner_noise(*obs, corner_noise_px, rng);
    if (truth_poses != nullptr) {
      truth_poses->push_back(camera_T_board);
    }
    views.push_back(BoardView{fmt::format("view{:02d}", i), 0, std::move(*obs)});
  }
  return views;
}

double rotation_error_rad(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  return Eigen::AngleAxisd(a.transpose() * b).angle();
}

}  // namespace cell::calibration::testing

namespace cell::calibration::testing {
namespace {

constexpr double kDegree = std::numbers::pi / 180.0;

/// Rotation with z along `forward`, turned by `roll` about it (x starts horizontal).
Eigen::Matrix3d looking_along(const Eigen::Vector3d& forward, double roll) {
  const Eigen::Vector3d z = forward.normalized();
  Eigen::Vector3d x = Eigen::Vector3d::UnitZ().cross(z);
  if (x.norm() < 1e-6) {
    x = Eigen::Vector3d::UnitX();
  }
  x.normalize();
  const Eigen::Vector3d y = z.cross(x);
  Eigen::Matrix3d r;
  r.col(0) = x;
  r.col(1) = y;
  r.col(2) = z;
  return r * Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitZ()).toRotationMatrix();
}

Eigen::Isometry3d pose(const Eigen::Vector3d& t, const Eigen::Matrix3d& r) {
  Eigen::Isometry3d p = Eigen::Isometry3d::Identity();
  p.linear() = r;
  p.translation() = t;
  return p;
}

Eigen::Matrix3d rpy(double roll_deg, double pitch_deg, double yaw_deg) {
  return (Eigen::AngleAxisd(yaw_deg * kDegree, Eigen::Vector3d::UnitZ()) *
          Eigen::AngleAxisd(pitch_deg * kDegree, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(roll_deg * kDegree, Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

/// True when the whole board (its margin included) projects inside the image, `margin_px` in.
bool board_in_view(const render::CameraModel& camera, const Eigen::Isometry3d& camera_T_board,
                   const BoardSpec& spec, double margin_px) {
  const double w = (spec.columns + 1) * spec.square_mm;
  const double h = (spec.rows + 1) * spec.square_mm;
  const double m = 12.0;
  for (const Eigen::Vector3d& c : {Eigen::Vector3d(-m, -m, 0), Eigen::Vector3d(w + m, -m, 0),
                                   Eigen::Vector3d(w + m, h + m, 0), Eigen::Vector3d(-m, h + m, 0),
                                   Eigen::Vector3d(w / 2, -m, 0), Eigen::Vector3d(w / 2, h + m, 0)}) {
    const Eigen::Vector3d pc = camera_T_board * c;
    if (pc.z() <= 0.0) {
      return false;
    }
    auto px = camera.project(pc);
    if (!px || px->x() < margin_px || px->y() < margin_px ||
        px->x() > camera.width_px() - 1 - margin_px || px->y() > camera.height_px() - 1 - margin_px) {
      return false;
    }
  }
  // Facing the camera (its printed side).
  return (camera_T_board.linear() * Eigen::Vector3d::UnitZ()).z() < -0.2;
}

render::Lighting even_lighting() {
  render::Lighting l;
  l.ambient = 0.9;
  return l;
}

/// Renders the board at world_T_board seen from world_T_camera, detects it and adds noise.
std::optional<BoardObservation> observe(const render::CameraModel& camera, const BoardSpec& spec,
                                        const Eigen::Isometry3d& world_T_board,
                                        const Eigen::Isometry3d& world_T_camera,
                                        double table_z, double table_reflectance,
                                        double pixel_sigma_px, std::uint64_t seed,
                                        std::mt19937_64& rng) {
  render::Scene scene;
  scene.table_height_mm = table_z;
  scene.table_reflectance = table_reflectance;
  scene.lights.fluorescent_on = false;
  scene.lights.lamp_on = false;
  scene.targets.push_back(chessboard_target(spec, world_T_board));
  const cv::Mat image = render_view(camera, even_lighting(), scene, world_T_camera, 1.0, seed);
  auto obs = detect_board(image, spec);
  if (!obs) {
    ADD_FAILURE() << "board not detected: " << obs.error().message;
    return std::nullopt;
  }
  add_corner_noise(*obs, pixel_sigma_px, rng);
  return std::move(*obs);
}

render::CameraModel synthetic_camera() {
  return render::CameraModel::create(800, 600, 1100.0, 1098.0, 402.5, 297.1,
                                     {-0.08, 0.05, 0.0002, -0.0001, 0.0})
      .value();
}

BoardSpec board_9x6(double square_mm) {
  BoardSpec b;
  b.columns = 9;
  b.rows = 6;
  b.square_mm = square_mm;
  return b;
}

/// The first inverse-kinematics solution for `base_T_mount` within the robot's limits.
std::optional<kinematics::JointVector> within_limits(const kinematics::RobotModel& robot,
                                                    const Eigen::Isometry3d& base_T_mount) {
  auto all = robot.inverse_all(base_T_mount);
  if (!all) {
    return std::nullopt;
  }
  for (const auto& sol : *all) {
    if (sol.within_limits()) {
      return sol.q;
    }
  }
  return std::nullopt;
}

void add_sample(HandEyeScenario& s, const Eigen::Isometry3d& mount,
                const kinematics::JointVector& q, BoardObservation obs, double rot_sigma,
                double trans_sigma, bool yaw_only, std::mt19937_64& rng) {
  HandEyeSample sample;
  const int k = static_cast<int>(s.samples.size());
  sample.id = fmt::format("pose {}", k);
  sample.stamp_ns = 1'000'000'000LL * (k + 1);
  sample.robot_stamp_ns = sample.stamp_ns - 2'000'000;  // the state 2 ms before the exposure
  sample.base_T_mount = noisy_pose(mount, rot_sigma, trans_sigma, yaw_only, rng);
  sample.observation = std::move(obs);
  s.samples.push_back(std::move(sample));
  s.true_mount.push_back(mount);
  s.joints.push_back(q);
}

}  // namespace

std::vector<cv::Mat> intrinsics_images(const render::CameraDescription& camera,
                                       const BoardSpec& board, double depth_mm,
                                       std::uint64_t seed) {
  std::vector<Eigen::Isometry3d> poses;
  (void)intrinsics_views(camera, board, 20, depth_mm, 0.0, seed, &poses);
  std::vector<cv::Mat> out;
  for (std::size_t i = 0; i < poses.size(); ++i) {
    render::Scene scene;
    scene.table_height_mm = -5000.0;
    scene.lights.fluorescent_on = false;
    scene.targets.push_back(chessboard_target(board, poses[i]));
    render::Lighting lighting = camera.lighting;
    lighting.ambient = 0.7;
    out.push_back(render_view(camera.truth.model, lighting, scene, Eigen::Isometry3d::Identity(),
                              1.0, seed + i));
  }
  return out;
}

Eigen::Isometry3d noisy_pose(const Eigen::Isometry3d& pose_in, double rotation_sigma_deg,
                             double translation_sigma_mm, bool yaw_only, std::mt19937_64& rng) {
  std::normal_distribution<double> rot(0.0, rotation_sigma_deg * kDegree);
  std::normal_distribution<double> trans(0.0, translation_sigma_mm);
  Eigen::Vector3d w(rot(rng), rot(rng), rot(rng));
  if (yaw_only) {
    w.x() = 0.0;
    w.y() = 0.0;
  }
  Eigen::Isometry3d delta = Eigen::Isometry3d::Identity();
  if (w.norm() > 0.0) {
    delta.linear() = Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix();
  }
  delta.translation() = Eigen::Vector3d(trans(rng), trans(rng), trans(rng));
  return pose_in * delta;
}

HandEyeScenario excalibur_eye_in_hand(int count,
                                      double rotation_sigma_deg,
                                      double translation_sigma_mm,
                                      double pixel_sigma_px,
                                      std::uint64_t seed,
                                      double min_elevation_deg,
                                      double max_elevation_deg) {
  HandEyeScenario s;
  s.name = "excalibur eye-in-hand";
  s.camera = synthetic_camera();
  s.board = board_9x6(12.0);
  s.options.setup = HandEyeSetup::kEyeInHand;
  const kinematics::RobotModel robot = robot_file("excalibur.yaml");
  // The camera beside the gripper, looking along the approach vector, a little off.
  s.truth_extrinsics = pose({48.0, -31.5, 62.0}, rpy(1.2, -0.8, 93.0));
  // The board on the table (base z = 0 is the bench), in front of the arm.
  s.truth_target = pose({380.0, -90.0, 3.0}, rpy(0.0, 0.0, 17.0));
  const Eigen::Vector3d centre = s.truth_target * Eigen::Vector3d(60.0, 42.0, 0.0);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (int attempt = 0; attempt < 4000 && static_cast<int>(s.samples.size()) < count; ++attempt) {
    const double dist = 230.0 + 100.0 * unit(rng);
    const double el =
        (min_elevation_deg + (max_elevation_deg - min_elevation_deg) * unit(rng)) * kDegree;
    const double az = (-180.0 + 360.0 * unit(rng)) * kDegree;
    const Eigen::Vector3d eye =
        centre + dist * Eigen::Vector3d(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az),
                                        std::sin(el));
    const Eigen::Vector3d aim = centre + Eigen::Vector3d(12.0 * (unit(rng) - 0.5),
                                                         12.0 * (unit(rng) - 0.5), 0.0);
    const Eigen::Isometry3d base_T_camera =
        pose(eye, looking_along(aim - eye, (-60.0 + 120.0 * unit(rng)) * kDegree));
    const Eigen::Isometry3d base_T_tool = base_T_camera * s.truth_extrinsics.inverse();
    const std::optional<kinematics::JointVector> picked = within_limits(robot, base_T_tool);
    if (!picked) {
      continue;
    }
    const Eigen::Isometry3d mount = robot.forward(*picked).value();
    const Eigen::Isometry3d world_T_camera = mount * s.truth_extrinsics;
    if (!board_in_view(s.camera, world_T_camera.inverse() * s.truth_target, s.board, 10.0)) {
      continue;
    }
    auto obs = observe(s.camera, s.board, s.truth_target, world_T_camera, 0.0, 0.3, pixel_sigma_px,
                       seed + static_cast<std::uint64_t>(attempt), rng);
    if (obs) {
      add_sample(s, mount, *picked, std::move(*obs), rotation_sigma_deg, translation_sigma_mm,
                 false, rng);
    }
  }
  EXPECT_EQ(static_cast<int>(s.samples.size()), count) << s.name;
  return s;
}

HandEyeScenario ibm7545_eye_in_hand(int count,
                                    double rotation_sigma_deg,
                                    double translation_sigma_mm,
                                    double pixel_sigma_px,
                                    std::uint64_t seed) {
  HandEyeScenario s;
  s.name = "7545 eye-in-hand (link 2)";
  const render::CameraDescription camera = camera_file("ibm7545_eye.yaml");
  s.camera = camera.truth.model;
  s.board.columns = 5;
  s.board.rows = 4;
  s.board.square_mm = 7.0;
  const kinematics::RobotModel robot = robot_file("ibm7545.yaml");
  const Eigen::Isometry3d world_T_base = camera.robot.world_T_base;
  const double table_z = 750.0;
  const double board_thickness = 3.0;  // render::Chessboard's default
  s.truth_extrinsics = camera.truth.pose;
  // The board on the table near the edge of the reach, where the camera point's arm (link 1
  // and the camera's 264 mm lever on link 2) is nearly stretched: there small moves of the
  // camera turn it a lot, which a SCARA needs to see its camera's offset (README.md).
  const double bx = 326.0;  // 652 mm from the J1 axis
  const double by = 565.0;
  s.truth_target = pose({bx - (s.board.columns + 1) * s.board.square_mm / 2, by - (s.board.rows + 1) * s.board.square_mm / 2,
                         table_z + board_thickness - world_T_base.translation().z()},
                        rpy(0.0, 0.0, 24.0));
  s.options.setup = HandEyeSetup::kEyeInHand;
  s.options.planar = true;
  s.options.planar_target_z_mm = s.truth_target.translation().z();
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (int attempt = 0; attempt < 400000 && static_cast<int>(s.samples.size()) < count; ++attempt) {
    kinematics::JointVector q(4);
    q << (20.0 + 80.0 * unit(rng)) * kDegree, (2.0 + 80.0 * unit(rng)) * kDegree, 0.0, 0.0;
    auto mount = render::base_T_mount(robot, render::MountFrame::kLink2, q);
    if (!mount) {
      continue;
    }
    const Eigen::Isometry3d world_T_camera = world_T_base * *mount * s.truth_extrinsics;
    const Eigen::Isometry3d world_T_board = world_T_base * s.truth_target;
    if (!board_in_view(s.camera, world_T_camera.inverse() * world_T_board, s.board, 20.0)) {
      continue;
    }
    auto obs = observe(s.camera, s.board, world_T_board, world_T_camera, table_z, 0.9,
                       pixel_sigma_px, seed + static_cast<std::uint64_t>(attempt), rng);
    if (obs) {
      add_sample(s, *mount, q, std::move(*obs), rotation_sigma_deg, translation_sigma_mm, true,
                 rng);
    }
  }
  EXPECT_EQ(static_cast<int>(s.samples.size()), count) << s.name;
  return s;
}

HandEyeScenario picker_eye_to_hand(int count,
                                   double rotation_sigma_deg,
                                   double translation_sigma_mm,
                                   double pixel_sigma_px,
                                   std::uint64_t seed) {
  HandEyeScenario s;
  s.name = "belt camera over the picker (eye-to-hand)";
  const render::CameraDescription camera = camera_file("belt_cam.yaml");
  s.camera = camera.truth.model;
  s.board = board_9x6(20.0);
  const kinematics::RobotModel robot = robot_file("scara_picker.yaml");
  const Eigen::Isometry3d world_T_base = pose({1000.0, 0.0, 960.0}, Eigen::Matrix3d::Identity());
  s.truth_extrinsics = world_T_base.inverse() * camera.truth.pose;
  // The board under the flange, its face 25 mm below, a little skewed on its holder.
  s.truth_target = pose({-97.0, -72.0, -25.0}, rpy(0.3, -0.2, 1.5));
  s.options.setup = HandEyeSetup::kEyeToHand;
  s.options.planar = true;
  s.options.planar_target_z_mm = s.truth_target.translation().z();
  s.options.planar_target_level = false;  // skewed on its holder
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (int attempt = 0; attempt < 4000 && static_cast<int>(s.samples.size()) < count; ++attempt) {
    const double x = 250.0 + 200.0 * unit(rng);
    const double y = -20.0 + 220.0 * unit(rng);
    const double z = -(100.0 + 100.0 * unit(rng));
    const double yaw = (-120.0 + 240.0 * unit(rng)) * kDegree;
    const Eigen::Isometry3d want =
        pose({x, y, z}, Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix());
    const std::optional<kinematics::JointVector> picked = within_limits(robot, want);
    if (!picked) {
      continue;
    }
    const Eigen::Isometry3d mount = robot.forward(*picked).value();
    const Eigen::Isometry3d world_T_board = world_T_base * mount * s.truth_target;
    if (!board_in_view(s.camera, camera.truth.pose.inverse() * world_T_board, s.board, 10.0)) {
      continue;
    }
    auto obs = observe(s.camera, s.board, world_T_board, camera.truth.pose, 760.0, 0.3,
                       pixel_sigma_px, seed + static_cast<std::uint64_t>(attempt), rng);
    if (obs) {
      add_sample(s, mount, *picked, std::move(*obs), rotation_sigma_deg, translation_sigma_mm, true,
                 rng);
    }
  }
  EXPECT_EQ(static_cast<int>(s.samples.size()), count) << s.name;
  return s;
}

HandEyeScenario excalibur_eye_to_hand(int count,
                                      double rotation_sigma_deg,
                                      double translation_sigma_mm,
                                      double pixel_sigma_px,
                                      std::uint64_t seed) {
  HandEyeScenario s;
  s.name = "fixed camera over the excalibur (eye-to-hand)";
  s.camera = synthetic_camera();
  s.board = board_9x6(20.0);
  const kinematics::RobotModel robot = robot_file("excalibur.yaml");
  s.truth_extrinsics = pose({430.0, 20.0, 1150.0}, rpy(178.5, 1.2, -88.0));
  // Held in the gripper, its face against the approach vector (toward the camera above).
  s.truth_target = pose({-100.0, -70.0, 35.0}, rpy(180.0, 0.0, 2.0) * rpy(0.4, -0.6, 0.0));
  s.options.setup = HandEyeSetup::kEyeToHand;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const Eigen::Vector3d cam = s.truth_extrinsics.translation();
  for (int attempt = 0; attempt < 6000 && static_cast<int>(s.samples.size()) < count; ++attempt) {
    // The board centre 550..800 mm below the camera, spread over the field, tilted up to 35
    // degrees toward it: the wider the spread, the better the camera's rotation is seen.
    const Eigen::Vector3d centre(cam.x() - 160.0 + 320.0 * unit(rng),
                                 cam.y() - 120.0 + 240.0 * unit(rng),
                                 cam.z() - 550.0 - 250.0 * unit(rng));
    const double tilt = 35.0 * unit(rng) * kDegree;
    const double dir = 360.0 * unit(rng) * kDegree;
    const Eigen::Vector3d up(std::sin(tilt) * std::cos(dir), std::sin(tilt) * std::sin(dir),
                             std::cos(tilt));
    // Board z = up (facing the camera), turned about it.
    const Eigen::Matrix3d r_board = looking_along(up, (-70.0 + 140.0 * unit(rng)) * kDegree);
    const Eigen::Isometry3d world_T_board =
        pose(centre - r_board * Eigen::Vector3d(100.0, 70.0, 0.0), r_board);
    const Eigen::Isometry3d base_T_tool = world_T_board * s.truth_target.inverse();
    const std::optional<kinematics::JointVector> picked = within_limits(robot, base_T_tool);
    if (!picked) {
      continue;
    }
    const Eigen::Isometry3d mount = robot.forward(*picked).value();
    if (!board_in_view(s.camera, s.truth_extrinsics.inverse() * mount * s.truth_target, s.board,
                       10.0)) {
      continue;
    }
    auto obs = observe(s.camera, s.board, mount * s.truth_target, s.truth_extrinsics, -200.0, 0.4,
                       pixel_sigma_px, seed + static_cast<std::uint64_t>(attempt), rng);
    if (obs) {
      add_sample(s, mount, *picked, std::move(*obs), rotation_sigma_deg, translation_sigma_mm,
                 false, rng);
    }
  }
  EXPECT_EQ(static_cast<int>(s.samples.size()), count) << s.name;
  return s;
}

}  // namespace cell::calibration::testing
