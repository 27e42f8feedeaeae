#include "cell/render/renderer.hpp"

#include <cmath>
#include <numbers>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "cell/render/truth.hpp"
#include "cell/testing/matchers.hpp"
#include "measure.hpp"
#include "test_cameras.hpp"

namespace cell::render {
namespace {

using ::cell::testing::IsErrWith;
using ::testing::HasSubstr;

constexpr double kPi = std::numbers::pi;
constexpr double kCornerTolPx = 0.05;  // the bound for an undistorted render

using testing::looking_down;
using testing::pinhole;

Eigen::Isometry3d part_pose(double x, double y, double z, double yaw) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  pose.translation() = Eigen::Vector3d(x, y, z);
  return pose;
}

CameraModel with_lens() {
  return CameraModel::create(512, 484, 1502.3, 1455.9, 258.4, 237.2,
                             Distortion{-0.12, 0.08, 0.0006, -0.0004, 0.0})
      .value();
}

/// Uniform light: every surface reads 255 * reflectance, whatever its orientation.
Lighting flat_light() {
  Lighting l;
  l.ambient = 1.0;
  return l;
}

Scene empty_scene(bool lamp, bool tubes) {
  Scene scene;
  scene.lights.lamp_on = lamp;
  scene.lights.fluorescent_on = tubes;
  return scene;
}

Part sticker(const std::string& id, double length, double width, const Eigen::Isometry3d& pose) {
  Part p;
  p.id = id;
  p.class_name = "rectangle";
  p.shape = Shape::kRectangle;
  p.length_mm = length;
  p.width_mm = width;
  p.height_mm = 0.0;
  p.reflectance = 0.05;
  p.world_T_part = pose;
  return p;
}

// dip14 of core/world's catalogue: JEDEC MS-001, 19.05 x 6.35 mm body, 3.30 mm thick over a
// 0.51 mm standoff (digest 000 §3: "a 14-pin package (6 x 19 mm)").
Part dip(const std::string& id, const Eigen::Isometry3d& pose, int pins = 14) {
  Part p;
  p.id = id;
  p.class_name = fmt::format("dip{}", pins);
  p.shape = Shape::kDip;
  p.length_mm = 19.05;
  p.width_mm = 6.35;
  p.height_mm = 3.81;
  p.pins = pins;
  p.leads = DipLeads::standard_for_width(p.width_mm);
  p.reflectance = 0.1;
  p.world_T_part = pose;
  return p;
}

cv::Mat render(Renderer& renderer, const Scene& scene, const Eigen::Isometry3d& world_T_camera,
               RenderOptions options = {}) {
  cv::Mat image;
  auto stats = renderer.render(scene, world_T_camera, options, image);
  EXPECT_TRUE(stats) << stats.error().message;
  return image;
}

std::vector<Eigen::Vector2d> truth_corners(const Scene& scene, const CameraModel& camera,
                                           const Eigen::Isometry3d& world_T_camera) {
  const auto truth = ground_truth(scene, camera, world_T_camera);
  EXPECT_EQ(truth.size(), 1U);
  return truth.empty() ? std::vector<Eigen::Vector2d>{} : truth.front().corners_px;
}

double max_corner_error(const std::vector<Eigen::Vector2d>& measured,
                        const std::vector<Eigen::Vector2d>& expected) {
  EXPECT_EQ(measured.size(), expected.size());
  double worst = 0.0;
  for (std::size_t i = 0; i < std::min(measured.size(), expected.size()); ++i) {
    worst = std::max(worst, (measured[i] - expected[i]).norm());
  }
  return measured.empty() ? 1e9 : worst;
}

// The must-hold: a part rendered at a known world pose appears where the true camera
// model projects it, to 0.05 px for a corner on an undistorted render. The corners are measured
// from pixel values alone (edge lines by the area method, intersected), under a tilted camera so
// that no edge is aligned with the pixel grid.
TEST(Renderer, PartCornersAppearWhereTheCameraProjectsThem) {
  const CameraModel camera = pinhole();
  auto renderer = Renderer::create(camera, flat_light()).value();
  Eigen::Isometry3d world_T_camera = looking_down({3.0, 4.0, 420.0}, 0.2);
  world_T_camera.rotate(Eigen::AngleAxisd(0.05, Eigen::Vector3d::UnitX()));
  Scene scene = empty_scene(false, false);
  scene.parts.push_back(sticker("p1", 30.0, 12.0, part_pose(8.0, -5.0, 0.0, 0.3)));
  const cv::Mat image = render(renderer, scene, world_T_camera);
  const auto expected = truth_corners(scene, camera, world_T_camera);
  const auto measured = testing::measure_polygon_corners(image, expected);
  const double error = max_corner_error(measured, expected);
  EXPECT_LT(error, kCornerTolPx);
  RecordProperty("max_corner_error_px", fmt::format("{:.4f}", error));

  // The measurement can tell: the same part 0.1 mm further along x (0.36 px) is caught.
  scene.parts.front().world_T_part.translation().x() += 0.1;
  const cv::Mat moved = render(renderer, scene, world_T_camera);
  const auto moved_corners = testing::measure_polygon_corners(moved, expected);
  EXPECT_GT(max_corner_error(moved_corners, expected), 0.25);
}

TEST(Renderer, TheLensBendsTheImageAsCvProjectPointsDoes) {
  const CameraModel camera = with_lens();
  auto renderer = Renderer::create(camera, flat_light()).value();
  const Eigen::Isometry3d world_T_camera = looking_down({0.0, 0.0, 420.0}, 0.1);
  // A small square near the image corner, where the lens moves points by about 1 px.
  Scene scene = empty_scene(false, false);
  scene.parts.push_back(sticker("p1", 7.0, 7.0, part_pose(55.0, -50.0, 0.0, 0.4)));
  const cv::Mat image = render(renderer, scene, world_T_camera);

  const auto truth = ground_truth(scene, camera, world_T_camera);
  ASSERT_EQ(truth.size(), 1U);
  // Expected corners from OpenCV itself.
  const Eigen::Isometry3d camera_T_world = world_T_camera.inverse();
  std::vector<cv::Point3d> object;
  const Part& part = scene.parts.front();
  for (const auto& c : {Eigen::Vector3d(-3.5, -3.5, 0), Eigen::Vector3d(3.5, -3.5, 0),
                        Eigen::Vector3d(3.5, 3.5, 0), Eigen::Vector3d(-3.5, 3.5, 0)}) {
    const Eigen::Vector3d p = camera_T_world * (part.world_T_part * c);
    object.emplace_back(p.x(), p.y(), p.z());
  }
  const cv::Mat k = (cv::Mat_<double>(3, 3) << camera.fx_px(), 0, camera.cx_px(), 0,
                     camera.fy_px(), camera.cy_px(), 0, 0, 1);
  const auto dist = camera.distortion().as_array();
  std::vector<cv::Point2d> cv_px;
  cv::projectPoints(object, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), k,
                    cv::Mat(1, 5, CV_64F, const_cast<double*>(dist.data())), cv_px);
  std::vector<Eigen::Vector2d> expected;
  std::vector<Eigen::Vector2d> pinhole_px;
  for (std::size_t i = 0; i < cv_px.size(); ++i) {
    expected.emplace_back(cv_px[i].x, cv_px[i].y);
    pinhole_px.emplace_back(camera.fx_px() * object[i].x / object[i].z + camera.cx_px(),
                            camera.fy_px() * object[i].y / object[i].z + camera.cy_px());
    EXPECT_LT((truth.front().corners_px[i] - expected.back()).norm(), 1e-9);
  }
  const auto measured = testing::measure_polygon_corners(image, expected, 3);
  EXPECT_LT(max_corner_error(measured, expected), kCornerTolPx);
  // ... and the distortion is really there: ignoring it misses by far more.
  EXPECT_GT(max_corner_error(measured, pinhole_px), 0.6);
}

TEST(Renderer, SameSceneSeedAndCameraGiveTheSameBytes) {
  const CameraModel camera = with_lens();
  Scene scene = empty_scene(true, true);
  for (int i = 0; i < 15; ++i) {
    const int column = i % 6;
    const int row = i / 6;  // rows of 6
    scene.parts.push_back(dip(fmt::format("ic{}", i),
                              part_pose(-55.0 + 22.0 * column, -45.0 + 40.0 * row, 0.0, 0.3 * i)));
  }
  const Eigen::Isometry3d world_T_camera = looking_down({0.0, 0.0, 420.0}, 0.7);
  RenderOptions options;
  options.noise_sigma = 2.0;
  options.seed = 5;
  auto first = Renderer::create(camera, Lighting{}).value();
  auto second = Renderer::create(camera, Lighting{}).value();
  const cv::Mat a = render(first, scene, world_T_camera, options);
  const cv::Mat b = render(second, scene, world_T_camera, options);
  const cv::Mat again = render(first, scene, world_T_camera, options);  // scratch reused
  ASSERT_EQ(a.size(), b.size());
  EXPECT_EQ(cv::countNonZero(a != b), 0);
  EXPECT_EQ(cv::countNonZero(a != again), 0);
  options.seed = 6;
  const cv::Mat c = render(first, scene, world_T_camera, options);
  const int differing = cv::countNonZero(a != c);
  EXPECT_GT(differing, a.total() / 2);  // sigma 2: most pixels change
  cv::Mat diff;
  cv::absdiff(a, c, diff);
  EXPECT_LT(cv::mean(diff)[0], 4.0);  // ... by noise only
}

TEST(Renderer, LightsChangeTheBackgroundLevel) {
  const CameraModel camera = with_lens();
  auto renderer = Renderer::create(camera, Lighting{}).value();
  const Eigen::Isometry3d world_T_camera = looking_down({0.0, 0.0, 420.0});
  auto level = [&](bool lamp, bool tubes) {
    return cv::mean(render(renderer, empty_scene(lamp, tubes), world_T_camera))[0];
  };
  const double both = level(true, true);
  const double tubes = level(false, true);
  const double lamp = level(true, false);
  const double none = level(false, false);
  EXPECT_GT(both, tubes + 20.0);
  EXPECT_GT(tubes, lamp + 20.0);
  EXPECT_GT(lamp, none + 20.0);
  EXPECT_GT(tubes, 150.0);  // digest 000 §3: a white table stays above the threshold of 150
  EXPECT_LT(none, 40.0);
  // The tubes hang to one side (+x): a gradient across the field, brighter toward them.
  const cv::Mat image = render(renderer, empty_scene(false, true), world_T_camera);
  const double left = cv::mean(image(cv::Rect(0, 0, 64, 484)))[0];
  const double right = cv::mean(image(cv::Rect(448, 0, 64, 484)))[0];
  EXPECT_GT(right - left, 3.0);
  // The lamp is a spot: brightest in the middle of the field.
  const cv::Mat spot = render(renderer, empty_scene(true, false), world_T_camera);
  EXPECT_GT(cv::mean(spot(cv::Rect(224, 210, 64, 64)))[0],
            cv::mean(spot(cv::Rect(0, 0, 64, 64)))[0] + 5.0);
}

TEST(Renderer, PinsCatchHighlightsAlongTheLongSides) {
  const CameraModel camera = pinhole();
  auto renderer = Renderer::create(camera, Lighting{}).value();
  const Eigen::Isometry3d world_T_camera = looking_down({0.0, 0.0, 420.0});
  Scene scene = empty_scene(true, true);
  const Part ic = dip("ic", part_pose(0.0, 0.0, 0.0, 0.0));  // long sides along u
  scene.parts.push_back(ic);
  const cv::Mat image = render(renderer, scene, world_T_camera);
  auto px = [&](double x, double y, double z) {
    return project_world(camera, world_T_camera, ic.world_T_part * Eigen::Vector3d(x, y, z))
        .value();
  };
  // Rows fully inside the upper lead row (part +y is image -v), from the body's side out to
  // the pin row, and columns within the row of leads.
  const double z_lead = 0.51 + 0.5 * (3.81 - 0.51);
  const double reach = 0.5 * (7.62 + 0.25);
  const int lead_first_row = static_cast<int>(std::ceil(px(0, reach, z_lead).y() + 0.5));
  const int lead_last_row = static_cast<int>(std::floor(px(0, 3.175, z_lead).y() - 0.5));
  ASSERT_GE(lead_last_row, lead_first_row);
  const int c0 = static_cast<int>(px(-8.0, 0, 0).x());
  const int c1 = static_cast<int>(px(8.0, 0, 0).x());
  const cv::Rect leads(c0, lead_first_row, c1 - c0, lead_last_row - lead_first_row + 1);
  const cv::Point2d top_left(px(-8.0, 2.5, 3.81).x(), px(-8.0, 2.5, 3.81).y());
  const cv::Rect body(static_cast<int>(top_left.x), static_cast<int>(top_left.y), c1 - c0,
                      static_cast<int>(px(8.0, -2.5, 3.81).y() - top_left.y));
  const double body_mean = cv::mean(image(body))[0];
  double lead_max = 0.0;
  cv::minMaxLoc(image(leads), nullptr, &lead_max);
  EXPECT_LT(body_mean, 40.0);
  EXPECT_GT(lead_max, 240.0);                              // highlights on the lead crests
  EXPECT_GT(cv::mean(image(leads))[0], body_mean + 60.0);  // the lead rows are bright
  // Beyond the short ends there are no leads: plain table.
  const int end_col = static_cast<int>(std::ceil(px(9.525, 0, 3.81).x())) + 2;
  EXPECT_GT(cv::mean(image(cv::Rect(end_col, body.y, 4, body.height)))[0], 200.0);
  // Without the halogen the leads are dull.
  scene.lights.lamp_on = false;
  const cv::Mat dull = render(renderer, scene, world_T_camera);
  double dull_max = 0.0;
  cv::minMaxLoc(dull(leads), nullptr, &dull_max);
  EXPECT_LT(dull_max, lead_max - 40.0);
  // Digest 000 §3: pins bias a naive bounding box. Under the tubes alone the leads' flanks are
  // below the threshold of 150, so the dark blob spans the pin rows, not just the body.
  cv::Mat dark;
  cv::threshold(dull, dark, 150, 255, cv::THRESH_BINARY_INV);
  const cv::Rect box = cv::boundingRect(dark);
  const double body_px = px(0, -3.175, 3.81).y() - px(0, 3.175, 3.81).y();
  const double leads_px = px(0, -reach, z_lead).y() - px(0, reach, z_lead).y();
  EXPECT_NEAR(box.height, leads_px, 2.0);
  EXPECT_GT(box.height, body_px + 3.0);
  EXPECT_NEAR(box.width, 19.05 * 3.56, 3.0);
}

TEST(Renderer, MotionBlurWidensAnEdgeBySpeedTimesExposure) {
  const CameraModel camera = pinhole();
  auto renderer = Renderer::create(camera, flat_light()).value();
  const Eigen::Isometry3d world_T_camera = looking_down({0.0, 0.0, 420.0});
  Scene scene = empty_scene(false, false);
  scene.parts.push_back(sticker("p", 40.0, 40.0, part_pose(0.0, 0.0, 0.0, 0.0)));
  const int row = 241;
  const cv::Mat still = render(renderer, scene, world_T_camera);
  // Digest 002 T7 at this camera's scale: 2.5 m/s for 2 ms is 5 mm, 17.8 px at 3.56 px/mm.
  scene.parts.front().velocity_mm_s = Eigen::Vector3d(2500.0, 0.0, 0.0);
  RenderOptions options;
  options.exposure_s = 0.002;
  const cv::Mat moving = render(renderer, scene, world_T_camera, options);
  const double blur_px = 2500.0 * 0.002 * 3.56;
  // The trailing (left) edge of the dark square: bright table, then the ramp.
  const int edge = static_cast<int>(std::lround(255.0 - 20.0 * 3.56));
  const double still_width = testing::ramp_width_px(still, row, edge - 15, edge + 15);
  const double moving_width = testing::ramp_width_px(moving, row, edge - 20, edge + 20);
  EXPECT_LE(still_width, 2.0);
  EXPECT_NEAR(moving_width, blur_px, 0.5);
  // The blur is centred on the mid-exposure position: the dark area is conserved.
  const double bright = still.at<std::uint8_t>(row, edge - 20);
  const double dark = still.at<std::uint8_t>(row, edge + 19);
  auto dark_length = [&](const cv::Mat& img) {
    double sum = 0.0;
    for (int c = edge - 20; c < edge + 20; ++c) {
      sum += (bright - img.at<std::uint8_t>(row, c)) / (bright - dark);
    }
    return sum;
  };
  EXPECT_NEAR(dark_length(moving), dark_length(still), 0.1);
}

TEST(Renderer, PolyhedronFacesAreShadedSoTheirEdgesShow) {
  const CameraModel camera = pinhole();
  auto renderer = Renderer::create(camera, Lighting{}).value();
  const Eigen::Isometry3d world_T_camera = looking_down({-30.0, -20.0, 420.0});
  Part pyramid;
  pyramid.id = "b1";
  pyramid.class_name = "pyramid";
  pyramid.shape = Shape::kPolyhedron;
  pyramid.reflectance = 0.6;
  pyramid.mesh.vertices_mm = {{-20, -20, 0}, {20, -20, 0}, {20, 20, 0}, {-20, 20, 0}, {0, 0, 25}};
  pyramid.mesh.faces = {{3, 2, 1, 0}, {0, 1, 4}, {1, 2, 4}, {2, 3, 4}, {3, 0, 4}};
  Scene scene = empty_scene(true, true);
  scene.parts.push_back(pyramid);
  const cv::Mat image = render(renderer, scene, world_T_camera);
  // Mean grey inside each side face, sampled around its projected centroid.
  std::vector<double> levels;
  for (std::size_t f = 1; f < pyramid.mesh.faces.size(); ++f) {
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (const auto i : pyramid.mesh.faces[f]) {
      c += pyramid.mesh.vertices_mm[i];
    }
    c /= 3.0;
    const auto px = project_world(camera, world_T_camera, c);
    ASSERT_TRUE(px);
    levels.push_back(
        cv::mean(image(cv::Rect(static_cast<int>(px->x()) - 3, static_cast<int>(px->y()) - 3, 6,
                                6)))[0]);
  }
  const auto [lo, hi] = std::minmax_element(levels.begin(), levels.end());
  EXPECT_GT(*hi - *lo, 15.0) << "faces: " << levels[0] << " " << levels[1] << " " << levels[2]
                             << " " << levels[3];
}

TEST(Renderer, MalformedPartsAreSkippedAndNamedNeverDrawnHalf) {
  const CameraModel camera = pinhole();
  auto renderer = Renderer::create(camera, Lighting{}).value();
  const Eigen::Isometry3d world_T_camera = looking_down({0.0, 0.0, 420.0});
  Scene scene = empty_scene(true, true);
  scene.parts.push_back(dip("good", part_pose(0.0, 0.0, 0.0, 0.0)));
  const cv::Mat reference = render(renderer, scene, world_T_camera);
  Part nan_pose = dip("nan", part_pose(10.0, 10.0, 0.0, 0.0));
  nan_pose.world_T_part.translation().x() = NAN;
  Part odd = dip("odd", part_pose(-30.0, 10.0, 0.0, 0.0), 13);
  Part broken = dip("mesh", part_pose(30.0, 10.0, 0.0, 0.0));
  broken.shape = Shape::kPolyhedron;
  broken.mesh.vertices_mm = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  broken.mesh.faces = {{0, 1, 2}, {0, 1, 3}, {1, 2, 3}, {0, 2, 9}};
  scene.parts.push_back(nan_pose);
  scene.parts.push_back(odd);
  scene.parts.push_back(broken);
  cv::Mat image;
  const auto stats = renderer.render(scene, world_T_camera, {}, image);
  ASSERT_TRUE(stats) << stats.error().message;
  EXPECT_EQ(stats->parts_skipped, 3);
  ASSERT_EQ(stats->skipped.size(), 3U);
  EXPECT_THAT(stats->skipped[0].message, HasSubstr("part 'nan'"));
  EXPECT_THAT(stats->skipped[1].message, HasSubstr("pins 13 must be even"));
  EXPECT_THAT(stats->skipped[2].message, HasSubstr("face 3 uses vertex 9 of 4"));
  EXPECT_EQ(cv::countNonZero(image != reference), 0);
  EXPECT_EQ(ground_truth(scene, camera, world_T_camera).size(), 1U);
}

TEST(Renderer, OpenCvFindsTheChessboardWhereItIs) {
  const CameraModel camera = with_lens();
  auto renderer = Renderer::create(camera, Lighting{}).value();
  const Eigen::Isometry3d world_T_camera = looking_down({0.0, 0.0, 420.0}, 0.25);
  Chessboard board;
  board.id = "cb";
  board.squares_x = 9;
  board.squares_y = 7;
  board.square_mm = 12.0;
  board.world_T_board = part_pose(-54.0, -42.0, board.thickness_mm, 0.05);
  Scene scene = empty_scene(true, true);
  scene.targets.push_back(board);
  RenderOptions options;
  options.noise_sigma = 1.0;
  const cv::Mat image = render(renderer, scene, world_T_camera, options);
  std::vector<cv::Point2f> found;
  ASSERT_TRUE(cv::findChessboardCorners(image, cv::Size(8, 6), found));
  cv::cornerSubPix(image, found, cv::Size(5, 5), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 50, 1e-4));
  double worst = 0.0;
  for (const auto& corner : chessboard_corners(board)) {
    const auto px = project_world(camera, world_T_camera, board.world_T_board * corner);
    ASSERT_TRUE(px);
    double nearest = 1e9;
    for (const auto& f : found) {
      nearest = std::min(nearest, std::hypot(f.x - px->x(), f.y - px->y()));
    }
    worst = std::max(worst, nearest);
  }
  EXPECT_LT(worst, 0.1);
}

TEST(Renderer, RejectsBadPosesAndOptionsWithoutTouchingTheImage) {
  auto renderer = Renderer::create(pinhole(), Lighting{}).value();
  cv::Mat image(3, 3, CV_8UC1, cv::Scalar(7));
  Eigen::Isometry3d skewed = looking_down({0.0, 0.0, 420.0});
  skewed.linear()(0, 1) = 0.3;
  EXPECT_THAT(renderer.render(empty_scene(true, true), skewed, {}, image),
              IsErrWith(Errc::kInvalidArgument, "world_T_camera"));
  RenderOptions options;
  options.noise_sigma = -1.0;
  EXPECT_THAT(renderer.render(empty_scene(true, true), looking_down({0, 0, 420}), options, image),
              IsErrWith(Errc::kInvalidArgument, "noise_sigma = -1"));
  EXPECT_EQ(image.rows, 3);
  Lighting bad;
  bad.ambient = -0.1;
  EXPECT_THAT(Renderer::create(pinhole(), bad), IsErrWith(Errc::kInvalidArgument, "ambient"));
}

}  // namespace
}  // namespace cell::render
